//! Episode files: one mcap per episode, written by [`EpisodeWriter`] and read by [`EpisodeReader`].
//!
//! Layout (see `data/SCHEMA.md`): chunked, zstd-compressed mcap with a summary section (chunk
//! indexes, message indexes, statistics) so that readers can seek. Every message of step `k` has
//! `sequence = k` and `log_time = publish_time = round(k · 10⁹ / fps)` ns.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use foxglove::messages::{CompressedImage, RawImage, Timestamp};
use foxglove::{Decode, Encode};
use mcap::records::{ChunkIndex, MessageHeader, Metadata};

use crate::error::{DataError, Result};
use crate::imageio::{ImageCompression, decode_rgb, encode_rgb};
use crate::schema::*;

/// Options of [`EpisodeWriter`].
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// Compression of the two RGB cameras.
    pub image_compression: ImageCompression,
    /// Target uncompressed chunk size in bytes (smaller = cheaper random access).
    pub chunk_size: u64,
    /// zstd level for chunks.
    pub zstd_level: u32,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            image_compression: ImageCompression::Png,
            chunk_size: 256 * 1024,
            zstd_level: 3,
        }
    }
}

/// Nanoseconds of step `k` at `fps` Hz.
pub fn step_time_ns(k: u64, fps: f64) -> u64 {
    (k as f64 * 1e9 / fps).round() as u64
}

