//! Block LU for the iteration matrices of multibody systems.
//!
//! The unknowns of a multibody model come in small groups that the model knows: the six
//! increments of a node, the multipliers of a joint, its stabilization unknowns, the states
//! of an element. The iteration matrix couples two groups only where an element or a joint
//! connects them, so that the graph of the groups is the graph of the mechanism: a tree for
//! an open chain, a tree plus a few loops for closed mechanisms, a path for a beam.
//! Eliminating such a graph leaves first creates no fill at all (Baraff 1996, "Linear-time
//! dynamics using Lagrange multipliers", SIGGRAPH, Sect. 5; Featherstone's articulated
//! body recursion is the same elimination for trees in minimal coordinates).
//!
//! The diagonal block of a joint's multipliers is zero (the matrix is the saddle point
//! `[[S, B^T], [B, 0]]`), so a joint cannot be eliminated on its own. Each such *saddle*
//! group is therefore merged into one of the node groups it is coupled to, into a
//! *supernode* whose diagonal block `[[S_i, B_i^T], [B_i, 0]]` is regular when the joint's
//! rows `B_i` have full rank on the node's six unknowns and `S_i` (mass and stiffness) is
//! positive definite on their null space. Each joint goes to the least loaded of its nodes
//! that still has room for its rows (at most six rows on a node's six unknowns; ties: the
//! later node, the child in a chain built from the ground), which pairs every body of a
//! chain with the joint to its parent; its stabilization unknowns go with its multipliers.
//! A joint that finds no room closes a loop (a four-bar's fourth joint): it becomes a *cut*
//! supernode of its own, eliminated after all the others, when the Schur complement has
//! filled its diagonal block with `-B S^-1 B^T` (the loop-closure equations of the
//! articulated-body methods for closed chains).
//!
//! The factorization is a right-looking supernodal LU:
//!
//! * the supernodes are ordered by approximate minimum degree (AMD, Amestoy, Davis & Duff
//!   1996, as implemented by faer) on the supernode graph: leaves first on a tree;
//! * the rows of each supernode's panels (positions after the supernode that couple to it,
//!   in `A` or through fill) are found once, on the symmetrized structure, by the
//!   elimination tree of the supernodes;
//! * each supernode's diagonal block is factorized with partial pivoting inside the block,
//!   `P_k S_kk = L_kk U_kk`, where `S_kk` is the block updated by the earlier supernodes;
//!   its panels become `L_jk = S_jk U_kk^-1` and `U_kj = L_kk^-1 P_k S_kj`, and the update
//!   `S_ij -= L_ik U_kj` of the later blocks goes to storage positions computed once.
//!
//! Pivoting is static between supernodes. That is safe only when the diagonal blocks are
//! well conditioned, which the factorization checks for each supernode:
//!
//! * every pivot against [`PIVOT_TOLERANCE`](super::PIVOT_TOLERANCE) times a scale of its
//!   own. A *regular* column (a node's increments, an element's states: a diagonal block of
//!   its own in `A`) is judged against the largest entry of its column of `A`, as the other
//!   backends judge every column: a free massless node leaves a pivot at the rounding level
//!   of that column. A *saddle* column (a joint's multipliers and stabilization unknowns)
//!   has no such block: its pivot is made by the elimination, `-B S^-1 B^T` with `S` the
//!   articulated inertia of everything eliminated before, and on a chain of `n` links `S`
//!   grows as `n^3` (the moment of inertia of the links beyond a joint about its axes
//!   normal to the chain: 3e8 times a link's own at 1000 links, 3e14 at 100 000), so that
//!   the pivot falls below any fixed fraction of the joint's column `B^T` (below 1e-13 of
//!   it from 31 000 links on) with nothing cancelling in it. A saddle pivot is judged
//!   against the magnitude of the terms that formed it, `|A| + |L| |U|` at its position
//!   (the sum of `|l_pt| |u_tc|` over every column eliminated before, in this supernode or
//!   in the earlier ones whose updates reach it), which bounds its rounding error (Higham,
//!   "Accuracy and stability of numerical algorithms", 2002, Thm. 9.3): redundant joint
//!   rows, or a loop-closing joint that repeats another, cancel it to the rounding level of
//!   that scale;
//! * the growth of the elimination: the largest product `max_i |l_ic| max_j |u_cj|` of a
//!   column of `L` and the matching row of `U` (one term of `|L| |U|`, which bounds the
//!   componentwise backward error of an LU, Higham 2002, Thm. 9.3), against the largest
//!   entry of the supernode's blocks
//!   before its elimination, at most [`GROWTH_LIMIT`]. A static pivot that is small
//!   against its own column makes this large, as threshold partial pivoting would see it
//!   (Duff, Erisman & Reid, "Direct methods for sparse matrices", Sect. 5.4). Schur
//!   complements that grow with the mechanism do not: the block of the root of chain_1000
//!   holds the articulated inertia of the whole chain, 3e8 times a link's own, and the
//!   elimination's growth stays below 3 (2.75 on chains of 1000 to 100 000 links, for the
//!   initial accelerations and the steps alike). The solves' normwise backward error
//!   `|A x - b| / (|A| |x| + |b|)` measured on 1000 and 10 000 links is 5e-16.
//!
//! A matrix that fails a check is handed to the general sparse LU with full partial
//! pivoting by the caller (the statics of a rigid mechanism, whose node blocks have no
//! mass, is one such case), which also tells a singular matrix from an unlucky pivot
//! order.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::amd;
use faer::sparse::SymbolicSparseColMatRef;

