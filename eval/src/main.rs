//! `eval`: closed-loop evaluation tables. Logic lives in the `eval` library.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand, ValueEnum};
use eval::report::{self, Results, ScalingRow};
use eval::{EvalConfig, EvalError, Policy, RunDir};

/// mimalloc as the allocator, as in `train`: the policy allocates and frees many tensor buffers
/// per step, whose pages glibc's malloc returns to the kernel and faults in again; `main` also
/// turns mimalloc's own purging off ([`data::alloc::keep_freed_pages`]).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum PolicyKind {
    /// The trained model of `--run`.
    Model,
    /// The scripted expert (privileged state).
    Expert,
    /// Uniform random actions.
    Random,
    /// All-zero actions.
    Zero,
}

/// `--policy`: a kind, or a policy server's `ws://` URL.
#[derive(Clone, PartialEq, Eq)]
enum PolicyArg {
    Kind(PolicyKind),
    Remote(String),
}

fn parse_backend(s: &str) -> Result<model::backend::BackendKind, String> {
    s.parse()
}

fn parse_policy(s: &str) -> Result<PolicyArg, String> {
    if s.contains("://") {
        eval::remote::parse_url(s).map_err(|e| e.to_string())?;
        return Ok(PolicyArg::Remote(s.to_string()));
    }
    PolicyKind::from_str(s, false)
        .map(PolicyArg::Kind)
        .map_err(|_| format!("`{s}`: expected model, expert, random, zero or ws://HOST:PORT"))
}

impl PolicyKind {
    fn name(self) -> &'static str {
        match self {
            PolicyKind::Model => "model",
            PolicyKind::Expert => "expert",
            PolicyKind::Random => "random",
            PolicyKind::Zero => "zero",
        }
    }
}

