//! RLDS import: TFDS TFRecord shards in the OpenVLA LIBERO layout (model.md §11) and LIBERO-Mem's
//! extra keys (libero-mem-reference.md §3) → one episode mcap per record, then `index.json`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use prost::Message;
use rayon::prelude::*;

use crate::episode::{EpisodeWriter, WriterOptions};
use crate::error::{DataError, Result};
use crate::example::{BytesList, Example, FloatList, Int64List, Kind};
use crate::imageio::{Flip, apply_flip, decode_gray8, decode_rgb};
use crate::index::{DatasetIndex, IndexOptions, build_index, write_atomic};
use crate::schema::*;
use crate::tfrecord::{TfRecordReader, write_record};

/// One RLDS episode as stored in a `tf.train.Example` (images still encoded).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct RldsEpisode {
    /// `steps/observation/image`: encoded agentview frames.
    pub images: Vec<Vec<u8>>,
    /// `steps/observation/wrist_image`: encoded wrist frames.
    pub wrist_images: Vec<Vec<u8>>,
    /// `steps/observation/state`, 8 per step.
    pub states: Vec<[f32; 8]>,
    /// `steps/observation/joint_state`, 7 per step.
    pub joint_states: Vec<[f32; 7]>,
    /// `steps/action`, 7 per step.
    pub actions: Vec<[f32; 7]>,
    /// `steps/language_instruction` (same every step).
    pub instruction: String,
    /// `steps/reward`.
    pub rewards: Vec<f32>,
    /// `steps/discount`.
    pub discounts: Vec<f32>,
    /// `steps/is_first`.
    pub is_first: Vec<bool>,
    /// `steps/is_last`.
    pub is_last: Vec<bool>,
    /// `steps/is_terminal`.
    pub is_terminal: Vec<bool>,
    /// `episode_metadata/file_path`.
    pub file_path: String,
    /// LIBERO-Mem `image_depth`: encoded 8-bit min–max scaled depth (JPEG).
    pub depth: Option<Vec<Vec<u8>>>,
    /// LIBERO-Mem `image_seg`: encoded 8-bit segmentation (PNG).
    pub segmentation: Option<Vec<Vec<u8>>>,
    /// LIBERO-Mem `image_reasoning`: per-step object/label text.
    pub reasoning: Option<Vec<String>>,
}

const OBS: &str = "steps/observation/";

fn chunks<const N: usize>(
    v: &[f32],
    key: &str,
    t: usize,
) -> std::result::Result<Vec<[f32; N]>, String> {
    if v.len() != N * t {
        return Err(format!(
            "feature `{key}` has {} values, expected {N} × {t} steps",
            v.len()
        ));
    }
    Ok(v.chunks_exact(N)
        .map(|c| c.try_into().expect("N values"))
        .collect())
}

