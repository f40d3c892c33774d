//! Block diagrams: control blocks wired by name, coupled to the mechanics
//! ([`crate::elements::control`] has the equations).
//!
//! A [`ControlSystem`] is a list of [`Block`]s. Every signal is a scalar; a block reads its
//! inputs from the outputs of other blocks ([`Signal`]), may own first-order states `x`
//! (integrators, filters, a motor's current), and has outputs `y`. Measurement blocks
//! ([`Quantity`]) read the mechanics (node and joint kinematics); actuator blocks
//! ([`Target`]) apply their input as a force, a moment or a joint torque. All numbers a
//! block uses are in its [`Block::params`] (named by [`BlockKind::param_names`]), so each is
//! a model parameter by path (`control.NAME.PARAM`) with an exact derivative.

use super::{JointId, NodeId, TimeFunction};
use flexmb_lie::Vec3;

/// One output of one block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Signal {
    /// Index in [`ControlSystem::blocks`].
    pub block: usize,
    /// Which of its outputs.
    pub output: usize,
}

/// What a measurement block reads (inertial components along a unit `axis`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Quantity {
    /// `axis . (x + R p)` \[m\].
    Position {
        node: NodeId,
        point: Vec3,
        axis: Vec3,
    },
    /// `axis . (xdot + R (omega x p))` \[m/s\].
    Velocity {
        node: NodeId,
        point: Vec3,
        axis: Vec3,
    },
    /// `axis . (xddot + R (omegadot x p + omega x (omega x p)))` \[m/s^2\].
    Acceleration {
        node: NodeId,
        point: Vec3,
        axis: Vec3,
    },
    /// `axis . (R omega)` \[rad/s\].
    AngularVelocity { node: NodeId, axis: Vec3 },
    /// Revolute/cylindrical angle (continuous over turns) \[rad\] or prismatic slide \[m\].
    JointCoordinate { joint: JointId },
    /// Its rate \[rad/s or m/s\].
    JointRate { joint: JointId },
    /// What a joint's constraint exerts on its node B, `-B^T lambda` on that node, as the
    /// `joint_force` and `joint_torque` sensors: `axis . f` (the force) or, with `moment`,
    /// `axis . m` (the moment about the joint point) \[N or N m\].
    ConstraintForce {
        joint: JointId,
        axis: Vec3,
        moment: bool,
    },
    /// Elastic stress resultant `component` of a beam element (index in `Model::beams`),
    /// section frame, as the `beam_stress` sensor: 0-2 forces, 3-5 moments \[N or N m\].
    SectionForce { beam: usize, component: usize },
    /// What a contact (index in `Model::contacts`) exerts on its node B, normal force and
    /// friction, as `axis . f` \[N\].
    ContactForce { contact: usize, axis: Vec3 },
}

impl Quantity {
    /// Whether the measurement reads more than its nodes' kinematics (a joint's multipliers,
    /// a beam's section law, a contact's law and states): it is evaluated in `f64` with its derivatives from the joint's
    /// beam's or contact's own kernel rather than by the diagram's automatic differentiation.
    pub fn is_reaction(&self) -> bool {
        matches!(
            self,
            Quantity::ConstraintForce { .. }
                | Quantity::SectionForce { .. }
                | Quantity::ContactForce { .. }
        )
    }
}

/// Where an actuator block applies its input `u`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Target {
    /// Torque `u` about a revolute/cylindrical joint's axis (on node B, and its reaction on
    /// node A), or force `u` along a prismatic joint's axis \[N m or N\].
    Joint { joint: JointId },
    /// Force `u axis` at the point `point` of a node \[N\]; `follower`: `axis` turns with
    /// the node.
    Force {
        node: NodeId,
        point: Vec3,
        axis: Vec3,
        follower: bool,
    },
    /// Moment `u axis` on a node \[N m\]; `follower`: `axis` turns with the node.
    Moment {
        node: NodeId,
        axis: Vec3,
        follower: bool,
    },
}

