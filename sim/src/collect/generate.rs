//! Dataset generation: scripted-expert demonstrations recorded as mcap episodes plus the dataset index.
//!
//! Episode `k` of a dataset is `episode_{k:05}.mcap`. Its seed is derived from the base seed, `k` and the
//! attempt number; an attempt the expert fails is discarded (the recorder's temporary file vanishes) and the
//! next attempt's seed is tried, so the same base seed always gives the same files, byte for byte. A file
//! appears under its final name only once complete, so a rerun skips finished episodes and never mistakes a
//! killed run's leftovers for an episode.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::collect::record::{RecordError, Recorder};
use crate::expert::Expert;
use crate::task::TaskSpec;
use crate::world::env::{Env, EnvConfig};

/// Attempts per episode before giving up (an episode done within fewer attempts is the same file
/// whatever the limit: attempt seeds do not depend on it).
pub const MAX_ATTEMPTS: u64 = 32;
/// Steps recorded after the goal is done (a short hold), when the expert has not stopped by then;
/// an expert asked to hold longer than this (`ExpertConfig::hold_steps`) is recorded until it
/// stops: its release and retreat, then the idle hold.
pub const HOLD_STEPS: usize = 10;

/// Errors from generation.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// The simulator failed.
    #[error(transparent)]
    Env(#[from] crate::world::env::EnvError),
    /// Writing an episode failed.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// Building the index failed.
    #[error(transparent)]
    Data(#[from] data::DataError),
    /// The expert failed every attempt of one episode.
    #[error("{task}: the expert failed all {MAX_ATTEMPTS} attempts of episode {episode}")]
    Expert {
        /// Task id.
        task: String,
        /// Episode index.
        episode: usize,
    },
    /// Bad arguments.
    #[error("{0}")]
    Argument(String),
}

/// The file in a generated dataset directory that records how its episodes were made.
pub const GENERATION_JSON: &str = "generation.json";
/// Format tag of [`GENERATION_JSON`].
pub const GENERATION_FORMAT: &str = "libero-mem-rs/generation/1";

/// `generation.json`: what makes a dataset's episodes what they are (the episode and validation
/// counts may grow: episode `k` is the same file whatever the total).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerationRecord {
    /// [`GENERATION_FORMAT`].
    pub format: String,
    /// Task id.
    pub task: String,
    /// Base seed.
    pub seed: u64,
    /// Camera image side.
    pub image_size: usize,
    /// The expert's action noise.
    pub action_noise: f64,
    /// The expert's seeded variation.
    pub variation: bool,
    /// The expert's idle steps after the goal.
    pub hold_steps: usize,
    /// Camera compression (`png` or `jpeg:Q`).
    pub image_compression: String,
    /// Chunk size and zstd level of the episode files.
    pub chunk_size: u64,
    /// zstd level.
    pub zstd_level: u32,
    /// How the expert chose `Or` branches (absent in records from before the choice existed:
    /// the destination rule).
    #[serde(default)]
    pub branch_rule: crate::expert::BranchRule,
    /// The expert's execution noise (DART; absent when 0, as in records from before it existed).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub exec_noise: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl GenerationRecord {
    /// The record of generating `task` with `cfg`.
    pub fn of(task: &TaskSpec, cfg: &GenerateConfig) -> Self {
        GenerationRecord {
            format: GENERATION_FORMAT.into(),
            task: task.id.clone(),
            seed: cfg.seed,
            image_size: cfg.image_size,
            action_noise: cfg.expert.action_noise,
            variation: cfg.expert.variation,
            hold_steps: cfg.expert.hold_steps,
            image_compression: match cfg.writer.image_compression {
                data::ImageCompression::Png => "png".into(),
                data::ImageCompression::Jpeg { quality } => format!("jpeg:{quality}"),
            },
            chunk_size: cfg.writer.chunk_size,
            zstd_level: cfg.writer.zstd_level,
            branch_rule: cfg.expert.branch_rule,
            exec_noise: cfg.expert.exec_noise,
        }
    }

    /// The fields in which `self` (the directory's) differs from `want`, as `key a → b`.
    fn differences(&self, want: &Self) -> Vec<String> {
        let (a, b) = (
            serde_json::to_value(self).expect("serialises"),
            serde_json::to_value(want).expect("serialises"),
        );
        let (a, b) = (
            a.as_object().expect("object"),
            b.as_object().expect("object"),
        );
        a.iter()
            .filter(|(k, v)| b.get(*k) != Some(v))
            .map(|(k, v)| format!("{k} {v} → {}", b[k]))
            .collect()
    }
}

