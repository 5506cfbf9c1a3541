//! Windowed training samples: a sample is (episode, t) → frames t−p … t+q (edge frames repeated,
//! with a validity mask), the next H_a actions for every frame (normalised with q01/q99, gripper
//! untouched), states, instruction, subgoal texts and object annotations. Frames are resized and
//! optionally augmented (seeded colour jitter + small shift, the same for the whole window).
//! Decoding is lazy (only when a sample is asked for) and parallel (rayon); every distinct frame
//! of a window is decoded once.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use crate::episode::EpisodeReader;
use crate::error::{DataError, Result};
use crate::imageio::resize_rgb;
use crate::index::{DatasetIndex, Split, Stats};
use crate::schema::{GoalProgress, ObjectAnnotation, RgbImage};

/// Seeded photometric and geometric augmentation, applied identically to all frames of a window.
#[derive(Clone, Debug, PartialEq)]
pub struct Augment {
    /// Additive brightness delta drawn from [−b, b] (pixels in [0, 1]), as TF `random_brightness`.
    pub brightness: f32,
    /// Contrast factor drawn from [1−c, 1+c] around each channel's mean.
    pub contrast: f32,
    /// Saturation factor drawn from [1−s, 1+s] (blend with the grey image).
    pub saturation: f32,
    /// Hue rotation drawn from [−h, h] turns (0.05 = ±18°), applied as a rotation of the
    /// chroma plane in YIQ space (an approximation of HSV hue shift).
    pub hue: f32,
    /// Maximum shift in output pixels in x and y (edge pixels repeated).
    pub max_shift: u32,
}

impl Default for Augment {
    fn default() -> Self {
        Augment {
            brightness: 0.2,
            contrast: 0.2,
            saturation: 0.2,
            hue: 0.05,
            max_shift: 4,
        }
    }
}

/// Window configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowConfig {
    /// Past frames p (frames t−p … t−1).
    pub past: usize,
    /// Future frames q (frames t+1 … t+q).
    pub future: usize,
    /// Action chunk length H_a (actions f … f+H_a−1 for every frame f).
    pub chunk: usize,
    /// Output image side (frames are resized to `image_size`²).
    pub image_size: u32,
    /// Also produce eye-in-hand frames.
    pub wrist: bool,
    /// Decode agentview frames (off for state-mode training: `images` stays empty).
    pub images: bool,
    /// Augmentation (None = off).
    pub augment: Option<Augment>,
    /// Seed of the augmentation.
    pub seed: u64,
    /// Leave the episode's idle tail out of the action targets (see [`idle_tail_start`]): the
    /// arm standing still with an unchanged gripper command after its last move, which teaches a
    /// policy to freeze (OpenVLA drops LIBERO's no-op steps for the same reason). The frames stay
    /// in the windows, so carried memory still sees them.
    pub mask_idle_tail: bool,
    /// With [`WindowConfig::mask_idle_tail`], the weight of the idle tail's steps in the action
    /// loss ([`WindowSample::action_weights`]) instead of none: 0 leaves them out, a small weight
    /// shows a policy the standstill after the task without making it the frames' majority.
    pub idle_tail_weight: f32,
    /// Weight factor (≥ 1; 1 = off) of the actions at the gripper's switches: each step whose
    /// gripper command differs from the step before's, and the steps either side of it
    /// ([`gripper_switches`]). The decision to close or to open is one step of a demo, where
    /// every other step's command can be read off the one before.
    pub switch_weight: f32,
    /// σ in metres of Gaussian noise on every position a state-mode model reads: the robot's
    /// eef position and each object's and articulated part's position, drawn per frame (0 = off;
    /// see [`perturb_positions`]). A regulariser for state-mode training: the action targets stay
    /// the demonstration's.
    pub state_noise: f32,
    /// Also give each frame its pointer target ([`pointer_targets`], [`WindowSample::targets`]):
    /// the object the demonstration reaches for next or carries the held object to.
    pub pointer_targets: bool,
}

/// Largest norm of the six arm dims of an action that counts as standing still (OpenVLA's no-op
/// threshold).
pub const IDLE_ARM_NORM: f32 = 1e-4;

/// Whether `action` stands still: arm dims within [`IDLE_ARM_NORM`] and the gripper command
/// `gripper`.
fn is_idle(action: &[f32; 7], gripper: f32) -> bool {
    action[..6].iter().map(|v| v * v).sum::<f32>().sqrt() <= IDLE_ARM_NORM && action[6] == gripper
}

/// First step of the idle tail of an episode's `actions`: the steps from there to the end keep
/// the arm still (norm ≤ [`IDLE_ARM_NORM`]) and repeat the last gripper command. `actions.len()`
/// when the last step moves (no tail); 0 when the whole episode stands still.
pub fn idle_tail_start(actions: &[[f32; 7]]) -> usize {
    let Some(last) = actions.last() else {
        return 0;
    };
    let g = last[6];
    actions.len() - actions.iter().rev().take_while(|a| is_idle(a, g)).count()
}

