//! The training loop.
//!
//! Our own loop on Burn's optimisers rather than burn-train's `Learner`: the Learner owns the
//! data loader (its worker threads and shuffling are not resumable mid-epoch from our sampler
//! state), clips gradients per tensor, and checkpoints through its own recorder layout; we need
//! a seeded sampler whose position is part of the checkpoint, global-norm clipping, atomic
//! checkpoints with a `latest` pointer, and `runs/<name>/` in LeRobot's layout. The loop is
//! short: sample → forward → backward → clip → AdamW step with the scheduled learning rate.
//!
//! Determinism: Burn's RNG is seeded with `[train].seed` before the model is built (the only
//! random draws: initialisation), the sampler's order is a function of (seed, epoch), and
//! augmentation of (seed, epoch, sample), so the same config gives the same weights, and a run
//! resumed from a checkpoint ends bit for bit where the uninterrupted run ends.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use indicatif::{ProgressBar, ProgressStyle};
use model::{Carry, Losses, ModelConfig, PolicyModel};
use serde::{Deserialize, Serialize};

use crate::checkpoint::{self, STATE_FORMAT, TrainState};
use crate::clip::clip_global_norm;
use crate::config::{BackendKind, Config, ObsMode, Sampling};
use crate::dataset::{ChunkSpan, RunData, ensure_dataset};
use crate::ema;
use crate::error::{Result, TrainError};
use crate::loader::{self, Draw, Prefetcher};
use crate::metrics::{self, JsonlWriter, Record};
use crate::parallel;
use crate::plot;
use crate::schedule::WarmupCosine;
use crate::stages;

/// Command-line choices that override or complement the config.
#[derive(Clone, Debug, Default)]
pub struct TrainOptions {
    /// Require a checkpoint to resume from (without it, resuming is still automatic when the
    /// run directory has checkpoints).
    pub resume: bool,
    /// Overrides `[train].keep`.
    pub keep: Option<usize>,
    /// Overrides `[train].steps`.
    pub steps: Option<u64>,
    /// Run directory (default `runs/<name>`).
    pub run_dir: Option<PathBuf>,
    /// Overrides `[backend].kind`.
    pub backend: Option<BackendKind>,
    /// Show the progress bar.
    pub progress: bool,
    /// Stop (after checkpointing) once this many steps are done, as if killed there; the
    /// schedule still spans `steps` (used to test resuming).
    pub stop_at: Option<u64>,
    /// Prepare each batch in the loop instead of on the loader thread ahead of the step (the
    /// same batches either way; for measuring).
    pub no_prefetch: bool,
}

/// Batches the loader thread keeps ready ahead of the step.
const PREFETCH_DEPTH: usize = 2;

/// What a run did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrainSummary {
    /// The run directory.
    pub run_dir: PathBuf,
    /// Step the run started from (0, or the checkpoint it resumed).
    pub start_step: u64,
    /// Steps done at the end.
    pub step: u64,
    /// Total loss of the first step of the whole run (from the metrics), if known.
    pub first_loss: Option<f64>,
    /// Mean total loss over the last steps of this invocation.
    pub final_loss: Option<f64>,
    /// Last validation loss (cold-memory windows).
    pub val_loss: Option<f64>,
    /// Last loss over the validation episodes walked whole with carried memory.
    pub val_walk_loss: Option<f64>,
    /// Optimiser steps per second in this invocation.
    pub steps_per_s: f64,
    /// The last checkpoint written or resumed.
    pub checkpoint: Option<PathBuf>,
}

/// The config with the command-line overrides applied, as saved in the run directory.
pub fn resolve(cfg: &Config, opts: &TrainOptions) -> Config {
    let mut c = cfg.clone();
    if let Some(s) = opts.steps {
        c.train.steps = s;
    }
    if let Some(k) = opts.keep {
        c.train.keep = k;
    }
    if let Some(b) = opts.backend {
        c.backend.kind = b;
    }
    c
}

/// The run directory of a config (`--run-dir` or `runs/<name>`).
pub fn run_dir(cfg: &Config, opts: &TrainOptions) -> PathBuf {
    opts.run_dir
        .clone()
        .unwrap_or_else(|| Path::new("runs").join(cfg.run_name()))
}

/// A loss read back to the host; a backend failure is [`TrainError::Device`] at `step`.
fn scalar(step: u64, x: &Tensor<1>) -> Result<f64> {
    x.clone()
        .try_into_scalar::<f32>()
        .map(f64::from)
        .map_err(|e| TrainError::Device {
            step,
            what: "the loss",
            message: e.to_string(),
        })
}

