//! `flexmb`: run multibody models from the command line.
//!
//! ```text
//! flexmb run MODEL.toml --out DIR [--set key.path=value ...] [--quiet] [--verify]
//!                       [--checkpoint-interval T] [--threads N]
//! flexmb run MODEL.toml --resume DIR [--set ...] [--threads N]
//! flexmb check MODEL.toml [--set ...]
//! flexmb sensitivity MODEL.toml --out DIR [--method direct|adjoint|fd] [--fd-step S]
//!                               [--check] [--memory-mb M] [--set ...] [--quiet] [--threads N]
//! flexmb optimize MODEL.toml --out DIR [--criterion NAME] [--iterations N] [--set ...]
//!                            [--threads N]
//! ```
//!
//! Contract (README.md, "The `flexmb` command" and "Outputs"): one exit code per class of
//! outcome ([`exit`]), one message per cause on stderr, the result files of
//! [`flexmb::output`] in the output directory.

// The doc comments of the commands and options are their --help text, where
// `[[criterion]]` names a table of the model file, not an item to link.
#![allow(rustdoc::broken_intra_doc_links)]

mod console;
mod signals;

use clap::{Parser, Subcommand};
use console::{say, tell};
use flexmb::output::{ErrorKind, OutputDir, Status, Summary};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Exit codes, one per class of outcome.
mod exit {
    /// The command did what was asked.
    pub const OK: i32 = 0;
    /// The analysis ran and failed (a step could not converge); results up to the failure
    /// are kept.
    pub const ANALYSIS_FAILED: i32 = 1;
    /// The model is invalid: the model file, or a check before the first step (settings,
    /// initial conditions, initial mass matrix). The same for `check` and `run`.
    pub const INVALID_MODEL: i32 = 2;
    /// The results could not be written (the output directory or a result file).
    pub const OUTPUT_FAILED: i32 = 3;
    /// The analysis stopped at a limit of its settings before its end (`max_steps` load
    /// steps before the final load factor; `optimize`: `--iterations` before L-BFGS
    /// converged); nothing failed and the results up to where it stopped are kept. The next
    /// code of flexmb's own outcome classes: below sysexits' 64-78, the shell's 126-127 and
    /// the 128 + n of signals, so it means nothing else.
    pub const INCOMPLETE: i32 = 4;
    /// The command line is wrong (sysexits' EX_USAGE).
    pub const USAGE: i32 = 64;
}

