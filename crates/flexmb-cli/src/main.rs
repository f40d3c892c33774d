//! `flexmb`: run multibody models from the command line.
//!
//! ```text
//! flexmb run MODEL.toml --out DIR [--set key.path=value ...]
//! flexmb check MODEL.toml [--set ...]
//! ```

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "flexmb",
    version,
    about = "Flexible multibody dynamics on Lie groups"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the analysis a model file declares; write sensors.csv and summary.json into DIR.
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
    },
    /// Read and check a model file (syntax, references, physics, initial conditions).
    Check {
        model: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

fn main() {
    let cli = Cli::parse();
    let code = match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            2
        }
    };
    std::process::exit(code);
}

fn run(cli: Cli) -> Result<i32> {
    match cli.command {
        Command::Run {
            model,
            out,
            set,
            quiet,
        } => {
            let file = flexmb::input::read_model_file(&model, &set)?;
            let bar = progress_bar(quiet);
            let summary = flexmb::driver::run(&file, &out, &mut |t, t_end| {
                bar.set_position((1000.0 * t / t_end).round() as u64);
                bar.set_message(format!("t = {t:.4} s"));
            })
            .with_context(|| format!("writing results into {}", out.display()))?;
            bar.finish_and_clear();
            for w in &summary.warnings {
                eprintln!("warning: {w}");
            }
            if summary.status != "ok" {
                eprintln!(
                    "error: {}",
                    summary.error.as_deref().unwrap_or("the analysis failed")
                );
                if summary.analysis == "static" {
                    eprintln!(
                        "results up to load factor {:.6e} are in {}",
                        summary.t_reached,
                        out.display()
                    );
                } else {
                    eprintln!(
                        "results up to t = {:.6} s are in {}",
                        summary.t_reached,
                        out.display()
                    );
                }
                return Ok(1);
            }
            println!(
                "{}: {} steps, {:.2} Newton iterations/step, {} rejected, {:.3} s ({:.3} s solving); results in {}",
                if summary.title.is_empty() { model.display().to_string() } else { summary.title.clone() },
                summary.steps,
                summary.newton_iterations_per_step,
                summary.rejected_steps,
                summary.wall_seconds,
                summary.solve_seconds,
                out.display()
            );
            Ok(0)
        }
        Command::Check { model, set } => {
            let file = flexmb::input::read_model_file(&model, &set)?;
            let (unknowns, warnings) = match &file.analysis {
                flexmb::input::Analysis::Dynamic(settings) => {
                    let sim = flexmb::Simulation::new(&file.model, *settings)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", model.display()))?;
                    (sim.data.layout.n_unknowns(), sim.warnings)
                }
                flexmb::input::Analysis::Static(settings) => {
                    let s = flexmb::solve::Statics::new(&file.model, *settings)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", model.display()))?;
                    (s.data.layout.n_unknowns(), s.warnings)
                }
            };
            for w in &warnings {
                eprintln!("warning: {w}");
            }
            println!(
                "{}: {} nodes, {} bodies, {} beam elements, {} joints, {} unknowns: ok",
                model.display(),
                file.model.nodes.len(),
                file.model.bodies.len(),
                file.model.beams.len(),
                file.model.joints.len(),
                unknowns
            );
            Ok(0)
        }
    }
}

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
