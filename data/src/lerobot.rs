//! LeRobotDataset v3.0 directories (what `lerobot`'s `LeRobotDataset(repo_id, root=…)` loads):
//! [`export`] writes one from a dataset of episodes, [`import`] reads one into episodes.
//!
//! Layout (LeRobot's path templates): `meta/info.json`, `meta/stats.json`, `meta/tasks.parquet`,
//! `meta/episodes/chunk-000/file-000.parquet`, `data/chunk-CCC/file-FFF.parquet`,
//! `videos/<key>/chunk-CCC/file-FFF.mp4`. Episodes are concatenated in the data and video files
//! (a new file once one passes its size limit, at an episode boundary); an episode's frames are
//! rows `dataset_from_index..dataset_to_index` and, in each video, the frames from
//! `from_timestamp` on. Frame k of an episode has `timestamp` k / fps.
//!
//! Features: `observation.images.image` (agentview) and `observation.images.wrist_image`
//! (eye-in-hand) as H.264 videos, `observation.state` (8: eef position, eef axis-angle, finger
//! joints), `action` (7), LeRobot's `timestamp`, `frame_index`, `episode_index`, `index`,
//! `task_index`, and ours: `observation.joint_state` (7), `observation.objects.pose` `[N, 7]`,
//! `observation.objects.box` `[N, 4]`, `observation.objects.visible` / `.grasped` `[N]` (0/1),
//! `observation.objects.instance_id` `[N]` (−1: no object in that row), `subgoal.satisfied`,
//! `subgoal.total`, `subgoal.current` (text) and `subgoal.labels` (the objects' labels as a
//! JSON array). N is the most objects of any episode; the episodes table names each episode's
//! objects (`libero_mem/objects`). Where episodes record articulated parts (episode schema 3:
//! drawer handles, the stove's knob), `observation.parts.pose` `[P, 7]`, `observation.parts.joint`
//! `[P]` and `observation.parts.object` `[P]` (the row of the part's object, −1: no part in that
//! row) follow, P the most parts of any episode, and the episodes table names them
//! (`libero_mem/parts`).

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{
    FixedSizeListBuilder, Float32Builder, Float64Builder, Int64Builder, ListBuilder, StringBuilder,
};
use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int64Type};
use arrow_array::{Array, ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;
use serde_json::{Value, json};

use crate::episode::{EpisodeWriter, WriterOptions};
use crate::error::{DataError, Result};
use crate::imageio::{Flip, apply_flip};
use crate::index::{DatasetIndex, IndexOptions, Split, build_index, quantile_sorted};
use crate::schema::{EpisodeMeta, GoalProgress, ObjectAnnotation, PartState, RgbImage, StepRecord};
use crate::video::{VideoOptions, VideoWriter};

/// LeRobot's dataset format version written and read.
pub const CODEBASE_VERSION: &str = "v3.0";
/// Video key of the agentview camera.
pub const IMAGE_KEY: &str = "observation.images.image";
/// Video key of the eye-in-hand camera.
pub const WRIST_KEY: &str = "observation.images.wrist_image";
/// Files per chunk folder (LeRobot's default).
pub const CHUNKS_SIZE: usize = 1000;
const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
const VIDEO_PATH: &str = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";
/// Per-frame text features: the pending subgoal, the objects' labels (a JSON array in the
/// order of the object rows) and the satisfied subgoals (a JSON array, in order).
const TEXT_FEATURES: [&str; 3] = ["subgoal.current", "subgoal.labels", "subgoal.done"];
const QUANTILES: [(&str, f64); 5] = [
    ("q01", 0.01),
    ("q10", 0.10),
    ("q50", 0.50),
    ("q90", 0.90),
    ("q99", 0.99),
];

/// How [`export`] writes.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    /// Transform from our upright frames to the stored ones. `Horizontal` (the default) stores
    /// them as LeRobot's and openpi's LIBERO datasets do (LIBERO's raw render turned by 180°,
    /// which is our upright frame mirrored), the orientation `eval --policy ws://` sends.
    pub flip: Flip,
    /// A key frame every this many frames (and at every episode start).
    pub keyframe_every: u32,
    /// Data file size limit in MB (LeRobot's default 100).
    pub data_file_mb: u64,
    /// Video file size limit in MB (LeRobot's default 200).
    pub video_file_mb: u64,
    /// `robot_type` in info.json.
    pub robot_type: String,
    /// Print one line per 100 episodes on stderr.
    pub progress: bool,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            flip: Flip::Horizontal,
            keyframe_every: 20,
            data_file_mb: 100,
            video_file_mb: 200,
            robot_type: "panda".into(),
            progress: false,
        }
    }
}

/// What [`export`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportReport {
    /// Episodes written.
    pub episodes: usize,
    /// Frames written.
    pub frames: u64,
    /// Distinct instructions.
    pub tasks: usize,
    /// Data parquet files.
    pub data_files: usize,
    /// Video files per camera.
    pub video_files: usize,
}

fn invalid(path: &Path, msg: impl Into<String>) -> DataError {
    DataError::invalid(path, msg)
}

fn pq_err(path: &Path, e: impl std::fmt::Display) -> DataError {
    invalid(path, format!("parquet: {e}"))
}

/// `chunk-CCC/file-FFF` of a template.
fn chunk_path(template: &str, key: &str, chunk: usize, file: usize) -> String {
    template
        .replace("{video_key}", key)
        .replace("{chunk_index:03d}", &format!("{chunk:03}"))
        .replace("{file_index:03d}", &format!("{file:03}"))
}

/// Next (chunk, file) position: `CHUNKS_SIZE` files per chunk folder.
fn next_file(pos: (usize, usize)) -> (usize, usize) {
    if pos.1 + 1 == CHUNKS_SIZE {
        (pos.0 + 1, 0)
    } else {
        (pos.0, pos.1 + 1)
    }
}

/// min, max, mean, std and the [`QUANTILES`] of one element over frames.
struct ElementStats {
    min: f64,
    max: f64,
    mean: f64,
    std: f64,
    quantiles: Vec<f64>,
}

/// Running statistics of one numeric feature (per element, over frames).
#[derive(Default)]
struct FeatureStats {
    values: Vec<Vec<f64>>,
}

impl FeatureStats {
    fn push(&mut self, v: &[f64]) {
        if self.values.is_empty() {
            self.values = vec![Vec::new(); v.len()];
        }
        for (col, x) in self.values.iter_mut().zip(v) {
            col.push(*x);
        }
    }

    /// `{min, max, mean, std, count, q01…q99}`, each shaped like the feature.
    fn to_json(&self, shape: &[usize]) -> Value {
        let mut out = serde_json::Map::new();
        let count = self.values.first().map_or(0, |c| c.len());
        let per: Vec<ElementStats> = self
            .values
            .iter()
            .map(|col| {
                let mut s = col.clone();
                s.sort_by(|a, b| a.total_cmp(b));
                let n = s.len().max(1) as f64;
                let mean = s.iter().sum::<f64>() / n;
                let var = s.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
                let q = QUANTILES
                    .iter()
                    .map(|(_, q)| quantile_sorted(&s, *q))
                    .collect();
                ElementStats {
                    min: s.first().copied().unwrap_or(0.0),
                    max: s.last().copied().unwrap_or(0.0),
                    mean,
                    std: var.sqrt(),
                    quantiles: q,
                }
            })
            .collect();
        let shaped = |f: &dyn Fn(&ElementStats) -> f64| -> Value {
            let flat: Vec<f64> = per.iter().map(f).collect();
            reshape(&flat, shape)
        };
        out.insert("min".into(), shaped(&|p| p.min));
        out.insert("max".into(), shaped(&|p| p.max));
        out.insert("mean".into(), shaped(&|p| p.mean));
        out.insert("std".into(), shaped(&|p| p.std));
        out.insert("count".into(), json!([count]));
        for (i, (name, _)) in QUANTILES.iter().enumerate() {
            out.insert((*name).into(), shaped(&|p| p.quantiles[i]));
        }
        Value::Object(out)
    }
}

