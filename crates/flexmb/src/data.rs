//! The numbering of the Newton unknowns ([`Layout`]) and, for one layout, the derived
//! quantities and workspaces of the solvers ([`Data`]).
//!
//! [`Layout`] numbers the unknowns of the Newton iteration in four blocks ([`Block`]):
//!
//! ```text
//! [ node 0 (6) | ... | node n-1 (6) | multipliers (n_active) | stabilization (n_active) | states (n_states) ]
//! ```
//!
//! The stabilization block exists only in the stabilized index-2 formulation (see
//! [`crate::solve::dynamics`]): one unknown `zeta` per active row, with the velocity-level
//! constraint as its equation. The states block holds the first-order states that elements
//! own ([`crate::elements::ElementKernel::n_states`]), element after element
//! ([`Layout::state_start`]), each with its element's equation for it. [`Layout::unknown`]
//! names an index as an [`UnknownId`] (a node component, a joint row's multiplier or
//! stabilization unknown, an element's state), which failures carry and [`Layout::describe`]
//! puts in words.
//!
//! [`Data::new`] builds, for a model and a layout, the sparsity pattern of the iteration
//! matrix, the linear solver (with the symbolic analysis of the sparse backend) and the
//! workspaces: matrix values in pattern order, residual, correction, `Phi`, rows of `B`,
//! nodal masses. It is built again whenever the layout changes (the stabilized form after
//! the initial accelerations, redundant rows chosen again during a run, a restored
//! checkpoint). `Data` holds no iterate: the system being solved holds it and passes it to
//! [`crate::assembly::assemble`] as an [`crate::assembly::Iterate`].
//!
//! Each node's 6 entries are a vector in the Lie algebra (translation, then rotation).
//! Constraint rows that are redundant (linearly dependent on others, e.g. in an
//! over-constrained closed loop) are left out of the unknowns: found at the start, and
//! chosen again as the mechanism moves ([`crate::solve::initial::reselect_redundant_rows`]);
//! their multipliers stay zero and the others carry the load (a valid, least-constrained
//! set).

use crate::elements::{ElementKernel, ElementRef};
pub use crate::error::UnknownId;
use crate::joints::{self, Row};
use crate::linear::{GroupKind, Groups, LinearSolver};
use crate::model::{JointId, Model, NodeId};
use flexmb_lie::Vec6;
use std::ops::Range;

/// Numbering of unknowns and constraint rows.
#[derive(Clone, Debug)]
pub struct Layout {
    pub n_nodes: usize,
    /// `6 n_nodes`.
    pub n_dofs: usize,
    /// Rows of each joint.
    pub joint_rows: Vec<Vec<Row>>,
    /// Index of each joint's first row in `State::lambda`.
    pub joint_row_start: Vec<usize>,
    /// Total constraint rows (including redundant ones).
    pub n_rows: usize,
    /// For each row, its unknown index among the multipliers, `None` if redundant.
    pub row_unknown: Vec<Option<usize>>,
    /// The row of each multiplier unknown (`n_active`): the inverse of `row_unknown`.
    pub active_rows: Vec<usize>,
    /// Number of independent rows (multiplier unknowns).
    pub n_active: usize,
    /// Stabilized index-2 formulation: `n_active` more unknowns and equations.
    pub stabilized: bool,
    /// Active rows touching each node, as `(row, slot)` (slot 0 = joint's node A).
    pub node_rows: Vec<Vec<(usize, usize)>>,
    /// Force elements.
    pub elements: Vec<ElementRef>,
    /// Index of each element's first state in `State::x` (one per element).
    pub state_start: Vec<usize>,
    /// Total first-order states.
    pub n_states: usize,
    /// Which states are algebraic ([`crate::elements::ElementKernel::is_algebraic`]).
    pub algebraic: Vec<bool>,
}

