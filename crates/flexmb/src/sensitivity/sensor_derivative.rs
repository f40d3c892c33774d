//! Derivatives of sensor values with respect to the state and the parameters.
//!
//! A sensor reads a few entries of the state: the configuration, velocity and acceleration
//! of one node (node sensors), of a joint's two nodes and its multipliers (joint sensors),
//! of an element's nodes and states (spring and rope forces, beam strains and stresses). Its
//! derivative is taken along each of these entries (configurations moved on the group,
//! `q exp(e_k eps)`), and along the parameters of its own item that enter it at a fixed
//! state (joint positions for joint sensors, spring, rope and section parameters for force
//! and stress sensors), by the fourth-order central difference
//!
//! ```text
//! f' = (8 (f(eps) - f(-eps)) - (f(2 eps) - f(-2 eps))) / (12 eps)
//! ```
//!
//! with `eps = 1e-4` times the entry's scale: truncation `O(eps^4)`, below round-off, and
//! exact for the entries a sensor depends on linearly or quadratically (velocities,
//! accelerations, multipliers, states). Energies and the constraint violation are not
//! differentiable sensors here (a criterion cannot use them).

use crate::data::Layout;
use crate::elements::rotational_spring::RotationalSpringElement;
use crate::elements::{ElementItem, ElementKernel, LocalBuffers, NodeState};
use crate::model::{Model, ParamId, ParamKind, Parameters, SensorKind};
use crate::solve::step::StateTangent;
use crate::state::State;

/// One entry of a state (see [`StateTangent`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Entry {
    /// Component `k % 6` of node `k / 6`: configuration (on the group), velocity,
    /// acceleration.
    Q(usize),
    V(usize),
    Vdot(usize),
    /// Multiplier of a constraint row.
    Lambda(usize),
    /// Element state and its rate.
    X(usize),
    Xdot(usize),
}

/// The derivative of a sensor value: sparse over the state's entries and the parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SensorGradient {
    pub state: Vec<(Entry, f64)>,
    pub params: Vec<(ParamId, f64)>,
}

impl SensorGradient {
    /// `df = (df/ds) ds`.
    pub fn dot(&self, ds: &StateTangent) -> f64 {
        self.state
            .iter()
            .map(|&(e, g)| {
                g * match e {
                    Entry::Q(k) => ds.q[k / 6][k % 6],
                    Entry::V(k) => ds.v[k / 6][k % 6],
                    Entry::Vdot(k) => ds.vdot[k / 6][k % 6],
                    Entry::Lambda(r) => ds.lambda[r],
                    Entry::X(i) => ds.x[i],
                    Entry::Xdot(i) => ds.xdot[i],
                }
            })
            .sum()
    }

    /// `bar += c (df/ds)^T`.
    pub fn add_to(&self, c: f64, bar: &mut StateTangent) {
        for &(e, g) in &self.state {
            let g = c * g;
            match e {
                Entry::Q(k) => bar.q[k / 6][k % 6] += g,
                Entry::V(k) => bar.v[k / 6][k % 6] += g,
                Entry::Vdot(k) => bar.vdot[k / 6][k % 6] += g,
                Entry::Lambda(r) => bar.lambda[r] += g,
                Entry::X(i) => bar.x[i] += g,
                Entry::Xdot(i) => bar.xdot[i] += g,
            }
        }
    }
}

/// Relative step of the differences.
const EPS: f64 = 1e-4;

/// Whether sensor `kind` can enter a criterion (it has a derivative here).
pub fn differentiable(kind: &SensorKind) -> bool {
    !matches!(
        kind,
        SensorKind::KineticEnergy
            | SensorKind::PotentialEnergy
            | SensorKind::TotalEnergy
            | SensorKind::ConstraintViolation
    )
}

