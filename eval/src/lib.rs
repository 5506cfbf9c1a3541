//! Closed-loop evaluation: rollouts of a policy in the simulator with the LIBERO-Mem goal tracker,
//! and the paper's tables — subgoal completion (tiered credit, Table 3) and success (Table 2) per
//! task, with 95 % confidence intervals, mean steps and over-repetition failures.
//!
//! Episode protocol (libero-mem-reference.md §4): reset from the episode seed (which includes
//! LIBERO-Mem's 20 settle steps with the gripper opening), then up to the task's step budget of
//! policy steps; the goal tracker is checked once per step. By default an episode ends as soon as it
//! succeeds (every subgoal satisfied), as `eval_slotssm_raw.py` does; with `full_budget` it runs the
//! whole budget like upstream's `mem_6`, where success also requires no over-repetition at the end.
//!
//! ```no_run
//! let tasks = eval::resolve_tasks("t1", None)?;
//! let cfg = eval::EvalConfig { episodes: 2, ..Default::default() };
//! let make = || -> Result<Box<dyn eval::Policy>, eval::EvalError> { Ok(Box::new(eval::ZeroPolicy)) };
//! let results = eval::evaluate(&tasks, &make, &cfg, &|_| {})?;
//! print!("{}", eval::report::markdown(&results.tasks));
//! # Ok::<(), eval::EvalError>(())
//! ```

#![warn(missing_docs)]

pub mod dagger;
pub mod error;
pub mod experiment;
pub mod policy;
pub mod remote;
pub mod report;
pub mod run;
pub mod viz;

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use sim::record::Recorder;
use sim::task::TaskSpec;
use sim::{Env, EnvConfig, Observation};

pub use error::EvalError;
pub use policy::{ExpertPolicy, ModelPolicy, Policy, RandomPolicy, ZeroPolicy};
pub use report::{EpisodeResult, Results, TaskSummary, summarize, wilson};
pub use run::RunDir;

/// How to run episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalConfig {
    /// Episodes per task.
    pub episodes: usize,
    /// Base seed; episode k of a task uses [`episode_seed`]`(seed, k)`.
    pub seed: u64,
    /// Run the whole step budget instead of stopping at success.
    pub full_budget: bool,
    /// Camera image side when the policy needs images (the side `sim generate` records).
    pub image_size: usize,
    /// Rendering quality: the fast dataset defaults, or `RenderQuality::high()` (LIBERO's look,
    /// for policies trained on LIBERO's own images).
    pub quality: sim::render::RenderQuality,
    /// Worker threads, one simulator and one policy each.
    pub workers: usize,
    /// Record every rollout as an mcap episode under this directory (`<task>/episode_<k>.mcap`).
    pub record: Option<PathBuf>,
    /// Write every rollout as an mp4 video under this directory (`<task>/episode_<k>.mp4`:
    /// agentview | eye-in-hand, the step and the pending subgoal under them).
    pub video: Option<PathBuf>,
    /// Write slot-attention overlays of the first rollout (first task, episode 0) here.
    pub viz: Option<PathBuf>,
    /// Every how many steps a visualisation frame is written.
    pub viz_every: usize,
    /// LIBERO's protocol for LIBERO tasks: episode k starts from the task's init state k (from the
    /// LIBERO pack), fixtures placed from the episode seed, then 10 idle steps (OpenVLA's
    /// `num_steps_wait`) before the policy acts.
    pub libero_init: bool,
    /// Asset pack the scenes are built from (builtin primitives or LIBERO's meshes).
    pub assets: sim::pack::AssetPack,
    /// Run only this shard's episodes of every task (k mod N = I); [`report::merge`] joins the
    /// shards' results into the unsharded run's.
    pub shard: data::shard::Shard,
    /// Keep every finished episode in this journal (JSON lines) and skip the episodes it already
    /// holds when the evaluation runs again (after a crash, a kill or a lost policy server); its
    /// first line names the evaluation (`journal_key`): a journal of another evaluation is
    /// started afresh.
    pub journal: Option<PathBuf>,
    /// What the journal's episodes were evaluated with (policy, run, checkpoint, execution, …).
    pub journal_key: String,
}