/// Fewest consecutive steps an object must be held to count as grasped (shorter contacts are
/// brushes of the fingers, not grasps).
pub const MIN_GRASP_STEPS: usize = 3;
/// Farthest an object may lie in the table plane (m) from where a carried object is let go to be
/// that carry's target.
pub const PLACE_RADIUS: f32 = 0.10;
/// Most an object may move during a carry (m) and still be its target: what moves along (a
/// basket's content) is carried, not aimed at.
pub const STILL_RADIUS: f32 = 0.02;

/// The object (index into each frame's annotations, scene order) that each step of an episode
/// heads for, from its per-step `frames` of object annotations: while nothing is held, the next
/// object the demonstration grasps (held for at least [`MIN_GRASP_STEPS`]); while an object is
/// held, the still object ([`STILL_RADIUS`]) nearest in the table plane to where it is let go,
/// if within [`PLACE_RADIUS`]. None after the last grasp, for a carry to no object, and without
/// grasp annotations.
pub fn pointer_targets(frames: &[&[ObjectAnnotation]]) -> Vec<Option<usize>> {
    let n = frames.len();
    let held: Vec<Option<usize>> = frames
        .iter()
        .map(|objects| objects.iter().position(|o| o.grasped == Some(true)))
        .collect();
    // Grasps: (first step, last step, object).
    let mut grasps = Vec::new();
    let mut s = 0;
    while s < n {
        let mut e = s;
        while e + 1 < n && held[e + 1] == held[s] {
            e += 1;
        }
        if let Some(o) = held[s].filter(|_| e + 1 - s >= MIN_GRASP_STEPS) {
            grasps.push((s, e, o));
        }
        s = e + 1;
    }
    let mut out = vec![None; n];
    let mut g = 0;
    for (t, target) in out.iter_mut().enumerate() {
        while grasps.get(g).is_some_and(|&(_, e, _)| e < t) {
            g += 1;
        }
        *target = match grasps.get(g) {
            Some(&(s, e, o)) if s <= t => place_target(frames[s], frames[e], o),
            Some(&(_, _, o)) => Some(o),
            None => None,
        };
    }
    out
}

/// The target of a carry of object `held` from the frame `start` to the frame `end` it is let go
/// in (see [`pointer_targets`]).
fn place_target(
    start: &[ObjectAnnotation],
    end: &[ObjectAnnotation],
    held: usize,
) -> Option<usize> {
    let at = end.get(held)?.pose?;
    let dist = |a: &[f32; 7], b: &[f32; 7], dims: usize| {
        (0..dims).map(|d| (a[d] - b[d]).powi(2)).sum::<f32>().sqrt()
    };
    end.iter()
        .enumerate()
        .filter(|&(i, _)| i != held)
        .filter_map(|(i, o)| {
            let now = o.pose?;
            let before = start.get(i)?.pose?;
            (dist(&now, &before, 3) <= STILL_RADIUS).then(|| (i, dist(&now, &at, 2)))
        })
        .filter(|&(_, d)| d <= PLACE_RADIUS)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The steps of `actions` whose gripper command differs from the step before's (never step 0).
pub fn gripper_switches(actions: &[[f32; 7]]) -> Vec<usize> {
    (1..actions.len())
        .filter(|&s| actions[s][6] != actions[s - 1][6])
        .collect()
}

impl Default for WindowConfig {
    fn default() -> Self {
        WindowConfig {
            past: 15,
            future: 0,
            chunk: 4,
            image_size: 64,
            wrist: false,
            images: true,
            augment: None,
            seed: 0,
            mask_idle_tail: false,
            idle_tail_weight: 0.0,
            switch_weight: 1.0,
            state_noise: 0.0,
            pointer_targets: false,
        }
    }
}

impl WindowConfig {
    /// Window length T = p + 1 + q.
    pub fn len(&self) -> usize {
        self.past + 1 + self.future
    }

    /// Always false (a window holds at least frame t).
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// q01/q99 action normalisation (OpenVLA BOUNDS_Q99, model.md §8), with the mask of the
/// normalised dimensions. The one implementation: training targets and the policy's outputs
/// (through `model::io::Processor`) use it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ActionNorm {
    /// 1st percentiles.
    pub q01: [f32; 7],
    /// 99th percentiles.
    pub q99: [f32; 7],
    /// Normalised dimensions (the gripper is not).
    pub mask: [bool; 7],
}

impl ActionNorm {
    /// From the index statistics.
    pub fn from_stats(s: &Stats) -> Result<Self> {
        let arr = |v: &[f32], what: &str| -> Result<[f32; 7]> {
            v.try_into().map_err(|_| {
                DataError::Argument(format!("action {what} has {} values, expected 7", v.len()))
            })
        };
        let m = &s.action.mask;
        if m.len() != 7 {
            return Err(DataError::Argument(format!(
                "action mask has {} values, expected 7",
                m.len()
            )));
        }
        Ok(ActionNorm {
            q01: arr(&s.action.q01, "q01")?,
            q99: arr(&s.action.q99, "q99")?,
            mask: std::array::from_fn(|i| m[i]),
        })
    }

    /// ā = clip(2(a−q01)/(q99−q01+1e-8) − 1, −1, 1) on masked dims; others unchanged.
    pub fn normalize(&self, a: &[f32; 7]) -> [f32; 7] {
        std::array::from_fn(|i| {
            if self.mask[i] {
                (2.0 * (a[i] - self.q01[i]) / (self.q99[i] - self.q01[i] + 1e-8) - 1.0)
                    .clamp(-1.0, 1.0)
            } else {
                a[i]
            }
        })
    }

    /// Inverse on masked dims: a = 0.5(ā+1)(q99−q01) + q01.
    pub fn denormalize(&self, a: &[f32; 7]) -> [f32; 7] {
        std::array::from_fn(|i| {
            if self.mask[i] {
                0.5 * (a[i] + 1.0) * (self.q99[i] - self.q01[i]) + self.q01[i]
            } else {
                a[i]
            }
        })
    }
}

/// One training sample.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowSample {
    /// Position of the episode in the index.
    pub episode: usize,
    /// The episode's seed (from its metadata).
    pub seed: u64,
    /// Centre step t.
    pub t: usize,
    /// Agentview frames `[T, 3, H, W]`, values in [0, 1] (empty when not decoded).
    pub images: Vec<f32>,
    /// Eye-in-hand frames `[T, 3, H, W]` when configured.
    pub wrist_images: Option<Vec<f32>>,
    /// `[T]`: true where t−p+j lies inside the episode (false = repeated edge frame).
    pub frame_mask: Vec<bool>,
    /// `[T]`: the step each window frame was taken from (clamped to the episode).
    pub frame_steps: Vec<usize>,
    /// Normalised action chunks `[T, H_a, 7]` (past the end: the last action repeated).
    pub actions: Vec<f32>,
    /// `[T, H_a]`: true where the action is a real step, not a repetition past the end (nor,
    /// with [`WindowConfig::mask_idle_tail`], a step of the episode's idle tail).
    pub action_mask: Vec<bool>,
    /// `[T, H_a]`: the weight of each action in the action loss: 1 where [`Self::action_mask`]
    /// holds, [`WindowConfig::idle_tail_weight`] on the idle tail's steps, 0 past the episode's
    /// end, each times [`WindowConfig::switch_weight`] at a gripper switch (a repeated edge
    /// frame's weights are those of its step: [`Self::frame_mask`] leaves them out, as it does
    /// its action mask).
    pub action_weights: Vec<f32>,
    /// States `[T, 8]`.
    pub states: Vec<f32>,
    /// The instruction.
    pub instruction: String,
    /// `[T]` goal progress as the policy observes it at each frame: before that frame's action
    /// (see [`observed_progress`]), as an environment reports it with the frame.
    pub goals: Vec<GoalProgress>,
    /// `[T]` object annotations per frame, with the subgoal labels as the policy observes them
    /// at that frame (the labels recorded at the step before, see [`observed_labels`]).
    pub objects: Vec<Vec<ObjectAnnotation>>,
    /// `[T]` each frame's pointer target, an index into its `objects` ([`pointer_targets`]);
    /// empty unless [`WindowConfig::pointer_targets`].
    pub targets: Vec<Option<usize>>,
}

