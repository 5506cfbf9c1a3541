//! Experiment configs: one TOML file per experiment with sections `[data]`, `[model]`, `[train]`,
//! `[backend]` and `[eval]`. Every table denies unknown keys, so a typo is an error that names
//! the key and the file, never a silent default.
//!
//! ```toml
//! name = "t3"                       # run name: runs/<name>/ (default: the file stem)
//! [data]
//! dir = "datasets/t3"               # relative to the working directory
//! generate = { task = "t3", episodes = 50, val = 5, seed = 0 }   # when `dir` has no index.json
//!                                   # (+ image_size = 128, workers = N: camera side, threads)
//! [model]
//! variant = "e_slotssm"             # e_slotssm | e_slotssm_oracle | slotvla_h<N> | dense | dense_h<N>
//! preset = "tiny"                   # tiny | full
//! [model.overrides]                 # any field of model::ModelConfig, merged into the preset
//! decoder = { layers = 3 }
//! [train]
//! steps = 20000
//! [[train.stages]]                  # optional staged training (see `Stage`)
//! name = "slots"
//! steps = 2000
//! losses = ["slot_recon", "contrastive"]
//! freeze = ["decoder"]
//! [[train.stages]]
//! name = "all"
//! losses = ["action", "contrastive", "window", "slot_recon"]
//! [backend]
//! kind = "flex"                     # flex | ndarray (feature `ndarray`) | wgpu (feature `wgpu`)
//! [eval]
//! tasks = ["t3"]
//! seeds = [0, 1, 2]
//! ```

use std::path::{Path, PathBuf};

use model::{ModelConfig, Variant};
use serde::{Deserialize, Serialize};

use crate::error::{Result, TrainError};

/// A whole experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Run name; the run directory is `runs/<name>/` (default: the config file's stem).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Dataset.
    pub data: DataConfig,
    /// Model variant, preset and overrides.
    pub model: ModelSection,
    /// Optimisation.
    #[serde(default)]
    pub train: TrainSection,
    /// Compute backend.
    #[serde(default)]
    pub backend: BackendSection,
    /// Evaluation settings (stored for the eval crate).
    #[serde(default)]
    pub eval: EvalSection,
    /// The file this config was read from (for error messages; not serialised).
    #[serde(skip)]
    pub source: Option<PathBuf>,
}

/// `[data]`: where the episodes are and how windows are cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// Dataset directory (`*.mcap` + `index.json`), relative to the working directory.
    pub dir: PathBuf,
    /// Generate the dataset through the simulator when `dir` is missing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generate: Option<GenerateSpec>,
    /// Frames per training window T (default: 16 for the tiny preset, 32 for full).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<usize>,
    /// Seeded colour jitter + shift augmentation (LIBERO-Mem's pipeline).
    #[serde(default = "yes")]
    pub augment: bool,
    /// No action loss on an episode's idle tail (the arm standing still after its last move,
    /// e.g. the hold of `generate.hold_steps`): frames that teach a policy to freeze.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub mask_idle_tail: bool,
    /// With `mask_idle_tail`, the idle tail's weight in the action loss instead of none (in
    /// [0, 1]; 0 = left out). Validation leaves the tail out whatever this says.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub idle_tail_weight: f64,
    /// The action loss's weight factor at the gripper's switches (each step whose gripper
    /// command differs from the step before's, and its two neighbours), in [1, 100]; 1 = off.
    /// Validation weighs every step alike.
    #[serde(default = "unit", skip_serializing_if = "is_unit")]
    pub gripper_switch_weight: f64,
    /// σ in metres of Gaussian noise on the positions a state-mode model reads (eef, objects,
    /// parts), drawn per training frame; validation windows stay clean (0 = off).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub state_noise: f64,
}

fn unit() -> f64 {
    1.0
}

fn is_unit(v: &f64) -> bool {
    *v == 1.0
}

/// serde default of switches that are on unless a config turns them off.
pub(crate) fn yes() -> bool {
    true
}

/// Whether a switch is at its default, on (serde leaves it out then).
pub(crate) fn is_yes(v: &bool) -> bool {
    *v
}

/// `[data].generate`: what `sim generate --task --episodes --val --seed --size --workers --out`
/// would produce (the same files, byte for byte: generation is a function of the seed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateSpec {
    /// Task id or alias (`t1` … `t10`, `t3@12`, `libero_goal/<stem>`), or a suite (`libero_mem`,
    /// `libero_goal`, a comma list): then `episodes` of every task, one multi-task dataset.
    pub task: String,
    /// Number of episodes (train + validation).
    pub episodes: usize,
    /// Episodes held out for validation (< `episodes`).
    #[serde(default)]
    pub val: usize,
    /// Base seed of the episodes.
    #[serde(default)]
    pub seed: u64,
    /// Camera image side recorded (default 128, as `sim generate`); training windows resize the
    /// frames to the model's `image_size`, so one dataset serves every model size.
    #[serde(default = "default_camera", skip_serializing_if = "is_default_camera")]
    pub image_size: usize,
    /// Simulator worker threads (default 1: two rendering threads have crashed in Mesa's
    /// llvmpipe); the files do not depend on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub workers: Option<usize>,
    /// A deterministic expert (`sim generate --plain-expert`): no seeded variation and no
    /// action noise, one demonstration per start state.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub plain_expert: bool,
    /// Idle steps recorded after the expert's release and retreat once the goal is done
    /// (`sim generate --hold-steps`; by default the recording ends 10 steps after the goal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_steps: Option<usize>,
    /// How the expert picks an `Or` goal's branch (`sim generate --branch-rule`): `destination`
    /// (default) or `gripper` (T7/T8: the bowl nearest the hand moves first).
    #[serde(default, skip_serializing_if = "is_default_branch_rule")]
    pub branch_rule: sim::expert::BranchRule,
    /// DART execution noise (`sim generate --exec-noise`): σ of the Gaussian push on the executed
    /// translation while the expert moves with the gripper open, its clean corrections recorded;
    /// 0 (default) = none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub exec_noise: f64,
}

/// Whether a number is zero, its default (serde: numbers left out of configs and checkpoints at
/// their default; counts, steps and chances alike).
pub(crate) fn is_zero<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

fn is_default_branch_rule(r: &sim::expert::BranchRule) -> bool {
    *r == sim::expert::BranchRule::default()
}

fn default_camera() -> usize {
    128
}

fn is_default_camera(s: &usize) -> bool {
    *s == default_camera()
}

/// Model size preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// model.md §0 tiny (CPU).
    Tiny,
    /// model.md §0 full (GPU).
    Full,
}

