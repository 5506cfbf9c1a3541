//! DAgger's data: a trained policy drives an episode up to a take-over step, then the scripted
//! expert, re-planned from where the episode stands ([`sim::expert::Expert::resume`]), finishes
//! it. The whole episode is recorded — the policy's frames too, since a memory policy must see
//! how it got there — with [`data::LABELLED_FROM`] set to the take-over step, so training learns
//! only the expert's actions, on the states the policy led to. Episodes the expert does not
//! finish (or that the policy had already over-repeated) are not kept.
//!
//! Files: `OUT/dagger_<suite folder>/episode_<k>.mcap` (`dagger_libero_mem_t3/…`), beside which
//! [`join_base`] links the episodes of the dataset the policy was trained on, so that `OUT` is a
//! dataset of both (DAgger's aggregation) that a config's `data.dir` can name.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::expert::{Expert, ExpertConfig};
use sim::record::Recorder;
use sim::task::TaskSpec;
use sim::{Env, EnvConfig};

use crate::{EvalError, Policy, PolicyFactory, episode_seed};

/// Settings of a DAgger collection.
#[derive(Debug, Clone)]
pub struct DaggerConfig {
    /// Episodes per task.
    pub episodes: usize,
    /// Base seed (episode k starts from [`episode_seed`]`(seed, k)`; keep it apart from the
    /// evaluation's).
    pub seed: u64,
    /// The take-over step is drawn uniformly from this share of the task's step budget.
    pub take_over: (f64, f64),
    /// Camera image side recorded (as the dataset's).
    pub image_size: usize,
    /// Worker threads (one simulator and one policy each).
    pub workers: usize,
    /// The expert that takes over.
    pub expert: ExpertConfig,
    /// The driving policy, as the collection's settings name it (e.g. the run and its step).
    pub source: String,
}

impl Default for DaggerConfig {
    fn default() -> Self {
        DaggerConfig {
            episodes: 20,
            seed: 2000,
            take_over: (0.05, 0.9),
            image_size: 32,
            workers: 1,
            expert: sim::generate::plain_expert(),
            source: String::new(),
        }
    }
}

/// The settings a collection into one folder keeps (`OUT/`[`SETTINGS`]): the episodes of its
/// ledger belong to them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// [`DaggerConfig::source`].
    pub source: String,
    /// [`DaggerConfig::seed`].
    pub seed: u64,
    /// [`DaggerConfig::take_over`].
    pub take_over: (f64, f64),
    /// [`DaggerConfig::image_size`].
    pub image_size: usize,
    /// [`DaggerConfig::expert`], as Rust's debug text.
    pub expert: String,
}

/// The file of a collection's [`Settings`].
pub const SETTINGS: &str = "dagger_settings.json";

impl DaggerConfig {
    /// The settings this collection keeps (not the episode count or the workers, which may change
    /// between runs into one folder).
    pub fn settings(&self) -> Settings {
        Settings {
            source: self.source.clone(),
            seed: self.seed,
            take_over: self.take_over,
            image_size: self.image_size,
            expert: format!("{:?}", self.expert),
        }
    }
}

/// Writes `OUT/`[`SETTINGS`] the first time; later collections into `out` must have the same
/// settings (else an error naming the file and the first setting that differs).
fn check_settings(out: &Path, cfg: &DaggerConfig) -> Result<(), EvalError> {
    let path = out.join(SETTINGS);
    let want = cfg.settings();
    match std::fs::read_to_string(&path) {
        Err(_) => {
            let json = serde_json::to_string_pretty(&want).expect("settings serialise");
            crate::write_atomic(&path, json.as_bytes())
        }
        Ok(text) => {
            let have: Settings = serde_json::from_str(&text).map_err(|e| EvalError::Input {
                path: path.clone(),
                message: format!("not DAgger settings: {e}"),
            })?;
            let differs = [
                ("source (--run)", have.source != want.source),
                ("seed", have.seed != want.seed),
                (
                    "take-over share (--from/--to)",
                    have.take_over != want.take_over,
                ),
                ("image size", have.image_size != want.image_size),
                ("expert (--branch-rule)", have.expert != want.expert),
            ];
            match differs.iter().find(|d| d.1) {
                None => Ok(()),
                Some((what, _)) => Err(EvalError::Input {
                    path,
                    message: format!(
                        "this folder holds a collection with another {what}: {have:?}, now {want:?} \
                         (collect into another folder)"
                    ),
                }),
            }
        }
    }
}

/// What happened in one take-over episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TakeOver {
    /// Task id.
    pub task: String,
    /// Episode index.
    pub episode: usize,
    /// Reset seed.
    pub seed: u64,
    /// The earliest take-over step drawn.
    #[serde(default)]
    pub from: usize,
    /// The step the expert took over at (the budget: it could not).
    pub at: usize,
    /// Subgoals satisfied when it took over.
    pub satisfied_at: usize,
    /// Steps the expert ran (0: no take-over — the policy had over-repeated first, or the
    /// budget ended before a state the expert can take over from).
    pub expert_steps: usize,
    /// Kept: the expert finished the goal without over-repetition (the file was written).
    pub kept: bool,
}

