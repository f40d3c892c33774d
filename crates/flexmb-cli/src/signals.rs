//! Termination signals during a run.
//!
//! Contract: SIGINT, SIGTERM and SIGHUP set the solver's interrupt flag; the run stops before
//! its next step, writes its summary with status `interrupted` and the process exits with
//! `128 + signal number` (130, 143, 129). A second of these signals while the flag is set
//! runs the signal's default action: the process ends at once, leaving the summary `running`
//! and the rows written so far.

pub use signal_hook::consts::signal::SIGINT;
use signal_hook::consts::signal::{SIGHUP, SIGTERM};
use signal_hook::flag;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

/// The signals that interrupt a run.
const SIGNALS: [i32; 3] = [SIGINT, SIGTERM, SIGHUP];

/// The interrupt flag handed to the solver and the signal that set it.
pub struct Interrupt {
    flag: Arc<AtomicBool>,
    /// Number of the last signal received, 0 before any.
    signal: Arc<AtomicUsize>,
}

impl Interrupt {
    /// Installs the handlers of [`SIGNALS`].
    pub fn install() -> std::io::Result<Self> {
        let interrupt = Self {
            flag: Arc::new(AtomicBool::new(false)),
            signal: Arc::new(AtomicUsize::new(0)),
        };
        for signal in SIGNALS {
            // Actions run in registration order: the default action first, armed only by an
            // earlier signal, then the record of this one.
            flag::register_conditional_default(signal, Arc::clone(&interrupt.flag))?;
            flag::register_usize(signal, Arc::clone(&interrupt.signal), signal as usize)?;
            flag::register(signal, Arc::clone(&interrupt.flag))?;
        }
        Ok(interrupt)
    }

    /// The flag the solver checks before every step.
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.flag)
    }

    /// The signal that set the flag. The handler of each signal records it before it sets
    /// the flag, so this is meaningful once the flag is set (SIGINT before that).
    pub fn received(&self) -> i32 {
        match self.signal.load(Ordering::SeqCst) {
            0 => SIGINT,
            s => i32::try_from(s).unwrap_or(SIGINT),
        }
    }
}

/// Conventional exit code of a process stopped by `signal`.
pub fn exit_code(signal: i32) -> i32 {
    128 + signal
}

/// `SIGINT` and so on (the number for a signal without a name).
pub fn name(signal: i32) -> String {
    signal_hook::low_level::signal_name(signal)
        .map_or_else(|| format!("signal {signal}"), str::to_string)
}