/// `[model]`: variant name, preset and overrides of any `ModelConfig` field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    /// Variant name (`e_slotssm`, `e_slotssm_oracle`, `slotvla_h<N>`, `dense`, `dense_h<N>`).
    pub variant: String,
    /// What the policy observes: `pixels` (the agentview camera) or `state` (the simulator's
    /// object poses and grasps, one token per object; needs episodes with object poses).
    #[serde(default, skip_serializing_if = "ObsMode::is_pixels")]
    pub obs: ObsMode,
    /// State mode: scales in cm of extra object − gripper features, tanh(Δ / s) per axis and
    /// scale (none by default; see `model::io::state`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub state_relative_cm: Vec<f32>,
    /// State mode: scales in cm of the squashed offset from each object token to its nearest
    /// other object, tanh(Δ / s) per axis and scale (none by default; see `model::io::state`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub state_neighbour_cm: Vec<f32>,
    /// State mode: each object token also gets its distance to the gripper and to its nearest
    /// other object (default false; see `model::io::state`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub state_distances: bool,
    /// State mode: whether the robot token carries the finger joint positions (default true;
    /// false leaves the gripper command to be read from the scene, not copied from the fingers).
    #[serde(default = "yes", skip_serializing_if = "is_yes")]
    pub state_fingers: bool,
    /// State mode: one more token per articulated part of an object — a drawer's handle, a
    /// stove's knob: where it is taken and its joint's position (default false; needs episodes
    /// of schema 3, see `data/SCHEMA.md`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub state_parts: bool,
    /// Size preset.
    #[serde(default = "tiny")]
    pub preset: Preset,
    /// Fields of `model::ModelConfig` replacing the preset's (nested tables merge key by key).
    #[serde(default, skip_serializing_if = "toml::Table::is_empty")]
    pub overrides: toml::Table,
}

/// `[model].obs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObsMode {
    /// The agentview camera.
    #[default]
    Pixels,
    /// The object state.
    State,
}

impl ObsMode {
    /// Whether it is `pixels` (the default).
    pub fn is_pixels(&self) -> bool {
        *self == ObsMode::Pixels
    }
}

fn tiny() -> Preset {
    Preset::Tiny
}

/// `[train.loss_weights]`: λ of every loss term (default: the preset's, model.md §0).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossWeights {
    /// λ_act.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action: Option<f64>,
    /// λ_tc.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrastive: Option<f64>,
    /// λ_win.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<f64>,
    /// λ_sa (0 also removes the slot decoder from the model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slot_recon: Option<f64>,
    /// Weight of the gripper dimension within the action loss (the arm's dimensions 1; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gripper: Option<f64>,
    /// λ_ptr: the pointer head's cross-entropy to the object each demonstration step heads for
    /// (state mode with `model.overrides.decoder.pointer`; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pointer: Option<f64>,
    /// λ_prog: a head's cross-entropy to the number of subgoals done, read off each frame's
    /// visual tokens (training only: the policy never observes it; needs `/goal`; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub progress: Option<f64>,
    /// λ_done: the termination head's binary cross-entropy to whether the goal is done (read off
    /// the decoder's action queries; the evaluator holds the robot still once the head says done;
    /// needs `/goal`; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub done: Option<f64>,
}

/// `[train]`: optimisation, schedule, checkpoints, validation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainSection {
    /// Optimiser steps.
    pub steps: u64,
    /// Windows (or episode lanes) per batch.
    pub batch_size: usize,
    /// How batches are drawn: `episodes` walks whole episodes in consecutive chunks of the
    /// window length, carrying the memory (slots, SSM state, history) from chunk to chunk
    /// (truncated BPTT, model.md §10); `windows` draws independent windows, each from a cold
    /// memory (for comparison).
    pub sampling: Sampling,
    /// `episodes` sampling: each lane leaves its first episode at a seeded step, so that the
    /// lanes walk different phases of their episodes from then on (false, the default: every lane
    /// starts at step 0 together and, on demos of similar length, every batch holds the same
    /// phase). Measured better on state-mode T1 and worse on LIBERO-Goal (train/README.md).
    pub stagger: bool,
    /// `episodes` sampling: each lane enters each episode at a seeded step in
    /// `0..=start_jitter` with a cold memory, instead of at its first frame (0, the default), so
    /// that the time since the memory started does not tell where the demo is (a policy whose
    /// memory can tell the time may otherwise follow one path timed from the start instead of
    /// reading the scene). The skipped steps are not fed.
    #[serde(skip_serializing_if = "is_zero")]
    pub start_jitter: usize,
    /// `episodes` sampling: the first `prefix_lanes` lanes of each batch walk only the first
    /// `prefix_steps` steps of each episode (rounded up to whole chunks) and then take the next
    /// episode, while the other lanes walk whole episodes. A lane walking whole episodes meets
    /// an episode start once per episode (one chunk in 21–27 on T3's demos), and only there is the first
    /// move not a continuation of the moves before it; prefix lanes see episode starts
    /// `episode length / prefix_steps` times as often (0, the default: every lane walks whole
    /// episodes).
    #[serde(skip_serializing_if = "is_zero")]
    pub prefix_lanes: usize,
    /// Steps of each episode a prefix lane walks (see `prefix_lanes`; needs it).
    #[serde(skip_serializing_if = "is_zero")]
    pub prefix_steps: usize,
    /// `episodes` sampling: lanes kept walking episodes, each with its carried memory (0, the
    /// default: `batch_size`). With more, each step advances a seeded choice of `batch_size`
    /// of them by one chunk while the rest wait with their memory, so that a step's chunks come
    /// from `lane_pool` episodes at unrelated phases instead of the same `batch_size` episodes
    /// for the 20–90 steps each takes to walk (a waiting lane's memory is a few steps' weights
    /// old when it goes on, as stored states in recurrent replay).
    #[serde(skip_serializing_if = "is_zero")]
    pub lane_pool: usize,
    /// `episodes` sampling: the chance in [0, 1] that a chunk in the middle of an episode starts
    /// a cold memory, as the episode's first chunk does (0, the default: the memory is carried
    /// through whole episodes; 1: every chunk is an independent window). Seeded per chunk.
    #[serde(skip_serializing_if = "is_zero")]
    pub memory_reset: f64,
    /// Data-parallel replicas of the model (default 1): each step splits the batch into this
    /// many groups of consecutive lanes, runs each group's forward and backward on its own
    /// thread with its own copy of the weights, and sums their gradients, each replica's loss
    /// weighted by its share of the batch's action mass, before the clip and the optimiser step.
    /// Divides `batch_size`. The action loss is then the batch's; the other losses are each
    /// replica's own means, weighted alike, so another count gives slightly other numbers, the
    /// same count the same bytes.
    #[serde(skip_serializing_if = "is_one")]
    pub replicas: usize,
    /// Exponential moving average of the weights (none by default): after every optimiser step
    /// `ema ← decay · ema + (1 − decay) · weights`, from the weights after the first step. The
    /// average is the policy a checkpoint's `model.bpk` holds (what eval and validation read);
    /// the trained weights go beside it as `train_model.bpk`, so that a run resumes bit for bit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ema: Option<f64>,
    /// Peak learning rate (AdamW).
    pub lr: f64,
    /// Linear warm-up steps (from 0 to `lr`).
    pub warmup_steps: u64,
    /// Cosine decay ends at `lr · final_lr_fraction`.
    pub final_lr_fraction: f64,
    /// AdamW decoupled weight decay.
    pub weight_decay: f64,
    /// AdamW β₁.
    pub beta1: f64,
    /// AdamW β₂.
    pub beta2: f64,
    /// Global gradient-norm clip (0 = off).
    pub grad_clip: f64,
    /// Checkpoint every N steps (0 = only at the end).
    pub checkpoint_every: u64,
    /// Checkpoints kept (0 = all).
    pub keep: usize,
    /// Seed of the initialisation, sampler order and augmentation.
    pub seed: u64,
    /// Validation every N steps (0 = only at the end; skipped without a val split).
    pub val_every: u64,
    /// Batches per validation (0 = the whole val split).
    pub val_batches: usize,
    /// Validation episodes walked whole with the memory carried from their first frame, as the
    /// closed loop reads it (`RUN/val_walk.jsonl`, beside `val.jsonl`'s cold-memory windows),
    /// evenly spread over the val split (0 = none; more than the split has: all).
    pub val_walk: usize,
    /// Loss weights.
    pub loss_weights: LossWeights,
    /// Staged training (empty = one stage: every loss, nothing frozen); see [`Stage`].
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<Stage>,
}