/// The exit codes as `flexmb --help` lists them.
const EXIT_CODES_HELP: &str = "\
Exit codes:
  0    success
  1    the analysis failed (results up to the failure are kept)
  2    the model is invalid (model file, settings or initial conditions), or cannot be
       analysed as asked (sensitivity, optimize: e.g. an event in the run)
  3    the results could not be written (output directory or files)
  4    the analysis stopped before its end at a limit of its settings (summary status
       \"incomplete\"; a warning says which setting to raise; results up to there are kept)
  64   wrong command line
  128+n  stopped by signal n: 130 SIGINT, 143 SIGTERM, 129 SIGHUP (summary status \"interrupted\")";

#[derive(Parser)]
#[command(
    name = "flexmb",
    version,
    about = "Flexible multibody dynamics on Lie groups",
    after_help = EXIT_CODES_HELP
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the analysis a model file declares; write sensors.csv, nodes.csv, beams.csv and
    /// summary.json into DIR (result files of an earlier run there are removed first).
    Run {
        /// Model file (TOML, see docs/model-format.md).
        model: PathBuf,
        /// Output directory (created if needed).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Override a scalar of the file, e.g. --set solver.h=0.0005 (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Re-check every accepted step with a freshly built iteration matrix and report the
        /// largest estimated error (in units of the Newton tolerance) in summary.json; costs
        /// one more factorization per step.
        #[arg(long)]
        verify: bool,
        /// Dynamic analysis: write DIR/checkpoint.json every T seconds of simulated time and
        /// at the end (a run stopped by a signal always writes one).
        #[arg(long, value_name = "T")]
        checkpoint_interval: Option<f64>,
        /// Go on with the run in DIR from its checkpoint.json (the same model and settings;
        /// t_end may be later): its result files are continued as the run would have written
        /// them.
        #[arg(long, value_name = "DIR", conflicts_with = "out")]
        resume: Option<PathBuf>,
        /// Threads of the assembly: 0 for all cores, 1 for a sequential run (timing); the
        /// results are the same bits whatever the number (default: the file's
        /// solver.threads, else all cores).
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(0..=1024))]
        threads: Option<u16>,
        /// The results file: h5 writes DIR/results.h5 as the run goes (docs/results-format.md),
        /// none writes only the CSV files (and then no plot and no animation).
        #[arg(long, value_parser = ["h5", "none"], default_value = "h5")]
        results: String,
        /// Do not draw DIR/summary.png (the sensors' histories) at the end of the run.
        #[arg(long)]
        no_plot: bool,
        /// Write DIR/view.html, the run's 3D animation for a web browser, at its end.
        #[arg(long)]
        view: bool,
    },
    /// Gradients of the model's [[criterion]] items with respect to its [[design_parameter]]
    /// items, exact for the computed solution; write gradients.json and gradients.csv into
    /// DIR. A run with an event (a contact or gear flank that closes or opens) is refused
    /// (exit 2): its gradients would not be exact (a hold's samples are followed).
    Sensitivity {
        model: PathBuf,
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// direct (one solve per parameter and step), adjoint (one backward sweep,
        /// independent of the number of parameters) or fd (central finite differences,
        /// 2 n_p + 1 runs); default: the file's [sensitivity] method, else adjoint.
        #[arg(long, value_parser = ["direct", "adjoint", "fd"])]
        method: Option<String>,
        /// Relative step of the finite differences, in [1e-12, 0.1] (default: the file's
        /// fd_step, else 1e-6).
        #[arg(long, value_name = "S")]
        fd_step: Option<f64>,
        /// Check the exact gradients: the adjoint against central finite differences, both
        /// computed again by full Newton at rtol <= 1e-10, atol <= 1e-12, written to
        /// gradient_check.csv with their relative differences (of scale dJ/dp).
        #[arg(long, conflicts_with = "method")]
        check: bool,
        /// Memory the adjoint may keep for the trajectory, in MiB, in [1, 1e6] (default: the
        /// file's memory_budget_mb, else 256); beyond it, steps are recomputed from
        /// checkpoints.
        #[arg(long, value_name = "M")]
        memory_mb: Option<f64>,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Threads of the assembly: 0 for all cores, 1 for a sequential run (timing); the
        /// results are the same bits whatever the number (default: the file's
        /// solver.threads, else all cores).
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(0..=1024))]
        threads: Option<u16>,
    },
    /// Lower one [[criterion]] of the model over its [[design_parameter]] items that have
    /// both bounds (L-BFGS on the adjoint gradients); write optimization.csv (one row per
    /// improvement) and optimization.json into DIR.
    Optimize {
        model: PathBuf,
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// The criterion to lower (default: the first).
        #[arg(long, value_name = "NAME")]
        criterion: Option<String>,
        /// Most L-BFGS iterations.
        #[arg(long, default_value_t = 20, value_name = "N")]
        iterations: u64,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Threads of the assembly: 0 for all cores, 1 for a sequential run (timing); the
        /// results are the same bits whatever the number (default: the file's
        /// solver.threads, else all cores).
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(0..=1024))]
        threads: Option<u16>,
    },
    /// Draw sensor histories from a results file (RESULTS: a results.h5, or the output
    /// directory of a run) into a PNG or SVG file.
    Plot {
        results: PathBuf,
        /// Sensors to draw (default: all).
        sensors: Vec<String>,
        /// Output file, .png or .svg.
        #[arg(short, long, value_name = "FILE")]
        output: PathBuf,
        /// shared: one axes; stacked: one panel per unit; auto: shared when every sensor
        /// has the same unit.
        #[arg(long, default_value = "auto", value_parser = ["auto", "shared", "stacked"])]
        layout: String,
    },
    /// Write a Paraview time series (DIR/results.pvd and one .vtu file per output step and
    /// kind: beams, bodies, frames, joints) from a results file or a run's directory.
    ExportVtk {
        results: PathBuf,
        /// Output directory (created if needed).
        #[arg(short, long, value_name = "DIR")]
        output: PathBuf,
    },
    /// Write the 3D animation of a run as one HTML file (opens in a web browser, no network
    /// needed) from a results file or a run's directory.
    View {
        results: PathBuf,
        /// Output file (.html).
        #[arg(short, long, value_name = "FILE")]
        output: PathBuf,
    },
    /// Read and check a model file (syntax, references, physics, initial conditions).
    Check {
        model: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

fn main() {
    let code = match Cli::try_parse() {
        Ok(cli) => match cli.command {
            Command::Run {
                model,
                out,
                set,
                quiet,
                verify,
                checkpoint_interval,
                resume,
                threads,
                results,
                no_plot,
                view,
            } => match checkpoint_interval {
                Some(t) if !(t.is_finite() && t > 0.0) => {
                    tell(format_args!(
                        "error: --checkpoint-interval must be a positive number of seconds, got {t}"
                    ));
                    exit::USAGE
                }
                _ => {
                    let options = flexmb::driver::RunOptions {
                        checkpoint_interval,
                        resume: resume.is_some(),
                    };
                    let files = RunFiles {
                        results: results == "h5",
                        plot: results == "h5" && !no_plot,
                        view: results == "h5" && view,
                    };
                    run(
                        &model,
                        resume.as_deref().unwrap_or(&out),
                        &with_threads(set, threads),
                        quiet,
                        verify,
                        options,
                        files,
                    )
                }
            },
            Command::Check { model, set } => check(&model, &set),
            Command::Plot {
                results,
                sensors,
                output,
                layout,
            } => plot(&results, &sensors, &layout, &output),
            Command::ExportVtk { results, output } => export_vtk(&results, &output),
            Command::View { results, output } => view(&results, &output),
            Command::Optimize {
                model,
                out,
                criterion,
                iterations,
                set,
                threads,
            } => optimize(
                &model,
                &out,
                &with_threads(set, threads),
                criterion.as_deref(),
                iterations,
            ),
            Command::Sensitivity {
                model,
                out,
                method,
                fd_step,
                check,
                memory_mb,
                set,
                quiet,
                threads,
            } => {
                let options = SensitivityOptions {
                    method,
                    fd_step,
                    check,
                    memory_mb,
                    quiet,
                };
                sensitivity(&model, &out, &with_threads(set, threads), options)
            }
        },
        Err(e) => {
            // Help and version go to stdout and succeed; a closed stdout loses them.
            let _ = e.print();
            if e.use_stderr() {
                exit::USAGE
            } else {
                exit::OK
            }
        }
    };
    std::process::exit(code);
}

/// The overrides with `--threads` as the last: `solver.threads` set like any key of the file.
fn with_threads(mut set: Vec<String>, threads: Option<u16>) -> Vec<String> {
    if let Some(n) = threads {
        set.push(format!("solver.threads={n}"));
    }
    set
}

/// The files of `flexmb run` beyond the CSV files and the summary.
#[derive(Clone, Copy)]
struct RunFiles {
    /// `results.h5`, written as the run goes.
    results: bool,
    /// `summary.png`, drawn at the end from the results file.
    plot: bool,
    /// `view.html`, written at the end from the results file.
    view: bool,
}

/// `flexmb run`: takes over the output directory, reads the model and runs it.
fn run(
    model: &Path,
    out: &Path,
    set: &[String],
    quiet: bool,
    verify: bool,
    options: flexmb::driver::RunOptions,
    files: RunFiles,
) -> i32 {
    let taken = if options.resume {
        OutputDir::reopen(out)
    } else {
        OutputDir::prepare(out)
    };
    let dir = match taken {
        Ok(dir) => dir,
        Err(e) => {
            tell(format_args!("error: {e}"));
            return exit::OUTPUT_FAILED;
        }
    };
    let interrupt = match signals::Interrupt::install(end_at_once(&dir, out)) {
        Ok(i) => Some(i),
        Err(e) => {
            tell(format_args!(
                "warning: cannot handle signals ({e}): a signal ends the run without a summary"
            ));
            None
        }
    };
    // From here on summary.json describes this run (a resumed run goes on in its directory).
    if let Err(e) = dir.write_summary(&Summary::default()) {
        tell(format_args!("error: {e}"));
        // The run ends here; its end is written in the room kept for it, if it was kept.
        let mut failed = Summary::default();
        failed.fail(ErrorKind::Output, e.to_string());
        let _ = dir.write_summary(&failed);
        return exit::OUTPUT_FAILED;
    }
    let mut file = match flexmb::input::read_model_file(model, set) {
        Ok(file) => file,
        Err(e) => {
            // The error's message includes its cause: print it alone, not its source chain.
            tell(format_args!("error: {e}"));
            let mut summary = Summary::default();
            summary.fail(ErrorKind::Model, e.to_string());
            return match dir.write_summary(&summary) {
                Ok(()) => exit::INVALID_MODEL,
                Err(w) => {
                    tell(format_args!("error: {w}"));
                    exit::OUTPUT_FAILED
                }
            };
        }
    };
    match &mut file.analysis {
        flexmb::input::Analysis::Dynamic(s) => s.verify = verify,
        flexmb::input::Analysis::Static(s) => s.verify = verify,
    }
    let bar = progress_bar(quiet);
    let h5 = flexmb_results::h5::H5Format;
    let formats: &[&dyn flexmb::output::StoreFormat] = if files.results { &[&h5] } else { &[] };
    let result = flexmb::driver::run_with(
        &file,
        &dir,
        options,
        formats,
        &mut |t, t_end| {
            bar.set_position((1000.0 * t / t_end).round() as u64);
            bar.set_message(format!("t = {t:.4} s"));
        },
        interrupt.as_ref().map(|i| i.flag()),
    );
    bar.finish_and_clear();
    let code = report(model, out, &result.summary, interrupt);
    if result.summary.steps > 0 || result.summary.outputs > 0 {
        draw(&dir, files);
    }
    match result.unwritten {
        // The outcome was said above; summary.json could not record it.
        Some(e) => {
            tell(format_args!("error: {e}"));
            exit::OUTPUT_FAILED
        }
        None => code,
    }
}

/// What the second signal does: the run in `dir` (the output directory `out`) is ended at
/// once, its summary written from what its result files hold; returns the exit code.
fn end_at_once(dir: &OutputDir, out: &Path) -> impl FnOnce(i32) -> i32 + Send + 'static {
    let (dir, out) = (dir.clone(), out.to_path_buf());
    move |signal| {
        let name = signals::name(signal);
        let note = format!(
            "a second {name} ended the run at once: the results stop at the last output step written (t_reached); the steps computed after it are lost and no checkpoint was written"
        );
        let ended = dir.end_now(&note, std::time::Duration::from_secs(2));
        match &ended.summary {
            Ok(Some(summary)) => tell(format_args!(
                "interrupted at once by a second {name}: results up to {} are in {}",
                reached(summary),
                out.display()
            )),
            // Not started, or ended (the first signal's end already recorded, its message
            // perhaps not yet printed): summary.json says which.
            Ok(None) => tell(format_args!(
                "interrupted at once by a second {name}: {} says where the results stop",
                out.join("summary.json").display()
            )),
            Err(e) => tell(format_args!("error: {e}")),
        }
        // The run's writer stays held until the process ends (at once, on return): the run
        // cannot write or record anything else meanwhile.
        std::mem::forget(ended);
        signals::exit_code(signal)
    }
}

