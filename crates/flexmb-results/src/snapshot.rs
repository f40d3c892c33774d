//! One output step of a run ([`Snapshot`], the engine's [`flexmb::output::Snapshot`]), one
//! solver step ([`StepStat`]) and a whole run in memory ([`Results`]).

use crate::info::ModelInfo;
use flexmb::input::{Analysis, ModelFile};
use flexmb::observe::{Observer, Sample};
pub use flexmb::output::Snapshot;
use flexmb::sensors::SensorEvaluator;
use flexmb::solve::{Simulation, Statics, StepInfo};
use flexmb::SolveError;
use serde::{Deserialize, Serialize};

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
        let snap = Snapshot::capture(s.model, &s.data.layout, s.state, s.at, values);
        self.results.snapshots.push(snap);
        Ok(())
    }
    fn accepted(&mut self, info: &StepInfo) -> Result<(), String> {
        self.results.steps.push(StepStat::of(info));
        Ok(())
    }
}