/// The state entries sensor `k` reads: nodes (all 18 entries each), constraint rows and
/// element states.
fn support(model: &Model, layout: &Layout, k: usize) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
    let element = |item: ElementItem, kernel: &dyn Fn(usize) -> Option<usize>, n: usize| {
        let nodes: Vec<usize> = (0..n).filter_map(kernel).collect();
        let start = item.state_start(model);
        let states = (start..start + item.n_states(model)).collect();
        (nodes, Vec::new(), states)
    };
    match &model.sensors[k].kind {
        SensorKind::Position { node, .. }
        | SensorKind::Velocity { node, .. }
        | SensorKind::Acceleration { node, .. }
        | SensorKind::Quaternion { node, .. }
        | SensorKind::AngularVelocity { node, .. }
        | SensorKind::AngularAcceleration { node, .. } => (vec![node.0], Vec::new(), Vec::new()),
        SensorKind::JointCoordinate { joint }
        | SensorKind::JointForce { joint, .. }
        | SensorKind::JointTorque { joint, .. } => {
            let j = &model.joints[joint.0];
            let nodes = [j.node_a, j.node_b].iter().flatten().map(|n| n.0).collect();
            let rows = if matches!(model.sensors[k].kind, SensorKind::JointCoordinate { .. }) {
                Vec::new()
            } else {
                let start = layout.joint_row_start[joint.0];
                (start..start + layout.joint_rows[joint.0].len()).collect()
            };
            (nodes, rows, Vec::new())
        }
        SensorKind::SpringForce { spring } => {
            let s = &model.springs[*spring];
            let slot = |i| s.node(i).map(|n| n.0);
            element(ElementItem::Spring(*spring), &slot, s.n_slots())
        }
        SensorKind::RopeForce { rope } => {
            let r = &model.ropes[*rope];
            let slot = |i| r.node(i).map(|n| n.0);
            element(ElementItem::Rope(*rope), &slot, r.n_slots())
        }
        SensorKind::Contact { contact, .. } => {
            let c = &model.contacts[*contact];
            let slot = |i: usize| [c.node_a, c.node_b][i].map(|n| n.0);
            element(ElementItem::Contact(*contact), &slot, 2)
        }
        SensorKind::RotationalSpringTorque { spring } => {
            let r = RotationalSpringElement::of(model, *spring);
            let slot = |i| r.node(i).map(|n| n.0);
            element(ElementItem::RotationalSpring(*spring), &slot, r.n_slots())
        }
        SensorKind::BushingForce { bushing, .. } => {
            let b = &model.bushings[*bushing];
            let slot = |i| b.node(i).map(|n| n.0);
            element(ElementItem::Bushing(*bushing), &slot, b.n_slots())
        }
        SensorKind::BeamStrain { beam, .. } | SensorKind::BeamStress { beam, .. } => {
            let nodes = model.beams[*beam].nodes.iter().map(|n| n.0).collect();
            (nodes, Vec::new(), Vec::new())
        }
        SensorKind::GearForce { gear } | SensorKind::GearTransmissionError { gear } => {
            let g = &model.gears[*gear];
            let slot = |i| g.node(i).map(|n| n.0);
            element(ElementItem::Gear(*gear), &slot, g.n_slots())
        }
        SensorKind::Block { block, output } => {
            let start = ElementItem::Control.state_start(model);
            let i = start + model.control.output_start[*block] + output;
            (Vec::new(), Vec::new(), vec![i])
        }
        _ => (Vec::new(), Vec::new(), Vec::new()),
    }
}

/// The parameters that enter sensor `k` at a fixed state.
pub fn sensor_parameters(model: &Model, params: &Parameters, k: usize) -> Vec<ParamId> {
    let kind = &model.sensors[k].kind;
    params
        .ids()
        .filter(|&id| match (kind, params.kind(id)) {
            (
                SensorKind::JointCoordinate { joint }
                | SensorKind::JointForce { joint, .. }
                | SensorKind::JointTorque { joint, .. },
                ParamKind::Joint(j, _),
            ) => *joint == j,
            (SensorKind::SpringForce { spring }, ParamKind::Spring(i, _)) => *spring == i,
            (SensorKind::RopeForce { rope }, ParamKind::Rope(i, _)) => *rope == i,
            (SensorKind::Contact { contact, .. }, ParamKind::Contact(i, _)) => *contact == i,
            (SensorKind::SpringForce { spring }, ParamKind::SpringLaw(i, _)) => *spring == i,
            (SensorKind::RotationalSpringTorque { spring }, ParamKind::RotationalSpring(i, _)) => {
                *spring == i
            }
            (SensorKind::BeamStress { beam, .. }, ParamKind::Beam(item, _)) => {
                params.beam_elements(item).contains(beam)
            }
            (SensorKind::GearForce { gear }, ParamKind::Gear(i, _)) => *gear == i,
            _ => false,
        })
        .collect()
}