/// Lazily decoding dataset of windows over one split of a dataset directory.
pub struct WindowDataset {
    readers: Vec<(usize, Arc<EpisodeReader>)>,
    samples: Vec<(u32, u32)>,
    cfg: WindowConfig,
    norm: ActionNorm,
    epoch: AtomicU64,
    /// Per episode of the split, the first step of its idle tail (read when the dataset opens;
    /// empty unless [`WindowConfig::mask_idle_tail`]).
    tails: Vec<usize>,
    /// Per episode of the split, its [`gripper_switches`] (empty unless
    /// [`WindowConfig::switch_weight`] ≠ 1).
    switches: Vec<Vec<usize>>,
    /// Per episode of the split, its [`pointer_targets`] (empty unless
    /// [`WindowConfig::pointer_targets`]).
    targets: Vec<Vec<Option<usize>>>,
}

/// One episode's scan at open: idle-tail start, gripper switches, pointer targets.
type Scan = (usize, Vec<usize>, Vec<Option<usize>>);

fn mix(mut z: u64) -> u64 {
    // splitmix64 finaliser
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A dataset directory with its index and every episode opened and checked once
/// ([`crate::EpisodeEntry::open`]: size, CRC-32, structure), so that a training run's checks and
/// both splits' windows share one read of each file.
#[derive(Clone, Debug)]
pub struct OpenedDataset {
    /// The dataset directory.
    pub dir: PathBuf,
    /// Its index.
    pub index: DatasetIndex,
    readers: Vec<Arc<EpisodeReader>>,
}

impl OpenedDataset {
    /// Loads `dir/index.json` and opens every episode ([`OpenedDataset::from_index`]).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        Self::from_index(dir, DatasetIndex::load(dir)?)
    }

    /// Opens every episode of `index` in `dir` in parallel; the first bad one in index order is
    /// the error, whatever order the threads read in.
    pub fn from_index(dir: &Path, index: DatasetIndex) -> Result<Self> {
        let readers = open_each(dir, &index.episodes.iter().collect::<Vec<_>>())?;
        Ok(OpenedDataset {
            dir: dir.to_path_buf(),
            index,
            readers,
        })
    }

    /// Every episode in index order: its index entry, its file's path and its reader.
    pub fn episodes(&self) -> Vec<(&crate::EpisodeEntry, PathBuf, &Arc<EpisodeReader>)> {
        self.index
            .episodes
            .iter()
            .zip(&self.readers)
            .map(|(e, r)| (e, self.dir.join(&e.file), r))
            .collect()
    }
}