/// Where a run's results are complete up to, in words: `t = 1.5 s`, `load factor 0.3`.
fn reached(summary: &Summary) -> String {
    if summary.analysis == "static" {
        format!("load factor {}", summary.t_reached)
    } else {
        format!("t = {} s", summary.t_reached)
    }
}

/// Draws what `files` asks for from the results file of the run in `dir` (also after a
/// failed or interrupted run: the steps up to its end). A drawing that fails is a warning:
/// the results themselves are written.
fn draw(dir: &OutputDir, files: RunFiles) {
    if !(files.plot || files.view) {
        return;
    }
    let results = match flexmb_results::h5::read(dir.path()) {
        Ok(r) => r,
        Err(e) => {
            tell(format_args!("warning: no plot or animation: {e}"));
            return;
        }
    };
    if files.plot {
        let path = dir.file(flexmb::output::SUMMARY_PLOT_FILE);
        match flexmb_results::plot::summary(&results, &path) {
            // A model without sensors: the run's notes said so (`driver::NO_SENSORS`).
            Ok(flexmb_results::plot::Summary::NoSensors) => {}
            Ok(summary) => {
                if let Some(note) = summary.note() {
                    say(format_args!("note: {note}"));
                }
            }
            Err(e) => tell(format_args!("warning: no summary plot: {e}")),
        }
    }
    if files.view {
        let path = dir.file(flexmb::output::VIEW_FILE);
        match flexmb_results::write_html(&results, &path) {
            Ok(()) => say(format_args!(
                "animation in {}: open it in a web browser",
                path.display()
            )),
            Err(e) => tell(format_args!("warning: no animation: {e}")),
        }
    }
}

