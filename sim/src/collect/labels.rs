//! LIBERO-Mem's per-object subgoal labels (the reference's `TrajectoryRecorder`): every object
//! starts at `"0"`; when a new subgoal is satisfied, each object the fingers touched in more than
//! [`TOUCH_THRESHOLD`] contact-steps since the previous one receives that subgoal's text (with its
//! ordinal, `"two: bowl 1 on plate 1"`), and all counters restart. The recorder writes them into
//! the episodes; the evaluator computes them live for oracle policies, with the same code.

use crate::engine::mujoco::ObjType;
use crate::world::env::{Env, GoalStatus};

/// Contacts (summed over control steps) after which a touched object receives the next subgoal label.
pub const TOUCH_THRESHOLD: u32 = 20;

/// The labels of every instance of a task scene, updated once per control step.
#[derive(Clone, Debug)]
pub struct LabelTracker {
    labels: Vec<String>,
    touches: Vec<u32>,
    finger_geoms: Vec<usize>,
    satisfied_seen: usize,
}

impl LabelTracker {
    /// A tracker for the scene of `env`, every label `"0"` (None without a task scene).
    pub fn new(env: &Env) -> Option<Self> {
        let scene = env.scene()?;
        let model = env.model();
        let finger_geoms = (0..model.ngeom())
            .filter(|&g| {
                model
                    .name(ObjType::Geom, g)
                    .is_some_and(|n| n.starts_with("gripper0_finger"))
            })
            .collect();
        Some(LabelTracker {
            labels: vec!["0".into(); scene.instances.len()],
            touches: vec![0; scene.instances.len()],
            finger_geoms,
            satisfied_seen: 0,
        })
    }

    /// Counts the finger contacts of the state `env` is in (once per control step, after it)
    /// and hands out the newest subgoal text if `goal` (the status after that step) has one.
    pub fn update(&mut self, env: &Env, goal: Option<&GoalStatus>) {
        if let Some(scene) = env.scene() {
            for c in env.data().contacts() {
                let other = if self.finger_geoms.contains(&c.geom1) {
                    c.geom2
                } else if self.finger_geoms.contains(&c.geom2) {
                    c.geom1
                } else {
                    continue;
                };
                if let Some(i) = scene
                    .instances
                    .iter()
                    .position(|inst| inst.geoms.contains(&other))
                {
                    self.touches[i] += 1;
                }
            }
        }
        let Some(goal) = goal else { return };
        if goal.satisfied > self.satisfied_seen {
            let text = goal.satisfied_texts.last().cloned().unwrap_or_default();
            for (label, t) in self.labels.iter_mut().zip(&self.touches) {
                if *t > TOUCH_THRESHOLD {
                    *label = text.clone();
                }
            }
            self.touches.iter_mut().for_each(|t| *t = 0);
            self.satisfied_seen = goal.satisfied;
        }
    }

    /// The label of every instance, in scene order.
    pub fn labels(&self) -> &[String] {
        &self.labels
    }
}
