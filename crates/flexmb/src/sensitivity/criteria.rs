//! Criteria: functions of a run's sensor histories, and their derivatives at one point.
//!
//! A criterion is an [`Expression`] of the model's sensors and time `t`, either terminal,
//! `G = f(s_N)` at the last point of the run, or integral, `I = int f dt`, evaluated by the
//! trapezoidal rule on the steps of the run,
//!
//! ```text
//! I = sum_{n=1..N} h_n (f_{n-1} + f_n) / 2,
//! ```
//!
//! which is the quadrature the gradients differentiate: the weight of point `n` is
//! `(h_n + h_{n+1}) / 2` (`h_0 = h_{N+1} = 0`).

use super::expression::Expression;
use super::sensor_derivative::{differentiable, sensor_gradient, SensorGradient};
use crate::data::Layout;
use crate::model::{Model, ParamId, Parameters, SensorKind};
use crate::state::State;

/// Terminal or integral.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CriterionKind {
    /// `f(s_N)` at the end of the run.
    Terminal,
    /// `int f dt` over the run (trapezoidal rule on its steps).
    Integral,
}

/// A criterion of a sensitivity analysis.
#[derive(Clone, Debug, PartialEq)]
pub struct Criterion {
    pub name: String,
    pub kind: CriterionKind,
    /// The expression as written.
    pub text: String,
    pub expression: Expression,
}

/// A reference signal `r(t)`: piecewise-linear in time, constant outside its samples (e.g.
/// read from a CSV file), for criteria such as `sq(z - z_ref)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    pub name: String,
    /// Sample times, increasing.
    pub t: Vec<f64>,
    pub values: Vec<f64>,
}

impl Reference {
    /// `r(t)`.
    pub fn at(&self, t: f64) -> f64 {
        let i = self.t.partition_point(|&x| x <= t);
        if i == 0 {
            self.values[0]
        } else if i == self.t.len() {
            self.values[i - 1]
        } else {
            let (t0, t1) = (self.t[i - 1], self.t[i]);
            let s = (t - t0) / (t1 - t0);
            self.values[i - 1] * (1.0 - s) + self.values[i] * s
        }
    }
}

impl Criterion {
    /// Parses `text` over the sensors of `model` and the `references` (by name). A sensor
    /// that has no derivative (energies, the constraint violation) is refused.
    pub fn new(
        model: &Model,
        references: &[Reference],
        name: &str,
        kind: CriterionKind,
        text: &str,
    ) -> Result<Self, String> {
        let n = model.sensors.len();
        // `t` and `pi` are the built-ins: a sensor of that name cannot be read.
        let words = text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'));
        for word in words.filter(|w| *w == "t" || *w == "pi") {
            if model.sensors.iter().any(|s| s.name == word) {
                return Err(format!(
                    "'{word}' is a built-in of the expressions and also a sensor's name: rename the sensor to use it in a criterion"
                ));
            }
        }
        let resolve = |s: &str| {
            model
                .sensors
                .iter()
                .position(|x| x.name == s)
                .or_else(|| references.iter().position(|r| r.name == s).map(|r| n + r))
        };
        let expression = Expression::parse(text, &resolve).map_err(|e| {
            let mut names: Vec<&str> = model.sensors.iter().map(|s| s.name.as_str()).collect();
            names.extend(references.iter().map(|r| r.name.as_str()));
            if e.message.starts_with("unknown name") {
                format!(
                    "{e} (sensors and references: {}; and t, pi)",
                    names.join(", ")
                )
            } else {
                e.to_string()
            }
        })?;
        for k in expression.variables().into_iter().filter(|&k| k < n) {
            let s = &model.sensors[k];
            if !differentiable(&s.kind) {
                return Err(format!(
                    "sensor '{}' ({}) has no derivative and cannot enter a criterion",
                    s.name,
                    sensor_type(&s.kind)
                ));
            }
        }
        Ok(Self {
            name: name.to_string(),
            kind,
            text: text.to_string(),
            expression,
        })
    }
}

fn sensor_type(kind: &SensorKind) -> &'static str {
    match kind {
        SensorKind::KineticEnergy => "kinetic_energy",
        SensorKind::PotentialEnergy => "potential_energy",
        SensorKind::TotalEnergy => "total_energy",
        _ => "constraint_violation",
    }
}

/// The criteria of an analysis with the sensors and references they read. Their
/// expressions' variables are the model's sensors, then the references.
#[derive(Clone, Debug, PartialEq)]
pub struct CriteriaSet {
    pub criteria: Vec<Criterion>,
    pub references: Vec<Reference>,
    /// Sensors read by any criterion (indices in `Model::sensors`), sorted.
    used: Vec<usize>,
    n_sensors: usize,
}