use super::Pivots;

/// Largest growth of an elimination the block LU accepts (see the module documentation).
pub const GROWTH_LIMIT: f64 = 1e6;

/// A partition of the unknowns into the groups the block LU eliminates together.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Groups {
    /// The unknowns of each group. Unknowns in no group become groups of their own.
    pub members: Vec<Vec<usize>>,
    /// What each group is.
    pub kinds: Vec<GroupKind>,
}

/// What a group of unknowns is, for the block LU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GroupKind {
    /// Unknowns with a diagonal block of their own (a node's increments, an element's
    /// states).
    Regular,
    /// A joint's multipliers: a zero diagonal block; eliminated with a regular neighbour
    /// that has room for its rows (one per unknown), or after all its neighbours when none
    /// has (a joint that closes a loop).
    Multipliers,
    /// The stabilization unknowns of the joint whose multipliers are group `of`:
    /// eliminated with them.
    Stabilization { of: usize },
}

impl Groups {
    /// Adds a group and returns its index (nothing, and `None`, if it is empty).
    pub fn push(
        &mut self,
        members: impl IntoIterator<Item = usize>,
        kind: GroupKind,
    ) -> Option<usize> {
        let members: Vec<usize> = members.into_iter().collect();
        if members.is_empty() {
            return None;
        }
        self.members.push(members);
        self.kinds.push(kind);
        Some(self.members.len() - 1)
    }
}

/// A factorization the block LU does not accept: a tiny or non-finite pivot, a growth
/// beyond [`GROWTH_LIMIT`], or a non-finite entry. The general LU decides what it is.
#[derive(Debug)]
pub(super) struct Rejected;

/// One supernode, in elimination order.
struct Supernode {
    /// First position and number of unknowns.
    start: usize,
    size: usize,
    /// Range in `BlockLu::rows` of the positions of the rows of `L` (= columns of `U`).
    rows: std::ops::Range<usize>,
    /// Offsets in `BlockLu::store` of the diagonal block (`size x size`), of `L`
    /// (`rows x size`) and of `U` (`size x rows`), all column-major.
    diag: usize,
    lower: usize,
    upper: usize,
    /// Offset in `BlockLu::targets` of the storage index of each entry of the update
    /// `L U` (`rows x rows`, column-major).
    targets: usize,
    /// The first of the supernode's saddle columns (a joint's multipliers and stabilization
    /// unknowns, after the node's own; `size` if none; 0 for a cut supernode).
    saddle: usize,
    /// Offset in `BlockLu::magnitudes` of the magnitudes of the saddle columns of the
    /// diagonal block (`size x (size - saddle)`, column-major).
    magnitude: usize,
    /// Range in `BlockLu::saddle_targets` of the entries of the update `L U` that land in the
    /// saddle columns of a later diagonal block.
    saddle_targets: std::ops::Range<usize>,
}

