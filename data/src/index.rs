//! Dataset directories: episode files plus `index.json` (episode list, lengths, train/val split,
//! action and state statistics as OpenVLA computes them, and a word vocabulary).

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::episode::EpisodeReader;
use crate::error::{DataError, Result};
use crate::text::Vocab;

pub use crate::fsio::write_atomic;

/// File name of the index inside a dataset directory.
pub const INDEX_FILE: &str = "index.json";
/// Format tag of the index file.
pub const INDEX_FORMAT: &str = "libero-mem-rs/dataset/1";

/// Which split an episode belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training split.
    Train,
    /// Validation split.
    Val,
}

/// One episode of the dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEntry {
    /// File name relative to the dataset directory.
    pub file: String,
    /// Number of steps.
    pub length: usize,
    /// Task id.
    pub task_id: String,
    /// Instruction.
    pub instruction: String,
    /// Episode seed.
    pub seed: u64,
    /// Split.
    pub split: Split,
    /// File size in bytes (absent in indexes written before integrity checks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<u64>,
    /// CRC-32 of the whole file, checked every time the episode is opened for training
    /// ([`EpisodeEntry::open`]; absent in indexes written before integrity checks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crc32: Option<u32>,
}

impl EpisodeEntry {
    /// Opens this episode of dataset `dir` and checks it against the index before it is trusted:
    /// size and CRC-32 of the whole file (every byte, the header and the summary included),
    /// then the mcap structure and the step count. A mismatch is bad input naming the file.
    pub fn open(&self, dir: &Path) -> Result<EpisodeReader> {
        let (path, bytes) = self.read(dir)?;
        self.check_bytes(path, bytes)
    }

    /// This episode's path in dataset `dir` and the whole file, unchecked; a file the index lists
    /// but the directory lacks is bad input.
    pub fn read(&self, dir: &Path) -> Result<(PathBuf, std::sync::Arc<[u8]>)> {
        let path = dir.join(&self.file);
        match std::fs::read(&path) {
            Ok(b) => Ok((path, b.into())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(DataError::invalid(
                &path,
                "listed in index.json but missing (rebuild the index with `data stats DIR`, or regenerate the episode)",
            )),
            Err(e) => Err(DataError::io(&path, e)),
        }
    }

    /// The checks of [`EpisodeEntry::open`] on a file already read into memory.
    pub fn check_bytes(&self, path: PathBuf, bytes: std::sync::Arc<[u8]>) -> Result<EpisodeReader> {
        let stale = "index.json was built from other files (rebuild it with `data stats DIR`, or regenerate the episode)";
        if let Some(n) = self.bytes
            && n != bytes.len() as u64
        {
            return Err(DataError::invalid(
                &path,
                format!(
                    "{} bytes, index.json says {n}: truncated or replaced; {stale}",
                    bytes.len()
                ),
            ));
        }
        if let Some(crc) = self.crc32 {
            let got = crc32fast::hash(&bytes);
            if got != crc {
                return Err(DataError::invalid(
                    &path,
                    format!(
                        "CRC-32 {got:08x}, index.json says {crc:08x}: the file is corrupt; {stale}"
                    ),
                ));
            }
        }
        let r = EpisodeReader::from_bytes(path, bytes)?;
        if r.len() != self.length {
            return Err(DataError::invalid(
                r.path(),
                format!(
                    "has {} steps, index.json says {} (rebuild it with `data stats`)",
                    r.len(),
                    self.length
                ),
            ));
        }
        Ok(r)
    }
}

/// Per-dimension statistics of a vector quantity (OpenVLA's `dataset_statistics.json` fields).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArrayStats {
    /// Mean.
    pub mean: Vec<f32>,
    /// Population standard deviation (numpy `std`, ddof = 0).
    pub std: Vec<f32>,
    /// Maximum.
    pub max: Vec<f32>,
    /// Minimum.
    pub min: Vec<f32>,
    /// 1st percentile (numpy `quantile`, linear interpolation).
    pub q01: Vec<f32>,
    /// 99th percentile (numpy `quantile`, linear interpolation).
    pub q99: Vec<f32>,
    /// Which dimensions are normalised (actions: all but the gripper).
    pub mask: Vec<bool>,
}

/// numpy's default `quantile` (linear interpolation between order statistics) of sorted data.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    let frac = pos - lo as f64;
    sorted[lo] + (sorted[hi] - sorted[lo]) * frac
}

