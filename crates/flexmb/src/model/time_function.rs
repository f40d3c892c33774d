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