/// Nested JSON arrays of `flat` in `shape` (row-major).
fn reshape(flat: &[f64], shape: &[usize]) -> Value {
    match shape {
        [] | [_] => json!(flat),
        [_, rest @ ..] => {
            let inner: usize = rest.iter().product();
            Value::Array(
                flat.chunks(inner.max(1))
                    .map(|c| reshape(c, rest))
                    .collect(),
            )
        }
    }
}

/// Per-channel image statistics in [0, 1] (LeRobot's `[3, 1, 1]` layout).
#[derive(Default)]
struct ImageStats {
    sum: [f64; 3],
    sq: [f64; 3],
    min: [u8; 3],
    max: [u8; 3],
    pixels: u64,
    frames: u64,
}

impl ImageStats {
    fn push(&mut self, rgb: &[u8]) {
        if self.frames == 0 {
            self.min = [255; 3];
            self.max = [0; 3];
        }
        for px in rgb.chunks_exact(3) {
            for (c, &v) in px.iter().enumerate() {
                self.sum[c] += v as f64 / 255.0;
                self.sq[c] += (v as f64 / 255.0).powi(2);
                self.min[c] = self.min[c].min(v);
                self.max[c] = self.max[c].max(v);
            }
        }
        self.pixels += (rgb.len() / 3) as u64;
        self.frames += 1;
    }

    fn to_json(&self) -> Value {
        let n = self.pixels.max(1) as f64;
        let ch = |f: &dyn Fn(usize) -> f64| json!((0..3).map(|c| [[f(c)]]).collect::<Vec<_>>());
        json!({
            "min": ch(&|c| self.min[c] as f64 / 255.0),
            "max": ch(&|c| self.max[c] as f64 / 255.0),
            "mean": ch(&|c| self.sum[c] / n),
            "std": ch(&|c| (self.sq[c] / n - (self.sum[c] / n).powi(2)).max(0.0).sqrt()),
            "count": [self.frames],
        })
    }
}

/// Rows of the per-object and per-part features: the most objects, and the most articulated
/// parts (drawer handles, knobs: episode schema 3), of any episode's frame.
#[derive(Clone, Copy, Debug, Default)]
struct Rows {
    obj: usize,
    part: usize,
}

/// The numeric per-frame features we write besides the videos: name, dtype, shape. The parts'
/// features are written only when some episode has parts.
fn numeric_features(rows: Rows) -> Vec<(&'static str, &'static str, Vec<usize>)> {
    let Rows {
        obj: n_obj,
        part: n_part,
    } = rows;
    let mut features = vec![
        ("observation.state", "float32", vec![8]),
        ("observation.joint_state", "float32", vec![7]),
        ("action", "float32", vec![7]),
        ("observation.objects.pose", "float32", vec![n_obj, 7]),
        ("observation.objects.box", "float32", vec![n_obj, 4]),
        ("observation.objects.visible", "float32", vec![n_obj]),
        ("observation.objects.grasped", "float32", vec![n_obj]),
        ("observation.objects.instance_id", "int64", vec![n_obj]),
    ];
    if n_part > 0 {
        features.extend([
            ("observation.parts.pose", "float32", vec![n_part, 7]),
            ("observation.parts.joint", "float32", vec![n_part]),
            ("observation.parts.object", "int64", vec![n_part]),
        ]);
    }
    features.extend([
        ("subgoal.satisfied", "int64", vec![1]),
        ("subgoal.total", "int64", vec![1]),
        ("timestamp", "float32", vec![1]),
        ("frame_index", "int64", vec![1]),
        ("episode_index", "int64", vec![1]),
        ("index", "int64", vec![1]),
        ("task_index", "int64", vec![1]),
    ]);
    features
}

/// A frame's parts, objects in order and each object's parts in order: (object row, part).
fn frame_parts(s: &StepRecord) -> impl Iterator<Item = (usize, &PartState)> {
    s.objects
        .iter()
        .enumerate()
        .flat_map(|(i, o)| o.parts.iter().map(move |p| (i, p)))
}

/// One frame's numbers, in the order of [`numeric_features`].
fn frame_values(
    s: &StepRecord,
    rows: Rows,
    fps: f64,
    episode: usize,
    index: u64,
    task: usize,
) -> Vec<Vec<f64>> {
    let n_obj = rows.obj;
    let mut pose = vec![0.0; n_obj * 7];
    let mut bbox = vec![0.0; n_obj * 4];
    let mut visible = vec![0.0; n_obj];
    let mut grasped = vec![0.0; n_obj];
    let mut ids = vec![-1.0; n_obj];
    for (i, o) in s.objects.iter().enumerate().take(n_obj) {
        if let Some(p) = o.pose {
            for (d, v) in p.iter().enumerate() {
                pose[i * 7 + d] = *v as f64;
            }
        }
        for (d, v) in o.bbox.iter().enumerate() {
            bbox[i * 4 + d] = *v as f64;
        }
        visible[i] = o.visible as u8 as f64;
        grasped[i] = o.grasped.unwrap_or(false) as u8 as f64;
        ids[i] = o.instance_id as f64;
    }
    let mut values = vec![
        s.state.iter().map(|v| *v as f64).collect(),
        s.joint_state.iter().map(|v| *v as f64).collect(),
        s.action.iter().map(|v| *v as f64).collect(),
        pose,
        bbox,
        visible,
        grasped,
        ids,
    ];
    if rows.part > 0 {
        let mut part_pose = vec![0.0; rows.part * 7];
        let mut joint = vec![0.0; rows.part];
        let mut owner = vec![-1.0; rows.part];
        for (j, (i, p)) in frame_parts(s).enumerate().take(rows.part) {
            for (d, v) in p.pose.iter().enumerate() {
                part_pose[j * 7 + d] = *v as f64;
            }
            joint[j] = p.joint as f64;
            owner[j] = i as f64;
        }
        values.extend([part_pose, joint, owner]);
    }
    values.extend([
        vec![s.progress.satisfied as f64],
        vec![s.progress.total as f64],
        vec![(s.step as f64 / fps) as f32 as f64],
        vec![s.step as f64],
        vec![episode as f64],
        vec![index as f64],
        vec![task as f64],
    ]);
    values
}

/// Arrow type of a feature as LeRobot's `datasets` features store it: a scalar for `[1]`, a
/// fixed-size list for `[n]`, a list of lists for `[n, m]` (`Array2D`).
fn arrow_type(dtype: &str, shape: &[usize]) -> DataType {
    let scalar = match dtype {
        "float32" => DataType::Float32,
        "float64" => DataType::Float64,
        "int64" => DataType::Int64,
        _ => DataType::Utf8,
    };
    match shape {
        [1] => scalar,
        [n] => DataType::FixedSizeList(Arc::new(Field::new("element", scalar, true)), *n as i32),
        _ => DataType::List(Arc::new(Field::new(
            "element",
            DataType::List(Arc::new(Field::new("element", scalar, true))),
            true,
        ))),
    }
}

