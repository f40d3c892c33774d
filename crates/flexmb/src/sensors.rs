//! Sensors: the output channels declared by a model, evaluated from the state.

use crate::data::{Data, Layout};
use crate::elements::{Context, ElementItem, ElementKernel, ElementRef, LocalBuffers, NodeState};
use crate::joints;
use crate::model::{JointId, Model, SensorFrame, SensorKind};
use crate::state::State;
use flexmb_lie::Vec3;

pub use crate::state::{node_states, node_states_into};

fn pair(nodes: &[NodeState], slots: [Option<crate::model::NodeId>; 2]) -> [NodeState; 2] {
    let g = NodeState::ground(Default::default());
    [
        slots[0].map_or(g, |n| nodes[n.0]),
        slots[1].map_or(g, |n| nodes[n.0]),
    ]
}

/// Kinetic and potential energy of the whole model \[J\]; `elements` are the model's force
/// elements ([`ElementRef::all`], e.g. those of [`crate::data::Layout`]).
pub fn energies(model: &Model, elements: &[ElementRef], state: &State) -> (f64, f64) {
    let nodes = node_states(state);
    let ctx = Context::at(model, state.t, 1.0);
    let mut ke = 0.0;
    let mut pe = 0.0;
    let mut buffers = LocalBuffers::default();
    let mut start = 0;
    for e in elements {
        let k = e.kernel(model);
        buffers.gather(&k, &nodes, (&state.x, &state.xdot, start), &state.lambda);
        start += k.n_states();
        let local = buffers.local(&nodes);
        ke += k.kinetic_energy(&ctx, &local);
        pe += k.potential_energy(&ctx, &local);
    }
    (ke, pe)
}

/// Evaluates sensors, keeping what unwrapping angles needs between calls.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SensorEvaluator {
    /// Last unwrapped joint angle per sensor.
    last_angle: Vec<Option<f64>>,
}

impl SensorEvaluator {
    /// Sensors it keeps memory for.
    pub fn len(&self) -> usize {
        self.last_angle.len()
    }

    pub fn is_empty(&self) -> bool {
        self.last_angle.is_empty()
    }

    pub fn new(model: &Model) -> Self {
        Self {
            last_angle: vec![None; model.sensors.len()],
        }
    }

    /// Column names, in order.
    pub fn names(model: &Model) -> Vec<String> {
        model.sensors.iter().map(|s| s.name.clone()).collect()
    }

    /// Values of all sensors at `state`, multipliers and constraint values from `data`.
    pub fn evaluate(&mut self, model: &Model, data: &Data, state: &State) -> Vec<f64> {
        let nodes = node_states(state);
        let mut buffers = LocalBuffers::default();
        let mut energy = None;
        let mut out = Vec::with_capacity(model.sensors.len());
        for (k, s) in model.sensors.iter().enumerate() {
            let value = match &s.kind {
                SensorKind::KineticEnergy
                | SensorKind::PotentialEnergy
                | SensorKind::TotalEnergy => {
                    let (ke, pe) = *energy
                        .get_or_insert_with(|| energies(model, &data.layout.elements, state));
                    match s.kind {
                        SensorKind::KineticEnergy => ke,
                        SensorKind::PotentialEnergy => pe,
                        _ => ke + pe,
                    }
                }
                SensorKind::JointCoordinate { joint } => {
                    let raw = sensor_value(model, &data.layout, k, &nodes, state, &mut buffers);
                    if joints::coordinate_is_angle(&model.joints[joint.0]) {
                        let unwrapped = self.last_angle[k].map_or(raw, |last| unwrap(raw, last));
                        self.last_angle[k] = Some(unwrapped);
                        unwrapped
                    } else {
                        raw
                    }
                }
                _ => sensor_value(model, &data.layout, k, &nodes, state, &mut buffers),
            };
            out.push(value);
        }
        out
    }
}