/// The take-over step of an episode of `task` started from `seed`.
pub fn take_over_step(task: &TaskSpec, seed: u64, share: (f64, f64)) -> usize {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7461_6b65_6f76);
    let (lo, hi) = (share.0.clamp(0.0, 1.0), share.1.clamp(0.0, 1.0));
    let f = if hi > lo {
        rng.random_range(lo..hi)
    } else {
        lo
    };
    (f * task.max_steps as f64) as usize
}

/// Idle steps the recording goes on for once the goal is done (as `sim generate` records).
const HOLD_AFTER_DONE: usize = 5;

/// Runs one take-over episode in `env` (built for `task`, rendering with segmentation): `policy`
/// drives from the reset until the first step from `from` on where the expert can take over
/// ([`sim::expert::can_take_over`]; none before the budget ends: nothing is kept), then the expert
/// runs until its plan ends or the goal has held for a few steps (at most the task's budget
/// again); writes `path` when the expert finishes the goal. The policy's part is found first and
/// then replayed into the recording (the metadata, written first, holds the take-over step): the
/// simulator repeats a seed's episode exactly, which the replay checks.
pub fn record_take_over(
    env: &mut Env,
    task: &TaskSpec,
    policy: &mut dyn Policy,
    seed: u64,
    from: usize,
    expert: &ExpertConfig,
    path: &Path,
) -> Result<TakeOver, EvalError> {
    let out_err = |e: sim::record::RecordError| EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    policy.reset(task, seed)?;
    let mut obs = env.reset(seed)?;
    let start_quat = obs.eef_quat;
    let mut actions = Vec::new();
    while actions.len() < task.max_steps
        && !(actions.len() >= from && sim::expert::can_take_over(&obs))
    {
        let a = policy.act(env, &obs)?;
        obs = env.step(&a)?;
        actions.push(a);
    }
    let at = actions.len();
    let reached = obs.state;
    let mut result = TakeOver {
        task: task.id.clone(),
        episode: 0,
        seed,
        from,
        at,
        satisfied_at: obs.goal.as_ref().map_or(0, |g| g.satisfied),
        expert_steps: 0,
        kept: false,
    };
    if at >= task.max_steps || obs.goal.as_ref().is_some_and(|g| g.failed) {
        return Ok(result);
    }
    let mut obs = env.reset(seed)?;
    let mut rec = Recorder::create_with(
        path,
        env,
        task,
        seed,
        data::WriterOptions::default(),
        &[(data::LABELLED_FROM, at.to_string())],
    )
    .map_err(out_err)?;
    for a in actions {
        let next = env.step(&a)?;
        rec.record(env, &obs, a, &next).map_err(out_err)?;
        obs = next;
    }
    if obs.state != reached {
        return Err(EvalError::Model(format!(
            "{} seed {seed}: the replay of the policy's {at} steps reached another state",
            task.id
        )));
    }
    let goal = |o: &sim::Observation| o.goal.clone().unwrap_or_default();
    let mut ex = Expert::resume(task, seed, expert.clone(), start_quat);
    let mut after_done = 0;
    while result.expert_steps < task.max_steps {
        let Some(a) = ex.act(env, &obs) else { break };
        let next = env.step(&a)?;
        rec.record(env, &obs, a, &next).map_err(out_err)?;
        obs = next;
        result.expert_steps += 1;
        let g = goal(&obs);
        if g.failed {
            break;
        }
        if g.done {
            after_done += 1;
            if after_done > HOLD_AFTER_DONE {
                break;
            }
        }
    }
    let g = goal(&obs);
    if g.done && !g.failed {
        rec.finish().map_err(out_err)?;
        result.kept = true;
    }
    Ok(result)
}

/// The folder of `task`'s take-over episodes under `out`.
pub fn task_dir(out: &Path, task: &TaskSpec) -> PathBuf {
    out.join(format!("dagger_{}", sim::generate::suite_folder(task)))
}

/// The file of episode `k` of `task` under `out`.
pub fn episode_path(out: &Path, task: &TaskSpec, k: usize) -> PathBuf {
    sim::generate::episode_path(&task_dir(out, task), k)
}