/// Reads the results of a run: a results file, or the output directory of a run.
fn read_results(path: &Path) -> Result<flexmb_results::Results, i32> {
    flexmb_results::h5::read(path).map_err(|e| {
        tell(format_args!("error: {e}"));
        exit::INVALID_MODEL
    })
}

/// `flexmb view`: the browser animation of a results file.
fn view(results: &Path, output: &Path) -> i32 {
    let results = match read_results(results) {
        Ok(r) => r,
        Err(code) => return code,
    };
    match flexmb_results::write_html(&results, output) {
        Ok(()) => {
            say(format_args!(
                "animation in {}: open it in a web browser",
                output.display()
            ));
            exit::OK
        }
        Err(e) => {
            tell(format_args!("error: {e}"));
            exit::OUTPUT_FAILED
        }
    }
}

/// `flexmb export-vtk`: the Paraview series of a results file.
fn export_vtk(results: &Path, output: &Path) -> i32 {
    let results = match read_results(results) {
        Ok(r) => r,
        Err(code) => return code,
    };
    match flexmb_results::export_vtk(&results, output) {
        Ok(series) => {
            say(format_args!(
                "{} files; open {} in Paraview",
                series.files,
                series.pvd.display()
            ));
            exit::OK
        }
        Err(e) => {
            tell(format_args!("error: {e}"));
            exit::OUTPUT_FAILED
        }
    }
}