impl RldsEpisode {
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// True if the episode has no steps.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Parses an Example; unknown keys are ignored. Observation extras are looked up under
    /// `steps/observation/<key>` and then `steps/<key>`.
    pub fn from_example(ex: &Example) -> std::result::Result<Self, String> {
        let need_f = |k: &str| {
            ex.floats(k)?
                .ok_or_else(|| format!("feature `{k}` missing"))
        };
        let need_b = |k: &str| ex.bytes(k)?.ok_or_else(|| format!("feature `{k}` missing"));
        let obs_b = |k: &str| -> std::result::Result<Option<&[Vec<u8>]>, String> {
            match ex.bytes(&format!("{OBS}{k}"))? {
                Some(v) => Ok(Some(v)),
                None => ex.bytes(&format!("steps/{k}")),
            }
        };
        let action = need_f("steps/action")?;
        if action.is_empty() || action.len() % 7 != 0 {
            return Err(format!(
                "feature `steps/action` has {} values, not a positive multiple of 7",
                action.len()
            ));
        }
        let t = action.len() / 7;
        let images = need_b(&format!("{OBS}image"))?.to_vec();
        let wrist_images = need_b(&format!("{OBS}wrist_image"))?.to_vec();
        for (k, v) in [("image", &images), ("wrist_image", &wrist_images)] {
            if v.len() != t {
                return Err(format!(
                    "feature `{OBS}{k}` has {} frames, expected {t}",
                    v.len()
                ));
            }
        }
        let bools = |k: &str| -> std::result::Result<Vec<bool>, String> {
            match ex.ints(k)? {
                Some(v) if v.len() == t => Ok(v.iter().map(|x| *x != 0).collect()),
                Some(v) => Err(format!(
                    "feature `{k}` has {} values, expected {t}",
                    v.len()
                )),
                None => Ok(vec![]),
            }
        };
        let floats_t = |k: &str| -> std::result::Result<Vec<f32>, String> {
            match ex.floats(k)? {
                Some(v) if v.len() == t => Ok(v.to_vec()),
                Some(v) => Err(format!(
                    "feature `{k}` has {} values, expected {t}",
                    v.len()
                )),
                None => Ok(vec![]),
            }
        };
        let frames = |k: &str| -> std::result::Result<Option<Vec<Vec<u8>>>, String> {
            match obs_b(k)? {
                Some(v) if v.len() == t => Ok(Some(v.to_vec())),
                Some(v) => Err(format!(
                    "feature `{k}` has {} frames, expected {t}",
                    v.len()
                )),
                None => Ok(None),
            }
        };
        let instruction = need_b("steps/language_instruction")?
            .first()
            .map(|b| String::from_utf8_lossy(b).into_owned())
            .unwrap_or_default();
        Ok(RldsEpisode {
            states: chunks::<8>(need_f(&format!("{OBS}state"))?, "state", t)?,
            joint_states: chunks::<7>(need_f(&format!("{OBS}joint_state"))?, "joint_state", t)?,
            actions: chunks::<7>(action, "steps/action", t)?,
            images,
            wrist_images,
            instruction,
            rewards: floats_t("steps/reward")?,
            discounts: floats_t("steps/discount")?,
            is_first: bools("steps/is_first")?,
            is_last: bools("steps/is_last")?,
            is_terminal: bools("steps/is_terminal")?,
            file_path: ex
                .bytes("episode_metadata/file_path")?
                .and_then(|v| v.first())
                .map(|b| String::from_utf8_lossy(b).into_owned())
                .unwrap_or_default(),
            depth: frames("image_depth")?,
            segmentation: frames("image_seg")?,
            reasoning: frames("image_reasoning")?.map(|v| {
                v.iter()
                    .map(|b| String::from_utf8_lossy(b).into_owned())
                    .collect()
            }),
        })
    }

    /// Builds the Example in the OpenVLA LIBERO layout (used to write test fixtures).
    pub fn to_example(&self) -> Example {
        let mut ex = Example::default();
        let b = |v: Vec<Vec<u8>>| Kind::BytesList(BytesList { value: v });
        let f = |v: Vec<f32>| Kind::FloatList(FloatList { value: v });
        let i = |v: &[bool]| {
            Kind::Int64List(Int64List {
                value: v.iter().map(|x| *x as i64).collect(),
            })
        };
        let t = self.len();
        ex.insert(&format!("{OBS}image"), b(self.images.clone()));
        ex.insert(&format!("{OBS}wrist_image"), b(self.wrist_images.clone()));
        ex.insert(
            &format!("{OBS}state"),
            f(self.states.iter().flatten().copied().collect()),
        );
        ex.insert(
            &format!("{OBS}joint_state"),
            f(self.joint_states.iter().flatten().copied().collect()),
        );
        ex.insert(
            "steps/action",
            f(self.actions.iter().flatten().copied().collect()),
        );
        ex.insert(
            "steps/language_instruction",
            b(vec![self.instruction.as_bytes().to_vec(); t]),
        );
        // Optional per-step lists are written only when present.
        for (key, v) in [
            ("steps/reward", &self.rewards),
            ("steps/discount", &self.discounts),
        ] {
            if !v.is_empty() {
                ex.insert(key, f(v.clone()));
            }
        }
        for (key, v) in [
            ("steps/is_first", &self.is_first),
            ("steps/is_last", &self.is_last),
            ("steps/is_terminal", &self.is_terminal),
        ] {
            if !v.is_empty() {
                ex.insert(key, i(v));
            }
        }
        ex.insert(
            "episode_metadata/file_path",
            b(vec![self.file_path.as_bytes().to_vec()]),
        );
        if let Some(d) = &self.depth {
            ex.insert(&format!("{OBS}image_depth"), b(d.clone()));
        }
        if let Some(s) = &self.segmentation {
            ex.insert(&format!("{OBS}image_seg"), b(s.clone()));
        }
        if let Some(r) = &self.reasoning {
            ex.insert(
                &format!("{OBS}image_reasoning"),
                b(r.iter().map(|s| s.as_bytes().to_vec()).collect()),
            );
        }
        ex
    }
}

