//! Where the entries of the exact step Jacobian go: one sparsity pattern per layout,
//! and the selection of each partial derivative from an assembly of the iteration matrix.

use crate::data::Layout;

/// The positions of the exact step Jacobian of one layout, sorted by row then column
/// without repeats: the iteration matrix's pattern ([`crate::data::Data::pattern`], whose repeated
/// positions are summed) with every node block of a row complete (six columns), plus, in
/// the stabilized form, the columns of `zeta` that `F_q T B(q_n)^T` fills. Built once per
/// [`crate::data::Data`] and kept there: the values of every step's Jacobian go on these
/// positions, so a solver's symbolic analysis is done once.
#[derive(Debug)]
pub struct JacobianPattern {
    /// Unknowns (rows and columns).
    pub n: usize,
    /// `(row, column)`.
    pub positions: Vec<(usize, usize)>,
    /// Positions of the first of the six entries of each node block `(row, 6 n..6 n + 6)`,
    /// with the node.
    pub(super) blocks: Vec<(usize, usize)>,
    /// Stabilized form: `(block, constraint row, slot, position)` for every block of node
    /// `n` and every active row acting on `n`: where `F_q T B(q_n)^T` puts its entries.
    pub(super) zeta: Vec<(usize, usize, usize, usize)>,
    /// The layout's groups of unknowns, for the block LU ([`Layout::groups`]).
    pub groups: crate::linear::Groups,
    /// Where each entry of the iteration matrix's pattern goes in each partial derivative
    /// ([`Selection`]): a position, or [`crate::assembly::Selected::NONE`].
    pub(super) selections: [Vec<u32>; Selection::COUNT],
    /// Positions in the velocity-level rows (stabilized form), which `F_v` divides by
    /// `gamma'`.
    pub(super) velocity_positions: Vec<u32>,
}

/// The partial derivatives of [`Partials`] taken from an assembly of the iteration matrix,
/// each a selection of its entries by row and column.
#[derive(Clone, Copy)]
pub(super) enum Selection {
    /// `F_q`: position-level rows (and the element states') against the configuration.
    Configuration,
    /// `F_mu`: the equilibrium rows (and the element states') against the multipliers.
    Multipliers,
    /// `F_v`: every row but the position-level ones against the velocities.
    Velocities,
    /// `F_vd`: equilibrium and element-state rows against the accelerations.
    Accelerations,
    /// `F_x`, `F_xd`: every row against the element states.
    States,
}

impl Selection {
    const COUNT: usize = 5;
    const ALL: [Selection; Self::COUNT] = [
        Selection::Configuration,
        Selection::Multipliers,
        Selection::Velocities,
        Selection::Accelerations,
        Selection::States,
    ];

    /// Whether entry `(i, j)` of the iteration matrix of `layout` belongs to this partial.
    pub(super) fn takes(self, layout: &Layout, i: usize, j: usize) -> bool {
        let (nd, na, so) = (layout.n_dofs, layout.n_active, layout.state_offset());
        match self {
            Selection::Configuration => j < nd && (i < nd + na || i >= so),
            Selection::Multipliers => (i < nd || i >= so) && (nd..nd + na).contains(&j),
            Selection::Velocities => j < nd && (i < nd || i >= nd + na),
            Selection::Accelerations => (i < nd || i >= so) && j < nd,
            Selection::States => j >= so,
        }
    }
}

impl JacobianPattern {
    pub(super) fn new(layout: &Layout, pattern: &[(usize, usize)]) -> Self {
        let nd = layout.n_dofs;
        let mut positions: Vec<(usize, usize)> = Vec::with_capacity(pattern.len());
        for &(i, j) in pattern {
            if j < nd {
                positions.extend((0..6).map(|c| (i, 6 * (j / 6) + c)));
            } else {
                positions.push((i, j));
            }
        }
        if layout.stabilized {
            let nodes: Vec<(usize, usize)> =
                positions.iter().filter(|p| p.1 < nd).copied().collect();
            for (i, j) in nodes {
                for &(row, _) in &layout.node_rows[j / 6] {
                    positions.push((i, layout.zeta(layout.row_unknown[row].expect("active row"))));
                }
            }
        }
        positions.sort_unstable();
        positions.dedup();
        let find = |p: &(usize, usize)| {
            positions
                .binary_search(p)
                .expect("a position of the pattern")
        };
        let of_pattern: Vec<usize> = pattern.iter().map(find).collect();
        let mut blocks = Vec::new();
        let mut zeta = Vec::new();
        for (k, &(i, j)) in positions.iter().enumerate() {
            if j < nd && j % 6 == 0 {
                let n = j / 6;
                blocks.push((k, n));
                if layout.stabilized {
                    for &(row, slot) in &layout.node_rows[n] {
                        let z = layout.zeta(layout.row_unknown[row].expect("active row"));
                        zeta.push((k, row, slot, find(&(i, z))));
                    }
                }
            }
        }
        let selections = Selection::ALL.map(|sel| {
            (pattern.iter().zip(&of_pattern))
                .map(|(&(i, j), &k)| match sel.takes(layout, i, j) {
                    true => k as u32,
                    false => crate::assembly::Selected::NONE,
                })
                .collect()
        });
        let so = layout.state_offset();
        let velocity_positions = (positions.iter().enumerate())
            .filter(|(_, &(i, _))| i >= nd + layout.n_active && i < so)
            .map(|(k, _)| k as u32)
            .collect();
        Self {
            n: layout.n_unknowns(),
            positions,
            blocks,
            zeta,
            groups: layout.groups(),
            selections,
            velocity_positions,
        }
    }

    /// The entries of `values` (on the iteration matrix's pattern) that `selection` takes,
    /// summed on the Jacobian's positions, into `out` (its storage reused).
    pub(super) fn select_into(&self, selection: Selection, values: &[f64], out: &mut Vec<f64>) {
        use crate::assembly::Sink;
        zeroed(out, self.positions.len());
        let mut sink = self.sink(selection, out);
        for &v in values {
            sink.entry(0, 0, v);
        }
    }

    /// A sink of the iteration matrix's entries that sums those of `selection` into `out`
    /// (on these positions).
    pub(super) fn sink<'s>(
        &'s self,
        selection: Selection,
        out: &'s mut [f64],
    ) -> crate::assembly::Selected<'s> {
        crate::assembly::Selected {
            dest: &self.selections[selection as usize],
            out,
            pos: 0,
        }
    }

    /// The position of `(row, column)`.
    pub(super) fn position(&self, at: (usize, usize)) -> usize {
        self.positions
            .binary_search(&at)
            .expect("a position of the step Jacobian")
    }
}

/// `out` as `n` zeros, its storage reused.
pub(super) fn zeroed(out: &mut Vec<f64>, n: usize) {
    out.clear();
    out.resize(n, 0.0);
}
