//! Linear solver for the Newton iterations of the implicit integrator.
//!
//! Every Newton iteration of the integrator solves `A dx = -r` with an
//! iteration matrix `A` whose sparsity pattern is fixed for the whole run
//! (it only depends on the model topology) while its values change at every
//! iteration. [`LinearSolver`] therefore separates the work in two phases:
//!
//! * [`LinearSolver::new`] / [`LinearSolver::with_backend`] receive the
//!   pattern as a list of `(row, col)` triplet positions (duplicates allowed,
//!   their values are summed), build the compressed storage and the map from
//!   triplet to storage slot once, and, for the sparse backend, run the
//!   symbolic analysis (COLAMD fill-reducing column ordering chosen by faer)
//!   once.
//! * [`LinearSolver::factorize`] scatters a new set of values into the
//!   preallocated storage and computes the numeric LU factorization, reusing
//!   all buffers; [`LinearSolver::solve_in_place`] and
//!   [`LinearSolver::solve_transpose_in_place`] then solve with `A` or `A^T`.
//!
//! # Backends
//!
//! * [`Backend::Dense`] (chosen by [`LinearSolver::new`] for `n <=`
//!   [`DENSE_MAX`]): the values are summed into a preallocated column-major
//!   `n x n` matrix that faer factors in place with partial pivoting
//!   (`PA = LU`); permutation and scratch memory are preallocated, so neither
//!   factorization nor solve allocates. Small systems (a few bodies and joints,
//!   6 to ~150 unknowns) are dominated by the fixed overhead of sparse
//!   machinery (a graph traversal per column, indirect addressing,
//!   permutations: about 0.5 us per unknown), while a dense LU of that size is
//!   cache-resident, vectorized arithmetic (about 1 us at 9 unknowns, 50 us at
//!   110).
//! * [`Backend::Sparse`]: left-looking (Gilbert-Peierls) simplicial sparse LU of
//!   faer with full partial pivoting on the rows and the COLAMD column ordering
//!   computed once. The iteration matrices of multibody dynamics are
//!   saddle-point matrices `[[S, B^T], [B, 0]]` with a zero diagonal block, so
//!   a factorization without row pivoting (or with a static pivot order) would
//!   break down; partial pivoting handles them. The `L`/`U` storage and the
//!   row permutation are reused between factorizations; they only grow if a
//!   new pivot sequence produces more fill than any previous one.
//!
//! * [`Backend::Block`] (chosen by [`LinearSolver::with_groups`] above [`DENSE_MAX`]
//!   unknowns, which is how the simulation builds its solver): the block LU of
//!   [`block`], on the groups of unknowns the model knows (a node's six increments, a
//!   joint's multipliers). It eliminates a mechanism's graph leaves first with dense
//!   supernode kernels and static pivoting inside supernodes, checked for growth; a
//!   matrix it rejects goes to the sparse LU above, built on first need, and after
//!   [`REJECTIONS_BEFORE_GENERAL`] rejections in a row the sparse LU keeps the work. On a
//!   1000-link chain it factorizes 3.1 times faster than the sparse LU and solves about
//!   as fast (`examples/linear_timing.rs`).
//!
//! # Singularity rule
//!
//! After the numeric factorization every pivot `u_kk` (diagonal of `U`) is
//! checked; the factorization is rejected with [`LinearError::Singular`] if a
//! pivot is exactly zero, non-finite, or `|u_kk| <= PIVOT_TOLERANCE * max_i
//! |a_ik|` (with [`PIVOT_TOLERANCE`] `= 1e-13`, relative to the largest
//! absolute entry of the pivot's own column of the assembled matrix, as the
//! block LU does for a node's columns; for a joint's multipliers, whose pivots
//! the elimination makes from nothing in their own diagonal block, the block LU
//! compares with the terms that formed the pivot instead, see [`block`]). A
//! matrix with a non-finite entry is rejected as well. The
//! reported column is the unknown (column of `A`) whose elimination produced
//! the bad pivot; it is `None` when no single unknown can be blamed (all-zero
//! matrix).
//!
//! The rule is relative to the column because partial pivoting is: scaling a
//! column of `A` (choosing another unit for one unknown) scales its pivot by the
//! same factor and changes neither the row interchanges nor the solution, so it
//! must not change the verdict either. A rule relative to the whole matrix
//! rejects well-posed systems whose unknowns differ in scale by many orders: the
//! force of a non-collocated servo constraint ([`crate::elements::control`])
//! enters the equilibrium rows, which are scaled by `1/(beta' m) ~ h^2`, while
//! its own row holds no entry in its column; on
//! `examples/servo_noncollocated.toml` its pivot is 1.6e-12, 5.0e-14 and 1.6e-15
//! times the largest entry of the matrix at `h` = 2e-3, 1e-3 and 5e-4 (as `h^5`),
//! but 8.0e-7, 1.0e-7 and 1.3e-8 times the largest entry of its own column (as
//! `h^3`: the force reaches the prescribed coordinate through the spring, whose
//! entries in the scaled matrix are `h^2` times the masses', and the servo's
//! position-level row weighs `h`). A singular matrix
//! (redundant rows, a node without mass) still leaves a pivot at the rounding
//! level of its column, or zero. [`LinearSolver::min_pivot_ratio`] stays
//! relative to the whole matrix on the dense and sparse backends.
//!
//! Faer's numeric LU routines do not report small or zero pivots themselves
//! (they divide by them and carry on), which is why the check is done here on
//! the factors, and why the sparse backend uses the simplicial LU, whose `U`
//! factor is accessible (faer's supernodal LU hides its factors; it factors a
//! 1000-body chain about 1.6x faster but solves 2x slower).

pub mod block;

pub use block::{GroupKind, Groups, GROWTH_LIMIT};

use block::BlockLu;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::lu::partial_pivoting::{factor as dense_factor, solve as dense_solve};
use faer::perm::PermRef;
use faer::sparse::linalg::lu::{factorize_symbolic_lu, simplicial, LuSymbolicParams, SymbolicLu};
use faer::sparse::linalg::{LuError, SupernodalThreshold};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, MatRef, Par};

/// Largest number of unknowns for which [`LinearSolver::new`] picks the dense
/// backend.
///
/// Measured on 2 cores (release, see `examples/linear_timing.rs`): on the
/// sparsest realistic topology, a chain of bodies (block-tridiagonal, 11
/// unknowns per body and joint), the sparse LU catches up with the dense one
/// around 90 unknowns and is 2x faster at 154; on patterns with more fill
/// (random 5-30 % density) the dense LU is 4-10x faster than the sparse one at
/// 120-150 unknowns. 150 bounds the loss in the first case and keeps the large
/// gain in the second.
pub const DENSE_MAX: usize = 150;

/// Relative pivot tolerance: a pivot with `|pivot| <= PIVOT_TOLERANCE * max
/// |a_ij|` is treated as zero and the matrix is reported singular.
pub const PIVOT_TOLERANCE: f64 = 1e-13;

/// Which backend a solver uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Dense,
    Sparse,
    /// The block LU of the model's groups of unknowns ([`block`]), with the sparse LU as
    /// fallback.
    Block,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinearError {
    #[error("the iteration matrix is singular (zero or tiny pivot{})", .column.map(|c| format!(" at unknown {c}")).unwrap_or_default())]
    Singular { column: Option<usize> },
    #[error("sparse factorization failed: {0}")]
    Factorization(String),
}

