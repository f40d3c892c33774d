//! The state: everything that changes during a run.

use crate::data::Layout;
use crate::elements::{Context, ElementKernel, LocalBuffers};
use crate::error::SolveError;
use crate::kernel::NodeState;
use crate::model::Model;
use flexmb_lie::{Frame, Group, Mat6, Vec6};

/// Configuration, velocities, accelerations and multipliers at one time.
///
/// Shapes: `q, v, vdot, a` have one entry per node (`n_nodes`); `lambda` one per constraint
/// row of every joint, in joint order (`n_rows`, rows removed as redundant stay 0).
#[derive(Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct State {
    pub t: f64,
    /// Node configurations on the group.
    pub q: Vec<Frame>,
    /// Velocities `v` (6 per node, group convention).
    pub v: Vec<Vec6>,
    /// Accelerations `vdot = dv/dt`.
    pub vdot: Vec<Vec6>,
    /// Algorithmic accelerations `a` of the generalized-alpha scheme.
    pub a: Vec<Vec6>,
    /// Lagrange multipliers (unscaled, physical units of the rows' generalized forces).
    pub lambda: Vec<f64>,
    /// First-order states of the elements (`n_states`, [`crate::data::Layout::state_start`]).
    #[serde(default)]
    pub x: Vec<f64>,
    /// Their rates `xdot`.
    #[serde(default)]
    pub xdot: Vec<f64>,
    /// Their algorithmic rates `w` of the first-order generalized-alpha scheme.
    #[serde(default)]
    pub w: Vec<f64>,
}

/// `clone_from` reuses the vectors' storage: the step saves its start this way at every
/// step (the derived `clone_from` allocates a new state each time).
impl Clone for State {
    fn clone(&self) -> Self {
        Self {
            t: self.t,
            q: self.q.clone(),
            v: self.v.clone(),
            vdot: self.vdot.clone(),
            a: self.a.clone(),
            lambda: self.lambda.clone(),
            x: self.x.clone(),
            xdot: self.xdot.clone(),
            w: self.w.clone(),
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.t = source.t;
        self.q.clone_from(&source.q);
        self.v.clone_from(&source.v);
        self.vdot.clone_from(&source.vdot);
        self.a.clone_from(&source.a);
        self.lambda.clone_from(&source.lambda);
        self.x.clone_from(&source.x);
        self.xdot.clone_from(&source.xdot);
        self.w.clone_from(&source.w);
        debug_assert!(self == source, "every field of the state is copied");
    }
}

impl State {
    /// The model's initial configuration and velocities, and the elements' initial states
    /// ([`crate::elements::ElementKernel::initial_states`]) of `layout`; accelerations,
    /// rates and multipliers zero (see [`crate::solve::initial_accelerations`] for
    /// consistent ones). Fails with [`SolveError::InitialStates`] when an element cannot
    /// solve for its states (the outputs of control blocks), naming the state.
    pub fn initial(model: &Model, layout: &Layout) -> Result<Self, SolveError> {
        let n_rows = layout.n_rows;
        let v = model
            .nodes
            .iter()
            .map(|n| {
                let u = match model.group {
                    Group::R3xSO3 => n.velocity,
                    Group::SE3 => n.frame.r.transpose() * n.velocity,
                };
                flexmb_lie::join(&u, &n.angular_velocity)
            })
            .collect();
        let n = model.nodes.len();
        let mut state = Self {
            t: 0.0,
            q: model.nodes.iter().map(|n| n.frame).collect(),
            v,
            vdot: vec![Vec6::zeros(); n],
            a: vec![Vec6::zeros(); n],
            lambda: vec![0.0; n_rows],
            x: vec![0.0; layout.n_states],
            xdot: vec![0.0; layout.n_states],
            w: vec![0.0; layout.n_states],
        };
        if layout.n_states > 0 {
            let nodes = node_states(&state);
            let ctx = Context::at(model, 0.0, 1.0);
            let mut buffers = LocalBuffers::default();
            for (e, &start) in layout.elements.iter().zip(&layout.state_start) {
                let kernel = e.kernel(model);
                let ns = kernel.n_states();
                if ns > 0 {
                    // the states and rates are still zero here
                    buffers.gather(
                        &kernel,
                        &nodes,
                        (&state.x, &state.xdot, start),
                        &state.lambda,
                    );
                    let x = &mut state.x[start..start + ns];
                    kernel
                        .initial_states(&ctx, &buffers.local(&nodes), x)
                        .map_err(|error| {
                            let unknown = error
                                .unknown()
                                .map(|i| layout.unknown(layout.state_offset() + start + i));
                            SolveError::InitialStates {
                                worst_equation: unknown.map_or_else(
                                    || e.describe(model),
                                    |u| layout.describe(model, u),
                                ),
                                unknown,
                                error: Box::new(error),
                            }
                        })?;
                }
            }
        }
        Ok(state)
    }
}

/// Node kinematics of a state (tangent operators identity).
pub fn node_states(state: &State) -> Vec<NodeState> {
    let mut out = Vec::new();
    node_states_into(state, &mut out);
    out
}

/// [`node_states`] into a reused buffer.
pub fn node_states_into(state: &State, out: &mut Vec<NodeState>) {
    out.clear();
    out.extend((0..state.q.len()).map(|i| NodeState {
        q: state.q[i],
        v: state.v[i],
        vdot: state.vdot[i],
        t: Mat6::identity(),
    }));
}
