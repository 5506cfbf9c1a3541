//! `eval`: closed-loop evaluation tables. Logic lives in the `eval` library.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::Context;
use clap::{Parser, ValueEnum};
use eval::{EvalConfig, EvalError, Policy, RandomPolicy, ZeroPolicy};

#[derive(Clone, Copy, ValueEnum)]
enum PolicyKind {
    /// All-zero actions.
    Zero,
    /// Uniform random actions.
    Random,
}

#[derive(Parser)]
#[command(
    name = "eval",
    version,
    about = "Closed-loop evaluation with subgoal-completion and success tables"
)]
struct Cli {
    /// Tasks: comma-separated ids (`t1,t3,libero_goal/turn_on_the_stove`) or `libero_mem`, `libero_goal`, `all`.
    #[arg(long, default_value = "libero_mem")]
    tasks: String,
    /// Episodes per task.
    #[arg(long, default_value_t = 20)]
    episodes: usize,
    /// Base seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sanity policy to evaluate.
    #[arg(long, value_enum, default_value = "zero")]
    policy: PolicyKind,
    /// Repetitions for the repetition family (t1–t6), e.g. 12 for the temporal-scaling test.
    #[arg(long)]
    repeat: Option<usize>,
    /// Run the whole step budget (upstream mem_6) instead of stopping at success.
    #[arg(long)]
    full_budget: bool,
    /// Worker threads (one simulator each).
    #[arg(long, default_value_t = 1)]
    workers: usize,
    /// Folder for results.md, results.json and results.csv.
    #[arg(long, default_value = "results")]
    out: PathBuf,
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            let bad_input = matches!(
                e.downcast_ref::<EvalError>(),
                Some(EvalError::Task(_) | EvalError::Argument(_))
            );
            ExitCode::from(if bad_input { 2 } else { 1 })
        }
    }
}

fn make_policy(kind: PolicyKind) -> Box<dyn Policy> {
    match kind {
        PolicyKind::Zero => Box::new(ZeroPolicy),
        PolicyKind::Random => Box::new(RandomPolicy::default()),
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    if cli.episodes == 0 || cli.workers == 0 {
        return Err(
            EvalError::Argument("--episodes and --workers must be at least 1".into()).into(),
        );
    }
    let tasks = eval::resolve_tasks(&cli.tasks, cli.repeat)?;
    let cfg = EvalConfig {
        episodes: cli.episodes,
        seed: cli.seed,
        full_budget: cli.full_budget,
        ..EvalConfig::default()
    };
    std::fs::create_dir_all(&cli.out).with_context(|| format!("creating {}", cli.out.display()))?;
    let total = (tasks.len() * cfg.episodes) as u64;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} episodes  {msg}  ETA {eta}")
            .expect("valid template"),
    );
    let mut rows = Vec::new();
    let mut all = Vec::new();
    for task in &tasks {
        let results = Mutex::new(Vec::new());
        let next = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| -> anyhow::Result<()> {
            let handles: Vec<_> = (0..cli.workers.min(cfg.episodes))
                .map(|_| {
                    s.spawn(|| -> Result<(), EvalError> {
                        let mut policy = make_policy(cli.policy);
                        let mut env = eval::env_for(task, policy.as_ref(), &cfg)?;
                        loop {
                            let k = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                            if k >= cfg.episodes {
                                return Ok(());
                            }
                            let r = eval::run_episode(&mut env, task, policy.as_mut(), &cfg, k)?;
                            let mut guard = results.lock().expect("no worker panicked");
                            guard.push(r);
                            let done = guard.len();
                            let mean = guard.iter().map(|e| e.tiered()).sum::<f64>() / done as f64;
                            bar.set_message(format!(
                                "{}: completion {:.0} %",
                                task.id,
                                100.0 * mean
                            ));
                            bar.inc(1);
                        }
                    })
                })
                .collect();
            for h in handles {
                h.join().expect("worker panicked")?;
            }
            Ok(())
        })?;
        let mut eps = results.into_inner().expect("no worker panicked");
        eps.sort_by_key(|e| e.episode);
        rows.push(eval::summarize(&task.id, &eps));
        all.extend(eps);
    }
    bar.finish_and_clear();
    let md = eval::markdown(&rows);
    print!("{md}");
    let json = serde_json::json!({ "policy": policy_name(cli.policy), "seed": cli.seed, "tasks": rows, "episodes": all });
    write_atomic(&cli.out.join("results.md"), md.as_bytes())?;
    write_atomic(
        &cli.out.join("results.json"),
        serde_json::to_string_pretty(&json)?.as_bytes(),
    )?;
    write_atomic(&cli.out.join("results.csv"), eval::csv(&rows).as_bytes())?;
    Ok(())
}

fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

fn policy_name(kind: PolicyKind) -> &'static str {
    match kind {
        PolicyKind::Zero => "zero",
        PolicyKind::Random => "random",
    }
}