pub use crate::stages::Stage;

fn is_one(n: &usize) -> bool {
    *n == 1
}

/// `[train].sampling`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// Consecutive chunks of whole episodes with carried memory.
    #[default]
    Episodes,
    /// Independent windows from every step, each from a cold memory.
    Windows,
}

impl Default for TrainSection {
    fn default() -> Self {
        TrainSection {
            steps: 20_000,
            batch_size: 8,
            sampling: Sampling::default(),
            stagger: false,
            start_jitter: 0,
            prefix_lanes: 0,
            prefix_steps: 0,
            lane_pool: 0,
            memory_reset: 0.0,
            replicas: 1,
            ema: None,
            lr: 3e-4,
            warmup_steps: 500,
            final_lr_fraction: 0.0,
            weight_decay: 1e-2,
            beta1: 0.9,
            beta2: 0.999,
            grad_clip: 1.0,
            checkpoint_every: 1000,
            keep: 3,
            seed: 0,
            val_every: 1000,
            val_batches: 8,
            val_walk: 16,
            loss_weights: LossWeights::default(),
            stages: Vec::new(),
        }
    }
}

pub use model::backend::BackendKind;

/// `[backend]`.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackendSection {
    /// Backend kind.
    pub kind: BackendKind,
}

/// `[eval]`: read by the eval crate (`eval --run runs/<name>`).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalSection {
    /// Task ids or aliases to roll out.
    pub tasks: Vec<String>,
    /// Episode seeds per task.
    pub seeds: Vec<u64>,
}

impl Config {
    /// Reads and checks a config file; errors name the file and the offending key.
    pub fn load(path: impl AsRef<Path>) -> Result<Config> {
        Config::load_with(path, &[])
    }