/// Square n x n matrix with a fixed pattern given as a list of (row, col)
/// triplet positions (duplicates allowed: their values are summed). Values are
/// supplied per factorization in the same order as the pattern.
pub struct LinearSolver {
    n: usize,
    /// `slots[k]`: storage index (dense: column-major `i + j * n`; sparse:
    /// position in the CSC value array) receiving the k-th triplet value.
    slots: Vec<usize>,
    factorizations: usize,
    /// Whether the last call to `factorize` succeeded.
    factorized: bool,
    /// The pivots of the last successful factorization.
    pivots: Pivots,
    inner: Inner,
}

/// What a backend's factorization gives: the pivots the singularity rule saw, or the
/// error.
type Factorized = Result<Pivots, LinearError>;

/// What the singularity rule saw of the pivots of a factorization.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pivots {
    /// The smallest `|pivot|` relative to its reference ([`LinearSolver::min_pivot_ratio`]).
    ratio: f64,
    /// The smallest `|pivot| / (PIVOT_TOLERANCE * scale)`, with the scale the rule judged it
    /// against ([`LinearSolver::pivot_margin`]).
    margin: f64,
}

impl Default for Pivots {
    fn default() -> Self {
        Self {
            ratio: f64::INFINITY,
            margin: f64::INFINITY,
        }
    }
}

impl Pivots {
    /// Takes in an accepted pivot, its reference for the ratio and its rule's scale.
    fn add(&mut self, pivot: f64, reference: f64, scale: f64) {
        self.ratio = self.ratio.min(pivot.abs() / reference);
        self.margin = self.margin.min(pivot.abs() / (PIVOT_TOLERANCE * scale));
    }
}

enum Inner {
    Dense(DenseLu),
    Sparse(Box<SparseLu>),
    Block(Box<BlockBackend>),
}

/// The block LU and the general sparse LU it hands the matrices it rejects to.
struct BlockBackend {
    block: BlockLu,
    /// The general LU (built on the first rejection, on the pattern the block LU recovers
    /// from its storage indices) and the CSC position of each triplet.
    general: Option<(Vec<usize>, Box<SparseLu>)>,
    /// Rejections in a row; from [`REJECTIONS_BEFORE_GENERAL`] on, the block LU is no
    /// longer tried.
    rejections: usize,
    /// Whether the last factorization is the general LU's.
    general_active: bool,
}

/// Consecutive rejections by the block LU after which the solver keeps the general LU
/// (matrices whose diagonal blocks stay singular, e.g. the statics of a rigid mechanism).
pub const REJECTIONS_BEFORE_GENERAL: usize = 3;

struct DenseLu {
    /// Column-major `n x n` matrix, overwritten by its LU factors.
    lu: Vec<f64>,
    /// The largest `|a_ij|` of each column `j` of the assembled matrix (`n`).
    column_max: Vec<f64>,
    perm_fwd: Vec<usize>,
    perm_inv: Vec<usize>,
    mem: MemBuffer,
}

struct SparseLu {
    /// CSC pattern of `A` (sorted, duplicates merged).
    pattern: SymbolicSparseColMat<usize>,
    /// CSC values of `A`.
    values: Vec<f64>,
    /// Symbolic analysis: holds the fill-reducing column permutation.
    symbolic: SymbolicLu<usize>,
    lu: simplicial::SimplicialLu<usize, f64>,
    row_perm_fwd: Vec<usize>,
    row_perm_inv: Vec<usize>,
    mem: MemBuffer,
}

impl LinearSolver {
    /// Chooses [`Backend::Dense`] when `n <= DENSE_MAX`, [`Backend::Sparse`]
    /// otherwise.
    ///
    /// # Panics
    /// If a pattern entry lies outside the `n x n` matrix.
    pub fn new(n: usize, pattern: &[(usize, usize)]) -> Result<Self, LinearError> {
        let backend = if n <= DENSE_MAX {
            Backend::Dense
        } else {
            Backend::Sparse
        };
        Self::with_backend(n, pattern, backend)
    }

    /// Chooses [`Backend::Dense`] when `n <= DENSE_MAX`, [`Backend::Block`] on the given
    /// groups of unknowns otherwise.
    ///
    /// # Panics
    /// If a pattern entry or a group member lies outside the `n x n` matrix.
    pub fn with_groups(
        n: usize,
        pattern: &[(usize, usize)],
        groups: &Groups,
    ) -> Result<Self, LinearError> {
        let backend = if n <= DENSE_MAX {
            Backend::Dense
        } else {
            Backend::Block
        };
        Self::build(n, pattern, backend, groups)
    }

    /// Builds a solver with an explicit backend (the block backend with every unknown a
    /// group of its own). For the sparse and block backends this performs the symbolic
    /// analysis (fill-reducing ordering).
    ///
    /// # Panics
    /// If a pattern entry lies outside the `n x n` matrix.
    pub fn with_backend(
        n: usize,
        pattern: &[(usize, usize)],
        backend: Backend,
    ) -> Result<Self, LinearError> {
        Self::build(n, pattern, backend, &Groups::default())
    }

    /// Builds a solver with an explicit backend and, for the block backend, groups.
    ///
    /// # Panics
    /// If a pattern entry or a group member lies outside the `n x n` matrix.
    pub fn build(
        n: usize,
        pattern: &[(usize, usize)],
        backend: Backend,
        groups: &Groups,
    ) -> Result<Self, LinearError> {
        for (k, &(i, j)) in pattern.iter().enumerate() {
            assert!(
                i < n && j < n,
                "pattern entry {k} = ({i}, {j}) outside the {n} x {n} matrix"
            );
        }
        let (slots, inner) = match backend {
            Backend::Dense => {
                let slots = pattern.iter().map(|&(i, j)| i + j * n).collect();
                let req = StackReq::any_of(&[
                    dense_factor::lu_in_place_scratch::<usize, f64>(
                        n,
                        n,
                        Par::Seq,
                        Default::default(),
                    ),
                    dense_solve::solve_in_place_scratch::<usize, f64>(n, 1, Par::Seq),
                    dense_solve::solve_transpose_in_place_scratch::<usize, f64>(n, 1, Par::Seq),
                ]);
                let dense = DenseLu {
                    lu: vec![0.0; n * n],
                    column_max: vec![0.0; n],
                    perm_fwd: (0..n).collect(),
                    perm_inv: (0..n).collect(),
                    mem: MemBuffer::new(req),
                };
                (slots, Inner::Dense(dense))
            }
            Backend::Sparse => {
                let (slots, sparse) = SparseLu::new(n, pattern)?;
                (slots, Inner::Sparse(Box::new(sparse)))
            }
            Backend::Block => {
                let (block, slots) = BlockLu::new(n, pattern, groups);
                let backend = BlockBackend {
                    block,
                    general: None,
                    rejections: 0,
                    general_active: false,
                };
                (slots, Inner::Block(Box::new(backend)))
            }
        };
        Ok(Self {
            n,
            slots,
            factorizations: 0,
            factorized: false,
            pivots: Pivots::default(),
            inner,
        })
    }

    /// The backend in use.
    pub fn backend(&self) -> Backend {
        match self.inner {
            Inner::Dense(_) => Backend::Dense,
            Inner::Sparse(_) => Backend::Sparse,
            Inner::Block(_) => Backend::Block,
        }
    }