/// Writes a TFDS-style RLDS dataset `<root>/<name>/1.0.0/` with one shard per element of
/// `shards` (for fixtures and tests); returns the version directory.
pub fn write_rlds_dataset(root: &Path, name: &str, shards: &[Vec<RldsEpisode>]) -> Result<PathBuf> {
    let dir = root.join(name).join("1.0.0");
    std::fs::create_dir_all(&dir).map_err(|e| DataError::io(&dir, e))?;
    let n = shards.len();
    for (i, eps) in shards.iter().enumerate() {
        let mut buf = vec![];
        for ep in eps {
            write_record(&mut buf, &ep.to_example().encode_to_vec()).expect("Vec write");
        }
        let p = dir.join(format!("{name}-train.tfrecord-{i:05}-of-{n:05}"));
        write_atomic(&p, &buf)?;
    }
    let info = serde_json::json!({
        "name": name,
        "version": "1.0.0",
        "fileFormat": "tfrecord",
        "splits": [{"name": "train", "shardLengths": shards.iter().map(|s| s.len().to_string()).collect::<Vec<_>>()}],
    });
    write_atomic(&dir.join("dataset_info.json"), info.to_string().as_bytes())?;
    let features = serde_json::json!({"pythonClassName": "tensorflow_datasets.core.features.features_dict.FeaturesDict"});
    write_atomic(&dir.join("features.json"), features.to_string().as_bytes())?;
    Ok(dir)
}

/// How the importer makes stored images upright.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlipChoice {
    /// From the dataset name: `libero_mem*` → none (stored as a vertical flip of the raw render,
    /// which is upright); other `libero*` (OpenVLA) → horizontal flip (stored = 180° rotation of
    /// the raw render, which is itself upside down); anything else → none.
    Auto,
    /// Apply this transform to every image.
    Fixed(Flip),
}

/// The transform [`FlipChoice::Auto`] picks for a dataset name.
pub fn auto_flip(dataset_name: &str) -> Flip {
    let n = dataset_name.to_ascii_lowercase();
    if n.starts_with("libero_mem") {
        Flip::None
    } else if n.starts_with("libero") {
        Flip::Horizontal
    } else {
        Flip::None
    }
}