fn record(step: u64, l: &Losses) -> Result<Record> {
    let opt = |x: &Option<Tensor<1>>| x.as_ref().map(|t| scalar(step, t)).transpose();
    Ok(Record {
        step,
        lr: 0.0,
        loss: scalar(step, &l.total)?,
        action: scalar(step, &l.action)?,
        contrastive: opt(&l.contrastive)?,
        window: opt(&l.window)?,
        slot_recon: opt(&l.slot_recon)?,
        pointer: opt(&l.pointer)?,
        progress: opt(&l.progress)?,
        done: opt(&l.done)?,
        grad_norm: 0.0,
        time_s: 0.0,
        data_s: 0.0,
        forward_s: 0.0,
        backward_s: 0.0,
        optim_s: 0.0,
        stage: None,
    })
}

fn config_error(cfg: &Config, message: String) -> TrainError {
    TrainError::Config {
        path: cfg
            .source
            .clone()
            .unwrap_or_else(|| PathBuf::from("<config>")),
        message,
    }
}

/// Weighted mean of loss records (validation): each record counts with its weight.
#[derive(Default)]
struct MeanRecord {
    sum: Option<Record>,
    weight: f64,
}

impl MeanRecord {
    /// Adds `r` with weight `w`; a term missing from any record is missing from the mean.
    fn add(&mut self, r: Record, w: f64) {
        let add = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a + w * b);
        let zero = Record {
            loss: 0.0,
            action: 0.0,
            contrastive: r.contrastive.map(|_| 0.0),
            window: r.window.map(|_| 0.0),
            slot_recon: r.slot_recon.map(|_| 0.0),
            pointer: r.pointer.map(|_| 0.0),
            progress: r.progress.map(|_| 0.0),
            done: r.done.map(|_| 0.0),
            ..r.clone()
        };
        let s = self.sum.take().unwrap_or(zero);
        self.sum = Some(Record {
            loss: s.loss + w * r.loss,
            action: s.action + w * r.action,
            contrastive: add(s.contrastive, r.contrastive),
            window: add(s.window, r.window),
            slot_recon: add(s.slot_recon, r.slot_recon),
            pointer: add(s.pointer, r.pointer),
            progress: add(s.progress, r.progress),
            done: add(s.done, r.done),
            ..s
        });
        self.weight += w;
    }

    /// The mean (None when nothing was added or every weight was zero).
    fn mean(self) -> Option<Record> {
        let n = self.weight;
        let div = |x: Option<f64>| x.map(|x| x / n);
        self.sum.filter(|_| n > 0.0).map(|s| Record {
            loss: s.loss / n,
            action: s.action / n,
            contrastive: div(s.contrastive),
            window: div(s.window),
            slot_recon: div(s.slot_recon),
            pointer: div(s.pointer),
            progress: div(s.progress),
            done: div(s.done),
            ..s
        })
    }
}

/// Mean losses over the validation split (evenly spread windows, fixed order, no augmentation).
pub fn validate(
    model: &PolicyModel,
    data: &RunData,
    batch_size: usize,
    max_batches: usize,
    step: u64,
    device: &Device,
) -> Result<Option<Record>> {
    let Some(val) = &data.val else {
        return Ok(None);
    };
    let n = if max_batches == 0 {
        val.len()
    } else {
        (max_batches * batch_size).min(val.len())
    };
    let indices: Vec<(usize, u64)> = (0..n).map(|k| (k * val.len() / n, 0)).collect();
    let model = model.valid();
    let mut mean = MeanRecord::default();
    for chunk in indices.chunks(batch_size) {
        let batch = data.batch(val, chunk, device)?;
        let (_, losses) = model.forward(&batch)?;
        mean.add(record(step, &losses)?, chunk.len() as f64);
    }
    Ok(mean.mean())
}