pub(super) struct BlockLu {
    /// The unknown at each position of the elimination order.
    unknown: Vec<usize>,
    supernodes: Vec<Supernode>,
    /// The row positions of every supernode's panels (ranges in [`Supernode::rows`]).
    rows: Vec<usize>,
    targets: Vec<usize>,
    /// Diagonal blocks, panels and fill, in one array.
    store: Vec<f64>,
    /// Row interchanges of the diagonal blocks, LAPACK style (row `c` of a block was swapped
    /// with row `swaps[start + c]` of the block, in the order of `c`).
    swaps: Vec<usize>,
    /// The largest entry of each column of `A`, by position.
    column_max: Vec<f64>,
    /// `|A| + |L| |U|` at the saddle columns of the diagonal blocks, accumulated as the
    /// elimination goes (the rounding scale of their pivots, module documentation).
    magnitudes: Vec<f64>,
    /// `(entry of the update L U, index in magnitudes)` of the entries that land in a saddle
    /// column of a later diagonal block.
    saddle_targets: Vec<(usize, usize)>,
    /// A vector in elimination order (solves) and one column of an update.
    work: Vec<f64>,
    column: Vec<f64>,
}

impl BlockLu {
    /// The symbolic analysis: supernodes, their order, the structure of the factors and the
    /// storage index of every triplet of `pattern` (returned beside the solver).
    pub(super) fn new(n: usize, pattern: &[(usize, usize)], groups: &Groups) -> (Self, Vec<usize>) {
        // Groups, completed with one group per unknown left out.
        let mut group_of = vec![usize::MAX; n];
        let mut members = groups.members.clone();
        let mut kinds = groups.kinds.clone();
        for (g, m) in members.iter().enumerate() {
            for &u in m {
                group_of[u] = g;
            }
        }
        for u in 0..n {
            if group_of[u] == usize::MAX {
                group_of[u] = members.len();
                members.push(vec![u]);
                kinds.push(GroupKind::Regular);
            }
        }
        let n_groups = members.len();
        let adjacency = graph(
            n_groups,
            pattern.iter().map(|&(i, j)| (group_of[i], group_of[j])),
        );

        // Each joint's multipliers join the least loaded of the regular neighbours that still
        // have room for its rows (ties: the later one), its stabilization unknowns with them.
        // A joint with no such neighbour (one that closes a loop) stays on its own: a *cut*
        // supernode, eliminated after the others, when their elimination has filled its
        // diagonal block with `-B S^-1 B^T`.
        let mut host: Vec<usize> = (0..n_groups).collect();
        let mut rows = vec![0usize; n_groups];
        let regular = |h: usize| kinds[h] == GroupKind::Regular;
        for g in (0..n_groups).filter(|&g| kinds[g] == GroupKind::Multipliers) {
            let size = members[g].len();
            if let Some(&h) = adjacency[g]
                .iter()
                .filter(|&&h| regular(h) && rows[h] + size <= members[h].len())
                .min_by_key(|&&h| (rows[h], std::cmp::Reverse(h)))
            {
                host[g] = h;
                rows[h] += size;
            }
        }
        for g in 0..n_groups {
            if let GroupKind::Stabilization { of } = kinds[g] {
                host[g] = host[of];
            }
        }
        let mut supernode_of_group = vec![usize::MAX; n_groups];
        let mut supernode_members: Vec<Vec<usize>> = Vec::new();
        for g in (0..n_groups).filter(|&g| host[g] == g) {
            supernode_of_group[g] = supernode_members.len();
            supernode_members.push(members[g].clone());
        }
        for g in (0..n_groups).filter(|&g| host[g] != g) {
            let s = supernode_of_group[host[g]];
            supernode_of_group[g] = s;
            supernode_members[s].extend_from_slice(&members[g]);
        }
        let n_super = supernode_members.len();
        // The host's own unknowns come first, then those of the groups it hosts: the saddle
        // columns are the last of the supernode (all of a cut one).
        // (and whether the supernode is cut: eliminated last)
        let (saddle_start, cut): (Vec<usize>, Vec<bool>) = (0..n_groups)
            .filter(|&g| host[g] == g)
            .map(|g| match regular(g) {
                true => (members[g].len(), false),
                false => (0, true),
            })
            .unzip();
        let supernode_graph = graph(
            n_super,
            adjacency.iter().enumerate().flat_map(|(g, adj)| {
                let of = &supernode_of_group;
                adj.iter().map(move |&h| (of[g], of[h]))
            }),
        );

        // Elimination order of the supernodes (the cut ones last), then the positions of the
        // unknowns.
        let mut order = postorder(&supernode_graph, &amd_order(&supernode_graph));
        order.sort_by_key(|&k| cut[k]);
        let mut position = vec![0usize; n];
        let mut unknown = Vec::with_capacity(n);
        let mut starts = Vec::with_capacity(n_super + 1);
        for &s in &order {
            starts.push(unknown.len());
            for &u in &supernode_members[s] {
                position[u] = unknown.len();
                unknown.push(u);
            }
        }
        starts.push(n);
        let mut supernode_at = vec![0usize; n];
        for k in 0..n_super {
            supernode_at[starts[k]..starts[k + 1]].fill(k);
        }

        // Rows of the panels: the couplings of A (symmetrized), then the rows each supernode
        // passes to its parent in the elimination tree.
        // (`added[p]`: the last supernode given position `p`, which skips at once the
        // repetitions within a block of triplets.)
        let mut panel_rows: Vec<Vec<usize>> = vec![Vec::new(); n_super];
        let mut added = vec![usize::MAX; n];
        for &(i, j) in pattern {
            let (pi, pj) = (position[i], position[j]);
            let (ki, kj) = (supernode_at[pi], supernode_at[pj]);
            let (k, p) = match ki.cmp(&kj) {
                std::cmp::Ordering::Less => (ki, pj),
                std::cmp::Ordering::Greater => (kj, pi),
                std::cmp::Ordering::Equal => continue,
            };
            if added[p] != k {
                added[p] = k;
                panel_rows[k].push(p);
            }
        }
        for k in 0..n_super {
            let mut r = std::mem::take(&mut panel_rows[k]);
            r.sort_unstable();
            r.dedup();
            if let Some(&first) = r.first() {
                let parent = supernode_at[first];
                let parent_end = starts[parent + 1];
                panel_rows[parent].extend(r.iter().copied().filter(|&p| p >= parent_end));
            }
            panel_rows[k] = r;
        }

        // Storage.
        let mut rows = Vec::new();
        let mut supernodes = Vec::with_capacity(n_super);
        let (mut size_store, mut n_targets, mut n_magnitudes) = (0, 0, 0);
        for (k, &s) in order.iter().enumerate() {
            let (start, size) = (starts[k], starts[k + 1] - starts[k]);
            let r = panel_rows[k].len();
            let first = rows.len();
            rows.extend_from_slice(&panel_rows[k]);
            supernodes.push(Supernode {
                start,
                size,
                rows: first..rows.len(),
                diag: size_store,
                lower: size_store + size * size,
                upper: size_store + size * size + r * size,
                targets: n_targets,
                saddle: saddle_start[s],
                magnitude: n_magnitudes,
                saddle_targets: 0..0,
            });
            size_store += size * size + 2 * r * size;
            n_targets += r * r;
            n_magnitudes += size * (size - saddle_start[s]);
        }
        let mut lu = Self {
            unknown,
            supernodes,
            rows,
            targets: Vec::with_capacity(n_targets),
            store: vec![0.0; size_store],
            swaps: vec![0; n],
            column_max: vec![0.0; n],
            magnitudes: vec![0.0; n_magnitudes],
            saddle_targets: Vec::new(),
            work: vec![0.0; n],
            column: Vec::new(),
        };
        let mut max_rows = 0;
        for k in 0..n_super {
            let panel = lu.supernodes[k].rows.clone();
            let first = lu.saddle_targets.len();
            max_rows = max_rows.max(panel.len());
            for (b, &pb) in lu.rows[panel.clone()].iter().enumerate() {
                for (a, &pa) in lu.rows[panel.clone()].iter().enumerate() {
                    let t = lu.index(&supernode_at, pa, pb);
                    lu.targets.push(t);
                    if let Some(m) = lu.magnitude_index(&supernode_at, pa, pb) {
                        lu.saddle_targets.push((a + b * panel.len(), m));
                    }
                }
            }
            lu.supernodes[k].saddle_targets = first..lu.saddle_targets.len();
        }
        lu.column = vec![0.0; max_rows];
        let slots = pattern
            .iter()
            .map(|&(i, j)| lu.index(&supernode_at, position[i], position[j]))
            .collect();
        (lu, slots)
    }

