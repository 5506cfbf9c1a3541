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
use crate::dataset::{RunData, ensure_dataset};
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
    /// Last validation loss.
    pub val_loss: Option<f64>,
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
    let mut sum: Option<Record> = None;
    let mut batches = 0.0;
    for chunk in indices.chunks(batch_size) {
        let batch = data.batch(val, chunk, device)?;
        let (_, losses) = model.forward(&batch)?;
        let r = record(step, &losses)?;
        let w = chunk.len() as f64;
        let add = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => Some(a + w * b),
            _ => None,
        };
        sum = Some(match sum {
            None => Record {
                loss: w * r.loss,
                action: w * r.action,
                contrastive: r.contrastive.map(|x| w * x),
                window: r.window.map(|x| w * x),
                slot_recon: r.slot_recon.map(|x| w * x),
                pointer: r.pointer.map(|x| w * x),
                progress: r.progress.map(|x| w * x),
                done: r.done.map(|x| w * x),
                ..r
            },
            Some(s) => Record {
                loss: s.loss + w * r.loss,
                action: s.action + w * r.action,
                contrastive: add(s.contrastive, r.contrastive),
                window: add(s.window, r.window),
                slot_recon: add(s.slot_recon, r.slot_recon),
                pointer: add(s.pointer, r.pointer),
                progress: add(s.progress, r.progress),
                done: add(s.done, r.done),
                ..s
            },
        });
        batches += w;
    }
    Ok(sum.map(|s| Record {
        loss: s.loss / batches,
        action: s.action / batches,
        contrastive: s.contrastive.map(|x| x / batches),
        window: s.window.map(|x| x / batches),
        slot_recon: s.slot_recon.map(|x| x / batches),
        pointer: s.pointer.map(|x| x / batches),
        progress: s.progress.map(|x| x / batches),
        done: s.done.map(|x| x / batches),
        ..s
    }))
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
        plot::loss_curve(&p, name, &pick(&train), &pick(&val))?;
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
    let mut candidates = checkpoint::candidates(&run)?;
    if opts.resume && candidates.is_empty() {
        return Err(TrainError::Usage(format!(
            "--resume: no checkpoint in {}",
            run.join(checkpoint::CHECKPOINTS).display()
        )));
    }
    let mut loaded = None;
    let mut last_err = None;
    for dir in candidates.drain(..) {
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
        match checkpoint::load(&dir, &mcfg, new_optimizer(&cfg), &ad) {
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
    if loaded.is_none()
        && let Some(e) = last_err
    {
        return Err(e);
    }
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
            if let Some(e) = &l.state.episodes
                && (e.pool, e.memory_reset) != (t.lane_pool, t.memory_reset)
            {
                return Err(TrainError::IncompatibleCheckpoint {
                    path: l.dir,
                    message: format!(
                        "it was trained with `train.lane_pool = {}` and `train.memory_reset = {}`, \
                         the config asks {} and {}",
                        e.pool, e.memory_reset, t.lane_pool, t.memory_reset
                    ),
                });
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
    let mut val_log = JsonlWriter::open(&run.join("val.jsonl"), state.step)?;

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
    let mut val_loss = None;
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
            if let Some(v) = validate(
                ema.as_ref().unwrap_or(&model),
                &data,
                t.batch_size,
                t.val_batches,
                state.step,
                &device,
            )? {
                val_loss = Some(v.loss);
                val_log.write(&v)?;
                bar.println(format!("step {}: val loss {:.4}", state.step, v.loss));
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
    if final_val
        && state.step > start_step
        && let Some(v) = validate(
            ema.as_ref().unwrap_or(&model),
            &data,
            t.batch_size,
            t.val_batches,
            state.step,
            &device,
        )?
    {
        val_loss = Some(v.loss);
        val_log.write(&v)?;
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
        val_loss,
        steps_per_s: if secs > 0.0 { done as f64 / secs } else { 0.0 },
        checkpoint: last_ckpt,
    })
}
