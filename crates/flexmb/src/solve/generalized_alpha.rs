//! Parameters of the generalized-alpha scheme.
//!
//! Chung & Hulbert (1993), J. Appl. Mech. 60, Eqs. (25)-(26) (optimal parameters from the
//! spectral radius at infinity `rho_inf`), in the form of Arnold & Brüls (2007), Multibody
//! Syst. Dyn. 18, Eq. (5):
//!
//! ```text
//! alpha_m = (2 rho_inf - 1)/(rho_inf + 1),  alpha_f = rho_inf/(rho_inf + 1),
//! gamma   = 1/2 + alpha_f - alpha_m,        beta    = (gamma + 1/2)^2 / 4.
//! ```
//! Newmark's average acceleration (trapezoidal rule) is `rho_inf = 1`; HHT-alpha is
//! `alpha_m = 0`.
//!
//! **First-order states** `x` (element internal variables, later control states) are
//! integrated by the first-order generalized-alpha method of Jansen, Whiting & Hulbert
//! (2000), Comput. Methods Appl. Mech. Engrg. 190, Eqs. (17)-(20) and (27), written like the
//! second-order scheme with an algorithmic rate `w` (Arnold & Brüls 2007, Eq. (5); the
//! coupled scheme of Brüls & Golinval 2008):
//!
//! ```text
//! x_{n+1} = x_n + h (1 - gamma) w_n + h gamma w_{n+1}
//! (1 - alpha_m) w_{n+1} + alpha_m w_n = (1 - alpha_f) xdot_{n+1} + alpha_f xdot_n
//! alpha_m = (3 rho_inf - 1) / (2 (rho_inf + 1)),  alpha_f = rho_inf / (rho_inf + 1),
//! gamma   = 1/2 + alpha_f - alpha_m
//! ```
//!
//! (Jansen et al.'s `alpha_m`, `alpha_f` are one minus these). For `xdot = lambda x` it is
//! second-order accurate with spectral radius `rho_inf` as `h lambda -> -infinity`, the same
//! `rho_inf` as the mechanical part.

/// The four numbers of the scheme.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaParameters {
    pub alpha_m: f64,
    pub alpha_f: f64,
    pub beta: f64,
    pub gamma: f64,
}

impl GaParameters {
    /// Optimal parameters for a spectral radius at infinity `rho_inf` in `[0, 1]`.
    pub fn from_rho_inf(rho_inf: f64) -> Self {
        let alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0);
        let alpha_f = rho_inf / (rho_inf + 1.0);
        let gamma = 0.5 + alpha_f - alpha_m;
        Self {
            alpha_m,
            alpha_f,
            beta: 0.25 * (gamma + 0.5).powi(2),
            gamma,
        }
    }

    /// HHT-alpha with `alpha` in `[0, 1/3]` (Hilber, Hughes & Taylor 1977).
    pub fn hht(alpha: f64) -> Self {
        Self {
            alpha_m: 0.0,
            alpha_f: alpha,
            beta: 0.25 * (1.0 + alpha).powi(2),
            gamma: 0.5 + alpha,
        }
    }

    /// `beta' = (1 - alpha_m) / (h^2 beta (1 - alpha_f))`: `d vdot / d(increment)`.
    pub fn beta_prime(&self, h: f64) -> f64 {
        (1.0 - self.alpha_m) / (h * h * self.beta * (1.0 - self.alpha_f))
    }

    /// `gamma' = gamma / (h beta)`: `d v / d(increment)`.
    pub fn gamma_prime(&self, h: f64) -> f64 {
        self.gamma / (h * self.beta)
    }
}

/// The three numbers of the first-order scheme (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FirstOrderParameters {
    pub alpha_m: f64,
    pub alpha_f: f64,
    pub gamma: f64,
}

impl FirstOrderParameters {
    /// Second-order accurate parameters with spectral radius at infinity `rho_inf` in
    /// `[0, 1]` (Jansen, Whiting & Hulbert 2000, Eq. (27)).
    pub fn from_rho_inf(rho_inf: f64) -> Self {
        let alpha_m = (3.0 * rho_inf - 1.0) / (2.0 * (rho_inf + 1.0));
        let alpha_f = rho_inf / (rho_inf + 1.0);
        Self {
            alpha_m,
            alpha_f,
            gamma: 0.5 + alpha_f - alpha_m,
        }
    }

    /// `(1 - alpha_m) / ((1 - alpha_f) gamma h)`: `d xdot_{n+1} / d x_{n+1}`.
    pub fn rate_coefficient(&self, h: f64) -> f64 {
        (1.0 - self.alpha_m) / ((1.0 - self.alpha_f) * self.gamma * h)
    }