impl Layout {
    /// The layout with all constraint rows active.
    pub fn new(model: &Model) -> Self {
        let (joint_rows, joint_row_start, n_rows) = joints::row_table(model);
        let elements = ElementRef::all(model);
        let mut state_start = Vec::with_capacity(elements.len());
        let mut n_states = 0;
        for item in crate::elements::ElementItem::all(model) {
            state_start.push(n_states);
            n_states += item.n_states(model);
        }
        let mut algebraic = Vec::with_capacity(n_states);
        for e in &elements {
            let kernel = e.kernel(model);
            algebraic.extend((0..kernel.n_states()).map(|i| kernel.is_algebraic(i)));
        }
        let mut layout = Self {
            n_nodes: model.nodes.len(),
            n_dofs: 6 * model.nodes.len(),
            joint_rows,
            joint_row_start,
            n_rows,
            row_unknown: (0..n_rows).map(Some).collect(),
            active_rows: (0..n_rows).collect(),
            n_active: n_rows,
            stabilized: false,
            node_rows: Vec::new(),
            elements,
            state_start,
            n_states,
            algebraic,
        };
        layout.rebuild_node_rows(model);
        layout
    }

    /// Recomputes [`Layout::node_rows`] from the active rows.
    fn rebuild_node_rows(&mut self, model: &Model) {
        let mut node_rows = vec![Vec::new(); self.n_nodes];
        for (j, joint) in model.joints.iter().enumerate() {
            for r in 0..self.joint_rows[j].len() {
                let row = self.joint_row_start[j] + r;
                if self.row_unknown[row].is_none() {
                    continue;
                }
                for (slot, node) in [joint.node_a, joint.node_b].into_iter().enumerate() {
                    if let Some(n) = node {
                        node_rows[n.0].push((row, slot));
                    }
                }
            }
        }
        self.node_rows = node_rows;
    }

    /// Total Newton unknowns.
    pub fn n_unknowns(&self) -> usize {
        self.n_dofs + self.n_active * (1 + self.stabilized as usize) + self.n_states
    }

    /// Index of the first state unknown (and equation) in the Newton vector.
    pub fn state_offset(&self) -> usize {
        self.n_dofs + self.n_active * (1 + self.stabilized as usize)
    }

    /// Index of the stabilization unknown (and velocity-constraint equation) of active row `k`.
    pub fn zeta(&self, k: usize) -> usize {
        self.n_dofs + self.n_active + k
    }

    /// The layout of the stabilized index-2 formulation or not, with the given rows left out
    /// as redundant.
    pub fn with_rows(model: &Model, stabilized: bool, redundant: &[usize]) -> Self {
        let mut layout = Self::new(model);
        layout.stabilized = stabilized;
        layout.deactivate_rows(model, redundant);
        layout
    }

    /// The rows left out as redundant, in increasing order.
    pub fn redundant_rows(&self) -> Vec<usize> {
        (0..self.n_rows)
            .filter(|&r| self.row_unknown[r].is_none())
            .collect()
    }

    /// Marks the given rows as redundant.
    pub fn deactivate_rows(&mut self, model: &Model, redundant: &[usize]) {
        self.active_rows.clear();
        for r in 0..self.n_rows {
            if redundant.contains(&r) {
                self.row_unknown[r] = None;
            } else {
                self.row_unknown[r] = Some(self.active_rows.len());
                self.active_rows.push(r);
            }
        }
        self.n_active = self.active_rows.len();
        self.rebuild_node_rows(model);
    }

    /// Global dof offset of a node slot.
    pub fn dof(&self, node: Option<NodeId>) -> Option<usize> {
        node.map(|n| 6 * n.0)
    }

    /// `(joint, row within joint)` of a global row index.
    pub fn locate_row(&self, row: usize) -> (usize, usize) {
        let j = self.joint_row_start.partition_point(|&s| s <= row) - 1;
        (j, row - self.joint_row_start[j])
    }

    /// A constraint row in the words of its joint, e.g. "revolute joint 'P5', row 3
    /// (translation along the joint's z axis)".
    pub fn describe_row(&self, model: &Model, row: usize) -> String {
        let (j, r) = self.locate_row(row);
        let joint = &model.joints[j];
        format!(
            "{} joint '{}', row {} ({})",
            joint.kind.name(),
            joint.name,
            r + 1,
            self.joint_rows[j][r].describe()
        )
    }

    /// The range of a block of unknowns in the Newton vector (empty if the block is absent).
    pub fn block(&self, block: Block) -> Range<usize> {
        let (nd, na) = (self.n_dofs, self.n_active);
        match block {
            Block::NodeIncrements => 0..nd,
            Block::Multipliers => nd..nd + na,
            Block::Stabilization if self.stabilized => nd + na..nd + 2 * na,
            Block::Stabilization => nd + na..nd + na,
            Block::States => self.state_offset()..self.n_unknowns(),
        }
    }