#[derive(Parser)]
#[command(
    name = "eval",
    version,
    about = "Closed-loop evaluation with subgoal-completion and success tables",
    args_conflicts_with_subcommands = true,
    args_override_self = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    eval: EvalArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Put several evaluated runs side by side (subgoal completion and success tables).
    Compare {
        /// Run directories (their `eval/results.json`), eval output folders or results.json files.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Also write the tables to this Markdown file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The paper's experiment: train every variant of an experiment file (with the `train`
    /// binary beside this one), evaluate each on held-out seeds, write the tables (resumable).
    Experiment {
        /// Experiment file, e.g. configs/experiments/paper.toml.
        file: PathBuf,
        /// Only rebuild the tables from the runs evaluated so far, in their run directories or in the
        /// ledger OUT/runs.json (no training, no rollouts).
        #[arg(long)]
        tables_only: bool,
        /// Only print the plan: every run (of --obs/--suite/--tag) with whether it is evaluated
        /// already and the `train` command that trains it (recipes expanded); runs nothing.
        #[arg(long, conflicts_with = "tables_only")]
        plan: bool,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Trainings at once (each `train` keeps about one core busy); the first run of a config
        /// whose dataset is not recorded yet trains alone first, as it generates the dataset.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
        jobs: u64,
        /// Train and evaluate only the runs of this observation mode (`state`, `pixels`); the
        /// tables keep every run of the file evaluated so far.
        #[arg(long)]
        obs: Option<String>,
        /// Train and evaluate only the runs of this suite (as the file's `suite`, e.g.
        /// `libero_mem`); the tables keep every run of the file evaluated so far.
        #[arg(long)]
        suite: Option<String>,
        /// Train and evaluate only the runs of the groups with this `tag` (`""`: the groups
        /// without one); the tables keep every run of the file evaluated so far.
        #[arg(long)]
        tag: Option<String>,
    },
    /// Join the results of the shards of one evaluation (`eval --shard I/N`, e.g. a Slurm array
    /// job's tasks) into the unsharded run's results.{md,json,csv}.
    Merge {
        /// Every shard's output folder (or results.json), in any order.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Folder for the merged results.md, results.json and results.csv.
        #[arg(long)]
        out: PathBuf,
    },
    /// Serve a training run over openpi's websocket protocol (any openpi client, or `eval
    /// --policy ws://HOST:PORT`, can query it); one streaming policy per connection.
    Serve {
        /// Training run directory (`runs/<name>`).
        #[arg(long)]
        run: PathBuf,
        /// Address to listen on.
        #[arg(long, default_value = "127.0.0.1")]
        host: String,
        /// Port (0: any free port, printed).
        #[arg(long, default_value_t = 8000)]
        port: u16,
        /// Stop after this many connections have ended [default: serve until killed].
        #[arg(long)]
        connections: Option<usize>,
        /// Backend to run the policy on: flex, ndarray, wgpu, cuda [default: the run's own].
        #[arg(long, value_parser = parse_backend)]
        backend: Option<model::backend::BackendKind>,
    },
    /// DAgger's data: the run's policy drives each episode up to a step drawn from the budget
    /// (and on to a state the expert can take over from), the scripted expert re-plans from there
    /// and finishes it; the episodes it finishes are recorded whole under OUT/dagger_<task
    /// folder>/ with the expert's steps as the only labels (`labelled_from`), to train on beside
    /// the run's dataset (resumable from the ledger OUT/dagger.jsonl).
    Dagger {
        /// Training run directory whose policy drives.
        #[arg(long)]
        run: PathBuf,
        /// Output folder (a suite dataset's layout).
        #[arg(long)]
        out: PathBuf,
        /// Tasks, as for evaluation [default: the run's `[eval].tasks`, else libero_mem].
        #[arg(long)]
        tasks: Option<String>,
        /// Episodes per task.
        #[arg(long, default_value_t = 20)]
        episodes: usize,
        /// Base seed of the episodes (keep it apart from the evaluation's).
        #[arg(long, default_value_t = 2000)]
        seed: u64,
        /// Earliest take-over, as a share of the task's step budget.
        #[arg(long, default_value_t = 0.05)]
        from: f64,
        /// Latest take-over, as a share of the task's step budget.
        #[arg(long, default_value_t = 0.9)]
        to: f64,
        /// Camera image side recorded (the dataset's).
        #[arg(long, default_value_t = 32)]
        image_size: usize,
        /// How the expert chooses an `Or` goal's branch (`gripper`, `destination`), as the
        /// dataset's generation did.
        #[arg(long, default_value = "gripper")]
        branch_rule: sim::expert::BranchRule,
        /// The dataset the policy was trained on: its episodes are linked into OUT beside the
        /// take-overs and OUT indexed as one dataset (its validation share and split seed).
        #[arg(long)]
        base: Option<PathBuf>,
        /// Worker threads (one simulator and one policy each).
        #[arg(long, default_value_t = 1)]
        workers: usize,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Temporal scaling: evaluate the repetition family at several repetition counts N.
    Scaling {
        /// Repetition counts (N unseen in training allowed), e.g. `3,5,7,9,12`.
        #[arg(long, value_delimiter = ',', required = true)]
        repeats: Vec<usize>,
        #[command(flatten)]
        eval: Box<EvalArgs>,
    },
}

#[derive(Args, Clone)]
struct EvalArgs {
    /// Training run directory to evaluate (`runs/<name>`: config, model, checkpoints).
    #[arg(long)]
    run: Option<PathBuf>,
    /// Policy: `model` (default with --run), a sanity policy without a checkpoint (`expert`,
    /// `random`, `zero`), or a policy server speaking openpi's websocket protocol
    /// (`ws://HOST:PORT`: openpi's `serve_policy.py`, `eval serve`), one connection per worker.
    #[arg(long, value_parser = parse_policy)]
    policy: Option<PolicyArg>,
    /// With a `ws://` policy: actions of each returned chunk executed before the next request
    /// (openpi's `replan_steps`).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    replan_steps: u64,
    /// With a `ws://` policy: send the pending subgoal's text (`libero_mem/subgoal`) with every
    /// request (the oracle subgoal).
    #[arg(long)]
    send_subgoal: bool,
    /// With a `ws://` policy: seconds to wait for the connection and for each reply.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u64).range(1..))]
    remote_timeout: u64,
    /// Tasks: comma-separated ids (`t1,t3,libero_goal/turn_on_the_stove`,
    /// `libero_90/<file_stem>`) or suites `libero_mem`, `libero_goal`, `all` (the 20 shipped), and,
    /// with the LIBERO pack, `libero_spatial`, `libero_object`, `libero_10`, `libero_90`
    /// [default: the run's `[eval].tasks`, else libero_mem].
    #[arg(long)]
    tasks: Option<String>,
    /// Backend the model runs on: flex, ndarray, wgpu or cuda (the last three behind the cargo
    /// features of the same name) [default: the one the run was trained on], e.g. `flex` to
    /// evaluate on the CPU a run trained on a GPU.
    #[arg(long, value_parser = parse_backend)]
    backend: Option<model::backend::BackendKind>,
    /// Episodes per task.
    #[arg(long, default_value_t = 20)]
    episodes: usize,
    /// Base seed (episode k uses a seed derived from it and k).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Repetitions for the repetition family (t1–t6), e.g. 12 (unseen in training is fine).
    #[arg(long)]
    repeat: Option<usize>,
    /// Run the whole step budget (upstream mem_6) instead of stopping at success.
    #[arg(long)]
    full_budget: bool,
    /// Worker threads (one simulator and one policy each).
    #[arg(long, default_value_t = 1)]
    workers: usize,
    /// With --workers N: N processes of eval instead of threads, each a shard (`--shard i/N`, its
    /// results under OUT/processes/), merged into OUT at the end — every core renders (llvmpipe
    /// draws one frame at a time per process); the same tables and recordings as one process.
    #[arg(long)]
    processes: bool,
    /// Camera image side rendered for the model (as recorded by `sim generate`) [default: 128;
    /// 256 with a `ws://` policy, the side openpi's LIBERO example renders before resizing to 224].
    #[arg(long)]
    image_size: Option<usize>,
    /// Rendering quality: `fast` (the dataset default) or `libero` (MuJoCo's defaults as robosuite
    /// renders: LIBERO's look, for policies trained on LIBERO's images).
    #[arg(long, default_value = "fast", value_parser = ["fast", "libero", "high"])]
    quality: String,
    /// Evaluate the run's checkpoint of this training step (`RUN/checkpoints/step_…`, e.g. 40000)
    /// instead of its newest one: closed-loop learning curves. Its results go to RUN/eval_step_N
    /// unless --out says otherwise, so RUN/eval stays the evaluation of the finished run.
    #[arg(long)]
    checkpoint: Option<u64>,
    /// Folder for results.md, results.json and results.csv [default: RUN/eval (RUN/eval_step_N
    /// with --checkpoint N), else `results`].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Record every rollout as an mcap episode under this folder.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Write every rollout as an mp4 under this folder (`<task>/episode_<k>.mp4`: agentview |
    /// eye-in-hand, step and pending subgoal as captions; H.264) and OUT/index.html linking each
    /// video with its episode's result row.
    #[arg(long)]
    video: Option<PathBuf>,
    /// Write slot-attention overlays of the first rollout to OUT/viz (model policy only).
    #[arg(long)]
    viz: bool,
    /// Every how many steps a slot overlay is written.
    #[arg(long, default_value_t = 4)]
    viz_every: usize,
    /// LIBERO's protocol for LIBERO tasks: episode k starts from the task's init state k (needs the
    /// LIBERO pack: `sim assets install libero`), then 10 idle steps. Implied for LIBERO tasks with
    /// `--assets libero` and for the pack-only suites.
    #[arg(long)]
    libero_init: bool,
    /// Asset pack of the scenes: builtin (primitives) or libero (LIBERO's arenas, meshes and
    /// robot look; needs `sim assets install libero`). The pack-only suites always use libero.
    #[arg(long, default_value = "builtin")]
    assets: String,
    /// Run only shard I of N of every task's episodes (k mod N = I; 0 ≤ I < N), e.g. one task of
    /// a Slurm array job; `eval merge` joins the shards' output folders.
    #[arg(long)]
    shard: Option<data::shard::Shard>,
    /// How the model's action chunks are executed: `first` (each step's first action),
    /// `ensemble` (ACT's temporal ensembling over the last H_a chunks) or N (the first N actions
    /// of a chunk open-loop, openpi's replan steps).
    #[arg(long, default_value = "first")]
    execute: eval::policy::Execution,
    /// Ignore the model's termination head (models trained with `train.loss_weights.done`):
    /// by default the robot is held still once the head says done for a few steps in a row.
    #[arg(long)]
    no_stop: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn main() -> ExitCode {
    data::alloc::keep_freed_pages();
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Compare { runs, out }) => compare(&runs, out),
        Some(Command::Merge { parts, out }) => merge(&parts, &out),
        Some(Command::Serve {
            run,
            host,
            port,
            connections,
            backend,
        }) => serve(&run, &host, port, connections, backend),
        Some(Command::Scaling { repeats, eval }) => scaling(&eval, &repeats),
        Some(Command::Dagger {
            run,
            out,
            tasks,
            episodes,
            seed,
            from,
            to,
            image_size,
            branch_rule,
            base,
            workers,
            quiet,
        }) => dagger(
            &run,
            &out,
            base.as_deref(),
            tasks,
            eval::dagger::DaggerConfig {
                episodes,
                seed,
                take_over: (from, to),
                image_size,
                workers,
                expert: sim::expert::ExpertConfig {
                    branch_rule,
                    ..sim::generate::plain_expert()
                },
                source: String::new(),
            },
            quiet,
        ),
        Some(Command::Experiment {
            file,
            tables_only,
            plan,
            quiet,
            jobs,
            obs,
            suite,
            tag,
        }) => experiment(
            &file,
            if plan {
                Mode::Plan
            } else if tables_only {
                Mode::TablesOnly
            } else {
                Mode::Run
            },
            quiet,
            jobs as usize,
            &eval::experiment::Only { obs, suite, tag },
        ),
        None => evaluate(&cli.eval),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => data::exit::report::<EvalError>(&e),
    }
}