    /// The algorithmic rate `w_{n+1}` from the rates at both ends and `w_n`.
    pub fn rate(&self, xdot_n: f64, xdot_1: f64, w_n: f64) -> f64 {
        (self.alpha_f * xdot_n + (1.0 - self.alpha_f) * xdot_1 - self.alpha_m * w_n)
            / (1.0 - self.alpha_m)
    }

    /// The rate `xdot_{n+1}` from `xdot_n`, `w_n` and `w_{n+1}` (the inverse of
    /// [`FirstOrderParameters::rate`]).
    pub fn rate_from(&self, xdot_n: f64, w_n: f64, w_1: f64) -> f64 {
        ((1.0 - self.alpha_m) * w_1 + self.alpha_m * w_n - self.alpha_f * xdot_n)
            / (1.0 - self.alpha_f)
    }

    /// The algorithmic rate `w_{n+1}` of the increment `dx = x_{n+1} - x_n` (the inverse of
    /// [`FirstOrderParameters::increment`]).
    pub fn rate_of_increment(&self, h: f64, dx: f64, w_n: f64) -> f64 {
        (dx - h * (1.0 - self.gamma) * w_n) / (h * self.gamma)
    }

    /// The increment `x_{n+1} - x_n` from `w_n` and `w_{n+1}`.
    pub fn increment(&self, h: f64, w_n: f64, w_1: f64) -> f64 {
        h * (1.0 - self.gamma) * w_n + h * self.gamma * w_1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One step of the first-order scheme on `xdot = lambda x`: `(x, w) -> (x, w)`.
    fn first_order_step(p: &FirstOrderParameters, z: f64, (x, w): (f64, f64)) -> (f64, f64) {
        // Unknown x1: xdot1 = lambda x1, w1 = rate(lambda x, lambda x1, w), x1 = x + inc.
        // Linear in x1: x1 = x + h (1 - g) w + h g (af l x + (1 - af) l x1 - am w) / (1 - am).
        let (am, af, g) = (p.alpha_m, p.alpha_f, p.gamma);
        let c = g / (1.0 - am);
        let x1 = (x + (1.0 - g) * w + c * (af * z * x - am * w)) / (1.0 - c * (1.0 - af) * z);
        let w1 = p.rate(z * x, z * x1, w);
        (x1, w1)
    }

    #[test]
    fn first_order_scheme_has_its_spectral_radius_and_second_order() {
        for rho in [0.0, 0.3, 0.6, 0.9, 1.0] {
            let p = FirstOrderParameters::from_rho_inf(rho);
            // Amplification matrix at h lambda -> -infinity (h = 1, rates in units of 1/h).
            let z = -1e9;
            let c0 = first_order_step(&p, z, (1.0, 0.0));
            let c1 = first_order_step(&p, z, (0.0, 1.0));
            let a = nalgebra::Matrix2::new(c0.0, c1.0, c0.1 / z, c1.1 / z);
            let radius = a
                .complex_eigenvalues()
                .iter()
                .map(|e| e.norm())
                .fold(0.0, f64::max);
            assert!((radius - rho).abs() < 1e-6, "rho_inf {rho}: {radius}");
            // Second order: the error at t = 1 of xdot = -x falls by 4 when h halves.
            let error = |n: usize| {
                let h = 1.0 / n as f64;
                let mut s = (1.0, -1.0);
                for _ in 0..n {
                    s = first_order_step(&p, -h, (s.0, s.1 * h));
                    s.1 /= h;
                }
                (s.0 - (-1.0f64).exp()).abs()
            };
            let ratio = error(100) / error(200);
            assert!((ratio - 4.0).abs() < 0.1, "rho_inf {rho}: ratio {ratio}");
        }
    }

    /// Table of benchmarks.md Sect. 7.1 (Chung & Hulbert 1993).
    #[test]
    fn parameters_match_chung_hulbert_table() {
        let cases = [
            (0.0, -1.0, 0.0, 1.0, 1.5),
            (0.5, 0.0, 1.0 / 3.0, 4.0 / 9.0, 5.0 / 6.0),
            (0.6, 0.125, 0.375, 0.390625, 0.75),
            (0.9, 8.0 / 19.0, 9.0 / 19.0, 100.0 / 361.0, 21.0 / 38.0),
            (1.0, 0.5, 0.5, 0.25, 0.5),
        ];
        for (rho, am, af, b, g) in cases {
            let p = GaParameters::from_rho_inf(rho);
            assert!((p.alpha_m - am).abs() < 1e-14);
            assert!((p.alpha_f - af).abs() < 1e-14);
            assert!((p.beta - b).abs() < 1e-14);
            assert!((p.gamma - g).abs() < 1e-14);
        }
    }
}