    /// Storage index of the entry at positions `(pa, pb)` of the (filled) matrix.
    fn index(&self, supernode_at: &[usize], pa: usize, pb: usize) -> usize {
        let (ka, kb) = (supernode_at[pa], supernode_at[pb]);
        let panel_index = |k: usize, p: usize| {
            let rows = &self.rows[self.supernodes[k].rows.clone()];
            rows.binary_search(&p)
                .expect("the filled structure holds every update")
        };
        if ka == kb {
            let s = &self.supernodes[ka];
            s.diag + (pa - s.start) + (pb - s.start) * s.size
        } else if ka > kb {
            let s = &self.supernodes[kb];
            let r = s.rows.len();
            s.lower + panel_index(kb, pa) + (pb - s.start) * r
        } else {
            let s = &self.supernodes[ka];
            s.upper + (pa - s.start) + panel_index(ka, pb) * s.size
        }
    }

    /// Index in `magnitudes` of the entry at positions `(pa, pb)`, if it lies in a saddle
    /// column of a diagonal block.
    fn magnitude_index(&self, supernode_at: &[usize], pa: usize, pb: usize) -> Option<usize> {
        let k = supernode_at[pb];
        let s = &self.supernodes[k];
        let (i, j) = (pa.checked_sub(s.start)?, pb - s.start);
        (supernode_at[pa] == k && j >= s.saddle).then(|| s.magnitude + i + (j - s.saddle) * s.size)
    }