/// `eval dagger`: take-over episodes of `run`'s policy into `out`, with a per-task summary
/// (printed; every episode in the ledger OUT/dagger.jsonl).
fn dagger(
    run: &std::path::Path,
    out: &std::path::Path,
    base: Option<&std::path::Path>,
    tasks: Option<String>,
    cfg: eval::dagger::DaggerConfig,
    quiet: bool,
) -> anyhow::Result<()> {
    if !(0.0..=1.0).contains(&cfg.take_over.0)
        || !(0.0..=1.0).contains(&cfg.take_over.1)
        || cfg.take_over.0 > cfg.take_over.1
    {
        return Err(EvalError::Argument(format!(
            "--from {} --to {}: need 0 ≤ from ≤ to ≤ 1",
            cfg.take_over.0, cfg.take_over.1
        ))
        .into());
    }
    let r = eval::run::open_at(run, None)?;
    let cfg = eval::dagger::DaggerConfig {
        source: format!("{} (step {})", r.dir.display(), r.step),
        ..cfg
    };
    let device = eval::run::device(&r, None)?;
    let spec = match tasks {
        Some(t) => t,
        None if !r.info.eval_tasks.is_empty() => r.info.eval_tasks.join(","),
        None => "libero_mem".into(),
    };
    let tasks = eval::resolve_tasks(&spec, None)?;
    let make =
        || -> Result<Box<dyn Policy>, EvalError> { Ok(Box::new(eval::run::policy(&r, &device)?)) };
    let bar = episodes_bar(quiet, (tasks.len() * cfg.episodes) as u64);
    bar.set_prefix("dagger");
    let kept = std::sync::atomic::AtomicUsize::new(0);
    let progress = |t: &eval::dagger::TakeOver| {
        let k =
            kept.fetch_add(t.kept as usize, std::sync::atomic::Ordering::SeqCst) + t.kept as usize;
        bar.inc(1);
        bar.set_message(format!("{}: {k} kept", report::short(&t.task)));
    };
    let entries = eval::dagger::collect(&tasks, &make, &cfg, out, &progress)?;
    bar.finish_and_clear();
    // No take-over (no expert step): the policy had over-repeated first, or the budget ended
    // before a state the expert can take over from.
    println!(
        "task  run  no take-over  expert finished (kept)  mean take-over step  satisfied at take-over"
    );
    for task in &tasks {
        let v: Vec<_> = entries.iter().filter(|t| t.task == task.id).collect();
        if v.is_empty() {
            continue;
        }
        let n = v.len() as f64;
        let none = v.iter().filter(|t| !t.kept && t.expert_steps == 0).count();
        let kept = v.iter().filter(|t| t.kept).count();
        println!(
            "{:<5} {:>4} {:>13} {:>15} of {:<6} {:>20.0} {:>23.2}",
            report::short(&task.id),
            v.len(),
            none,
            kept,
            v.len() - none,
            v.iter().map(|t| t.at as f64).sum::<f64>() / n,
            v.iter().map(|t| t.satisfied_at as f64).sum::<f64>() / n
        );
    }
    if let Some(base) = base {
        let index = eval::dagger::join_base(out, base)?;
        println!(
            "{}: {} episodes with {}'s, indexed (train on it with data.dir = {:?})",
            out.display(),
            index.episodes.len(),
            base.display(),
            out.display()
        );
    }
    Ok(())
}