    /// Loads a config file with `KEY=VALUE` overrides applied first (`model.variant=slotvla_h1`,
    /// `train.steps=500`, `name="x"`; the value is TOML, a bare word is a string); an override of
    /// an unknown key or of a bad value is an error naming it.
    pub fn load_with(path: impl AsRef<Path>, sets: &[String]) -> Result<Config> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| TrainError::Config {
            path: path.to_path_buf(),
            message: format!("cannot read: {e}"),
        })?;
        let err = |message: String| TrainError::Config {
            path: path.to_path_buf(),
            message,
        };
        let text = if sets.is_empty() {
            text
        } else {
            let mut table: toml::Table =
                toml::from_str(&text).map_err(|e| err(describe_toml_error(&text, &e)))?;
            for s in sets {
                apply_set(&mut table, s).map_err(err)?;
            }
            toml::to_string(&table).map_err(|e| err(e.to_string()))?
        };
        let cfg = Config::parse(&text).map_err(err)?;
        let mut cfg = cfg;
        cfg.source = Some(path.to_path_buf());
        if cfg.name.is_none() {
            cfg.name = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        }
        Ok(cfg)
    }

    /// Parses config text; the error message names the key (and line) at fault.
    pub fn parse(text: &str) -> std::result::Result<Config, String> {
        let cfg: Config = toml::from_str(text).map_err(|e| describe_toml_error(text, &e))?;
        cfg.check()?;
        Ok(cfg)
    }

    /// Value checks that serde cannot express (the message names the key).
    fn check(&self) -> std::result::Result<(), String> {
        Variant::from_name(&self.model.variant).map_err(|e| format!("model.variant: {e}"))?;
        // The state-mode scales in cm: each only read in state mode, each a list of cm > 0.
        let scales = [
            ("model.state_relative_cm", &self.model.state_relative_cm),
            ("model.state_neighbour_cm", &self.model.state_neighbour_cm),
        ];
        // The state-mode keys set away from their defaults, refused outside state mode.
        let state_only = scales
            .iter()
            .map(|&(key, cm)| (key, !cm.is_empty()))
            .chain([
                ("model.state_distances", self.model.state_distances),
                ("model.state_fingers", !self.model.state_fingers),
            ]);
        for (key, set) in state_only {
            if set && self.model.obs != ObsMode::State {
                return Err(format!(
                    "{key}: only state mode (`obs = \"state\"`) reads it"
                ));
            }
        }
        let w = self.data.idle_tail_weight;
        if !(w.is_finite() && (0.0..=1.0).contains(&w)) {
            return Err(format!(
                "data.idle_tail_weight: must be a weight in [0, 1] (got {w})"
            ));
        }
        if w > 0.0 && !self.data.mask_idle_tail {
            return Err(
                "data.idle_tail_weight: weights the idle tail that `data.mask_idle_tail = true` \
                 sets apart; set that too"
                    .into(),
            );
        }
        let (lanes, steps) = (self.train.prefix_lanes, self.train.prefix_steps);
        if (lanes > 0) != (steps > 0) {
            return Err(format!(
                "train.prefix_lanes = {lanes} with train.prefix_steps = {steps}: set both (lanes \
                 walking the first prefix_steps steps of each episode) or neither"
            ));
        }
        // Options of the episode sampler, away from their defaults.
        for (key, set, what) in [
            (
                "train.start_jitter",
                self.train.start_jitter > 0,
                "jitters where lanes enter episodes",
            ),
            (
                "train.prefix_lanes",
                lanes > 0,
                "cuts the episodes that lanes walk",
            ),
            (
                "train.lane_pool",
                self.train.lane_pool > 0,
                "keeps a pool of episode lanes",
            ),
            (
                "train.memory_reset",
                self.train.memory_reset != 0.0,
                "resets the carried memory mid-episode",
            ),
        ] {
            if set && self.train.sampling != Sampling::Episodes {
                return Err(format!(
                    "{key}: {what}, which only `train.sampling = \"episodes\"` has"
                ));
            }
        }
        if lanes > self.train.batch_size {
            return Err(format!(
                "train.prefix_lanes = {lanes}: more than the batch's {} lanes",
                self.train.batch_size
            ));
        }
        let r = self.train.memory_reset;
        if !(r.is_finite() && (0.0..=1.0).contains(&r)) {
            return Err(format!(
                "train.memory_reset: must be a chance in [0, 1] (got {r})"
            ));
        }
        let pool = self.train.lane_pool;
        if pool > 0 && pool < self.train.batch_size {
            return Err(format!(
                "train.lane_pool = {pool}: fewer than the batch's {} lanes (0 or at least the \
                 batch size)",
                self.train.batch_size
            ));
        }
        let g = self.data.gripper_switch_weight;
        if !(g.is_finite() && (1.0..=100.0).contains(&g)) {
            return Err(format!(
                "data.gripper_switch_weight: must be a factor in [1, 100] (got {g})"
            ));
        }
        let sigma = self.data.state_noise;
        if !(sigma.is_finite() && (0.0..=0.1).contains(&sigma)) {
            return Err(format!(
                "data.state_noise: must be a number of metres in [0, 0.1] (got {sigma})"
            ));
        }
        if sigma > 0.0 && self.model.obs != ObsMode::State {
            return Err("data.state_noise: only state mode (`obs = \"state\"`) reads it".into());
        }
        if self.model.state_parts && self.model.obs != ObsMode::State {
            return Err("model.state_parts: only state mode (`obs = \"state\"`) reads it".into());
        }
        for (key, cm) in scales {
            if let Some(s) = model::io::state::bad_relative_scale(cm) {
                return Err(format!(
                    "{key}: scales are finite numbers of cm > 0 (got {s})"
                ));
            }
        }
        let t = &self.train;
        let bad = |k: &str, why: &str| Err(format!("train.{k}: {why}"));
        if t.steps == 0 {
            return bad("steps", "must be ≥ 1");
        }
        if t.batch_size == 0 {
            return bad("batch_size", "must be ≥ 1");
        }
        if t.replicas == 0 || !t.batch_size.is_multiple_of(t.replicas) {
            return Err(format!(
                "train.replicas: must be ≥ 1 and divide train.batch_size {} (got {})",
                t.batch_size, t.replicas
            ));
        }
        if let Some(d) = t.ema
            && !(d > 0.0 && d < 1.0)
        {
            return bad("ema", &format!("the decay must be in (0, 1) (got {d})"));
        }
        if !(t.lr > 0.0 && t.lr.is_finite()) {
            return bad("lr", "must be > 0");
        }
        if !(0.0..=1.0).contains(&t.final_lr_fraction) {
            return bad("final_lr_fraction", "must be in [0, 1]");
        }
        // Written so that NaN fails every check (`NaN >= 0.0` is false).
        let finite_nonneg = |x: f64| x >= 0.0 && x.is_finite();
        if !finite_nonneg(t.grad_clip) {
            return bad("grad_clip", "must be a finite number ≥ 0 (0 = no clipping)");
        }
        if !finite_nonneg(t.weight_decay) {
            return bad("weight_decay", "must be a finite number ≥ 0");
        }
        if !((0.0..1.0).contains(&t.beta1) && (0.0..1.0).contains(&t.beta2)) {
            return bad("beta1 / beta2", "must be in [0, 1)");
        }
        let w = &t.loss_weights;
        for (key, v) in [
            ("action", w.action),
            ("contrastive", w.contrastive),
            ("window", w.window),
            ("slot_recon", w.slot_recon),
            ("gripper", w.gripper),
            ("pointer", w.pointer),
            ("progress", w.progress),
            ("done", w.done),
        ] {
            if let Some(v) = v
                && !finite_nonneg(v)
            {
                return Err(format!(
                    "train.loss_weights.{key}: must be a finite number ≥ 0 (got {v})"
                ));
            }
        }
        if let Some(g) = &self.data.generate {
            if g.episodes == 0 || g.val >= g.episodes {
                return Err(format!(
                    "data.generate: need episodes ≥ 1 and val < episodes (got {} and {})",
                    g.episodes, g.val
                ));
            }
            if g.image_size < 8 || g.workers == Some(0) {
                return Err("data.generate: image_size must be ≥ 8 and workers ≥ 1".into());
            }
            if !(g.exec_noise.is_finite() && g.exec_noise >= 0.0) {
                return Err(format!(
                    "data.generate: exec_noise must be a number ≥ 0 (got {})",
                    g.exec_noise
                ));
            }
        }
        crate::stages::check(&t.stages)?;
        if let Some(i) = t.stages.iter().position(|s| !s.idle_tail)
            && !self.data.mask_idle_tail
        {
            return Err(format!(
                "train.stages[{i}] (`{}`).idle_tail: leaves out the idle tail that \
                 `data.mask_idle_tail = true` marks; without it there is none",
                t.stages[i].name
            ));
        }
        if self.data.window == Some(0) {
            return Err("data.window: must be ≥ 1".into());
        }
        // Resolve the model once so that bad overrides fail at load time.
        self.model_config(Vec::new())?;
        Ok(())
    }

    /// The run name (set by [`Config::load`] from the file stem when absent).
    pub fn run_name(&self) -> String {
        self.name.clone().unwrap_or_else(|| "run".into())
    }

    /// Frames per training window T.
    pub fn window_len(&self) -> usize {
        self.data.window.unwrap_or(match self.model.preset {
            Preset::Tiny => 16,
            Preset::Full => 32,
        })
    }

    /// The resolved model config: preset, then overrides, then loss weights, then `vocab`
    /// (the dataset's words, without `<pad>`/`<unk>`).
    pub fn model_config(&self, vocab: Vec<String>) -> std::result::Result<ModelConfig, String> {
        let variant =
            Variant::from_name(&self.model.variant).map_err(|e| format!("model.variant: {e}"))?;
        let preset = match self.model.preset {
            Preset::Tiny => ModelConfig::tiny(variant),
            Preset::Full => ModelConfig::full(variant),
        };
        let mut value = toml::Table::try_from(&preset).map_err(|e| e.to_string())?;
        if self.model.overrides.contains_key("variant") {
            return Err("model.overrides.variant: set `model.variant` instead".into());
        }
        if let Some(toml::Value::Table(t)) = self.model.overrides.get("text")
            && t.contains_key("vocab")
        {
            return Err(
                "model.overrides.text.vocab: the vocabulary comes from the dataset index".into(),
            );
        }
        merge(&mut value, &self.model.overrides, "model.overrides")?;
        let mut cfg: ModelConfig = value
            .try_into()
            .map_err(|e: toml::de::Error| format!("model.overrides: {}", e.message()))?;
        let w = &self.train.loss_weights;
        if let Some(v) = w.action {
            cfg.loss.action = v;
        }
        if let Some(v) = w.contrastive {
            cfg.loss.contrastive = v;
        }
        if let Some(v) = w.window {
            cfg.loss.window = v;
        }
        if let Some(v) = w.slot_recon {
            cfg.loss.slot_recon = v;
        }
        if let Some(v) = w.gripper {
            cfg.loss.gripper = v;
        }
        if let Some(v) = w.pointer {
            cfg.loss.pointer = v;
        }
        if let Some(v) = w.progress {
            cfg.loss.progress = v;
        }
        if let Some(v) = w.done {
            cfg.loss.done = v;
        }
        cfg.text.vocab = vocab;
        if cfg.loss.pointer > 0.0 && !cfg.decoder.pointer {
            return Err("train.loss_weights.pointer: needs the pointer head \
                 (model.overrides.decoder = { pointer = true })"
                .into());
        }
        cfg.validate().map_err(|e| format!("[model]: {e}"))?;
        if cfg.decoder.pointer && self.model.obs != ObsMode::State {
            return Err(
                "model.overrides.decoder.pointer: only state mode (`obs = \"state\"`) reads it"
                    .into(),
            );
        }
        Ok(cfg)
    }

    /// The config as TOML (what `runs/<name>/config.toml` holds).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("a config always serialises")
    }
}