/// `entries` opened in parallel ([`crate::EpisodeEntry::open`]), in their order; the first bad
/// one in that order is the error, whatever order the threads read in.
fn open_each(dir: &Path, entries: &[&crate::EpisodeEntry]) -> Result<Vec<Arc<EpisodeReader>>> {
    entries
        .par_iter()
        .map(|e| e.open(dir).map(Arc::new))
        .collect::<Vec<_>>()
        .into_iter()
        .collect()
}

fn check_config(cfg: &WindowConfig) -> Result<()> {
    if cfg.chunk == 0 || cfg.image_size == 0 {
        return Err(DataError::Argument(
            "chunk and image_size must be positive".into(),
        ));
    }
    Ok(())
}

impl WindowDataset {
    /// Opens the episodes of `split` listed in `dir/index.json`.
    pub fn open(dir: impl AsRef<Path>, split: Split, cfg: WindowConfig) -> Result<Self> {
        let dir = dir.as_ref();
        let index = DatasetIndex::load(dir)?;
        Self::from_index(dir, &index, split, cfg)
    }

    /// Like [`WindowDataset::open`] with an index already in memory.
    pub fn from_index(
        dir: &Path,
        index: &DatasetIndex,
        split: Split,
        cfg: WindowConfig,
    ) -> Result<Self> {
        check_config(&cfg)?;
        let (ids, entries): (Vec<usize>, Vec<_>) = index.split(split).into_iter().unzip();
        let readers = ids.into_iter().zip(open_each(dir, &entries)?).collect();
        Self::with_readers(index, readers, cfg)
    }

    /// Like [`WindowDataset::from_index`] on a dataset opened already: both splits and other
    /// passes over the data share one read and one check of each file.
    pub fn from_opened(data: &OpenedDataset, split: Split, cfg: WindowConfig) -> Result<Self> {
        check_config(&cfg)?;
        let readers = data
            .index
            .split(split)
            .into_iter()
            .map(|(i, _)| (i, data.readers[i].clone()))
            .collect();
        Self::with_readers(&data.index, readers, cfg)
    }

    fn with_readers(
        index: &DatasetIndex,
        readers: Vec<(usize, Arc<EpisodeReader>)>,
        cfg: WindowConfig,
    ) -> Result<Self> {
        let norm = ActionNorm::from_stats(&index.stats)?;
        let samples = readers
            .iter()
            .enumerate()
            .flat_map(|(k, (_, r))| (0..r.len() as u32).map(move |t| (k as u32, t)))
            .collect();
        // One read of every episode's steps when any of these needs them.
        let switched = cfg.switch_weight != 1.0;
        let read = if cfg.mask_idle_tail || switched || cfg.pointer_targets {
            readers
                .par_iter()
                .map(|(_, r)| -> Result<Scan> {
                    let steps = r.read_raw_steps(0..r.len())?;
                    let actions: Vec<[f32; 7]> = steps.iter().map(|s| s.action).collect();
                    let targets = if cfg.pointer_targets {
                        let frames: Vec<&[ObjectAnnotation]> =
                            steps.iter().map(|s| s.objects.as_slice()).collect();
                        pointer_targets(&frames)
                    } else {
                        Vec::new()
                    };
                    Ok((
                        idle_tail_start(&actions),
                        gripper_switches(&actions),
                        targets,
                    ))
                })
                .collect::<Result<Vec<_>>>()?
        } else {
            Vec::new()
        };
        let mut tails = Vec::with_capacity(read.len());
        let mut switches = Vec::with_capacity(read.len());
        let mut targets = Vec::with_capacity(read.len());
        for (tail, sw, tg) in read {
            tails.push(tail);
            switches.push(sw);
            targets.push(tg);
        }
        if !cfg.mask_idle_tail {
            tails.clear();
        }
        if !switched {
            switches.clear();
        }
        if !cfg.pointer_targets {
            targets.clear();
        }
        if cfg.pointer_targets && targets.iter().flatten().all(Option::is_none) {
            let path = readers.first().map(|(_, r)| r.path().to_path_buf());
            return Err(DataError::invalid(
                path.unwrap_or_default(),
                "pointer targets asked for, but no step of the split's episodes holds an object \
                 (the episodes record no grasps)",
            ));
        }
        Ok(WindowDataset {
            readers,
            samples,
            cfg,
            norm,
            epoch: AtomicU64::new(0),
            tails,
            switches,
            targets,
        })
    }

    /// Number of samples (every step of every episode of the split).
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The configuration.
    pub fn config(&self) -> &WindowConfig {
        &self.cfg
    }

    /// The action normalisation in use.
    pub fn action_norm(&self) -> &ActionNorm {
        &self.norm
    }

