//! The data side of a run: make sure the dataset exists (generating it when the config asks and
//! the `generate` feature is on), open the train/val windows, draw batches in a seeded order and
//! turn them into the model's [`model::WindowBatch`] through the policy's one input path,
//! [`model::Processor::batch`].

#[cfg(feature = "generate")]
use std::path::Path;

use burn::prelude::*;
use data::{DatasetIndex, OpenedDataset, Split, WindowConfig, WindowDataset};
#[cfg(feature = "generate")]
use indicatif::{ProgressBar, ProgressStyle};
use model::Processor;
use model::io::state::{StateSpec, StateStats};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[cfg(feature = "generate")]
use crate::config::GenerateSpec;
use crate::config::{Config, is_zero};
use crate::error::{Result, TrainError};

/// Makes sure `[data].dir` holds a dataset: present → nothing to do; missing with
/// `[data].generate` → [`generate_dataset`] (with a progress bar when `progress`); missing
/// without → [`TrainError::DatasetMissing`].
pub fn ensure_dataset(cfg: &Config, progress: bool) -> Result<()> {
    let dir = &cfg.data.dir;
    if dir.join(data::index::INDEX_FILE).is_file() {
        return Ok(());
    }
    match &cfg.data.generate {
        #[cfg(feature = "generate")]
        Some(spec) => generate_dataset(spec, dir, progress).map(|_| ()),
        #[cfg(not(feature = "generate"))]
        Some(_) => {
            let _ = progress;
            Err(TrainError::DatasetMissing {
                dir: dir.clone(),
                hint: "`[data].generate` needs the simulator, and this trainer was built without \
                       it (cargo feature `train/generate`); record the episodes with \
                       `sim generate --task T --out DIR` first"
                    .into(),
            })
        }
        None => Err(TrainError::DatasetMissing {
            dir: dir.clone(),
            hint: "no index.json there and `[data].generate` is not set; record episodes with \
                   `sim generate --task T --out DIR` (it writes the index)"
                .into(),
        }),
    }
}