/// The resolved policy choice, with the run it loads.
struct Setup {
    kind: PolicyKind,
    remote: Option<eval::remote::RemoteConfig>,
    run: Option<RunDir>,
    device: burn::prelude::Device,
    tasks: String,
    out: PathBuf,
    execute: eval::policy::Execution,
    stop: bool,
}

fn setup(args: &EvalArgs) -> anyhow::Result<Setup> {
    let remote = match &args.policy {
        Some(PolicyArg::Remote(url)) => {
            if args.run.is_some() {
                return Err(EvalError::Argument(
                    "give either --run or a ws:// --policy, not both".into(),
                )
                .into());
            }
            Some(eval::remote::RemoteConfig {
                url: url.clone(),
                replan_steps: args.replan_steps as usize,
                send_subgoal: args.send_subgoal,
                timeout: std::time::Duration::from_secs(args.remote_timeout),
            })
        }
        _ => None,
    };
    let kind = match (&args.policy, &args.run) {
        (Some(PolicyArg::Kind(k)), _) => *k,
        (Some(PolicyArg::Remote(_)), _) => PolicyKind::Zero,
        (None, Some(_)) => PolicyKind::Model,
        (None, None) => {
            return Err(EvalError::Argument(
                "give a training run (`--run runs/NAME`) or a sanity policy (`--policy expert|random|zero`)"
                    .into(),
            )
            .into());
        }
    };
    let run = match (kind, &args.run) {
        (PolicyKind::Model, Some(dir)) => Some(eval::run::open_at(dir, args.checkpoint)?),
        (PolicyKind::Model, None) => {
            return Err(
                EvalError::Argument("`--policy model` needs `--run runs/NAME`".into()).into(),
            );
        }
        _ => None,
    };
    if args.checkpoint.is_some() && run.is_none() {
        return Err(EvalError::Argument(
            "--checkpoint needs a model policy (`--run runs/NAME`)".into(),
        )
        .into());
    }
    if args.viz && kind != PolicyKind::Model {
        return Err(EvalError::Argument("--viz needs the model policy (`--run`)".into()).into());
    }
    let device = match &run {
        Some(r) => eval::run::device(r, args.backend)?,
        None if args.backend.is_some() => {
            return Err(
                EvalError::Argument("--backend needs a model policy (`--run`)".into()).into(),
            );
        }
        None => burn::prelude::Device::flex(),
    };
    let tasks = match (&args.tasks, &run) {
        (Some(t), _) => t.clone(),
        (None, Some(r)) if !r.info.eval_tasks.is_empty() => r.info.eval_tasks.join(","),
        _ => "libero_mem".to_string(),
    };
    let out = match (&args.out, &run) {
        (Some(o), _) => o.clone(),
        (None, Some(r)) => r.dir.join(match args.checkpoint {
            Some(step) => format!("eval_step_{step}"),
            None => "eval".to_string(),
        }),
        (None, None) => PathBuf::from("results"),
    };
    Ok(Setup {
        kind,
        remote,
        run,
        device,
        tasks,
        out,
        execute: args.execute,
        stop: !args.no_stop,
    })
}