/// The kind of a block, with its structure (sizes); its numbers are in [`Block::params`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum BlockKind {
    /// `y = f(t)` (the time functions of the model file); its parameters are the function's
    /// amplitudes ([`TimeFunction::amplitude_keys`], `function.<key>`).
    Source(TimeFunction),
    /// `y = K u`, `K` of `rows x cols` (params `gain`, or `gain[i,j]`).
    Gain { rows: usize, cols: usize },
    /// `y = sum_i sign_i u_i`.
    Sum { signs: Vec<f64> },
    /// `y = prod_i u_i`.
    Product { inputs: usize },
    /// `xdot = k u`, `y = x` (params `gain`, `initial`).
    Integrator,
    /// First-order lag `T xdot = K u - x`, `y = x` (params `gain`, `time_constant`,
    /// `initial`).
    Lag,
    /// PID with filtered derivative and back-calculation anti-windup (params `kp`, `ki`,
    /// `kd`, `tf`, `lower`, `upper`, `kb`).
    Pid,
    /// `xdot = A x + B u`, `y = C x + D u` (params `A[i,j]`, `B[i,j]`, `C[i,j]`, `D[i,j]`,
    /// `x0[i]`).
    StateSpace {
        states: usize,
        inputs: usize,
        outputs: usize,
    },
    /// `Y(s)/U(s) = (b_0 s^m + ... + b_m) / (a_0 s^n + ... + a_n)`, `m <= n` (params `num[i]`,
    /// `den[i]`), realized in controllable canonical form.
    TransferFunction { num: usize, den: usize },
    /// `y = min(max(u, lower), upper)`.
    Saturation,
    /// `y = u - upper` above `upper`, `u - lower` below `lower`, 0 between.
    DeadZone,
    /// `xdot = min(max((u - x) / time_constant, -falling), rising)`, `y = x`.
    RateLimiter,
    /// Piecewise-linear `y(u)` through `(breakpoints[i], values[i])`, constant outside
    /// (params `values[i]`).
    Lookup { breakpoints: Vec<f64> },
    /// Zero-order hold: `y` is `u` sampled every `period` seconds from `t = 0` and held.
    Hold { period: f64 },
    /// DC motor, inputs `[voltage, speed]`: `L idot = V - R i - k_e omega`, `y = k_t i`
    /// (params `resistance`, `inductance`, `torque_constant`, `back_emf`).
    DcMotor,
    /// A measurement of the mechanics.
    Measure(Quantity),
    /// Applies its input to the mechanics.
    Actuator(Target),
    /// Servo constraint: its output `u`, applied along `target`, is the input that makes
    /// `quantity` (a node's position along an axis, or a joint coordinate) follow `f(t)`
    /// (parameters: the amplitudes of `f`, as a source's, then `initial`, the value of `u`
    /// the consistent initial accelerations start from when `target` is not collocated
    /// with `quantity`). The inverse dynamics of an underactuated system (Blajer &
    /// Kołodziejczyk 2004).
    Servo {
        quantity: Quantity,
        target: Target,
        function: TimeFunction,
    },
}

