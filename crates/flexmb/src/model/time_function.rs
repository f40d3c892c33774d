//! Scalar functions of time that scale loads and drive joints.
//!
//! Every function returns its value and its first two time derivatives, which the consistent
//! initial accelerations of driven joints need (`Phi_t`, `Phi_tt`).

use std::f64::consts::PI;

/// A scalar function of time `f(t)`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TimeFunction {
    /// `f = value`.
    Constant { value: f64 },
    /// `f = offset + slope (t - start)` for `t >= start`, `offset` before.
    Linear { slope: f64, start: f64, offset: f64 },
    /// Ramp from 0 at `t0` to `value` at `t1`, constant after.
    Ramp { t0: f64, t1: f64, value: f64 },
    /// 0 before `t0`, `value` from `t0` on.
    Step { t0: f64, value: f64 },
    /// `f = offset + amplitude sin(2 pi frequency t + phase)`.
    Sine {
        amplitude: f64,
        frequency: f64,
        phase: f64,
        offset: f64,
    },
    /// Linear chirp: `f = offset + amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 duration)))`,
    /// the frequency sweeping from `f0` at `t = 0` to `f1` at `duration` (and on at the same
    /// rate after it).
    Chirp {
        amplitude: f64,
        f0: f64,
        f1: f64,
        duration: f64,
        offset: f64,
    },
    /// Piecewise-linear interpolation of `(t, f)` points, constant outside.
    Table { points: Vec<(f64, f64)> },
    /// Smooth spin-up of a hub (Simo & Vu-Quoc 1986; Kane, Ryan & Banerjee 1987):
    /// `f = (w/T)(t^2/2 + (T/2pi)^2 (cos(2 pi t/T) - 1))` for `t < T`, `w (t - T/2)` after.
    SpinUp { omega: f64, duration: f64 },
    /// Raised-cosine bump: `f = height (1 - cos(2 pi (t - start)/duration))/2` for
    /// `start <= t <= start + duration`, 0 outside. `f` and `f'` are continuous; `f''` jumps
    /// between 0 and `height (2 pi/duration)^2/2` at both ends (the closed interval takes the
    /// bump's value).
    Bump {
        height: f64,
        start: f64,
        duration: f64,
    },
    /// `f = value s((t - start)/duration)` with the quintic `s(x) = 6x^5 - 15x^4 + 10x^3` on
    /// `[0, 1]`, 0 before, `value` after: `f`, `f'` and `f''` are continuous.
    SmoothStep {
        value: f64,
        start: f64,
        duration: f64,
    },
    /// `f(t) = g(t - delay)`.
    Delay {
        delay: f64,
        function: Box<TimeFunction>,
    },
    /// `f(t) = g(t)` for `start <= t <= end`, 0 outside.
    Window {
        start: f64,
        end: f64,
        function: Box<TimeFunction>,
    },
    /// `f = g_0 + g_1 + ...`.
    Sum { functions: Vec<TimeFunction> },
    /// `f = factor g`.
    Scaled {
        factor: f64,
        function: Box<TimeFunction>,
    },
}

