//! Episode recording: an [`Env`] rollout → one mcap episode through the `data` crate's writer.
//!
//! Each record pairs the observation at step t with the action taken there and the goal progress after
//! it. Per-object annotations come from the agentview segmentation (instance id = index of the object or
//! fixture in the scene + 1, 0 for background, table and robot), with LIBERO-Mem's subgoal labels: every
//! object starts at `"0"`; when a new subgoal is satisfied, each object the fingers touched in more than 20
//! contact-steps since the previous one receives that subgoal's text (the reference's `TrajectoryRecorder`).

use std::path::{Path, PathBuf};

use data::{
    DepthImage, EpisodeMeta, EpisodeWriter, Image, ObjectAnnotation, RgbImage, Segmentation,
    StepRecord, WriterOptions,
};

use super::labels::LabelTracker;
pub use super::labels::TOUCH_THRESHOLD;
use crate::task::TaskSpec;
use crate::world::env::{Env, Observation};

/// Version string stored in every episode's metadata.
pub const SIM_VERSION: &str = concat!(
    "libero-mem-rs sim ",
    env!("CARGO_PKG_VERSION"),
    " (MuJoCo 2.2.2)"
);
/// Version of the built-in asset library.
pub const ASSET_VERSION: &str = "primitives-1";

/// Errors while recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The data crate failed to write.
    #[error(transparent)]
    Data(#[from] data::DataError),
    /// The environment is not a task environment with cameras and segmentation.
    #[error("cannot record: {0}")]
    Setup(String),
}

/// Writes one episode step by step.
pub struct Recorder {
    writer: EpisodeWriter,
    labels: LabelTracker,
    step: u64,
}

impl Recorder {
    /// Starts an episode file at `path` for `task` run with `seed` in `env` (which must render with
    /// segmentation on).
    pub fn create(
        path: &Path,
        env: &Env,
        task: &TaskSpec,
        seed: u64,
        opts: WriterOptions,
    ) -> Result<Recorder, RecordError> {
        Recorder::create_with(path, env, task, seed, opts, &[])
    }

    /// [`create`](Self::create) with further `(key, value)` pairs in the episode metadata's
    /// `extra` map (e.g. [`data::LABELLED_FROM`]).
    pub fn create_with(
        path: &Path,
        env: &Env,
        task: &TaskSpec,
        seed: u64,
        opts: WriterOptions,
        extra: &[(&str, String)],
    ) -> Result<Recorder, RecordError> {
        let scene = env
            .scene()
            .ok_or_else(|| RecordError::Setup("the environment has no task scene".into()))?;
        if !env.config().render || !env.config().segmentation {
            return Err(RecordError::Setup(
                "the environment must render with segmentation on".into(),
            ));
        }
        let labels = LabelTracker::new(env)
            .ok_or_else(|| RecordError::Setup("the environment has no task scene".into()))?;
        let mut meta = EpisodeMeta {
            task_id: task.id.clone(),
            instruction: task.instruction.clone(),
            bddl: task.bddl_text.clone(),
            seed,
            sim_version: SIM_VERSION.into(),
            asset_version: ASSET_VERSION.into(),
            ..EpisodeMeta::default()
        };
        meta.extra
            .insert("goal_len".into(), task.goal_len.to_string());
        meta.extra
            .insert("max_steps".into(), task.max_steps.to_string());
        meta.extra.insert(
            "instances".into(),
            scene
                .instances
                .iter()
                .map(|i| i.name.as_str())
                .collect::<Vec<_>>()
                .join(","),
        );
        for (k, v) in extra {
            meta.extra.insert((*k).to_string(), v.clone());
        }
        Ok(Recorder {
            writer: EpisodeWriter::create(path, meta, opts)?,
            labels,
            step: 0,
        })
    }

