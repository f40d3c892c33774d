//! Termination signals during a run.
//!
//! Contract: SIGINT, SIGTERM and SIGHUP set the solver's interrupt flag; the run stops before
//! its next step, writes its summary with status `interrupted` and the process exits with
//! `128 + signal number` (130, 143, 129). A second of these signals (a second Ctrl-C, or
//! `timeout -s INT`, which signals the process and then its group) ends the run at once: a
//! thread of its own, woken by every signal (the self-pipe of `signal_hook`, one byte a
//! signal, so that two signals in a row are two), stops the result files' writer between
//! two output steps, writes the summary of what the files hold (`interrupted`) and ends the
//! process with the same code. A third signal while it does so runs the signal's default
//! action.

pub use signal_hook::consts::signal::SIGINT;
use signal_hook::consts::signal::{SIGHUP, SIGTERM};
use signal_hook::flag;
use signal_hook::low_level::pipe;
use std::io::Read;
use std::os::unix::net::UnixStream;
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
    /// Installs the handlers of [`SIGNALS`]. At the second signal, `end` is called on the
    /// signals' thread with its number, to record the run's end at once; the process then
    /// exits with the code it returns (without running exit handlers, which could wait for
    /// the threads still at work).
    pub fn install(end: impl FnOnce(i32) -> i32 + Send + 'static) -> std::io::Result<Self> {
        let interrupt = Self {
            flag: Arc::new(AtomicBool::new(false)),
            signal: Arc::new(AtomicUsize::new(0)),
        };
        let ending = Arc::new(AtomicBool::new(false));
        let (mut read, write) = UnixStream::pair()?;
        for signal in SIGNALS {
            // Actions run in registration order: the default action first, armed only while
            // the run is being ended at once, then the record of this signal, the flag and
            // the byte that wakes the signals' thread.
            flag::register_conditional_default(signal, Arc::clone(&ending))?;
            flag::register_usize(signal, Arc::clone(&interrupt.signal), signal as usize)?;
            flag::register(signal, Arc::clone(&interrupt.flag))?;
            pipe::register(signal, write.try_clone()?)?;
        }
        let signal = Arc::clone(&interrupt.signal);
        std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                let mut byte = [0u8];
                // the first signal asks the run to stop before its next step
                if read.read_exact(&mut byte).is_err() || read.read_exact(&mut byte).is_err() {
                    return;
                }
                ending.store(true, Ordering::SeqCst);
                let code = end(received(&signal));
                signal_hook::low_level::exit(code)
            })?;
        Ok(interrupt)
    }

    /// The flag the solver checks before every step.
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.flag)
    }

    /// The signal that set the flag. The handler of each signal records it before it sets
    /// the flag, so this is meaningful once the flag is set (SIGINT before that).
    pub fn received(&self) -> i32 {
        received(&self.signal)
    }
}

/// The signal recorded in `signal` (SIGINT before any).
fn received(signal: &AtomicUsize) -> i32 {
    match signal.load(Ordering::SeqCst) {
        0 => SIGINT,
        s => i32::try_from(s).unwrap_or(SIGINT),
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