/// The `datasets` feature description of a column (the parquet's `huggingface` metadata).
fn hf_feature(dtype: &str, shape: &[usize]) -> Value {
    let dt = if dtype == "string" { "string" } else { dtype };
    match shape {
        [1] => json!({"dtype": dt, "_type": "Value"}),
        [n] => json!({"feature": {"dtype": dt, "_type": "Value"}, "length": n, "_type": "List"}),
        _ => json!({"shape": shape, "dtype": dt, "_type": "Array2D"}),
    }
}

/// Column builders of one data file.
struct DataColumns {
    dims: Rows,
    numeric: Vec<Vec<f64>>,
    rows: usize,
    current: Vec<String>,
    labels: Vec<String>,
    done: Vec<String>,
    bytes: u64,
}

impl DataColumns {
    fn new(dims: Rows) -> Self {
        DataColumns {
            dims,
            numeric: vec![Vec::new(); numeric_features(dims).len()],
            rows: 0,
            current: Vec::new(),
            labels: Vec::new(),
            done: Vec::new(),
            bytes: 0,
        }
    }

    fn push(
        &mut self,
        values: Vec<Vec<f64>>,
        progress: &GoalProgress,
        objects: &[ObjectAnnotation],
    ) {
        for (col, v) in self.numeric.iter_mut().zip(values) {
            self.bytes += 4 * v.len() as u64;
            col.extend(v);
        }
        self.current.push(progress.current_subgoal.clone());
        let labels: Vec<&str> = objects.iter().map(|o| o.subgoal_label.as_str()).collect();
        let text = serde_json::to_string(&labels).unwrap_or_default();
        self.bytes += (progress.current_subgoal.len() + text.len()) as u64;
        self.labels.push(text);
        let done = serde_json::to_string(&progress.satisfied_subgoals).unwrap_or_default();
        self.bytes += done.len() as u64;
        self.done.push(done);
        self.rows += 1;
    }

    /// The schema of the data files.
    fn schema(dims: Rows) -> Schema {
        let mut fields = Vec::new();
        let mut hf = serde_json::Map::new();
        for (name, dtype, shape) in numeric_features(dims) {
            let mut f = Field::new(name, arrow_type(dtype, &shape), false);
            if shape.len() == 2 {
                let meta: std::collections::HashMap<String, String> = [
                    (
                        "ARROW:extension:name".to_string(),
                        "datasets.features.features.Array2DExtensionType".to_string(),
                    ),
                    (
                        "ARROW:extension:metadata".to_string(),
                        json!([shape, dtype]).to_string(),
                    ),
                ]
                .into();
                f = f.with_metadata(meta);
            }
            fields.push(f);
            hf.insert(name.into(), hf_feature(dtype, &shape));
        }
        for name in TEXT_FEATURES {
            fields.push(Field::new(name, DataType::Utf8, false));
            hf.insert(name.into(), hf_feature("string", &[1]));
        }
        let meta: std::collections::HashMap<String, String> = [(
            "huggingface".to_string(),
            json!({"info": {"features": Value::Object(hf)}}).to_string(),
        )]
        .into();
        Schema::new(fields).with_metadata(meta)
    }

    fn batch(self) -> std::result::Result<RecordBatch, arrow_schema::ArrowError> {
        let schema = Arc::new(Self::schema(self.dims));
        let mut cols: Vec<ArrayRef> = Vec::new();
        for ((_, dtype, shape), flat) in numeric_features(self.dims).iter().zip(&self.numeric) {
            cols.push(column(dtype, shape, flat, self.rows));
        }
        let mut cur = StringBuilder::new();
        for s in &self.current {
            cur.append_value(s);
        }
        let mut lab = StringBuilder::new();
        for s in &self.labels {
            lab.append_value(s);
        }
        let mut done = StringBuilder::new();
        for s in &self.done {
            done.append_value(s);
        }
        cols.push(Arc::new(cur.finish()));
        cols.push(Arc::new(lab.finish()));
        cols.push(Arc::new(done.finish()));
        RecordBatch::try_new(schema, cols)
    }
}

/// One column of `rows` frames from row-major values.
fn column(dtype: &str, shape: &[usize], flat: &[f64], rows: usize) -> ArrayRef {
    let per: usize = shape.iter().product();
    match (dtype, shape) {
        ("float32", [1]) => Arc::new(
            flat.iter()
                .map(|v| *v as f32)
                .collect::<arrow_array::Float32Array>(),
        ),
        (_, [1]) => Arc::new(
            flat.iter()
                .map(|v| *v as i64)
                .collect::<arrow_array::Int64Array>(),
        ),
        ("float32", [n]) => {
            let mut b = FixedSizeListBuilder::new(Float32Builder::new(), *n as i32)
                .with_field(Arc::new(Field::new("element", DataType::Float32, true)));
            for r in 0..rows {
                for v in &flat[r * per..(r + 1) * per] {
                    b.values().append_value(*v as f32);
                }
                b.append(true);
            }
            Arc::new(b.finish())
        }
        (_, [n]) => {
            let mut b = FixedSizeListBuilder::new(Int64Builder::new(), *n as i32)
                .with_field(Arc::new(Field::new("element", DataType::Int64, true)));
            for r in 0..rows {
                for v in &flat[r * per..(r + 1) * per] {
                    b.values().append_value(*v as i64);
                }
                b.append(true);
            }
            Arc::new(b.finish())
        }
        (_, [_, m]) => {
            let inner = ListBuilder::new(Float32Builder::new()).with_field(Arc::new(Field::new(
                "element",
                DataType::Float32,
                true,
            )));
            let mut b = ListBuilder::new(inner).with_field(Arc::new(Field::new(
                "element",
                DataType::List(Arc::new(Field::new("element", DataType::Float32, true))),
                true,
            )));
            for r in 0..rows {
                for obj in flat[r * per..(r + 1) * per].chunks(*m) {
                    for v in obj {
                        b.values().values().append_value(*v as f32);
                    }
                    b.values().append(true);
                }
                b.append(true);
            }
            Arc::new(b.finish())
        }
        _ => unreachable!("features have one or two dimensions"),
    }
}

/// Writes `batch` to `path` as one parquet file (zstd).
fn write_parquet(path: &Path, batch: &RecordBatch) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    }
    let file = File::create(path).map_err(|e| DataError::io(path, e))?;
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("valid level"),
        ))
        .build();
    let mut w =
        ArrowWriter::try_new(file, batch.schema(), Some(props)).map_err(|e| pq_err(path, e))?;
    w.write(batch).map_err(|e| pq_err(path, e))?;
    w.close().map_err(|e| pq_err(path, e))?;
    Ok(())
}

/// Video writers of both cameras for the current video file.
struct Videos {
    writers: [Option<VideoWriter>; 2],
    pos: (usize, usize),
    frames: u64,
    files: usize,
}

