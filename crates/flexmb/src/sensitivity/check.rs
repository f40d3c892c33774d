//! The check of the exact gradients against central finite differences (`flexmb
//! sensitivity --check`), run where the difference measures the gradient and not the error
//! of the Newton iteration.
//!
//! A central difference `(J(p + d) - J(p - d)) / (2 d)` divides the error of each run by `d`.
//! A run is solved to the Newton tolerance, and a Newton iteration that reuses its factorized
//! matrix (the chord method, the dynamic default) accepts iterates whose error is a good part
//! of the tolerance (up to 1/100 of it), different for `p + d` and `p - d`. The exact
//! gradient also moves with that error: it is the derivative at the computed point. Measured
//! on the right-angle cantilever (`examples/right_angle_cantilever_sensitivity.toml`, relative
//! step 1e-6, the largest relative difference of its 8 gradients): 2.0e-5 at the model's
//! settings (`rtol` 1e-6, `atol` 1e-9, the matrix reused), 6.2e-6 with `rtol` 1e-12 or
//! 1e-13, 1.2e-6 with `atol` 1e-14 as well, 1.8e-8 with a fresh matrix at every iteration
//! (full Newton, whose error after its last correction is quadratic in it) at the model's
//! tolerances, and 1.2e-8 with full Newton at `rtol` 1e-10, `atol` 1e-12.
//!
//! So the check's own runs, the adjoint it compares and the finite differences, are solved by
//! full Newton with tolerances at most [`RTOL`] and [`ATOL`] ([`settings`]); the gradients
//! the analysis reports stay those of the model's settings, and the check says how far they
//! are from its adjoint. The relative differences compare `scale dJ/dp`
//! ([`super::report::differences`]).

use super::{adjoint, finite_differences, Gradients, Problem, SensitivityError};
use crate::solve::Analysis;
use crate::solve::NewtonSettings;

/// Largest relative Newton tolerance of the check's runs.
pub const RTOL: f64 = 1e-10;
/// Largest absolute Newton tolerance of the check's runs \[m or rad\].
pub const ATOL: f64 = 1e-12;

/// The Newton settings of the check's runs from those of the analysis: full Newton (a
/// fresh matrix at every iteration), `rtol` at most [`RTOL`], `atol` at most [`ATOL`].
pub fn settings(newton: &NewtonSettings) -> NewtonSettings {
    NewtonSettings {
        rtol: newton.rtol.min(RTOL),
        atol: newton.atol.min(ATOL),
        reuse_jacobian: false,
        ..*newton
    }
}

/// What [`check`] compared: the exact gradients (adjoint) and central differences, both at
/// the check's Newton settings `newton`.
pub struct Check {
    pub exact: Gradients,
    pub fd: Gradients,
    pub newton: NewtonSettings,
}

/// The check of `computed`, the adjoint gradients of `problem`: the adjoint (computed again
/// unless the problem's settings are already the check's) and central differences with
/// relative step `fd_step`, both at the check's settings ([`settings`]). `progress` follows
/// the adjoint's backward sweep.
pub fn check(
    problem: &Problem,
    computed: &Gradients,
    fd_step: f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Check, SensitivityError> {
    let mut analysis = problem.analysis.clone();
    let newton = match &mut analysis {
        Analysis::Dynamic(s) => &mut s.newton,
        Analysis::Static(s) => &mut s.newton,
    };
    *newton = settings(newton);
    let newton = *newton;
    let tight = Problem {
        analysis,
        ..problem.clone()
    };
    let exact = if tight.analysis == problem.analysis {
        computed.clone()
    } else {
        match tight.analysis {
            Analysis::Dynamic(_) => adjoint(&tight, progress)?,
            Analysis::Static(_) => super::statics::gradients(&tight, false)?,
        }
    };
    let fd = finite_differences(&tight, fd_step)?;
    Ok(Check { exact, fd, newton })
}
