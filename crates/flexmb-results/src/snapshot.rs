//! One output step of a run ([`Snapshot`]), one solver step ([`StepStat`]) and a whole run
//! in memory ([`Results`]).

use crate::info::ModelInfo;
use flexmb::data::Data;
use flexmb::elements::point_velocity;
use flexmb::input::{Analysis, ModelFile};
use flexmb::model::JointId;
use flexmb::observe::{Observer, Sample};
use flexmb::sensors::{joint_point, joint_reaction, node_states, SensorEvaluator};
use flexmb::solve::{Simulation, Statics, StepInfo};
use flexmb::{Model, SolveError, State};
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
    /// Per joint: its point \[m\] (see [`flexmb::sensors::joint_point`]).
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
    /// Sensor values, in [`ModelInfo::sensors`] order.
    pub sensors: Vec<f64>,
}

/// One accepted step of a dynamic run, or one converged load step of a static run by load
/// control or arc length (`at` the load factor, `h` the load increment).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, hdf5::H5Type)]
#[repr(C)]
pub struct StepStat {
    /// Time (load factor) at the end of the step.
    pub at: f64,
    /// Step size.
    pub h: f64,
    /// Newton iterations, failed attempts included.
    pub iterations: u32,
    /// Attempts rejected before the accepted one.
    pub rejected: u32,
    /// Whether the accepted attempt used a freshly built iteration matrix.
    pub fresh_matrix: bool,
}

impl StepStat {
    pub fn of(i: &StepInfo) -> Self {
        Self {
            at: i.t,
            h: i.h,
            iterations: i.iterations as u32,
            rejected: i.rejected as u32,
            fresh_matrix: !i.reused_matrix,
        }
    }
}

impl Snapshot {
    /// The snapshot of `state` at `at`; `sensors` are the sensor values.
    pub fn capture(model: &Model, data: &Data, state: &State, at: f64, sensors: Vec<f64>) -> Self {
        let nodes = node_states(state);
        let mut s = Snapshot {
            at,
            sensors,
            multipliers: state.lambda.clone(),
            ..Default::default()
        };
        for n in &nodes {
            let om = n.q.r * n.v.fixed_rows::<3>(3);
            let v = point_velocity(model.group, n, &Vec3::zeros());
            s.position.push(n.q.x.into());
            s.orientation.push(n.q.quaternion());
            s.velocity.push([v.x, v.y, v.z, om.x, om.y, om.z]);
        }
        for j in 0..model.joints.len() {
            let (f, m) = joint_reaction(model, &data.layout, JointId(j), &nodes, state);
            s.joint_position
                .push(joint_point(model, JointId(j), &nodes).into());
            s.joint_reaction.push([f.x, f.y, f.z, m.x, m.y, m.z]);
        }
        for b in &model.beams {
            let st = b.state(&[nodes[b.nodes[0].0], nodes[b.nodes[1].0]]);
            s.beam_strain.push(st.strain.into());
            s.beam_stress.push(st.stress.into());
        }
        s
    }
}

/// A run's results in memory: what the HDF5 results file holds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Results {
    pub info: ModelInfo,
    pub snapshots: Vec<Snapshot>,
    pub steps: Vec<StepStat>,
}

impl Results {
    /// Runs the analysis of `file` and keeps its results in memory (no file is written).
    /// On a solver error the results up to it are returned with the error.
    pub fn collect(file: &ModelFile) -> (Self, Option<SolveError>) {
        let model = &file.model;
        let analysis = match file.analysis {
            Analysis::Dynamic(_) => "dynamic",
            Analysis::Static(_) => "static",
        };
        let mut recorder = Recorder {
            results: Results {
                info: ModelInfo::of(model, analysis),
                ..Default::default()
            },
            sensors: SensorEvaluator::new(model),
        };
        let error = match &file.analysis {
            Analysis::Dynamic(settings) => Simulation::new(model, *settings)
                .and_then(|mut sim| sim.run(&mut recorder).map(|_| ())),
            Analysis::Static(settings) => {
                Statics::new(model, *settings).and_then(|mut st| st.run(&mut recorder).map(|_| ()))
            }
        }
        .err();
        (recorder.results, error)
    }

    /// The values of the sensor called `name` at every snapshot.
    pub fn sensor(&self, name: &str) -> Option<Vec<f64>> {
        let k = self.info.sensor(name)?;
        Some(self.snapshots.iter().map(|s| s.sensors[k]).collect())
    }

    /// Time (or load factor) of every snapshot.
    pub fn times(&self) -> Vec<f64> {
        self.snapshots.iter().map(|s| s.at).collect()
    }
}

/// Collects a run into [`Results`].
struct Recorder {
    results: Results,
    sensors: SensorEvaluator,
}

impl Observer for Recorder {
    fn output(&mut self, s: &Sample) -> Result<(), String> {
        let values = self.sensors.evaluate(s.model, s.data, s.state);
        let snap = Snapshot::capture(s.model, s.data, s.state, s.at, values);
        self.results.snapshots.push(snap);
        Ok(())
    }
    fn accepted(&mut self, info: &StepInfo) -> Result<(), String> {
        self.results.steps.push(StepStat::of(info));
        Ok(())
    }
}