/// Generates `spec` into `dir` with the simulator's scripted expert (`sim::generate`): the same
/// files as `sim generate` with the same arguments; resumable (finished episodes are kept, so an
/// interrupted generation continues where it stopped); writes the dataset index last.
#[cfg(feature = "generate")]
pub fn generate_dataset(spec: &GenerateSpec, dir: &Path, progress: bool) -> Result<DatasetIndex> {
    let bad = |message: String| TrainError::Usage(format!("data.generate: {message}"));
    let tasks = sim::pack::resolve_suites(&spec.task, None).map_err(|e| bad(e.to_string()))?;
    if tasks.is_empty() {
        return Err(bad(format!("task `{}` names no task", spec.task)));
    }
    let name = spec.task.clone();
    // One simulator thread unless asked: with two, Mesa's llvmpipe has crashed (SIGSEGV in
    // mjr_readPixels) in about one of five 30-episode runs here; a rerun resumes.
    let workers = spec.workers.unwrap_or(1);
    let gen_cfg = sim::generate::GenerateConfig {
        episodes: spec.episodes,
        val: spec.val,
        seed: spec.seed,
        workers,
        image_size: spec.image_size,
        expert: sim::expert::ExpertConfig {
            branch_rule: spec.branch_rule,
            exec_noise: spec.exec_noise,
            ..sim::generate::expert_config(spec.plain_expert, spec.hold_steps)
        },
        ..Default::default()
    };
    let bar = if progress {
        let b = ProgressBar::new((spec.episodes * tasks.len()) as u64);
        b.set_style(
            ProgressStyle::with_template(
                "generating {prefix} {bar:30} {pos}/{len} episodes  {msg}  ETA {eta}",
            )
            .expect("valid template"),
        );
        b.set_prefix(name.clone());
        b
    } else {
        ProgressBar::hidden()
    };
    let started = std::time::Instant::now();
    let on_progress = |i: usize, p: sim::generate::GenerateProgress| {
        bar.set_position((i * spec.episodes + p.done) as u64);
        bar.set_message(format!(
            "{}: {} ok, {} failed attempts",
            tasks[i].id, p.successes, p.failures
        ));
    };
    let generated = if tasks.len() == 1 {
        sim::generate::generate(&tasks[0], dir, &gen_cfg, &|p| on_progress(0, p))
    } else {
        sim::generate::generate_suite(&tasks, dir, &gen_cfg, &on_progress)
    };
    let index = generated.map_err(|e| match e {
        sim::generate::GenerateError::Argument(m) => bad(m),
        sim::generate::GenerateError::Data(d) => TrainError::Data(d),
        e if e.is_bad_input() => bad(e.to_string()),
        other => TrainError::Other(format!("generating {}: {other}", dir.display())),
    })?;
    bar.finish_and_clear();
    if progress {
        let steps: usize = index.episodes.iter().map(|e| e.length).sum();
        eprintln!(
            "generated {}: {} episodes ({steps} steps, {}² frames) in {} in {:.1} s",
            name,
            index.episodes.len(),
            spec.image_size,
            dir.display(),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(index)
}

/// Leaves a window's idle tail out of its action loss: the weight of every action that is not
/// a real step ([`data::WindowSample::action_mask`] false: the idle tail, or past the end, already
/// 0) becomes 0.
fn drop_idle_tail(s: &mut data::WindowSample) {
    for (w, &real) in s.action_weights.iter_mut().zip(&s.action_mask) {
        if !real {
            *w = 0.0;
        }
    }
}

/// Train and validation windows of a dataset, with the batcher.
pub struct RunData {
    /// The dataset index.
    pub index: DatasetIndex,
    /// Training windows.
    pub train: WindowDataset,
    /// Validation windows (None when the split is empty).
    pub val: Option<WindowDataset>,
    /// The policy's input path: samples → model tensors.
    pub processor: Processor,
}

impl RunData {
    /// Opens `[data].dir` for a model of `model` (image size, text length; in state mode the
    /// object-state spec it was built for, see [`state_spec`]).
    ///
    /// `data` is `[data].dir` with every episode opened ([`data::OpenedDataset`]).
    pub fn open(
        cfg: &Config,
        model: &model::ModelConfig,
        state: Option<StateSpec>,
        data: &OpenedDataset,
    ) -> Result<Self> {
        let index = data.index.clone();
        let [h, w] = model.image_size;
        if h != w {
            return Err(TrainError::Usage(format!(
                "model image_size {:?}: the dataset produces square frames",
                model.image_size
            )));
        }
        let win = WindowConfig {
            past: cfg.window_len() - 1,
            future: 0,
            chunk: model.decoder.horizon,
            image_size: h as u32,
            wrist: false,
            images: !model.observation.is_state(),
            augment: cfg.data.augment.then(data::Augment::default),
            seed: cfg.train.seed,
            mask_idle_tail: cfg.data.mask_idle_tail,
            idle_tail_weight: cfg.data.idle_tail_weight as f32,
            switch_weight: cfg.data.gripper_switch_weight as f32,
            state_noise: cfg.data.state_noise as f32,
            pointer_targets: model.loss.pointer > 0.0,
        };
        let train = WindowDataset::from_opened(data, Split::Train, win.clone())?;
        if train.is_empty() {
            return Err(TrainError::Usage(format!(
                "dataset {}: the train split is empty",
                cfg.data.dir.display()
            )));
        }
        let val_win = WindowConfig {
            augment: None,
            idle_tail_weight: 0.0,
            switch_weight: 1.0,
            state_noise: 0.0,
            ..win
        };
        let val = if index.split(Split::Val).is_empty() {
            None
        } else {
            Some(WindowDataset::from_opened(data, Split::Val, val_win)?)
        };
        let processor = match state {
            None => Processor::new(model, train.action_norm().clone()),
            Some(spec) => Processor::with_state(model, train.action_norm().clone(), spec)?,
        };
        Ok(RunData {
            index,
            train,
            val,
            processor,
        })
    }

    /// The dataset's words in the model's id order (`<pad>` and `<unk>` are implicit there).
    pub fn model_vocab(index: &DatasetIndex) -> Result<Vec<String>> {
        let v = &index.vocab;
        if v.len() < 2 || v[0] != "<pad>" || v[1] != "<unk>" {
            return Err(TrainError::Other(
                "index.json vocab must start with <pad>, <unk>".into(),
            ));
        }
        Ok(v[2..].to_vec())
    }

    /// Samples `indices` of `ds` (augmentation seeded with `epoch`) as a model batch on `device`.
    pub fn batch(
        &self,
        ds: &WindowDataset,
        indices: &[(usize, u64)],
        device: &Device,
    ) -> Result<model::WindowBatch> {
        self.batch_with(ds, indices, true, device)
    }

    /// [`Self::batch`], the idle tails weighted (`idle_tail`) or left out of the action loss.
    pub fn batch_with(
        &self,
        ds: &WindowDataset,
        indices: &[(usize, u64)],
        idle_tail: bool,
        device: &Device,
    ) -> Result<model::WindowBatch> {
        use rayon::prelude::*;
        let mut samples = indices
            .par_iter()
            .map(|&(i, epoch)| ds.get_with_epoch(i, epoch))
            .collect::<data::Result<Vec<_>>>()?;
        if !idle_tail {
            samples.iter_mut().for_each(drop_idle_tail);
        }
        Ok(self.processor.batch(&samples, device)?)
    }

    /// The training chunks `spans` as a model batch on `device`, with the lanes that start an
    /// episode (`[B]`, true = fresh).
    pub fn chunk_batch(
        &self,
        spans: &[ChunkSpan],
        device: &Device,
    ) -> Result<(model::WindowBatch, Tensor<1, Bool>)> {
        self.chunk_batch_with(spans, true, device)
    }

    /// [`Self::chunk_batch`], the idle tails weighted (`idle_tail`) or left out of the action
    /// loss.
    pub fn chunk_batch_with(
        &self,
        spans: &[ChunkSpan],
        idle_tail: bool,
        device: &Device,
    ) -> Result<(model::WindowBatch, Tensor<1, Bool>)> {
        self.chunk_batch_of(&self.train, spans, idle_tail, device)
    }

    /// [`Self::chunk_batch_with`] over the episodes of `ds` (the training or validation split).
    pub fn chunk_batch_of(
        &self,
        ds: &WindowDataset,
        spans: &[ChunkSpan],
        idle_tail: bool,
        device: &Device,
    ) -> Result<(model::WindowBatch, Tensor<1, Bool>)> {
        use rayon::prelude::*;
        let mut samples = spans
            .par_iter()
            .map(|s| ds.chunk(s.episode, s.start, s.epoch))
            .collect::<data::Result<Vec<_>>>()?;
        if !idle_tail {
            samples.iter_mut().for_each(drop_idle_tail);
        }
        let fresh: Vec<bool> = spans.iter().map(|s| s.fresh).collect();
        let fresh = Tensor::from_data(TensorData::new(fresh, [spans.len()]), device);
        Ok((self.processor.batch(&samples, device)?, fresh))
    }
}

/// Seeded sampling order: sample positions form one endless stream of epochs, each a fresh
/// ChaCha8 permutation seeded by (seed, epoch). The state is one counter, so a resumed run
/// draws exactly the batches the uninterrupted run would have drawn.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Sampler {
    /// Seed of the permutations.
    pub seed: u64,
    /// Samples per epoch.
    pub len: usize,
    /// Samples drawn so far.
    pub drawn: u64,
    #[serde(skip)]
    cache: Option<(u64, Vec<usize>)>,
}

impl Sampler {
    /// A sampler over `len` samples.
    pub fn new(seed: u64, len: usize) -> Self {
        Sampler {
            seed,
            len,
            drawn: 0,
            cache: None,
        }
    }

    /// Current epoch.
    pub fn epoch(&self) -> u64 {
        self.drawn / self.len as u64
    }

    fn permutation(&mut self, epoch: u64) -> &[usize] {
        if self.cache.as_ref().map(|c| c.0) != Some(epoch) {
            let mut p: Vec<usize> = (0..self.len).collect();
            let seed = self.seed ^ epoch.wrapping_mul(0x9e37_79b9_7f4a_7c15);
            p.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
            self.cache = Some((epoch, p));
        }
        &self.cache.as_ref().expect("just filled").1
    }

    /// The next `n` (sample index, epoch) pairs.
    pub fn next_batch(&mut self, n: usize) -> Vec<(usize, u64)> {
        (0..n)
            .map(|_| {
                let epoch = self.epoch();
                let pos = (self.drawn % self.len as u64) as usize;
                let i = self.permutation(epoch)[pos];
                self.drawn += 1;
                (i, epoch)
            })
            .collect()
    }
}

/// One lane of the episode sampler: the episode it walks and where its next chunk starts.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Lane {
    /// Position of the episode in the training split.
    pub episode: usize,
    /// Epoch of the episode draw (seeds its augmentation).
    pub epoch: u64,
    /// First step of the lane's next chunk.
    pub start: usize,
    /// Step at which the lane leaves this episode before its end (with `stagger`, the first
    /// episode of each lane; with [`EpisodeSampler::prefix_lanes`], every episode of a prefix
    /// lane); None walks it to its end. Absent in checkpoints written before lanes were
    /// staggered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop: Option<usize>,
    /// Step at which the lane entered this episode (0 unless the sampler jitters starts: see
    /// [`EpisodeSampler::start_jitter`]); the chunk starting there starts a cold memory.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub first: usize,
}