/// Mean losses over whole validation episodes walked the way episode sampling trains: `lanes`
/// episodes at a time, each from its first frame in consecutive chunks of the split's window
/// length with the memory (slots, SSM state, history) carried from chunk to chunk, a lane taking
/// the next episode when its own ends. `episodes`: how many of the split's episodes, evenly
/// spread over it in split order (more than the split has: all; 0: none, and None is returned).
/// Each chunk counts with its action mass (its frames in the action loss), so the action term is
/// the per-frame mean over the walked episodes. Unlike [`validate`], which starts every window
/// from a cold memory, this reads the memory as the closed loop does: from the episode's start.
pub fn validate_walked(
    model: &PolicyModel,
    data: &RunData,
    lanes: usize,
    episodes: usize,
    step: u64,
    device: &Device,
) -> Result<Option<Record>> {
    let Some(val) = &data.val else {
        return Ok(None);
    };
    let total = val.num_episodes();
    let n = episodes.min(total);
    let window = val.config().len();
    if n == 0 || lanes == 0 {
        return Ok(None);
    }
    let mut queue = (0..n).map(|k| k * total / n);
    let model = model.valid();
    let mut mean = MeanRecord::default();
    // Per lane: the episode it walks and the first step of its next chunk.
    let mut walking: Vec<Option<(usize, usize)>> = vec![None; lanes];
    let mut carry = Carry::default();
    loop {
        let mut fresh = vec![false; lanes];
        for (lane, slot) in walking.iter_mut().enumerate() {
            let done = slot.is_none_or(|(e, start)| start >= val.episode_len(e));
            if done {
                *slot = queue.next().map(|e| (e, 0));
                fresh[lane] = slot.is_some();
            }
        }
        let active: Vec<usize> = (0..lanes).filter(|&l| walking[l].is_some()).collect();
        if active.is_empty() {
            break;
        }
        let spans: Vec<ChunkSpan> = active
            .iter()
            .map(|&l| {
                let (episode, start) = walking[l].expect("active lane");
                ChunkSpan {
                    episode,
                    start,
                    epoch: 0,
                    fresh: fresh[l],
                    lane: l,
                }
            })
            .collect();
        let (batch, fresh_t) = data.chunk_batch_of(val, &spans, true, device)?;
        let carry_in = if carry.is_empty() {
            Carry::default()
        } else if active.len() == lanes {
            carry.clone().with_fresh(fresh_t)
        } else {
            carry.pick_lanes(&active, lanes)?.with_fresh(fresh_t)
        };
        let (_, losses, out) = model.forward_from(&batch, carry_in)?;
        mean.add(record(step, &losses)?, model.action_mass(&batch)?);
        carry = if active.len() == lanes {
            out
        } else {
            carry.put_lanes(lanes, &active, &out)?
        };
        for &l in &active {
            if let Some((_, start)) = walking[l].as_mut() {
                *start += window;
            }
        }
    }
    Ok(mean.mean())
}

/// Where a run's walked validation goes (one [`Record`] per validation, as `val.jsonl`).
pub const VAL_WALK_FILE: &str = "val_walk.jsonl";

/// Both validations of one model: cold-memory windows ([`validate`]) and whole episodes walked
/// with the memory carried ([`validate_walked`]); None where the run has no val split or the
/// config turns one off.
#[derive(Clone, Debug, Default)]
pub struct Validation {
    /// Step of the weights validated.
    pub step: u64,
    /// Mean losses over cold-memory windows (`val.jsonl`).
    pub windows: Option<Record>,
    /// Mean losses over walked episodes (`val_walk.jsonl`).
    pub walked: Option<Record>,
}

impl Validation {
    /// "val loss 0.0936 (walked 0.1021)", or None when neither was measured.
    pub fn line(&self) -> Option<String> {
        let walked = self
            .walked
            .as_ref()
            .map(|w| format!("walked {:.4}", w.loss));
        match (&self.windows, walked) {
            (Some(v), Some(w)) => Some(format!("val loss {:.4} ({w})", v.loss)),
            (Some(v), None) => Some(format!("val loss {:.4}", v.loss)),
            (None, Some(w)) => Some(format!("val loss: {w}")),
            (None, None) => None,
        }
    }
}

/// A run's two validation logs and the last losses written to them.
struct ValLogs {
    windows: JsonlWriter,
    walked: JsonlWriter,
    loss: Option<f64>,
    walk_loss: Option<f64>,
}

impl ValLogs {
    /// Appends what `v` measured to its log.
    fn write(&mut self, v: &Validation) -> Result<()> {
        if let Some(r) = &v.windows {
            self.loss = Some(r.loss);
            self.windows.write(r)?;
        }
        if let Some(r) = &v.walked {
            self.walk_loss = Some(r.loss);
            self.walked.write(r)?;
        }
        Ok(())
    }
}

/// Both validations of `model` at `step` as `cfg` asks for them.
fn validations(
    model: &PolicyModel,
    data: &RunData,
    cfg: &Config,
    step: u64,
    device: &Device,
) -> Result<Validation> {
    let t = &cfg.train;
    let windows = validate(model, data, t.batch_size, t.val_batches, step, device)?;
    let walked = validate_walked(model, data, t.batch_size, t.val_walk, step, device)?;
    Ok(Validation {
        step,
        windows,
        walked,
    })
}

