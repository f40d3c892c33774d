//! The ranges of the numbers a model and its analysis take (documented in
//! `docs/model-format.md`, section "Ranges").
//!
//! They are generous for any physical model in SI units (or other consistent units within
//! some decades of them) and keep every product the solver forms (masses over squared step
//! sizes, stiffnesses over lengths, energies, ...) finite and far from underflow: each
//! quantity spans at most 60 decades and the solver multiplies a few of them.

/// Largest magnitude of a coordinate, length, velocity \[m/s\], angular velocity \[rad/s\],
/// acceleration (gravity) [m/s^2] or frequency \[Hz\].
pub const MAX_KINEMATIC: f64 = 1e9;

/// Largest magnitude of a physical constant or load: mass, inertia, stiffness, damping,
/// section property, force, torque, value of a time function.
pub const MAX_PHYSICAL: f64 = 1e30;

/// Smallest positive mass, principal moment of inertia, or property of a beam section (a
/// value the model needs positive; its zero or a denormal number would make the matrices
/// singular without a visible cause).
pub const MIN_PHYSICAL: f64 = 1e-30;

/// Largest friction coefficient (contacts, worm gears).
pub const MAX_FRICTION: f64 = 100.0;

/// Largest angle \[rad\] (rotation vector, phase) and, in degrees, `angle_deg`: beyond it a
/// double has lost the 1e-10 precision of an orientation.
pub const MAX_ANGLE: f64 = 1e6;

/// Largest magnitude of a time \[s\] (end time, times of time functions).
pub const MAX_TIME: f64 = 1e12;

/// Smallest time step, output interval or time-function interval \[s\]: `h^2` and `1/h^2`
/// times a mass or a stiffness stay finite, and `h_min`, `1e-4 h`, stay normal numbers.
pub const MIN_STEP: f64 = 1e-12;

/// Most time steps (`t_end / h`) or outputs (`t_end / output_interval`) of a dynamic
/// analysis: the time `t + h` then always advances (`h / t >= 1e-10`, far above the 1e-16
/// relative precision of a double).
pub const MAX_STEPS: f64 = 1e10;

/// Smallest beam element length relative to the extent of the model (the diagonal of the box
/// around its nodes) and to the radius of gyration of its section `sqrt(EI / EA)`: a shorter
/// element is degenerate (its stiffness and mass are out of scale with the rest).
pub const MIN_RELATIVE_LENGTH: f64 = 1e-6;

/// Most nodes and most beam elements of one model (a memory bound: an element takes about
/// 1.5 kB, its share of the solver's matrices more).
pub const MAX_ITEMS: usize = 2_000_000;

/// Most points of one rope: its local matrix is dense, `(6 n)^2` entries.
pub const MAX_ROPE_POINTS: usize = 64;

/// Most levels of time functions nested in one another, counting the outermost (a `delay`
/// of a `bump` has 2): evaluation recurses once per level.
pub const MAX_FUNCTION_DEPTH: usize = 8;

/// Most functions of one `sum` time function.
pub const MAX_FUNCTION_TERMS: usize = 64;

/// Whether `v` is in `[lo, hi]` (false for NaN).
pub fn within(v: f64, lo: f64, hi: f64) -> bool {
    lo <= v && v <= hi
}