    /// Number of unknowns.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of triplet positions of the pattern (the expected length of the
    /// `values` passed to [`factorize`](Self::factorize)).
    pub fn pattern_len(&self) -> usize {
        self.slots.len()
    }

    /// The triplet positions `(i, j)` the solver was built on, recovered from their storage
    /// indices (the solver keeps no second copy: on large models the pattern is a quarter
    /// of the memory, [`crate::data::Data::pattern`]).
    pub fn pattern(&self) -> Vec<(usize, usize)> {
        match &self.inner {
            Inner::Dense(_) => self
                .slots
                .iter()
                .map(|&s| (s % self.n, s / self.n))
                .collect(),
            Inner::Sparse(s) => {
                let (col_ptr, row_idx) = (s.pattern.col_ptr(), s.pattern.row_idx());
                self.slots
                    .iter()
                    .map(|&k| (row_idx[k], col_ptr.partition_point(|&p| p <= k) - 1))
                    .collect()
            }
            Inner::Block(b) => b.block.pattern(&self.slots),
        }
    }

    /// Number of structurally distinct nonzeros of the matrix (duplicates
    /// merged; for the dense backend `n * n`).
    pub fn nnz(&self) -> usize {
        match &self.inner {
            Inner::Dense(_) => self.n * self.n,
            Inner::Sparse(s) => s.values.len(),
            Inner::Block(b) => b.block.stored(),
        }
    }

    /// Whether the last call to [`factorize`](Self::factorize) succeeded, i.e.
    /// whether the solve functions can be used.
    pub fn is_factorized(&self) -> bool {
        self.factorized
    }

    /// `min_k |u_kk| / max_ij |a_ij|` of the last successful factorization
    /// (`None` before any; the block LU divides each pivot by the largest entry of its
    /// own column instead, see [`block`]). A cheap conditioning indicator: a sudden fall
    /// announces a nearly singular iteration matrix (the singularity rule itself compares
    /// each pivot with its own column, so a matrix whose unknowns differ in scale by many
    /// orders is accepted with a ratio below [`PIVOT_TOLERANCE`]).
    pub fn min_pivot_ratio(&self) -> Option<f64> {
        self.factorized.then_some(self.pivots.ratio)
    }

    /// How far the last successful factorization was from being called singular: the
    /// smallest `|u_kk| / (PIVOT_TOLERANCE * scale_k)` over its pivots, with `scale_k` what
    /// the singularity rule compared the pivot with (the largest entry of its column of `A`;
    /// for the block LU's saddle columns `|A| + |L| |U|` at the pivot, see [`block`]). Above
    /// 1 for every accepted factorization; `None` before any.
    pub fn pivot_margin(&self) -> Option<f64> {
        self.factorized.then_some(self.pivots.margin)
    }

    /// Numeric factorization with the given values (`values.len() ==
    /// pattern.len()`, duplicates summed). Does not allocate in the steady
    /// state. Returns [`LinearError::Singular`] on a zero, non-finite or tiny
    /// pivot (see the module documentation); the solver then has no usable
    /// factorization until the next successful call.
    ///
    /// # Panics
    /// If `values.len()` differs from the pattern length.
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), LinearError> {
        assert_eq!(
            values.len(),
            self.slots.len(),
            "factorize: {} values for a pattern of {} entries",
            values.len(),
            self.slots.len()
        );
        self.factorizations += 1;
        self.factorized = false;
        let n = self.n;
        if n == 0 {
            self.factorized = true;
            self.pivots = Pivots::default();
            return Ok(());
        }
        self.pivots = match &mut self.inner {
            Inner::Dense(d) => d.factorize(n, &self.slots, values)?,
            Inner::Sparse(s) => s.factorize(n, &self.slots, values)?,
            Inner::Block(b) => b.factorize(n, &self.slots, values)?,
        };
        self.factorized = true;
        Ok(())
    }

    /// Solve `A x = b` in place (`b` overwritten by `x`) with the last
    /// factorization.
    ///
    /// # Panics
    /// If `b.len() != n` or if there is no successful factorization.
    pub fn solve_in_place(&mut self, b: &mut [f64]) {
        self.solve_impl(b, false);
    }

    /// Solve `A^T x = b` in place (`b` overwritten by `x`) with the last
    /// factorization (for adjoint sensitivity analysis).
    ///
    /// # Panics
    /// If `b.len() != n` or if there is no successful factorization.
    pub fn solve_transpose_in_place(&mut self, b: &mut [f64]) {
        self.solve_impl(b, true);
    }

    /// Number of numeric factorizations done so far (every call to
    /// [`factorize`](Self::factorize), including those reporting a singular
    /// matrix).
    pub fn factorizations(&self) -> usize {
        self.factorizations
    }

    fn solve_impl(&mut self, b: &mut [f64], transpose: bool) {
        let n = self.n;
        assert_eq!(
            b.len(),
            n,
            "solve: right-hand side of length {} for n = {n}",
            b.len()
        );
        assert!(
            self.factorized,
            "solve called without a successful factorization"
        );
        if n == 0 {
            return;
        }
        match &mut self.inner {
            Inner::Dense(d) => {
                let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
                let lu = MatRef::from_column_major_slice(&d.lu, n, n);
                let perm = PermRef::new_checked(&d.perm_fwd, &d.perm_inv, n);
                let stack = MemStack::new(&mut d.mem);
                // L (unit lower) and U (upper) share the same storage; the
                // triangular solves only read their own triangle.
                if transpose {
                    dense_solve::solve_transpose_in_place_with_conj(
                        lu,
                        lu,
                        perm,
                        Conj::No,
                        rhs,
                        Par::Seq,
                        stack,
                    );
                } else {
                    dense_solve::solve_in_place_with_conj(
                        lu,
                        lu,
                        perm,
                        Conj::No,
                        rhs,
                        Par::Seq,
                        stack,
                    );
                }
            }
            Inner::Sparse(s) => s.solve(n, b, transpose),
            Inner::Block(block) => match &mut block.general {
                Some((_, general)) if block.general_active => general.solve(n, b, transpose),
                _ => block.block.solve_in_place(b, transpose),
            },
        }
    }
}

impl DenseLu {
    /// Assembles, factors and checks the pivots.
    fn factorize(&mut self, n: usize, slots: &[usize], values: &[f64]) -> Factorized {
        sum_triplets(&mut self.lu, slots, values);
        // Entries outside the pattern are zero: the pattern slots suffice.
        let max_bits = slots.iter().map(|&s| abs_bits(self.lu[s])).max();
        let max_abs = check_max_abs(max_bits, || {
            slots
                .iter()
                .find(|&&s| !self.lu[s].is_finite())
                .map(|&s| s / n)
        })?;
        self.column_max.fill(0.0);
        for &s in slots {
            let m = &mut self.column_max[s / n];
            *m = m.max(self.lu[s].abs());
        }
        let stack = MemStack::new(&mut self.mem);
        dense_factor::lu_in_place(
            MatMut::from_column_major_slice_mut(&mut self.lu, n, n),
            &mut self.perm_fwd,
            &mut self.perm_inv,
            Par::Seq,
            stack,
            Default::default(),
        );
        let mut pivots = Pivots::default();
        for k in 0..n {
            let pivot = self.lu[k + k * n];
            check_pivot(pivot, (self.column_max[k], max_abs), k, &mut pivots)?;
        }
        Ok(pivots)
    }
}