    /// The groups of unknowns the block LU eliminates together
    /// ([`crate::linear::Groups`]): each node's six increments; each joint's
    /// multipliers and, in the stabilized formulation, its stabilization unknowns (saddle
    /// groups, with a zero diagonal block); each element's states.
    pub fn groups(&self) -> Groups {
        let mut groups = Groups::default();
        for node in 0..self.n_nodes {
            groups.push(6 * node..6 * node + 6, GroupKind::Regular);
        }
        let joint_unknowns = |j: usize, first: usize| {
            let start = self.joint_row_start[j];
            (start..start + self.joint_rows[j].len())
                .filter_map(|row| self.row_unknown[row])
                .map(move |k| first + k)
        };
        let (multipliers, stabilization) = (
            self.block(Block::Multipliers).start,
            self.block(Block::Stabilization).start,
        );
        for j in 0..self.joint_rows.len() {
            let lambda = groups.push(joint_unknowns(j, multipliers), GroupKind::Multipliers);
            if let (Some(of), true) = (lambda, self.stabilized) {
                groups.push(
                    joint_unknowns(j, stabilization),
                    GroupKind::Stabilization { of },
                );
            }
        }
        let offset = self.state_offset();
        for (e, &start) in self.state_start.iter().enumerate() {
            let end = self
                .state_start
                .get(e + 1)
                .copied()
                .unwrap_or(self.n_states);
            groups.push(offset + start..offset + end, GroupKind::Regular);
        }
        groups
    }

    /// What unknown `i` of the Newton vector is.
    pub fn unknown(&self, i: usize) -> UnknownId {
        let (nd, na) = (self.n_dofs, self.n_active);
        let row = |k: usize| {
            let (j, r) = self.locate_row(self.active_rows[k]);
            (JointId(j), r as u8)
        };
        if i < nd {
            UnknownId::Node {
                node: NodeId(i / 6),
                component: (i % 6) as u8,
            }
        } else if i < nd + na {
            let (joint, row) = row(i - nd);
            UnknownId::Multiplier { joint, row }
        } else if i < self.state_offset() {
            let (joint, row) = row(i - nd - na);
            UnknownId::Stabilization { joint, row }
        } else {
            let k = i - self.state_offset();
            // the last element whose states start at or before k: it owns state k (an
            // element without states shares its start with the next element)
            let element = self.state_start.partition_point(|&s| s <= k) - 1;
            UnknownId::State {
                element,
                index: (k - self.state_start[element]) as u16,
            }
        }
    }

    /// An unknown in words, with the equation it stands for (e.g. "equilibrium of node 'tip',
    /// component ry"; "revolute joint 'P5', row 3 (translation along the joint's z axis)").
    pub fn describe(&self, model: &Model, id: UnknownId) -> String {
        const COMP: [&str; 6] = ["x", "y", "z", "rx", "ry", "rz"];
        match id {
            UnknownId::Node { node, component } => format!(
                "equilibrium of node '{}', component {}",
                model.nodes[node.0].name, COMP[component as usize]
            ),
            UnknownId::Multiplier { joint, row } => {
                self.describe_row(model, self.joint_row_start[joint.0] + row as usize)
            }
            UnknownId::Stabilization { joint, row } => format!(
                "velocity-level constraint of {}",
                self.describe_row(model, self.joint_row_start[joint.0] + row as usize)
            ),
            UnknownId::State { element, index } => match &self.elements[element] {
                // a block's own words: `output 0 of block 'pid'`
                ElementRef::Control(_) => format!(
                    "the equation of {} (control blocks)",
                    model.control.describe(index as usize)
                ),
                e => format!("state equation {} of {}", index + 1, e.describe(model)),
            },
        }
    }

    /// [`Layout::describe`] of unknown `i`.
    pub fn describe_unknown(&self, model: &Model, i: usize) -> String {
        self.describe(model, self.unknown(i))
    }
}

/// The blocks of the Newton vector, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Block {
    /// `6 n_nodes` configuration increments (Lie algebra: translation, then rotation).
    NodeIncrements,
    /// One scaled multiplier per active constraint row.
    Multipliers,
    /// One stabilization unknown `zeta` per active row (stabilized index-2 form only).
    Stabilization,
    /// The first-order states of the elements.
    States,
}