/// Applies one `KEY=VALUE` override (dotted key, TOML value or a bare string) to `table`.
fn apply_set(table: &mut toml::Table, set: &str) -> std::result::Result<(), String> {
    let (key, value) = set
        .split_once('=')
        .ok_or_else(|| format!("--set `{set}`: expected KEY=VALUE"))?;
    let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
        Ok(mut t) => t.remove("v").expect("just parsed"),
        Err(_) => toml::Value::String(value.to_string()),
    };
    let parts: Vec<&str> = key.trim().split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(format!("--set `{set}`: empty key part"));
    }
    let mut t = table;
    for p in &parts[..parts.len() - 1] {
        t = match t
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        {
            toml::Value::Table(inner) => inner,
            _ => return Err(format!("--set `{set}`: `{p}` is not a table")),
        };
    }
    t.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

/// Deep-merges `over` into `base`; a key that `base` lacks is an error naming its path.
fn merge(base: &mut toml::Table, over: &toml::Table, at: &str) -> std::result::Result<(), String> {
    for (k, v) in over {
        let path = format!("{at}.{k}");
        match (base.get_mut(k), v) {
            (None, _) => {
                let known: Vec<&str> = base.keys().map(String::as_str).collect();
                return Err(format!(
                    "unknown key `{path}` (expected one of: {})",
                    known.join(", ")
                ));
            }
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o, &path)?,
            (Some(slot), v) => *slot = v.clone(),
        }
    }
    Ok(())
}

/// One line: `line L, column C: <message>` (the message names the unknown or bad key).
fn describe_toml_error(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().to_string();
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.len() - before.rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;
            let key = text[span.clone()].trim();
            if key.is_empty() || key.len() > 60 {
                format!("line {line}, column {col}: {msg}")
            } else {
                format!("line {line}, column {col} (`{key}`): {msg}")
            }
        }
        None => msg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = r#"