impl BlockKind {
    /// The type name of the model file.
    pub fn name(&self) -> &'static str {
        match self {
            BlockKind::Source(_) => "source",
            BlockKind::Gain { .. } => "gain",
            BlockKind::Sum { .. } => "sum",
            BlockKind::Product { .. } => "product",
            BlockKind::Integrator => "integrator",
            BlockKind::Lag => "lag",
            BlockKind::Pid => "pid",
            BlockKind::StateSpace { .. } => "state_space",
            BlockKind::TransferFunction { .. } => "transfer_function",
            BlockKind::Saturation => "saturation",
            BlockKind::DeadZone => "dead_zone",
            BlockKind::RateLimiter => "rate_limiter",
            BlockKind::Lookup { .. } => "lookup",
            BlockKind::Hold { .. } => "hold",
            BlockKind::DcMotor => "dc_motor",
            BlockKind::Measure(_) => "measure",
            BlockKind::Actuator(_) => "actuator",
            BlockKind::Servo { .. } => "servo",
        }
    }

    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        match self {
            BlockKind::Source(_) | BlockKind::Measure(_) | BlockKind::Servo { .. } => 0,
            BlockKind::Gain { cols, .. } => *cols,
            BlockKind::Sum { signs } => signs.len(),
            BlockKind::Product { inputs } => *inputs,
            BlockKind::StateSpace { inputs, .. } => *inputs,
            BlockKind::DcMotor => 2,
            _ => 1,
        }
    }

    /// Number of first-order states.
    pub fn n_states(&self) -> usize {
        match self {
            BlockKind::Integrator
            | BlockKind::Lag
            | BlockKind::RateLimiter
            | BlockKind::Hold { .. }
            | BlockKind::DcMotor => 1,
            BlockKind::Pid => 2,
            BlockKind::StateSpace { states, .. } => *states,
            BlockKind::TransferFunction { den, .. } => den.saturating_sub(1),
            _ => 0,
        }
    }

    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        match self {
            BlockKind::Gain { rows, .. } => *rows,
            BlockKind::StateSpace { outputs, .. } => *outputs,
            BlockKind::Actuator(_) => 0,
            _ => 1,
        }
    }

    /// Whether an output depends on an input at the same instant (direct feedthrough):
    /// a cycle of such blocks is an algebraic loop.
    pub fn feedthrough(&self) -> bool {
        !matches!(
            self,
            BlockKind::Integrator
                | BlockKind::Lag
                | BlockKind::RateLimiter
                | BlockKind::Hold { .. }
                | BlockKind::DcMotor
                | BlockKind::Source(_)
                | BlockKind::Measure(_)
                | BlockKind::Servo { .. }
        )
    }

    /// The names of the block's parameters, in the order of [`Block::params`].
    pub fn param_names(&self) -> Vec<String> {
        let list = |names: &[&str]| names.iter().map(|s| s.to_string()).collect();
        let matrix = |name: &str, rows: usize, cols: usize| -> Vec<String> {
            (0..rows)
                .flat_map(|i| (0..cols).map(move |j| format!("{name}[{i},{j}]")))
                .collect()
        };
        let vector = |name: &str, n: usize| -> Vec<String> {
            (0..n).map(|i| format!("{name}[{i}]")).collect()
        };
        match self {
            BlockKind::Source(f) => f
                .amplitude_keys()
                .iter()
                .map(|k| format!("function.{k}"))
                .collect(),
            BlockKind::Servo { function: f, .. } => f
                .amplitude_keys()
                .iter()
                .map(|k| format!("function.{k}"))
                .chain(["initial".to_string()])
                .collect(),
            BlockKind::Gain { rows: 1, cols: 1 } => list(&["gain"]),
            BlockKind::Gain { rows, cols } => matrix("gain", *rows, *cols),
            BlockKind::Integrator => list(&["gain", "initial"]),
            BlockKind::Lag => list(&["gain", "time_constant", "initial"]),
            BlockKind::Pid => list(&["kp", "ki", "kd", "tf", "lower", "upper", "kb"]),
            BlockKind::StateSpace {
                states: n,
                inputs: m,
                outputs: p,
            } => [
                matrix("A", *n, *n),
                matrix("B", *n, *m),
                matrix("C", *p, *n),
                matrix("D", *p, *m),
                vector("x0", *n),
            ]
            .concat(),
            BlockKind::TransferFunction { num, den } => {
                [vector("num", *num), vector("den", *den)].concat()
            }
            BlockKind::Saturation | BlockKind::DeadZone => list(&["lower", "upper"]),
            BlockKind::RateLimiter => list(&["rising", "falling", "time_constant"]),
            BlockKind::Lookup { breakpoints } => vector("values", breakpoints.len()),
            BlockKind::DcMotor => {
                list(&["resistance", "inductance", "torque_constant", "back_emf"])
            }
            _ => Vec::new(),
        }
    }
}

/// One block: its kind, its parameters and where its inputs come from.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Block {
    pub name: String,
    pub kind: BlockKind,
    /// Values of the block's own parameters: [`BlockKind::param_names`] after the amplitudes
    /// of a source's or servo's function, which stay in the function ([`Block::value`]).
    pub params: Vec<f64>,
    /// One per input ([`BlockKind::n_inputs`]).
    pub inputs: Vec<Signal>,
}

impl Block {
    /// The number of amplitudes of the block's time function (a source's, a servo's): its
    /// first parameters.
    pub fn n_amplitudes(&self) -> usize {
        match &self.kind {
            BlockKind::Source(f) | BlockKind::Servo { function: f, .. } => f.amplitude_count(),
            _ => 0,
        }
    }

    /// Parameter `k` of [`BlockKind::param_names`].
    pub fn value(&self, k: usize) -> f64 {
        match &self.kind {
            BlockKind::Source(f) | BlockKind::Servo { function: f, .. }
                if k < f.amplitude_count() =>
            {
                f.amplitude(k)
            }
            _ => self.params[k - self.n_amplitudes()],
        }
    }

    /// Sets parameter `k` of [`BlockKind::param_names`].
    pub fn set_param(&mut self, k: usize, value: f64) {
        let n = self.n_amplitudes();
        match &mut self.kind {
            BlockKind::Source(f) | BlockKind::Servo { function: f, .. } if k < n => {
                f.set_amplitude(k, value)
            }
            _ => self.params[k - n] = value,
        }
    }