/// The angle `raw` plus the multiple of `2 pi` that brings it closest to `near`.
pub fn unwrap(raw: f64, near: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    near + (raw - near + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI
}

/// The value of sensor `k` of `model` at `state` (its node kinematics `nodes`, multipliers
/// in the rows of `layout`); joint angles in `(-pi, pi]`, not unwrapped.
pub fn sensor_value(
    model: &Model,
    layout: &Layout,
    k: usize,
    nodes: &[NodeState],
    state: &State,
    buffers: &mut LocalBuffers,
) -> f64 {
    let ctx = Context::at(model, state.t, 1.0);
    match &model.sensors[k].kind {
        SensorKind::Position {
            node,
            point,
            component,
        } => nodes[node.0].q.point(point)[*component],
        SensorKind::Velocity {
            node,
            point,
            component,
        } => crate::elements::point_velocity(model.group, &nodes[node.0], point)[*component],
        SensorKind::Acceleration {
            node,
            point,
            component,
        } => crate::elements::point_acceleration(model.group, &nodes[node.0], point)[*component],
        SensorKind::Quaternion { node, component } => nodes[node.0].q.quaternion()[*component],
        SensorKind::AngularVelocity {
            node,
            frame,
            component,
        } => {
            let om = nodes[node.0].v.fixed_rows::<3>(3).into_owned();
            match frame {
                SensorFrame::Body => om[*component],
                SensorFrame::Inertial => (nodes[node.0].q.r * om)[*component],
            }
        }
        SensorKind::AngularAcceleration {
            node,
            frame,
            component,
        } => {
            // d(R omega)/dt = R (omega x omega + omegadot) = R omegadot
            let omd = nodes[node.0].vdot.fixed_rows::<3>(3).into_owned();
            match frame {
                SensorFrame::Body => omd[*component],
                SensorFrame::Inertial => (nodes[node.0].q.r * omd)[*component],
            }
        }
        SensorKind::JointCoordinate { joint } => {
            let j = &model.joints[joint.0];
            joints::coordinate(j, &pair(nodes, [j.node_a, j.node_b]))
        }
        kind @ (SensorKind::JointForce { joint, component }
        | SensorKind::JointTorque { joint, component }) => {
            let (f, m) = joint_reaction(model, layout, *joint, nodes, state);
            if matches!(kind, SensorKind::JointForce { .. }) {
                f[*component]
            } else {
                m[*component]
            }
        }
        SensorKind::SpringForce { spring } => {
            let sp = crate::elements::spring::SpringElement::of(model, *spring);
            let start = ElementItem::Spring(*spring).state_start(model);
            buffers.gather(&sp, nodes, (&state.x, &state.xdot, start), &state.lambda);
            sp.tension(&ctx, &buffers.local(nodes))
        }
        SensorKind::Contact { contact, quantity } => {
            let item = ElementItem::Contact(*contact);
            let c = &model.contacts[*contact];
            let element = crate::elements::contact::ContactElement {
                contact: c,
                effective_mass: f64::INFINITY,
            };
            buffers.gather(
                &element,
                nodes,
                (&state.x, &state.xdot, item.state_start(model)),
                &state.lambda,
            );
            let s = element.state(&ctx, &buffers.local(nodes));
            match quantity {
                0 => s.normal_force,
                1 => (-s.gap).max(0.0),
                2 => s.gap,
                3 => s.slip_velocity,
                4 => s.friction_force,
                _ => {
                    let stiction = c.friction.map_or(0.0, |f| f.stiction_velocity);
                    (s.gap < 0.0 && s.slip_velocity < stiction) as u8 as f64
                }
            }
        }
        SensorKind::RopeForce { rope: i } => {
            let rope = &model.ropes[*i];
            let start = ElementItem::Rope(*i).state_start(model);
            buffers.gather(rope, nodes, (&state.x, &state.xdot, start), &state.lambda);
            rope.force(&ctx, &buffers.local(nodes))
        }
        SensorKind::RotationalSpringTorque { spring: i } => {
            let sp = crate::elements::rotational_spring::RotationalSpringElement::of(model, *i);
            let start = ElementItem::RotationalSpring(*i).state_start(model);
            buffers.gather(&sp, nodes, (&state.x, &state.xdot, start), &state.lambda);
            sp.torque(&ctx, &buffers.local(nodes))
        }
        SensorKind::BushingForce { bushing, component } => {
            let b = &model.bushings[*bushing];
            buffers.gather(b, nodes, (&state.x, &state.xdot, 0), &state.lambda);
            b.state(model.group, buffers.local(nodes).nodes).sigma[*component]
        }
        kind @ (SensorKind::KineticEnergy
        | SensorKind::PotentialEnergy
        | SensorKind::TotalEnergy) => {
            let (ke, pe) = energies(model, &layout.elements, state);
            match kind {
                SensorKind::KineticEnergy => ke,
                SensorKind::PotentialEnergy => pe,
                _ => ke + pe,
            }
        }
        SensorKind::ConstraintViolation => constraint_violation(model, layout, state, nodes),
        kind @ (SensorKind::BeamStrain { beam, component }
        | SensorKind::BeamStress { beam, component }) => {
            let b = &model.beams[*beam];
            let st = b.state(&[nodes[b.nodes[0].0], nodes[b.nodes[1].0]]);
            if matches!(kind, SensorKind::BeamStrain { .. }) {
                st.strain[*component]
            } else {
                st.stress[*component]
            }
        }
        kind @ (SensorKind::GearForce { gear } | SensorKind::GearTransmissionError { gear }) => {
            let g = &model.gears[*gear];
            buffers.gather(g, nodes, (&state.x, &state.xdot, 0), &state.lambda);
            let local = buffers.local(nodes);
            if matches!(kind, SensorKind::GearForce { .. }) {
                g.mesh_force(&ctx, &local)
            } else {
                g.transmission_error(&ctx, &local)
            }
        }
        SensorKind::Block { block, output } => {
            let start = ElementItem::Control.state_start(model);
            state.x[start + model.control.output_start[*block] + output]
        }
    }
}

/// Force and torque (about the joint point) exerted by joint `joint` on its node B,
/// inertial frame, from the multipliers of `state` (\[N\], \[N m\]).
pub fn joint_reaction(
    model: &Model,
    layout: &Layout,
    joint: JointId,
    nodes: &[NodeState],
    state: &State,
) -> (Vec3, Vec3) {
    let j = &model.joints[joint.0];
    let start = layout.joint_row_start[joint.0];
    let rows = &layout.joint_rows[joint.0];
    joints::reaction_on_b(
        j,
        rows,
        &pair(nodes, [j.node_a, j.node_b]),
        &state.lambda[start..start + rows.len()],
        state.t,
    )
}

/// The point of joint `joint` (origin of its frame on node B, or on node A when B is the
/// ground), inertial \[m\].
pub fn joint_point(model: &Model, joint: JointId, nodes: &[NodeState]) -> Vec3 {
    let j = &model.joints[joint.0];
    let (fa, fb) = joints::node_frames(j, &pair(nodes, [j.node_a, j.node_b]));
    match j.node_b {
        Some(_) => fb.compose(&j.frame_b).x,
        None => fa.compose(&j.frame_a).x,
    }
}

/// The unit of a sensor's values, for labels: `m`, `m/s`, `rad`, `N`, ...; empty for a
/// number without unit (a quaternion component, a strain).
pub fn unit(kind: &SensorKind) -> &'static str {
    match kind {
        SensorKind::Position { .. } => "m",
        SensorKind::Velocity { .. } => "m/s",
        SensorKind::Acceleration { .. } => "m/s^2",
        SensorKind::AngularAcceleration { .. } => "rad/s^2",
        SensorKind::AngularVelocity { .. } => "rad/s",
        SensorKind::Quaternion { .. } => "",
        SensorKind::JointCoordinate { .. } => "rad or m",
        SensorKind::JointForce { .. }
        | SensorKind::SpringForce { .. }
        | SensorKind::RopeForce { .. } => "N",
        SensorKind::Contact { quantity, .. } => ["N", "m", "m", "m/s", "N", ""][*quantity],
        SensorKind::JointTorque { .. } | SensorKind::RotationalSpringTorque { .. } => "N m",
        SensorKind::KineticEnergy | SensorKind::PotentialEnergy | SensorKind::TotalEnergy => "J",
        SensorKind::ConstraintViolation => "m or rad",
        SensorKind::BeamStrain { component, .. } => {
            if *component < 3 {
                ""
            } else {
                "1/m"
            }
        }
        SensorKind::BeamStress { component, .. } | SensorKind::BushingForce { component, .. } => {
            if *component < 3 {
                "N"
            } else {
                "N m"
            }
        }
        SensorKind::GearForce { .. } => "N",
        SensorKind::GearTransmissionError { .. } => "m",
        SensorKind::Block { .. } => "",
    }
}

/// Largest `|Phi|` over the active constraint rows at `state`.
pub fn constraint_violation(
    model: &Model,
    layout: &Layout,
    state: &State,
    nodes: &[NodeState],
) -> f64 {
    let zeros = [0.0; joints::MAX_ROWS];
    let mut worst = 0.0f64;
    for (j, joint) in model.joints.iter().enumerate() {
        let p = pair(nodes, [joint.node_a, joint.node_b]);
        let rows = &layout.joint_rows[j];
        let jv = joints::evaluate_joint(
            model.group,
            joint,
            rows,
            &p,
            state.t,
            &zeros[..rows.len()],
            None,
        );
        for r in 0..rows.len() {
            if layout.row_unknown[layout.joint_row_start[j] + r].is_some() {
                worst = worst.max(jv.phi[r].abs());
            }
        }
    }
    worst
}