/// Exports dataset `dir` (its `index.json`; train episodes first, then validation) as a
/// LeRobotDataset v3.0 directory `out`, which must not exist yet. Written into a temporary
/// directory beside `out` and renamed at the end: a failed export leaves nothing at `out`.
pub fn export(dir: &Path, out: &Path, opts: &ExportOptions) -> Result<ExportReport> {
    if out.exists() {
        return Err(DataError::Argument(format!(
            "{}: already exists (the export writes a new directory)",
            out.display()
        )));
    }
    let index = DatasetIndex::load(dir)?;
    let mut order: Vec<usize> = index.split(Split::Train).iter().map(|(i, _)| *i).collect();
    let n_train = order.len();
    order.extend(index.split(Split::Val).iter().map(|(i, _)| *i));
    if order.is_empty() {
        return Err(invalid(&dir.join("index.json"), "no episodes"));
    }
    // First pass: image size and the most objects and parts of any episode.
    let mut dims = Rows::default();
    let mut size = None;
    for &i in &order {
        let r = index.episodes[i].open(dir)?;
        let s = r.read_step(0)?;
        dims.obj = dims.obj.max(s.objects.len());
        dims.part = dims.part.max(frame_parts(&s).count());
        let wh = (s.agentview.width, s.agentview.height);
        let path = r.path().to_path_buf();
        if (s.eye_in_hand.width, s.eye_in_hand.height) != wh {
            return Err(invalid(&path, "the two cameras differ in size"));
        }
        match size {
            None => size = Some(wh),
            Some(prev) if prev != wh => {
                return Err(invalid(
                    &path,
                    format!(
                        "images {}×{}, other episodes {}×{}: one size per dataset",
                        wh.0, wh.1, prev.0, prev.1
                    ),
                ));
            }
            _ => {}
        }
    }
    let (w, h) = size.expect("at least one episode");
    let fps = index.fps;
    if fps <= 0.0 || fps.fract() != 0.0 {
        return Err(invalid(
            &dir.join("index.json"),
            format!("fps {fps}: LeRobot needs a whole number"),
        ));
    }
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
    let tmp = tempfile::Builder::new()
        .prefix(".lerobot-")
        .tempdir_in(parent)
        .map_err(|e| DataError::io(parent, e))?;
    let root = tmp.path();

    let mut tasks: Vec<String> = Vec::new();
    let mut stats: Vec<FeatureStats> = (0..numeric_features(dims).len())
        .map(|_| FeatureStats::default())
        .collect();
    let mut img_stats = [ImageStats::default(), ImageStats::default()];
    let mut episodes_rows: Vec<BTreeMap<String, Value>> = Vec::new();
    let mut data = DataColumns::new(dims);
    let mut data_pos = (0usize, 0usize);
    let mut data_files = 0usize;
    let mut data_start_row = 0u64;
    let mut videos = Videos {
        writers: [None, None],
        pos: (0, 0),
        frames: 0,
        files: 0,
    };
    let vopts = VideoOptions {
        keyframe_every: opts.keyframe_every,
        every_frame: true,
    };
    let mut index_row = 0u64;
    for (e, &i) in order.iter().enumerate() {
        let entry = &index.episodes[i];
        let reader = entry.open(dir)?;
        let steps = reader.read_all()?;
        let meta = reader.meta().clone();
        let task = match tasks.iter().position(|t| *t == meta.instruction) {
            Some(t) => t,
            None => {
                tasks.push(meta.instruction.clone());
                tasks.len() - 1
            }
        };
        // Video files: a new one once the current passed its limit.
        if videos.writers[0].is_some()
            && videos
                .writers
                .iter()
                .flatten()
                .map(|v| v.bytes())
                .max()
                .unwrap_or(0)
                > opts.video_file_mb * 1024 * 1024
        {
            for v in videos.writers.iter_mut() {
                v.take().expect("open").finish()?;
            }
            videos.pos = next_file(videos.pos);
            videos.frames = 0;
        }
        if videos.writers[0].is_none() {
            for (c, key) in [IMAGE_KEY, WRIST_KEY].iter().enumerate() {
                let p = root.join(chunk_path(VIDEO_PATH, key, videos.pos.0, videos.pos.1));
                videos.writers[c] = Some(VideoWriter::create_with(
                    &p, w as usize, h as usize, fps as u32, vopts,
                )?);
            }
            videos.files += 1;
        }
        let from_ts = videos.frames as f64 / fps;
        for v in videos.writers.iter_mut().flatten() {
            v.force_keyframe();
        }
        let from_row = index_row;
        for s in &steps {
            for (c, img) in [&s.agentview, &s.eye_in_hand].into_iter().enumerate() {
                if (img.width, img.height) != (w, h) {
                    return Err(invalid(
                        reader.path(),
                        format!(
                            "step {}: image {}×{}, expected {w}×{h}",
                            s.step, img.width, img.height
                        ),
                    ));
                }
                let mut px = img.data.clone();
                apply_flip(&mut px, w as usize, h as usize, 3, opts.flip);
                img_stats[c].push(&px);
                videos.writers[c].as_mut().expect("open").push(&px)?;
            }
            let n_parts = frame_parts(s).count();
            if s.objects.len() > dims.obj || n_parts > dims.part {
                return Err(invalid(
                    reader.path(),
                    format!(
                        "step {}: {} objects and {n_parts} parts, step 0 of the dataset's \
                         episodes at most {} and {}",
                        s.step,
                        s.objects.len(),
                        dims.obj,
                        dims.part
                    ),
                ));
            }
            let values = frame_values(s, dims, fps, e, index_row, task);
            for (st, v) in stats.iter_mut().zip(&values) {
                st.push(v);
            }
            data.push(values, &s.progress, &s.objects);
            index_row += 1;
        }
        videos.frames += steps.len() as u64;
        let objects: Vec<Value> = steps
            .first()
            .map(|s| s.objects.iter().map(|o| json!(o.name)).collect())
            .unwrap_or_default();
        let mut row = BTreeMap::new();
        row.insert("episode_index".into(), json!(e));
        row.insert("tasks".into(), json!([meta.instruction]));
        row.insert("length".into(), json!(steps.len()));
        row.insert("data/chunk_index".into(), json!(data_pos.0));
        row.insert("data/file_index".into(), json!(data_pos.1));
        row.insert("dataset_from_index".into(), json!(from_row));
        row.insert("dataset_to_index".into(), json!(index_row));
        for key in [IMAGE_KEY, WRIST_KEY] {
            row.insert(format!("videos/{key}/chunk_index"), json!(videos.pos.0));
            row.insert(format!("videos/{key}/file_index"), json!(videos.pos.1));
            row.insert(format!("videos/{key}/from_timestamp"), json!(from_ts));
            row.insert(
                format!("videos/{key}/to_timestamp"),
                json!(videos.frames as f64 / fps),
            );
        }
        row.insert("meta/episodes/chunk_index".into(), json!(0));
        row.insert("meta/episodes/file_index".into(), json!(0));
        row.insert("libero_mem/task_id".into(), json!(meta.task_id));
        row.insert("libero_mem/seed".into(), json!(meta.seed as i64));
        row.insert("libero_mem/source_file".into(), json!(entry.file));
        row.insert("libero_mem/objects".into(), Value::Array(objects));
        if dims.part > 0 {
            let parts: Vec<Value> = steps
                .first()
                .map(|s| frame_parts(s).map(|(_, p)| json!(p.name)).collect())
                .unwrap_or_default();
            row.insert("libero_mem/parts".into(), Value::Array(parts));
        }
        episodes_rows.push(row);
        // Data files: a new one once the current passed its limit.
        if data.bytes > opts.data_file_mb * 1024 * 1024 || e + 1 == order.len() {
            let p = root.join(chunk_path(DATA_PATH, "", data_pos.0, data_pos.1));
            let batch = std::mem::replace(&mut data, DataColumns::new(dims))
                .batch()
                .map_err(|err| pq_err(&p, err))?;
            debug_assert_eq!(batch.num_rows() as u64, index_row - data_start_row);
            write_parquet(&p, &batch)?;
            data_files += 1;
            data_pos = next_file(data_pos);
            data_start_row = index_row;
        }
        if opts.progress && (e + 1) % 100 == 0 {
            eprintln!("exported {} of {} episodes", e + 1, order.len());
        }
    }
    for v in videos.writers.iter_mut() {
        if let Some(v) = v.take() {
            v.finish()?;
        }
    }

    // meta/tasks.parquet: the task text as the pandas index, as LeRobot writes it.
    write_tasks(&root.join("meta/tasks.parquet"), &tasks)?;
    write_episodes(
        &root.join("meta/episodes/chunk-000/file-000.parquet"),
        &episodes_rows,
    )?;

    let mut features = serde_json::Map::new();
    for (key, cam) in [(IMAGE_KEY, "agentview"), (WRIST_KEY, "eye_in_hand")] {
        features.insert(
            key.into(),
            json!({
                "dtype": "video",
                "shape": [h, w, 3],
                "names": ["height", "width", "channel"],
                "info": {
                    "video.height": h, "video.width": w, "video.codec": "h264",
                    "video.pix_fmt": "yuv420p", "video.is_depth_map": false,
                    "video.fps": fps as u32, "video.channels": 3, "has_audio": false,
                    "libero_mem.camera": cam,
                }
            }),
        );
    }
    let names: BTreeMap<&str, Value> = [
        (
            "observation.state",
            json!([
                "eef_x",
                "eef_y",
                "eef_z",
                "eef_axis_angle_x",
                "eef_axis_angle_y",
                "eef_axis_angle_z",
                "gripper_finger_left",
                "gripper_finger_right"
            ]),
        ),
        (
            "observation.joint_state",
            json!([
                "joint_0", "joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6"
            ]),
        ),
        (
            "action",
            json!([
                "dx",
                "dy",
                "dz",
                "d_axis_angle_x",
                "d_axis_angle_y",
                "d_axis_angle_z",
                "gripper"
            ]),
        ),
        (
            "observation.objects.pose",
            json!(["object", "x_y_z_qw_qx_qy_qz"]),
        ),
        ("observation.objects.box", json!(["object", "x_y_w_h"])),
        (
            "observation.parts.pose",
            json!(["part", "x_y_z_qw_qx_qy_qz"]),
        ),
    ]
    .into();
    let mut stats_json = serde_json::Map::new();
    for ((name, dtype, shape), st) in numeric_features(dims).iter().zip(&stats) {
        features.insert(
            (*name).into(),
            json!({"dtype": dtype, "shape": shape, "names": names.get(name).cloned().unwrap_or(Value::Null)}),
        );
        stats_json.insert((*name).into(), st.to_json(shape));
    }
    for name in TEXT_FEATURES {
        features.insert(
            name.into(),
            json!({"dtype": "string", "shape": [1], "names": null}),
        );
    }
    for (c, key) in [IMAGE_KEY, WRIST_KEY].iter().enumerate() {
        stats_json.insert((*key).into(), img_stats[c].to_json());
    }
    let n = order.len();
    let mut splits = serde_json::Map::new();
    splits.insert("train".into(), json!(format!("0:{n_train}")));
    if n_train < n {
        splits.insert("val".into(), json!(format!("{n_train}:{n}")));
    }
    let info = json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": opts.robot_type,
        "total_episodes": n,
        "total_frames": index_row,
        "total_tasks": tasks.len(),
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": opts.data_file_mb,
        "video_files_size_in_mb": opts.video_file_mb,
        "fps": fps as u32,
        "splits": Value::Object(splits),
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH,
        "features": Value::Object(features),
        "libero_mem": {
            "exported_from": "libero-mem-rs",
            "image_flip": opts.flip.name(),
            "max_objects": dims.obj,
            "max_parts": dims.part,
        },
    });
    let write_json = |p: &Path, v: &Value| -> Result<()> {
        let text =
            serde_json::to_string_pretty(v).map_err(|e| DataError::Argument(e.to_string()))?;
        std::fs::write(p, text).map_err(|e| DataError::io(p, e))
    };
    write_json(&root.join("meta/info.json"), &info)?;
    write_json(&root.join("meta/stats.json"), &Value::Object(stats_json))?;
    let tmp_path = tmp.keep();
    std::fs::rename(&tmp_path, out).map_err(|e| {
        let _ = std::fs::remove_dir_all(&tmp_path);
        DataError::io(out, e)
    })?;
    Ok(ExportReport {
        episodes: n,
        frames: index_row,
        tasks: tasks.len(),
        data_files,
        video_files: videos.files,
    })
}