/// Validates the newest checkpoint of `cfg`'s run directory (its EMA weights where it keeps
/// them) without training or writing anything: `train --validate`. Both validations use the
/// config's settings (`val_batches`, `val_walk`, batch size, window length), so runs
/// trained before `val_walk` existed can be compared on it.
pub fn validate_run(cfg: &Config, opts: &TrainOptions) -> Result<(PathBuf, Validation)> {
    let cfg = resolve(cfg, opts);
    let run = run_dir(&cfg, opts);
    let device = model::backend::device(cfg.backend.kind)?;
    let ad = device.clone().autodiff();
    let (mcfg, data) = open_data(&cfg)?;
    let Some(l) = newest_checkpoint(checkpoint::candidates(&run)?, &cfg, &mcfg, &ad)? else {
        return Err(TrainError::Usage(format!(
            "--validate: no checkpoint in {}",
            run.join(checkpoint::CHECKPOINTS).display()
        )));
    };
    let model = l.ema.as_ref().unwrap_or(&l.model);
    Ok((
        l.dir.clone(),
        validations(model, &data, &cfg, l.state.step, &device)?,
    ))
}

fn new_optimizer(cfg: &Config) -> ModuleOptimizer {
    let t = &cfg.train;
    AdamWConfig::new()
        .with_beta_1(t.beta1 as f32)
        .with_beta_2(t.beta2 as f32)
        .with_weight_decay(t.weight_decay as f32)
        .init()
}

/// Draws the loss curves of a run directory into `RUN/plots/loss_<term>.png`.
pub fn plot_run(run_dir: &Path) -> Result<Vec<PathBuf>> {
    let train = metrics::read(&run_dir.join("metrics.jsonl"))?;
    let val = metrics::read(&run_dir.join("val.jsonl"))?;
    // Runs trained before the walked validation have no such file: no dots (a missing file
    // reads as empty).
    let walked = metrics::read(&run_dir.join(VAL_WALK_FILE))?;
    let dir = run_dir.join("plots");
    std::fs::create_dir_all(&dir).map_err(|e| TrainError::io(&dir, e))?;
    let mut out = vec![];
    let Some(first) = train.first() else {
        return Ok(out);
    };
    for (name, _) in first.terms() {
        let pick = |rs: &[Record]| -> Vec<(u64, f64)> {
            rs.iter()
                .filter_map(|r| {
                    r.terms()
                        .into_iter()
                        .find(|t| t.0 == name)
                        .map(|t| (r.step, t.1))
                })
                .collect()
        };
        let p = dir.join(format!("loss_{name}.png"));
        plot::loss_curve(&p, name, &pick(&train), &pick(&val), &pick(&walked))?;
        out.push(p);
    }
    Ok(out)
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    data::index::write_atomic(path, text.as_bytes()).map_err(TrainError::from)
}

/// Opens the dataset of `cfg` (which must exist) for the model it configures: the model config
/// completed from the data (vocabulary; in state mode the object tokens) and the run's windows.
pub fn open_data(cfg: &Config) -> Result<(ModelConfig, RunData)> {
    // Every episode read and checked once, for the checks below and both splits' windows.
    let opened = data::OpenedDataset::open(&cfg.data.dir)?;
    let vocab = RunData::model_vocab(&opened.index)?;
    let mut mcfg: ModelConfig = cfg.model_config(vocab).map_err(|m| config_error(cfg, m))?;
    if mcfg.variant.needs_subgoal_text() || mcfg.loss.progress > 0.0 || mcfg.loss.done > 0.0 {
        crate::dataset::check_goals(&opened)?;
    }
    let state = match cfg.model.obs {
        ObsMode::Pixels => None,
        ObsMode::State => {
            let spec = crate::dataset::state_spec(
                &opened,
                &cfg.model.state_relative_cm,
                &cfg.model.state_neighbour_cm,
                cfg.model.state_distances,
                cfg.model.state_fingers,
                cfg.model.state_parts,
            )?;
            mcfg = mcfg.with_state(spec.tokens(), spec.num_categories(), spec.features());
            mcfg.validate()
                .map_err(|e| config_error(cfg, e.to_string()))?;
            Some(spec)
        }
    };
    let data = RunData::open(cfg, &mcfg, state, &opened)?;
    Ok((mcfg, data))
}

/// What one replica's forward and backward gave.
struct ReplicaStep {
    /// Its losses, read back, and its forward and backward times.
    rec: Record,
    /// Its gradients (of its loss scaled as asked).
    grads: GradientsParams,
    /// The memory after its lanes' chunk, detached.
    carry: Carry,
}