fn fox_time(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

#[derive(Default)]
struct Channels {
    agentview: u16,
    eye_in_hand: u16,
    state: u16,
    joint_state: u16,
    action: u16,
    objects: u16,
    goal: u16,
    segmentation: Option<(u16, &'static str)>,
    depth: Option<u16>,
    raw_schema: u16,
}

/// Writes one episode to `<path>` through a temporary file in the same directory; the final name
/// appears only after [`EpisodeWriter::finish`] succeeds.
pub struct EpisodeWriter {
    path: PathBuf,
    tmp_path: tempfile::TempPath,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    opts: WriterOptions,
    meta: EpisodeMeta,
    ch: Channels,
    steps: u64,
    size: Option<((u32, u32), (u32, u32))>,
}

fn mcap_err(path: &Path, e: mcap::McapError) -> DataError {
    match e {
        mcap::McapError::Io(source) => DataError::io(path, source),
        other => DataError::invalid(path, format!("mcap write error: {other}")),
    }
}

impl EpisodeWriter {
    /// Starts writing an episode to `path` (the temporary file lives next to it).
    pub fn create(path: impl AsRef<Path>, meta: EpisodeMeta, opts: WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if !(meta.fps.is_finite() && meta.fps > 0.0) {
            return Err(DataError::Argument(format!(
                "fps must be positive, got {}",
                meta.fps
            )));
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let tmp = tempfile::Builder::new()
            .prefix(".episode-")
            .suffix(".mcap.tmp")
            .tempfile_in(&dir)
            .map_err(|e| DataError::io(&dir, e))?;
        let (file, tmp_path) = tmp.into_parts();
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(opts.zstd_level)
            .chunk_size(Some(opts.chunk_size))
            .library(format!("libero-mem-rs data {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| mcap_err(&path, e))?;
        let ch = Self::register(&mut w).map_err(|e| mcap_err(&path, e))?;
        w.write_metadata(&Metadata {
            name: METADATA_NAME.into(),
            metadata: meta.to_map(),
        })
        .map_err(|e| mcap_err(&path, e))?;
        Ok(EpisodeWriter {
            path,
            tmp_path,
            writer: Some(w),
            opts,
            meta,
            ch,
            steps: 0,
            size: None,
        })
    }

    fn register(w: &mut mcap::Writer<BufWriter<File>>) -> mcap::McapResult<Channels> {
        let img = CompressedImage::get_schema().expect("foxglove schema");
        let img_schema = w.add_schema(&img.name, &img.encoding, &img.data)?;
        let raw = RawImage::get_schema().expect("foxglove schema");
        let raw_schema = w.add_schema(&raw.name, &raw.encoding, &raw.data)?;
        let json = |w: &mut mcap::Writer<BufWriter<File>>, topic: &str, schema: &str| {
            let s = w.add_schema(
                schema,
                "jsonschema",
                json_schema(schema).unwrap_or("").as_bytes(),
            )?;
            w.add_channel(s, topic, "json", &BTreeMap::new())
        };
        let cam = |w: &mut mcap::Writer<BufWriter<File>>, topic: &str, frame: &str| {
            let md = BTreeMap::from([("frame_id".to_string(), frame.to_string())]);
            w.add_channel(img_schema, topic, "protobuf", &md)
        };
        Ok(Channels {
            agentview: cam(w, TOPIC_AGENTVIEW, "agentview")?,
            eye_in_hand: cam(w, TOPIC_EYE_IN_HAND, "robot0_eye_in_hand")?,
            state: json(w, TOPIC_STATE, SCHEMA_STATE)?,
            joint_state: json(w, TOPIC_JOINT_STATE, SCHEMA_JOINT_STATE)?,
            action: json(w, TOPIC_ACTION, SCHEMA_ACTION)?,
            objects: json(w, TOPIC_OBJECTS, SCHEMA_OBJECTS)?,
            goal: json(w, TOPIC_GOAL, SCHEMA_GOAL)?,
            segmentation: None,
            depth: None,
            raw_schema,
        })
    }

    /// Number of steps written so far.
    pub fn steps_written(&self) -> u64 {
        self.steps
    }

    /// The metadata this episode is written with.
    pub fn meta(&self) -> &EpisodeMeta {
        &self.meta
    }

    fn check(&self, s: &StepRecord) -> Result<()> {
        let bad = |msg: String| Err(DataError::Argument(format!("step {}: {msg}", s.step)));
        if s.step != self.steps {
            return bad(format!(
                "steps must be consecutive from 0, expected {}",
                self.steps
            ));
        }
        for (name, img) in [("agentview", &s.agentview), ("eye_in_hand", &s.eye_in_hand)] {
            if img.channels != 3 || !img.is_consistent() || img.width == 0 || img.height == 0 {
                return bad(format!(
                    "{name} must be a non-empty [H, W, 3] u8 image, got {}x{}x{} with {} bytes",
                    img.height,
                    img.width,
                    img.channels,
                    img.data.len()
                ));
            }
        }
        let sizes = (
            (s.agentview.width, s.agentview.height),
            (s.eye_in_hand.width, s.eye_in_hand.height),
        );
        if let Some(first) = self.size
            && first != sizes
        {
            return bad(format!("image sizes changed from {first:?} to {sizes:?}"));
        }
        let finite = s
            .state
            .iter()
            .chain(&s.joint_state)
            .chain(&s.action)
            .all(|v| v.is_finite())
            && s.objects
                .iter()
                .all(|o| o.bbox.iter().all(|v| v.is_finite()));
        if !finite {
            return bad("non-finite value in state, joint_state, action or a box".into());
        }
        match &s.segmentation {
            Some(Segmentation::U16(i)) if i.channels != 1 || !i.is_consistent() => {
                return bad("segmentation must be [H, W, 1]".into());
            }
            Some(Segmentation::I32(i)) if i.channels != 1 || !i.is_consistent() => {
                return bad("segmentation must be [H, W, 1]".into());
            }
            _ => {}
        }
        if let Some(d) = &s.depth
            && (d.channels != 1 || !d.is_consistent())
        {
            return bad("depth must be [H, W, 1]".into());
        }
        Ok(())
    }

    /// Appends one step (steps must come in order 0, 1, 2, …).
    pub fn write_step(&mut self, s: &StepRecord) -> Result<()> {
        self.check(s)?;
        let path = self.path.clone();
        let me = |e| mcap_err(&path, e);
        let t = step_time_ns(s.step, self.meta.fps);
        let seq = u32::try_from(s.step)
            .map_err(|_| DataError::Argument(format!("step {} too large", s.step)))?;
        let stamp = fox_time(t);
        // Encode first (can fail), then write.
        let compression = self.opts.image_compression;
        let enc = |img: &RgbImage, frame: &str| -> Result<Vec<u8>> {
            let data = encode_rgb(img, compression).map_err(DataError::Argument)?;
            let msg = CompressedImage {
                timestamp: Some(stamp),
                frame_id: frame.into(),
                data: data.into(),
                format: compression.format().into(),
            };
            Ok(prost::Message::encode_to_vec(&msg))
        };
        let agent = enc(&s.agentview, "agentview")?;
        let eye = enc(&s.eye_in_hand, "robot0_eye_in_hand")?;
        let js = |v: &dyn erased::Ser| v.to_json();
        let state = js(&StateMsg {
            step: s.step,
            state: s.state,
        })?;
        let joints = js(&JointStateMsg {
            step: s.step,
            position: s.joint_state,
        })?;
        let action = js(&ActionMsg {
            step: s.step,
            action: s.action,
        })?;
        let objects = js(&ObjectsMsg {
            step: s.step,
            objects: s.objects.clone(),
        })?;
        let goal = js(&GoalMsg {
            step: s.step,
            progress: s.progress.clone(),
        })?;

        let w = self.writer.as_mut().expect("writer present until finish");
        let hdr = |channel_id| MessageHeader {
            channel_id,
            sequence: seq,
            log_time: t,
            publish_time: t,
        };
        w.write_to_known_channel(&hdr(self.ch.agentview), &agent)
            .map_err(me)?;
        w.write_to_known_channel(&hdr(self.ch.eye_in_hand), &eye)
            .map_err(me)?;
        if let Some(seg) = &s.segmentation {
            let (encoding, w_, h_, bytes): (&'static str, u32, u32, Vec<u8>) = match seg {
                Segmentation::U16(i) => (
                    "16UC1",
                    i.width,
                    i.height,
                    i.data.iter().flat_map(|v| v.to_le_bytes()).collect(),
                ),
                Segmentation::I32(i) => (
                    "32SC1",
                    i.width,
                    i.height,
                    i.data.iter().flat_map(|v| v.to_le_bytes()).collect(),
                ),
            };
            let id = match self.ch.segmentation {
                Some((id, enc)) if enc == encoding => id,
                Some((_, enc)) => {
                    return Err(DataError::Argument(format!(
                        "step {}: segmentation encoding changed from {enc} to {encoding}",
                        s.step
                    )));
                }
                None => {
                    let md = BTreeMap::from([
                        ("frame_id".to_string(), "agentview".to_string()),
                        ("encoding".to_string(), encoding.to_string()),
                    ]);
                    let id = w
                        .add_channel(self.ch.raw_schema, TOPIC_SEGMENTATION, "protobuf", &md)
                        .map_err(me)?;
                    self.ch.segmentation = Some((id, encoding));
                    id
                }
            };
            let bpp = bytes.len() as u32 / (w_ * h_).max(1);
            let msg = RawImage {
                timestamp: Some(stamp),
                frame_id: "agentview".into(),
                width: w_,
                height: h_,
                encoding: encoding.into(),
                step: w_ * bpp,
                data: bytes.into(),
            };
            w.write_to_known_channel(&hdr(id), &prost::Message::encode_to_vec(&msg))
                .map_err(me)?;
        }
        if let Some(d) = &s.depth {
            let id = match self.ch.depth {
                Some(id) => id,
                None => {
                    let md = BTreeMap::from([
                        ("frame_id".to_string(), "agentview".to_string()),
                        ("encoding".to_string(), "32FC1".to_string()),
                        ("units".to_string(), "m".to_string()),
                    ]);
                    let id = w
                        .add_channel(self.ch.raw_schema, TOPIC_DEPTH, "protobuf", &md)
                        .map_err(me)?;
                    self.ch.depth = Some(id);
                    id
                }
            };
            let msg = RawImage {
                timestamp: Some(stamp),
                frame_id: "agentview".into(),
                width: d.width,
                height: d.height,
                encoding: "32FC1".into(),
                step: d.width * 4,
                data: d
                    .data
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect::<Vec<u8>>()
                    .into(),
            };
            w.write_to_known_channel(&hdr(id), &prost::Message::encode_to_vec(&msg))
                .map_err(me)?;
        }
        w.write_to_known_channel(&hdr(self.ch.state), &state)
            .map_err(me)?;
        w.write_to_known_channel(&hdr(self.ch.joint_state), &joints)
            .map_err(me)?;
        w.write_to_known_channel(&hdr(self.ch.action), &action)
            .map_err(me)?;
        w.write_to_known_channel(&hdr(self.ch.objects), &objects)
            .map_err(me)?;
        w.write_to_known_channel(&hdr(self.ch.goal), &goal)
            .map_err(me)?;
        self.size = Some((
            (s.agentview.width, s.agentview.height),
            (s.eye_in_hand.width, s.eye_in_hand.height),
        ));
        self.steps += 1;
        Ok(())
    }

    /// Writes the summary, syncs and renames the temporary file to the final path.
    pub fn finish(mut self) -> Result<PathBuf> {
        let path = self.path.clone();
        if self.steps == 0 {
            return Err(DataError::Argument(format!(
                "{}: an episode needs at least one step",
                path.display()
            )));
        }
        let mut w = self.writer.take().expect("writer present until finish");
        w.finish().map_err(|e| mcap_err(&path, e))?;
        let buf = w.into_inner();
        let file = buf
            .into_inner()
            .map_err(|e| DataError::io(&path, e.into_error()))?;
        file.sync_all().map_err(|e| DataError::io(&path, e))?;
        crate::fsio::set_readable(&file, &path)?;
        drop(file);
        self.tmp_path
            .persist(&path)
            .map_err(|e| DataError::io(&path, e.error))?;
        Ok(path)
    }
}

mod erased {
    //! Tiny helper so the JSON encodings above share one error mapping.
    use crate::error::{DataError, Result};

    pub trait Ser {
        fn to_json(&self) -> Result<Vec<u8>>;
    }
    impl<T: serde::Serialize> Ser for T {
        fn to_json(&self) -> Result<Vec<u8>> {
            serde_json::to_vec(self).map_err(|e| DataError::Argument(format!("json: {e}")))
        }
    }
}

/// A compressed camera frame as stored (PNG or JPEG bytes).
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedImage {
    /// `png` or `jpeg`.
    pub format: String,
    /// The encoded bytes.
    pub data: bytes::Bytes,
}

impl EncodedImage {
    /// Decodes to RGB `[H, W, 3]`.
    pub fn decode(&self) -> Result<RgbImage, String> {
        decode_rgb(&self.data, &self.format)
    }
}

/// One step as read from disk, with camera frames still encoded (decode lazily).
#[derive(Clone, Debug, PartialEq)]
pub struct RawStep {
    /// Step index.
    pub step: u64,
    /// Agentview frame, encoded.
    pub agentview: EncodedImage,
    /// Eye-in-hand frame, encoded.
    pub eye_in_hand: EncodedImage,
    /// Segmentation, if recorded.
    pub segmentation: Option<Segmentation>,
    /// Depth, if recorded.
    pub depth: Option<DepthImage>,
    /// 8-D state.
    pub state: [f32; 8],
    /// 7-D joint state.
    pub joint_state: [f32; 7],
    /// 7-D action.
    pub action: [f32; 7],
    /// Per-object annotations.
    pub objects: Vec<ObjectAnnotation>,
    /// Goal progress.
    pub progress: GoalProgress,
}

#[derive(Default)]
struct PartialStep {
    agentview: Option<EncodedImage>,
    eye_in_hand: Option<EncodedImage>,
    segmentation: Option<Segmentation>,
    depth: Option<DepthImage>,
    state: Option<[f32; 8]>,
    joint_state: Option<[f32; 7]>,
    action: Option<[f32; 7]>,
    objects: Option<Vec<ObjectAnnotation>>,
    progress: Option<GoalProgress>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Kind {
    Agentview,
    EyeInHand,
    Segmentation,
    Depth,
    State,
    JointState,
    Action,
    Objects,
    Goal,
}

/// Per-channel facts reported by [`EpisodeReader::channels`].
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelInfo {
    /// Topic name.
    pub topic: String,
    /// Schema name.
    pub schema: String,
    /// Message encoding (`protobuf` or `json`).
    pub encoding: String,
    /// Number of messages (from the summary statistics).
    pub count: u64,
}

/// Random-access reader of one episode file (the whole file is held in memory).
pub struct EpisodeReader {
    path: PathBuf,
    bytes: Arc<[u8]>,
    summary: mcap::Summary,
    meta: EpisodeMeta,
    len: usize,
    kinds: HashMap<u16, Kind>,
    chunks: Vec<ChunkIndex>,
    has_segmentation: bool,
    has_depth: bool,
}

impl std::fmt::Debug for EpisodeReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpisodeReader")
            .field("path", &self.path)
            .field("len", &self.len)
            .finish()
    }
}

fn read_err(path: &Path, offset: u64, what: &str, e: mcap::McapError) -> DataError {
    DataError::corrupt(path, offset, format!("{what}: {e}"))
}

impl EpisodeReader {
    /// Opens and validates an episode file: magic, summary, channels, schemas and metadata.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let bytes: Arc<[u8]> = std::fs::read(&path)
            .map_err(|e| DataError::io(&path, e))?
            .into();
        Self::from_bytes(path, bytes)
    }

    /// The whole file, as read.
    pub fn file_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Validates an episode held in memory; `path` is only used in error messages.
    pub fn from_bytes(path: PathBuf, bytes: Arc<[u8]>) -> Result<Self> {
        let n = bytes.len() as u64;
        let magic = mcap::MAGIC;
        if !bytes.starts_with(magic) {
            return Err(DataError::corrupt(
                &path,
                0,
                "not an mcap file (bad start magic)",
            ));
        }
        if n < (2 * magic.len() + 29) as u64 || !bytes.ends_with(magic) {
            return Err(DataError::corrupt(
                &path,
                n,
                format!("file ends at byte {n} without the mcap end magic (truncated?)"),
            ));
        }
        let footer_off = n - magic.len() as u64 - 29;
        let footer =
            mcap::read::footer(&bytes).map_err(|e| read_err(&path, footer_off, "bad footer", e))?;
        if footer.summary_start == 0 {
            return Err(DataError::schema(
                &path,
                footer_off,
                "no summary section (file was written without indexes)",
            ));
        }
        if footer.summary_start >= footer_off {
            return Err(DataError::corrupt(
                &path,
                footer_off,
                format!(
                    "footer points to summary at {} beyond the footer",
                    footer.summary_start
                ),
            ));
        }
        let summary = match mcap::Summary::read(&bytes) {
            Ok(Some(s)) => s,
            Ok(None) => {
                return Err(DataError::schema(&path, footer_off, "no summary section"));
            }
            Err(e) => return Err(read_err(&path, footer.summary_start, "summary section", e)),
        };
        let soff = footer.summary_start;
        // Metadata.
        let mi = summary
            .metadata_indexes
            .iter()
            .find(|m| m.name == METADATA_NAME)
            .ok_or_else(|| DataError::schema(&path, soff, "no `episode` metadata record"))?;
        let md = mcap::read::metadata(&bytes, mi)
            .map_err(|e| read_err(&path, mi.offset, "episode metadata record", e))?;
        let meta = EpisodeMeta::from_map(&md.metadata)
            .map_err(|m| DataError::schema(&path, mi.offset, m))?;
        // Channels.
        let mut kinds = HashMap::new();
        let mut found: HashMap<Kind, u16> = HashMap::new();
        for (id, ch) in &summary.channels {
            let expect = |kind, schema: &str, enc: &str| -> Result<Option<Kind>> {
                let sname = ch.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
                if sname != schema || ch.message_encoding != enc {
                    return Err(DataError::schema(
                        &path,
                        soff,
                        format!(
                            "channel `{}` has schema `{sname}` / encoding `{}`, expected `{schema}` / `{enc}`",
                            ch.topic, ch.message_encoding
                        ),
                    ));
                }
                Ok(Some(kind))
            };
            let kind = match ch.topic.as_str() {
                TOPIC_AGENTVIEW => expect(Kind::Agentview, SCHEMA_COMPRESSED_IMAGE, "protobuf")?,
                TOPIC_EYE_IN_HAND => expect(Kind::EyeInHand, SCHEMA_COMPRESSED_IMAGE, "protobuf")?,
                TOPIC_SEGMENTATION => expect(Kind::Segmentation, SCHEMA_RAW_IMAGE, "protobuf")?,
                TOPIC_DEPTH => expect(Kind::Depth, SCHEMA_RAW_IMAGE, "protobuf")?,
                TOPIC_STATE => expect(Kind::State, SCHEMA_STATE, "json")?,
                TOPIC_JOINT_STATE => expect(Kind::JointState, SCHEMA_JOINT_STATE, "json")?,
                TOPIC_ACTION => expect(Kind::Action, SCHEMA_ACTION, "json")?,
                TOPIC_OBJECTS => expect(Kind::Objects, SCHEMA_OBJECTS, "json")?,
                TOPIC_GOAL => expect(Kind::Goal, SCHEMA_GOAL, "json")?,
                _ => None, // unknown extra channels are ignored
            };
            if let Some(k) = kind {
                kinds.insert(*id, k);
                found.insert(k, *id);
            }
        }
        let required = [
            (Kind::Agentview, TOPIC_AGENTVIEW),
            (Kind::EyeInHand, TOPIC_EYE_IN_HAND),
            (Kind::State, TOPIC_STATE),
            (Kind::JointState, TOPIC_JOINT_STATE),
            (Kind::Action, TOPIC_ACTION),
            (Kind::Objects, TOPIC_OBJECTS),
            (Kind::Goal, TOPIC_GOAL),
        ];
        for (k, topic) in required {
            if !found.contains_key(&k) {
                return Err(DataError::schema(
                    &path,
                    soff,
                    format!("required channel `{topic}` missing"),
                ));
            }
        }
        let stats = summary
            .stats
            .as_ref()
            .ok_or_else(|| DataError::schema(&path, soff, "summary has no statistics record"))?;
        let count = |k: Kind| {
            stats
                .channel_message_counts
                .get(&found[&k])
                .copied()
                .unwrap_or(0)
        };
        let len = count(Kind::State);
        for (k, topic) in required {
            if count(k) != len {
                return Err(DataError::schema(
                    &path,
                    soff,
                    format!(
                        "channel `{topic}` has {} messages, `{TOPIC_STATE}` has {len}",
                        count(k)
                    ),
                ));
            }
        }
        let has_segmentation = found
            .get(&Kind::Segmentation)
            .is_some_and(|_| count(Kind::Segmentation) > 0);
        let has_depth = found
            .get(&Kind::Depth)
            .is_some_and(|_| count(Kind::Depth) > 0);
        // Chunk indexes: validate bounds ourselves so that a damaged index is an error, not a panic.
        let mut chunks = summary.chunk_indexes.clone();
        for c in &chunks {
            let end = c.chunk_start_offset.checked_add(c.chunk_length);
            if c.chunk_length < 9 + 40 || end.is_none_or(|e| e > soff) {
                return Err(DataError::corrupt(
                    &path,
                    soff,
                    format!(
                        "chunk index points outside the data section (start {}, length {})",
                        c.chunk_start_offset, c.chunk_length
                    ),
                ));
            }
            if c.compression != "zstd" && !c.compression.is_empty() {
                return Err(DataError::schema(
                    &path,
                    c.chunk_start_offset,
                    format!("unsupported chunk compression `{}`", c.compression),
                ));
            }
        }
        chunks.sort_by_key(|c| (c.message_start_time, c.chunk_start_offset));
        Ok(EpisodeReader {
            path,
            bytes,
            summary,
            meta,
            len: len as usize,
            kinds,
            chunks,
            has_segmentation,
            has_depth,
        })
    }

    /// The file this reader reads.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Episode metadata.
    pub fn meta(&self) -> &EpisodeMeta {
        &self.meta
    }

    /// Number of steps.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True if the episode has no steps.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// File size in bytes.
    pub fn file_size(&self) -> u64 {
        self.bytes.len() as u64
    }

    /// Whether segmentation / depth were recorded.
    pub fn has_segmentation_depth(&self) -> (bool, bool) {
        (self.has_segmentation, self.has_depth)
    }

    /// Number of chunks in the file.
    pub fn chunk_count(&self) -> usize {
        self.chunks.len()
    }

    /// Duration in seconds (`len / fps`).
    pub fn duration_s(&self) -> f64 {
        self.len as f64 / self.meta.fps
    }

    /// All channels with their schema, encoding and message count, sorted by topic.
    pub fn channels(&self) -> Vec<ChannelInfo> {
        let counts = self
            .summary
            .stats
            .as_ref()
            .map(|s| &s.channel_message_counts);
        let mut v: Vec<ChannelInfo> = self
            .summary
            .channels
            .iter()
            .map(|(id, c)| ChannelInfo {
                topic: c.topic.clone(),
                schema: c
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                encoding: c.message_encoding.clone(),
                count: counts.and_then(|m| m.get(id).copied()).unwrap_or(0),
            })
            .collect();
        v.sort_by(|a, b| a.topic.cmp(&b.topic));
        v
    }

    /// Reads and decodes step `k` (both camera frames decoded).
    pub fn read_step(&self, k: usize) -> Result<StepRecord> {
        let raw = self.read_raw_steps(k..k + 1)?;
        let raw = raw.into_iter().next().expect("one step");
        self.decode_step(raw)
    }

    /// Decodes the camera frames of a raw step.
    pub fn decode_step(&self, raw: RawStep) -> Result<StepRecord> {
        let dec = |img: &EncodedImage, topic: &str| {
            img.decode().map_err(|m| {
                DataError::invalid(&self.path, format!("step {} on `{topic}`: {m}", raw.step))
            })
        };
        Ok(StepRecord {
            step: raw.step,
            agentview: dec(&raw.agentview, TOPIC_AGENTVIEW)?,
            eye_in_hand: dec(&raw.eye_in_hand, TOPIC_EYE_IN_HAND)?,
            segmentation: raw.segmentation,
            depth: raw.depth,
            state: raw.state,
            joint_state: raw.joint_state,
            action: raw.action,
            objects: raw.objects,
            progress: raw.progress,
        })
    }

    /// Reads and decodes every step.
    pub fn read_all(&self) -> Result<Vec<StepRecord>> {
        self.read_raw_steps(0..self.len)?
            .into_iter()
            .map(|r| self.decode_step(r))
            .collect()
    }

    /// Decompresses every chunk and checks every message (CRCs, schemas, completeness).
    pub fn verify(&self) -> Result<()> {
        self.read_raw_steps(0..self.len).map(|_| ())
    }

    /// Reads steps `range` without decoding camera frames; only the chunks that overlap the
    /// range in time are decompressed.
    pub fn read_raw_steps(&self, range: Range<usize>) -> Result<Vec<RawStep>> {
        if range.start >= range.end || range.end > self.len {
            return Err(DataError::Argument(format!(
                "{}: step range {range:?} outside 0..{}",
                self.path.display(),
                self.len
            )));
        }
        let t0 = step_time_ns(range.start as u64, self.meta.fps);
        let t1 = step_time_ns(range.end as u64 - 1, self.meta.fps);
        let mut parts: Vec<PartialStep> = (range.clone()).map(|_| PartialStep::default()).collect();
        for c in &self.chunks {
            if c.message_end_time < t0 || c.message_start_time > t1 {
                continue;
            }
            let off = c.chunk_start_offset;
            let body = self.decompress_chunk(c)?;
            let mut pos = 0usize;
            while pos < body.len() {
                let rec_off = pos;
                let bad = |m: String| {
                    DataError::corrupt(
                        &self.path,
                        off,
                        format!("chunk: record at {rec_off} of its decompressed data: {m}"),
                    )
                };
                if body.len() - pos < 9 {
                    return Err(bad("record header cut short".into()));
                }
                let op = body[pos];
                let len = u64::from_le_bytes(body[pos + 1..pos + 9].try_into().expect("8 bytes"));
                if len > (body.len() - pos - 9) as u64 {
                    return Err(bad(format!("record length {len} runs past the chunk")));
                }
                let rec = &body[pos + 9..pos + 9 + len as usize];
                pos += 9 + len as usize;
                if op != 0x05 {
                    continue; // schema/channel records: we use the summary's
                }
                let (channel_id, sequence, log_time, data) = match mcap::parse_record(op, rec) {
                    Ok(mcap::records::Record::Message { header, data }) => {
                        (header.channel_id, header.sequence, header.log_time, data)
                    }
                    Ok(_) => continue,
                    Err(e) => return Err(bad(format!("message record: {e}"))),
                };
                let k = sequence as usize;
                if log_time < t0 || log_time > t1 || !range.contains(&k) {
                    continue;
                }
                let Some(kind) = self.kinds.get(&channel_id) else {
                    continue;
                };
                self.put(&mut parts[k - range.start], *kind, &data, k, off)?;
            }
        }
        parts
            .into_iter()
            .enumerate()
            .map(|(i, p)| self.complete(p, range.start + i))
            .collect()
    }

    fn put(&self, p: &mut PartialStep, kind: Kind, data: &[u8], k: usize, off: u64) -> Result<()> {
        let bad = |topic: &str, m: String| {
            DataError::corrupt(
                &self.path,
                off,
                format!("chunk: step {k} on `{topic}`: {m}"),
            )
        };
        fn json<T: serde::de::DeserializeOwned>(d: &[u8]) -> Result<T, String> {
            serde_json::from_slice(d).map_err(|e| format!("bad JSON: {e}"))
        }
        let check_step = |topic: &str, s: u64| {
            if s != k as u64 {
                Err(bad(topic, format!("message says step {s}")))
            } else {
                Ok(())
            }
        };
        match kind {
            Kind::Agentview | Kind::EyeInHand => {
                let topic = if kind == Kind::Agentview {
                    TOPIC_AGENTVIEW
                } else {
                    TOPIC_EYE_IN_HAND
                };
                let msg = CompressedImage::decode(data)
                    .map_err(|e| bad(topic, format!("protobuf: {e}")))?;
                let img = EncodedImage {
                    format: msg.format,
                    data: msg.data,
                };
                if kind == Kind::Agentview {
                    p.agentview = Some(img);
                } else {
                    p.eye_in_hand = Some(img);
                }
            }
            Kind::Segmentation | Kind::Depth => {
                let topic = if kind == Kind::Depth {
                    TOPIC_DEPTH
                } else {
                    TOPIC_SEGMENTATION
                };
                let msg =
                    RawImage::decode(data).map_err(|e| bad(topic, format!("protobuf: {e}")))?;
                let (w, h) = (msg.width, msg.height);
                let n = w as usize * h as usize;
                let need = |bpp: usize| {
                    if msg.data.len() != n * bpp || msg.step as usize != w as usize * bpp {
                        Err(bad(
                            topic,
                            format!(
                                "{} image {w}x{h} has {} bytes and step {}",
                                msg.encoding,
                                msg.data.len(),
                                msg.step
                            ),
                        ))
                    } else {
                        Ok(())
                    }
                };
                match (kind, msg.encoding.as_str()) {
                    (Kind::Segmentation, "16UC1") => {
                        need(2)?;
                        let d = msg
                            .data
                            .chunks_exact(2)
                            .map(|b| u16::from_le_bytes([b[0], b[1]]));
                        p.segmentation = Some(Segmentation::U16(Image {
                            width: w,
                            height: h,
                            channels: 1,
                            data: d.collect(),
                        }));
                    }
                    (Kind::Segmentation, "32SC1") => {
                        need(4)?;
                        let d = msg
                            .data
                            .chunks_exact(4)
                            .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                        p.segmentation = Some(Segmentation::I32(Image {
                            width: w,
                            height: h,
                            channels: 1,
                            data: d.collect(),
                        }));
                    }
                    (Kind::Depth, "32FC1") => {
                        need(4)?;
                        let d = msg
                            .data
                            .chunks_exact(4)
                            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                        p.depth = Some(Image {
                            width: w,
                            height: h,
                            channels: 1,
                            data: d.collect(),
                        });
                    }
                    (_, e) => return Err(bad(topic, format!("unsupported encoding `{e}`"))),
                }
            }
            Kind::State => {
                let m: StateMsg = json(data).map_err(|e| bad(TOPIC_STATE, e))?;
                check_step(TOPIC_STATE, m.step)?;
                p.state = Some(m.state);
            }
            Kind::JointState => {
                let m: JointStateMsg = json(data).map_err(|e| bad(TOPIC_JOINT_STATE, e))?;
                check_step(TOPIC_JOINT_STATE, m.step)?;
                p.joint_state = Some(m.position);
            }
            Kind::Action => {
                let m: ActionMsg = json(data).map_err(|e| bad(TOPIC_ACTION, e))?;
                check_step(TOPIC_ACTION, m.step)?;
                p.action = Some(m.action);
            }
            Kind::Objects => {
                let m: ObjectsMsg = json(data).map_err(|e| bad(TOPIC_OBJECTS, e))?;
                check_step(TOPIC_OBJECTS, m.step)?;
                p.objects = Some(m.objects);
            }
            Kind::Goal => {
                let m: GoalMsg = json(data).map_err(|e| bad(TOPIC_GOAL, e))?;
                check_step(TOPIC_GOAL, m.step)?;
                p.progress = Some(m.progress);
            }
        }
        Ok(())
    }

    fn complete(&self, p: PartialStep, k: usize) -> Result<RawStep> {
        let missing = |topic: &str| {
            DataError::schema(
                &self.path,
                self.summary_offset(),
                format!("step {k} has no message on `{topic}`"),
            )
        };
        if self.has_segmentation && p.segmentation.is_none() {
            return Err(missing(TOPIC_SEGMENTATION));
        }
        if self.has_depth && p.depth.is_none() {
            return Err(missing(TOPIC_DEPTH));
        }
        Ok(RawStep {
            step: k as u64,
            agentview: p.agentview.ok_or_else(|| missing(TOPIC_AGENTVIEW))?,
            eye_in_hand: p.eye_in_hand.ok_or_else(|| missing(TOPIC_EYE_IN_HAND))?,
            segmentation: p.segmentation,
            depth: p.depth,
            state: p.state.ok_or_else(|| missing(TOPIC_STATE))?,
            joint_state: p.joint_state.ok_or_else(|| missing(TOPIC_JOINT_STATE))?,
            action: p.action.ok_or_else(|| missing(TOPIC_ACTION))?,
            objects: p.objects.ok_or_else(|| missing(TOPIC_OBJECTS))?,
            progress: p.progress.ok_or_else(|| missing(TOPIC_GOAL))?,
        })
    }

    /// Compares a chunk's own header with its index entry before decompressing, so that a damaged
    /// size field is reported instead of driving a huge allocation.
    fn check_chunk_header(&self, c: &ChunkIndex) -> Result<()> {
        let off = c.chunk_start_offset;
        let b = &self.bytes[off as usize..(off + c.chunk_length) as usize];
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        let bad = |m: String| {
            Err(DataError::corrupt(
                &self.path,
                off,
                format!("chunk header: {m}"),
            ))
        };
        if b[0] != 0x06 {
            return bad(format!("opcode {:#04x} is not a chunk", b[0]));
        }
        if u64_at(1) != c.chunk_length - 9 {
            return bad(format!(
                "record length {} disagrees with the index ({})",
                u64_at(1),
                c.chunk_length - 9
            ));
        }
        if u64_at(9) != c.message_start_time || u64_at(17) != c.message_end_time {
            return bad("message times disagree with the chunk index".into());
        }
        if u64_at(25) != c.uncompressed_size {
            return bad(format!(
                "uncompressed size {} disagrees with the index ({})",
                u64_at(25),
                c.uncompressed_size
            ));
        }
        const MAX_CHUNK: u64 = 1 << 30;
        if c.uncompressed_size > MAX_CHUNK {
            return bad(format!(
                "uncompressed size {} over the 1 GiB limit",
                c.uncompressed_size
            ));
        }
        let name_len = u32::from_le_bytes(b[37..41].try_into().expect("4 bytes")) as usize;
        if 41 + name_len + 8 > b.len() || b[41..41 + name_len] != *c.compression.as_bytes() {
            return bad("compression name disagrees with the chunk index".into());
        }
        let records = u64_at(41 + name_len);
        if records != c.compressed_size || 49 + name_len as u64 + records != b.len() as u64 {
            return bad(format!(
                "records length {records} disagrees with the index ({})",
                c.compressed_size
            ));
        }
        Ok(())
    }

    /// Decompresses one chunk's records and checks their CRC. (Done here rather than through
    /// `mcap::Summary::stream_chunk`, which trusts damaged length fields and can abort the process
    /// on a huge allocation.)
    fn decompress_chunk(&self, c: &ChunkIndex) -> Result<Vec<u8>> {
        self.check_chunk_header(c)?;
        let off = c.chunk_start_offset;
        let b = &self.bytes[off as usize..(off + c.chunk_length) as usize];
        let crc = u32::from_le_bytes(b[33..37].try_into().expect("4 bytes"));
        let name_len = c.compression.len();
        let data = &b[49 + name_len..];
        let out = match c.compression.as_str() {
            "" => data.to_vec(),
            "zstd" => zstd::bulk::decompress(data, c.uncompressed_size as usize)
                .map_err(|e| DataError::corrupt(&self.path, off, format!("chunk: zstd: {e}")))?,
            other => {
                return Err(DataError::schema(
                    &self.path,
                    off,
                    format!("unsupported chunk compression `{other}`"),
                ));
            }
        };
        if out.len() as u64 != c.uncompressed_size {
            return Err(DataError::corrupt(
                &self.path,
                off,
                format!(
                    "chunk: decompressed to {} bytes, header says {}",
                    out.len(),
                    c.uncompressed_size
                ),
            ));
        }
        if crc != 0 {
            let got = crc32fast::hash(&out);
            if got != crc {
                return Err(DataError::corrupt(
                    &self.path,
                    off,
                    format!("chunk: CRC mismatch (stored {crc:08x}, computed {got:08x})"),
                ));
            }
        }
        Ok(out)
    }

    fn summary_offset(&self) -> u64 {
        mcap::read::footer(&self.bytes)
            .map(|f| f.summary_start)
            .unwrap_or(0)
    }
}