/// Options of [`convert_rlds`].
#[derive(Clone, Debug)]
pub struct ConvertOptions {
    /// Orientation handling.
    pub flip: FlipChoice,
    /// Episode writer options (JPEG recommended for full LIBERO: PNG files are ~6× larger).
    pub writer: WriterOptions,
    /// Index options for the final `index.json`.
    pub index: IndexOptions,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

impl Default for ConvertOptions {
    fn default() -> Self {
        ConvertOptions {
            flip: FlipChoice::Auto,
            writer: WriterOptions::default(),
            index: IndexOptions::default(),
            progress: false,
        }
    }
}

/// Summary of a conversion.
#[derive(Clone, Debug)]
pub struct ConvertReport {
    /// Dataset name.
    pub name: String,
    /// Shards read.
    pub shards: usize,
    /// Episodes written.
    pub episodes: usize,
    /// Steps written.
    pub steps: usize,
    /// Transform applied to every image.
    pub flip: Flip,
    /// The index written to the output directory.
    pub index: DatasetIndex,
}

/// TFRecord shards (`*.tfrecord-*`) under `src` (searched up to 3 levels deep), sorted.
pub fn find_shards(src: &Path) -> Result<Vec<PathBuf>> {
    fn walk(d: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<()> {
        for e in std::fs::read_dir(d).map_err(|e| DataError::io(d, e))? {
            let p = e.map_err(|e| DataError::io(d, e))?.path();
            if p.is_dir() && depth > 0 {
                walk(&p, depth - 1, out)?;
            } else if p
                .file_name()
                .is_some_and(|n| n.to_string_lossy().contains(".tfrecord-"))
            {
                out.push(p);
            }
        }
        Ok(())
    }
    let mut v = vec![];
    walk(src, 3, &mut v)?;
    v.sort();
    Ok(v)
}

fn dataset_name(shard: &Path) -> String {
    if let Some(dir) = shard.parent() {
        let info = dir.join("dataset_info.json");
        if let Ok(text) = std::fs::read_to_string(&info)
            && let Ok(v) = serde_json::from_str::<serde_json::Value>(&text)
            && let Some(n) = v.get("name").and_then(|n| n.as_str())
        {
            return n.to_string();
        }
    }
    let f = shard
        .file_name()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned();
    f.split(".tfrecord")
        .next()
        .unwrap_or("rlds")
        .trim_end_matches("-train")
        .to_string()
}

/// Parses LIBERO-Mem's reasoning text `name:segid,[x y w h],label#…` (boxes in pixels of a
/// `width`×`height` image). `None` if it does not follow that format.
pub fn parse_reasoning(text: &str, width: u32, height: u32) -> Option<Vec<ObjectAnnotation>> {
    let mut out = vec![];
    for part in text.split('#').filter(|p| !p.trim().is_empty()) {
        let (name, rest) = part.split_once(':')?;
        let (segid, rest) = rest.split_once(',')?;
        let open = rest.find('[')?;
        let close = rest.find(']')?;
        let nums: Vec<f32> = rest[open + 1..close]
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<f32>().ok())
            .collect::<Option<_>>()?;
        if nums.len() != 4 {
            return None;
        }
        let label = rest[close + 1..].trim_start_matches(',').trim().to_string();
        let (w, h) = (width.max(1) as f32, height.max(1) as f32);
        let bbox = [nums[0] / w, nums[1] / h, nums[2] / w, nums[3] / h];
        out.push(ObjectAnnotation {
            instance_id: segid.trim().parse().ok()?,
            name: name.trim().to_string(),
            bbox,
            visible: bbox[2] > 0.0 && bbox[3] > 0.0,
            subgoal_label: if label.is_empty() { "0".into() } else { label },
            pose: None,
            grasped: None,
            parts: Vec::new(),
        });
    }
    Some(out)
}

/// Applies an image flip to a normalised `[x, y, w, h]` box.
pub fn flip_box(b: [f32; 4], flip: Flip) -> [f32; 4] {
    let [x, y, w, h] = b;
    match flip {
        Flip::None => b,
        Flip::Horizontal => [1.0 - x - w, y, w, h],
        Flip::Vertical => [x, 1.0 - y - h, w, h],
        Flip::Rotate180 => [1.0 - x - w, 1.0 - y - h, w, h],
    }
}

/// Converts one RLDS episode to step records (images decoded and made upright with `flip`).
pub fn episode_steps(ep: &RldsEpisode, flip: Flip) -> std::result::Result<Vec<StepRecord>, String> {
    let mut robot_labels: Vec<String> = vec![];
    (0..ep.len())
        .map(|k| {
            let rgb = |bytes: &[u8], what: &str| -> std::result::Result<RgbImage, String> {
                let mut img = decode_rgb(bytes, "").map_err(|e| format!("step {k} {what}: {e}"))?;
                apply_flip(
                    &mut img.data,
                    img.width as usize,
                    img.height as usize,
                    3,
                    flip,
                );
                Ok(img)
            };
            let agentview = rgb(&ep.images[k], "image")?;
            let eye_in_hand = rgb(&ep.wrist_images[k], "wrist_image")?;
            let segmentation = match &ep.segmentation {
                Some(v) => {
                    let (w, h, mut d) =
                        decode_gray8(&v[k], "").map_err(|e| format!("step {k} image_seg: {e}"))?;
                    apply_flip(&mut d, w as usize, h as usize, 1, flip);
                    Some(Segmentation::U16(Image {
                        width: w,
                        height: h,
                        channels: 1,
                        data: d.into_iter().map(u16::from).collect(),
                    }))
                }
                None => None,
            };
            let depth = match &ep.depth {
                Some(v) => {
                    let (w, h, mut d) = decode_gray8(&v[k], "")
                        .map_err(|e| format!("step {k} image_depth: {e}"))?;
                    apply_flip(&mut d, w as usize, h as usize, 1, flip);
                    Some(Image {
                        width: w,
                        height: h,
                        channels: 1,
                        data: d.into_iter().map(|v| v as f32 / 255.0).collect(),
                    })
                }
                None => None,
            };
            let mut objects = vec![];
            let mut progress = GoalProgress::default();
            if let Some(r) = &ep.reasoning {
                match parse_reasoning(&r[k], agentview.width, agentview.height) {
                    Some(objs) => {
                        for o in &objs {
                            if o.name == "robot"
                                && o.subgoal_label != "0"
                                && !robot_labels.contains(&o.subgoal_label)
                            {
                                robot_labels.push(o.subgoal_label.clone());
                            }
                        }
                        objects = objs
                            .into_iter()
                            .map(|mut o| {
                                o.bbox = flip_box(o.bbox, flip);
                                o
                            })
                            .collect();
                        progress.satisfied = robot_labels.len() as u32;
                        progress.satisfied_subgoals = robot_labels.clone();
                    }
                    None => progress.current_subgoal = r[k].clone(),
                }
            }
            Ok(StepRecord {
                step: k as u64,
                agentview,
                eye_in_hand,
                segmentation,
                depth,
                state: ep.states[k],
                joint_state: ep.joint_states[k],
                action: ep.actions[k],
                objects,
                progress,
            })
        })
        .collect()
}

fn task_id(name: &str, ep: &RldsEpisode) -> String {
    let suite = name.trim_end_matches("_no_noops");
    let stem = Path::new(&ep.file_path)
        .file_stem()
        .map(|s| s.to_string_lossy().trim_end_matches("_demo").to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| {
            crate::text::words(&ep.instruction)
                .collect::<Vec<_>>()
                .join("_")
        });
    format!("{suite}/{stem}")
}

/// Converts every shard under `src` into episode files in `out` (in parallel over shards, one
/// file per record, named `<name>_s<shard>_e<record>.mcap`), then writes `out/index.json`.
pub fn convert_rlds(src: &Path, out: &Path, opts: &ConvertOptions) -> Result<ConvertReport> {
    let shards = find_shards(src)?;
    if shards.is_empty() {
        return Err(DataError::invalid(
            src,
            "no TFRecord shards (`*.tfrecord-*`) found",
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| DataError::io(out, e))?;
    let name = dataset_name(&shards[0]);
    let flip = match opts.flip {
        FlipChoice::Auto => auto_flip(&name),
        FlipChoice::Fixed(f) => f,
    };
    let bar = if opts.progress {
        let b = indicatif::ProgressBar::new(shards.len() as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{elapsed_precise} [{bar:30}] {pos}/{len} shards {msg}",
            )
            .expect("valid template"),
        );
        b
    } else {
        indicatif::ProgressBar::hidden()
    };
    let episodes = AtomicUsize::new(0);
    let steps = AtomicUsize::new(0);
    shards
        .par_iter()
        .enumerate()
        .try_for_each(|(si, shard)| -> Result<()> {
            for (ri, rec) in TfRecordReader::open(shard)?.enumerate() {
                let (offset, bytes) = rec?;
                let bad = |m: String| {
                    DataError::invalid(shard, format!("record {ri} at byte offset {offset}: {m}"))
                };
                let ex = Example::decode(bytes.as_slice()).map_err(|e| {
                    DataError::corrupt(
                        shard,
                        offset,
                        format!("record {ri}: not a tf.train.Example: {e}"),
                    )
                })?;
                let ep = RldsEpisode::from_example(&ex).map_err(bad)?;
                let recs = episode_steps(&ep, flip).map_err(bad)?;
                let mut meta = EpisodeMeta {
                    task_id: task_id(&name, &ep),
                    instruction: ep.instruction.clone(),
                    seed: (si as u64) << 32 | ri as u64,
                    sim_version: format!("rlds-import:{name}"),
                    asset_version: "libero".into(),
                    ..EpisodeMeta::default()
                };
                meta.extra.insert(
                    "source_file".into(),
                    shard
                        .file_name()
                        .unwrap_or_default()
                        .to_string_lossy()
                        .into_owned(),
                );
                meta.extra.insert("source_record".into(), ri.to_string());
                meta.extra
                    .insert("source_episode_path".into(), ep.file_path.clone());
                meta.extra.insert("applied_flip".into(), flip.name().into());
                if ep.depth.is_some() {
                    meta.extra.insert(
                        "depth_units".into(),
                        "per-frame min-max scaled to [0,1], not metres".into(),
                    );
                }
                let path = out.join(format!("{name}_s{si:05}_e{ri:04}.mcap"));
                let mut w = EpisodeWriter::create(&path, meta, opts.writer.clone())?;
                for r in &recs {
                    w.write_step(r)?;
                }
                w.finish()?;
                episodes.fetch_add(1, Ordering::Relaxed);
                steps.fetch_add(recs.len(), Ordering::Relaxed);
                bar.set_message(format!("{} episodes", episodes.load(Ordering::Relaxed)));
            }
            bar.inc(1);
            Ok(())
        })?;
    bar.finish_and_clear();
    let index = build_index(out, &opts.index)?;
    Ok(ConvertReport {
        name,
        shards: shards.len(),
        episodes: episodes.into_inner(),
        steps: steps.into_inner(),
        flip,
        index,
    })
}