/// `flexmb plot`: sensor histories from a results file.
fn plot(results: &Path, sensors: &[String], layout: &str, output: &Path) -> i32 {
    let results = match read_results(results) {
        Ok(r) => r,
        Err(code) => return code,
    };
    let layout = layout.parse().expect("clap allows only the layouts");
    match flexmb_results::plot::plot(&results, sensors, layout, output) {
        Ok(()) => {
            say(format_args!("plot in {}", output.display()));
            exit::OK
        }
        Err(e) => {
            tell(format_args!("error: {e}"));
            match e {
                flexmb_results::PlotError::Draw { .. } => exit::OUTPUT_FAILED,
                _ => exit::USAGE,
            }
        }
    }
}

/// Says how a run ended (closing line, warnings, error) and returns its exit code.
fn report(
    model: &Path,
    out: &Path,
    summary: &Summary,
    interrupt: Option<signals::Interrupt>,
) -> i32 {
    for n in &summary.notes {
        say(format_args!("note: {n}"));
    }
    for w in &summary.warnings {
        tell(format_args!("warning: {w}"));
    }
    let reached = reached(summary);
    let error = summary.error.as_deref().unwrap_or("the analysis failed");
    match (summary.status, summary.error_kind) {
        (Status::Ok, _) => {
            say(format_args!(
                "{}: {} steps, {:.2} Newton iterations/step, {} rejected, {:.3} s ({:.3} s solving); results in {}",
                if summary.title.is_empty() { model.display().to_string() } else { summary.title.clone() },
                summary.steps,
                summary.newton_iterations_per_step,
                summary.rejected_steps,
                summary.wall_seconds,
                summary.solve_seconds,
                out.display()
            ));
            if let Some(v) = &summary.verify {
                say(format_args!(
                    "verify: {} steps re-checked with a fresh matrix; largest estimated error {:.3e} of the Newton tolerance at {}",
                    v.steps, v.max_error, v.t
                ));
            }
            exit::OK
        }
        (Status::Incomplete, _) => {
            // (the warning above says which limit and what to raise)
            tell(format_args!(
                "incomplete: results up to {reached} are in {}",
                out.display()
            ));
            exit::INCOMPLETE
        }
        (Status::Interrupted, _) => {
            let signal = interrupt.map_or(signals::SIGINT, |i| i.received());
            tell(format_args!(
                "interrupted by {}: results up to {reached} are in {}",
                signals::name(signal),
                out.display()
            ));
            signals::exit_code(signal)
        }
        (_, Some(ErrorKind::Model)) => {
            tell(format_args!("error: {}: {error}", model.display()));
            exit::INVALID_MODEL
        }
        (_, Some(ErrorKind::Output)) => {
            tell(format_args!("error: {error}"));
            exit::OUTPUT_FAILED
        }
        _ => {
            tell(format_args!("error: {error}"));
            tell(format_args!(
                "results up to {reached} are in {}",
                out.display()
            ));
            exit::ANALYSIS_FAILED
        }
    }
}