/// Format line of an evaluation journal ([`EvalConfig::journal`]).
pub const JOURNAL_FORMAT: &str = "libero-mem-rs/eval-journal/1";

/// Opens `path` as the journal of the evaluation `key` (seed, budget and protocol settings of
/// `cfg` included): the records it holds (a torn last line is dropped), rewritten so that the
/// file is whole, and the file to append to. A journal of another evaluation is replaced.
/// Evaluations journal [`EpisodeResult`]s, DAgger collections their take-overs.
pub(crate) fn open_journal<T: serde::Serialize + serde::de::DeserializeOwned>(
    path: &Path,
    key: &str,
) -> Result<(Vec<T>, std::fs::File), EvalError> {
    let header = serde_json::json!({"format": JOURNAL_FORMAT, "evaluation": key}).to_string();
    let mut kept = Vec::new();
    if let Ok(text) = std::fs::read_to_string(path) {
        let mut lines = text.lines();
        if lines.next() == Some(header.as_str()) {
            for line in lines {
                match serde_json::from_str::<T>(line) {
                    Ok(e) => kept.push(e),
                    Err(_) => break,
                }
            }
            if !kept.is_empty() {
                eprintln!(
                    "{}: resuming, {} episodes already evaluated",
                    path.display(),
                    kept.len()
                );
            }
        } else {
            eprintln!(
                "{}: a journal of another evaluation; starting afresh",
                path.display()
            );
        }
    }
    let mut body = header;
    body.push('\n');
    for e in &kept {
        body.push_str(&serde_json::to_string(e).expect("episode results serialise"));
        body.push('\n');
    }
    write_atomic(path, body.as_bytes())?;
    let file = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map_err(|e| data::DataError::io(path, e))?;
    Ok((kept, file))
}

/// Whether episodes of `task` follow LIBERO's protocol (init state k, idle steps): asked for with
/// [`EvalConfig::libero_init`], or implied by a LIBERO task on LIBERO's assets (libero.md §6).
pub fn libero_protocol(task: &TaskSpec, cfg: &EvalConfig) -> bool {
    cfg.libero_init
        || task.suite.pack_only()
        || (cfg.assets == sim::pack::AssetPack::Libero
            && task.suite == sim::task::Suite::LiberoGoal)
}

/// Idle steps after an init state under [`EvalConfig::libero_init`] (OpenVLA's `num_steps_wait`).
pub const LIBERO_IDLE_STEPS: usize = 10;

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig {
            episodes: 20,
            seed: 0,
            full_budget: false,
            image_size: 128,
            quality: sim::render::RenderQuality::default(),
            workers: 1,
            record: None,
            video: None,
            viz: None,
            viz_every: 4,
            libero_init: false,
            assets: sim::pack::AssetPack::Builtin,
            shard: data::shard::Shard::WHOLE,
            journal: None,
            journal_key: String::new(),
        }
    }
}

/// The seed of episode `k` under base seed `seed` (SplitMix64 of both, so neighbouring seeds differ).
pub fn episode_seed(seed: u64, k: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k)
        .wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A file-system-safe name for a task id (`libero_mem/t3@5` → `libero_mem-t3@5`).