/// Forward, losses and backward of one lane group on `model` (the whole batch without data
/// parallelism), the loss scaled by `scale` before the backward pass.
#[allow(clippy::too_many_arguments)]
fn replica_step(
    model: &PolicyModel,
    shard: loader::Shard,
    carry_in: Carry,
    stage: Option<&stages::Stage>,
    cfg: &Config,
    mcfg: &ModelConfig,
    step: u64,
    scale: f64,
) -> Result<ReplicaStep> {
    let forward_started = Instant::now();
    let (_, losses, carry) = model.forward_from(&shard.batch, carry_in)?;
    let mut rec = record(step, &losses)?;
    let total = match stage {
        Some(s) => {
            let total = stages::total(s, &losses, &mcfg.loss).ok_or_else(|| {
                config_error(
                    cfg,
                    format!(
                        "train.stages `{}`: the {} model computes none of its losses {:?}",
                        s.name, cfg.model.variant, s.losses
                    ),
                )
            })?;
            rec.loss = scalar(step, &total)?;
            rec.stage = Some(s.name.clone());
            total
        }
        None => losses.total,
    };
    if !rec.loss.is_finite() {
        return Err(TrainError::NonFinite(step));
    }
    rec.forward_s = forward_started.elapsed().as_secs_f64();
    let backward_started = Instant::now();
    let total = if scale == 1.0 {
        total
    } else {
        total.mul_scalar(scale)
    };
    let grads = GradientsParams::from_grads(total.backward(), model);
    rec.backward_s = backward_started.elapsed().as_secs_f64();
    Ok(ReplicaStep { rec, grads, carry })
}

/// `replicas` kernel pools of `threads / replicas` threads each (at least one), where `threads`
/// is the size of the pool the run was started in (`--threads`); none for one replica.
fn replica_pools(replicas: usize) -> Result<Vec<rayon::ThreadPool>> {
    if replicas <= 1 {
        return Ok(vec![]);
    }
    let each = (rayon::current_num_threads() / replicas).max(1);
    (0..replicas)
        .map(|i| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(each)
                .thread_name(move |k| format!("replica-{i}-{k}"))
                .build()
                .map_err(|e| TrainError::Other(format!("a kernel pool for replica {i}: {e}")))
        })
        .collect()
}

/// The newest checkpoint of `candidates` (newest first) that verifies and loads; None when
/// there is none. A checkpoint of another model is an error (never a silent fall back to an
/// older one); corrupt or unreadable ones are skipped with a warning, and the newest one's error
/// is returned when none is usable (the evaluator's rule, `model::run::newest_valid`).
fn newest_checkpoint(
    candidates: Vec<PathBuf>,
    cfg: &Config,
    mcfg: &ModelConfig,
    ad: &Device,
) -> Result<Option<checkpoint::Loaded>> {
    let mut loaded = None;
    let mut last_err = None;
    for dir in candidates {
        // The evaluator's rule (model::run::newest_valid): verify against the manifest first.
        match model::run::verify_checkpoint(&dir) {
            Ok((_, model::run::Verified::Manifest)) => {}
            Ok((_, model::run::Verified::NoManifest)) => eprintln!(
                "warning: checkpoint {} has no manifest (written before manifests): its files are not verified",
                dir.display()
            ),
            Err(e) => {
                eprintln!(
                    "warning: skipping corrupt checkpoint {}: {e}",
                    dir.display()
                );
                // The newest one's error is the one reported when none is usable (as eval does).
                last_err.get_or_insert(TrainError::from(e));
                continue;
            }
        }
        match checkpoint::load(&dir, mcfg, new_optimizer(cfg), ad) {
            Ok(l) => {
                loaded = Some(l);
                break;
            }
            // Another model: never fall back to an older checkpoint of it silently.
            Err(e @ TrainError::IncompatibleCheckpoint { .. })
                if checkpoint::read_state(&dir).is_ok() =>
            {
                return Err(e);
            }
            Err(e) => {
                eprintln!(
                    "warning: skipping unreadable checkpoint {}: {e}",
                    dir.display()
                );
                last_err.get_or_insert(e);
            }
        }
    }
    match (loaded, last_err) {
        (None, Some(e)) => Err(e),
        (loaded, _) => Ok(loaded),
    }
}