[data]
dir = "d"
[model]
variant = "e_slotssm"
"#;

    #[test]
    fn minimal_config_gets_defaults() {
        let c = Config::parse(MIN).unwrap();
        assert_eq!(c.train, TrainSection::default());
        assert_eq!(c.backend.kind, BackendKind::Flex);
        assert_eq!(c.window_len(), 16);
        let m = c.model_config(vec!["bowl".into()]).unwrap();
        assert_eq!(m, {
            let mut t = ModelConfig::tiny(Variant::from_name("e_slotssm").unwrap());
            t.text.vocab = vec!["bowl".into()];
            t
        });
        // Round trip through the resolved TOML.
        assert_eq!(Config::parse(&c.to_toml()).unwrap(), c);
        // The idle tail is trained on unless asked; a run's config says so only when it is not.
        assert!(!c.data.mask_idle_tail);
        assert!(!c.to_toml().contains("mask_idle_tail"));
        let m = Config::parse(&MIN.replace("dir = \"d\"", "dir = \"d\"\nmask_idle_tail = true"))
            .unwrap();
        assert!(m.data.mask_idle_tail);
        assert!(m.to_toml().contains("mask_idle_tail = true"));
        assert_eq!(Config::parse(&m.to_toml()).unwrap(), m);
    }

    #[test]
    fn stages_parse_round_trip_and_name_bad_keys() {
        let text = format!(
            "{MIN}[[train.stages]]\nname = \"slots\"\nsteps = 5\nlosses = [\"slot_recon\"]\nfreeze = [\"decoder\"]\n[[train.stages]]\nname = \"all\"\nlosses = [\"action\"]\n"
        );
        let c = Config::parse(&text).unwrap();
        assert_eq!(c.train.stages.len(), 2);
        assert_eq!(c.train.stages[0].freeze, ["decoder"]);
        assert_eq!(c.train.stages[1].steps, None);
        assert_eq!(Config::parse(&c.to_toml()).unwrap(), c);
        let e = Config::parse(&text.replace("freeze", "frezee")).unwrap_err();
        assert!(e.contains("frezee"), "{e}");
        // A stage without the idle tail: written only when false, refused without a tail.
        assert!(!c.to_toml().contains("idle_tail"));
        let no_tail = text.replace("freeze = [\"decoder\"]", "idle_tail = false");
        let e = Config::parse(&no_tail).unwrap_err();
        assert!(
            e.contains("train.stages[0] (`slots`).idle_tail")
                && e.contains("`data.mask_idle_tail = true`"),
            "{e}"
        );
        let c =
            Config::parse(&no_tail.replace("dir = \"d\"", "dir = \"d\"\nmask_idle_tail = true"))
                .unwrap();
        assert!(!c.train.stages[0].idle_tail && c.train.stages[1].idle_tail);
        assert!(c.to_toml().contains("idle_tail = false"));
        assert_eq!(Config::parse(&c.to_toml()).unwrap(), c);
        // A part the model lacks is checked against the built model (stages::check_freeze).
    }

    #[test]
    fn unknown_keys_are_named() {
        let e = Config::parse(&format!("{MIN}[train]\nlrr = 1.0\n")).unwrap_err();
        assert!(e.contains("lrr") && e.contains("line"), "{e}");
        let e =
            Config::parse(&format!("{MIN}[model.overrides.encoder]\nchanels = [1]\n")).unwrap_err();
        assert!(e.contains("model.overrides.encoder.chanels"), "{e}");
        let e = Config::parse(&MIN.replace("e_slotssm", "slotssm")).unwrap_err();
        assert!(e.contains("model.variant"), "{e}");
        let e = Config::parse(&format!("{MIN}[backend]\nkind = \"metal\"\n")).unwrap_err();
        assert!(e.contains("metal"), "{e}");
    }

    #[test]
    fn overrides_and_loss_weights_apply() {
        let c = Config::parse(&format!(
            "{MIN}[model.overrides]\nimage_size = [32, 32]\ndecoder = {{ layers = 1 }}\n[train.loss_weights]\nslot_recon = 0.0\ngripper = 4.0\n"
        ))
        .unwrap();
        let m = c.model_config(vec![]).unwrap();
        assert_eq!(m.image_size, [32, 32]);
        assert_eq!(m.decoder.layers, 1);
        assert_eq!(m.decoder.width, 128);
        assert_eq!(m.loss.slot_recon, 0.0);
        assert_eq!(m.loss.gripper, 4.0);
        let plain = Config::parse(MIN).unwrap().model_config(vec![]).unwrap();
        assert_eq!(plain.loss.gripper, 1.0);
        let e = Config::parse(&format!("{MIN}[train.loss_weights]\ngripper = -1.0\n")).unwrap_err();
        assert_eq!(
            e,
            "train.loss_weights.gripper: must be a finite number ≥ 0 (got -1)"
        );
        let e =
            Config::parse(&format!("{MIN}[model.overrides]\nimage_size = \"big\"\n")).unwrap_err();
        assert!(e.contains("model.overrides"), "{e}");
    }

    #[test]
    fn bad_numbers_are_named() {
        let e = |extra: &str| Config::parse(&format!("{MIN}{extra}")).unwrap_err();
        assert_eq!(
            e("[train]\ngrad_clip = nan\n"),
            "train.grad_clip: must be a finite number ≥ 0 (0 = no clipping)"
        );
        assert_eq!(
            e("[train]\nweight_decay = nan\n"),
            "train.weight_decay: must be a finite number ≥ 0"
        );
        assert_eq!(e("[train]\nlr = inf\n"), "train.lr: must be > 0");
        assert_eq!(
            e("[train]\nbeta2 = 1.0\n"),
            "train.beta1 / beta2: must be in [0, 1)"
        );
        assert_eq!(
            e("[train.loss_weights]\nwindow = nan\n"),
            "train.loss_weights.window: must be a finite number ≥ 0 (got NaN)"
        );
        assert_eq!(e("[train]\nsteps = 0\n"), "train.steps: must be ≥ 1");
        assert_eq!(
            e("[model.overrides]\nimage_size = [0, 0]\n"),
            "[model]: invalid model config: image_size [0, 0]: each side must be ≥ 8 pixels"
        );
        assert_eq!(
            e("[model.overrides]\nwindow = { past = 100000 }\n"),
            "[model]: invalid model config: window.past = 100000 is above the limit 1024"
        );
        let with_noise = |noise: &str| {
            format!(
                "[data]\ndir = \"d\"\ngenerate = {{ task = \"t1\", episodes = 2, val = 1, exec_noise = {noise} }}\n[model]\nvariant = \"e_slotssm\"\n"
            )
        };
        assert_eq!(
            Config::parse(&with_noise("-0.1")).unwrap_err(),
            "data.generate: exec_noise must be a number ≥ 0 (got -0.1)"
        );
        let c = Config::parse(&with_noise("0.2")).unwrap();
        assert_eq!(c.data.generate.as_ref().unwrap().exec_noise, 0.2);
        // Without noise the key is left out, so configs written before it read back the same.
        let plain = Config::parse(&with_noise("0.0")).unwrap();
        let text = toml::to_string(&plain).unwrap();
        assert!(!text.contains("exec_noise"), "{text}");
        assert_eq!(Config::parse(&text).unwrap(), plain);
    }

    #[test]
    fn set_overrides_apply_and_name_bad_keys() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(&p, MIN).unwrap();
        let sets = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let c = Config::load_with(
            &p,
            &sets(&[
                "model.variant=slotvla_h1",
                "train.steps=7",
                "name=x",
                "model.obs=state",
            ]),
        )
        .unwrap();
        assert_eq!(c.model.variant, "slotvla_h1");
        assert_eq!(c.train.steps, 7);
        assert_eq!(c.run_name(), "x");
        assert_eq!(c.model.obs, ObsMode::State);
        let c = Config::load_with(
            &p,
            &sets(&["model.obs=state", "model.state_relative_cm=[2, 8.5]"]),
        )
        .unwrap();
        assert_eq!(c.model.state_relative_cm, [2.0, 8.5]);
        let c = Config::load_with(
            &p,
            &sets(&["model.obs=state", "model.state_neighbour_cm=[3, 10]"]),
        )
        .unwrap();
        assert_eq!(c.model.state_neighbour_cm, [3.0, 10.0]);
        assert!(c.to_toml().contains("state_neighbour_cm"));
        let c = Config::load_with(&p, &sets(&["model.obs=state", "model.state_fingers=false"]))
            .unwrap();
        assert!(!c.model.state_fingers);
        assert!(c.to_toml().contains("state_fingers = false"));
        let e = Config::load_with(&p, &sets(&["model.state_fingers=false"])).unwrap_err();
        assert!(
            e.to_string()
                .contains("model.state_fingers: only state mode"),
            "{e}"
        );
        // The two state-mode switches that default to off: written only when on, refused
        // outside state mode.
        let on = |c: &Config| (c.model.state_parts, c.model.state_distances);
        for (key, want) in [
            ("model.state_parts", (true, false)),
            ("model.state_distances", (false, true)),
        ] {
            let short = key.trim_start_matches("model.");
            let c =
                Config::load_with(&p, &sets(&["model.obs=state", &format!("{key}=true")])).unwrap();
            assert_eq!(on(&c), want, "{key}");
            assert!(c.to_toml().contains(&format!("{short} = true")), "{key}");
            let c = Config::load_with(&p, &sets(&["model.obs=state"])).unwrap();
            assert_eq!(on(&c), (false, false));
            assert!(!c.to_toml().contains(short), "{key}");
            let e = Config::load_with(&p, &sets(&[&format!("{key}=true")])).unwrap_err();
            assert!(
                e.to_string().contains(&format!("{key}: only state mode")),
                "{e}"
            );
        }
        // The pointer head (a decoder override): state mode with step queries only.
        let ptr = "model.overrides.decoder.pointer=true";
        let step = "model.overrides.decoder.queries=\"step\"";
        let c = Config::load_with(&p, &sets(&["model.obs=state", step, ptr])).unwrap();
        assert!(c.to_toml().contains("pointer = true"));
        let e = Config::load_with(&p, &sets(&[step, ptr])).unwrap_err();
        assert!(
            e.to_string()
                .contains("model.overrides.decoder.pointer: only state mode"),
            "{e}"
        );
        let e = Config::load_with(&p, &sets(&["model.obs=state", ptr])).unwrap_err();
        assert!(
            e.to_string()
                .contains("decoder.pointer needs a continuous head"),
            "{e}"
        );
        // Its loss weight: with the head only, and a finite number ≥ 0.
        let lw = "train.loss_weights.pointer=0.5";
        let c = Config::load_with(&p, &sets(&["model.obs=state", step, ptr, lw])).unwrap();
        assert!(c.to_toml().contains("pointer = 0.5"));
        let e = Config::load_with(&p, &sets(&["model.obs=state", step, lw])).unwrap_err();
        assert!(
            e.to_string()
                .contains("train.loss_weights.pointer: needs the pointer head"),
            "{e}"
        );
        // The progress loss: any variant and observation, written only when set, a finite
        // number ≥ 0, and it reaches the model config (which then builds the head).
        let c = Config::load_with(&p, &sets(&["train.loss_weights.progress=0.5"])).unwrap();
        assert!(c.to_toml().contains("progress = 0.5"));
        let m = c.model_config(vec!["bowl".into()]).unwrap();
        assert_eq!(m.loss.progress, 0.5);
        let c = Config::load_with(&p, &sets(&[])).unwrap();
        assert!(!c.to_toml().contains("progress"));
        assert_eq!(
            c.model_config(vec!["bowl".into()]).unwrap().loss.progress,
            0.0
        );
        let e = Config::load_with(&p, &sets(&["train.loss_weights.progress=-1"])).unwrap_err();
        assert!(
            e.to_string()
                .contains("train.loss_weights.progress: must be a finite number ≥ 0"),
            "{e}"
        );
        let bad = "train.loss_weights.pointer=-1";
        let e = Config::load_with(&p, &sets(&["model.obs=state", step, ptr, bad])).unwrap_err();
        assert!(
            e.to_string()
                .contains("train.loss_weights.pointer: must be a finite number ≥ 0"),
            "{e}"
        );
        let c =
            Config::load_with(&p, &sets(&["model.obs=state", "data.state_noise=0.005"])).unwrap();
        assert_eq!(c.data.state_noise, 0.005);
        assert!(c.to_toml().contains("state_noise = 0.005"));
        assert!(
            !Config::load_with(&p, &sets(&["model.obs=state"]))
                .unwrap()
                .to_toml()
                .contains("state_noise")
        );
        let e = Config::load_with(&p, &sets(&["data.state_noise=0.005"])).unwrap_err();
        assert!(
            e.to_string().contains("data.state_noise: only state mode"),
            "{e}"
        );
        for bad in ["-0.01", "0.5", "nan"] {
            let e = Config::load_with(
                &p,
                &sets(&["model.obs=state", &format!("data.state_noise={bad}")]),
            )
            .unwrap_err();
            assert!(
                e.to_string()
                    .contains("data.state_noise: must be a number of metres in [0, 0.1]"),
                "{bad}: {e}"
            );
        }
        let c = Config::load_with(
            &p,
            &sets(&["data.mask_idle_tail=true", "data.idle_tail_weight=0.1"]),
        )
        .unwrap();
        assert_eq!(c.data.idle_tail_weight, 0.1);
        assert!(c.to_toml().contains("idle_tail_weight = 0.1"));
        let c = Config::load_with(&p, &sets(&["data.mask_idle_tail=true"])).unwrap();
        assert!(!c.to_toml().contains("idle_tail_weight"));
        let e = Config::load_with(&p, &sets(&["data.idle_tail_weight=0.1"])).unwrap_err();
        assert!(
            e.to_string().contains("data.idle_tail_weight")
                && e.to_string().contains("`data.mask_idle_tail = true`")
                && e.to_string().contains(&p.display().to_string()),
            "{e}"
        );
        for bad in ["-0.1", "1.5", "nan"] {
            let e = Config::load_with(
                &p,
                &sets(&[
                    "data.mask_idle_tail=true",
                    &format!("data.idle_tail_weight={bad}"),
                ]),
            )
            .unwrap_err();
            assert!(
                e.to_string()
                    .contains("data.idle_tail_weight: must be a weight in [0, 1]"),
                "{bad}: {e}"
            );
        }
        let c = Config::load_with(&p, &sets(&["train.start_jitter=30"])).unwrap();
        assert_eq!(c.train.start_jitter, 30);
        assert!(c.to_toml().contains("start_jitter = 30"));
        assert!(
            !Config::load_with(&p, &sets(&[]))
                .unwrap()
                .to_toml()
                .contains("start_jitter")
        );
        let e = Config::load_with(
            &p,
            &sets(&["train.start_jitter=30", "train.sampling=\"windows\""]),
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("train.start_jitter: jitters where lanes enter episodes")
                && e.to_string().contains(&p.display().to_string()),
            "{e}"
        );
        let c = Config::load_with(
            &p,
            &sets(&["train.prefix_lanes=4", "train.prefix_steps=40"]),
        )
        .unwrap();
        assert_eq!((c.train.prefix_lanes, c.train.prefix_steps), (4, 40));
        let toml = c.to_toml();
        assert!(toml.contains("prefix_lanes = 4") && toml.contains("prefix_steps = 40"));
        assert!(
            !Config::load_with(&p, &sets(&[]))
                .unwrap()
                .to_toml()
                .contains("prefix_")
        );
        for (bad, want) in [
            (vec!["train.prefix_lanes=4"], "set both"),
            (vec!["train.prefix_steps=40"], "set both"),
            (
                vec!["train.prefix_lanes=9", "train.prefix_steps=40"],
                "train.prefix_lanes = 9: more than the batch's 8 lanes",
            ),
            (
                vec![
                    "train.prefix_lanes=4",
                    "train.prefix_steps=40",
                    "train.sampling=\"windows\"",
                ],
                "train.prefix_lanes: cuts the episodes that lanes walk",
            ),
        ] {
            let e = Config::load_with(&p, &sets(&bad)).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.contains(&p.display().to_string()),
                "{bad:?}: {e}"
            );
        }
        // The sampler options: kept in the saved config when set, left out at their default,
        // and refused with the file and key named when out of range or without episode lanes.
        let c = Config::load_with(&p, &sets(&["train.memory_reset=0.5", "train.lane_pool=64"]))
            .unwrap();
        assert_eq!((c.train.memory_reset, c.train.lane_pool), (0.5, 64));
        let toml = c.to_toml();
        assert!(toml.contains("memory_reset = 0.5") && toml.contains("lane_pool = 64"));
        let toml = Config::load_with(&p, &sets(&[])).unwrap().to_toml();
        assert!(!toml.contains("memory_reset") && !toml.contains("lane_pool"));
        for (bad, want) in [
            (
                vec!["train.memory_reset=1.5"],
                "train.memory_reset: must be a chance in [0, 1] (got 1.5)",
            ),
            (
                vec!["train.memory_reset=nan"],
                "must be a chance in [0, 1] (got NaN)",
            ),
            (
                vec!["train.memory_reset=0.5", "train.sampling=\"windows\""],
                "train.memory_reset: resets the carried memory mid-episode, which only",
            ),
            (
                vec!["train.lane_pool=4"],
                "train.lane_pool = 4: fewer than the batch's 8 lanes",
            ),
            (
                vec!["train.lane_pool=64", "train.sampling=\"windows\""],
                "train.lane_pool: keeps a pool of episode lanes, which only",
            ),
        ] {
            let e = Config::load_with(&p, &sets(&bad)).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.contains(&p.display().to_string()),
                "{bad:?}: {e}"
            );
        }
        let c = Config::load_with(&p, &sets(&["data.gripper_switch_weight=4"])).unwrap();
        assert_eq!(c.data.gripper_switch_weight, 4.0);
        assert!(c.to_toml().contains("gripper_switch_weight = 4.0"));
        let c = Config::load_with(&p, &sets(&[])).unwrap();
        assert_eq!(c.data.gripper_switch_weight, 1.0);
        assert!(!c.to_toml().contains("gripper_switch_weight"));
        for bad in ["0.5", "101", "nan"] {
            let e = Config::load_with(&p, &sets(&[&format!("data.gripper_switch_weight={bad}")]))
                .unwrap_err();
            assert!(
                e.to_string()
                    .contains("data.gripper_switch_weight: must be a factor in [1, 100]"),
                "{bad}: {e}"
            );
        }
        // The two state-mode scale lists go through one check each way.
        for (key, bad, got) in [
            ("model.state_relative_cm", "[0]", "0"),
            ("model.state_neighbour_cm", "[3, -1]", "-1"),
        ] {
            let e = Config::load_with(&p, &sets(&[&format!("{key}=[3]")])).unwrap_err();
            assert!(
                e.to_string().contains(&format!("{key}: only state mode")),
                "{e}"
            );
            let e = Config::load_with(&p, &sets(&["model.obs=state", &format!("{key}={bad}")]))
                .unwrap_err();
            assert!(
                e.to_string().contains(&format!(
                    "{key}: scales are finite numbers of cm > 0 (got {got})"
                )),
                "{e}"
            );
        }
        let e = Config::load_with(&p, &sets(&["train.stepz=7"])).unwrap_err();
        assert!(e.to_string().contains("stepz"), "{e}");
        let e = Config::load_with(&p, &sets(&["train.steps"])).unwrap_err();
        assert!(e.to_string().contains("KEY=VALUE"), "{e}");
        let e = Config::load_with(&p, &sets(&["model.variant.x=1"])).unwrap_err();
        assert!(e.to_string().contains("not a table"), "{e}");
    }
}