    /// Number of stored entries (diagonal blocks and panels, fill included).
    pub(super) fn stored(&self) -> usize {
        self.store.len()
    }

    /// Assembles and factorizes; returns what the singularity rule saw of the pivots.
    pub(super) fn factorize(
        &mut self,
        slots: &[usize],
        values: &[f64],
    ) -> Result<Pivots, Rejected> {
        super::sum_triplets(&mut self.store, slots, values);
        self.find_column_max()?;
        // |A| at the saddle columns of the diagonal blocks, to which each elimination adds its
        // |L| |U|.
        for sn in &self.supernodes {
            let (s, q) = (sn.size, sn.saddle);
            let block = &self.store[sn.diag + q * s..sn.diag + s * s];
            let magnitudes = &mut self.magnitudes[sn.magnitude..sn.magnitude + block.len()];
            for (m, a) in magnitudes.iter_mut().zip(block) {
                *m = a.abs();
            }
        }
        let mut pivots = Pivots::default();
        for k in 0..self.supernodes.len() {
            let sn = &self.supernodes[k];
            let (s, r, start, q) = (sn.size, sn.rows.len(), sn.start, sn.saddle);
            let (diag, lower, upper, targets) = (sn.diag, sn.lower, sn.upper, sn.targets);
            let magnitudes = &mut self.magnitudes[sn.magnitude..sn.magnitude + s * (s - q)];
            let saddle_targets = &self.saddle_targets[sn.saddle_targets.clone()];
            // This supernode's blocks, and the storage of the later ones (the updates').
            let (mine, later) = self.store.split_at_mut(upper + s * r);
            let (mine, u) = mine.split_at_mut(upper);
            let (d, l) = mine[diag..].split_at_mut(lower - diag);
            let block_max = d[..s * s]
                .iter()
                .chain(l.iter())
                .chain(u.iter())
                .fold(0.0f64, |m, x| m.max(x.abs()));
            // P D = L U with partial pivoting inside the block; the same interchanges on the
            // rows of the U panel.
            for c in 0..s {
                let p = (c..s)
                    .max_by(|&a, &b| d[a + c * s].abs().total_cmp(&d[b + c * s].abs()))
                    .expect("c < s");
                self.swaps[start + c] = p;
                if p != c {
                    for j in 0..s {
                        d.swap(c + j * s, p + j * s);
                    }
                    for j in 0..r {
                        u.swap(c + j * s, p + j * s);
                    }
                    for j in 0..s - q {
                        magnitudes.swap(c + j * s, p + j * s);
                    }
                }
                // The singularity rule (module documentation): a regular column's pivot
                // against its column of A, a saddle column's against |A| + |L| |U| at its
                // position.
                let pivot = d[c + c * s];
                let column = self.column_max[start + c];
                let scale = if c < q {
                    column
                } else {
                    magnitudes[c + (c - q) * s]
                };
                if !pivot.is_finite() || pivot.abs() <= super::PIVOT_TOLERANCE * scale {
                    return Err(Rejected);
                }
                pivots.add(pivot, column, scale);
                let inv = 1.0 / pivot;
                for i in c + 1..s {
                    d[i + c * s] *= inv;
                }
                for j in c + 1..s {
                    let f = d[c + j * s];
                    if f != 0.0 {
                        for i in c + 1..s {
                            d[i + j * s] -= d[i + c * s] * f;
                        }
                        if j >= q {
                            let m = &mut magnitudes[(j - q) * s..(j - q + 1) * s];
                            for i in c + 1..s {
                                m[i] += (d[i + c * s] * f).abs();
                            }
                        }
                    }
                }
            }
            // U panel := L_kk^-1 (P U panel).
            for col in u.chunks_exact_mut(s) {
                for c in 0..s {
                    let f = col[c];
                    if f != 0.0 {
                        for i in c + 1..s {
                            col[i] -= d[i + c * s] * f;
                        }
                    }
                }
            }
            // L panel := L panel U_kk^-1, column by column, and the growth of this
            // elimination (module documentation).
            let mut growth = 0.0f64;
            for c in 0..s {
                for t in 0..c {
                    let f = d[t + c * s];
                    if f != 0.0 {
                        let (done, rest) = l.split_at_mut(c * r);
                        for (x, &y) in rest[..r].iter_mut().zip(&done[t * r..(t + 1) * r]) {
                            *x -= y * f;
                        }
                    }
                }
                let inv = 1.0 / d[c + c * s];
                let mut l_max = 1.0f64;
                for x in &mut l[c * r..(c + 1) * r] {
                    *x *= inv;
                    l_max = l_max.max(x.abs());
                }
                let u_row = (c..s)
                    .map(|j| d[c + j * s])
                    .chain((0..r).map(|a| u[c + a * s]));
                let u_max = u_row.fold(0.0f64, |m, x| m.max(x.abs()));
                growth = growth.max(l_max * u_max);
            }
            let growth = growth / block_max;
            if growth.is_nan() || growth > GROWTH_LIMIT {
                return Err(Rejected);
            }
            // Update of the later blocks: S -= L U, one column at a time; |L| |U| added to the
            // magnitudes of the saddle columns it reaches.
            for &(e, m) in saddle_targets {
                let (a, b) = (e % r, e / r);
                let lu: f64 = (0..s).map(|c| (l[c * r + a] * u[c + b * s]).abs()).sum();
                self.magnitudes[m] += lu;
            }
            for b in 0..r {
                let column = &mut self.column[..r];
                column.fill(0.0);
                for c in 0..s {
                    let f = u[c + b * s];
                    if f != 0.0 {
                        for (x, &y) in column.iter_mut().zip(&l[c * r..(c + 1) * r]) {
                            *x += y * f;
                        }
                    }
                }
                let next = upper + s * r;
                for (&t, &x) in self.targets[targets + b * r..targets + (b + 1) * r]
                    .iter()
                    .zip(column.iter())
                {
                    later[t - next] -= x;
                }
            }
        }
        Ok(pivots)
    }