impl SparseLu {
    /// `A x = b` or `A^T x = b` in place with the last factorization.
    fn solve(&mut self, n: usize, b: &mut [f64], transpose: bool) {
        let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
        let row_perm = PermRef::new_checked(&self.row_perm_fwd, &self.row_perm_inv, n);
        let col_perm = self.symbolic.col_perm();
        let stack = MemStack::new(&mut self.mem);
        if transpose {
            self.lu.solve_transpose_in_place_with_conj(
                row_perm,
                col_perm,
                Conj::No,
                rhs,
                Par::Seq,
                stack,
            );
        } else {
            self.lu
                .solve_in_place_with_conj(row_perm, col_perm, Conj::No, rhs, Par::Seq, stack);
        }
    }

    /// Compresses the pattern and runs the symbolic analysis; returns the CSC position of
    /// each triplet beside the solver.
    fn new(n: usize, pattern: &[(usize, usize)]) -> Result<(Vec<usize>, Self), LinearError> {
        let (col_ptr, row_idx, slots) = compress_pattern(n, pattern);
        let nnz = row_idx.len();
        let pattern = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let params = LuSymbolicParams {
            // The simplicial LU exposes U, needed for the pivot check.
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_lu(pattern.as_ref(), params)
            .map_err(|e| LinearError::Factorization(format!("{e:?}")))?;
        let req = StackReq::any_of(&[
            simplicial::factorize_simplicial_numeric_lu_scratch::<usize, f64>(n, n),
            simplicial::solve_in_place_scratch::<usize, f64>(n, 1, Par::Seq),
            simplicial::solve_transpose_in_place_scratch::<usize, f64>(n, 1, Par::Seq),
        ]);
        let sparse = SparseLu {
            pattern,
            values: vec![0.0; nnz],
            symbolic,
            lu: simplicial::SimplicialLu::new(),
            row_perm_fwd: (0..n).collect(),
            row_perm_inv: (0..n).collect(),
            mem: MemBuffer::try_new(req).map_err(|_| {
                LinearError::Factorization("out of memory for the LU scratch".into())
            })?,
        };
        Ok((slots, sparse))
    }

    /// Assembles, factors and checks the pivots.
    fn factorize(&mut self, n: usize, slots: &[usize], values: &[f64]) -> Factorized {
        sum_triplets(&mut self.values, slots, values);
        let max_bits = self.values.iter().map(|&v| abs_bits(v)).max();
        let max_abs = check_max_abs(max_bits, || {
            let k = self.values.iter().position(|v| !v.is_finite())?;
            Some(self.pattern.col_ptr().partition_point(|&p| p <= k) - 1)
        })?;
        let col_perm = self.symbolic.col_perm();
        let stack = MemStack::new(&mut self.mem);
        let a = SparseColMatRef::new(self.pattern.as_ref(), &self.values);
        simplicial::factorize_simplicial_numeric_lu(
            &mut self.row_perm_fwd,
            &mut self.row_perm_inv,
            &mut self.lu,
            a,
            col_perm,
            stack,
        )
        .map_err(|e| match e {
            LuError::SymbolicSingular { index } => LinearError::Singular {
                column: Some(col_perm.arrays().0[index]),
            },
            LuError::Generic(e) => LinearError::Factorization(format!("{e:?}")),
        })?;
        // Column j of U holds the pivot of the j-th eliminated column (the
        // original column col_perm[j]) as its entry in row j.
        let u = self.lu.u_factor_unsorted();
        let a_col_ptr = self.pattern.col_ptr();
        let mut pivots = Pivots::default();
        for j in 0..n {
            let pivot = u
                .row_idx_of_col_raw(j)
                .iter()
                .zip(u.val_of_col(j))
                .rev()
                .find(|(&i, _)| i == j)
                .map_or(0.0, |(_, &v)| v);
            let column = col_perm.arrays().0[j];
            let col = &self.values[a_col_ptr[column]..a_col_ptr[column + 1]];
            let column_max = col.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            check_pivot(pivot, (column_max, max_abs), column, &mut pivots)?;
        }
        Ok(pivots)
    }
}

impl BlockBackend {
    /// The block LU, or the general LU for a matrix the block LU rejects (see
    /// [`REJECTIONS_BEFORE_GENERAL`]).
    fn factorize(&mut self, n: usize, slots: &[usize], values: &[f64]) -> Factorized {
        self.general_active = false;
        if self.rejections < REJECTIONS_BEFORE_GENERAL {
            match self.block.factorize(slots, values) {
                Ok(pivots) => {
                    self.rejections = 0;
                    return Ok(pivots);
                }
                Err(block::Rejected) => self.rejections += 1,
            }
        }
        if self.general.is_none() {
            let (slots, sparse) = SparseLu::new(n, &self.block.pattern(slots))?;
            self.general = Some((slots, Box::new(sparse)));
        }
        let (general_slots, general) = self.general.as_mut().expect("built above");
        let pivots = general.factorize(n, general_slots, values)?;
        self.general_active = true;
        Ok(pivots)
    }
}

/// Bit pattern of `|v|`. For non-negative IEEE doubles the integer order of
/// the bit patterns is the numeric order, and every non-finite value (inf,
/// NaN) has a larger pattern than any finite one, so a plain integer maximum
/// gives both the largest magnitude and a finiteness check, without the
/// NaN-handling branches of `f64::max`.
fn abs_bits(v: f64) -> u64 {
    v.to_bits() & !(1u64 << 63)
}

/// Turns the maximum of [`abs_bits`] over the matrix entries into the largest
/// absolute entry. A non-finite entry is reported as singular at the column
/// found by `non_finite_column` (only evaluated on that error path), an
/// all-zero (or empty) matrix as singular without a column.
fn check_max_abs(
    max_bits: Option<u64>,
    non_finite_column: impl FnOnce() -> Option<usize>,
) -> Result<f64, LinearError> {
    const INF_BITS: u64 = 0x7ff0_0000_0000_0000;
    match max_bits {
        Some(bits) if bits >= INF_BITS => Err(LinearError::Singular {
            column: non_finite_column(),
        }),
        Some(bits) if bits > 0 => Ok(f64::from_bits(bits)),
        _ => Err(LinearError::Singular { column: None }),
    }
}

/// The matrix of the triplets `values` in `storage`: each added at its slot, in the order of
/// the triplets (duplicates summed), every other entry zero.
fn sum_triplets(storage: &mut [f64], slots: &[usize], values: &[f64]) {
    storage.fill(0.0);
    for (&s, &v) in slots.iter().zip(values) {
        storage[s] += v;
    }
}

/// Applies the singularity rule to one pivot of the column whose largest entry is
/// `column_max` and adds it to `pivots` (its ratio relative to `max_abs`, the largest entry
/// of the matrix).
fn check_pivot(
    pivot: f64,
    (column_max, max_abs): (f64, f64),
    column: usize,
    pivots: &mut Pivots,
) -> Result<(), LinearError> {
    if !pivot.is_finite() || pivot.abs() <= PIVOT_TOLERANCE * column_max {
        return Err(LinearError::Singular {
            column: Some(column),
        });
    }
    pivots.add(pivot, max_abs, column_max);
    Ok(())
}

/// Compresses a triplet pattern to CSC (rows sorted within each column,
/// duplicates merged). Returns `(col_ptr, row_idx, slots)` where `slots[k]` is
/// the CSC position of the k-th triplet. Linear in the number of triplets: a
/// counting sort by column, then a sort of each (short) column by row.
fn compress_pattern(n: usize, pattern: &[(usize, usize)]) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
    // Triplet indices bucketed by column.
    let mut start = vec![0usize; n + 1];
    for &(_, j) in pattern {
        start[j + 1] += 1;
    }
    for j in 0..n {
        start[j + 1] += start[j];
    }
    let mut order = vec![0usize; pattern.len()];
    let mut next = start.clone();
    for (k, &(_, j)) in pattern.iter().enumerate() {
        order[next[j]] = k;
        next[j] += 1;
    }
    let mut col_ptr = vec![0usize; n + 1];
    let mut row_idx = Vec::with_capacity(pattern.len());
    let mut slots = vec![0usize; pattern.len()];
    for j in 0..n {
        let column = &mut order[start[j]..start[j + 1]];
        column.sort_unstable_by_key(|&k| pattern[k].0);
        let mut last = None;
        for &k in column.iter() {
            let i = pattern[k].0;
            if last != Some(i) {
                row_idx.push(i);
                last = Some(i);
            }
            slots[k] = row_idx.len() - 1;
        }
        col_ptr[j + 1] = row_idx.len();
    }
    (col_ptr, row_idx, slots)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Minimal deterministic linear congruential generator (Knuth MMIX).
    struct Lcg(u64);