/// Trains `cfg` (see the module docs); resumes automatically from the run directory's newest
/// complete checkpoint.
pub fn train(cfg: &Config, opts: &TrainOptions) -> Result<TrainSummary> {
    let cfg = resolve(cfg, opts);
    let run = run_dir(&cfg, opts);
    let t = cfg.train.clone();
    let device = model::backend::device(cfg.backend.kind)?;
    let ad = device.clone().autodiff();

    ensure_dataset(&cfg, opts.progress)?;
    let (mcfg, data) = open_data(&cfg)?;
    let data = Arc::new(data);

    std::fs::create_dir_all(&run).map_err(|e| TrainError::io(&run, e))?;
    checkpoint::clean_temporaries(&run)?;
    let config_toml = cfg.to_toml();

    // Fresh model and optimiser, or the newest loadable checkpoint.
    let candidates = checkpoint::candidates(&run)?;
    if opts.resume && candidates.is_empty() {
        return Err(TrainError::Usage(format!(
            "--resume: no checkpoint in {}",
            run.join(checkpoint::CHECKPOINTS).display()
        )));
    }
    let loaded = newest_checkpoint(candidates, &cfg, &mcfg, &ad)?;
    let episodes = data.train.num_episodes();
    let (mut model, mut ema, mut optim, mut state, mut carry, resumed_from) = match loaded {
        Some(l) => {
            ad.seed(l.state.rng_seed ^ l.state.step);
            if l.state.ema != t.ema {
                let says = |d: Option<f64>| d.map_or("none".to_string(), |d| d.to_string());
                return Err(TrainError::IncompatibleCheckpoint {
                    path: l.dir,
                    message: format!(
                        "it was trained with `train.ema` {}, the config asks {}",
                        says(l.state.ema),
                        says(t.ema)
                    ),
                });
            }
            let lanes = l.state.episodes.as_ref().map_or(episodes, |e| e.order.len);
            if lanes != episodes {
                return Err(TrainError::IncompatibleCheckpoint {
                    path: l.dir,
                    message: format!(
                        "its episode sampler covers {lanes} training episodes, the dataset now has {episodes}"
                    ),
                });
            }
            if l.state.episodes.is_some() != (t.sampling == Sampling::Episodes) {
                return Err(TrainError::IncompatibleCheckpoint {
                    path: l.dir,
                    message: format!(
                        "it was trained with another `[train].sampling` than `{}`",
                        if t.sampling == Sampling::Episodes {
                            "episodes"
                        } else {
                            "windows"
                        }
                    ),
                });
            }
            // The episode sampler's options come from the checkpoint: a changed one is refused,
            // not ignored.
            if let (Some(saved), Some(asked)) = (&l.state.episodes, &Draw::new(&t, &data).episodes)
            {
                let differ: Vec<String> = saved
                    .options()
                    .into_iter()
                    .zip(asked.options())
                    .filter(|(a, b)| a.1 != b.1)
                    .map(|((key, was), (_, now))| format!("`{key} = {was}` (the config: {now})"))
                    .collect();
                if !differ.is_empty() {
                    return Err(TrainError::IncompatibleCheckpoint {
                        path: l.dir,
                        message: format!("its episode sampler was made with {}", differ.join(", ")),
                    });
                }
            }
            let carry = checkpoint::read_carry(&l.dir, &ad)?;
            if l.state.sampler.len != data.train.len() {
                return Err(TrainError::IncompatibleCheckpoint {
                    path: l.dir,
                    message: format!(
                        "its sampler covers {} training windows, the dataset now has {}",
                        l.state.sampler.len,
                        data.train.len()
                    ),
                });
            }
            (l.model, l.ema, l.optim, l.state, carry, Some(l.dir))
        }
        None => {
            ad.seed(t.seed);
            let model = PolicyModel::new(&mcfg, &ad)?;
            let fresh = Draw::new(&t, &data);
            let state = TrainState {
                format: STATE_FORMAT.into(),
                step: 0,
                sampler: fresh.windows,
                episodes: fresh.episodes,
                rng_seed: t.seed,
                elapsed_s: 0.0,
                model: mcfg.clone(),
                ema: t.ema,
            };
            (
                model,
                None,
                new_optimizer(&cfg),
                state,
                Carry::default(),
                None,
            )
        }
    };
    let start_step = state.step;
    let window = cfg.window_len();
    stages::check_freeze(&t.stages, &model).map_err(|m| config_error(&cfg, m))?;

    // The policy's files (model::run, what eval reads) and, LeRobot-style, the resolved config.
    let info = model::run::RunInfo::new(cfg.backend.kind, cfg.eval.tasks.clone());
    model::run::write_policy(&run, &info, &mcfg, &data.processor)?;
    write_file(&run.join("config.toml"), &config_toml)?;
    let mut train_log = JsonlWriter::open(&run.join("metrics.jsonl"), state.step)?;
    let mut val_logs = ValLogs {
        windows: JsonlWriter::open(&run.join("val.jsonl"), state.step)?,
        walked: JsonlWriter::open(&run.join(VAL_WALK_FILE), state.step)?,
        loss: None,
        walk_loss: None,
    };

    let sched = WarmupCosine {
        lr: t.lr,
        warmup: t.warmup_steps,
        total: t.steps,
        final_fraction: t.final_lr_fraction,
    };
    let end = opts.stop_at.map_or(t.steps, |s| s.min(t.steps));
    let bar = if opts.progress {
        let b = ProgressBar::new(t.steps);
        b.set_style(
            ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg} ({per_sec}, ETA {eta})",
            )
            .expect("valid template"),
        );
        b.set_position(state.step);
        b.reset_eta();
        b
    } else {
        ProgressBar::hidden()
    };

    let started = Instant::now();
    let elapsed_before = state.elapsed_s;
    let mut last_ckpt = resumed_from.clone();
    let mut recent: Vec<f64> = vec![];
    let mut last_val_step = None;
    let val_due = |step: u64| t.val_every > 0 && step.is_multiple_of(t.val_every);
    // The loader thread draws from a copy of the sampler; the loop advances the saved one.
    let draw = Draw {
        windows: state.sampler.clone(),
        episodes: state.episodes.clone(),
    };
    let prefetch = (!opts.no_prefetch && end > state.step).then(|| {
        Prefetcher::spawn(
            Arc::clone(&data),
            draw,
            t.batch_size,
            window,
            t.replicas,
            state.step..end,
            t.stages.clone(),
            PREFETCH_DEPTH,
            ad.clone(),
        )
    });
    // Data parallelism: one kernel pool per replica, the threads of the run's pool shared out
    // (at least one each), so that replicas do not queue behind each other's kernels.
    let pools = replica_pools(t.replicas)?;
    while state.step < end {
        let data_started = Instant::now();
        // With episode sampling, consecutive chunks of whole episodes: the memory of the
        // previous chunk goes on.
        let key = loader::draw_next(
            state.episodes.as_mut(),
            &mut state.sampler,
            &data,
            t.batch_size,
            window,
        );
        let idle_tail = stages::idle_tail(&t.stages, state.step);
        let prepared = match &prefetch {
            Some(p) => {
                let prepared = p.next()?;
                if prepared.key != key || prepared.idle_tail != idle_tail {
                    return Err(TrainError::Other(format!(
                        "step {}: the loader prepared other windows than the sampler drew \
                         (or weighted their idle tails otherwise than the stage says)",
                        state.step + 1
                    )));
                }
                prepared
            }
            None => loader::prepare(&data, key, idle_tail, t.replicas, &ad)?,
        };
        // Time the step waited for its batch (with the loader thread: ~0 once it keeps up).
        let data_s = data_started.elapsed().as_secs_f64();
        let stage = stages::active(&t.stages, state.step).map(|(_, s)| s);
        let replicas = prepared.shards.len();
        let per = t.batch_size / replicas;
        // With a lane pool the batch's lanes are the pool lanes the sampler picked.
        let pool = state
            .episodes
            .as_ref()
            .filter(|e| e.pooled(t.batch_size))
            .map_or(0, |e| e.pool);
        let picked: Option<Vec<usize>> = match &prepared.key {
            loader::DrawKey::Episodes(spans) if pool > 0 => {
                Some(spans.iter().map(|s| s.lane).collect())
            }
            _ => None,
        };
        let batch_carry = match &picked {
            Some(lanes) if !carry.is_empty() => carry.pick_lanes(lanes, pool)?,
            Some(_) => Carry::default(),
            None => std::mem::take(&mut carry),
        };
        let inputs: Vec<(loader::Shard, Carry)> = prepared
            .shards
            .into_iter()
            .enumerate()
            .map(|(i, shard)| {
                let carry_in = match &shard.fresh {
                    Some(fresh) if !batch_carry.is_empty() => batch_carry
                        .lanes(i * per, per, t.batch_size)
                        .with_fresh(fresh.clone()),
                    _ => Carry::default(),
                };
                (shard, carry_in)
            })
            .collect();
        let step_no = state.step + 1;
        // Each replica's weight in the step's loss (its share of the action mass).
        let scales = if replicas == 1 {
            vec![1.0]
        } else {
            parallel::replica_weights(
                &inputs
                    .iter()
                    .map(|(shard, _)| model.action_mass(&shard.batch))
                    .collect::<std::result::Result<Vec<_>, _>>()?,
            )
        };
        let outs = if replicas == 1 {
            let (shard, carry_in) = inputs.into_iter().next().expect("one shard");
            vec![replica_step(
                &model, shard, carry_in, stage, &cfg, &mcfg, step_no, scales[0],
            )?]
        } else {
            // Burn initialises parameters lazily, on first use, from one seeded stream: a new
            // model's first forward runs here, on the shared weights, so that they are drawn in
            // the order one replica draws them (forking would draw them in module order).
            if state.step == 0 && resumed_from.is_none() {
                let (shard, carry_in) = &inputs[0];
                model.forward_from(&shard.batch, carry_in.clone())?;
            }
            // Each lane group on its own thread with its own copy of the weights (fresh
            // autodiff leaves with the same parameter ids, so the graphs stay apart).
            std::thread::scope(|scope| {
                let handles: Vec<_> = inputs
                    .into_iter()
                    .zip(&pools)
                    .zip(scales.iter().copied())
                    .map(|(((shard, carry_in), pool), scale)| {
                        let replica = model.clone().fork(&ad);
                        let (cfg, mcfg) = (&cfg, &mcfg);
                        scope.spawn(move || {
                            pool.install(|| {
                                replica_step(
                                    &replica, shard, carry_in, stage, cfg, mcfg, step_no, scale,
                                )
                            })
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| {
                        h.join().unwrap_or_else(|_| {
                            Err(TrainError::Other(format!(
                                "step {step_no}: a replica's thread panicked"
                            )))
                        })
                    })
                    .collect::<Result<Vec<_>>>()
            })?
        };
        let optim_started = Instant::now();
        let mut recs = Vec::with_capacity(replicas);
        let mut grads = Vec::with_capacity(replicas);
        let mut carries = Vec::with_capacity(replicas);
        for (o, scale) in outs.into_iter().zip(scales) {
            recs.push((o.rec, scale));
            grads.push(o.grads);
            carries.push(o.carry);
        }
        if state.episodes.is_some() {
            let out = Carry::cat_lanes(carries)?;
            carry = match &picked {
                Some(lanes) => carry.put_lanes(pool, lanes, &out)?,
                None => out,
            };
        }
        let mut rec = parallel::mean_record(recs);
        rec.data_s = data_s;
        let mut grads = parallel::sum_gradients(&model, grads, &ad);
        if let Some(s) = stage {
            stages::freeze(&model, s, &mut grads);
        }
        rec.grad_norm = clip_global_norm(&model, &mut grads, t.grad_clip).map_err(|message| {
            TrainError::Device {
                step: state.step + 1,
                what: "the gradient norm",
                message,
            }
        })?;
        rec.lr = sched.lr(state.step);
        model = optim.step(rec.lr, model, grads);
        if let Some(decay) = t.ema {
            ema = Some(match ema.take() {
                None => ema::start(&model),
                Some(e) => ema::update(e, &model, decay).map_err(TrainError::Other)?,
            });
        }
        rec.optim_s = optim_started.elapsed().as_secs_f64();
        state.step += 1;
        state.elapsed_s = elapsed_before + started.elapsed().as_secs_f64();
        rec.time_s = state.elapsed_s;
        train_log.write(&rec)?;
        recent.push(rec.loss);
        if recent.len() > 20 {
            recent.remove(0);
        }
        bar.set_position(state.step);
        bar.set_message(match &rec.stage {
            Some(name) => format!("{name}: loss {:.4}", rec.loss),
            None => format!("loss {:.4}", rec.loss),
        });

        if val_due(state.step) {
            let v = validations(
                ema.as_ref().unwrap_or(&model),
                &data,
                &cfg,
                state.step,
                &device,
            )?;
            val_logs.write(&v)?;
            if let Some(line) = v.line() {
                bar.println(format!("step {}: {line}", state.step));
            }
            last_val_step = Some(state.step);
        }
        let ckpt_due = (t.checkpoint_every > 0 && state.step.is_multiple_of(t.checkpoint_every))
            || state.step == end;
        if ckpt_due {
            last_ckpt = Some(checkpoint::save(
                &run,
                &model,
                ema.as_ref(),
                &optim,
                &state,
                &carry,
                &config_toml,
            )?);
            checkpoint::prune(&run, t.keep)?;
            // Re-seed at every checkpoint as a resumed run does, so that random draws after
            // it (none today: the forward is deterministic) match too.
            ad.seed(state.rng_seed ^ state.step);
        }
    }
    let final_val = state.step == t.steps && last_val_step != Some(state.step);
    if final_val && state.step > start_step {
        let v = validations(
            ema.as_ref().unwrap_or(&model),
            &data,
            &cfg,
            state.step,
            &device,
        )?;
        val_logs.write(&v)?;
    }
    bar.finish_and_clear();
    plot_run(&run)?;
    let done = state.step - start_step;
    let secs = started.elapsed().as_secs_f64();
    let first_loss = metrics::read(&run.join("metrics.jsonl"))?
        .first()
        .map(|r| r.loss);
    Ok(TrainSummary {
        run_dir: run,
        start_step,
        step: state.step,
        first_loss,
        final_loss: (!recent.is_empty()).then(|| recent.iter().sum::<f64>() / recent.len() as f64),
        val_loss: val_logs.loss,
        val_walk_loss: val_logs.walk_loss,
        steps_per_s: if secs > 0.0 { done as f64 / secs } else { 0.0 },
        checkpoint: last_ckpt,
    })
}