    /// The largest entry of each column of `A` (duplicates summed), the singularity rule's
    /// scale, from the assembled storage (the entries of the filled structure that are not
    /// in `A` hold 0); rejects a non-finite entry.
    fn find_column_max(&mut self) -> Result<(), Rejected> {
        self.column_max.fill(0.0);
        let column_max = &mut self.column_max;
        let mut take = |position: usize, entries: &[f64]| {
            let m = &mut column_max[position];
            for v in entries.iter().map(|v| v.abs()) {
                if !v.is_finite() {
                    return Err(Rejected);
                }
                *m = m.max(v);
            }
            Ok(())
        };
        for sn in &self.supernodes {
            let (s, r) = (sn.size, sn.rows.len());
            // Column-major: the diagonal block's and L's columns are the supernode's, U's
            // the panel rows'.
            let diag = self.store[sn.diag..sn.lower].chunks_exact(s);
            for (c, column) in diag.enumerate() {
                take(sn.start + c, column)?;
            }
            if r > 0 {
                for (c, column) in self.store[sn.lower..sn.upper].chunks_exact(r).enumerate() {
                    take(sn.start + c, column)?;
                }
            }
            let upper = self.store[sn.upper..sn.upper + s * r].chunks_exact(s);
            for (&p, column) in self.rows[sn.rows.clone()].iter().zip(upper) {
                take(p, column)?;
            }
        }
        Ok(())
    }

    /// The triplet positions `(i, j)` of the pattern whose storage indices are `slots` (as
    /// [`BlockLu::new`] returned them): the pattern of the general LU, built from them when
    /// it is first needed.
    pub(super) fn pattern(&self, slots: &[usize]) -> Vec<(usize, usize)> {
        let position = |t: usize| {
            let sn = &self.supernodes[self.supernodes.partition_point(|sn| sn.diag <= t) - 1];
            let (s, rows) = (sn.size, &self.rows[sn.rows.clone()]);
            if t < sn.lower {
                let o = t - sn.diag;
                (sn.start + o % s, sn.start + o / s)
            } else if t < sn.upper {
                let o = t - sn.lower;
                (rows[o % rows.len()], sn.start + o / rows.len())
            } else {
                let o = t - sn.upper;
                (sn.start + o % s, rows[o / s])
            }
        };
        slots
            .iter()
            .map(|&t| {
                let (pa, pb) = position(t);
                (self.unknown[pa], self.unknown[pb])
            })
            .collect()
    }