#[cfg(test)]
mod fuzz {
    use super::*;
    use proptest::prelude::*;

    const SEEDS: [&str; 3] = [
        include_str!("../../configs/state/t1.toml"),
        include_str!("../../configs/t3.toml"),
        include_str!("../../configs/libero_goal.toml"),
    ];

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]
        /// Fuzzing the config loader: shipped configs with characters replaced, lines cut or
        /// duplicated, and numbers swapped for extreme ones, load or give an error message, never
        /// a panic.
        #[test]
        fn damaged_configs_load_or_say_why(
            seed in 0usize..3,
            edits in proptest::collection::vec((any::<usize>(), 0u8..4, 0usize..12), 1..5),
        ) {
            let mut text = SEEDS[seed].to_string();
            const BITS: [&str; 12] = ["=", "[", "]", "\"", "\n", "0", "-1", "nan", "inf", "1e308", "18446744073709551615", "{"];
            for (at, kind, v) in edits {
                let mut i = at % text.len().max(1);
                while !text.is_char_boundary(i) { i -= 1; }
                match kind {
                    0 => text.insert_str(i, BITS[v]),
                    1 => text.truncate(i),
                    2 => { let j = text[i..].find('\n').map_or(text.len(), |j| i + j); text.replace_range(i..j, BITS[v]) }
                    _ => { let line = text[i..].lines().next().unwrap_or("").to_string(); text.insert_str(i, &line) }
                }
            }
            match Config::parse(&text) {
                Ok(c) => { c.model_config(vec![]).map_err(TestCaseError::fail)?; }
                Err(e) => prop_assert!(!e.is_empty()),
            }
        }
    }
}

