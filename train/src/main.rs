//! `train CONFIG [--set KEY=VALUE]… [--resume] [--keep K] [--steps N] [--run-dir DIR] [--backend B]`: trains an
//! experiment config; exit status 2 on bad input (config, dataset, backend, checkpoint).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

/// Train a LIBERO-Mem policy from an experiment config.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Experiment config (TOML), e.g. configs/t3.toml.
    config: PathBuf,
    /// Continue from the run directory's newest checkpoint (an error if there is none);
    /// resuming is automatic anyway when checkpoints exist.
    #[arg(long)]
    resume: bool,
    /// Keep only the newest K checkpoints (0 = all); overrides [train].keep.
    #[arg(long)]
    keep: Option<usize>,
    /// Total optimiser steps (≥ 1); overrides [train].steps.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    steps: Option<u64>,
    /// Run directory (default: runs/<name>).
    #[arg(long)]
    run_dir: Option<PathBuf>,
    /// Backend: flex, ndarray (feature `ndarray`) or wgpu (feature `wgpu`); overrides [backend].
    #[arg(long)]
    backend: Option<String>,
    /// Override a config key, `KEY=VALUE` with a TOML value (repeatable), e.g.
    /// `--set model.variant=slotvla_h1 --set name=t3_h1`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn run(args: Args) -> Result<train::TrainSummary, train::TrainError> {
    let cfg = train::Config::load_with(&args.config, &args.sets)?;
    let opts = train::TrainOptions {
        resume: args.resume,
        keep: args.keep,
        steps: args.steps,
        run_dir: args.run_dir,
        backend: args
            .backend
            .as_deref()
            .map(str::parse)
            .transpose()
            .map_err(train::TrainError::Usage)?,
        progress: !args.quiet,
        stop_at: None,
    };
    train::train(&cfg, &opts)
}

fn main() -> ExitCode {
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    match run(args) {
        Ok(s) => {
            let fmt = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.4}"));
            data::outln!(
                "{}: steps {}..{}, loss {} → {}, val {}, {:.2} steps/s",
                s.run_dir.display(),
                s.start_step,
                s.step,
                fmt(s.first_loss),
                fmt(s.final_loss),
                fmt(s.val_loss),
                s.steps_per_s
            );
            ExitCode::SUCCESS
        }
        Err(e) => data::exit::report::<train::TrainError>(&anyhow::Error::new(e)),
    }
}