impl ArrayStats {
    /// Statistics over rows `[N, D]` (each row one step); `mask` marks normalised dimensions.
    pub fn compute<const D: usize>(rows: &[[f32; D]], mask: [bool; D]) -> ArrayStats {
        let n = rows.len().max(1) as f64;
        let mut s = ArrayStats {
            mean: vec![],
            std: vec![],
            max: vec![],
            min: vec![],
            q01: vec![],
            q99: vec![],
            mask: mask.to_vec(),
        };
        for d in 0..D {
            let mut col: Vec<f64> = rows.iter().map(|r| r[d] as f64).collect();
            let mean = col.iter().sum::<f64>() / n;
            let var = col.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
            col.sort_by(|a, b| a.total_cmp(b));
            s.mean.push(mean as f32);
            s.std.push(var.sqrt() as f32);
            s.min.push(col.first().copied().unwrap_or(0.0) as f32);
            s.max.push(col.last().copied().unwrap_or(0.0) as f32);
            s.q01.push(quantile_sorted(&col, 0.01) as f32);
            s.q99.push(quantile_sorted(&col, 0.99) as f32);
        }
        s
    }
}

/// Statistics block of the index.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Action statistics (mask: dims 0–5 normalised, gripper not).
    pub action: ArrayStats,
    /// 8-D proprio state statistics.
    pub state: ArrayStats,
    /// Number of steps the statistics were computed over (train split).
    pub num_transitions: usize,
    /// Number of train episodes.
    pub num_trajectories: usize,
}

/// Options of [`build_index`].
#[derive(Clone, Debug)]
pub struct IndexOptions {
    /// Fraction of episodes put in the validation split.
    pub val_fraction: f64,
    /// Seed of the split shuffle.
    pub seed: u64,
}

impl Default for IndexOptions {
    fn default() -> Self {
        IndexOptions {
            val_fraction: 0.05,
            seed: 0,
        }
    }
}

/// The dataset index stored as `index.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetIndex {
    /// Format tag, [`INDEX_FORMAT`].
    pub format: String,
    /// Control frequency of the episodes.
    pub fps: f64,
    /// Validation fraction used for the split.
    pub val_fraction: f64,
    /// Seed used for the split.
    pub split_seed: u64,
    /// Episodes, sorted by file name.
    pub episodes: Vec<EpisodeEntry>,
    /// Statistics over the train split.
    pub stats: Stats,
    /// Word vocabulary of instructions, subgoal texts and object labels.
    pub vocab: Vec<String>,
}

impl DatasetIndex {
    /// Reads `DIR/index.json`.
    pub fn load(dir: impl AsRef<Path>) -> Result<Self> {
        let p = dir.as_ref().join(INDEX_FILE);
        let text = std::fs::read_to_string(&p).map_err(|e| DataError::io(&p, e))?;
        let idx: DatasetIndex = serde_json::from_str(&text).map_err(|e| {
            DataError::invalid(
                &p,
                format!("bad index (line {}, column {}): {e}", e.line(), e.column()),
            )
        })?;
        if idx.format != INDEX_FORMAT {
            return Err(DataError::invalid(
                &p,
                format!("format `{}`, expected `{INDEX_FORMAT}`", idx.format),
            ));
        }
        Ok(idx)
    }

    /// Writes `DIR/index.json` atomically (temporary file + rename).
    pub fn save(&self, dir: impl AsRef<Path>) -> Result<PathBuf> {
        let p = dir.as_ref().join(INDEX_FILE);
        let text =
            serde_json::to_string_pretty(self).map_err(|e| DataError::Argument(e.to_string()))?;
        write_atomic(&p, text.as_bytes())?;
        Ok(p)
    }

    /// Episodes of one split, with their positions in [`DatasetIndex::episodes`].
    pub fn split(&self, split: Split) -> Vec<(usize, &EpisodeEntry)> {
        self.episodes
            .iter()
            .enumerate()
            .filter(|(_, e)| e.split == split)
            .collect()
    }

    /// The vocabulary as a [`Vocab`].
    pub fn vocab(&self) -> Vocab {
        Vocab::from_words(self.vocab.clone())
    }
}

/// Episode files (`*.mcap`) of a directory and of its immediate subdirectories (a suite
/// dataset: one subfolder per task), sorted by path.
pub fn episode_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v = vec![];
    for e in std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))? {
        let e = e.map_err(|e| DataError::io(dir, e))?;
        let p = e.path();
        if p.extension().is_some_and(|x| x == "mcap") && p.is_file() {
            v.push(p);
        } else if p.is_dir() {
            for e in std::fs::read_dir(&p).map_err(|e| DataError::io(&p, e))? {
                let q = e.map_err(|e| DataError::io(&p, e))?.path();
                if q.extension().is_some_and(|x| x == "mcap") && q.is_file() {
                    v.push(q);
                }
            }
        }
    }
    v.sort();
    Ok(v)
}