/// `meta/tasks.parquet`: column `task_index` and the task text as the pandas index.
fn write_tasks(path: &Path, tasks: &[String]) -> Result<()> {
    let pandas = json!({
        "index_columns": ["__index_level_0__"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode", "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": null, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}
        ],
        "attributes": {},
        "creator": {"library": "libero-mem-rs", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.0.0"
    });
    let schema = Arc::new(
        Schema::new(vec![
            Field::new("task_index", DataType::Int64, false),
            Field::new("__index_level_0__", DataType::Utf8, false),
        ])
        .with_metadata(std::collections::HashMap::from([(
            "pandas".to_string(),
            pandas.to_string(),
        )])),
    );
    let idx: arrow_array::Int64Array = (0..tasks.len() as i64).collect();
    let text: arrow_array::StringArray = tasks.iter().map(|t| Some(t.as_str())).collect();
    let batch = RecordBatch::try_new(schema, vec![Arc::new(idx), Arc::new(text)])
        .map_err(|e| pq_err(path, e))?;
    write_parquet(path, &batch)
}

/// `meta/episodes/…parquet` from rows of JSON values (ints, floats, strings, string lists).
fn write_episodes(path: &Path, rows: &[BTreeMap<String, Value>]) -> Result<()> {
    let first = rows.first().expect("at least one episode");
    // LeRobot's column order first, then ours.
    let mut keys: Vec<&String> = first.keys().collect();
    keys.sort_by_key(|k| {
        let order = [
            "episode_index",
            "tasks",
            "length",
            "data/chunk_index",
            "data/file_index",
            "dataset_from_index",
            "dataset_to_index",
        ];
        let rank = order
            .iter()
            .position(|o| o == k)
            .unwrap_or(if k.starts_with("videos/") {
                order.len()
            } else if k.starts_with("meta/") {
                order.len() + 1
            } else {
                order.len() + 2
            });
        (rank, (*k).clone())
    });
    let mut fields = Vec::new();
    let mut cols: Vec<ArrayRef> = Vec::new();
    for k in keys {
        let vals: Vec<&Value> = rows.iter().map(|r| &r[k.as_str()]).collect();
        match vals[0] {
            Value::Array(_) => {
                let mut b = ListBuilder::new(StringBuilder::new())
                    .with_field(Arc::new(Field::new("element", DataType::Utf8, true)));
                for v in &vals {
                    for s in v.as_array().into_iter().flatten() {
                        b.values().append_value(s.as_str().unwrap_or_default());
                    }
                    b.append(true);
                }
                fields.push(Field::new(
                    k.as_str(),
                    DataType::List(Arc::new(Field::new("element", DataType::Utf8, true))),
                    false,
                ));
                cols.push(Arc::new(b.finish()));
            }
            Value::String(_) => {
                let mut b = StringBuilder::new();
                for v in &vals {
                    b.append_value(v.as_str().unwrap_or_default());
                }
                fields.push(Field::new(k.as_str(), DataType::Utf8, false));
                cols.push(Arc::new(b.finish()));
            }
            Value::Number(n) if n.is_f64() => {
                let mut b = Float64Builder::new();
                for v in &vals {
                    b.append_value(v.as_f64().unwrap_or_default());
                }
                fields.push(Field::new(k.as_str(), DataType::Float64, false));
                cols.push(Arc::new(b.finish()));
            }
            _ => {
                let mut b = Int64Builder::new();
                for v in &vals {
                    b.append_value(v.as_i64().unwrap_or_default());
                }
                fields.push(Field::new(k.as_str(), DataType::Int64, false));
                cols.push(Arc::new(b.finish()));
            }
        }
    }
    let batch =
        RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).map_err(|e| pq_err(path, e))?;
    write_parquet(path, &batch)
}