/// `flexmb check`: reads the model and builds its solver (the checks a run makes before its
/// first step), without writing anything.
fn check(model: &Path, set: &[String]) -> i32 {
    let file = match flexmb::input::read_model_file(model, set) {
        Ok(file) => file,
        Err(e) => {
            tell(format_args!("error: {e}"));
            return exit::INVALID_MODEL;
        }
    };
    let built = match &file.analysis {
        flexmb::input::Analysis::Dynamic(settings) => {
            flexmb::Simulation::new(&file.model, *settings)
                .map(|sim| (sim.data.layout.n_unknowns(), sim.notes))
        }
        flexmb::input::Analysis::Static(settings) => {
            flexmb::solve::Statics::new(&file.model, *settings)
                .map(|s| (s.data.layout.n_unknowns(), s.notes))
        }
    };
    let (unknowns, notes) = match built {
        Ok(built) => built,
        Err(e) => {
            tell(format_args!("error: {}: {e}", model.display()));
            return exit::INVALID_MODEL;
        }
    };
    for n in &notes {
        say(format_args!("note: {n}"));
    }
    say(format_args!(
        "{}: {} nodes, {} bodies, {} beam elements, {} joints, {} unknowns: ok",
        model.display(),
        file.model.nodes.len(),
        file.model.bodies.len(),
        file.model.beams.len(),
        file.model.joints.len(),
        unknowns
    ));
    exit::OK
}

/// The options of `flexmb sensitivity`.
struct SensitivityOptions {
    method: Option<String>,
    fd_step: Option<f64>,
    check: bool,
    memory_mb: Option<f64>,
    quiet: bool,
}

/// The output directory of `sensitivity` or `optimize`, the model file and its
/// sensitivity setup (taken out of it), which must declare design parameters and
/// criteria; the exit code of a failure, said.
fn prepare_sensitivity(
    model: &Path,
    out: &Path,
    set: &[String],
) -> Result<
    (
        OutputDir,
        flexmb::input::ModelFile,
        flexmb::sensitivity::Setup,
    ),
    i32,
> {
    let dir = OutputDir::prepare(out).map_err(|e| {
        tell(format_args!("error: {e}"));
        exit::OUTPUT_FAILED
    })?;
    let file = flexmb::input::read_model_file(model, set).map_err(|e| {
        tell(format_args!("error: {e}"));
        exit::INVALID_MODEL
    })?;
    let mut file = file;
    let missing = match &file.sensitivity {
        None => Some("the model declares no [[design_parameter]] and no [[criterion]]: nothing to differentiate (docs/model-format.md, \"Sensitivity analysis\")"),
        Some(s) if s.design.is_empty() || s.criteria.is_empty() => Some(
            "a sensitivity analysis needs at least one [[design_parameter]] and one [[criterion]]",
        ),
        Some(_) => None,
    };
    if let Some(m) = missing {
        tell(format_args!("error: {}: {m}", model.display()));
        return Err(exit::INVALID_MODEL);
    }
    let setup = file.sensitivity.take().expect("checked above");
    Ok((dir, file, setup))
}

/// Says why a sensitivity analysis or an optimization failed and returns its exit code: a
/// problem that cannot be analysed as asked (found before the first step, or an event in the
/// run) is an invalid model, said with the model file as `run` says it; the rest is a failed
/// analysis, or one stopped before its end (no gradients of the criteria as declared).
fn sensitivity_failed(model: &Path, e: &flexmb::sensitivity::SensitivityError) -> i32 {
    use flexmb::sensitivity::SensitivityError;
    if e.is_refusal() {
        tell(format_args!("error: {}: {e}", model.display()));
        return exit::INVALID_MODEL;
    }
    tell(format_args!("error: {e}"));
    match e {
        SensitivityError::Solve(flexmb::SolveError::Incomplete { .. }) => exit::INCOMPLETE,
        _ => exit::ANALYSIS_FAILED,
    }
}

/// `Err` with the message of a number option outside `range` (the range of the model file's
/// key `key`).
fn check_option(option: &str, key: &str, v: Option<f64>, range: (f64, f64)) -> Result<(), i32> {
    match v {
        Some(v) if !(v >= range.0 && v <= range.1) => {
            tell(format_args!(
                "error: {option} must be in [{:e}, {:e}] (the range of {key} in [sensitivity]), got {v:e}",
                range.0, range.1
            ));
            Err(exit::USAGE)
        }
        _ => Ok(()),
    }
}

