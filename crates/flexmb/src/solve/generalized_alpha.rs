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

#[cfg(test)]
mod tests {
    use super::*;

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