pub fn task_slug(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_alphanumeric() || "_@.-".contains(c) {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// Extras of one rollout: a recording file and a visualisation folder.
#[derive(Debug, Default, Clone)]
pub struct RolloutOutputs {
    /// Record the rollout to this mcap file.
    pub record: Option<PathBuf>,
    /// Write the rollout's video to this mp4 file.
    pub video: Option<PathBuf>,
    /// Write slot overlays into this folder.
    pub viz: Option<PathBuf>,
    /// Every how many steps an overlay is written.
    pub viz_every: usize,
}

fn goal(o: &Observation) -> Result<&sim::GoalStatus, EvalError> {
    o.goal
        .as_ref()
        .ok_or_else(|| EvalError::Argument("the environment has no task goal".into()))
}

/// Runs episode `k` of `task` with `policy` in `env` (which must be built for `task`, rendering
/// with segmentation when recording).
pub fn run_episode(
    env: &mut Env,
    task: &TaskSpec,
    policy: &mut dyn Policy,
    cfg: &EvalConfig,
    k: usize,
    out: &RolloutOutputs,
    init: Option<&sim::pack::InitStates>,
) -> Result<EpisodeResult, EvalError> {
    let seed = episode_seed(cfg.seed, k as u64);
    policy.reset(task, seed)?;
    let mut obs = match init {
        None => env.reset(seed)?,
        Some(states) => {
            let (nq, nv) = (env.model().nq(), env.model().nv());
            let st = states
                .require(k, nq, nv)
                .map_err(|e| EvalError::Argument(e.to_string()))?;
            env.reset_to_init(seed, st.qpos, st.qvel)?;
            env.settle()?
        }
    };
    let record_err = |path: &Path, e: sim::record::RecordError| EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut recorder = match &out.record {
        Some(path) => Some(
            Recorder::create(path, env, task, seed, data::WriterOptions::default())
                .map_err(|e| record_err(path, e))?,
        ),
        None => None,
    };
    let mut viz = match &out.viz {
        Some(dir) => Some(viz::Writer::create(dir, out.viz_every.max(1))?),
        None => None,
    };
    let mut video = out
        .video
        .as_ref()
        .map(|p| viz::Video::new(p, task.max_steps));
    let mut steps = 0;
    while steps < task.max_steps {
        let g = goal(&obs)?;
        if !cfg.full_budget && g.satisfied >= g.goal_len {
            break;
        }
        if let Some(v) = video.as_mut() {
            v.frame(&obs, steps)?;
        }
        let a = policy.act(env, &obs)?;
        if let Some(v) = viz.as_mut() {
            v.frame(steps, &obs, policy)?;
        }
        let next = env.step(&a)?;
        if let (Some(rec), Some(path)) = (recorder.as_mut(), out.record.as_ref()) {
            rec.record(env, &obs, a, &next)
                .map_err(|e| record_err(path, e))?;
        }
        obs = next;
        steps += 1;
    }
    if let (Some(rec), Some(path)) = (recorder, out.record.as_ref()) {
        rec.finish().map_err(|e| record_err(path, e))?;
    }
    if let Some(mut v) = video {
        v.frame(&obs, steps)?;
        v.finish()?;
    }
    let g = goal(&obs)?;
    let success = if cfg.full_budget {
        g.done && !g.failed
    } else {
        g.done || g.satisfied >= g.goal_len
    };
    Ok(EpisodeResult {
        task: task.id.clone(),
        episode: k,
        seed,
        steps,
        satisfied: g.satisfied,
        goal_len: g.goal_len,
        success,
        over_repetition: g.failed,
    })
}

/// An environment configured for `policy` (rendering only when it needs images or when recording,
/// with segmentation when it reads object boxes or when recording).
pub fn env_for(task: &TaskSpec, policy: &dyn Policy, cfg: &EvalConfig) -> Result<Env, EvalError> {
    let record = cfg.record.is_some();
    Env::from_task_with_assets(
        task,
        EnvConfig {
            render: policy.needs_images() || record || cfg.video.is_some(),
            segmentation: record || policy.needs_segmentation(),
            image_size: cfg.image_size,
            quality: cfg.quality,
            settle_steps: if libero_protocol(task, cfg) {
                LIBERO_IDLE_STEPS
            } else {
                EnvConfig::default().settle_steps
            },
            ..EnvConfig::default()
        },
        cfg.assets,
    )
    .map_err(|e| match e {
        sim::EnvError::Config(m) => EvalError::Argument(m),
        other => other.into(),
    })
}

/// Progress of [`evaluate`], reported after every episode.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Task of the episode just finished.
    pub task: String,
    /// Episodes finished over all tasks.
    pub done: usize,
    /// Episodes in all.
    pub total: usize,
    /// Mean subgoal completion (%) of the finished episodes of this task.
    pub completion: f64,
    /// Successes among the finished episodes of this task.
    pub successes: usize,
}

/// Makes one policy per worker.
pub type PolicyFactory<'a> = dyn Fn() -> Result<Box<dyn Policy>, EvalError> + Sync + 'a;

/// Runs `cfg.episodes` episodes of every task (those of `cfg.shard`) on `cfg.workers` threads (one
/// simulator and one policy each, made by `make`), and summarises them. Episode k of a task always
/// uses the same seed, so the results depend neither on the number of workers nor on sharding.
pub fn evaluate(
    tasks: &[TaskSpec],
    make: &PolicyFactory,
    cfg: &EvalConfig,
    progress: &(dyn Fn(&Progress) + Sync),
) -> Result<Results, EvalError> {
    if cfg.episodes == 0 || cfg.workers == 0 {
        return Err(EvalError::Argument(
            "--episodes and --workers must be at least 1".into(),
        ));
    }
    for dir in cfg.record.iter().chain(&cfg.video) {
        for task in tasks {
            let d = dir.join(task_slug(&task.id));
            std::fs::create_dir_all(&d).map_err(|e| EvalError::Output {
                path: d.clone(),
                message: e.to_string(),
            })?;
        }
    }
    let items = cfg.shard.items(cfg.episodes);
    if items.is_empty() {
        return Err(EvalError::Argument(format!(
            "shard {} of {} episodes per task holds no episode",
            cfg.shard, cfg.episodes
        )));
    }
    let total = tasks.len() * items.len();
    let key = format!(
        "{} | seed {} | {} episodes | full budget {} | libero init {} | assets {:?} | image {} | shard {}",
        cfg.journal_key,
        cfg.seed,
        cfg.episodes,
        cfg.full_budget,
        cfg.libero_init,
        cfg.assets,
        cfg.image_size,
        cfg.shard
    );
    let (journaled, journal) = match &cfg.journal {
        Some(p) => {
            let (kept, file) = open_journal::<EpisodeResult>(p, &key)?;
            (kept, Some(Mutex::new(file)))
        }
        None => (Vec::new(), None),
    };
    let done = AtomicUsize::new(0);
    let mut rows = Vec::new();
    let mut all = Vec::new();
    for (ti, task) in tasks.iter().enumerate() {
        let init_states = if libero_protocol(task, cfg) {
            let pack = sim::pack::LiberoPack::locate_default()
                .map_err(|e| EvalError::Argument(e.to_string()))?;
            Some(
                pack.init_states(&task.id)
                    .map_err(|e| EvalError::Argument(e.to_string()))?,
            )
        } else {
            None
        };
        // Episodes of this task the journal holds already (same seed: same episode).
        let earlier: Vec<EpisodeResult> = journaled
            .iter()
            .filter(|e| {
                e.task == task.id
                    && items.contains(&e.episode)
                    && e.seed == episode_seed(cfg.seed, e.episode as u64)
            })
            .cloned()
            .collect();
        let todo: Vec<usize> = items
            .iter()
            .copied()
            .filter(|k| !earlier.iter().any(|e| e.episode == *k))
            .collect();
        done.fetch_add(earlier.len(), Ordering::SeqCst);
        let results = Mutex::new(earlier);
        let init = || -> Result<_, EvalError> {
            let policy = make()?;
            let env = env_for(task, policy.as_ref(), cfg)?;
            Ok((policy, env))
        };
        let work = |(policy, env): &mut (Box<dyn Policy>, Env), i: usize| {
            let k = todo[i];
            let outputs = RolloutOutputs {
                record: cfg.record.as_ref().map(|d| {
                    d.join(task_slug(&task.id))
                        .join(format!("episode_{k:06}.mcap"))
                }),
                video: cfg.video.as_ref().map(|d| {
                    d.join(task_slug(&task.id))
                        .join(format!("episode_{k:06}.mp4"))
                }),
                viz: cfg.viz.clone().filter(|_| ti == 0 && k == 0),
                viz_every: cfg.viz_every,
            };
            let r = run_episode(
                env,
                task,
                policy.as_mut(),
                cfg,
                k,
                &outputs,
                init_states.as_ref(),
            )?;
            let mut guard = results.lock().unwrap_or_else(|p| p.into_inner());
            if let (Some(j), Some(path)) = (&journal, &cfg.journal) {
                use std::io::Write;
                let mut f = j.lock().unwrap_or_else(|p| p.into_inner());
                let line = serde_json::to_string(&r).expect("episode results serialise") + "\n";
                f.write_all(line.as_bytes())
                    .and_then(|_| f.flush())
                    .map_err(|e| data::DataError::io(path, e))?;
            }
            guard.push(r);
            let n = guard.len();
            progress(&Progress {
                task: task.id.clone(),
                done: done.fetch_add(1, Ordering::SeqCst) + 1,
                total,
                completion: 100.0 * guard.iter().map(EpisodeResult::tiered).sum::<f64>() / n as f64,
                successes: guard.iter().filter(|e| e.success).count(),
            });
            Ok(())
        };
        if !todo.is_empty() {
            data::pool::for_each(todo.len(), cfg.workers, init, work, || {
                EvalError::Argument("an evaluation worker panicked".into())
            })?;
        }
        let mut eps = results.into_inner().unwrap_or_else(|p| p.into_inner());
        eps.sort_by_key(|e| e.episode);
        rows.push(summarize(&task.id, &eps));
        all.extend(eps);
    }
    Ok(Results {
        policy: String::new(),
        run: None,
        checkpoint_step: None,
        execution: None,
        seed: cfg.seed,
        episodes_per_task: cfg.episodes,
        full_budget: cfg.full_budget,
        shard: cfg.shard,
        tasks: rows,
        episodes: all,
    })
}

/// Resolves `--tasks` (comma-separated ids, or the suites `libero_mem`, `libero_goal`, `all`);
/// `repeat` sets the repetition count of the repetition family (t1–t6).
pub fn resolve_tasks(spec: &str, repeat: Option<usize>) -> Result<Vec<TaskSpec>, EvalError> {
    let out = sim::pack::resolve_suites(spec, repeat)?;
    if out.is_empty() {
        return Err(EvalError::Argument("no tasks given".into()));
    }
    Ok(out)
}

/// Writes `bytes` to `path` atomically (`data::index::write_atomic`: a synced temporary file in the
/// same folder, renamed), creating the folder first, so a reader never sees a half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), EvalError> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| data::DataError::io(dir, e))?;
    }
    Ok(data::index::write_atomic(path, bytes)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episode_seeds_differ_and_repeat() {
        assert_eq!(episode_seed(0, 3), episode_seed(0, 3));
        assert_ne!(episode_seed(0, 3), episode_seed(0, 4));
        assert_ne!(episode_seed(0, 3), episode_seed(1, 3));
    }

    #[test]
    fn suites_and_repeats_resolve() {
        let mem = resolve_tasks("libero_mem", None).unwrap();
        assert_eq!(mem.len(), 10);
        let goal = resolve_tasks("libero_goal", None).unwrap();
        assert_eq!(goal.len(), 10);
        let t3 = resolve_tasks("t3", Some(9)).unwrap();
        assert_eq!(t3[0].goal_len, 9);
        assert!(
            resolve_tasks("t7", Some(4)).is_err(),
            "t7 has no repetitions"
        );
        let e = resolve_tasks("t99", None).unwrap_err();
        assert_eq!(e.exit_code(), 2);
        assert!(resolve_tasks(" , ", None).is_err());
        assert_eq!(task_slug("libero_mem/t3@5"), "libero_mem-t3@5");
    }

    #[test]
    fn results_do_not_depend_on_workers_and_random_beats_nothing() {
        let tasks = resolve_tasks("t1", None).unwrap();
        let run = |workers| {
            let cfg = EvalConfig {
                episodes: 3,
                seed: 5,
                workers,
                ..EvalConfig::default()
            };
            let make =
                || -> Result<Box<dyn Policy>, EvalError> { Ok(Box::new(RandomPolicy::default())) };
            evaluate(&tasks, &make, &cfg, &|_| {}).unwrap()
        };
        let (a, b) = (run(1), run(2));
        assert_eq!(a.episodes, b.episodes);
        assert_eq!(a.episodes.len(), 3);
        assert!(a.episodes.iter().all(|e| e.steps == tasks[0].max_steps));
        assert_eq!(a.tasks[0].success, 0.0);
    }

    #[test]
    fn shards_merge_into_the_unsharded_results() {
        use data::shard::Shard;
        let tasks = resolve_tasks("t1,t2", None).unwrap();
        let run = |shard| {
            let cfg = EvalConfig {
                episodes: 3,
                seed: 9,
                shard,
                ..EvalConfig::default()
            };
            let make =
                || -> Result<Box<dyn Policy>, EvalError> { Ok(Box::new(RandomPolicy::default())) };
            let mut r = evaluate(&tasks, &make, &cfg, &|_| {}).unwrap();
            r.policy = "random".into();
            r
        };
        let whole = run(Shard::WHOLE);
        let parts: Vec<(PathBuf, Results)> = [1, 0]
            .into_iter()
            .map(|i| {
                let shard = Shard::new(i, 2).unwrap();
                (PathBuf::from(format!("s{i}")), run(shard))
            })
            .collect();
        assert_eq!(
            parts[0].1.episodes.len(),
            2,
            "shard 1/2 runs episode 1 of each task"
        );
        assert!(parts[1].1.markdown().contains("shard 0/2"));
        let merged = report::merge(&parts).unwrap();
        assert_eq!(merged, whole);
        assert_eq!(merged.markdown(), whole.markdown());
        assert_eq!(
            serde_json::to_string(&merged).unwrap(),
            serde_json::to_string(&whole).unwrap(),
            "no shard field in the merged file"
        );
        // A shard missing, given twice, or of another evaluation is refused.
        let e = report::merge(&parts[..1]).unwrap_err();
        assert!(e.to_string().contains("shard 0/2 is missing"), "{e}");
        let twice = vec![parts[0].clone(), parts[0].clone()];
        let e = report::merge(&twice).unwrap_err();
        assert!(
            e.to_string().contains("s1: shard 1/2 is given twice"),
            "{e}"
        );
        let mut other = parts.clone();
        other[1].1.seed = 10;
        let e = report::merge(&other).unwrap_err();
        assert!(
            e.to_string()
                .contains("s0: not a shard of the same evaluation as s1: its seed differs"),
            "{e}"
        );
        let mut lost = parts.clone();
        lost[1].1.episodes.retain(|e| e.task.ends_with("t1"));
        let e = report::merge(&lost).unwrap_err();
        assert!(
            e.to_string().contains("libero_mem/t2 episode 0 is in none"),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2);
        let e = evaluate(
            &tasks,
            &|| -> Result<Box<dyn Policy>, EvalError> { Ok(Box::new(ZeroPolicy)) },
            &EvalConfig {
                episodes: 2,
                shard: Shard::new(2, 3).unwrap(),
                ..EvalConfig::default()
            },
            &|_| {},
        )
        .unwrap_err();
        assert!(e.to_string().contains("holds no episode"), "{e}");
    }
}