// ---------------------------------------------------------------------------------------------
// Import

/// How [`import`] reads.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Transform from the stored frames to upright ones (None: from `info.json`'s
    /// `libero_mem.image_flip` when we exported it, else `Horizontal`, LeRobot's LIBERO layout).
    pub flip: Option<Flip>,
    /// Fraction of episodes in the validation split of the new dataset.
    pub val_fraction: f64,
    /// The `ffmpeg` program that decodes the videos (any codec it knows: AV1, H.264…).
    pub ffmpeg: PathBuf,
    /// How the episodes' frames are stored.
    pub writer: WriterOptions,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            flip: None,
            val_fraction: 0.05,
            ffmpeg: PathBuf::from("ffmpeg"),
            writer: WriterOptions::default(),
        }
    }
}

/// What [`import`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportReport {
    /// Episodes written.
    pub episodes: usize,
    /// Frames written.
    pub frames: u64,
}

/// One episode's row of `meta/episodes`.
#[derive(Clone, Debug)]
struct EpisodeRow {
    index: i64,
    task: String,
    length: usize,
    data_file: (i64, i64),
    from: i64,
    videos: Vec<(String, (i64, i64), f64)>,
    task_id: Option<String>,
    seed: Option<i64>,
    objects: Vec<String>,
    parts: Vec<String>,
}

/// All record batches of a parquet file.
fn read_parquet(path: &Path) -> Result<Vec<RecordBatch>> {
    let file = File::open(path).map_err(|e| DataError::io(path, e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| pq_err(path, e))?
        .with_batch_size(8192)
        .build()
        .map_err(|e| pq_err(path, e))?;
    reader
        .map(|b| b.map_err(|e| pq_err(path, e)))
        .collect::<Result<Vec<_>>>()
}

fn col<'a>(b: &'a RecordBatch, name: &str, path: &Path) -> Result<&'a ArrayRef> {
    b.column_by_name(name)
        .ok_or_else(|| invalid(path, format!("no column `{name}`")))
}

fn int_at(a: &ArrayRef, row: usize, name: &str, path: &Path) -> Result<i64> {
    match a.data_type() {
        DataType::Int64 => Ok(a.as_primitive::<Int64Type>().value(row)),
        DataType::Int32 => Ok(a.as_primitive::<arrow_array::types::Int32Type>().value(row) as i64),
        t => Err(invalid(
            path,
            format!("column `{name}`: {t}, expected an integer"),
        )),
    }
}

fn str_at(a: &ArrayRef, row: usize) -> Option<String> {
    match a.data_type() {
        DataType::Utf8 => Some(a.as_string::<i32>().value(row).to_string()),
        DataType::LargeUtf8 => Some(a.as_string::<i64>().value(row).to_string()),
        _ => None,
    }
}

/// Row `row` of a numeric column as f64 values (scalar, fixed-size or variable list, nested).
fn floats_at(a: &ArrayRef, row: usize) -> Option<Vec<f64>> {
    if a.is_null(row) {
        return None;
    }
    Some(match a.data_type() {
        DataType::Float32 => vec![a.as_primitive::<Float32Type>().value(row) as f64],
        DataType::Float64 => vec![a.as_primitive::<Float64Type>().value(row)],
        DataType::Int64 => vec![a.as_primitive::<Int64Type>().value(row) as f64],
        DataType::FixedSizeList(_, _) => flatten(&a.as_fixed_size_list().value(row))?,
        DataType::List(_) => flatten(&a.as_list::<i32>().value(row))?,
        DataType::LargeList(_) => flatten(&a.as_list::<i64>().value(row))?,
        _ => return None,
    })
}

fn flatten(a: &ArrayRef) -> Option<Vec<f64>> {
    let mut out = Vec::new();
    for r in 0..a.len() {
        out.extend(floats_at(a, r)?);
    }
    Some(out)
}