/// One chunk of a batch: which episode, from which step, and whether the lane starts the
/// episode there (its carried memory is then not used).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkSpan {
    /// Position of the episode in the training split.
    pub episode: usize,
    /// First step.
    pub start: usize,
    /// Epoch of the episode draw.
    pub epoch: u64,
    /// The chunk starts the episode.
    pub fresh: bool,
    /// The lane that walks it (its row in the carried memory; with a lane pool, a row of the
    /// pool's memory, else the chunk's position in the batch).
    pub lane: usize,
}

/// Episode-long training (truncated BPTT, model.md §10): B lanes each walk one episode in
/// consecutive chunks from its first frame, and take the next episode of a seeded per-epoch
/// order when theirs ends. The state (episode order position, lanes) is part of the checkpoint,
/// so a resumed run draws exactly the chunks the uninterrupted run would have drawn.
///
/// With `stagger` (`train.stagger`), each lane leaves its *first* episode after a seeded number of steps
/// (uniform over the episode's length), so that from then on the lanes are at different phases
/// of their episodes. Without it every lane starts at step 0 together and, on demonstrations of
/// similar length, they stay in step for many episodes: every batch then holds the same phase
/// of the task (all reaches, then all grasps, …). Staggering lifted state-mode T1 (65 → 95 %
/// success) but sank the LIBERO-Goal multi-task policy (27.5 → 0 %), so it is off by default
/// (train/README.md). A shortened first episode is still walked from its first frame, so no
/// lane ever starts cold in the middle of an episode.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeSampler {
    /// Draws episodes in the order of a [`Sampler`] over the split's episodes.
    pub order: Sampler,
    /// The lanes (empty before the first batch).
    pub lanes: Vec<Lane>,
    /// Lanes leave their first episode at a seeded step (false in checkpoints written before
    /// the option existed, whose lanes were all started already).
    #[serde(default)]
    pub stagger: bool,
    /// `train.start_jitter`: a lane enters each episode at a seeded step in `0..=start_jitter`
    /// (uniform, below the episode's length) with a cold memory, instead of at its first frame
    /// (0, the default). Breaks the link between the time since the memory started and where the
    /// demo is, so that a policy whose memory can tell the time cannot follow one path timed from
    /// the start; the steps before the entry are skipped, never fed as padding.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub start_jitter: usize,
    /// `train.prefix_lanes`: lanes 0…prefix_lanes−1 leave each episode after
    /// [`EpisodeSampler::prefix_steps`] steps (0, the default: every lane walks whole episodes).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub prefix_lanes: usize,
    /// `train.prefix_steps`: the steps a prefix lane walks of each episode (rounded up to whole
    /// chunks).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub prefix_steps: usize,
    /// `train.lane_pool`: lanes kept walking their episodes (0, the default: as many as the
    /// batch has). With more lanes than the batch, each batch advances a seeded choice of
    /// `batch_size` of them by one chunk and the others wait where they are with their memory,
    /// so that one step's chunks come from `lane_pool` episodes at unrelated phases instead of
    /// the same few episodes for many steps in a row.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub pool: usize,
    /// `train.memory_reset`: the chance that a chunk in the middle of an episode starts a cold
    /// memory as if it began the episode (0, the default: never), seeded per chunk by the episode,
    /// its epoch and the chunk's first step. Between carried memory (0) and independent
    /// windows (1): the memory a lane trains with spans `len / p` steps on average.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub memory_reset: f64,
    /// Batches drawn from a lane pool so far (seeds the next choice of lanes).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub picks: u64,
}