/// Makes `out` a dataset of its take-over episodes and of every episode of the dataset `base`
/// (hard links where the file system allows, else copies; files already there are kept), and
/// writes `out`'s index with `base`'s validation share and split seed.
pub fn join_base(out: &Path, base: &Path) -> Result<data::DatasetIndex, EvalError> {
    let base_index = data::DatasetIndex::load(base)?;
    for src in data::index::episode_files(base)? {
        let rel = src.strip_prefix(base).unwrap_or(&src);
        let dst = out.join(rel);
        if dst.exists() {
            continue;
        }
        let fail = |e: std::io::Error| EvalError::Output {
            path: dst.clone(),
            message: e.to_string(),
        };
        if let Some(parent) = dst.parent() {
            std::fs::create_dir_all(parent).map_err(fail)?;
        }
        if std::fs::hard_link(&src, &dst).is_err() {
            // Another file system: copy under a temporary name, then rename (no half file).
            let tmp = dst.with_extension("mcap.part");
            std::fs::copy(&src, &tmp).map_err(fail)?;
            std::fs::rename(&tmp, &dst).map_err(fail)?;
        }
    }
    Ok(data::build_index(
        out,
        &data::IndexOptions {
            val_fraction: base_index.val_fraction,
            seed: base_index.split_seed,
        },
    )?)
}

/// The ledger of a collection: a journal (the evaluation's format, keyed by the collection's
/// [`Settings`]) of one [`TakeOver`] per line, appended as episodes finish; a torn last line (a
/// killed collection) is dropped when it is opened again.
pub const LEDGER: &str = "dagger.jsonl";

/// Collects `cfg.episodes` take-over episodes of every task into `out` (see the module docs),
/// each recorded in the ledger `OUT/`[`LEDGER`]; a re-run skips the episodes the ledger holds
/// (same seed; a kept one only while its file exists). `progress` gets each episode run.
/// Returns every episode of the tasks, earlier and new, in task and episode order.
pub fn collect(
    tasks: &[TaskSpec],
    make: &PolicyFactory,
    cfg: &DaggerConfig,
    out: &Path,
    progress: &(dyn Fn(&TakeOver) + Sync),
) -> Result<Vec<TakeOver>, EvalError> {
    if cfg.episodes == 0 || cfg.workers == 0 {
        return Err(EvalError::Argument(
            "--episodes and --workers must be at least 1".into(),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| EvalError::Output {
        path: out.to_path_buf(),
        message: e.to_string(),
    })?;
    check_settings(out, cfg)?;
    let ledger_path = out.join(LEDGER);
    let key = serde_json::to_string(&cfg.settings()).expect("settings serialise");
    let (earlier, file) = crate::open_journal::<TakeOver>(&ledger_path, &key)?;
    let ledger = Mutex::new(file);
    let mut all = Vec::new();
    for task in tasks {
        let dir = task_dir(out, task);
        std::fs::create_dir_all(&dir).map_err(|e| EvalError::Output {
            path: dir.clone(),
            message: e.to_string(),
        })?;
        let mut done: Vec<TakeOver> = Vec::new();
        for k in 0..cfg.episodes {
            let seed = episode_seed(cfg.seed, k as u64);
            let found = earlier.iter().rev().find(|e| {
                e.task == task.id
                    && e.episode == k
                    && e.seed == seed
                    && (!e.kept || episode_path(out, task, k).exists())
            });
            if let Some(e) = found {
                done.push(e.clone());
            }
        }
        let todo: Vec<usize> = (0..cfg.episodes)
            .filter(|k| !done.iter().any(|e| e.episode == *k))
            .collect();
        let results = Mutex::new(done);
        let init = || -> Result<_, EvalError> {
            let policy = make()?;
            let env = Env::from_task(
                task,
                EnvConfig {
                    render: true,
                    segmentation: true,
                    image_size: cfg.image_size,
                    ..EnvConfig::default()
                },
            )?;
            Ok((policy, env))
        };
        let work = |(policy, env): &mut (Box<dyn Policy>, Env), i: usize| {
            let k = todo[i];
            let seed = episode_seed(cfg.seed, k as u64);
            let from = take_over_step(task, seed, cfg.take_over);
            let path = episode_path(out, task, k);
            let mut r =
                record_take_over(env, task, policy.as_mut(), seed, from, &cfg.expert, &path)?;
            r.episode = k;
            {
                use std::io::Write;
                let mut f = ledger.lock().unwrap_or_else(|p| p.into_inner());
                let line = serde_json::to_string(&r).expect("take-overs serialise") + "\n";
                f.write_all(line.as_bytes())
                    .and_then(|_| f.flush())
                    .map_err(|e| data::DataError::io(&ledger_path, e))?;
            }
            progress(&r);
            results.lock().unwrap_or_else(|p| p.into_inner()).push(r);
            Ok(())
        };
        if !todo.is_empty() {
            data::pool::for_each(todo.len(), cfg.workers, init, work, || {
                EvalError::Argument("a DAgger worker panicked".into())
            })?;
        }
        let mut v = results.into_inner().unwrap_or_else(|p| p.into_inner());
        v.sort_by_key(|r| r.episode);
        all.extend(v);
    }
    Ok(all)
}