/// Decodes every frame of `video` from `start` seconds on (`count` frames, `[H, W, 3]` each)
/// with ffmpeg.
fn decode_frames(
    ffmpeg: &Path,
    video: &Path,
    start: f64,
    count: usize,
    w: usize,
    h: usize,
) -> Result<Vec<Vec<u8>>> {
    let out = std::process::Command::new(ffmpeg)
        .args(["-v", "error", "-nostdin", "-ss"])
        .arg(format!("{start:.6}"))
        .arg("-i")
        .arg(video)
        .args([
            "-frames:v",
            &count.to_string(),
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-",
        ])
        .output()
        .map_err(|e| {
            invalid(
                video,
                format!(
                    "could not run `{}` to decode it: {e} (install ffmpeg or pass --ffmpeg)",
                    ffmpeg.display()
                ),
            )
        })?;
    if !out.status.success() {
        return Err(invalid(
            video,
            format!(
                "ffmpeg failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        ));
    }
    let frame = w * h * 3;
    if out.stdout.len() != frame * count {
        return Err(invalid(
            video,
            format!(
                "{} frames of {w}×{h} from {start:.3} s, expected {count}",
                out.stdout.len() / frame.max(1)
            ),
        ));
    }
    Ok(out.stdout.chunks(frame).map(|c| c.to_vec()).collect())
}

/// Reads a LeRobotDataset v3.0 directory `root` (LeRobot's LIBERO layout: `observation.images.image`,
/// `observation.images.wrist_image`, `observation.state` (8), `action` (7); our extras when
/// present) into a dataset directory `out` of mcap episodes with an `index.json`. Every file the
/// metadata names is checked before anything is written.
pub fn import(root: &Path, out: &Path, opts: &ImportOptions) -> Result<ImportReport> {
    let info_path = root.join("meta/info.json");
    let text = std::fs::read_to_string(&info_path).map_err(|e| DataError::io(&info_path, e))?;
    let info: Value = serde_json::from_str(&text).map_err(|e| {
        invalid(
            &info_path,
            format!("line {}, column {}: {e}", e.line(), e.column()),
        )
    })?;
    let version = info["codebase_version"].as_str().unwrap_or("");
    if !version.starts_with("v3.") {
        return Err(invalid(
            &info_path,
            format!("codebase_version `{version}`: only LeRobotDataset v3 is read"),
        ));
    }
    let fps = info["fps"]
        .as_f64()
        .filter(|f| *f > 0.0)
        .ok_or_else(|| invalid(&info_path, "no positive `fps`"))?;
    let data_tpl = info["data_path"].as_str().unwrap_or(DATA_PATH).to_string();
    let video_tpl = info["video_path"]
        .as_str()
        .unwrap_or(VIDEO_PATH)
        .to_string();
    let feats = info["features"]
        .as_object()
        .ok_or_else(|| invalid(&info_path, "no `features`"))?;
    for (key, dims) in [("observation.state", 8), ("action", 7)] {
        let shape = feats
            .get(key)
            .and_then(|f| f["shape"].as_array())
            .ok_or_else(|| invalid(&info_path, format!("no feature `{key}`")))?;
        if shape.len() != 1 || shape[0].as_u64() != Some(dims) {
            return Err(invalid(
                &info_path,
                format!("feature `{key}`: shape {shape:?}, expected [{dims}]"),
            ));
        }
    }
    let mut cams = Vec::new();
    for key in [IMAGE_KEY, WRIST_KEY] {
        let f = feats
            .get(key)
            .ok_or_else(|| invalid(&info_path, format!("no feature `{key}`")))?;
        if f["dtype"] != "video" {
            return Err(invalid(
                &info_path,
                format!(
                    "feature `{key}`: dtype {}, only videos are read",
                    f["dtype"]
                ),
            ));
        }
        let shape: Vec<usize> = f["shape"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_u64().map(|v| v as usize))
                    .collect()
            })
            .unwrap_or_default();
        let names: Vec<&str> = f["names"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_str()).collect())
            .unwrap_or_default();
        let (h, w) = match (shape.as_slice(), names.first()) {
            ([c, h, w], Some(&"channels")) | ([c, h, w], Some(&"channel")) if *c == 3 => (*h, *w),
            ([h, w, 3], _) => (*h, *w),
            _ => {
                return Err(invalid(
                    &info_path,
                    format!("feature `{key}`: shape {shape:?}, expected [H, W, 3]"),
                ));
            }
        };
        cams.push((key, w, h));
    }
    let flip = opts
        .flip
        .unwrap_or(match info["libero_mem"]["image_flip"].as_str() {
            Some("none") => Flip::None,
            Some("vflip") => Flip::Vertical,
            Some("rot180") => Flip::Rotate180,
            _ => Flip::Horizontal,
        });

    // Tasks and episodes.
    let tasks_path = root.join("meta/tasks.parquet");
    let mut tasks: BTreeMap<i64, String> = BTreeMap::new();
    for b in read_parquet(&tasks_path)? {
        let idx = col(&b, "task_index", &tasks_path)?.clone();
        let text = b
            .column_by_name("__index_level_0__")
            .or_else(|| b.column_by_name("task"))
            .ok_or_else(|| {
                invalid(
                    &tasks_path,
                    "no task text column (`__index_level_0__` or `task`)",
                )
            })?;
        for r in 0..b.num_rows() {
            tasks.insert(
                int_at(&idx, r, "task_index", &tasks_path)?,
                str_at(text, r).unwrap_or_default(),
            );
        }
    }
    let ep_dir = root.join("meta/episodes");
    let mut ep_files = Vec::new();
    for chunk in std::fs::read_dir(&ep_dir).map_err(|e| DataError::io(&ep_dir, e))? {
        let chunk = chunk.map_err(|e| DataError::io(&ep_dir, e))?.path();
        if chunk.is_dir() {
            for f in std::fs::read_dir(&chunk).map_err(|e| DataError::io(&chunk, e))? {
                let f = f.map_err(|e| DataError::io(&chunk, e))?.path();
                if f.extension().is_some_and(|x| x == "parquet") {
                    ep_files.push(f);
                }
            }
        }
    }
    ep_files.sort();
    if ep_files.is_empty() {
        return Err(invalid(&ep_dir, "no episodes parquet file"));
    }
    let mut episodes = Vec::new();
    for p in &ep_files {
        for b in read_parquet(p)? {
            let g = |name: &str| col(&b, name, p).cloned();
            let (ei, len, dc, df, from) = (
                g("episode_index")?,
                g("length")?,
                g("data/chunk_index")?,
                g("data/file_index")?,
                g("dataset_from_index")?,
            );
            let tasks_col = g("tasks")?;
            for r in 0..b.num_rows() {
                let task = match tasks_col.data_type() {
                    DataType::List(_) => {
                        let l = tasks_col.as_list::<i32>().value(r);
                        if l.is_empty() { None } else { str_at(&l, 0) }
                    }
                    _ => str_at(&tasks_col, r),
                }
                .unwrap_or_default();
                let mut videos = Vec::new();
                for (key, _, _) in &cams {
                    let c = g(&format!("videos/{key}/chunk_index"))?;
                    let f = g(&format!("videos/{key}/file_index"))?;
                    let ts = g(&format!("videos/{key}/from_timestamp"))?;
                    let from_ts = floats_at(&ts, r)
                        .and_then(|v| v.first().copied())
                        .unwrap_or(0.0);
                    videos.push((
                        key.to_string(),
                        (
                            int_at(&c, r, "chunk_index", p)?,
                            int_at(&f, r, "file_index", p)?,
                        ),
                        from_ts,
                    ));
                }
                let names = |key: &str| -> Vec<String> {
                    b.column_by_name(key)
                        .filter(|a| matches!(a.data_type(), DataType::List(_)))
                        .map(|a| {
                            let l = a.as_list::<i32>().value(r);
                            (0..l.len()).filter_map(|i| str_at(&l, i)).collect()
                        })
                        .unwrap_or_default()
                };
                let objects = names("libero_mem/objects");
                let parts = names("libero_mem/parts");
                episodes.push(EpisodeRow {
                    index: int_at(&ei, r, "episode_index", p)?,
                    task,
                    length: int_at(&len, r, "length", p)?.max(0) as usize,
                    data_file: (
                        int_at(&dc, r, "data/chunk_index", p)?,
                        int_at(&df, r, "data/file_index", p)?,
                    ),
                    from: int_at(&from, r, "dataset_from_index", p)?,
                    videos,
                    task_id: b
                        .column_by_name("libero_mem/task_id")
                        .and_then(|a| str_at(a, r)),
                    seed: b
                        .column_by_name("libero_mem/seed")
                        .and_then(|a| int_at(a, r, "seed", p).ok()),
                    objects,
                    parts,
                });
            }
        }
    }
    episodes.sort_by_key(|e| e.index);
    // Every file the metadata names exists before anything is written.
    let fill = |tpl: &str, key: &str, (c, f): (i64, i64)| {
        root.join(chunk_path(tpl, key, c.max(0) as usize, f.max(0) as usize))
    };
    for e in &episodes {
        let p = fill(&data_tpl, "", e.data_file);
        if !p.is_file() {
            return Err(invalid(
                &p,
                format!("missing (named by episode {})", e.index),
            ));
        }
        for (key, pos, _) in &e.videos {
            let p = fill(&video_tpl, key, *pos);
            if !p.is_file() {
                return Err(invalid(
                    &p,
                    format!("missing (named by episode {})", e.index),
                ));
            }
        }
    }

    std::fs::create_dir_all(out).map_err(|e| DataError::io(out, e))?;
    let mut frames = 0u64;
    let mut loaded: Option<((i64, i64), Vec<RecordBatch>, i64)> = None;
    for e in &episodes {
        let p = fill(&data_tpl, "", e.data_file);
        if loaded.as_ref().map(|l| l.0) != Some(e.data_file) {
            let batches = read_parquet(&p)?;
            // The first global index in the file.
            let first = batches
                .first()
                .and_then(|b| b.column_by_name("index").map(|a| int_at(a, 0, "index", &p)))
                .transpose()?
                .unwrap_or(e.from);
            loaded = Some((e.data_file, batches, first));
        }
        let (_, batches, first) = loaded.as_ref().expect("loaded");
        let mut rows: Vec<(&RecordBatch, usize)> = Vec::new();
        let mut skip = (e.from - first).max(0) as usize;
        for b in batches {
            if skip >= b.num_rows() {
                skip -= b.num_rows();
                continue;
            }
            for r in skip..b.num_rows() {
                if rows.len() == e.length {
                    break;
                }
                rows.push((b, r));
            }
            skip = 0;
        }
        if rows.len() != e.length {
            return Err(invalid(
                &p,
                format!(
                    "episode {}: {} rows, the episodes table says {}",
                    e.index,
                    rows.len(),
                    e.length
                ),
            ));
        }
        let mut cam_frames = Vec::new();
        for ((key, pos, from_ts), (_, w, h)) in e.videos.iter().zip(&cams) {
            let vp = fill(&video_tpl, key, *pos);
            let mut fr = decode_frames(&opts.ffmpeg, &vp, *from_ts, e.length, *w, *h)?;
            for f in fr.iter_mut() {
                apply_flip(f, *w, *h, 3, flip);
            }
            cam_frames.push((fr, *w, *h));
        }
        let meta = EpisodeMeta {
            task_id: e.task_id.clone().unwrap_or_else(|| {
                format!(
                    "lerobot/task_{}",
                    tasks
                        .iter()
                        .find(|(_, t)| **t == e.task)
                        .map_or(0, |(i, _)| *i)
                )
            }),
            instruction: e.task.clone(),
            seed: e.seed.unwrap_or(e.index) as u64,
            sim_version: "lerobot-import:v3.0".into(),
            fps,
            extra: [
                ("source_root".to_string(), root.display().to_string()),
                ("source_episode_index".to_string(), e.index.to_string()),
                ("applied_flip".to_string(), flip.name().to_string()),
            ]
            .into(),
            ..EpisodeMeta::default()
        };
        let path = out.join(format!("episode_{:06}.mcap", e.index));
        let mut w = EpisodeWriter::create(&path, meta, opts.writer.clone())?;
        for (k, (b, r)) in rows.iter().enumerate() {
            let get = |name: &str| b.column_by_name(name).and_then(|a| floats_at(a, *r));
            let fixed = |name: &str, n: usize| -> Result<Vec<f32>> {
                let v = get(name).ok_or_else(|| {
                    invalid(&p, format!("episode {}, frame {k}: no `{name}`", e.index))
                })?;
                if v.len() != n || v.iter().any(|x| !x.is_finite()) {
                    return Err(invalid(
                        &p,
                        format!(
                            "episode {}, frame {k}: `{name}` is not {n} finite numbers",
                            e.index
                        ),
                    ));
                }
                Ok(v.into_iter().map(|x| x as f32).collect())
            };
            let state = fixed("observation.state", 8)?;
            let action = fixed("action", 7)?;
            let joint = get("observation.joint_state")
                .filter(|v| v.len() == 7)
                .unwrap_or(vec![0.0; 7]);
            let ids = get("observation.objects.instance_id").unwrap_or_default();
            let pose = get("observation.objects.pose").unwrap_or_default();
            let bbox = get("observation.objects.box").unwrap_or_default();
            let visible = get("observation.objects.visible").unwrap_or_default();
            let grasped = get("observation.objects.grasped").unwrap_or_default();
            let labels: Vec<String> = b
                .column_by_name("subgoal.labels")
                .and_then(|a| str_at(a, *r))
                .and_then(|t| serde_json::from_str(&t).ok())
                .unwrap_or_default();
            let part_pose = get("observation.parts.pose").unwrap_or_default();
            let part_joint = get("observation.parts.joint").unwrap_or_default();
            let part_object = get("observation.parts.object").unwrap_or_default();
            let mut objects = Vec::new();
            for (i, id) in ids.iter().enumerate() {
                if *id < 0.0 {
                    continue;
                }
                let parts = part_object
                    .iter()
                    .enumerate()
                    .filter(|(_, o)| **o == i as f64)
                    .map(|(j, _)| PartState {
                        name: e.parts.get(j).cloned().unwrap_or_default(),
                        pose: std::array::from_fn(|d| {
                            part_pose.get(j * 7 + d).copied().unwrap_or(0.0) as f32
                        }),
                        joint: part_joint.get(j).copied().unwrap_or(0.0) as f32,
                    })
                    .collect();
                let at =
                    |v: &[f64], d: usize, n: usize| v.get(i * n + d).copied().unwrap_or(0.0) as f32;
                objects.push(ObjectAnnotation {
                    instance_id: *id as i32,
                    name: e.objects.get(i).cloned().unwrap_or_default(),
                    bbox: [
                        at(&bbox, 0, 4),
                        at(&bbox, 1, 4),
                        at(&bbox, 2, 4),
                        at(&bbox, 3, 4),
                    ],
                    visible: at(&visible, 0, 1) > 0.5,
                    subgoal_label: labels.get(i).cloned().unwrap_or_else(|| "0".into()),
                    pose: (pose.len() >= (i + 1) * 7)
                        .then(|| std::array::from_fn(|d| at(&pose, d, 7))),
                    grasped: (grasped.len() > i).then(|| at(&grasped, 0, 1) > 0.5),
                    parts,
                });
            }
            let int = |name: &str| get(name).and_then(|v| v.first().copied()).unwrap_or(0.0) as u32;
            let current = b
                .column_by_name("subgoal.current")
                .and_then(|a| str_at(a, *r))
                .unwrap_or_default();
            let img = |c: usize| {
                let (fr, w, h) = &cam_frames[c];
                RgbImage {
                    width: *w as u32,
                    height: *h as u32,
                    channels: 3,
                    data: fr[k].clone(),
                }
            };
            let rec = StepRecord {
                step: k as u64,
                agentview: img(0),
                eye_in_hand: img(1),
                segmentation: None,
                depth: None,
                state: std::array::from_fn(|d| state[d]),
                joint_state: std::array::from_fn(|d| joint[d] as f32),
                action: std::array::from_fn(|d| action[d]),
                objects,
                progress: GoalProgress {
                    satisfied: int("subgoal.satisfied"),
                    total: int("subgoal.total"),
                    satisfied_subgoals: b
                        .column_by_name("subgoal.done")
                        .and_then(|a| str_at(a, *r))
                        .and_then(|t| serde_json::from_str(&t).ok())
                        .unwrap_or_default(),
                    current_subgoal: current,
                },
            };
            w.write_step(&rec)?;
        }
        w.finish()?;
        frames += e.length as u64;
    }
    build_index(
        out,
        &IndexOptions {
            val_fraction: opts.val_fraction,
            seed: 0,
        },
    )?;
    Ok(ImportReport {
        episodes: episodes.len(),
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_and_file_positions_follow_lerobots_templates() {
        assert_eq!(
            chunk_path(DATA_PATH, "", 0, 7),
            "data/chunk-000/file-007.parquet"
        );
        assert_eq!(
            chunk_path(VIDEO_PATH, IMAGE_KEY, 12, 3),
            "videos/observation.images.image/chunk-012/file-003.mp4"
        );
        assert_eq!(next_file((0, 5)), (0, 6));
        assert_eq!(next_file((2, CHUNKS_SIZE - 1)), (3, 0));
    }

    #[test]
    fn statistics_are_shaped_like_the_feature() {
        let mut s = FeatureStats::default();
        for k in 0..5 {
            s.push(&[k as f64, 10.0, 0.0, -(k as f64)]);
        }
        let j = s.to_json(&[2, 2]);
        assert_eq!(j["min"], json!([[0.0, 10.0], [0.0, -4.0]]));
        assert_eq!(j["max"], json!([[4.0, 10.0], [0.0, 0.0]]));
        assert_eq!(j["mean"], json!([[2.0, 10.0], [0.0, -2.0]]));
        assert_eq!(j["count"], json!([5]));
        // numpy's linear quantile: q50 of 0..4 is 2, q10 is 0.4.
        assert_eq!(j["q50"][0][0], json!(2.0));
        assert!((j["q10"][0][0].as_f64().unwrap() - 0.4).abs() < 1e-12);
        let std = j["std"][0][0].as_f64().unwrap();
        assert!((std - 2f64.sqrt()).abs() < 1e-12, "{std}");
    }
}