fn make_policy(s: &Setup) -> Result<Box<dyn Policy>, EvalError> {
    if let Some(r) = &s.remote {
        return Ok(Box::new(eval::remote::RemotePolicy::connect(r.clone())?));
    }
    Ok(match s.kind {
        PolicyKind::Model => Box::new(
            eval::run::policy(
                s.run
                    .as_ref()
                    .ok_or_else(|| EvalError::Argument("no run".into()))?,
                &s.device,
            )?
            .with_execution(s.execute)
            .with_stop(s.stop),
        ),
        PolicyKind::Expert => Box::new(eval::ExpertPolicy::default()),
        PolicyKind::Random => Box::new(eval::RandomPolicy::default()),
        PolicyKind::Zero => Box::new(eval::ZeroPolicy),
    })
}

/// The progress bar of an evaluation of `total` episodes (hidden with `--quiet`).
fn episodes_bar(quiet: bool, total: u64) -> indicatif::ProgressBar {
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(total)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{prefix} {bar:30} {pos}/{len} episodes  {msg}  {elapsed} ETA {eta}",
        )
        .expect("valid template"),
    );
    bar
}

fn run_tasks(
    args: &EvalArgs,
    s: &Setup,
    tasks: &[sim::task::TaskSpec],
    viz: Option<PathBuf>,
) -> anyhow::Result<Results> {
    let cfg = EvalConfig {
        episodes: args.episodes,
        seed: args.seed,
        full_budget: args.full_budget,
        image_size: args.image_size.unwrap_or(if s.remote.is_some() {
            eval::remote::OPENPI_RENDER_SIZE
        } else {
            128
        }),
        quality: if args.quality == "fast" {
            sim::render::RenderQuality::default()
        } else {
            sim::render::RenderQuality::high()
        },
        workers: args.workers,
        record: args.record.clone(),
        video: args.video.clone(),
        viz,
        viz_every: args.viz_every,
        libero_init: args.libero_init,
        assets: args.assets.parse().map_err(EvalError::Argument)?,
        shard: args.shard.unwrap_or_default(),
        journal: Some(journal_path(&s.out)),
        journal_key: format!(
            "policy {} | run {:?} | checkpoint {:?} | execute {} | remote {:?} | quality {}",
            s.policy_name(),
            s.run.as_ref().map(|r| r.dir.display().to_string()),
            s.run.as_ref().map(|r| r.step),
            s.execute,
            s.remote.as_ref().map(|r| (r.replan_steps, r.send_subgoal)),
            args.quality
        ),
    };
    let total = (tasks.len() * cfg.shard.items(cfg.episodes).len()) as u64;
    let bar = episodes_bar(args.quiet, total);
    let make = || make_policy(s);
    let progress = |p: &eval::Progress| {
        bar.set_position(p.done as u64);
        bar.set_message(format!(
            "{}: completion {:.0} %, {} successes",
            report::short(&p.task),
            p.completion,
            p.successes
        ));
    };
    let mut results = eval::evaluate(tasks, &make, &cfg, &progress)?;
    bar.finish_and_clear();
    results.policy = s.policy_name();
    results.run = s.run.as_ref().map(|r| r.dir.display().to_string());
    results.checkpoint_step = s.run.as_ref().map(|r| r.step);
    if s.kind == PolicyKind::Model && (s.execute != eval::policy::Execution::First || !s.stop) {
        let stop = if s.stop { "" } else { ", no stop" };
        results.execution = Some(format!("{}{stop}", s.execute));
    }
    Ok(results)
}

impl Setup {
    /// The policy's name in tables: its kind, or the server's URL.
    fn policy_name(&self) -> String {
        match &self.remote {
            Some(r) => r.url.clone(),
            None => self.kind.name().to_string(),
        }
    }
}

fn header(s: &Setup, args: &EvalArgs) -> String {
    let run = s
        .run
        .as_ref()
        .map(|r| (r.dir.display().to_string(), r.step));
    report::header(
        &s.policy_name(),
        run.as_ref().map(|(d, step)| (d.as_str(), *step)),
        args.seed,
        args.episodes,
        args.full_budget,
        args.shard.unwrap_or_default(),
    )
}

/// How a page in `from` links the folder `to`: relative when `to` lies under `from`, else the
/// absolute path.
fn link(from: &std::path::Path, to: &std::path::Path) -> String {
    let abs = |p: &std::path::Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let (f, t) = (abs(from), abs(to));
    match t.strip_prefix(&f) {
        Ok(rel) if !rel.as_os_str().is_empty() => rel.display().to_string(),
        _ => t.display().to_string(),
    }
}

/// The journal of the episodes finished so far (kept until the tables are written, so that a
/// killed evaluation resumes).
fn journal_path(out: &std::path::Path) -> PathBuf {
    out.join("episodes.jsonl")
}