    /// Sets the epoch mixed into augmentation seeds (so each epoch sees new augmentations).
    pub fn set_epoch(&self, epoch: u64) {
        self.epoch.store(epoch, Ordering::Relaxed);
    }

    /// Sample `i` with the current epoch.
    pub fn get(&self, i: usize) -> Result<WindowSample> {
        self.get_with_epoch(i, self.epoch.load(Ordering::Relaxed))
    }

    /// Samples `indices`, decoded in parallel on the current rayon pool.
    pub fn get_many(&self, indices: &[usize]) -> Result<Vec<WindowSample>> {
        indices.par_iter().map(|&i| self.get(i)).collect()
    }

    /// Sample `i` with an explicit epoch; same (seed, epoch, i) → same sample, bit for bit.
    pub fn get_with_epoch(&self, i: usize, epoch: u64) -> Result<WindowSample> {
        let &(k, t) = self.samples.get(i).ok_or_else(|| {
            DataError::Argument(format!("sample {i} out of range 0..{}", self.samples.len()))
        })?;
        let aug_seed = mix(self.cfg.seed ^ mix(epoch ^ mix(i as u64)));
        self.window(k as usize, t as usize, aug_seed)
    }

    /// Episodes of the split.
    pub fn num_episodes(&self) -> usize {
        self.readers.len()
    }

    /// Steps of episode `k` of the split.
    pub fn episode_len(&self, k: usize) -> usize {
        self.readers[k].1.len()
    }

    /// First step of the idle tail of episode `k` of the split ([`idle_tail_start`]); None
    /// unless the dataset masks idle tails ([`WindowConfig::mask_idle_tail`]).
    pub fn idle_tail(&self, k: usize) -> Option<usize> {
        self.tails.get(k).copied()
    }

    /// A chunk of episode `k` of the split (position in the split, not the index): the T =
    /// p + 1 + q frames from `start`, for training with memory carried from chunk to chunk.
    /// Frames past the episode end repeat its last frame and are masked. The augmentation is
    /// drawn per (seed, epoch, episode), so every chunk of an episode pass looks the same.
    pub fn chunk(&self, k: usize, start: usize, epoch: u64) -> Result<WindowSample> {
        if k >= self.readers.len() || start >= self.episode_len(k) {
            return Err(DataError::Argument(format!(
                "chunk at step {start} of episode {k}: out of range ({} episodes)",
                self.readers.len()
            )));
        }
        let aug_seed = mix(self.cfg.seed ^ mix(epoch ^ mix((k as u64) | (1 << 63))));
        self.window(k, start + self.cfg.past, aug_seed)
    }

    /// The window of episode `k` (position in the split) centred at step `t` (which may lie
    /// past the end: those frames are masked).
    fn window(&self, k: usize, t: usize, aug_seed: u64) -> Result<WindowSample> {
        let (episode, r) = &self.readers[k];
        let n = r.len();
        let c = &self.cfg;
        let tl = c.len();
        let frame_steps: Vec<usize> = (0..tl)
            .map(|j| (t as isize - c.past as isize + j as isize).clamp(0, n as isize - 1) as usize)
            .collect();
        let frame_mask: Vec<bool> = (0..tl)
            .map(|j| {
                let s = t as isize - c.past as isize + j as isize;
                s >= 0 && s < n as isize
            })
            .collect();
        let lo = frame_steps[0];
        let hi = frame_steps[tl - 1];
        let last = (hi + c.chunk - 1).min(n - 1);
        // One step before the window too: the progress a frame observes is its predecessor's.
        let first = lo.saturating_sub(1);
        let all = r.read_raw_steps(first..last + 1)?;
        let before = (lo > first).then(|| all[0].progress.clone());
        let before_objects = (lo > first).then(|| all[0].objects.as_slice());
        let raw = &all[lo - first..];

        let mut rng = ChaCha8Rng::seed_from_u64(aug_seed);
        let aug = c.augment.as_ref().map(|a| AugParams::draw(a, &mut rng));
        let s = c.image_size as usize;
        let decode = |which: bool, f: usize| -> Result<Vec<f32>> {
            let st = &raw[f - lo];
            let enc = if which {
                &st.eye_in_hand
            } else {
                &st.agentview
            };
            let img = enc
                .decode()
                .map_err(|m| DataError::invalid(r.path(), format!("step {f}: {m}")))?;
            Ok(to_chw(
                &resize_rgb(img, c.image_size, c.image_size),
                aug.as_ref(),
            ))
        };
        let frames = |which: bool| -> Result<Vec<f32>> {
            let decoded: Vec<Vec<f32>> = (lo..=hi)
                .into_par_iter()
                .map(|f| decode(which, f))
                .collect::<Result<_>>()?;
            let mut out = Vec::with_capacity(tl * 3 * s * s);
            for &f in &frame_steps {
                out.extend_from_slice(&decoded[f - lo]);
            }
            Ok(out)
        };
        let images = if c.images { frames(false)? } else { Vec::new() };
        let wrist_images = if c.wrist { Some(frames(true)?) } else { None };
        let end = self.idle_tail(k).unwrap_or(n);
        let labelled_from = r
            .meta()
            .labelled_from()
            .map_err(|m| DataError::invalid(r.path(), m))?;
        let mut objects: Vec<Vec<ObjectAnnotation>> = frame_steps
            .iter()
            .map(|&f| {
                let previous = if f == lo {
                    before_objects
                } else {
                    Some(raw[f - 1 - lo].objects.as_slice())
                };
                let mut objects = observed_labels(previous, &raw[f - lo].objects);
                if let Some(a) = aug.as_ref().filter(|_| c.images) {
                    shift_boxes(&mut objects, a.dx, a.dy, c.image_size);
                }
                objects
            })
            .collect();
        let mut actions = Vec::with_capacity(tl * c.chunk * 7);
        let mut action_mask = Vec::with_capacity(tl * c.chunk);
        let mut action_weights = Vec::with_capacity(tl * c.chunk);
        let mut states = Vec::with_capacity(tl * 8);
        for (&f, frame_objects) in frame_steps.iter().zip(&mut objects) {
            for h in 0..c.chunk {
                let a = (f + h).min(n - 1);
                actions.extend(self.norm.normalize(&raw[a - lo].action));
                action_mask.push(f + h < end);
                let weight = if f + h < labelled_from {
                    // The policy's own action before the expert took over: no label.
                    0.0
                } else if f + h < end {
                    1.0
                } else if f + h < n {
                    c.idle_tail_weight
                } else {
                    0.0
                };
                let at_switch = self
                    .switches
                    .get(k)
                    .is_some_and(|sw| sw.iter().any(|&s| s.abs_diff(f + h) <= 1));
                action_weights.push(weight * if at_switch { c.switch_weight } else { 1.0 });
            }
            let mut state = raw[f - lo].state;
            if c.state_noise > 0.0 {
                let seed = mix(aug_seed ^ mix(f as u64 ^ NOISE_SALT));
                perturb_positions(c.state_noise, seed, &mut state, frame_objects);
            }
            states.extend(state);
        }
        Ok(WindowSample {
            episode: *episode,
            seed: r.meta().seed,
            t,
            images,
            wrist_images,
            frame_mask,
            actions,
            action_mask,
            action_weights,
            states,
            instruction: r.meta().instruction.clone(),
            goals: frame_steps
                .iter()
                .map(|&f| {
                    let previous = if f == lo {
                        before.as_ref()
                    } else {
                        Some(&raw[f - 1 - lo].progress)
                    };
                    observed_progress(previous, &raw[f - lo].progress)
                })
                .collect(),
            objects,
            targets: match self.targets.get(k) {
                Some(tg) => frame_steps.iter().map(|&f| tg[f]).collect(),
                None => Vec::new(),
            },
            frame_steps,
        })
    }
}

