//! Cost of one Newton linear solve (numeric factorization + solve) with
//! `flexmb::solve::linear::LinearSolver` on multibody-like saddle-point
//! systems.
//!
//! Run with `cargo run --release -p flexmb --example linear_timing`.
//!
//! A chain of `nb` bodies is assembled block-tridiagonally: each block has 6
//! unknowns for the body followed by `nc` constraint rows (Lagrange
//! multipliers) coupling the body to the previous one (the first body to the
//! ground). The matrix is `[[S, G^T], [B, 0]]` with a zero diagonal block for
//! the multipliers, interleaved body by body.

use flexmb::solve::linear::{Backend, GroupKind, Groups, LinearSolver, DENSE_MAX};
use std::hint::black_box;
use std::time::Instant;

struct Lcg(u64);

impl Lcg {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// Pattern and two value sets (alternated like successive Newton iterations).
struct Chain {
    n: usize,
    /// Each body's unknowns, then each joint's multipliers (saddle).
    groups: Groups,
    pattern: Vec<(usize, usize)>,
    values: [Vec<f64>; 2],
}

fn chain(nb: usize, nc: usize, seed: u64) -> Chain {
    let mut rng = Lcg(seed);
    let bs = 6 + nc;
    let n = nb * bs;
    let mut pattern = Vec::new();
    for b in 0..nb {
        let body = b * bs;
        let cons = body + 6;
        for i in 0..6 {
            for j in 0..6 {
                pattern.push((body + i, body + j));
            }
        }
        let mut bodies = vec![body];
        if b > 0 {
            bodies.push(body - bs);
        }
        for &other in &bodies {
            for r in 0..nc {
                for j in 0..6 {
                    pattern.push((cons + r, other + j)); // B
                    pattern.push((other + j, cons + r)); // G^T
                }
            }
        }
    }
    let mut groups = Groups::default();
    for b in 0..nb {
        groups.push(b * bs..b * bs + 6, GroupKind::Regular);
        groups.push(b * bs + 6..(b + 1) * bs, GroupKind::Multipliers);
    }
    let mut values = [Vec::new(), Vec::new()];
    for set in &mut values {
        for &(i, j) in &pattern {
            let (bi, bj) = (i / bs, j / bs);
            let (li, lj) = (i % bs, j % bs);
            let v = if li < 6 && lj < 6 {
                // Body block: diagonally dominant mass + stiffness.
                if li == lj {
                    10.0 + rng.uniform(0.0, 1.0)
                } else {
                    rng.uniform(-1.0, 1.0)
                }
            } else {
                // Joint Jacobian: +-[I 0] plus small terms, sign by side.
                let (r, c) = if li >= 6 { (li - 6, lj) } else { (lj - 6, li) };
                let own = bi == bj;
                let sign = if own { 1.0 } else { -1.0 };
                let base = if r == c { sign } else { 0.0 };
                base + rng.uniform(-0.1, 0.1)
            };
            set.push(v);
        }
    }
    Chain {
        n,
        groups,
        pattern,
        values,
    }
}

fn time_case(label: &str, sys: &Chain, backend: Backend, reps: usize) {
    let t0 = Instant::now();
    let mut solver = LinearSolver::build(sys.n, &sys.pattern, backend, &sys.groups).unwrap();
    let setup = t0.elapsed().as_secs_f64() * 1e6;
    let mut b = vec![0.0; sys.n];
    // Warm-up: reaches the steady state of all buffers.
    for k in 0..2 {
        solver.factorize(&sys.values[k]).unwrap();
        b.fill(1.0);
        solver.solve_in_place(&mut b);
    }
    let mut t_fact = 0.0;
    let mut t_solve = 0.0;
    for k in 0..reps {
        let t = Instant::now();
        solver.factorize(black_box(&sys.values[k % 2])).unwrap();
        let t1 = Instant::now();
        b.fill(1.0);
        solver.solve_in_place(black_box(&mut b));
        let t2 = Instant::now();
        t_fact += (t1 - t).as_secs_f64();
        t_solve += (t2 - t1).as_secs_f64();
    }
    black_box(&b);
    let us = |t: f64| t / reps as f64 * 1e6;
    println!(
        "{label:<34} {:>6?} n={:>6} nnz={:>7}  setup {:>9.1} us | factorize {:>9.2} us + solve {:>8.2} us = {:>9.2} us",
        backend,
        sys.n,
        solver.nnz(),
        setup,
        us(t_fact),
        us(t_solve),
        us(t_fact + t_solve),
    );
}

fn main() {
    println!("DENSE_MAX = {DENSE_MAX}; times per Newton iteration (factorize + solve)");
    let small = chain(1, 3, 1);
    let medium = chain(10, 5, 2);
    let large = chain(1000, 5, 3);
    time_case(
        "dense 9x9 (1 body, 3 constraints)",
        &small,
        Backend::Dense,
        200_000,
    );
    time_case("dense 110x110 (10 blocks)", &medium, Backend::Dense, 20_000);
    time_case("sparse 11000 (1000 blocks)", &large, Backend::Sparse, 200);
    time_case("block 11000 (1000 blocks)", &large, Backend::Block, 200);
    let huge = chain(10_000, 5, 5);
    time_case("sparse 110000 (10000 blocks)", &huge, Backend::Sparse, 10);
    time_case("block 110000 (10000 blocks)", &huge, Backend::Block, 20);
    println!("-- crossover check --");
    time_case("9x9 on the sparse backend", &small, Backend::Sparse, 50_000);
    time_case(
        "110x110 on the sparse backend",
        &medium,
        Backend::Sparse,
        5_000,
    );
    for nb in [1, 2, 3, 4, 5, 6, 8, 10, 14, 20] {
        let sys = chain(nb, 5, 4);
        for backend in [Backend::Dense, Backend::Sparse, Backend::Block] {
            time_case(&format!("{} blocks", nb), &sys, backend, 2_000);
        }
    }
}