/// Removes the journal once the results it fed are written.
fn drop_journal(out: &std::path::Path) {
    let _ = std::fs::remove_file(journal_path(out));
}

/// Writes results.md, results.json and results.csv of `results` into `out`.
fn write_results(out: &std::path::Path, results: &Results) -> anyhow::Result<()> {
    eval::write_atomic(&out.join("results.md"), results.markdown().as_bytes())?;
    eval::write_atomic(
        &out.join("results.json"),
        serde_json::to_string_pretty(results)?.as_bytes(),
    )?;
    eval::write_atomic(
        &out.join("results.csv"),
        report::csv(&results.tasks).as_bytes(),
    )?;
    eprintln!("wrote {}/results.{{md,json,csv}}", out.display());
    Ok(())
}

fn evaluate(args: &EvalArgs) -> anyhow::Result<()> {
    let s = setup(args)?;
    let tasks = eval::resolve_tasks(&s.tasks, args.repeat)?;
    let viz = args.viz.then(|| s.out.join("viz"));
    let by_processes = args.processes && args.workers > 1 && args.shard.is_none();
    if args.processes && args.viz {
        return Err(EvalError::Argument(
            "--viz draws the first rollout of one process: not with --processes".into(),
        )
        .into());
    }
    let results = if by_processes {
        run_in_processes(args, &s, &tasks)?
    } else {
        run_tasks(args, &s, &tasks, viz.clone())?
    };
    data::out!("{}", results.markdown());
    write_results(&s.out, &results)?;
    drop_journal(&s.out);
    if let Some(v) = &args.video {
        let page = s.out.join("index.html");
        let dir = link(&s.out, v);
        let video = |e: &eval::EpisodeResult| {
            format!(
                "{dir}/{}/episode_{:06}.mp4",
                eval::task_slug(&e.task),
                e.episode
            )
        };
        eval::write_atomic(&page, report::index_html(&results, &video).as_bytes())?;
        eprintln!("videos under {}, listed in {}", v.display(), page.display());
    }
    if let Some(v) = viz {
        eprintln!("slot overlays in {}", v.display());
    }
    if let Some(r) = &args.record {
        eprintln!("rollouts recorded under {}", r.display());
    }
    Ok(())
}

/// Evaluates with `args.workers` processes of this program, process i the same command with
/// `--shard i/N --workers 1 --out OUT/processes/shard_i` (each keeps its own journal there, so a
/// killed evaluation resumes), then merges their results as `eval merge` does. Recordings and
/// videos go to the shared folders directly (each episode its own file).
fn run_in_processes(
    args: &EvalArgs,
    s: &Setup,
    tasks: &[sim::task::TaskSpec],
) -> anyhow::Result<Results> {
    let n = args.workers;
    let root = s.out.join("processes");
    let dirs: Vec<PathBuf> = (0..n).map(|i| root.join(format!("shard_{i}"))).collect();
    let own = data::procs::own_args(&["--processes"]);
    let shard_args = |i: usize| {
        let mut a = own.clone();
        a.extend(["--workers", "1", "--quiet", "--shard", &format!("{i}/{n}")].map(Into::into));
        a.extend(["--out".into(), dirs[i].clone().into_os_string()]);
        a
    };
    let bar = episodes_bar(args.quiet, (tasks.len() * args.episodes) as u64);
    bar.set_prefix(format!("{n} processes"));
    // Finished episodes: the lines of each process's journal, or all of its episodes once its
    // results are written (the journal is gone then).
    let count_done = || {
        let done: usize = dirs
            .iter()
            .enumerate()
            .map(|(i, d)| match std::fs::read_to_string(journal_path(d)) {
                Ok(t) => t.lines().count(),
                Err(_) if d.join("results.json").is_file() => {
                    let shard = data::shard::Shard::new(i, n).unwrap_or_default();
                    tasks.len() * shard.items(args.episodes).len()
                }
                Err(_) => 0,
            })
            .sum();
        bar.set_position(done as u64);
    };
    let ran = data::procs::run_all(n, &root, shard_args, count_done);
    bar.finish_and_clear();
    ran.map_err(|f| {
        if f.is_bad_input() {
            anyhow::Error::new(EvalError::Argument(f.to_string()))
        } else {
            anyhow::Error::new(f)
        }
    })?;
    let parts = dirs
        .iter()
        .map(|d| Results::load(d))
        .collect::<Result<Vec<_>, _>>()?;
    let merged = report::merge(&parts)?;
    let _ = std::fs::remove_dir_all(&root);
    Ok(merged)
}

fn serve(
    run: &std::path::Path,
    host: &str,
    port: u16,
    connections: Option<usize>,
    backend: Option<model::backend::BackendKind>,
) -> anyhow::Result<()> {
    let rd = eval::run::open(run)?;
    let device = eval::run::device(&rd, backend)?;
    // Loaded once up front, so a run that cannot serve fails here (exit 2), not per connection.
    eval::run::policy(&rd, &device)?;
    let listener = std::net::TcpListener::bind((host, port))
        .map_err(|e| EvalError::Argument(format!("cannot listen on {host}:{port}: {e}")))?;
    let addr = listener.local_addr()?;
    eprintln!("serving {} on ws://{addr}", rd.dir.display());
    let info = eval::remote::server::ServerInfo {
        run: rd.dir.display().to_string(),
        step: rd.step,
    };
    let make = || eval::run::policy(&rd, &device);
    eval::remote::server::serve(listener, &make, &info, connections, &|m| eprintln!("{m}"))?;
    Ok(())
}

