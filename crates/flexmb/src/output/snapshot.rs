//! One output step of a run as owned values ([`Snapshot`]): what the result files hold of
//! the state at an output point. The writer thread ([`super::writer`]) computes it from the
//! copy of the state the solver's thread hands over, and writes the CSV files and the
//! stores from it.

use crate::data::Layout;
use crate::elements::{point_velocity, NodeState};
use crate::model::{JointId, Model};
use crate::sensors::{joint_point, joint_reaction, node_states};
use crate::state::State;
use flexmb_lie::Vec3;
use serde::{Deserialize, Serialize};

/// The results at one output step. Vectors are inertial.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// Time \[s\] or load factor.
    pub at: f64,
    /// Per node: position of its origin \[m\].
    pub position: Vec<[f64; 3]>,
    /// Per node: unit quaternion `w, x, y, z` of its rotation node-to-inertial.
    pub orientation: Vec<[f64; 4]>,
    /// Per node: velocity of its origin \[m/s\] and angular velocity \[rad/s\].
    pub velocity: Vec<[f64; 6]>,
    /// Per joint: its point \[m\] (see [`crate::sensors::joint_point`]).
    pub joint_position: Vec<[f64; 3]>,
    /// Per joint: force \[N\] and torque about its point \[N m\] on its node B.
    pub joint_reaction: Vec<[f64; 6]>,
    /// The multipliers of every constraint row, joint after joint.
    pub multipliers: Vec<f64>,
    /// Per beam element: strains (axial, shear 2, shear 3, torsion, curvature 2, curvature 3).
    pub beam_strain: Vec<[f64; 6]>,
    /// Per beam element: stress resultants (N, V2, V3 \[N\], torque, M2, M3 \[N m\]),
    /// section frame.
    pub beam_stress: Vec<[f64; 6]>,
    /// Sensor values, in the order of the model's sensors.
    pub sensors: Vec<f64>,
}

impl Snapshot {
    /// The snapshot of `state` at `at` (`layout`: the rows of the state's multipliers);
    /// `sensors` are the sensor values.
    pub fn capture(
        model: &Model,
        layout: &Layout,
        state: &State,
        at: f64,
        sensors: Vec<f64>,
    ) -> Self {
        let nodes = node_states(state);
        let mut s = Self::of_nodes(model, &nodes, at, sensors);
        s.multipliers = state.lambda.clone();
        for n in &nodes {
            let om = n.q.r * n.v.fixed_rows::<3>(3);
            let v = point_velocity(model.group, n, &Vec3::zeros());
            s.velocity.push([v.x, v.y, v.z, om.x, om.y, om.z]);
        }
        for j in 0..model.joints.len() {
            let (f, m) = joint_reaction(model, layout, JointId(j), &nodes, state);
            s.joint_position
                .push(joint_point(model, JointId(j), &nodes).into());
            s.joint_reaction.push([f.x, f.y, f.z, m.x, m.y, m.z]);
        }
        s
    }

    /// What the CSV files hold of `state` at `at`: the node positions and orientations, the
    /// beam strains and stress resultants and the sensor values (no velocities, joints or
    /// multipliers: those of [`Snapshot::capture`] cost the joint reactions).
    pub fn capture_shape(model: &Model, state: &State, at: f64, sensors: Vec<f64>) -> Self {
        Self::of_nodes(model, &node_states(state), at, sensors)
    }

    /// The node configurations, beam states and sensor values.
    fn of_nodes(model: &Model, nodes: &[NodeState], at: f64, sensors: Vec<f64>) -> Self {
        let mut s = Snapshot {
            at,
            sensors,
            ..Default::default()
        };
        for n in nodes {
            s.position.push(n.q.x.into());
            s.orientation.push(n.q.quaternion());
        }
        for b in &model.beams {
            let st = b.state(&[nodes[b.nodes[0].0], nodes[b.nodes[1].0]]);
            s.beam_strain.push(st.strain.into());
            s.beam_stress.push(st.stress.into());
        }
        s
    }
}