/// Seed of lane `lane`'s first stop, from the sampler's seed.
fn stop_seed(seed: u64, lane: usize) -> u64 {
    seed ^ 0x6c61_6e65_5f73_7461 ^ (lane as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

impl EpisodeSampler {
    /// A sampler over `episodes` episodes; `stagger` as described above.
    pub fn new(seed: u64, episodes: usize, stagger: bool) -> Self {
        EpisodeSampler {
            order: Sampler::new(seed, episodes),
            lanes: Vec::new(),
            stagger,
            start_jitter: 0,
            prefix_lanes: 0,
            prefix_steps: 0,
            pool: 0,
            memory_reset: 0.0,
            picks: 0,
        }
    }

    /// The same sampler starting a cold memory at a mid-episode chunk with chance `p`
    /// ([`EpisodeSampler::memory_reset`]).
    pub fn with_memory_reset(mut self, p: f64) -> Self {
        self.memory_reset = p;
        self
    }

    /// Whether the chunk of `episode` (drawn in `epoch`) from `start` resets the memory.
    fn resets(&self, episode: usize, epoch: u64, start: usize) -> bool {
        if self.memory_reset <= 0.0 {
            return false;
        }
        let seed = self.order.seed
            ^ 0x7265_7365_745f_6d65
            ^ (episode as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ epoch.wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (start as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
        ChaCha8Rng::seed_from_u64(seed).random_bool(self.memory_reset.min(1.0))
    }

    /// The same sampler keeping `pool` lanes and advancing a seeded choice of a batch's worth of
    /// them per batch ([`EpisodeSampler::pool`]; 0 or at most the batch size: every lane, every batch).
    pub fn with_lane_pool(mut self, pool: usize) -> Self {
        self.pool = pool;
        self
    }

    /// The options that shape what this sampler draws, as `[train]` keys and values (the seed
    /// and the episode count are checked on their own): a resumed run must ask for the same.
    pub fn options(&self) -> [(&'static str, String); 6] {
        [
            ("train.stagger", self.stagger.to_string()),
            ("train.start_jitter", self.start_jitter.to_string()),
            ("train.prefix_lanes", self.prefix_lanes.to_string()),
            ("train.prefix_steps", self.prefix_steps.to_string()),
            ("train.lane_pool", self.pool.to_string()),
            ("train.memory_reset", self.memory_reset.to_string()),
        ]
    }

    /// Whether batches of `lanes` chunks are drawn from a pool of more lanes (then a chunk's
    /// [`ChunkSpan::lane`] is a row of the pool's memory, not its place in the batch).
    pub fn pooled(&self, lanes: usize) -> bool {
        self.pool > lanes
    }

    /// The lanes the next batch of `lanes` chunks advances, ascending: all of them without a
    /// pool larger than the batch, else `lanes` of the pool's, drawn without replacement by a
    /// ChaCha8 stream seeded by the sampler's seed and the batch's number.
    fn pick_lanes(&mut self, lanes: usize) -> Vec<usize> {
        if !self.pooled(lanes) {
            return (0..lanes).collect();
        }
        let seed = self.order.seed
            ^ 0x706f_6f6c_5f6c_616e
            ^ self.picks.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.picks += 1;
        let mut picked =
            rand::seq::index::sample(&mut ChaCha8Rng::seed_from_u64(seed), self.pool, lanes)
                .into_vec();
        picked.sort_unstable();
        picked
    }

    /// The same sampler with its first `lanes` lanes walking only the first `steps` steps of
    /// each episode ([`EpisodeSampler::prefix_lanes`]; the staggered first stop does not apply
    /// to them).
    pub fn with_prefix_lanes(mut self, lanes: usize, steps: usize) -> Self {
        self.prefix_lanes = lanes;
        self.prefix_steps = steps;
        self
    }

    /// Where lane `lane` leaves an episode it entered at `first`: after the prefix for a prefix
    /// lane, else `otherwise`.
    fn lane_stop(&self, lane: usize, first: usize, otherwise: Option<usize>) -> Option<usize> {
        if lane < self.prefix_lanes {
            Some(first + self.prefix_steps.max(1))
        } else {
            otherwise
        }
    }

    /// The same sampler entering episodes at a seeded step in `0..=jitter`
    /// ([`EpisodeSampler::start_jitter`]).
    pub fn with_start_jitter(mut self, jitter: usize) -> Self {
        self.start_jitter = jitter;
        self
    }

    /// Draws the next episode of the order and the step at which a lane enters it: 0, or with
    /// [`EpisodeSampler::start_jitter`] a step seeded by the draw's position in the order.
    fn draw_episode(&mut self, episode_len: &impl Fn(usize) -> usize) -> (usize, u64, usize) {
        let draw = self.order.drawn;
        let (episode, epoch) = self.order.next_batch(1)[0];
        let first = if self.start_jitter == 0 {
            0
        } else {
            let seed =
                self.order.seed ^ 0x6a69_7474_6572_5f73 ^ draw.wrapping_mul(0x9e37_79b9_7f4a_7c15);
            let last = self
                .start_jitter
                .min(episode_len(episode).saturating_sub(1));
            ChaCha8Rng::seed_from_u64(seed).random_range(0..=last)
        };
        (episode, epoch, first)
    }

    /// The next batch: `lanes` chunks of `len` steps; `episode_len(k)` gives episode k's length.
    pub fn next_batch(
        &mut self,
        lanes: usize,
        len: usize,
        episode_len: impl Fn(usize) -> usize,
    ) -> Vec<ChunkSpan> {
        let picked = self.pick_lanes(lanes);
        while self.lanes.len() < lanes.max(self.pool) {
            let (episode, epoch, first) = self.draw_episode(&episode_len);
            let stop = self.stagger.then(|| {
                ChaCha8Rng::seed_from_u64(stop_seed(self.order.seed, self.lanes.len()))
                    .random_range(1..=episode_len(episode).max(1))
            });
            let stop = self.lane_stop(self.lanes.len(), first, stop.map(|s| s.max(first + 1)));
            self.lanes.push(Lane {
                episode,
                epoch,
                start: first,
                stop,
                first,
            });
        }
        picked
            .into_iter()
            .map(|l| {
                let lane = &self.lanes[l];
                let end = episode_len(lane.episode).min(lane.stop.unwrap_or(usize::MAX));
                if lane.start >= end {
                    let (episode, epoch, first) = self.draw_episode(&episode_len);
                    self.lanes[l] = Lane {
                        episode,
                        epoch,
                        start: first,
                        stop: self.lane_stop(l, first, None),
                        first,
                    };
                }
                let lane = &self.lanes[l];
                let fresh =
                    lane.start == lane.first || self.resets(lane.episode, lane.epoch, lane.start);
                let lane = &mut self.lanes[l];
                let span = ChunkSpan {
                    episode: lane.episode,
                    start: lane.start,
                    epoch: lane.epoch,
                    fresh,
                    lane: l,
                };
                lane.start += len;
                span
            })
            .collect()
    }
}

/// The object-state spec of a dataset (state mode): the categories of every object of every
/// episode, the most objects in one scene, and the standardisation of the token features over
/// every 4th frame of the training episodes. Every episode must have been recorded with object
/// poses (episode schema 2); the first that was not is named in the error. `relative_cm`: the
/// scales of the squashed object − gripper features (`[model].state_relative_cm`); `fingers`:
/// whether the robot token carries the finger joints (`[model].state_fingers`); `parts`: whether
/// articulated parts are tokens (`[model].state_parts`; an error when no episode records any);
/// `neighbour_cm`: the scales of the offsets to each token's nearest other object
/// (`[model].state_neighbour_cm`); `distances`: whether object tokens end with their distances to
/// the gripper and to their nearest other object (`[model].state_distances`).
pub fn state_spec(
    data: &OpenedDataset,
    relative_cm: &[f32],
    neighbour_cm: &[f32],
    distances: bool,
    fingers: bool,
    parts: bool,
) -> Result<StateSpec> {
    let new_stats = || {
        let s = StateStats::new(relative_cm)
            .with_neighbours(neighbour_cm)
            .with_distances(distances);
        let s = if fingers { s } else { s.without_fingers() };
        if parts { s.with_parts() } else { s }
    };
    use rayon::prelude::*;
    let stats = data
        .episodes()
        .into_par_iter()
        .map(|(e, path, r)| -> Result<StateStats> {
            let steps = r.read_raw_steps(0..r.len())?;
            let missing = || {
                TrainError::Usage(format!(
                    "{}: `obs = \"state\"` needs object poses in /objects, and this episode was \
                     recorded without them (re-generate it with this version's `sim generate`)",
                    path.display()
                ))
            };
            let mut stats = new_stats();
            for (t, s) in steps.iter().enumerate() {
                if s.objects.is_empty() || s.objects.iter().any(|o| o.pose.is_none()) {
                    return Err(missing());
                }
                // Validation episodes give the categories and object count, not the statistics.
                if e.split == Split::Train && t % 4 == 0 || t == 0 {
                    stats
                        .add(&s.objects, &s.state)
                        .map_err(|m| TrainError::Usage(format!("{}: {m}", path.display())))?;
                }
            }
            Ok(stats)
        })
        .collect::<Vec<Result<StateStats>>>()
        // In index order, so the error names the first bad episode whatever the threads did.
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let mut all = new_stats();
    for s in &stats {
        all.merge(s);
    }
    let spec = all.finish();
    if parts && !spec.categories.iter().any(|c| c.contains('/')) {
        return Err(TrainError::Usage(format!(
            "{}: `state_parts = true` needs the articulated parts of objects in /objects (episode \
             schema 3), and no episode records any (recorded before schema 3, or no scene has a \
             drawer, knob or door: re-generate it with this version's `sim generate`, or drop \
             state_parts)",
            data.dir.display()
        )));
    }
    Ok(spec)
}

/// Checks that every episode of the dataset records its goal progress (`/goal` with a known
/// goal length), which an oracle variant and the progress and termination losses read; the first that does not (e.g. imported from
/// RLDS, which has no subgoals) is named in the error.
pub fn check_goals(data: &OpenedDataset) -> Result<()> {
    for (_, path, r) in data.episodes() {
        let has_channel = r
            .channels()
            .iter()
            .any(|c| c.topic == "/goal" && c.count > 0);
        let first = r.read_raw_steps(0..1.min(r.len()))?;
        if !has_channel || first.first().is_none_or(|s| s.progress.total == 0) {
            return Err(TrainError::Usage(format!(
                "{}: the oracle variant and train.loss_weights.progress / done read the goal progress, \
                 and this episode's /goal records none (no subgoals: recorded without a goal \
                 tracker, or imported)",
                path.display()
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads `a` back from its JSON (as a checkpoint holds it) and checks that the copy draws
    /// the same next `n` batches of `lanes` chunks of `len` steps as `a` does.
    fn assert_resumes_identically(
        a: &mut EpisodeSampler,
        n: usize,
        lanes: usize,
        len: usize,
        lens: impl Fn(usize) -> usize + Copy,
    ) {
        let mut b: EpisodeSampler =
            serde_json::from_str(&serde_json::to_string(&*a).unwrap()).unwrap();
        for _ in 0..n {
            assert_eq!(
                a.next_batch(lanes, len, lens),
                b.next_batch(lanes, len, lens)
            );
        }
    }

    #[test]
    fn sampler_visits_every_sample_once_per_epoch_and_resumes_exactly() {
        let mut s = Sampler::new(7, 10);
        let first: Vec<_> = s.next_batch(10);
        let mut seen: Vec<usize> = first.iter().map(|x| x.0).collect();
        seen.sort();
        assert_eq!(seen, (0..10).collect::<Vec<_>>());
        assert!(first.iter().all(|x| x.1 == 0));
        let mut a = Sampler::new(7, 10);
        a.next_batch(13);
        let json = serde_json::to_string(&a).unwrap();
        let mut b: Sampler = serde_json::from_str(&json).unwrap();
        assert_eq!(a.next_batch(9), b.next_batch(9));
        assert_ne!(Sampler::new(8, 10).next_batch(10), first);
    }

    #[test]
    fn episode_lanes_walk_whole_episodes_in_chunks_and_resume_exactly() {
        for stagger in [false, true] {
            lanes_walk_and_resume(stagger);
        }
    }

    fn lanes_walk_and_resume(stagger: bool) {
        let lens = [5usize, 3, 7];
        let mut s = EpisodeSampler::new(1, 3, stagger);
        let mut walked: std::collections::BTreeMap<(usize, u64), Vec<usize>> = Default::default();
        for _ in 0..12 {
            let b = s.next_batch(2, 2, |k| lens[k]);
            assert_eq!(b.len(), 2);
            for c in &b {
                assert!(c.start < lens[c.episode]);
                assert_eq!(c.fresh, c.start == 0);
                walked
                    .entry((c.episode, c.epoch))
                    .or_default()
                    .push(c.start);
            }
        }
        // Each episode pass is walked from step 0 in consecutive chunks of 2 steps.
        assert!(walked.len() >= 4);
        for ((k, _), starts) in &walked {
            assert_eq!(
                *starts,
                (0..starts.len()).map(|i| 2 * i).collect::<Vec<_>>(),
                "{k}"
            );
            assert!(starts.len() <= lens[*k].div_ceil(2));
        }
        // Resumed from its serialised state, the sampler continues identically.
        let mut a = EpisodeSampler::new(1, 3, stagger);
        for _ in 0..5 {
            a.next_batch(2, 2, |k| lens[k]);
        }
        assert_resumes_identically(&mut a, 7, 2, 2, |k| lens[k]);
    }

    #[test]
    fn jittered_lanes_enter_episodes_at_seeded_steps_and_resume_exactly() {
        let lens = |k: usize| 20 + k % 7;
        let mut s = EpisodeSampler::new(5, 50, false).with_start_jitter(6);
        let mut entries = Vec::new();
        let mut next: std::collections::HashMap<usize, usize> = Default::default();
        for _ in 0..80 {
            for (lane, c) in s.next_batch(4, 3, lens).into_iter().enumerate() {
                assert!(c.start < lens(c.episode));
                if c.fresh {
                    // A lane enters at step 0…6 and walks on from there in chunks of 3.
                    assert!(c.start <= 6, "{c:?}");
                    entries.push(c.start);
                } else {
                    assert_eq!(Some(&c.start), next.get(&lane), "{c:?}");
                }
                next.insert(lane, c.start + 3);
            }
        }
        // Every entry step turns up, the first frame among them.
        let seen: std::collections::BTreeSet<usize> = entries.iter().copied().collect();
        assert_eq!(seen, (0..=6).collect(), "{entries:?}");
        // The same seed draws the same entries; a resumed sampler continues identically.
        let mut a = EpisodeSampler::new(5, 50, false).with_start_jitter(6);
        let mut b = a.clone();
        for _ in 0..30 {
            assert_eq!(a.next_batch(4, 3, lens), b.next_batch(4, 3, lens));
        }
        assert_resumes_identically(&mut a, 30, 4, 3, lens);
        // Without jitter the draws are those of a sampler that never had the option.
        let mut plain = EpisodeSampler::new(5, 50, false);
        let mut zero = EpisodeSampler::new(5, 50, false).with_start_jitter(0);
        for _ in 0..30 {
            let b = plain.next_batch(4, 3, lens);
            assert!(b.iter().all(|c| c.fresh == (c.start == 0)));
            assert_eq!(b, zero.next_batch(4, 3, lens));
        }
        assert!(!serde_json::to_string(&zero).unwrap().contains("jitter"));
    }

    #[test]
    fn a_lane_pool_advances_a_seeded_choice_of_lanes_and_resumes_exactly() {
        let lens = |k: usize| 10 + k % 5;
        let mut s = EpisodeSampler::new(3, 40, false).with_lane_pool(12);
        // Where each pool lane's next chunk starts, and which lanes each batch took.
        let mut next: std::collections::HashMap<usize, (usize, usize)> = Default::default();
        let mut counts = [0usize; 12];
        let mut batches = std::collections::BTreeSet::new();
        for _ in 0..300 {
            let b = s.next_batch(4, 3, lens);
            let lanes: Vec<usize> = b.iter().map(|c| c.lane).collect();
            // Four distinct pool lanes, ascending.
            assert!(
                lanes.windows(2).all(|w| w[0] < w[1]) && lanes[3] < 12,
                "{lanes:?}"
            );
            batches.insert(lanes);
            for c in &b {
                counts[c.lane] += 1;
                assert!(c.start < lens(c.episode));
                assert_eq!(c.fresh, c.start == 0, "{c:?}");
                // A lane goes on from where it stopped, however many batches it waited.
                if !c.fresh {
                    assert_eq!(next.get(&c.lane), Some(&(c.episode, c.start)), "{c:?}");
                }
                next.insert(c.lane, (c.episode, c.start + 3));
            }
        }
        // Every lane takes part, about 4/12 of the time, in many different groupings.
        assert_eq!(s.lanes.len(), 12);
        assert!(
            counts.iter().all(|&n| (60..=140).contains(&n)),
            "{counts:?}"
        );
        assert!(batches.len() > 100, "{}", batches.len());
        // Seeded: the same again; resumed from its serialised state, it continues identically.
        let mut a = EpisodeSampler::new(3, 40, false).with_lane_pool(12);
        let mut b = a.clone();
        for _ in 0..20 {
            assert_eq!(a.next_batch(4, 3, lens), b.next_batch(4, 3, lens));
        }
        assert_resumes_identically(&mut a, 50, 4, 3, lens);
        assert_ne!(
            EpisodeSampler::new(4, 40, false)
                .with_lane_pool(12)
                .next_batch(4, 3, lens),
            EpisodeSampler::new(3, 40, false)
                .with_lane_pool(12)
                .next_batch(4, 3, lens)
        );
        // A pool no larger than the batch draws what a sampler without one draws.
        let mut plain = EpisodeSampler::new(3, 40, false);
        let mut same = EpisodeSampler::new(3, 40, false).with_lane_pool(4);
        for _ in 0..30 {
            let b = plain.next_batch(4, 3, lens);
            assert_eq!(b.iter().map(|c| c.lane).collect::<Vec<_>>(), [0, 1, 2, 3]);
            assert_eq!(b, same.next_batch(4, 3, lens));
        }
        assert!(!serde_json::to_string(&plain).unwrap().contains("pool"));
    }

    #[test]
    fn memory_resets_start_cold_chunks_mid_episode_at_the_seeded_rate() {
        let lens = |k: usize| 30 + k % 11;
        let mut s = EpisodeSampler::new(9, 60, false).with_memory_reset(0.25);
        let mut plain = EpisodeSampler::new(9, 60, false);
        let (mut mid, mut reset) = (0usize, 0usize);
        for _ in 0..500 {
            let (b, p) = (s.next_batch(4, 4, lens), plain.next_batch(4, 4, lens));
            // The same chunks as without resets; only `fresh` differs, and only mid-episode.
            for (c, q) in b.iter().zip(&p) {
                assert_eq!(
                    (c.episode, c.start, c.epoch, c.lane),
                    (q.episode, q.start, q.epoch, q.lane)
                );
                if c.start == 0 {
                    assert!(c.fresh);
                } else {
                    assert!(!q.fresh);
                    mid += 1;
                    reset += c.fresh as usize;
                }
            }
        }
        let rate = reset as f64 / mid as f64;
        assert!((0.22..0.28).contains(&rate), "{reset} of {mid}");
        // Seeded per chunk: a resumed sampler continues identically.
        assert_resumes_identically(&mut s, 40, 4, 4, lens);
        assert!(
            !serde_json::to_string(&plain)
                .unwrap()
                .contains("memory_reset")
        );
    }

    #[test]
    fn prefix_lanes_walk_episode_starts_and_resume_exactly() {
        let lens = |k: usize| 20 + k % 7;
        // 4 lanes in chunks of 3; lanes 0 and 1 walk the first 5 steps (two chunks) of each episode.
        let mut s = EpisodeSampler::new(5, 50, false).with_prefix_lanes(2, 5);
        let mut walked: Vec<Vec<usize>> = vec![Vec::new(); 4];
        let mut fresh = [0usize; 4];
        for _ in 0..60 {
            for (lane, c) in s.next_batch(4, 3, lens).into_iter().enumerate() {
                assert!(c.start < lens(c.episode));
                assert_eq!(c.fresh, c.start == 0, "{c:?}");
                if c.fresh {
                    fresh[lane] += 1;
                } else {
                    assert_eq!(walked[lane].last(), Some(&(c.start - 3)), "{c:?}");
                }
                walked[lane].push(c.start);
            }
        }
        // Prefix lanes only ever feed the chunks at steps 0 and 3; the others walk on to the end.
        for lane in 0..2 {
            assert!(
                walked[lane].iter().all(|&t| t == 0 || t == 3),
                "{:?}",
                walked[lane]
            );
            assert_eq!(fresh[lane], 30);
        }
        for lane in 2..4 {
            assert!(walked[lane].iter().any(|&t| t >= 18), "{:?}", walked[lane]);
            assert!(fresh[lane] <= 9, "{fresh:?}");
        }
        // The same seed draws the same chunks; a sampler read back from JSON continues identically.
        let mut a = EpisodeSampler::new(5, 50, false).with_prefix_lanes(2, 5);
        for _ in 0..13 {
            a.next_batch(4, 3, lens);
        }
        assert_resumes_identically(&mut a, 40, 4, 3, lens);
        // Without prefix lanes the draws are those of a sampler that never had the option, and
        // nothing new is written to the checkpoint.
        let mut plain = EpisodeSampler::new(5, 50, false);
        let mut zero = EpisodeSampler::new(5, 50, false).with_prefix_lanes(0, 0);
        for _ in 0..30 {
            assert_eq!(plain.next_batch(4, 3, lens), zero.next_batch(4, 3, lens));
        }
        assert!(!serde_json::to_string(&zero).unwrap().contains("prefix"));
    }

    #[test]
    fn staggered_lanes_walk_different_phases() {
        // 8 lanes over 100 episodes of equal length 40 in chunks of 4.
        let phases = |stagger: bool| {
            let mut s = EpisodeSampler::new(3, 100, stagger);
            let mut distinct = Vec::new();
            let mut first_passes = std::collections::BTreeSet::new();
            for step in 0..60 {
                let b = s.next_batch(8, 4, |_| 40);
                let starts: std::collections::BTreeSet<usize> = b.iter().map(|c| c.start).collect();
                distinct.push(starts.len());
                for c in &b {
                    if c.fresh && step > 0 {
                        first_passes.insert(c.episode);
                    }
                }
            }
            (distinct, first_passes.len())
        };
        let (aligned, _) = phases(false);
        assert!(aligned.iter().all(|&d| d == 1), "{aligned:?}");
        let (staggered, refills) = phases(true);
        // After the first (shortened) episodes the 8 lanes sit at several phases at once.
        let late = &staggered[20..];
        assert!(late.iter().all(|&d| d >= 4), "{staggered:?}");
        assert!(refills >= 8, "{refills}");
        // The stops are seeded: the same seed draws the same chunks.
        let mut a = EpisodeSampler::new(3, 100, true);
        let mut b = EpisodeSampler::new(3, 100, true);
        for _ in 0..30 {
            assert_eq!(a.next_batch(8, 4, |_| 40), b.next_batch(8, 4, |_| 40));
        }
    }
}