/// Removes what a killed generation left in `dir`: the recorder's `.episode-*.mcap.tmp` files
/// and the video writer's `.video-*.mp4.tmp` files.
pub fn clean_temporaries(dir: &Path) -> Result<(), GenerateError> {
    for e in std::fs::read_dir(dir).map_err(|e| data::DataError::io(dir, e))? {
        let e = e.map_err(|e| data::DataError::io(dir, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with(".episode-") && name.ends_with(".mcap.tmp")
            || name.starts_with(".video-") && name.ends_with(".mp4.tmp")
        {
            std::fs::remove_file(e.path()).map_err(|err| data::DataError::io(e.path(), err))?;
        }
    }
    Ok(())
}

/// Creates `dir` and claims it for `task` with `cfg`'s parameters (refused when it holds episodes
/// of other parameters, unless `cfg.force`, which removes them); an unsharded `cfg` also removes
/// the temporaries of killed runs. What every generation does first; a parent of several
/// processes recording shards into `dir` does it once before starting them.
pub fn prepare_dir(task: &TaskSpec, dir: &Path, cfg: &GenerateConfig) -> Result<(), GenerateError> {
    std::fs::create_dir_all(dir).map_err(|e| data::DataError::io(dir, e))?;
    if cfg.shard.is_whole() {
        clean_temporaries(dir)?;
    }
    claim_dir(dir, &GenerationRecord::of(task, cfg), cfg.force)
}

/// Makes sure `dir` holds (or will hold) episodes of `want` only. A directory recorded with other
/// parameters is refused, unless `force`, which removes its episodes and index first. A directory
/// from before these records is checked on its first episode's task and seed.
fn claim_dir(dir: &Path, want: &GenerationRecord, force: bool) -> Result<(), GenerateError> {
    let path = dir.join(GENERATION_JSON);
    let mismatch = if path.exists() {
        let text = std::fs::read_to_string(&path).map_err(|e| data::DataError::io(&path, e))?;
        let have: GenerationRecord = serde_json::from_str(&text).map_err(|e| {
            GenerateError::Argument(format!("{}: not a generation record: {e}", path.display()))
        })?;
        have.differences(want)
    } else {
        let first = episode_path(dir, 0);
        match first.exists().then(|| data::EpisodeReader::open(&first)) {
            Some(Ok(r)) => {
                let meta = r.meta();
                let seeds: Vec<u64> = (0..MAX_ATTEMPTS)
                    .map(|a| attempt_seed(want.seed, 0, a))
                    .collect();
                let mut d = vec![];
                if meta.task_id != want.task {
                    d.push(format!("task \"{}\" → \"{}\"", meta.task_id, want.task));
                }
                if !seeds.contains(&meta.seed) {
                    d.push(format!(
                        "episode 0's seed {} is not one of seed {}'s",
                        meta.seed, want.seed
                    ));
                }
                d
            }
            // An unreadable first episode is redone like any other (it is not trusted).
            Some(Err(_)) | None => vec![],
        }
    };
    if !mismatch.is_empty() {
        if !force {
            return Err(GenerateError::Argument(format!(
                "{}: holds episodes generated with other parameters ({}); pass --force to replace \
                 them, or generate into another directory",
                dir.display(),
                mismatch.join(", ")
            )));
        }
        for e in std::fs::read_dir(dir).map_err(|e| data::DataError::io(dir, e))? {
            let p = e.map_err(|e| data::DataError::io(dir, e))?.path();
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            if (name.starts_with("episode_") && name.ends_with(".mcap"))
                || name == data::index::INDEX_FILE
            {
                std::fs::remove_file(&p).map_err(|e| data::DataError::io(&p, e))?;
            }
        }
    }
    let text = serde_json::to_string_pretty(want).expect("serialises");
    data::index::write_atomic(&path, text.as_bytes())?;
    Ok(())
}

impl GenerateError {
    /// True when the input (arguments, the task file, the output directory's contents) is at
    /// fault: the workspace's exit code 2.
    pub fn is_bad_input(&self) -> bool {
        match self {
            GenerateError::Env(e) => e.is_bad_input(),
            GenerateError::Data(d) => d.is_bad_input(),
            GenerateError::Argument(_) => true,
            GenerateError::Record(_) | GenerateError::Expert { .. } => false,
        }
    }
}

/// What to generate.
#[derive(Debug, Clone)]
pub struct GenerateConfig {
    /// Episodes in total (train + validation).
    pub episodes: usize,
    /// Of which validation.
    pub val: usize,
    /// Base seed.
    pub seed: u64,
    /// Worker threads (one simulator each).
    pub workers: usize,
    /// Camera image side.
    pub image_size: usize,
    /// Episode writer options (image compression, chunking).
    pub writer: data::WriterOptions,
    /// The expert's settings (default: seeded variation and action noise on; with both off,
    /// one deterministic demonstration per start state — unimodal targets for imitation).
    pub expert: crate::expert::ExpertConfig,
    /// Replace the episodes of a directory generated with other parameters (else an error).
    pub force: bool,
    /// Record only this shard's episodes (k mod N = I; see [`generate_episodes`]).
    pub shard: data::shard::Shard,
    /// Also write each recorded episode as an mp4 beside its mcap ([`video_path`]); not part of
    /// the dataset's identity (its `generation.json`).
    pub video: bool,
}

impl Default for GenerateConfig {
    fn default() -> Self {
        GenerateConfig {
            episodes: 120,
            val: 20,
            seed: 0,
            workers: 1,
            image_size: 128,
            writer: data::WriterOptions::default(),
            expert: crate::expert::ExpertConfig::default(),
            force: false,
            shard: data::shard::Shard::WHOLE,
            video: false,
        }
    }
}

/// Counters reported while generating.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GenerateProgress {
    /// Episodes complete (written now or found from an earlier run).
    pub done: usize,
    /// Expert attempts that succeeded.
    pub successes: usize,
    /// Expert attempts that failed (discarded).
    pub failures: usize,
}

/// Path of episode `k` in `dir`.
pub fn episode_path(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("episode_{k:05}.mcap"))
}