    impl Lcg {
        fn next_u64(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            self.0
        }
        /// Uniform in [0, 1).
        fn next_f64(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next_f64()
        }
        fn below(&mut self, n: usize) -> usize {
            ((self.next_u64() >> 33) % n as u64) as usize
        }
    }

    struct System {
        n: usize,
        pattern: Vec<(usize, usize)>,
        values: Vec<f64>,
    }

    /// Random well-conditioned, nonsymmetric sparse saddle-point matrix
    /// `[[S, G^T], [B, 0]]` with `ns` primal unknowns and `nc` constraints:
    /// `S` strictly diagonally dominant, `B` full row rank (one dominant entry
    /// per row in distinct columns), `G = B + small perturbation`.
    fn saddle_system(ns: usize, nc: usize, seed: u64) -> System {
        assert!(nc <= ns);
        let mut rng = Lcg(seed);
        let n = ns + nc;
        let mut pattern = Vec::new();
        let mut values = Vec::new();
        for i in 0..ns {
            let mut off_sum = 0.0;
            for _ in 0..3 {
                let j = rng.below(ns);
                if j != i {
                    let v = rng.uniform(-1.0, 1.0);
                    off_sum += f64::abs(v);
                    pattern.push((i, j));
                    values.push(v);
                }
            }
            pattern.push((i, i));
            values.push(2.0 + off_sum + rng.next_f64());
        }
        for r in 0..nc {
            let mut cols = vec![(
                r * ns / nc,
                rng.uniform(1.0, 2.0) * if rng.below(2) == 0 { 1.0 } else { -1.0 },
            )];
            for _ in 0..2 {
                let c = rng.below(ns);
                if cols.iter().all(|&(cc, _)| cc != c) {
                    cols.push((c, rng.uniform(-0.2, 0.2)));
                }
            }
            for (c, v) in cols {
                pattern.push((ns + r, c));
                values.push(v);
                pattern.push((c, ns + r));
                values.push(v + rng.uniform(-0.05, 0.05));
            }
        }
        System { n, pattern, values }
    }

    fn matvec(
        n: usize,
        pattern: &[(usize, usize)],
        values: &[f64],
        x: &[f64],
        transpose: bool,
    ) -> Vec<f64> {
        let mut y = vec![0.0; n];
        for (&(i, j), &v) in pattern.iter().zip(values) {
            if transpose {
                y[j] += v * x[i];
            } else {
                y[i] += v * x[j];
            }
        }
        y
    }

