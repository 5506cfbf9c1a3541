//! Episode schema: in-memory step records, episode metadata, topics and the JSON message types
//! written to mcap (see `data/SCHEMA.md`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Version tag stored in every episode's metadata (version 2 adds object poses and grasp flags
/// to the object annotations, version 3 the poses of their articulated parts).
pub const SCHEMA_VERSION: &str = "libero-mem-rs/episode/3";
/// Versions this reader understands; files of version 1 read with no object poses, files of
/// version 2 with no parts.
pub const READABLE_VERSIONS: [&str; 3] = [
    "libero-mem-rs/episode/1",
    "libero-mem-rs/episode/2",
    SCHEMA_VERSION,
];
/// Name of the mcap metadata record holding [`EpisodeMeta`].
pub const METADATA_NAME: &str = "episode";

/// Topic of the agentview RGB camera (`foxglove.CompressedImage`, protobuf).
pub const TOPIC_AGENTVIEW: &str = "/agentview/image";
/// Topic of the eye-in-hand RGB camera (`foxglove.CompressedImage`, protobuf).
pub const TOPIC_EYE_IN_HAND: &str = "/eye_in_hand/image";
/// Topic of the agentview instance segmentation (`foxglove.RawImage`, `16UC1` or `32SC1`).
pub const TOPIC_SEGMENTATION: &str = "/agentview/segmentation";
/// Topic of the agentview depth in metres (`foxglove.RawImage`, `32FC1`).
pub const TOPIC_DEPTH: &str = "/agentview/depth";
/// Topic of the 8-D proprio state (JSON `lmr.State`).
pub const TOPIC_STATE: &str = "/robot/state";
/// Topic of the 7-D joint state (JSON `lmr.JointState`).
pub const TOPIC_JOINT_STATE: &str = "/robot/joint_state";
/// Topic of the 7-D action (JSON `lmr.Action`).
pub const TOPIC_ACTION: &str = "/robot/action";
/// Topic of the per-object annotations (JSON `lmr.ObjectAnnotations`).
pub const TOPIC_OBJECTS: &str = "/objects";
/// Topic of the goal progress (JSON `lmr.GoalProgress`).
pub const TOPIC_GOAL: &str = "/goal";

/// Schema name of [`StateMsg`].
pub const SCHEMA_STATE: &str = "lmr.State";
/// Schema name of [`JointStateMsg`].
pub const SCHEMA_JOINT_STATE: &str = "lmr.JointState";
/// Schema name of [`ActionMsg`].
pub const SCHEMA_ACTION: &str = "lmr.Action";
/// Schema name of [`ObjectsMsg`].
pub const SCHEMA_OBJECTS: &str = "lmr.ObjectAnnotations";
/// Schema name of [`GoalMsg`].
pub const SCHEMA_GOAL: &str = "lmr.GoalProgress";
/// Foxglove's compressed image schema name.
pub const SCHEMA_COMPRESSED_IMAGE: &str = "foxglove.CompressedImage";
/// Foxglove's raw image schema name.
pub const SCHEMA_RAW_IMAGE: &str = "foxglove.RawImage";

/// A dense image, row-major, row 0 = top, channels interleaved: `data.len() == height*width*channels`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Image<T> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Channels per pixel (3 for RGB, 1 for ids or depth).
    pub channels: u32,
    /// Pixels, shape `[height, width, channels]`.
    pub data: Vec<T>,
}

impl<T: Clone + Default> Image<T> {
    /// A zero image of shape `[height, width, channels]`.
    pub fn zeros(width: u32, height: u32, channels: u32) -> Self {
        Image {
            width,
            height,
            channels,
            data: vec![T::default(); (width * height * channels) as usize],
        }
    }
}

impl<T> Image<T> {
    /// Builds an image from `[height, width, channels]` data; `None` if the length does not match.
    pub fn new(width: u32, height: u32, channels: u32, data: Vec<T>) -> Option<Self> {
        (data.len() == width as usize * height as usize * channels as usize).then_some(Image {
            width,
            height,
            channels,
            data,
        })
    }