/// Salt of the per-frame state-noise seeds (apart from the augmentation's draws).
const NOISE_SALT: u64 = 0x7374_6174_655f_6e6f;

/// Adds σ-Gaussian noise (metres) to the eef position `state[0..3]`, then to the position of
/// every object with a pose and of each of its parts, in scene order, all drawn from `seed` (the
/// same seed perturbs the same frame identically).
pub fn perturb_positions(
    sigma: f32,
    seed: u64,
    state: &mut [f32; 8],
    objects: &mut [ObjectAnnotation],
) {
    let normal = Normal::new(0.0f32, sigma).expect("σ ≥ 0 is checked by the config");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut shift = |p: &mut [f32]| {
        for x in &mut p[..3] {
            *x += normal.sample(&mut rng);
        }
    };
    shift(&mut state[..]);
    for o in objects {
        if let Some(p) = o.pose.as_mut() {
            shift(&mut p[..]);
        }
        for part in &mut o.parts {
            shift(&mut part.pose[..]);
        }
    }
}

/// The goal progress a policy observes at a step: the progress recorded at the step before
/// (episodes record each step's progress *after* its action, an environment reports it with the
/// next observation). At step 0 (`previous` = None) it is the reset's: nothing satisfied, the
/// first subgoal pending (taken from the recorded progress, which rarely has moved by then).
pub fn observed_progress(previous: Option<&GoalProgress>, current: &GoalProgress) -> GoalProgress {
    match previous {
        Some(p) => p.clone(),
        None if current.satisfied == 0 => current.clone(),
        None => GoalProgress {
            satisfied: 0,
            total: current.total,
            satisfied_subgoals: Vec::new(),
            current_subgoal: current
                .satisfied_subgoals
                .first()
                .cloned()
                .unwrap_or_default(),
        },
    }
}

/// The objects a policy observes at a step: as recorded there, with the subgoal labels recorded
/// at the step before (the recorder gives a step the labels after its action, like its progress;
/// see [`observed_progress`]). At step 0 (`previous` = None) every label is `"0"`.
pub fn observed_labels(
    previous: Option<&[ObjectAnnotation]>,
    current: &[ObjectAnnotation],
) -> Vec<ObjectAnnotation> {
    current
        .iter()
        .enumerate()
        .map(|(i, o)| ObjectAnnotation {
            subgoal_label: previous
                .and_then(|p| p.get(i))
                .map_or_else(|| "0".to_string(), |p| p.subgoal_label.clone()),
            ..o.clone()
        })
        .collect()
}