    /// The parameter named `name`.
    pub fn param(&self, name: &str) -> Option<f64> {
        let k = self.kind.param_names().iter().position(|n| n == name)?;
        Some(self.value(k))
    }
}

/// The blocks of a model and where each one's unknowns are among the element's states:
/// block after block, its states, then its outputs.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ControlSystem {
    pub blocks: Vec<Block>,
    /// First state of each block (index among the element's states).
    pub state_start: Vec<usize>,
    /// First output of each block (index among the element's states).
    pub output_start: Vec<usize>,
    /// Number of unknowns: states and outputs of all blocks.
    pub n_unknowns: usize,
}

impl ControlSystem {
    /// The system of `blocks`, its unknowns numbered.
    pub fn new(blocks: Vec<Block>) -> Self {
        let (mut state_start, mut output_start) = (Vec::new(), Vec::new());
        let mut n = 0;
        for b in &blocks {
            state_start.push(n);
            n += b.kind.n_states();
            output_start.push(n);
            n += b.kind.n_outputs();
        }
        Self {
            blocks,
            state_start,
            output_start,
            n_unknowns: n,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// Whether a servo's target acts along its measured quantity (a force on the measured
    /// node along the measured axis, a joint's torque or force on its own coordinate): its
    /// input then appears in the quantity's second derivative (relative degree 2).
    pub fn collocated(quantity: &Quantity, target: &Target) -> bool {
        match (quantity, target) {
            (
                Quantity::Position { node, axis, .. },
                Target::Force {
                    node: n,
                    axis: a,
                    follower: false,
                    ..
                },
            ) => node == n && (axis - a).norm() < 1e-12,
            (Quantity::JointCoordinate { joint }, Target::Joint { joint: j }) => joint == j,
            _ => false,
        }
    }

    /// Whether a measurement, actuator or servo acts along joint `j`.
    pub fn uses_joint(&self, j: JointId) -> bool {
        let along = |q: Option<&Quantity>, t: Option<&Target>| {
            matches!(q, Some(Quantity::JointCoordinate { joint } | Quantity::JointRate { joint } | Quantity::ConstraintForce { joint, .. }) if *joint == j)
                || matches!(t, Some(Target::Joint { joint }) if *joint == j)
        };
        self.blocks.iter().any(|b| match &b.kind {
            BlockKind::Measure(q) => along(Some(q), None),
            BlockKind::Actuator(t) => along(None, Some(t)),
            BlockKind::Servo {
                quantity, target, ..
            } => along(Some(quantity), Some(target)),
            _ => false,
        })
    }

    /// Whether a measurement reads the section forces of beam element `e`.
    pub fn uses_beam(&self, e: usize) -> bool {
        self.blocks.iter().any(|b| {
            matches!(&b.kind, BlockKind::Measure(Quantity::SectionForce { beam, .. }) if *beam == e)
        })
    }

    /// Whether a measurement reads the force of contact `i`.
    pub fn uses_contact(&self, i: usize) -> bool {
        self.blocks.iter().any(|b| {
            matches!(&b.kind, BlockKind::Measure(Quantity::ContactForce { contact, .. }) if *contact == i)
        })
    }

    /// Whether a block is a zero-order hold (the diagram then has events: its samples).
    pub fn has_holds(&self) -> bool {
        self.blocks
            .iter()
            .any(|b| matches!(b.kind, BlockKind::Hold { .. }))
    }

    /// The unknown (index among the element's states) of a signal.
    pub fn unknown(&self, s: Signal) -> usize {
        self.output_start[s.block] + s.output
    }

    /// The block that owns unknown `i` (the last whose unknowns start at or before `i`: a
    /// block without unknowns shares its start with the next block).
    pub fn owner(&self, i: usize) -> usize {
        self.state_start.partition_point(|&s| s <= i) - 1
    }

    /// Whether unknown `i` is an output (an algebraic unknown: no rate in its equation).
    pub fn is_output(&self, i: usize) -> bool {
        i >= self.output_start[self.owner(i)]
    }

    /// The block by name.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.blocks.iter().position(|b| b.name == name)
    }

    /// What unknown `i` is in words, e.g. `output 0 of block 'pid'`.
    pub fn describe(&self, i: usize) -> String {
        let b = self.owner(i);
        let name = &self.blocks[b].name;
        if i >= self.output_start[b] {
            format!("output {} of block '{name}'", i - self.output_start[b])
        } else {
            format!("state {} of block '{name}'", i - self.state_start[b])
        }
    }
}