    /// Solves `A x = b` (`transpose = false`) or `A^T x = b` in place with the last
    /// factorization.
    ///
    /// With `Lt_kk = P_k^T L_kk`, `A = Lt U`. Forward: `y_k = L_kk^-1 P_k (b_k - sum_j L_kj
    /// y_j)`, backward: `x_k = U_kk^-1 (y_k - sum_j U_kj x_j)`. Transposed: `U^T z = b`
    /// forward, then `x_k = P_k^T L_kk^-T (z_k - sum_j L_jk^T x_j)` backward.
    pub(super) fn solve_in_place(&mut self, b: &mut [f64], transpose: bool) {
        let y = &mut self.work;
        for (p, &u) in self.unknown.iter().enumerate() {
            y[p] = b[u];
        }
        let store = &self.store;
        // Forward, in elimination order: each supernode's rows are final once the earlier
        // ones have passed their updates on.
        for sn in &self.supernodes {
            let (s, end) = (sn.size, sn.start + sn.size);
            let rows = &self.rows[sn.rows.clone()];
            let r = rows.len();
            let d = &store[sn.diag..sn.diag + s * s];
            let (head, later) = y.split_at_mut(end);
            let seg = &mut head[sn.start..];
            if transpose {
                // U_kk^T z_k = y_k (lower), then y_j -= U_kj^T z_k.
                for c in 0..s {
                    let dot: f64 = d[c * s..c * s + c]
                        .iter()
                        .zip(&seg[..c])
                        .map(|(a, z)| a * z)
                        .sum();
                    seg[c] = (seg[c] - dot) / d[c + c * s];
                }
                let u = &store[sn.upper..sn.upper + s * r];
                for (col, &p) in u.chunks_exact(s).zip(rows) {
                    let dot: f64 = col.iter().zip(seg.iter()).map(|(a, z)| a * z).sum();
                    later[p - end] -= dot;
                }
            } else {
                // y_k = L_kk^-1 P_k y_k, then y_j -= L_jk y_k.
                for c in 0..s {
                    seg.swap(c, self.swaps[sn.start + c]);
                }
                for c in 0..s {
                    let f = seg[c];
                    let (done, rest) = seg.split_at_mut(c + 1);
                    let _ = done;
                    for (x, &a) in rest.iter_mut().zip(&d[c * s + c + 1..(c + 1) * s]) {
                        *x -= a * f;
                    }
                }
                let l = &store[sn.lower..sn.lower + r * s];
                for (col, &f) in l.chunks_exact(r.max(1)).zip(seg.iter()) {
                    for (&p, &a) in rows.iter().zip(col) {
                        later[p - end] -= a * f;
                    }
                }
            }
        }
        // Backward, in reverse order: each supernode needs the later ones' solution.
        for sn in self.supernodes.iter().rev() {
            let (s, end) = (sn.size, sn.start + sn.size);
            let rows = &self.rows[sn.rows.clone()];
            let r = rows.len();
            let d = &store[sn.diag..sn.diag + s * s];
            let (head, later) = y.split_at_mut(end);
            let seg = &mut head[sn.start..];
            if transpose {
                // x_k = P_k^T L_kk^-T (z_k - L_jk^T x_j).
                let l = &store[sn.lower..sn.lower + r * s];
                for (col, x) in l.chunks_exact(r.max(1)).zip(seg.iter_mut()) {
                    let dot: f64 = col.iter().zip(rows).map(|(a, &p)| a * later[p - end]).sum();
                    *x -= dot;
                }
                for c in (0..s).rev() {
                    let dot: f64 = d[c * s + c + 1..(c + 1) * s]
                        .iter()
                        .zip(&seg[c + 1..])
                        .map(|(a, x)| a * x)
                        .sum();
                    seg[c] -= dot;
                }
                for c in (0..s).rev() {
                    seg.swap(c, self.swaps[sn.start + c]);
                }
            } else {
                // x_k = U_kk^-1 (y_k - U_kj x_j).
                let u = &store[sn.upper..sn.upper + s * r];
                for (col, &p) in u.chunks_exact(s).zip(rows) {
                    let f = later[p - end];
                    for (x, &a) in seg.iter_mut().zip(col) {
                        *x -= a * f;
                    }
                }
                for c in (0..s).rev() {
                    let v = seg[c] / d[c + c * s];
                    seg[c] = v;
                    for (x, &a) in seg[..c].iter_mut().zip(&d[c * s..c * s + c]) {
                        *x -= a * v;
                    }
                }
            }
        }
        for (p, &u) in self.unknown.iter().enumerate() {
            b[u] = y[p];
        }
    }
}