    /// True if `data` has exactly `height*width*channels` elements.
    pub fn is_consistent(&self) -> bool {
        self.data.len() == self.width as usize * self.height as usize * self.channels as usize
    }
}

/// An 8-bit RGB image `[H, W, 3]`, upright.
pub type RgbImage = Image<u8>;
/// A depth image in metres `[H, W, 1]`, upright.
pub type DepthImage = Image<f32>;

/// Instance segmentation `[H, W, 1]`: one instance id per pixel, 0 = background.
#[derive(Clone, Debug, PartialEq)]
pub enum Segmentation {
    /// 16-bit ids (stored as `16UC1`).
    U16(Image<u16>),
    /// 32-bit signed ids (stored as `32SC1`).
    I32(Image<i32>),
}

impl Segmentation {
    /// (width, height) of the map.
    pub fn size(&self) -> (u32, u32) {
        match self {
            Segmentation::U16(i) => (i.width, i.height),
            Segmentation::I32(i) => (i.width, i.height),
        }
    }
}

/// One object's annotation at one step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectAnnotation {
    /// Instance id as it appears in the segmentation map.
    pub instance_id: i32,
    /// Object name (e.g. `akita_black_bowl_1` or LIBERO-Mem's simplified `bowl`).
    pub name: String,
    /// Box `[x, y, w, h]` in the upright agentview image, normalised to [0, 1] (x right, y down).
    #[serde(rename = "box")]
    pub bbox: [f32; 4],
    /// Whether any pixel of the object is visible.
    pub visible: bool,
    /// The object's subgoal label (`"0"` before any subgoal touched it, as LIBERO-Mem).
    pub subgoal_label: String,
    /// Privileged pose in the world frame: position (m) and orientation quaternion (w, x, y, z)
    /// of the object's root body (schema 2; absent in version-1 files and imported data).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<[f32; 7]>,
    /// Whether both gripper fingers touch the object at this step (schema 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasped: Option<bool>,
    /// The object's articulated parts (a cabinet's drawer handles, a stove's knob) at this step
    /// (schema 3; empty for rigid objects, in older files and in imported data).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<PartState>,
}

/// Privileged state of one articulated part of an object (schema 3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartState {
    /// Part name within its object's category (e.g. `middle_handle`, `knob`).
    pub name: String,
    /// World position (m) of the point a gripper takes the part by, and the orientation
    /// quaternion (w, x, y, z) of the part's body.
    pub pose: [f32; 7],
    /// Position of the part's joint (m for a slide, rad for a hinge).
    pub joint: f32,
}

/// Goal progress at one step.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct GoalProgress {
    /// Number of subgoals satisfied so far.
    pub satisfied: u32,
    /// Number of subgoals of the task (0 when unknown, e.g. imported data).
    pub total: u32,
    /// Texts of the satisfied subgoals, in the order they were satisfied.
    pub satisfied_subgoals: Vec<String>,
    /// Text of the subgoal being worked on (empty when unknown or when all are done).
    pub current_subgoal: String,
}

/// Everything recorded at one control step (20 Hz).
#[derive(Clone, Debug, PartialEq)]
pub struct StepRecord {
    /// Step index, 0-based, consecutive.
    pub step: u64,
    /// Agentview RGB, upright, `[H, W, 3]`.
    pub agentview: RgbImage,
    /// Eye-in-hand RGB, upright, `[H, W, 3]`.
    pub eye_in_hand: RgbImage,
    /// Optional agentview instance segmentation `[H, W, 1]`.
    pub segmentation: Option<Segmentation>,
    /// Optional agentview depth in metres `[H, W, 1]`.
    pub depth: Option<DepthImage>,
    /// Proprio: eef position (3), eef axis-angle (3), gripper finger qpos (2).
    pub state: [f32; 8],
    /// The 7 arm joint angles.
    pub joint_state: [f32; 7],
    /// Action taken at this step: Δpos (3), Δaxis-angle (3), gripper (−1 open, +1 close).
    pub action: [f32; 7],
    /// Per-object annotations.
    pub objects: Vec<ObjectAnnotation>,
    /// Goal progress after this step.
    pub progress: GoalProgress,
}

