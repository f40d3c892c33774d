//! Threads of the assembly: the setting, the size below which a model stays sequential, and
//! the thread pools.
//!
//! The setting is a number of threads, `threads` in `[solver]`
//! ([`crate::DynamicSettings::threads`], [`crate::solve::StaticSettings::threads`], `--threads`
//! on the command line): 0 for all cores (the default), 1 for the plain sequential assembly,
//! which never touches rayon. [`Threads::for_model`] turns it into what a [`crate::data::Data`]
//! assembles with: models of fewer than [`MIN_PARALLEL_ITEMS`] force elements and joints stay
//! sequential whatever the setting (below it, waking the threads costs more than they save;
//! BENCHMARKS.md, "Threads").
//!
//! The results do not depend on the number of threads, bit for bit: how
//! [`crate::assembly::assemble`] keeps its sums in a fixed order is said there.
//!
//! Pools are shared: one per thread count, built on first use and kept for the life of the
//! process, so that many simulations (a sensitivity study, a test suite) do not each start
//! their own threads.

use crate::model::Model;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

/// Force elements plus joints below which a model is assembled sequentially whatever the
/// setting: the crossover measured on beams and chains on 2 cores (BENCHMARKS.md, "Threads").
pub const MIN_PARALLEL_ITEMS: usize = 300;

/// Largest number of threads a setting may ask for.
pub const MAX_THREADS: usize = 1024;

/// How a [`crate::data::Data`] assembles: sequentially (the default), or on a pool of threads.
#[derive(Clone, Debug, Default)]
pub struct Threads {
    /// `None`: sequential, rayon is not used.
    pool: Option<Arc<rayon::ThreadPool>>,
}

impl Threads {
    /// The plain sequential assembly.
    pub fn sequential() -> Self {
        Self::default()
    }

    /// What the setting `requested` (0: all cores) gives for `model`: sequential for one
    /// thread, or below [`MIN_PARALLEL_ITEMS`] items.
    pub fn for_model(model: &Model, requested: usize) -> Self {
        if parallel_items(model) < MIN_PARALLEL_ITEMS {
            return Self::sequential();
        }
        Self::forced(requested)
    }

    /// `requested` threads (0: all cores) whatever the size of the model (tests and
    /// measurements); sequential for one thread, or if the threads cannot be started.
    pub fn forced(requested: usize) -> Self {
        let n = resolve(requested);
        if n <= 1 {
            return Self::sequential();
        }
        Self { pool: pool(n) }
    }

    /// Number of threads the assembly runs on (1: sequential).
    pub fn count(&self) -> usize {
        self.pool.as_ref().map_or(1, |p| p.current_num_threads())
    }

    /// The pool, `None` for the sequential assembly.
    pub(crate) fn pool(&self) -> Option<&rayon::ThreadPool> {
        self.pool.as_deref()
    }
}

impl Threads {
    /// `f(i, &mut items[i])` for every item, on the pool's threads when there is one (in
    /// chunks of at least [`MIN_CHUNK`]). Each call touches its own item only, so the
    /// results are those of the sequential loop, bit for bit.
    pub(crate) fn for_each<T: Send>(&self, items: &mut [T], f: impl Fn(usize, &mut T) + Sync) {
        use rayon::prelude::*;
        match self.pool() {
            Some(pool) => pool.install(|| {
                items
                    .par_iter_mut()
                    .with_min_len(MIN_CHUNK)
                    .enumerate()
                    .for_each(|(i, x)| f(i, x))
            }),
            None => items.iter_mut().enumerate().for_each(|(i, x)| f(i, x)),
        }
    }
}

/// Smallest number of nodes a thread takes in `Threads::for_each`.
pub const MIN_CHUNK: usize = 256;

/// The items whose contributions the assembly computes in parallel: force elements and joints.
pub fn parallel_items(model: &Model) -> usize {
    crate::elements::ElementItem::all(model).count() + model.joints.len()
}

/// The number of threads a setting asks for: `requested`, or the number of cores for 0.
pub fn resolve(requested: usize) -> usize {
    if requested == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        requested
    }
}

/// The shared pool of `n` threads (`None` if it cannot be built).
fn pool(n: usize) -> Option<Arc<rayon::ThreadPool>> {
    static POOLS: OnceLock<Mutex<Vec<Arc<rayon::ThreadPool>>>> = OnceLock::new();
    let mut pools = POOLS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(PoisonError::into_inner);
    if let Some(p) = pools.iter().find(|p| p.current_num_threads() == n) {
        return Some(Arc::clone(p));
    }
    let p = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(|i| format!("flexmb-assembly-{i}"))
        .build()
        .ok()?;
    let p = Arc::new(p);
    pools.push(Arc::clone(&p));
    Some(p)
}