fn scaling(args: &EvalArgs, repeats: &[usize]) -> anyhow::Result<()> {
    if args.repeat.is_some() {
        return Err(
            EvalError::Argument("use --repeats with `scaling`, not --repeat".into()).into(),
        );
    }
    let s = setup(args)?;
    let mut rows = Vec::new();
    for &n in repeats {
        let tasks = eval::resolve_tasks(&s.tasks, Some(n))?;
        let results = run_tasks(args, &s, &tasks, None)?;
        for t in results.tasks {
            rows.push(ScalingRow {
                task: t.task.split('@').next().unwrap_or(&t.task).to_string(),
                repeats: n,
                summary: t,
            });
        }
    }
    let md = format!("{}{}", header(&s, args), report::scaling_table(&rows));
    data::out!("{md}");
    eval::write_atomic(&s.out.join("scaling.md"), md.as_bytes())?;
    eval::write_atomic(
        &s.out.join("scaling.json"),
        serde_json::to_string_pretty(&rows)?.as_bytes(),
    )?;
    drop_journal(&s.out);
    eprintln!("wrote {}/scaling.{{md,json}}", s.out.display());
    Ok(())
}

fn merge(paths: &[PathBuf], out: &std::path::Path) -> anyhow::Result<()> {
    let parts = paths
        .iter()
        .map(|p| Results::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let merged = report::merge(&parts)?;
    data::out!("{}", merged.markdown());
    write_results(out, &merged)
}

fn compare(paths: &[PathBuf], out: Option<PathBuf>) -> anyhow::Result<()> {
    let mut runs = Vec::new();
    for p in paths {
        let (file, r) = Results::load(p)?;
        let name = r
            .run
            .as_deref()
            .map(|d| {
                std::path::Path::new(d)
                    .file_name()
                    .map_or(d.to_string(), |n| n.to_string_lossy().into_owned())
            })
            .unwrap_or_else(|| format!("{} ({})", r.policy, file.display()));
        runs.push((name, r));
    }
    let md = report::compare(&runs);
    data::out!("{md}");
    if let Some(o) = out {
        eval::write_atomic(&o, md.as_bytes())
            .with_context(|| format!("writing {}", o.display()))?;
    }
    Ok(())
}

/// What `eval experiment` does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Train, evaluate and write the tables.
    Run,
    /// Only rebuild the tables (`--tables-only`).
    TablesOnly,
    /// Only print the plan (`--plan`).
    Plan,
}