/// Everything derived from a model plus the solver workspaces.
pub struct Data {
    pub layout: Layout,
    /// Values of the iteration matrix at its triplet positions ([`Data::pattern`], fixed
    /// for the run).
    pub values: Vec<f64>,
    /// `(unknown, index in values)` of every pattern entry on the diagonal.
    pub diagonal_slots: Vec<(usize, usize)>,
    /// Diagonal of the last assembled iteration matrix (`n_unknowns`; filled on demand
    /// from `values`).
    pub diagonal: Vec<f64>,
    /// Residual of the Newton system (`n_unknowns`).
    pub residual: Vec<f64>,
    /// Newton correction (`n_unknowns`).
    pub correction: Vec<f64>,
    /// Constraint values `Phi` (`n_rows`).
    pub phi: Vec<f64>,
    /// Diagonal nodal masses and inertias (`n_nodes`, 6 each: the body and lumped beam
    /// masses on the translations, the mean of their inertias on the rotations).
    pub nodal_mass: Vec<flexmb_lie::Vec6>,
    /// Rows of `B` at the current iterate (`n_rows`, group coordinates).
    pub b_rows: Vec<crate::elements::Vec12>,
    /// One element's local inputs, vector and matrix during assembly (scratch).
    pub local: crate::elements::LocalBuffers,
    /// The threads of the assembly (sequential unless set: [`Data::with_threads`]).
    pub threads: crate::parallel::Threads,
    pub solver: LinearSolver,
    /// What higher layers derive from the layout on first use and keep with it: the
    /// parallel assembly's per-item positions (`assembly::ParallelScratch`), the positions
    /// of the exact step Jacobian (`solve::step::JacobianPattern`).
    pub derived: Derived,
}

/// Structures derived from a [`Layout`] by the layers above this one, built on first use
/// and kept as long as the [`Data`] of the layout: one of each type, found by its type, so
/// that this layer does not name them.
#[derive(Default)]
pub struct Derived(Vec<Box<dyn std::any::Any + Send + Sync>>);

impl Derived {
    /// The kept `T`, built by `make` if there is none yet.
    pub fn get_or_insert_with<T: std::any::Any + Send + Sync>(
        &mut self,
        make: impl FnOnce() -> T,
    ) -> &mut T {
        let at = match self.0.iter().position(|d| d.is::<T>()) {
            Some(at) => at,
            None => {
                self.0.push(Box::new(make()));
                self.0.len() - 1
            }
        };
        self.0[at]
            .downcast_mut()
            .expect("the entry found has the type asked for")
    }
}

impl Data {
    /// The triplet positions of the iteration matrix, one per entry of `values` (recovered
    /// from the solver, [`LinearSolver::pattern`]: on a 100 000-link chain a second copy
    /// was a quarter of the memory).
    pub fn pattern(&self) -> Vec<(usize, usize)> {
        self.solver.pattern()
    }

    /// The same data assembling on `threads` (the results are the same bits).
    pub fn with_threads(mut self, threads: crate::parallel::Threads) -> Self {
        self.threads = threads;
        self
    }
}

/// `(slot, dof offset)` of the slots that are nodes (not the ground).
pub fn active_slots(slots: [Option<usize>; 2]) -> impl Iterator<Item = (usize, usize)> {
    slots
        .into_iter()
        .enumerate()
        .filter_map(|(k, d)| d.map(|d| (k, d)))
}

/// Diagonal nodal masses: bodies (mass, and the mean principal inertia about the node) and
/// the lumped halves of beam elements.
pub(crate) fn nodal_mass(model: &Model) -> Vec<Vec6> {
    let mut out = vec![Vec6::zeros(); model.nodes.len()];
    let mut add = |node: NodeId, m: f64, j: f64| {
        let v = &mut out[node.0];
        for k in 0..3 {
            v[k] += m;
            v[3 + k] += j;
        }
    };
    for b in &model.bodies {
        let j_o = b.inertia.trace() / 3.0 + b.mass * b.com.norm_squared() * 2.0 / 3.0;
        add(b.node, b.mass, j_o);
    }
    for b in &model.beams {
        let half = 0.5 * b.length;
        let j = b.section.rotary_inertia.trace() / 3.0 * half;
        for node in b.nodes {
            add(node, b.section.mass_per_length * half, j);
        }
    }
    out
}