/// Seed of attempt `attempt` of episode `k` (SplitMix64 over the three).
pub fn attempt_seed(seed: u64, k: u64, attempt: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k.wrapping_mul(0xD1B5_4A32_D192_ED03))
        .wrapping_add(attempt.wrapping_mul(0x8CB9_2BA7_2F3D_8DD7));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The deterministic expert: no seeded variation and no action noise.
pub fn plain_expert() -> crate::expert::ExpertConfig {
    crate::expert::ExpertConfig {
        action_noise: 0.0,
        variation: false,
        ..crate::expert::ExpertConfig::default()
    }
}

/// The expert `sim generate` and `[data].generate` run: [`plain_expert`] when `plain`, else the
/// default; `hold_steps` idle steps (arm still, gripper open) after the goal is done, where
/// `None` keeps the default.
pub fn expert_config(plain: bool, hold_steps: Option<usize>) -> crate::expert::ExpertConfig {
    let base = if plain {
        plain_expert()
    } else {
        crate::expert::ExpertConfig::default()
    };
    crate::expert::ExpertConfig {
        hold_steps: hold_steps.unwrap_or(base.hold_steps),
        ..base
    }
}

/// The video of the episode recorded at `path` (`episode_<k>.mp4` beside `episode_<k>.mcap`).
pub fn video_path(path: &Path) -> PathBuf {
    path.with_extension("mp4")
}