impl TimeFunction {
    /// `(f, f', f'')` at time `t`.
    pub fn eval(&self, t: f64) -> (f64, f64, f64) {
        match self {
            TimeFunction::Constant { value } => (*value, 0.0, 0.0),
            TimeFunction::Linear {
                slope,
                start,
                offset,
            } => {
                if t < *start {
                    (*offset, 0.0, 0.0)
                } else {
                    (offset + slope * (t - start), *slope, 0.0)
                }
            }
            TimeFunction::Ramp { t0, t1, value } => {
                if t <= *t0 {
                    (0.0, 0.0, 0.0)
                } else if t >= *t1 {
                    (*value, 0.0, 0.0)
                } else {
                    let s = value / (t1 - t0);
                    (s * (t - t0), s, 0.0)
                }
            }
            TimeFunction::Step { t0, value } => {
                if t < *t0 {
                    (0.0, 0.0, 0.0)
                } else {
                    (*value, 0.0, 0.0)
                }
            }
            TimeFunction::Sine {
                amplitude,
                frequency,
                phase,
                offset,
            } => {
                let w = 2.0 * PI * frequency;
                let (s, c) = (w * t + phase).sin_cos();
                (
                    offset + amplitude * s,
                    amplitude * w * c,
                    -amplitude * w * w * s,
                )
            }
            TimeFunction::Chirp {
                amplitude,
                f0,
                f1,
                duration,
                offset,
            } => {
                // phase 2 pi (f0 t + r t^2 / 2), r the sweep rate
                let r = (f1 - f0) / duration;
                let phi = 2.0 * PI * (f0 * t + 0.5 * r * t * t);
                let (dphi, ddphi) = (2.0 * PI * (f0 + r * t), 2.0 * PI * r);
                let (s, c) = phi.sin_cos();
                (
                    offset + amplitude * s,
                    amplitude * c * dphi,
                    amplitude * (ddphi * c - dphi * dphi * s),
                )
            }
            TimeFunction::Table { points } => table(points, t),
            TimeFunction::SpinUp { omega, duration } => {
                let (w, tt) = (*omega, *duration);
                if t < tt {
                    let k = 2.0 * PI / tt;
                    let (s, c) = (k * t).sin_cos();
                    (
                        w / tt * (0.5 * t * t + (c - 1.0) / (k * k)),
                        w / tt * (t - s / k),
                        w / tt * (1.0 - c),
                    )
                } else {
                    (w * (t - 0.5 * tt), w, 0.0)
                }
            }
            TimeFunction::Bump {
                height,
                start,
                duration,
            } => {
                let x = (t - start) / duration;
                if (0.0..=1.0).contains(&x) {
                    let k = 2.0 * PI / duration;
                    let (s, c) = (2.0 * PI * x).sin_cos();
                    let h = 0.5 * height;
                    (h * (1.0 - c), h * k * s, h * k * k * c)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
            TimeFunction::SmoothStep {
                value,
                start,
                duration,
            } => {
                let x = (t - start) / duration;
                if x <= 0.0 {
                    (0.0, 0.0, 0.0)
                } else if x >= 1.0 {
                    (*value, 0.0, 0.0)
                } else {
                    let s = x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
                    let ds = 30.0 * x * x * (1.0 - x) * (1.0 - x);
                    let dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x);
                    (
                        value * s,
                        value * ds / duration,
                        value * dds / (duration * duration),
                    )
                }
            }
            TimeFunction::Delay { delay, function } => function.eval(t - delay),
            TimeFunction::Window {
                start,
                end,
                function,
            } => {
                if *start <= t && t <= *end {
                    function.eval(t)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
            TimeFunction::Sum { functions } => functions.iter().fold((0.0, 0.0, 0.0), |a, g| {
                let b = g.eval(t);
                (a.0 + b.0, a.1 + b.1, a.2 + b.2)
            }),
            TimeFunction::Scaled { factor, function } => {
                let (f, d1, d2) = function.eval(t);
                (factor * f, factor * d1, factor * d2)
            }
        }
    }

    /// `f(t)`.
    pub fn value(&self, t: f64) -> f64 {
        self.eval(t).0
    }

    /// The coefficients `f` is linear in (its amplitudes), by their key in the model file:
    /// `value` (constant, ramp, step, smooth step), `slope` and `offset` (linear), `amplitude`
    /// and `offset` (sine), `points.<i>.1` (the value of table point `i`), `omega` (spin-up),
    /// `height` (bump); a function of functions has the keys of its functions after their
    /// field, `function.<key>` (delay, window, scaled, after `factor` for scaled) and
    /// `functions.<i>.<key>` (sum). A key is the dotted path of the field in the function's
    /// table of the model file (what `--set` and [`super::Parameters`] take after the
    /// function's own path). `f`, `f'` and `f''` are linear in each amplitude, and jointly in
    /// all of them except that the `factor` of a scaled function multiplies the amplitudes of
    /// its function (see [`TimeFunction::amplitude_derivative`]); the other fields (times,
    /// frequency, phase, delay) are not amplitudes.
    pub fn amplitude_keys(&self) -> Vec<String> {
        let inner = |prefix: &str, g: &TimeFunction| -> Vec<String> {
            let keys = g.amplitude_keys().into_iter();
            keys.map(|k| format!("{prefix}.{k}")).collect()
        };
        match self {
            TimeFunction::Constant { .. }
            | TimeFunction::Ramp { .. }
            | TimeFunction::Step { .. }
            | TimeFunction::SmoothStep { .. } => vec!["value".into()],
            TimeFunction::Linear { .. } => vec!["slope".into(), "offset".into()],
            TimeFunction::Sine { .. } | TimeFunction::Chirp { .. } => {
                vec!["amplitude".into(), "offset".into()]
            }
            TimeFunction::Table { points } => {
                (0..points.len()).map(|i| format!("points.{i}.1")).collect()
            }
            TimeFunction::SpinUp { .. } => vec!["omega".into()],
            TimeFunction::Bump { .. } => vec!["height".into()],
            TimeFunction::Delay { function, .. } | TimeFunction::Window { function, .. } => {
                inner("function", function)
            }
            TimeFunction::Sum { functions } => functions
                .iter()
                .enumerate()
                .flat_map(|(i, g)| inner(&format!("functions.{i}"), g))
                .collect(),
            TimeFunction::Scaled { function, .. } => std::iter::once("factor".to_string())
                .chain(inner("function", function))
                .collect(),
        }
    }

    /// Number of amplitudes (the length of [`TimeFunction::amplitude_keys`]).
    pub fn amplitude_count(&self) -> usize {
        match self {
            TimeFunction::Table { points } => points.len(),
            TimeFunction::Linear { .. }
            | TimeFunction::Sine { .. }
            | TimeFunction::Chirp { .. } => 2,
            TimeFunction::Delay { function, .. } | TimeFunction::Window { function, .. } => {
                function.amplitude_count()
            }
            TimeFunction::Sum { functions } => functions.iter().map(Self::amplitude_count).sum(),
            TimeFunction::Scaled { function, .. } => 1 + function.amplitude_count(),
            TimeFunction::Constant { .. }
            | TimeFunction::Ramp { .. }
            | TimeFunction::Step { .. }
            | TimeFunction::SpinUp { .. }
            | TimeFunction::Bump { .. }
            | TimeFunction::SmoothStep { .. } => 1,
        }
    }

    /// The term of a sum that holds amplitude `k` of the sum, and its index in that term.
    fn term_of(functions: &[TimeFunction], mut k: usize) -> (&TimeFunction, usize) {
        for g in functions {
            let n = g.amplitude_count();
            if k < n {
                return (g, k);
            }
            k -= n;
        }
        panic!("amplitude index out of range")
    }

    /// The amplitudes in the order of [`TimeFunction::amplitude_keys`], mutably.
    fn amplitudes_mut(&mut self) -> Vec<&mut f64> {
        match self {
            TimeFunction::Constant { value }
            | TimeFunction::Ramp { value, .. }
            | TimeFunction::Step { value, .. }
            | TimeFunction::SmoothStep { value, .. } => vec![value],
            TimeFunction::Linear { slope, offset, .. } => vec![slope, offset],
            TimeFunction::Sine {
                amplitude, offset, ..
            }
            | TimeFunction::Chirp {
                amplitude, offset, ..
            } => vec![amplitude, offset],
            TimeFunction::Table { points } => points.iter_mut().map(|p| &mut p.1).collect(),
            TimeFunction::SpinUp { omega, .. } => vec![omega],
            TimeFunction::Bump { height, .. } => vec![height],
            TimeFunction::Delay { function, .. } | TimeFunction::Window { function, .. } => {
                function.amplitudes_mut()
            }
            TimeFunction::Sum { functions } => functions
                .iter_mut()
                .flat_map(TimeFunction::amplitudes_mut)
                .collect(),
            TimeFunction::Scaled { factor, function } => {
                let mut all = vec![factor];
                all.extend(function.amplitudes_mut());
                all
            }
        }
    }

    /// Amplitude `k` (see [`TimeFunction::amplitude_keys`]).
    pub fn amplitude(&self, k: usize) -> f64 {
        match self {
            TimeFunction::Constant { value }
            | TimeFunction::Ramp { value, .. }
            | TimeFunction::Step { value, .. }
            | TimeFunction::SmoothStep { value, .. } => [*value][k],
            TimeFunction::Linear { slope, offset, .. } => [*slope, *offset][k],
            TimeFunction::Sine {
                amplitude, offset, ..
            }
            | TimeFunction::Chirp {
                amplitude, offset, ..
            } => [*amplitude, *offset][k],
            TimeFunction::Table { points } => points[k].1,
            TimeFunction::SpinUp { omega, .. } => [*omega][k],
            TimeFunction::Bump { height, .. } => [*height][k],
            TimeFunction::Delay { function, .. } | TimeFunction::Window { function, .. } => {
                function.amplitude(k)
            }
            TimeFunction::Sum { functions } => {
                let (g, k) = Self::term_of(functions, k);
                g.amplitude(k)
            }
            TimeFunction::Scaled { factor, function } => match k {
                0 => *factor,
                _ => function.amplitude(k - 1),
            },
        }
    }

    /// Sets amplitude `k` (see [`TimeFunction::amplitude_keys`]).
    pub fn set_amplitude(&mut self, k: usize, value: f64) {
        *self.amplitudes_mut()[k] = value;
    }

    /// `(df, df', df'')/da_k` at time `t`, the other amplitudes fixed. A function of time
    /// alone is linear in its amplitudes: the derivative is the function with amplitude `k`
    /// set to 1 and the others to 0. Delay, window and sum pass it on to the function that
    /// holds the amplitude (sum: the other terms do not depend on it). Scaled, `factor g`, is
    /// linear in `factor` and in the amplitudes of `g` separately, not jointly: the
    /// derivative is `g` for `factor` and `factor dg/da` for an amplitude `a` of `g`.
    pub fn amplitude_derivative(&self, k: usize, t: f64) -> (f64, f64, f64) {
        match self {
            TimeFunction::Delay { delay, function } => function.amplitude_derivative(k, t - delay),
            TimeFunction::Window {
                start,
                end,
                function,
            } => {
                if *start <= t && t <= *end {
                    function.amplitude_derivative(k, t)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
            TimeFunction::Sum { functions } => {
                let (g, k) = Self::term_of(functions, k);
                g.amplitude_derivative(k, t)
            }
            TimeFunction::Scaled { factor, function } => match k {
                0 => function.eval(t),
                _ => {
                    let (d0, d1, d2) = function.amplitude_derivative(k - 1, t);
                    (factor * d0, factor * d1, factor * d2)
                }
            },
            _ => {
                let mut unit = self.clone();
                for (i, a) in unit.amplitudes_mut().into_iter().enumerate() {
                    *a = if i == k { 1.0 } else { 0.0 };
                }
                unit.eval(t)
            }
        }
    }

    /// Whether functions are nested more than `max` levels deep, counting this one (a
    /// `delay` of a `bump` has 2 levels); looks no deeper than `max + 1` levels.
    pub fn deeper_than(&self, max: usize) -> bool {
        if max == 0 {
            return true;
        }
        match self {
            TimeFunction::Delay { function, .. }
            | TimeFunction::Window { function, .. }
            | TimeFunction::Scaled { function, .. } => function.deeper_than(max - 1),
            TimeFunction::Sum { functions } => functions.iter().any(|g| g.deeper_than(max - 1)),
            _ => false,
        }
    }
}

fn table(points: &[(f64, f64)], t: f64) -> (f64, f64, f64) {
    match points {
        [] => (0.0, 0.0, 0.0),
        [p] => (p.1, 0.0, 0.0),
        _ => {
            if t <= points[0].0 {
                return (points[0].1, 0.0, 0.0);
            }
            let last = points[points.len() - 1];
            if t >= last.0 {
                return (last.1, 0.0, 0.0);
            }
            let i = points.partition_point(|p| p.0 <= t) - 1;
            let (a, b) = (points[i], points[i + 1]);
            let slope = (b.1 - a.1) / (b.0 - a.0);
            (a.1 + slope * (t - a.0), slope, 0.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_derivatives(f: &TimeFunction, ts: &[f64]) {
        let e = 1e-6;
        for &t in ts {
            let (_, d1, d2) = f.eval(t);
            let fd1 = (f.value(t + e) - f.value(t - e)) / (2.0 * e);
            let fd2 = (f.eval(t + e).1 - f.eval(t - e).1) / (2.0 * e);
            assert!((d1 - fd1).abs() < 1e-6 * (1.0 + d1.abs()), "{f:?} at {t}");
            assert!((d2 - fd2).abs() < 1e-5 * (1.0 + d2.abs()), "{f:?} at {t}");
        }
    }

    #[test]
    fn time_function_derivatives_match_differences() {
        check_derivatives(
            &TimeFunction::Sine {
                amplitude: 2.0,
                frequency: 0.7,
                phase: 0.3,
                offset: 1.0,
            },
            &[0.0, 0.4, 2.1],
        );
        check_derivatives(
            &TimeFunction::SpinUp {
                omega: 6.0,
                duration: 15.0,
            },
            &[0.5, 7.0, 14.0, 20.0],
        );
        check_derivatives(
            &TimeFunction::Linear {
                slope: 0.6,
                start: 0.0,
                offset: 0.0,
            },
            &[0.5, 3.0],
        );
        check_derivatives(
            &TimeFunction::Chirp {
                amplitude: 0.5,
                f0: 0.5,
                f1: 4.0,
                duration: 2.0,
                offset: 0.1,
            },
            &[0.0, 0.7, 1.9, 3.0],
        );
    }

    #[test]
    fn amplitude_derivatives_match_differences() {
        let functions = [
            TimeFunction::Constant { value: 2.0 },
            TimeFunction::Linear {
                slope: 0.6,
                start: 0.2,
                offset: -1.0,
            },
            TimeFunction::Ramp {
                t0: 0.1,
                t1: 2.0,
                value: 3.0,
            },
            TimeFunction::Step {
                t0: 0.5,
                value: 4.0,
            },
            TimeFunction::Sine {
                amplitude: 2.0,
                frequency: 0.7,
                phase: 0.3,
                offset: 1.0,
            },
            TimeFunction::Table {
                points: vec![(0.0, 1.0), (1.0, 5.0), (2.0, -1.0)],
            },
            TimeFunction::Chirp {
                amplitude: 0.5,
                f0: 0.5,
                f1: 4.0,
                duration: 2.0,
                offset: 0.1,
            },
            TimeFunction::SpinUp {
                omega: 6.0,
                duration: 1.5,
            },
            TimeFunction::Bump {
                height: 0.05,
                start: 0.5,
                duration: 1.0,
            },
            TimeFunction::SmoothStep {
                value: 2.0,
                start: 0.5,
                duration: 1.0,
            },
            TimeFunction::Delay {
                delay: 0.3,
                function: Box::new(TimeFunction::Bump {
                    height: 0.05,
                    start: 0.5,
                    duration: 1.0,
                }),
            },
            // Scaled nested in scaled: the product of factors, not jointly linear.
            TimeFunction::Scaled {
                factor: 2.5,
                function: Box::new(TimeFunction::Scaled {
                    factor: -0.7,
                    function: Box::new(TimeFunction::Sine {
                        amplitude: 2.0,
                        frequency: 0.7,
                        phase: 0.3,
                        offset: 1.0,
                    }),
                }),
            },
            nested(),
        ];
        for f in functions {
            let keys = f.amplitude_keys();
            for k in 0..keys.len() {
                for t in [0.05, 0.8, 1.3, 2.5] {
                    let a = f.amplitude(k);
                    let e = 1e-6 * (1.0 + a.abs());
                    let at = |v: f64| {
                        let mut g = f.clone();
                        g.set_amplitude(k, v);
                        g.eval(t)
                    };
                    let (p, m) = (at(a + e), at(a - e));
                    let d = f.amplitude_derivative(k, t);
                    let fd = [(p.0 - m.0), (p.1 - m.1), (p.2 - m.2)].map(|x| x / (2.0 * e));
                    for (i, (x, y)) in [d.0, d.1, d.2].iter().zip(fd).enumerate() {
                        assert!(
                            (x - y).abs() < 1e-7 * (1.0 + y.abs()),
                            "{f:?}, {}: derivative {i} at {t}: {x} vs {y}",
                            keys[k]
                        );
                    }
                }
            }
        }
    }

    fn bump() -> TimeFunction {
        TimeFunction::Bump {
            height: 0.05,
            start: 0.2,
            duration: 0.4,
        }
    }

    /// `factor (g_0 + g_1 + g_2)` with a delayed bump, a windowed sine and a scaled smooth
    /// step: every new type, nested.
    fn nested() -> TimeFunction {
        TimeFunction::Scaled {
            factor: 1.5,
            function: Box::new(TimeFunction::Sum {
                functions: vec![
                    TimeFunction::Delay {
                        delay: 0.3,
                        function: Box::new(bump()),
                    },
                    TimeFunction::Window {
                        start: 0.1,
                        end: 2.0,
                        function: Box::new(TimeFunction::Sine {
                            amplitude: 2.0,
                            frequency: 0.7,
                            phase: 0.3,
                            offset: 1.0,
                        }),
                    },
                    TimeFunction::Scaled {
                        factor: -3.0,
                        function: Box::new(TimeFunction::SmoothStep {
                            value: 0.8,
                            start: 0.5,
                            duration: 1.2,
                        }),
                    },
                ],
            }),
        }
    }

    #[test]
    fn new_function_derivatives_match_differences() {
        // Interior points: away (by more than the difference step) from the ends of the bump,
        // the window and the step, where f'' (bump) or f (window) jumps.
        check_derivatives(&bump(), &[0.0, 0.25, 0.35, 0.4, 0.55, 0.7]);
        let step = TimeFunction::SmoothStep {
            value: 0.8,
            start: 0.5,
            duration: 1.2,
        };
        // C2: also across both ends.
        check_derivatives(&step, &[0.0, 0.5, 0.6, 1.1, 1.6, 1.7, 2.5]);
        let delayed = TimeFunction::Delay {
            delay: 0.3,
            function: Box::new(bump()),
        };
        check_derivatives(&delayed, &[0.1, 0.55, 0.65, 0.8, 1.2]);
        for t in [0.1, 0.55, 0.65, 0.8, 1.2] {
            assert_eq!(delayed.eval(t), bump().eval(t - 0.3));
        }
        check_derivatives(&nested(), &[0.05, 0.3, 0.7, 0.95, 1.3, 1.9, 2.1, 3.0]);
        // The nested function is the formula written out.
        let sine = |t: f64| {
            let w = 2.0 * PI * 0.7;
            let (s, c) = (w * t + 0.3).sin_cos();
            (1.0 + 2.0 * s, 2.0 * w * c, -2.0 * w * w * s)
        };
        for t in [0.05, 0.3, 0.7, 0.9, 1.3, 1.9, 2.0, 2.1, 3.0] {
            let b = bump().eval(t - 0.3);
            let w = if (0.1..=2.0).contains(&t) {
                sine(t)
            } else {
                (0.0, 0.0, 0.0)
            };
            let st = step.eval(t);
            let expect = [
                1.5 * (b.0 + w.0 - 3.0 * st.0),
                1.5 * (b.1 + w.1 - 3.0 * st.1),
                1.5 * (b.2 + w.2 - 3.0 * st.2),
            ];
            let got = nested().eval(t);
            for (x, y) in [got.0, got.1, got.2].iter().zip(expect) {
                assert!(
                    (x - y).abs() <= 1e-12 * (1.0 + y.abs()),
                    "at {t}: {x} vs {y}"
                );
            }
        }
    }

    #[test]
    fn bump_values_at_its_ends_and_peak() {
        let f = bump();
        let k = 2.0 * PI / 0.4;
        let jump = 0.5 * 0.05 * k * k;
        // Outside: 0.
        assert_eq!(f.eval(0.1), (0.0, 0.0, 0.0));
        assert_eq!(f.eval(0.6 + 1e-9), (0.0, 0.0, 0.0));
        // Start: f and f' are 0, f'' takes the bump's value.
        let (f0, d0, dd0) = f.eval(0.2);
        assert_eq!((f0, d0), (0.0, 0.0));
        assert!((dd0 - jump).abs() < 1e-12 * jump);
        // Peak: exactly the height, f' = 0, f'' = -height (2 pi/duration)^2/2.
        let (fp, dp, ddp) = f.eval(0.4);
        assert_eq!(fp, 0.05);
        assert!(dp.abs() < 1e-14);
        assert!((ddp + jump).abs() < 1e-12 * jump);
        // End: back to 0 with zero slope; f'' jumps from `jump` to 0.
        let (fe, de, dde) = f.eval(0.6);
        assert!(fe.abs() < 1e-15 && de.abs() < 1e-12);
        assert!((dde - jump).abs() < 1e-9 * jump);
        // Quarter points: half the height, the largest slope.
        let (fq, dq, _) = f.eval(0.3);
        assert!((fq - 0.025).abs() < 1e-15);
        assert!((dq - 0.5 * 0.05 * k).abs() < 1e-12);
        // C1 across the ends.
        for t in [0.2, 0.6] {
            let (a, b) = (f.eval(t - 1e-9), f.eval(t + 1e-9));
            assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-6);
        }
    }

    #[test]
    fn smooth_step_and_window_values() {
        let f = TimeFunction::SmoothStep {
            value: 0.8,
            start: 0.5,
            duration: 1.2,
        };
        assert_eq!(f.eval(0.5), (0.0, 0.0, 0.0));
        assert_eq!(f.eval(1.7), (0.8, 0.0, 0.0));
        assert_eq!(f.eval(9.0), (0.8, 0.0, 0.0));
        let (m, dm, ddm) = f.eval(1.1);
        assert!((m - 0.4).abs() < 1e-15);
        assert!((dm - 0.8 * 1.875 / 1.2).abs() < 1e-14);
        assert!(ddm.abs() < 1e-14);
        // C2 across both ends.
        for t in [0.5, 1.7] {
            let (a, b) = (f.eval(t - 1e-7), f.eval(t + 1e-7));
            assert!((a.0 - b.0).abs() < 1e-12);
            assert!((a.1 - b.1).abs() < 1e-9 && (a.2 - b.2).abs() < 1e-5);
        }
        let w = TimeFunction::Window {
            start: 1.0,
            end: 2.0,
            function: Box::new(TimeFunction::Linear {
                slope: 2.0,
                start: 0.0,
                offset: 1.0,
            }),
        };
        assert_eq!(w.eval(0.999), (0.0, 0.0, 0.0));
        assert_eq!(w.eval(1.0), (3.0, 2.0, 0.0));
        assert_eq!(w.eval(2.0), (5.0, 2.0, 0.0));
        assert_eq!(w.eval(2.001), (0.0, 0.0, 0.0));
    }

    #[test]
    fn nested_amplitude_keys_values_and_setters_agree() {
        let f = nested();
        let keys = f.amplitude_keys();
        assert_eq!(
            keys,
            [
                "factor",
                "function.functions.0.function.height",
                "function.functions.1.function.amplitude",
                "function.functions.1.function.offset",
                "function.functions.2.factor",
                "function.functions.2.function.value",
            ]
        );
        assert_eq!(f.amplitude_count(), keys.len());
        let values: Vec<f64> = (0..keys.len()).map(|k| f.amplitude(k)).collect();
        assert_eq!(values, [1.5, 0.05, 2.0, 1.0, -3.0, 0.8]);
        for k in 0..keys.len() {
            let mut g = f.clone();
            g.set_amplitude(k, 7.0 + k as f64);
            for j in 0..keys.len() {
                let want = if j == k { 7.0 + k as f64 } else { values[j] };
                assert_eq!(g.amplitude(j), want, "set {}, read {}", keys[k], keys[j]);
            }
        }
        let delayed = TimeFunction::Delay {
            delay: 0.3,
            function: Box::new(bump()),
        };
        assert_eq!(delayed.amplitude_keys(), ["function.height"]);
        // Checkpoints: the nested function survives a round trip through JSON.
        let text = serde_json::to_string(&f).unwrap();
        assert_eq!(serde_json::from_str::<TimeFunction>(&text).unwrap(), f);
    }

    #[test]
    fn nesting_depth_is_counted_from_the_outermost_function() {
        let mut f = bump();
        assert!(!f.deeper_than(1) && f.deeper_than(0));
        for level in 2..=9 {
            f = TimeFunction::Delay {
                delay: 0.1,
                function: Box::new(f),
            };
            assert!(!f.deeper_than(level) && f.deeper_than(level - 1), "{level}");
        }
        let sum = TimeFunction::Sum {
            functions: vec![bump(), f],
        };
        assert!(!sum.deeper_than(10) && sum.deeper_than(9));
    }

    #[test]
    fn spin_up_is_continuous_at_the_end_of_the_manoeuvre() {
        let f = TimeFunction::SpinUp {
            omega: 6.0,
            duration: 15.0,
        };
        let (a, b) = (f.eval(15.0 - 1e-9), f.eval(15.0 + 1e-9));
        assert!((a.0 - b.0).abs() < 1e-7 && (a.1 - b.1).abs() < 1e-7);
        assert!((b.0 - 6.0 * 7.5).abs() < 1e-7);
    }

    #[test]
    fn table_interpolates_and_clamps() {
        let f = TimeFunction::Table {
            points: vec![(0.0, 0.0), (1.0, 50.0), (2.0, 0.0)],
        };
        assert_eq!(f.value(-1.0), 0.0);
        assert!((f.value(0.5) - 25.0).abs() < 1e-12);
        assert!((f.value(1.5) - 25.0).abs() < 1e-12);
        assert_eq!(f.value(3.0), 0.0);
        assert_eq!(f.eval(1.5).1, -50.0);
    }
}