fn experiment(
    file: &std::path::Path,
    mode: Mode,
    quiet: bool,
    jobs: usize,
    only: &eval::experiment::Only,
) -> anyhow::Result<()> {
    use eval::experiment::{self as exp, Experiment};
    let x = Experiment::load(file)?;
    let plan = x.plan();
    only.check(&x, file)?;
    let tables_only = mode == Mode::TablesOnly;
    let bar = if quiet || mode == Mode::Plan {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(plan.len() as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:20} {pos}/{len} runs  {msg}  {elapsed}")
            .expect("valid template"),
    );
    let mut done = Vec::new();
    let write_tables =
        |done: &[exp::RunResult], missing: &[(String, String)]| -> anyhow::Result<()> {
            std::fs::create_dir_all(&x.out)?;
            eval::write_atomic(
                &x.out.join("results.md"),
                exp::markdown(&x, done, missing).as_bytes(),
            )?;
            eval::write_atomic(
                &x.out.join("results.json"),
                serde_json::to_string_pretty(&exp::results_json(done))?.as_bytes(),
            )?;
            eval::write_atomic(&x.out.join("results.csv"), exp::csv(done).as_bytes())?;
            eval::write_atomic(&x.out.join("results.svg"), exp::svg(done).as_bytes())?;
            eval::write_atomic(
                &exp::Ledger::path(&x),
                serde_json::to_string_pretty(&exp::Ledger::of(&x, done))?.as_bytes(),
            )?;
            Ok(())
        };
    let started = std::time::Instant::now();
    // The runs evaluated already (read once): from their run directories, else from the ledger
    // kept beside the tables (a fresh clone holds no run directories).
    let ledger = exp::Ledger::load(&x)?.filter(|l| {
        let usable = l.usable(&x);
        if !usable {
            eprintln!(
                "{}: evaluated under another protocol (episodes, seed or budget); not used, and \
                 rewritten with this experiment's runs",
                exp::Ledger::path(&x).display()
            );
        }
        usable
    });
    let mut recorded = 0;
    let evaluated: Vec<Option<exp::RunResult>> = plan
        .iter()
        .map(|p| {
            let run = x.runs_dir.join(&p.name);
            exp::load_result(&x, &run, &p.spec.obs, &p.label).or_else(|| {
                let r = ledger
                    .as_ref()?
                    .find(&run.display().to_string(), &p.spec.obs, &p.label);
                recorded += usize::from(r.is_some());
                r.cloned()
            })
        })
        .collect();
    if recorded > 0 {
        eprintln!(
            "{recorded} evaluated runs read from {} (their run directories are not here)",
            exp::Ledger::path(&x).display()
        );
    }
    if mode == Mode::Plan {
        for (p, r) in plan.iter().zip(&evaluated) {
            if !only.admits(p.spec) {
                continue;
            }
            let state = match r {
                Some(r) => format!("evaluated ({:.1} % mean completion)", r.mean_completion()),
                None => "to train and evaluate".to_string(),
            };
            println!(
                "{} [{}] {state}\n  {}",
                p.name,
                p.label,
                exp::train_command(p, &x.runs_dir)
            );
        }
        return Ok(());
    }
    // With --jobs N, every run still to evaluate is trained first (N at once), then evaluated.
    let pretrained = jobs > 1 && !tables_only;
    if pretrained {
        let todo: Vec<&exp::Planned> = plan
            .iter()
            .zip(&evaluated)
            .filter(|(p, r)| r.is_none() && only.admits(p.spec))
            .map(|(p, _)| p)
            .collect();
        let (alone, side_by_side) = exp::training_waves(&todo, exp::dataset_ready);
        for p in &alone {
            bar.set_message(format!("{}: training (generates its dataset)", p.name));
            exp::train(p, &x.runs_dir, None)?;
        }
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = exp::threads_per_job(cores, jobs);
        bar.set_message(format!(
            "training {} runs, {} at once, {threads} threads each",
            side_by_side.len(),
            jobs
        ));
        data::pool::for_each(
            side_by_side.len(),
            jobs,
            || Ok(()),
            |_, k| {
                let p = side_by_side[k];
                exp::train(p, &x.runs_dir, Some(threads))
            },
            || EvalError::Model("a training thread panicked".into()),
        )?;
    }
    for (i, (p, evaluated)) in plan.iter().zip(evaluated).enumerate() {
        let run = x.runs_dir.join(&p.name);
        if let Some(r) = evaluated {
            done.push(r);
            bar.inc(1);
            continue;
        }
        if tables_only || !only.admits(p.spec) {
            bar.inc(1);
            continue;
        }
        if !pretrained {
            bar.set_message(format!("{}: training", p.name));
            exp::train(p, &x.runs_dir, None)?;
        }
        // Evaluated meanwhile (`eval --run` by hand on a free core while other runs trained):
        // the same protocol at the run's last step gives the same rows, so they are taken.
        if let Some(r) = exp::load_result(&x, &run, &p.spec.obs, &p.label) {
            eprintln!("{}: evaluated meanwhile, its results read back", p.name);
            done.push(r);
            bar.inc(1);
            continue;
        }
        let rd = eval::run::open(&run)?;
        let device = eval::run::device(&rd, None)?;
        let tasks = eval::resolve_tasks(&p.spec.suite, None)?;
        let cfg = EvalConfig {
            episodes: x.episodes,
            seed: x.seed,
            full_budget: x.full_budget,
            workers: x.workers,
            ..EvalConfig::default()
        };
        let make = || -> Result<Box<dyn Policy>, EvalError> {
            Ok(Box::new(eval::run::policy(&rd, &device)?))
        };
        let name = p.name.clone();
        let progress = |pr: &eval::Progress| {
            bar.set_message(format!(
                "{name}: evaluating {}/{} episodes",
                pr.done, pr.total
            ));
        };
        let mut results = eval::evaluate(&tasks, &make, &cfg, &progress)?;
        results.policy = "model".into();
        results.run = Some(run.display().to_string());
        results.checkpoint_step = Some(rd.step);
        let out = run.join("eval");
        eval::write_atomic(
            &out.join("results.md"),
            report::markdown(&results.tasks).as_bytes(),
        )?;
        eval::write_atomic(
            &out.join("results.csv"),
            report::csv(&results.tasks).as_bytes(),
        )?;
        eval::write_atomic(
            &out.join("results.json"),
            serde_json::to_string_pretty(&results)?.as_bytes(),
        )?;
        if let Some(r) = exp::load_result(&x, &run, &p.spec.obs, &p.label) {
            done.push(r);
        }
        let missing: Vec<(String, String)> =
            plan[i + 1..].iter().map(|q| q.not_trained()).collect();
        write_tables(&done, &missing)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let missing: Vec<(String, String)> = plan
        .iter()
        .filter(|p| {
            let run = x.runs_dir.join(&p.name).display().to_string();
            !done.iter().any(|d| d.run == run)
        })
        .map(|p| p.not_trained())
        .collect();
    write_tables(&done, &missing)?;
    data::out!("{}", exp::markdown(&x, &done, &missing));
    eprintln!(
        "wrote {}/results.{{md,json,csv,svg}} ({} of {} runs) in {:.1} min",
        x.out.display(),
        done.len(),
        plan.len(),
        started.elapsed().as_secs_f64() / 60.0
    );
    Ok(())
}