/// Episode-level metadata (stored as the mcap metadata record `episode`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeMeta {
    /// Task id, e.g. `libero_mem/t3` or `libero_goal/open_the_middle_drawer_of_the_cabinet`.
    pub task_id: String,
    /// Natural-language instruction.
    pub instruction: String,
    /// BDDL text of the task (empty for imported data without it).
    pub bddl: String,
    /// Episode seed (every random choice derives from it).
    pub seed: u64,
    /// Simulator version string (or the importer's name for converted data).
    pub sim_version: String,
    /// Asset pack version string.
    pub asset_version: String,
    /// Orientation of the stored images; always `upright` (row 0 = top) for files we write.
    pub image_orientation: String,
    /// Control frequency in Hz (20 for LIBERO).
    pub fps: f64,
    /// Free-form extra keys (source file, applied image transform, depth units…).
    pub extra: BTreeMap<String, String>,
}

impl Default for EpisodeMeta {
    fn default() -> Self {
        EpisodeMeta {
            task_id: String::new(),
            instruction: String::new(),
            bddl: String::new(),
            seed: 0,
            sim_version: String::new(),
            asset_version: String::new(),
            image_orientation: "upright".into(),
            fps: 20.0,
            extra: BTreeMap::new(),
        }
    }
}

/// Key of [`EpisodeMeta::extra`]: the first step whose recorded action is a label to learn from.
/// Episodes a policy began and the scripted expert finished (DAgger, `eval dagger`) record the
/// policy's own actions before it; training gives those no weight and the statistics leave them out.
pub const LABELLED_FROM: &str = "labelled_from";

impl EpisodeMeta {
    /// The first step whose action is a label ([`LABELLED_FROM`]; 0, every step, when absent), or
    /// the stored text when it is not a step number.
    pub fn labelled_from(&self) -> std::result::Result<usize, String> {
        match self.extra.get(LABELLED_FROM) {
            None => Ok(0),
            Some(v) => v
                .parse()
                .map_err(|_| format!("extra.{LABELLED_FROM} = {v:?} is not a step number")),
        }
    }

    /// Flattens to the string map stored in mcap; extra keys are prefixed with `extra.`.
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert("schema_version".into(), SCHEMA_VERSION.into());
        m.insert("task_id".into(), self.task_id.clone());
        m.insert("instruction".into(), self.instruction.clone());
        m.insert("bddl".into(), self.bddl.clone());
        m.insert("seed".into(), self.seed.to_string());
        m.insert("sim_version".into(), self.sim_version.clone());
        m.insert("asset_version".into(), self.asset_version.clone());
        m.insert("image_orientation".into(), self.image_orientation.clone());
        m.insert("fps".into(), format!("{}", self.fps));
        for (k, v) in &self.extra {
            m.insert(format!("extra.{k}"), v.clone());
        }
        m
    }

    /// Parses the string map stored in mcap; the error says which key is missing or bad.
    pub fn from_map(m: &BTreeMap<String, String>) -> Result<Self, String> {
        let get = |k: &str| {
            m.get(k)
                .cloned()
                .ok_or_else(|| format!("metadata key `{k}` missing"))
        };
        let version = get("schema_version")?;
        if !READABLE_VERSIONS.contains(&version.as_str()) {
            return Err(format!(
                "schema_version is `{version}`, this reader understands {}",
                READABLE_VERSIONS.map(|v| format!("`{v}`")).join(" and ")
            ));
        }
        let seed = get("seed")?
            .parse::<u64>()
            .map_err(|e| format!("metadata key `seed`: {e}"))?;
        let fps = get("fps")?
            .parse::<f64>()
            .map_err(|e| format!("metadata key `fps`: {e}"))?;
        if !(fps.is_finite() && fps > 0.0) {
            return Err(format!("metadata key `fps` must be positive, got {fps}"));
        }
        let extra = m
            .iter()
            .filter_map(|(k, v)| k.strip_prefix("extra.").map(|k| (k.to_string(), v.clone())))
            .collect();
        Ok(EpisodeMeta {
            task_id: get("task_id")?,
            instruction: get("instruction")?,
            bddl: get("bddl")?,
            seed,
            sim_version: get("sim_version")?,
            asset_version: get("asset_version")?,
            image_orientation: get("image_orientation")?,
            fps,
            extra,
        })
    }
}