/// The sensor values of the points of a run (only the used sensors filled; joint angles
/// unwrapped along the run) and the step sizes.
#[derive(Clone, Debug, Default)]
pub struct History {
    pub t: Vec<f64>,
    pub values: Vec<Vec<f64>>,
    /// Last unwrapped angle per sensor.
    last_angle: Vec<Option<f64>>,
    /// Storage reused by [`CriteriaSet::record`] from point to point.
    nodes: Vec<crate::elements::NodeState>,
    buffers: crate::elements::LocalBuffers,
}

impl History {
    /// Step sizes `h_n = t_n - t_{n-1}`, `n = 1..N`.
    pub fn steps(&self) -> Vec<f64> {
        self.t.windows(2).map(|w| w[1] - w[0]).collect()
    }
}

impl CriteriaSet {
    pub fn new(model: &Model, references: Vec<Reference>, criteria: Vec<Criterion>) -> Self {
        let n_sensors = model.sensors.len();
        let mut used: Vec<usize> = criteria
            .iter()
            .flat_map(|c| c.expression.variables())
            .filter(|&k| k < n_sensors)
            .collect();
        used.sort_unstable();
        used.dedup();
        Self {
            criteria,
            references,
            used,
            n_sensors,
        }
    }

    /// Number of expression variables: sensors, then references.
    fn n_variables(&self) -> usize {
        self.n_sensors + self.references.len()
    }

    pub fn len(&self) -> usize {
        self.criteria.len()
    }

    pub fn is_empty(&self) -> bool {
        self.criteria.is_empty()
    }

    /// Records the sensor values of the next point of a run.
    pub fn record(&self, model: &Model, layout: &Layout, state: &State, history: &mut History) {
        history.last_angle.resize(self.n_sensors, None);
        crate::sensors::node_states_into(state, &mut history.nodes);
        let (nodes, buffers) = (&history.nodes, &mut history.buffers);
        let mut values = vec![0.0; self.n_variables()];
        for (r, reference) in self.references.iter().enumerate() {
            values[self.n_sensors + r] = reference.at(state.t);
        }
        for &k in &self.used {
            let mut v = crate::sensors::sensor_value(model, layout, k, nodes, state, buffers);
            if let SensorKind::JointCoordinate { joint } = model.sensors[k].kind {
                if crate::joints::coordinate_is_angle(&model.joints[joint.0]) {
                    let last = history.last_angle[k];
                    v = last.map_or(v, |l| crate::sensors::unwrap(v, l));
                    history.last_angle[k] = Some(v);
                }
            }
            values[k] = v;
        }
        history.t.push(state.t);
        history.values.push(values);
    }

    /// The criteria's values for a recorded run.
    pub fn values(&self, history: &History) -> Vec<f64> {
        let hs = history.steps();
        let n_points = history.t.len();
        self.criteria
            .iter()
            .map(|c| {
                (0..n_points)
                    .map(|n| {
                        let w = weight(c.kind, n, &hs);
                        if w == 0.0 {
                            0.0
                        } else {
                            w * c.expression.eval(&history.values[n], history.t[n])
                        }
                    })
                    .sum()
            })
            .collect()
    }

    /// The derivatives at point `n` of a recorded run whose state is `state`: for each
    /// criterion `c` with weight `weights[c]` at the point, `weights[c] df_c/dsensor`
    /// combined with the sensors' derivatives, returned as one list of
    /// `(sensor gradient, coefficient per criterion)`.
    pub fn point_gradients(
        &self,
        model: &Model,
        layout: &Layout,
        state: &State,
        values: &[f64],
        weights: &[f64],
        params: (&Parameters, &[ParamId], &mut Model),
    ) -> Vec<(SensorGradient, Vec<f64>)> {
        let mut per_sensor = vec![vec![0.0; self.criteria.len()]; self.n_sensors];
        let mut g = vec![0.0; self.n_variables()];
        for (c, crit) in self.criteria.iter().enumerate() {
            if weights[c] == 0.0 {
                continue;
            }
            g.iter_mut().for_each(|x| *x = 0.0);
            crit.expression
                .eval_gradient(values, state.t, weights[c], &mut g);
            for &k in &self.used {
                per_sensor[k][c] = g[k];
            }
        }
        let (params, wanted, scratch) = params;
        self.used
            .iter()
            .filter(|&&k| per_sensor[k].iter().any(|&x| x != 0.0))
            .map(|&k| {
                let grad = sensor_gradient(
                    model,
                    layout,
                    k,
                    state,
                    Some((params, wanted, &mut *scratch)),
                );
                (grad, per_sensor[k].clone())
            })
            .collect()
    }
}

/// The weight of point `n` (0..=N) of a run with step sizes `hs` (`h_1..h_N`) in a
/// criterion of `kind`.
pub fn weight(kind: CriterionKind, n: usize, hs: &[f64]) -> f64 {
    let last = hs.len();
    match kind {
        CriterionKind::Terminal => {
            if n == last {
                1.0
            } else {
                0.0
            }
        }
        CriterionKind::Integral => {
            let before = if n > 0 { hs[n - 1] } else { 0.0 };
            let after = if n < last { hs[n] } else { 0.0 };
            0.5 * (before + after)
        }
    }
}