    /// Records `obs` (the observation the action was chosen from), the `action`, and the progress
    /// reported by `next` (the observation after the step). Call after `env.step` returned `next`.
    pub fn record(
        &mut self,
        env: &Env,
        obs: &Observation,
        action: [f32; 7],
        next: &Observation,
    ) -> Result<(), RecordError> {
        let scene = env
            .scene()
            .ok_or_else(|| RecordError::Setup("no task scene".into()))?;
        // Finger contacts during this step (counted on the state after it, once per control step).
        self.labels.update(env, next.goal.as_ref());
        let goal = next.goal.clone().unwrap_or_default();

        let s = obs.image_size as u32;
        let rgb = |v: &[u8]| -> Result<RgbImage, RecordError> {
            if v.len() != (3 * s * s) as usize {
                return Err(RecordError::Setup(
                    "observation images do not match the image size".into(),
                ));
            }
            Ok(RgbImage {
                width: s,
                height: s,
                channels: 3,
                data: v.to_vec(),
            })
        };
        let seg = obs
            .agentview_segmentation
            .as_ref()
            .ok_or_else(|| RecordError::Setup("no segmentation".into()))?;
        let ids = instance_ids(scene, seg);
        let mut objects = annotations(scene, &ids, s as usize, self.labels.labels());
        add_poses(&mut objects, obs);
        let record = StepRecord {
            step: self.step,
            agentview: rgb(&obs.agentview_rgb)?,
            eye_in_hand: rgb(&obs.eye_in_hand_rgb)?,
            segmentation: Some(Segmentation::U16(Image {
                width: s,
                height: s,
                channels: 1,
                data: ids,
            })),
            depth: obs.agentview_depth.as_ref().map(|d| DepthImage {
                width: s,
                height: s,
                channels: 1,
                data: d.clone(),
            }),
            state: obs.state,
            joint_state: obs.joint_state,
            action,
            objects,
            progress: goal.progress(),
        };
        self.writer.write_step(&record)?;
        self.step += 1;
        Ok(())
    }

    /// Steps written so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Closes the file under its final name. Dropping a recorder instead leaves no file behind.
    pub fn finish(self) -> Result<PathBuf, RecordError> {
        Ok(self.writer.finish()?)
    }
}

/// The objects of a task scene as an episode records them at one observation: instance names in
/// scene order, boxes and visibility from the agentview segmentation (zero boxes, not visible,
/// when `obs` has none), poses and grasps, and the given oracle labels (`"0"` where `labels` has
/// none). The recorder and the evaluator's input path both build them here.
pub fn object_annotations(
    env: &Env,
    obs: &Observation,
    labels: &[String],
) -> Vec<ObjectAnnotation> {
    let Some(scene) = env.scene() else {
        return Vec::new();
    };
    let n = scene.instances.len();
    let labels: Vec<String> = (0..n)
        .map(|k| labels.get(k).cloned().unwrap_or_else(|| "0".into()))
        .collect();
    let s = obs.image_size;
    let ids = match &obs.agentview_segmentation {
        Some(seg) if s > 0 && seg.len() == s * s => instance_ids(scene, seg),
        _ => Vec::new(),
    };
    let mut objects = annotations(scene, &ids, s.max(1), &labels);
    add_poses(&mut objects, obs);
    objects
}

/// Top-level body id map → instance id map (index + 1; 0 for everything else).
fn instance_ids(scene: &crate::world::scene::Scene, seg: &[i32]) -> Vec<u16> {
    seg.iter()
        .map(|&b| {
            if b < 0 {
                0
            } else {
                scene
                    .instances
                    .iter()
                    .position(|i| i.root_body == b as usize)
                    .map_or(0, |k| k as u16 + 1)
            }
        })
        .collect()
}

/// The observed poses and grasps of the objects (scene order).
fn add_poses(objects: &mut [ObjectAnnotation], obs: &Observation) {
    for (o, st) in objects.iter_mut().zip(&obs.objects) {
        o.pose = Some(st.pose());
        o.grasped = Some(st.grasped);
        o.parts = st
            .parts
            .iter()
            .map(|p| data::PartState {
                name: p.name.clone(),
                pose: p.pose(),
                joint: p.joint as f32,
            })
            .collect();
    }
}

/// Boxes and visibility of every instance from an instance-id map `[S, S]`.
fn annotations(
    scene: &crate::world::scene::Scene,
    ids: &[u16],
    s: usize,
    labels: &[String],
) -> Vec<ObjectAnnotation> {
    let n = scene.instances.len();
    let mut lo = vec![(usize::MAX, usize::MAX); n];
    let mut hi = vec![(0usize, 0usize); n];
    let mut seen = vec![false; n];
    for (p, &id) in ids.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let k = id as usize - 1;
        let (y, x) = (p / s, p % s);
        seen[k] = true;
        lo[k] = (lo[k].0.min(x), lo[k].1.min(y));
        hi[k] = (hi[k].0.max(x), hi[k].1.max(y));
    }
    scene
        .instances
        .iter()
        .enumerate()
        .map(|(k, inst)| ObjectAnnotation {
            instance_id: k as i32 + 1,
            name: inst.name.clone(),
            bbox: if seen[k] {
                let (x0, y0) = lo[k];
                let (x1, y1) = hi[k];
                [
                    x0 as f32 / s as f32,
                    y0 as f32 / s as f32,
                    (x1 + 1 - x0) as f32 / s as f32,
                    (y1 + 1 - y0) as f32 / s as f32,
                ]
            } else {
                [0.0; 4]
            },
            visible: seen[k],
            subgoal_label: labels[k].clone(),
            pose: None,
            grasped: None,
            parts: Vec::new(),
        })
        .collect()
}