/// An upright RGB frame as a policy input: resized to `size`² (the `image` crate's filter, see
/// [`resize_rgb`]) and laid out `[3, size, size]` in [0, 1]. Training windows (without
/// augmentation) and the streaming policy both go through it.
pub fn frame_chw(img: RgbImage, size: u32) -> Vec<f32> {
    to_chw(&resize_rgb(img, size, size), None)
}

/// Augmentation parameters drawn once per window.
#[derive(Clone, Debug)]
struct AugParams {
    brightness: f32,
    contrast: f32,
    saturation: f32,
    hue: f32,
    dx: i64,
    dy: i64,
}

impl AugParams {
    fn draw(a: &Augment, rng: &mut ChaCha8Rng) -> Self {
        let sym = |rng: &mut ChaCha8Rng, r: f32| {
            if r > 0.0 {
                rng.random_range(-r..=r)
            } else {
                0.0
            }
        };
        let m = a.max_shift as i64;
        AugParams {
            brightness: sym(rng, a.brightness),
            contrast: 1.0 + sym(rng, a.contrast),
            saturation: 1.0 + sym(rng, a.saturation),
            hue: sym(rng, a.hue) * std::f32::consts::TAU,
            dx: if m > 0 { rng.random_range(-m..=m) } else { 0 },
            dy: if m > 0 { rng.random_range(-m..=m) } else { 0 },
        }
    }
}

/// Moves the seen objects' boxes with the content of a frame shifted by [`to_chw`] (output
/// pixel (x, y) shows input pixel (x + dx, y + dy) of a `size`² frame), so boxes and pixels
/// stay aligned under augmentation.
fn shift_boxes(objects: &mut [ObjectAnnotation], dx: i64, dy: i64, size: u32) {
    for o in objects.iter_mut().filter(|o| o.visible) {
        o.bbox[0] -= dx as f32 / size as f32;
        o.bbox[1] -= dy as f32 / size as f32;
    }
}