/// JSON message on [`TOPIC_STATE`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateMsg {
    /// Step index.
    pub step: u64,
    /// The 8-D state.
    pub state: [f32; 8],
}

/// JSON message on [`TOPIC_JOINT_STATE`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointStateMsg {
    /// Step index.
    pub step: u64,
    /// The 7 joint angles (rad).
    pub position: [f32; 7],
}

/// JSON message on [`TOPIC_ACTION`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionMsg {
    /// Step index.
    pub step: u64,
    /// The 7-D action.
    pub action: [f32; 7],
}

/// JSON message on [`TOPIC_OBJECTS`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectsMsg {
    /// Step index.
    pub step: u64,
    /// Annotations of all tracked objects.
    pub objects: Vec<ObjectAnnotation>,
}

/// JSON message on [`TOPIC_GOAL`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalMsg {
    /// Step index.
    pub step: u64,
    /// The progress.
    #[serde(flatten)]
    pub progress: GoalProgress,
}

/// JSON Schema (draft 2020-12) text for one of our schema names.
pub fn json_schema(name: &str) -> Option<&'static str> {
    Some(match name {
        SCHEMA_STATE => {
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"lmr.State","description":"Proprio state: eef position (3, m), eef axis-angle (3, rad), gripper finger qpos (2)","type":"object","properties":{"step":{"type":"integer"},"state":{"type":"array","items":{"type":"number"},"minItems":8,"maxItems":8}},"required":["step","state"]}"#
        }
        SCHEMA_JOINT_STATE => {
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"lmr.JointState","description":"7 arm joint angles (rad)","type":"object","properties":{"step":{"type":"integer"},"position":{"type":"array","items":{"type":"number"},"minItems":7,"maxItems":7}},"required":["step","position"]}"#
        }
        SCHEMA_ACTION => {
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"lmr.Action","description":"Action: delta position (3), delta axis-angle (3), gripper (-1 open, +1 close)","type":"object","properties":{"step":{"type":"integer"},"action":{"type":"array","items":{"type":"number"},"minItems":7,"maxItems":7}},"required":["step","action"]}"#
        }
        SCHEMA_OBJECTS => {
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"lmr.ObjectAnnotations","type":"object","properties":{"step":{"type":"integer"},"objects":{"type":"array","items":{"type":"object","properties":{"instance_id":{"type":"integer"},"name":{"type":"string"},"box":{"description":"x, y, w, h normalised to [0,1] in the upright agentview image","type":"array","items":{"type":"number"},"minItems":4,"maxItems":4},"visible":{"type":"boolean"},"subgoal_label":{"type":"string"},"pose":{"description":"world position (m) and quaternion w, x, y, z of the object's root body","type":"array","items":{"type":"number"},"minItems":7,"maxItems":7},"grasped":{"description":"both gripper fingers touch the object","type":"boolean"},"parts":{"description":"articulated parts: grasp point and body orientation, joint position","type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"pose":{"type":"array","items":{"type":"number"},"minItems":7,"maxItems":7},"joint":{"type":"number"}},"required":["name","pose","joint"]}}},"required":["instance_id","name","box","visible","subgoal_label"]}}},"required":["step","objects"]}"#
        }
        SCHEMA_GOAL => {
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"lmr.GoalProgress","type":"object","properties":{"step":{"type":"integer"},"satisfied":{"type":"integer"},"total":{"type":"integer"},"satisfied_subgoals":{"type":"array","items":{"type":"string"}},"current_subgoal":{"type":"string"}},"required":["step","satisfied","total","satisfied_subgoals","current_subgoal"]}"#
        }
        _ => return None,
    })
}