    fn norm_inf(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |m, x| f64::max(m, x.abs()))
    }

    fn random_rhs(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Lcg(seed);
        (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect()
    }

    /// The solution of `A x = b` (of `A^T x = b` if `transpose`) with `solver`'s factors.
    fn solved(solver: &mut LinearSolver, b: &[f64], transpose: bool) -> Vec<f64> {
        let mut x = b.to_vec();
        if transpose {
            solver.solve_transpose_in_place(&mut x);
        } else {
            solver.solve_in_place(&mut x);
        }
        x
    }

    /// Solves with the given backend and returns x, checking the relative
    /// residual.
    fn solve_checked(sys: &System, backend: Backend, b: &[f64], transpose: bool) -> Vec<f64> {
        let mut solver = LinearSolver::with_backend(sys.n, &sys.pattern, backend).unwrap();
        assert_eq!(solver.backend(), backend);
        solver.factorize(&sys.values).unwrap();
        let x = solved(&mut solver, b, transpose);
        assert!(x.iter().all(|v| v.is_finite()));
        let ax = matvec(sys.n, &sys.pattern, &sys.values, &x, transpose);
        let res: Vec<f64> = ax.iter().zip(b).map(|(a, b)| a - b).collect();
        let a_norm = norm_inf(&sys.values) * 8.0;
        let rel = norm_inf(&res) / (a_norm * norm_inf(&x) + norm_inf(b));
        assert!(
            rel < 1e-13,
            "{backend:?} transpose={transpose}: relative residual {rel:e}"
        );
        x
    }

    fn assert_close(x: &[f64], y: &[f64], tol: f64) {
        let diff: Vec<f64> = x.iter().zip(y).map(|(a, b)| a - b).collect();
        let rel = norm_inf(&diff) / norm_inf(x);
        assert!(rel < tol, "solutions differ: relative {rel:e}");
    }

    fn both_backends_agree(ns: usize, nc: usize, seed: u64) {
        let sys = saddle_system(ns, nc, seed);
        let b = random_rhs(sys.n, seed + 1);
        for transpose in [false, true] {
            let xd = solve_checked(&sys, Backend::Dense, &b, transpose);
            let xs = solve_checked(&sys, Backend::Sparse, &b, transpose);
            assert_close(&xd, &xs, 1e-10);
            let xb = solve_checked(&sys, Backend::Block, &b, transpose);
            assert_close(&xd, &xb, 1e-10);
        }
    }

    #[test]
    fn dense_size_saddle_point_both_backends() {
        both_backends_agree(14, 6, 1);
        both_backends_agree(6, 3, 7);
    }

    #[test]
    fn sparse_size_saddle_point_both_backends() {
        both_backends_agree(300, 100, 2);
    }

    #[test]
    fn new_picks_backend_by_size() {
        let small = saddle_system(14, 6, 3);
        assert_eq!(
            LinearSolver::new(small.n, &small.pattern)
                .unwrap()
                .backend(),
            Backend::Dense
        );
        let large = saddle_system(300, 100, 4);
        let solver = LinearSolver::new(large.n, &large.pattern).unwrap();
        assert_eq!(solver.backend(), Backend::Sparse);
        assert_eq!(solver.n(), 400);
        assert_eq!(solver.pattern_len(), large.pattern.len());
        let edge = saddle_system(DENSE_MAX - 50, 50, 5);
        assert_eq!(
            LinearSolver::new(edge.n, &edge.pattern).unwrap().backend(),
            Backend::Dense
        );
        let edge = saddle_system(DENSE_MAX - 49, 50, 5);
        assert_eq!(
            LinearSolver::new(edge.n, &edge.pattern).unwrap().backend(),
            Backend::Sparse
        );
    }

    #[test]
    fn duplicates_are_summed() {
        for (ns, nc) in [(14, 6), (300, 100)] {
            let sys = saddle_system(ns, nc, 11);
            let b = random_rhs(sys.n, 12);
            // Split every value into two duplicated entries, in a shuffled
            // order.
            let mut rng = Lcg(13);
            let mut entries: Vec<((usize, usize), f64)> = Vec::new();
            for (&p, &v) in sys.pattern.iter().zip(&sys.values) {
                let w = rng.uniform(-1.0, 1.0);
                entries.push((p, w));
                entries.push((p, v - w));
            }
            for k in (1..entries.len()).rev() {
                entries.swap(k, rng.below(k + 1));
            }
            let dup = System {
                n: sys.n,
                pattern: entries.iter().map(|e| e.0).collect(),
                values: entries.iter().map(|e| e.1).collect(),
            };
            for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
                let x = solve_checked(&sys, backend, &b, false);
                let mut solver = LinearSolver::with_backend(dup.n, &dup.pattern, backend).unwrap();
                assert_eq!(solver.pattern_len(), 2 * sys.pattern.len());
                if backend != Backend::Dense {
                    // Same merged structure as the original pattern.
                    let reference =
                        LinearSolver::with_backend(sys.n, &sys.pattern, backend).unwrap();
                    assert_eq!(solver.nnz(), reference.nnz());
                }
                solver.factorize(&dup.values).unwrap();
                let mut y = b.clone();
                solver.solve_in_place(&mut y);
                assert_close(&x, &y, 1e-10);
            }
        }
    }

    #[test]
    fn transpose_solve_matches_explicit_transpose() {
        for (ns, nc) in [(14, 6), (300, 100)] {
            let sys = saddle_system(ns, nc, 21);
            let b = random_rhs(sys.n, 22);
            let transposed = System {
                n: sys.n,
                pattern: sys.pattern.iter().map(|&(i, j)| (j, i)).collect(),
                values: sys.values.clone(),
            };
            for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
                let xt = solve_checked(&sys, backend, &b, true);
                let x = solve_checked(&transposed, backend, &b, false);
                assert_close(&x, &xt, 1e-10);
            }
        }
    }

    #[test]
    fn zero_row_is_singular_on_both_backends() {
        for (ns, nc) in [(14, 6), (300, 100)] {
            let sys = saddle_system(ns, nc, 31);
            for row in [0, ns / 2, ns + nc / 2] {
                // Row present in the pattern with zero values.
                let values: Vec<f64> = sys
                    .pattern
                    .iter()
                    .zip(&sys.values)
                    .map(|(&(i, _), &v)| if i == row { 0.0 } else { v })
                    .collect();
                // Row absent from the pattern (structurally singular).
                let (pattern_s, values_s): (Vec<_>, Vec<_>) = sys
                    .pattern
                    .iter()
                    .zip(&sys.values)
                    .filter(|(&(i, _), _)| i != row)
                    .map(|(&p, &v)| (p, v))
                    .unzip();
                for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
                    let mut solver =
                        LinearSolver::with_backend(sys.n, &sys.pattern, backend).unwrap();
                    let err = solver.factorize(&values).unwrap_err();
                    assert!(
                        matches!(err, LinearError::Singular { column: Some(_) }),
                        "{backend:?}: {err}"
                    );
                    assert!(!solver.is_factorized());
                    // The solver recovers with good values on the same pattern.
                    solver.factorize(&sys.values).unwrap();
                    assert!(solver.is_factorized());

                    let mut solver =
                        LinearSolver::with_backend(sys.n, &pattern_s, backend).unwrap();
                    let err = solver.factorize(&values_s).unwrap_err();
                    assert!(
                        matches!(err, LinearError::Singular { column: Some(_) }),
                        "{backend:?}: {err}"
                    );
                }
            }
        }
    }

    #[test]
    fn rank_deficient_and_tiny_pivots_are_singular() {
        // Row 2 = row 0 + row 1: rounding leaves a tiny, nonzero pivot.
        let pattern = [
            (0, 0),
            (0, 1),
            (0, 2),
            (1, 0),
            (1, 1),
            (1, 2),
            (2, 0),
            (2, 1),
            (2, 2),
        ];
        let (r0, r1) = ([0.1, 0.7, 0.3], [0.3, 0.2, 0.9]);
        let values = [
            r0[0],
            r0[1],
            r0[2],
            r1[0],
            r1[1],
            r1[2],
            r0[0] + r1[0],
            r0[1] + r1[1],
            r0[2] + r1[2],
        ];
        // Scaled-down row: pivot ~1e-15 relative to the largest entry.
        let mut scaled = [2.0, 1.0, 0.5, 1.0, 3.0, 1.0, 0.5, 1.0, 4.0];
        scaled[6..].iter_mut().for_each(|v| *v *= 1e-14);
        for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
            let mut solver = LinearSolver::with_backend(3, &pattern, backend).unwrap();
            assert!(matches!(
                solver.factorize(&values),
                Err(LinearError::Singular { column: Some(_) })
            ));
            assert!(matches!(
                solver.factorize(&scaled),
                Err(LinearError::Singular { column: Some(_) })
            ));
            assert!(matches!(
                solver.factorize(&[0.0; 9]),
                Err(LinearError::Singular { column: None })
            ));
            let mut nan = [2.0, 1.0, 0.5, 1.0, 3.0, 1.0, 0.5, 1.0, 4.0];
            nan[4] = f64::NAN;
            assert!(matches!(
                solver.factorize(&nan),
                Err(LinearError::Singular { column: Some(1) })
            ));
            nan[4] = f64::INFINITY;
            assert!(matches!(
                solver.factorize(&nan),
                Err(LinearError::Singular { column: Some(1) })
            ));
            assert_eq!(solver.factorizations(), 5);
            solver
                .factorize(&[2.0, 1.0, 0.5, 1.0, 3.0, 1.0, 0.5, 1.0, 4.0])
                .unwrap();
            assert!(solver.min_pivot_ratio().unwrap() > 0.1);
        }
        let err = LinearError::Singular { column: Some(3) };
        assert_eq!(
            err.to_string(),
            "the iteration matrix is singular (zero or tiny pivot at unknown 3)"
        );
        let err = LinearError::Singular { column: None };
        assert_eq!(
            err.to_string(),
            "the iteration matrix is singular (zero or tiny pivot)"
        );
    }

    #[test]
    #[should_panic(expected = "without a successful factorization")]
    fn solve_after_failed_factorization_panics() {
        let mut solver = LinearSolver::with_backend(2, &[(0, 0), (1, 1)], Backend::Dense).unwrap();
        let _ = solver.factorize(&[1.0, 0.0]);
        solver.solve_in_place(&mut [1.0, 1.0]);
    }

    #[test]
    fn refactorization_with_new_values() {
        for (ns, nc) in [(14, 6), (300, 100)] {
            let sys = saddle_system(ns, nc, 41);
            let b = random_rhs(sys.n, 42);
            for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
                let mut solver = LinearSolver::with_backend(sys.n, &sys.pattern, backend).unwrap();
                let mut rng = Lcg(43);
                for it in 0..4 {
                    // New values on the same pattern (Newton-like drift,
                    // including sign changes that alter the pivot sequence).
                    let values: Vec<f64> = if it == 0 {
                        sys.values.clone()
                    } else {
                        sys.values
                            .iter()
                            .map(|v| v * rng.uniform(0.5, 1.5))
                            .collect()
                    };
                    let reference = System {
                        n: sys.n,
                        pattern: sys.pattern.clone(),
                        values: values.clone(),
                    };
                    solver.factorize(&values).unwrap();
                    let mut x = b.clone();
                    solver.solve_in_place(&mut x);
                    let expected = solve_checked(&reference, Backend::Dense, &b, false);
                    assert_close(&expected, &x, 1e-10);
                    let mut xt = b.clone();
                    solver.solve_transpose_in_place(&mut xt);
                    let expected = solve_checked(&reference, Backend::Dense, &b, true);
                    assert_close(&expected, &xt, 1e-10);
                }
                assert_eq!(solver.factorizations(), 4);
            }
        }
    }

    /// A chain of `nb` bodies (6 unknowns each, diagonally dominant mass block) and `nb`
    /// joints of `nc` rows (body 0 to the ground, body b to body b - 1), with the coupling
    /// of the joint's geometric stiffness between neighbouring bodies; the joints' unknowns
    /// after all the bodies', as in the model's layout. Also returns the groups.
    fn chain_system(nb: usize, nc: usize, seed: u64) -> (System, Groups) {
        let mut rng = Lcg(seed);
        let n = nb * (6 + nc);
        let mut pattern = Vec::new();
        let mut values = Vec::new();
        let mut groups = Groups::default();
        let mut push = |i, j, v| {
            pattern.push((i, j));
            values.push(v);
        };
        for b in 0..nb {
            for i in 0..6 {
                for j in 0..6 {
                    let v = if i == j { 10.0 } else { rng.uniform(-1.0, 1.0) };
                    push(6 * b + i, 6 * b + j, v);
                    if b > 0 {
                        push(6 * b + i, 6 * (b - 1) + j, rng.uniform(-0.5, 0.5));
                        push(6 * (b - 1) + i, 6 * b + j, rng.uniform(-0.5, 0.5));
                    }
                }
            }
            let rows = 6 * nb + nc * b;
            for r in 0..nc {
                for j in 0..6 {
                    let own = if r == j { 1.0 } else { 0.0 } + rng.uniform(-0.1, 0.1);
                    push(rows + r, 6 * b + j, own);
                    push(6 * b + j, rows + r, own);
                    if b > 0 {
                        let other = if r == j { -1.0 } else { 0.0 } + rng.uniform(-0.1, 0.1);
                        push(rows + r, 6 * (b - 1) + j, other);
                        push(6 * (b - 1) + j, rows + r, other);
                    }
                }
                push(rows + r, rows + r, 0.0);
            }
        }
        for b in 0..nb {
            groups.push(6 * b..6 * b + 6, GroupKind::Regular);
        }
        for b in 0..nb {
            groups.push(
                6 * nb + nc * b..6 * nb + nc * (b + 1),
                GroupKind::Multipliers,
            );
        }
        (System { n, pattern, values }, groups)
    }

    #[test]
    fn block_lu_of_a_chain_has_no_fill() {
        let (nb, nc) = (40, 5);
        let (sys, groups) = chain_system(nb, nc, 51);
        let b = random_rhs(sys.n, 52);
        let mut solver = LinearSolver::with_groups(sys.n, &sys.pattern, &groups).unwrap();
        assert_eq!(solver.backend(), Backend::Block);
        // Every body with the joint to its parent: one supernode of 11 unknowns whose panels
        // hold rows of its two neighbours only (the parent body's 6 rows when eliminated
        // from the tip, the child's 11 from the root; none for the last): no fill.
        let s = 6 + nc;
        assert!(solver.nnz() <= nb * s * s + (nb - 1) * 2 * s * s);
        assert!(solver.nnz() >= nb * s * s + (nb - 1) * 2 * 6 * s);
        assert_block_lu_solves(&mut solver, &sys, &b, 1e-12);
    }

    #[test]
    fn block_lu_of_closed_loops_and_branches() {
        // The chain of 30 bodies closed by a joint of 3 rows between the last body and the
        // first (a loop), and a branch: a second joint of 2 rows from body 10 to body 20.
        let (nb, nc) = (30, 5);
        let (mut sys, mut groups) = chain_system(nb, nc, 71);
        let mut rng = Lcg(72);
        for (a, b, rows) in [(nb - 1, 0, 3), (10, 20, 2)] {
            let first = sys.n;
            sys.n += rows;
            for r in 0..rows {
                for j in 0..6 {
                    for (body, sign) in [(a, 1.0), (b, -1.0)] {
                        let v = if r == j { sign } else { 0.0 } + rng.uniform(-0.1, 0.1);
                        sys.pattern.push((first + r, 6 * body + j));
                        sys.values.push(v);
                        sys.pattern.push((6 * body + j, first + r));
                        sys.values.push(v);
                    }
                }
            }
            groups.push(first..first + rows, GroupKind::Multipliers);
        }
        let b = random_rhs(sys.n, 73);
        let mut solver = LinearSolver::with_groups(sys.n, &sys.pattern, &groups).unwrap();
        assert_eq!(solver.backend(), Backend::Block);
        assert_block_lu_solves(&mut solver, &sys, &b, 1e-11);
        // The pattern, for the general LU, from the storage index of each triplet.
        assert_eq!(solver.pattern(), sys.pattern);
    }

    /// The dense and sparse backends give back the pattern they were built on, duplicates
    /// and order kept ([`LinearSolver::pattern`]; the block backend in
    /// `block_lu_of_closed_loops_and_branches`).
    #[test]
    fn solvers_recover_their_pattern() {
        let mut sys = saddle_system(300, 100, 6);
        // duplicates, summed by the solver, each kept in the pattern
        let twice: Vec<_> = sys.pattern[..50].to_vec();
        sys.pattern.extend(twice);
        for backend in [Backend::Dense, Backend::Sparse] {
            let solver = LinearSolver::with_backend(sys.n, &sys.pattern, backend).unwrap();
            assert_eq!(solver.pattern(), sys.pattern, "{backend:?}");
        }
    }

    /// Normwise backward error `|A x - b| / (|A| |x| + |b|)` of a solve (infinity norms).
    fn backward_error(sys: &System, x: &[f64], b: &[f64], transpose: bool) -> f64 {
        let ax = matvec(sys.n, &sys.pattern, &sys.values, x, transpose);
        let r: Vec<f64> = ax.iter().zip(b).map(|(a, b)| a - b).collect();
        let abs: Vec<f64> = sys.values.iter().map(|v| v.abs()).collect();
        let x_abs: Vec<f64> = x.iter().map(|v| v.abs()).collect();
        let ax_abs = matvec(sys.n, &sys.pattern, &abs, &x_abs, transpose);
        norm_inf(&r) / (norm_inf(&ax_abs) + norm_inf(b))
    }

    /// The entries of `sys` by position.
    fn entries(sys: &System) -> std::collections::HashMap<(usize, usize), f64> {
        sys.pattern
            .iter()
            .copied()
            .zip(sys.values.iter().copied())
            .collect()
    }

    /// `sys` with the entries of unknown `copy`'s row and column set to those of `of`'s
    /// (a repeated constraint row), except the diagonal.
    fn repeat_row(sys: &System, copy: usize, of: usize) -> System {
        let at = entries(sys);
        let values = sys
            .pattern
            .iter()
            .zip(&sys.values)
            .map(|(&(i, j), &v)| match (i == copy, j == copy) {
                (true, false) => at[&(of, j)],
                (false, true) => at[&(i, of)],
                _ => v,
            })
            .collect();
        System {
            n: sys.n,
            pattern: sys.pattern.clone(),
            values,
        }
    }

    #[test]
    fn block_lu_takes_heavy_chains_whose_joint_pivots_are_tiny_against_their_columns() {
        // Bodies 1e15 times heavier than their joints' entries, as the articulated inertia of
        // a chain of 1e5 links is: each joint's pivots, B S^-1 B^T, are 1e-16 times its
        // column of A (B^T) but not small against the terms that formed them. The block LU
        // takes the matrix and solves it to the rounding level.
        let (nb, nc) = (40, 5);
        let (mut sys, groups) = chain_system(nb, nc, 81);
        for (&(i, j), v) in sys.pattern.iter().zip(sys.values.iter_mut()) {
            if i < 6 * nb && j < 6 * nb {
                *v *= 1e15;
            }
        }
        let mut solver = LinearSolver::with_groups(sys.n, &sys.pattern, &groups).unwrap();
        solver.factorize(&sys.values).unwrap();
        let Inner::Block(block) = &solver.inner else {
            unreachable!()
        };
        assert!(!block.general_active, "the block LU took this matrix");
        assert!(solver.min_pivot_ratio().unwrap() < PIVOT_TOLERANCE);
        assert!(solver.pivot_margin().unwrap() > 1e10);
        let b = random_rhs(sys.n, 82);
        for transpose in [false, true] {
            let x = solved(&mut solver, &b, transpose);
            assert!(backward_error(&sys, &x, &b, transpose) < 1e-15);
        }
        // A joint's row repeated: its pivot cancels to the rounding level of the terms
        // that formed it; the block LU hands the matrix on and the general LU finds it
        // singular.
        let rows = 6 * nb + nc * 7;
        let repeated = repeat_row(&sys, rows + 4, rows + 3);
        assert!(matches!(
            solver.factorize(&repeated.values),
            Err(LinearError::Singular { .. })
        ));
    }

    #[test]
    fn block_lu_rejects_a_loop_closing_joint_that_repeats_a_joint() {
        // A joint of 3 rows between bodies 10 and 9 with the first rows of the joint already
        // there: it closes a loop (a cut supernode, whose block the other supernodes' updates
        // fill with -B S^-1 B^T) and is redundant, which those updates cancel.
        let (nb, nc) = (30, 5);
        let (mut sys, mut groups) = chain_system(nb, nc, 91);
        let first = sys.n;
        let rows = 6 * nb + nc * 10;
        sys.n += 3;
        let at = entries(&sys);
        for r in 0..3 {
            for j in 6 * 9..6 * 11 {
                let v = at[&(rows + r, j)];
                sys.pattern.extend([(first + r, j), (j, first + r)]);
                sys.values.extend([v, v]);
            }
        }
        groups.push(first..first + 3, GroupKind::Multipliers);
        let mut solver = LinearSolver::with_groups(sys.n, &sys.pattern, &groups).unwrap();
        assert!(matches!(
            solver.factorize(&sys.values),
            Err(LinearError::Singular { .. })
        ));
    }

    /// Factorizes `sys` (the block LU must take it, not hand it on) and checks both solves
    /// against the dense LU.
    fn assert_block_lu_solves(solver: &mut LinearSolver, sys: &System, b: &[f64], tol: f64) {
        solver.factorize(&sys.values).unwrap();
        let Inner::Block(block) = &solver.inner else {
            unreachable!()
        };
        assert!(!block.general_active, "the block LU took this matrix");
        for transpose in [false, true] {
            let x = solved(solver, b, transpose);
            let expected = solve_checked(sys, Backend::Dense, b, transpose);
            assert_close(&expected, &x, tol);
        }
    }

    #[test]
    fn block_lu_hands_a_rejected_matrix_to_the_general_lu() {
        let (sys, groups) = chain_system(20, 5, 61);
        let b = random_rhs(sys.n, 62);
        let mut solver = LinearSolver::with_groups(sys.n, &sys.pattern, &groups).unwrap();
        // Without mass, the first body's block [[0, B^T], [B, 0]] is singular (6 + 5
        // unknowns, rank 10): the block LU rejects the matrix, which is regular through the
        // next joint; the general LU solves it.
        let massless = System {
            n: sys.n,
            pattern: sys.pattern.clone(),
            values: sys
                .pattern
                .iter()
                .zip(&sys.values)
                .map(|(&(i, j), &v)| if i < 6 && j < 6 { 0.0 } else { v })
                .collect(),
        };
        solver.factorize(&massless.values).unwrap();
        let mut x = b.clone();
        solver.solve_in_place(&mut x);
        assert_close(
            &solve_checked(&massless, Backend::Dense, &b, false),
            &x,
            1e-9,
        );
        // Good values again: back to the block LU.
        solver.factorize(&sys.values).unwrap();
        let Inner::Block(block) = &solver.inner else {
            unreachable!()
        };
        assert!(!block.general_active);

        // [[e, 1], [1, e]] in two groups: whichever goes first, its pivot e is fine against
        // the largest entry but gives a multiplier 1/e beyond the growth limit. The general
        // LU, with full partial pivoting, solves it.
        let e = 1e-8;
        let two = System {
            n: 2,
            pattern: vec![(0, 0), (0, 1), (1, 0), (1, 1)],
            values: vec![e, 1.0, 1.0, e],
        };
        let mut groups = Groups::default();
        groups.push([0], GroupKind::Regular);
        groups.push([1], GroupKind::Regular);
        let mut solver = LinearSolver::build(2, &two.pattern, Backend::Block, &groups).unwrap();
        solver.factorize(&two.values).unwrap();
        let Inner::Block(block) = &solver.inner else {
            unreachable!()
        };
        assert!(block.general_active);
        let mut x = vec![1.0, 2.0];
        solver.solve_in_place(&mut x);
        assert_close(
            &solve_checked(&two, Backend::Dense, &[1.0, 2.0], false),
            &x,
            1e-14,
        );
        // Good values: the block LU.
        solver.factorize(&[2.0, 1.0, 1.0, 2.0]).unwrap();
        let Inner::Block(block) = &solver.inner else {
            unreachable!()
        };
        assert!(!block.general_active);
    }

    #[test]
    fn solver_is_send_and_sync() {
        fn assert_send_sync<T: Send + Sync>() {}
        assert_send_sync::<LinearSolver>();
        assert_send_sync::<LinearError>();
    }

    #[test]
    fn empty_system() {
        for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
            let mut solver = LinearSolver::with_backend(0, &[], backend).unwrap();
            solver.factorize(&[]).unwrap();
            solver.solve_in_place(&mut []);
            solver.solve_transpose_in_place(&mut []);
            assert_eq!(solver.factorizations(), 1);
        }
    }
}