/// The rollout video frame ([`data::video::frame`]) of `obs` at `step` of a `budget`-step
/// episode, captioned with its goal progress (what `sim generate --video` and `eval --video` write).
pub fn video_frame(
    obs: &crate::Observation,
    step: usize,
    budget: usize,
) -> Option<(Vec<u8>, usize, usize)> {
    let g = obs.goal.as_ref();
    let caption = data::video::Caption {
        step,
        budget,
        progress: g.map(|g| (g.satisfied, g.goal_len, g.failed)),
        pending: g.and_then(|g| g.pending.clone()),
    };
    data::video::frame(
        &obs.agentview_rgb,
        &obs.eye_in_hand_rgb,
        obs.image_size,
        &caption,
    )
}

/// Appends `obs`'s frame to the episode's video (started at the first frame).
fn push_frame(
    video: &mut Option<data::video::VideoWriter>,
    path: &Path,
    obs: &crate::Observation,
    task: &TaskSpec,
) -> Result<(), GenerateError> {
    let Some((rgb, w, h)) = video_frame(obs, obs.step, task.max_steps) else {
        return Err(GenerateError::Argument(
            "video: the environment renders no camera images".into(),
        ));
    };
    if video.is_none() {
        *video = Some(data::video::VideoWriter::create(
            video_path(path),
            w,
            h,
            20,
        )?);
    }
    video.as_mut().expect("created").push(&rgb)?;
    Ok(())
}

/// Records one expert episode to `path` (and, with `video`, its mp4 to [`video_path`]);
/// `Ok(false)` (and no file) when the expert fails.
pub fn record_episode(
    env: &mut Env,
    task: &TaskSpec,
    seed: u64,
    path: &Path,
    writer: data::WriterOptions,
    expert: &crate::expert::ExpertConfig,
    video: bool,
) -> Result<bool, GenerateError> {
    // A start the scene cannot place is the task file's fault: say which task.
    let mut obs = env.reset(seed).map_err(|e| match e {
        crate::world::env::EnvError::Scene(source) => crate::world::env::EnvError::TaskScene {
            task: task.id.clone(),
            source,
        },
        other => other,
    })?;
    let expert_hold = expert.hold_steps;
    let mut expert = Expert::with_config(task, seed, expert.clone());
    let mut rec = Recorder::create(path, env, task, seed, writer)?;
    let mut frames = None;
    let mut after_done = 0;
    for _ in 0..task.max_steps {
        let Some(action) = expert.act(env, &obs) else {
            break;
        };
        if video {
            push_frame(&mut frames, path, &obs, task)?;
        }
        // With execution noise the arm moves by the perturbed action; the label is the clean one.
        let next = env.step(&expert.executed(action))?;
        rec.record(env, &obs, action, &next)?;
        obs = next;
        let g = obs
            .goal
            .as_ref()
            .expect("task environments report goal progress");
        if g.done {
            after_done += 1;
            if after_done > HOLD_STEPS && expert_hold <= HOLD_STEPS {
                break;
            }
        }
    }
    let g = obs
        .goal
        .as_ref()
        .expect("task environments report goal progress");
    if g.done && !g.failed {
        if video {
            push_frame(&mut frames, path, &obs, task)?;
            if let Some(v) = frames {
                v.finish()?;
            }
        }
        rec.finish()?;
        Ok(true)
    } else {
        Ok(false)
    }
}

/// Generates `cfg.episodes` episodes of `task` into `dir` (skipping finished ones) and writes the index.
/// A sharded `cfg` is refused: shards record with [`generate_episodes`], and the index is written
/// once all are done (by this function, which then finds every episode and records none).
pub fn generate(
    task: &TaskSpec,
    dir: &Path,
    cfg: &GenerateConfig,
    on_progress: &(dyn Fn(GenerateProgress) + Sync),
) -> Result<data::DatasetIndex, GenerateError> {
    if !cfg.shard.is_whole() {
        return Err(GenerateError::Argument(format!(
            "shard {}: a shard records episodes but writes no index (generate_episodes)",
            cfg.shard
        )));
    }
    generate_episodes(task, dir, cfg, on_progress)?;
    write_index(dir, cfg)
}