/// `flexmb sensitivity`: the gradients of the model's criteria.
fn sensitivity(model: &Path, out: &Path, set: &[String], options: SensitivityOptions) -> i32 {
    use flexmb::sensitivity::{self, check, report, Method};
    if let Err(code) = check_option(
        "--fd-step",
        "fd_step",
        options.fd_step,
        sensitivity::FD_STEP_RANGE,
    )
    .and_then(|()| {
        check_option(
            "--memory-mb",
            "memory_budget_mb",
            options.memory_mb,
            sensitivity::MEMORY_BUDGET_MB_RANGE,
        )
    }) {
        return code;
    }
    let (dir, file, setup) = match prepare_sensitivity(model, out, set) {
        Ok(prepared) => prepared,
        Err(code) => return code,
    };
    let setup = &setup;
    let fd_step = options.fd_step.unwrap_or(setup.fd_step);
    let method = match options.method.as_deref() {
        _ if options.check => Method::Adjoint,
        Some("direct") => Method::Direct,
        Some("fd") => Method::Fd,
        Some(_) => Method::Adjoint,
        None => setup.method,
    };
    let mut problem = setup.problem(
        std::sync::Arc::new(file.model.clone()),
        file.analysis.clone(),
    );
    if let Some(m) = options.memory_mb {
        problem.memory_budget = (m * (1 << 20) as f64) as usize;
    }
    let bar = progress_bar(options.quiet);
    let mut progress = |done: usize, total: usize| {
        bar.set_position((1000 * done / total.max(1)) as u64);
        bar.set_message("backward sweep");
    };
    let started = std::time::Instant::now();
    let result = sensitivity::gradients(&problem, method, fd_step, &mut progress);
    bar.finish_and_clear();
    let g = match result {
        Ok(g) => g,
        Err(e) => return sensitivity_failed(model, &e),
    };
    for w in &g.warnings {
        tell(format_args!("warning: {w}"));
    }
    let wall = started.elapsed().as_secs_f64();
    let values = problem.values();
    let written = dir
        .write_file(
            flexmb::output::GRADIENTS_JSON_FILE,
            &report::json(setup, &values, method, &g, wall),
        )
        .and_then(|()| dir.write_file(flexmb::output::GRADIENTS_CSV_FILE, &report::csv(setup, &g)));
    if let Err(e) = written {
        tell(format_args!("error: {e}"));
        return exit::OUTPUT_FAILED;
    }
    for (c, crit) in setup.criteria.criteria.iter().enumerate() {
        say(format_args!("{} = {:.10e}", crit.name, g.values[c]));
        for (k, d) in setup.design.iter().enumerate() {
            say(format_args!(
                "  d/d {:<40} {:>+.10e}",
                d.path, g.gradients[c][k]
            ));
        }
    }
    if options.check {
        let checked = match check::check(&problem, &g, fd_step, &mut progress) {
            Ok(checked) => checked,
            Err(e) => return sensitivity_failed(model, &e),
        };
        let (table, worst) = report::check_csv(setup, &checked.exact, &checked.fd);
        if let Err(e) = dir.write_file(flexmb::output::GRADIENT_CHECK_FILE, &table) {
            tell(format_args!("error: {e}"));
            return exit::OUTPUT_FAILED;
        }
        let n = checked.newton;
        say(format_args!(
            "check: the adjoint against central differences (relative step {fd_step:e}), both solved by full Newton at rtol {:e}, atol {:e}, where the differences measure the gradient rather than the Newton iteration's error: largest relative difference of scale dJ/dp {worst:.3e}; table in {}",
            n.rtol,
            n.atol,
            dir.file(flexmb::output::GRADIENT_CHECK_FILE).display()
        ));
        say(format_args!(
            "check: the gradients written (the model's Newton settings) are within {:.3e} of the check's adjoint",
            report::largest_difference(setup, &checked.exact, &g)
        ));
    }
    say(format_args!(
        "{} criteria, {} parameters by {:?} in {wall:.3} s ({} forward runs, {} steps); results in {}",
        setup.criteria.len(),
        setup.design.len(),
        method,
        g.stats.forward_runs,
        g.stats.steps,
        out.display()
    ));
    exit::OK
}

