//! `train CONFIG [--set KEY=VALUE]… [--resume] [--keep K] [--steps N] [--run-dir DIR] [--backend B]
//! [--threads N] [--bench N [--json]] [--validate]`: trains an experiment config (or measures the
//! trainer's speed on it, or validates its newest checkpoint); exit status 2 on bad input (config,
//! dataset, backend, checkpoint).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

/// mimalloc as the allocator: the model allocates and frees many tensor buffers per step, whose
/// pages glibc's malloc returns to the kernel and faults in again (≈ 10 % of the
/// decoder's forward+backward alone); `main` also turns mimalloc's own purging off
/// ([`data::alloc::keep_freed_pages`]).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
    /// Backend: flex, ndarray, wgpu or cuda (the last three behind the cargo features of the same
    /// name); overrides [backend].
    #[arg(long)]
    backend: Option<String>,
    /// Override a config key, `KEY=VALUE` with a TOML value (repeatable), e.g.
    /// `--set model.variant=slotvla_h1 --set name=t3_h1`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Threads of the pool that runs the tensor kernels and reads the data (default: one per
    /// core, or RAYON_NUM_THREADS). Results are the same bit for bit at any count.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
    /// Prepare each batch in the loop instead of on the loader thread (same batches; slower).
    #[arg(long)]
    no_prefetch: bool,
    /// Measure instead of training: N timed steps (after 3 untimed) in a throw-away run
    /// directory, with the time per step and its parts, and the loader's windows/s alone.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    bench: Option<u64>,
    /// With --bench: print the figures as one JSON line instead of a table.
    #[arg(long, requires = "bench")]
    json: bool,
    /// Validate the run directory's newest checkpoint (its EMA weights where kept) instead of
    /// training: the cold-memory windows of `val.jsonl` and the validation episodes walked with
    /// carried memory of `val_walk.jsonl` (`[train].val_walk` of them), printed, nothing written.
    #[arg(long, conflicts_with_all = ["bench", "resume", "steps"])]
    validate: bool,
}

enum Outcome {
    Trained(train::TrainSummary),
    Validated(PathBuf, Box<train::trainer::Validation>),
    Measured(train::bench::BenchReport, bool),
}

fn run(args: Args) -> Result<Outcome, train::TrainError> {
    if let Some(n) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(usize::from(n))
            .build_global()
            .map_err(|e| train::TrainError::Other(format!("--threads: {e}")))?;
    }
    let cfg = train::Config::load_with(&args.config, &args.sets)?;
    if let Some(steps) = args.bench {
        let mut cfg = cfg;
        if let Some(b) = &args.backend {
            cfg.backend.kind = b.parse().map_err(train::TrainError::Usage)?;
        }
        let opts = train::bench::BenchOptions {
            steps,
            warmup: 3,
            loader_batches: 20,
        };
        return Ok(Outcome::Measured(
            train::bench::run(&cfg, &opts, !args.quiet)?,
            args.json,
        ));
    }
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
        no_prefetch: args.no_prefetch,
    };
    if args.validate {
        return train::trainer::validate_run(&cfg, &opts)
            .map(|(c, v)| Outcome::Validated(c, Box::new(v)));
    }
    train::train(&cfg, &opts).map(Outcome::Trained)
}

fn main() -> ExitCode {
    data::alloc::keep_freed_pages();
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    match run(args) {
        Ok(Outcome::Measured(report, json)) => {
            if json {
                data::outln!("{}", serde_json::to_string(&report).expect("plain numbers"));
            } else {
                data::outln!("{}", report.to_markdown());
            }
            ExitCode::SUCCESS
        }
        Ok(Outcome::Trained(s)) => {
            let fmt = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.4}"));
            data::outln!(
                "{}: steps {}..{}, loss {} → {}, val {} (walked {}), {:.2} steps/s",
                s.run_dir.display(),
                s.start_step,
                s.step,
                fmt(s.first_loss),
                fmt(s.final_loss),
                fmt(s.val_loss),
                fmt(s.val_walk_loss),
                s.steps_per_s
            );
            ExitCode::SUCCESS
        }
        Ok(Outcome::Validated(checkpoint, v)) => {
            data::outln!(
                "{} (step {}): {}",
                checkpoint.display(),
                v.step,
                v.line().unwrap_or_else(|| "no validation split".into())
            );
            for (name, r) in [("windows", &v.windows), ("walked", &v.walked)] {
                if let Some(r) = r {
                    data::outln!(
                        "{name} {}",
                        serde_json::to_string(r).expect("plain numbers")
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Err(e) => data::exit::report::<train::TrainError>(&anyhow::Error::new(e)),
    }
}