/// `[H, W, 3]` u8 → `[3, H, W]` f32 in [0, 1], with optional augmentation
/// (shift, then brightness, contrast, saturation, hue, then clamp).
fn to_chw(img: &RgbImage, aug: Option<&AugParams>) -> Vec<f32> {
    let (w, h) = (img.width as usize, img.height as usize);
    let hw = w * h;
    let mut out = vec![0f32; 3 * hw];
    let (dx, dy) = aug.map(|a| (a.dx, a.dy)).unwrap_or((0, 0));
    for y in 0..h {
        let sy = (y as i64 + dy).clamp(0, h as i64 - 1) as usize;
        for x in 0..w {
            let sx = (x as i64 + dx).clamp(0, w as i64 - 1) as usize;
            let p = (sy * w + sx) * 3;
            for ch in 0..3 {
                out[ch * hw + y * w + x] = img.data[p + ch] as f32 / 255.0;
            }
        }
    }
    if let Some(a) = aug {
        for v in out.iter_mut() {
            *v += a.brightness;
        }
        for ch in 0..3 {
            let plane = &mut out[ch * hw..(ch + 1) * hw];
            let mean = plane.iter().sum::<f32>() / hw as f32;
            for v in plane.iter_mut() {
                *v = (*v - mean) * a.contrast + mean;
            }
        }
        // Saturation and hue together as one colour matrix: RGB → YIQ, scale and rotate the
        // chroma (I, Q) plane, back to RGB.
        const TO_YIQ: [[f32; 3]; 3] = [
            [0.299, 0.587, 0.114],
            [0.596, -0.274, -0.322],
            [0.211, -0.523, 0.312],
        ];
        // exact inverse of TO_YIQ (so zero jitter is the identity up to f32 rounding)
        const TO_RGB: [[f32; 3]; 3] = [
            [1.0, 0.956_170_7, 0.621_432_6],
            [1.0, -0.272_688_6, -0.646_813_2],
            [1.0, -1.103_744_1, 1.700_623_1],
        ];
        let (sn, cs) = a.hue.sin_cos();
        let sat = a.saturation;
        let chroma = [
            [1.0, 0.0, 0.0],
            [0.0, sat * cs, -sat * sn],
            [0.0, sat * sn, sat * cs],
        ];
        let mut m = [[0f32; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = (0..3)
                    .map(|k| {
                        TO_RGB[r][k] * (0..3).map(|l| chroma[k][l] * TO_YIQ[l][c]).sum::<f32>()
                    })
                    .sum();
            }
        }
        for i in 0..hw {
            let p = [out[i], out[hw + i], out[2 * hw + i]];
            for (ch, row) in m.iter().enumerate() {
                out[ch * hw + i] = (row[0] * p[0] + row[1] * p[1] + row[2] * p[2]).clamp(0.0, 1.0);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifted_boxes_stay_on_the_shifted_pixels() {
        // A 16² black frame with a white 3×2 block at x 5..8, y 9..11.
        let size = 16u32;
        let mut data = vec![0u8; 16 * 16 * 3];
        for y in 9..11 {
            for x in 5..8 {
                data[(y * 16 + x) * 3..(y * 16 + x) * 3 + 3].copy_from_slice(&[255; 3]);
            }
        }
        let img = RgbImage {
            width: size,
            height: size,
            channels: 3,
            data,
        };
        let aug = AugParams {
            brightness: 0.0,
            contrast: 1.0,
            saturation: 1.0,
            hue: 0.0,
            dx: 2,
            dy: -3,
        };
        let out = to_chw(&img, Some(&aug));
        let box_of = |o: &ObjectAnnotation| {
            let s = size as f32;
            let x0 = (o.bbox[0] * s).round() as usize;
            let y0 = (o.bbox[1] * s).round() as usize;
            (
                x0,
                y0,
                (o.bbox[2] * s).round() as usize,
                (o.bbox[3] * s).round() as usize,
            )
        };
        let seen = ObjectAnnotation {
            instance_id: 1,
            name: "block".into(),
            bbox: [5.0 / 16.0, 9.0 / 16.0, 3.0 / 16.0, 2.0 / 16.0],
            visible: true,
            subgoal_label: "0".into(),
            pose: None,
            grasped: None,
            parts: Vec::new(),
        };
        let unseen = ObjectAnnotation {
            bbox: [0.0; 4],
            visible: false,
            ..seen.clone()
        };
        let mut objects = vec![seen, unseen];
        shift_boxes(&mut objects, aug.dx, aug.dy, size);
        let (x0, y0, w, h) = box_of(&objects[0]);
        assert_eq!((x0, y0, w, h), (3, 12, 3, 2));
        // Exactly the white pixels of the shifted frame lie in the shifted box.
        for y in 0..16 {
            for x in 0..16 {
                let inside = (x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y);
                assert_eq!(out[y * 16 + x] > 0.5, inside, "pixel ({x}, {y})");
            }
        }
        assert_eq!(
            objects[1].bbox, [0.0; 4],
            "an unseen object keeps its zero box"
        );
    }

    /// An object at (x, y) on the table, held or not.
    fn at(name: &str, x: f32, y: f32, held: bool) -> ObjectAnnotation {
        ObjectAnnotation {
            instance_id: 1,
            name: name.into(),
            bbox: [0.0; 4],
            visible: true,
            subgoal_label: "0".into(),
            pose: Some([x, y, 0.9, 1.0, 0.0, 0.0, 0.0]),
            grasped: Some(held),
            parts: Vec::new(),
        }
    }

    #[test]
    fn pointer_targets_follow_reach_then_carry() {
        // bowl_1 (0) is grasped at steps 3..=6 and carried onto plate_2 (3), which stays still;
        // then bowl_2 (1) is grasped at 9..=11 and carried to nowhere near anything; a one-step
        // touch of plate_1 at step 8 is no grasp.
        let mut frames = Vec::new();
        for t in 0..14 {
            let b1 = if (3..=6).contains(&t) {
                at("bowl_1", 0.3 * (t - 3) as f32 / 3.0, 0.0, true)
            } else if t > 6 {
                at("bowl_1", 0.3, 0.0, false)
            } else {
                at("bowl_1", 0.0, 0.0, false)
            };
            let b2 = if (9..=11).contains(&t) {
                at("bowl_2", -0.2, 0.1 + 0.1 * (t - 9) as f32, true)
            } else if t > 11 {
                at("bowl_2", -0.2, 0.3, false)
            } else {
                at("bowl_2", -0.2, 0.1, false)
            };
            let p1 = at("plate_1", 0.5, 0.5, t == 8);
            let p2 = at("plate_2", 0.31, 0.02, false);
            frames.push(vec![b1, b2, p1, p2]);
        }
        let views: Vec<&[ObjectAnnotation]> = frames.iter().map(Vec::as_slice).collect();
        let t = pointer_targets(&views);
        let want: Vec<Option<usize>> = [
            [Some(0); 3].as_slice(),
            &[Some(3); 4],
            &[Some(1); 2], // the touch at 8 is skipped: still reaching for bowl_2
            &[None; 3],    // carried to (−0.2, 0.3): nothing still within 10 cm
            &[None; 2],    // after the last grasp
        ]
        .concat();
        assert_eq!(t, want);
        // Without grasp annotations nothing is a target.
        for f in &mut frames {
            for o in f.iter_mut() {
                o.grasped = None;
            }
        }
        let views: Vec<&[ObjectAnnotation]> = frames.iter().map(Vec::as_slice).collect();
        assert!(pointer_targets(&views).iter().all(Option::is_none));
    }

    #[test]
    fn a_carry_aims_at_what_stays_still_not_at_what_moves_along() {
        // The basket (0) is carried 0.3 m with the cheese (1) inside it; the other basket (2)
        // ends 5 cm from where the first is let go.
        let frames: Vec<Vec<ObjectAnnotation>> = (0..4)
            .map(|t| {
                let x = 0.1 * t as f32;
                vec![
                    at("basket_1", x, 0.0, true),
                    at("cream_cheese", x + 0.01, 0.0, false),
                    at("basket_2", 0.35, 0.0, false),
                ]
            })
            .collect();
        let views: Vec<&[ObjectAnnotation]> = frames.iter().map(Vec::as_slice).collect();
        assert_eq!(pointer_targets(&views), vec![Some(2); 4]);
    }
}