/// The sorted, deduplicated adjacency lists of a graph on `n` vertices given by its edges
/// (both directions added, loops left out). An edge repeating the last one added to its
/// first vertex is skipped at once: the triplets of a block all give the same edge, and the
/// lists stay as long as the graph's edges (not the matrix's entries) while they are built.
fn graph(n: usize, edges: impl Iterator<Item = (usize, usize)>) -> Vec<Vec<usize>> {
    let mut adjacency: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (a, b) in edges {
        if a != b && adjacency[a].last() != Some(&b) {
            adjacency[a].push(b);
            adjacency[b].push(a);
        }
    }
    for a in &mut adjacency {
        a.sort_unstable();
        a.dedup();
    }
    adjacency
}

/// The elimination order `order` of a graph rearranged into a post-order of its elimination
/// tree: each subtree contiguous, children before their parent. The fill is the same (Liu,
/// "The role of elimination trees in sparse factorization", SIAM J. Matrix Anal. Appl. 11,
/// 1990, Sect. 6), and a supernode's storage is next to its parent's, which keeps the
/// factorization and the solves in cache order on long chains (AMD alone interleaves the
/// two ends of a chain; on 10 000 links the scattered updates cost 10 times the
/// elimination).
fn postorder(adjacency: &[Vec<usize>], order: &[usize]) -> Vec<usize> {
    const NONE: usize = usize::MAX;
    let n = order.len();
    let mut rank = vec![0; n];
    for (k, &v) in order.iter().enumerate() {
        rank[v] = k;
    }
    // Elimination tree by path-compressed ancestors (Liu 1990, Sect. 5).
    let (mut parent, mut ancestor) = (vec![NONE; n], vec![NONE; n]);
    for &k in order {
        for &i in adjacency[k].iter().filter(|&&i| rank[i] < rank[k]) {
            let mut r = i;
            loop {
                let a = ancestor[r];
                if a == k {
                    break;
                }
                ancestor[r] = k;
                if a == NONE {
                    parent[r] = k;
                    break;
                }
                r = a;
            }
        }
    }
    let mut children = vec![Vec::new(); n];
    let mut roots = Vec::new();
    for &v in order {
        match parent[v] {
            NONE => roots.push(v),
            p => children[p].push(v),
        }
    }
    // Depth first, without recursion (a chain's tree is as deep as the chain is long).
    let mut out = Vec::with_capacity(n);
    let mut stack: Vec<(usize, usize)> = Vec::new();
    for &root in &roots {
        stack.push((root, 0));
        while let Some((v, next)) = stack.pop() {
            if let Some(&child) = children[v].get(next) {
                stack.push((v, next + 1));
                stack.push((child, 0));
            } else {
                out.push(v);
            }
        }
    }
    out
}

/// Approximate minimum degree order of a graph: `order[k]` is the vertex eliminated `k`-th.
fn amd_order(adjacency: &[Vec<usize>]) -> Vec<usize> {
    let n = adjacency.len();
    let mut col_ptr = Vec::with_capacity(n + 1);
    col_ptr.push(0);
    let mut row_idx = Vec::new();
    for a in adjacency {
        row_idx.extend_from_slice(a);
        col_ptr.push(row_idx.len());
    }
    let (mut perm, mut perm_inv) = (vec![0usize; n], vec![0usize; n]);
    let a = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    let mut mem = MemBuffer::new(amd::order_scratch::<usize>(n, row_idx.len()));
    match amd::order(
        &mut perm,
        &mut perm_inv,
        a,
        amd::Control::default(),
        MemStack::new(&mut mem),
    ) {
        Ok(_) => perm,
        // Only an index overflow can fail: keep the natural order.
        Err(_) => (0..n).collect(),
    }
}