/// The fourth-order central difference of a scalar `f` at step `eps`.
fn difference(eps: f64, f: &mut dyn FnMut(f64) -> f64) -> f64 {
    super::fourth_order_difference(eps, &mut |e| vec![f(e)])[0]
}

/// The derivative of sensor `k` at `state` with respect to the state's entries and, when
/// `params` is given (with a model `scratch` equal to `model`, used to move parameters and
/// left as it was), to the parameters in `wanted` that enter it.
pub fn sensor_gradient(
    model: &Model,
    layout: &Layout,
    k: usize,
    state: &State,
    params: Option<(&Parameters, &[ParamId], &mut Model)>,
) -> SensorGradient {
    let mut buffers = LocalBuffers::default();
    let nodes = crate::sensors::node_states(state);
    let angle = match &model.sensors[k].kind {
        SensorKind::JointCoordinate { joint } => {
            crate::joints::coordinate_is_angle(&model.joints[joint.0])
        }
        _ => false,
    };
    let center = crate::sensors::sensor_value(model, layout, k, &nodes, state, &mut buffers);
    // An angle is taken on the branch of the value at the point.
    let fix = |v: f64| {
        if angle {
            crate::sensors::unwrap(v, center)
        } else {
            v
        }
    };
    let (node_list, rows, states) = support(model, layout, k);
    let length = super::length_scale(model);
    let mut out = SensorGradient::default();
    // A sensor reads node kinematics from the nodes, the rest from the state.
    let mut moved_nodes: Vec<NodeState> = nodes.clone();
    for &n in &node_list {
        let base = nodes[n];
        for c in 0..6 {
            let i = 6 * n + c;
            for entry in [Entry::Q(i), Entry::V(i), Entry::Vdot(i)] {
                let eps = EPS
                    * match entry {
                        Entry::Q(_) if c < 3 => length,
                        Entry::Q(_) => 1.0,
                        Entry::V(_) => base.v.norm().max(1.0),
                        _ => base.vdot.norm().max(1.0),
                    };
                let g = difference(eps, &mut |e| {
                    let mut node = base;
                    match entry {
                        // the configuration, on the group
                        Entry::Q(_) => {
                            let mut d = flexmb_lie::Vec6::zeros();
                            d[c] = e;
                            node.q = model.group.integrate(&base.q, &d);
                        }
                        Entry::V(_) => node.v[c] += e,
                        _ => node.vdot[c] += e,
                    }
                    moved_nodes[n] = node;
                    let v = crate::sensors::sensor_value(
                        model,
                        layout,
                        k,
                        &moved_nodes,
                        state,
                        &mut buffers,
                    );
                    fix(v)
                });
                moved_nodes[n] = base;
                push(&mut out, entry, g);
            }
        }
    }
    // Multipliers and element states: moved on a copy of the state, made only when read.
    let mut moved_state = (!rows.is_empty() || !states.is_empty()).then(|| state.clone());
    let mut scalar = |entry: Entry, get: &dyn Fn(&mut State) -> &mut f64| {
        let moved_state = moved_state.as_mut().expect("made for rows and states");
        let base = *get(moved_state);
        let eps = EPS * base.abs().max(1.0);
        let g = difference(eps, &mut |e| {
            *get(moved_state) = base + e;
            crate::sensors::sensor_value(model, layout, k, &nodes, moved_state, &mut buffers)
        });
        *get(moved_state) = base;
        push(&mut out, entry, g);
    };
    for &r in &rows {
        scalar(Entry::Lambda(r), &|s: &mut State| &mut s.lambda[r]);
    }
    for &i in &states {
        scalar(Entry::X(i), &|s: &mut State| &mut s.x[i]);
        scalar(Entry::Xdot(i), &|s: &mut State| &mut s.xdot[i]);
    }
    if let Some((params, wanted, scratch)) = params {
        for id in sensor_parameters(model, params, k) {
            if !wanted.contains(&id) {
                continue;
            }
            let value = params.value(model, id);
            let eps = EPS * value.abs().max(length);
            let g = difference(eps, &mut |e| {
                params.set(scratch, id, value + e);
                let v =
                    crate::sensors::sensor_value(scratch, layout, k, &nodes, state, &mut buffers);
                fix(v)
            });
            params.set(scratch, id, value);
            if g != 0.0 {
                out.params.push((id, g));
            }
        }
    }
    out
}

fn push(out: &mut SensorGradient, entry: Entry, g: f64) {
    if g != 0.0 {
        out.state.push((entry, g));
    }
}