struct Scanned {
    entry: EpisodeEntry,
    actions: Vec<[f32; 7]>,
    states: Vec<[f32; 8]>,
    texts: Vec<String>,
    fps: f64,
}

/// (Re)builds `DIR/index.json` from the `*.mcap` files in `dir`, reading every file fully (which
/// also verifies every chunk). Same files and options → same index, byte for byte.
pub fn build_index(dir: impl AsRef<Path>, opts: &IndexOptions) -> Result<DatasetIndex> {
    let dir = dir.as_ref();
    if !(0.0..1.0).contains(&opts.val_fraction) {
        return Err(DataError::Argument(format!(
            "val fraction must be in [0, 1), got {}",
            opts.val_fraction
        )));
    }
    let files = episode_files(dir)?;
    if files.is_empty() {
        return Err(DataError::invalid(dir, "no *.mcap episode files"));
    }
    let scanned: Vec<Scanned> = files
        .par_iter()
        .map(|p| {
            let r = EpisodeReader::open(p)?;
            let (bytes, crc32) = (r.file_bytes().len() as u64, crc32fast::hash(r.file_bytes()));
            let raw = r.read_raw_steps(0..r.len())?;
            // Statistics over labelled steps only (a policy's own actions before a take-over are
            // not what training fits).
            let labelled = r
                .meta()
                .labelled_from()
                .map_err(|m| DataError::invalid(p, m))?
                .min(raw.len());
            let mut texts = vec![r.meta().instruction.clone()];
            for s in &raw {
                if texts.last() != Some(&s.progress.current_subgoal) {
                    texts.push(s.progress.current_subgoal.clone());
                }
                texts.extend(s.progress.satisfied_subgoals.iter().cloned());
                texts.extend(s.objects.iter().map(|o| o.subgoal_label.clone()));
                texts.extend(s.objects.iter().map(|o| o.name.clone()));
            }
            texts.sort();
            texts.dedup();
            Ok(Scanned {
                entry: EpisodeEntry {
                    // Relative to the dataset, `/`-separated (`t3/episode_00001.mcap` in a suite).
                    file: p
                        .strip_prefix(dir)
                        .unwrap_or(p)
                        .components()
                        .map(|c| c.as_os_str().to_string_lossy().into_owned())
                        .collect::<Vec<_>>()
                        .join("/"),
                    length: r.len(),
                    task_id: r.meta().task_id.clone(),
                    instruction: r.meta().instruction.clone(),
                    seed: r.meta().seed,
                    split: Split::Train,
                    bytes: Some(bytes),
                    crc32: Some(crc32),
                },
                actions: raw[labelled..].iter().map(|s| s.action).collect(),
                states: raw.iter().map(|s| s.state).collect(),
                texts,
                fps: r.meta().fps,
            })
        })
        .collect::<Result<_>>()?;
    let fps = scanned[0].fps;
    if let Some(s) = scanned.iter().find(|s| s.fps != fps) {
        return Err(DataError::invalid(
            dir.join(&s.entry.file),
            format!("fps {} differs from the dataset's {fps}", s.fps),
        ));
    }
    // Seeded split: shuffle positions, the first round(n·f) become validation (at least one
    // train episode always remains).
    let n = scanned.len();
    let n_val = ((n as f64 * opts.val_fraction).round() as usize).min(n - 1);
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(opts.seed));
    let mut split = vec![Split::Train; n];
    for &i in &order[..n_val] {
        split[i] = Split::Val;
    }
    let mut actions = vec![];
    let mut states = vec![];
    let mut words = vec![];
    let mut episodes = vec![];
    for (i, s) in scanned.into_iter().enumerate() {
        let mut e = s.entry;
        e.split = split[i];
        if e.split == Split::Train {
            actions.extend(s.actions);
            states.extend(s.states);
        }
        words.extend(s.texts);
        episodes.push(e);
    }
    let num_trajectories = episodes.iter().filter(|e| e.split == Split::Train).count();
    let mut action_mask = [true; 7];
    action_mask[6] = false;
    let stats = Stats {
        action: ArrayStats::compute(&actions, action_mask),
        state: ArrayStats::compute(&states, [true; 8]),
        num_transitions: actions.len(),
        num_trajectories,
    };
    let idx = DatasetIndex {
        format: INDEX_FORMAT.into(),
        fps,
        val_fraction: opts.val_fraction,
        split_seed: opts.seed,
        episodes,
        stats,
        vocab: Vocab::build(words.iter().map(|s| s.as_str()))
            .words()
            .to_vec(),
    };
    idx.save(dir)?;
    Ok(idx)
}