#[cfg(test)]
mod shipped {
    use super::*;

    /// Every config in `configs/` loads, resolves its model and names its run after the file.
    #[test]
    fn shipped_configs_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
        let mut names = vec![];
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                let c = Config::load(&p).unwrap_or_else(|e| panic!("{e}"));
                let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
                assert_eq!(c.run_name(), stem);
                c.model_config(vec![]).unwrap();
                names.push(stem);
            }
        }
        names.sort();
        let mut want: Vec<String> = (1..=10).map(|i| format!("t{i}")).collect();
        want.extend(["tiny", "libero_goal", "slotvla_h1", "slotvla_h8", "dense"].map(String::from));
        want.sort();
        assert_eq!(names, want);
        // State-mode configs are named `state_<file>` and read the object state.
        let mut states = vec![];
        for e in std::fs::read_dir(dir.join("state")).unwrap() {
            let p = e.unwrap().path();
            let c = Config::load(&p).unwrap_or_else(|e| panic!("{e}"));
            let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
            assert_eq!(c.run_name(), format!("state_{stem}"));
            assert_eq!(c.model.obs, ObsMode::State, "{}", p.display());
            c.model_config(vec![]).unwrap();
            states.push(stem);
        }
        states.sort();
        assert_eq!(
            states,
            [
                "libero_goal",
                "libero_mem",
                "libero_mem_dagger1",
                "t1",
                "t10",
                "t2",
                "t3",
                "t4",
                "t5",
                "t6",
                "t7",
                "t8",
                "t9",
                "tiny"
            ]
        );
    }
}
