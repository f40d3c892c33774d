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
    /// Piecewise-linear interpolation of `(t, f)` points, constant outside.
    Table { points: Vec<(f64, f64)> },
    /// Smooth spin-up of a hub (Simo & Vu-Quoc 1986; Kane, Ryan & Banerjee 1987):
    /// `f = (w/T)(t^2/2 + (T/2pi)^2 (cos(2 pi t/T) - 1))` for `t < T`, `w (t - T/2)` after.
    SpinUp { omega: f64, duration: f64 },
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
        }
    }

    /// `f(t)`.
    pub fn value(&self, t: f64) -> f64 {
        self.eval(t).0
    }

    /// The coefficients `f` is linear in (its amplitudes), by their key in the model file:
    /// `value` (constant, ramp, step), `slope` and `offset` (linear), `amplitude` and `offset`
    /// (sine), `points.<i>.1` (the value of table point `i`), `omega` (spin-up). `f`, `f'`
    /// and `f''` are linear in them jointly; the other fields (times, frequency, phase) are
    /// not amplitudes.
    pub fn amplitude_keys(&self) -> Vec<String> {
        match self {
            TimeFunction::Constant { .. }
            | TimeFunction::Ramp { .. }
            | TimeFunction::Step { .. } => vec!["value".into()],
            TimeFunction::Linear { .. } => vec!["slope".into(), "offset".into()],
            TimeFunction::Sine { .. } => vec!["amplitude".into(), "offset".into()],
            TimeFunction::Table { points } => {
                (0..points.len()).map(|i| format!("points.{i}.1")).collect()
            }
            TimeFunction::SpinUp { .. } => vec!["omega".into()],
        }
    }

    /// The amplitudes in the order of [`TimeFunction::amplitude_keys`], mutably.
    fn amplitudes_mut(&mut self) -> Vec<&mut f64> {
        match self {
            TimeFunction::Constant { value }
            | TimeFunction::Ramp { value, .. }
            | TimeFunction::Step { value, .. } => vec![value],
            TimeFunction::Linear { slope, offset, .. } => vec![slope, offset],
            TimeFunction::Sine {
                amplitude, offset, ..
            } => vec![amplitude, offset],
            TimeFunction::Table { points } => points.iter_mut().map(|p| &mut p.1).collect(),
            TimeFunction::SpinUp { omega, .. } => vec![omega],
        }
    }

    /// Amplitude `k` (see [`TimeFunction::amplitude_keys`]).
    pub fn amplitude(&self, k: usize) -> f64 {
        match self {
            TimeFunction::Constant { value }
            | TimeFunction::Ramp { value, .. }
            | TimeFunction::Step { value, .. } => [*value][k],
            TimeFunction::Linear { slope, offset, .. } => [*slope, *offset][k],
            TimeFunction::Sine {
                amplitude, offset, ..
            } => [*amplitude, *offset][k],
            TimeFunction::Table { points } => points[k].1,
            TimeFunction::SpinUp { omega, .. } => [*omega][k],
        }
    }

    /// Sets amplitude `k` (see [`TimeFunction::amplitude_keys`]).
    pub fn set_amplitude(&mut self, k: usize, value: f64) {
        *self.amplitudes_mut()[k] = value;
    }

    /// `(df, df', df'')/da_k` at time `t`: since `f` is linear in its amplitudes, the function
    /// itself with amplitude `k` set to 1 and the others to 0.
    pub fn amplitude_derivative(&self, k: usize, t: f64) -> (f64, f64, f64) {
        let mut unit = self.clone();
        for (i, a) in unit.amplitudes_mut().into_iter().enumerate() {
            *a = if i == k { 1.0 } else { 0.0 };
        }
        unit.eval(t)
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
            TimeFunction::SpinUp {
                omega: 6.0,
                duration: 1.5,
            },
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