/// Records the episodes of `cfg.shard` among `cfg.episodes` of `task` into `dir`, skipping
/// finished ones; returns how many the shard owns. Episode k is the same file whichever shard
/// records it, so shards running at once into one directory (a shared file system) leave it as
/// an unsharded run would, short of the index. A shard leaves other processes' temporary files
/// alone (they may be recording); the unsharded pass that writes the index removes a killed
/// shard's leftovers.
pub fn generate_episodes(
    task: &TaskSpec,
    dir: &Path,
    cfg: &GenerateConfig,
    on_progress: &(dyn Fn(GenerateProgress) + Sync),
) -> Result<usize, GenerateError> {
    if cfg.episodes == 0 || cfg.val >= cfg.episodes || cfg.workers == 0 {
        return Err(GenerateError::Argument(format!(
            "need episodes ≥ 1, val < episodes and workers ≥ 1 (got {} episodes, {} val, {} workers)",
            cfg.episodes, cfg.val, cfg.workers
        )));
    }
    prepare_dir(task, dir, cfg)?;
    let items = cfg.shard.items(cfg.episodes);
    let progress = Mutex::new(GenerateProgress::default());
    let report = |f: &dyn Fn(&mut GenerateProgress)| {
        let mut p = progress.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut p);
        on_progress(*p);
    };
    // Each worker builds its simulator only when it has an episode to record (finished episodes
    // of an interrupted run are skipped).
    let work = |env: &mut Option<Env>, i: usize| -> Result<(), GenerateError> {
        let k = items[i];
        let path = episode_path(dir, k);
        if path.exists() {
            report(&|p| p.done += 1);
            return Ok(());
        }
        if env.is_none() {
            *env = Some(Env::from_task(
                task,
                EnvConfig {
                    image_size: cfg.image_size,
                    segmentation: true,
                    ..EnvConfig::default()
                },
            )?);
        }
        let env = env.as_mut().expect("just built");
        for attempt in 0..MAX_ATTEMPTS {
            let seed = attempt_seed(cfg.seed, k as u64, attempt);
            if record_episode(
                env,
                task,
                seed,
                &path,
                cfg.writer.clone(),
                &cfg.expert,
                cfg.video,
            )? {
                report(&|p| {
                    p.successes += 1;
                    p.done += 1;
                });
                return Ok(());
            }
            report(&|p| p.failures += 1);
        }
        Err(GenerateError::Expert {
            task: task.id.clone(),
            episode: k,
        })
    };
    data::pool::for_each(
        items.len(),
        cfg.workers,
        || Ok(None),
        work,
        || GenerateError::Argument("a generation worker panicked".into()),
    )?;
    Ok(items.len())
}

/// Generates a suite dataset: `cfg.episodes` episodes of every task of `tasks` into one subfolder
/// per task under `dir` (each a dataset of its own, as [`generate`] writes it), then the suite's
/// index over all of them (`dir/index.json`, episode files relative to `dir`), from which one
/// multi-task policy trains. `on_progress` gets the task's position with its progress.
pub fn generate_suite(
    tasks: &[TaskSpec],
    dir: &Path,
    cfg: &GenerateConfig,
    on_progress: &(dyn Fn(usize, GenerateProgress) + Sync),
) -> Result<data::DatasetIndex, GenerateError> {
    if tasks.is_empty() {
        return Err(GenerateError::Argument("a suite of no tasks".into()));
    }
    for (i, t) in tasks.iter().enumerate() {
        generate(t, &dir.join(suite_folder(t)), cfg, &|p| on_progress(i, p))?;
    }
    write_index(dir, cfg)
}

/// Builds and writes `dir/index.json` over the episodes of `dir` and of its subfolders, with
/// `cfg`'s validation share and seed.
pub fn write_index(dir: &Path, cfg: &GenerateConfig) -> Result<data::DatasetIndex, GenerateError> {
    Ok(data::build_index(
        dir,
        &data::IndexOptions {
            val_fraction: cfg.val as f64 / cfg.episodes as f64,
            seed: cfg.seed,
        },
    )?)
}

/// The subfolder of a task in a suite dataset (`libero_mem/t3` → `libero_mem_t3`).
pub fn suite_folder(task: &TaskSpec) -> String {
    task.id.replace('/', "_")
}