/// `flexmb optimize`: lowers a criterion over the bounded design parameters.
fn optimize(
    model: &Path,
    out: &Path,
    set: &[String],
    criterion: Option<&str>,
    iterations: u64,
) -> i32 {
    use flexmb::sensitivity::optimize::{optimize, Evaluator, Improvement};
    let (dir, file, setup) = match prepare_sensitivity(model, out, set) {
        Ok(prepared) => prepared,
        Err(code) => return code,
    };
    let setup = &setup;
    let invalid = |m: String| {
        tell(format_args!("error: {}: {m}", model.display()));
        exit::INVALID_MODEL
    };
    if file.analysis.dynamic().is_none() {
        return invalid("optimize runs a dynamic analysis".into());
    }
    let names: Vec<&str> = setup
        .criteria
        .criteria
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    let index = match criterion {
        None => 0,
        Some(name) => match names.iter().position(|n| *n == name) {
            Some(i) => i,
            None => {
                return invalid(format!(
                    "no criterion '{name}' (criteria: {})",
                    names.join(", ")
                ))
            }
        },
    };
    let problem = setup.problem(
        std::sync::Arc::new(file.model.clone()),
        file.analysis.clone(),
    );
    let mut evaluator = Evaluator::new(problem);
    let started = std::time::Instant::now();
    let mut report = |it: &Improvement| {
        let values: Vec<String> = it.values.iter().map(|v| format!("{v:.6e}")).collect();
        say(format_args!(
            "evaluation {:>3}: {} = {:.10e} at [{}]",
            it.evaluation,
            names[index],
            it.criterion,
            values.join(", ")
        ));
    };
    let outcome = optimize(
        &mut evaluator,
        &setup.design,
        index,
        iterations,
        &mut report,
    );
    // The improvements found are written whatever the outcome.
    let (history, status, iterations_done, runs) = match &outcome {
        Ok(o) => (&o.history, o.status.clone(), Some(o.iterations), o.runs),
        Err(s) => (&s.history, format!("stopped: {}", s.error), None, s.runs),
    };
    if !history.is_empty() {
        let csv = flexmb::sensitivity::report::optimization_csv(&setup.design, history);
        let json = serde_json::json!({
            "criterion": names[index],
            "parameters": setup.design.iter().map(|d| d.path.clone()).collect::<Vec<_>>(),
            "status": status,
            "iterations": iterations_done,
            "runs": runs,
            "wall_seconds": started.elapsed().as_secs_f64(),
            "first": history.first(),
            "last": history.last(),
        });
        let mut text = serde_json::to_string_pretty(&json).expect("numbers and strings");
        text.push('\n');
        let written = dir
            .write_file(flexmb::output::OPTIMIZATION_CSV_FILE, &csv)
            .and_then(|()| dir.write_file(flexmb::output::OPTIMIZATION_JSON_FILE, &text));
        if let Err(e) = written {
            tell(format_args!("error: {e}"));
            return exit::OUTPUT_FAILED;
        }
    }
    let optimum = match outcome {
        Ok(o) => o,
        Err(stopped) => {
            let code = sensitivity_failed(model, &stopped.error);
            if !stopped.history.is_empty() {
                tell(format_args!(
                    "the {} improvements found before are in {}",
                    stopped.history.len(),
                    dir.file(flexmb::output::OPTIMIZATION_CSV_FILE).display()
                ));
            }
            return code;
        }
    };
    let (first, last) = (
        &optimum.history[0],
        &optimum.history[optimum.history.len() - 1],
    );
    say(format_args!(
        "{}: {:.6e} -> {:.6e} ({:.1} %) in {} L-BFGS iterations, {} runs ({}); history in {}",
        names[index],
        first.criterion,
        last.criterion,
        100.0 * (last.criterion - first.criterion) / first.criterion.abs().max(f64::MIN_POSITIVE),
        optimum.iterations,
        optimum.runs,
        optimum.status,
        out.display()
    ));
    if optimum.iteration_limit {
        tell(format_args!(
            "warning: the optimization stopped after --iterations {iterations} L-BFGS iterations before it converged: the last point is the best found, not an optimum; raise --iterations"
        ));
        return exit::INCOMPLETE;
    }
    exit::OK
}

/// A progress bar on stderr when it is a terminal; hidden otherwise or with `--quiet`.
fn progress_bar(quiet: bool) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::hidden());
    }
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:40} {percent:>3}% {msg} [{elapsed_precise} < {eta_precise}]",
        )
        .expect("valid template"),
    );
    bar
}
