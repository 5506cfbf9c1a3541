//! Perceptual aliasing of expert episodes: how often does a frame's nearest neighbour (in a memoryless
//! feature space) need a different next subgoal?
//!
//! Every frame of a set of expert episodes gets a feature vector (a downsampled grey agentview image, the
//! robot and object state, or both) and a label (the index of the pending subgoal, i.e. the number of
//! subgoals the goal tracker has satisfied so far, and its text). For each frame the nearest other frame
//! is found, excluding frames of the same episode within ±`k` steps (those trivially look alike). The
//! aliasing fraction is the share of frames whose nearest neighbour has a different label: a policy that
//! sees only the current frame cannot tell those situations apart, so the task needs memory.

use thiserror::Error;

use crate::expert::Expert;
use crate::task::TaskSpec;
use crate::world::env::{Env, EnvConfig, EnvError, Observation};

/// Errors of [`collect`].
#[derive(Debug, Error)]
pub enum AliasingError {
    /// The environment failed.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// Bad arguments.
    #[error("{0}")]
    Argument(String),
}

/// One recorded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Episode index within the collection.
    pub episode: usize,
    /// Control step within the episode.
    pub t: usize,
    /// Downsampled grey agentview image, values in [0, 1], row-major.
    pub image: Vec<f32>,
    /// Robot state (end-effector position, quaternion, gripper) and object positions and quaternions.
    pub state: Vec<f32>,
    /// Index of the pending subgoal (= satisfied subgoals).
    pub label: usize,
    /// Text of the pending subgoal (`"done"` once complete).
    pub label_text: String,
}

/// Which part of a frame the nearest-neighbour search sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Features {
    /// Image and state, each block standardised and weighted equally.
    Both,
    /// The downsampled image only.
    Image,
    /// The robot and object state only.
    State,
}

/// Aliasing figures for one feature choice.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Frames with an admissible neighbour.
    pub frames: usize,
    /// Fraction whose nearest neighbour has a different pending-subgoal index.
    pub index_fraction: f64,
    /// Fraction whose nearest neighbour has a different pending-subgoal text.
    pub text_fraction: f64,
    /// Fraction whose nearest neighbour comes from another episode.
    pub cross_episode: f64,
    /// Per pending-subgoal index: (index, text, frames, fraction with a different index).
    pub per_label: Vec<(usize, String, usize, f64)>,
}

/// Averages `side`×`side` blocks of an `n`×`n` RGB image into a `side`×`side` grey image in [0, 1].
pub fn downsample_grey(rgb: &[u8], n: usize, side: usize) -> Vec<f32> {
    let mut out = vec![0f32; side * side];
    let mut cnt = vec![0u32; side * side];
    for y in 0..n {
        let by = y * side / n;
        for x in 0..n {
            let bx = x * side / n;
            let p = &rgb[3 * (y * n + x)..3 * (y * n + x) + 3];
            let g = 0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32;
            out[by * side + bx] += g / 255.0;
            cnt[by * side + bx] += 1;
        }
    }
    for (o, c) in out.iter_mut().zip(cnt) {
        *o /= c.max(1) as f32;
    }
    out
}

fn state_of(env: &Env, obs: &Observation) -> Vec<f32> {
    let mut s: Vec<f32> = obs.state.to_vec();
    if let Some(scene) = env.scene() {
        for inst in &scene.instances {
            if inst.def.kind != crate::world::assets::AssetKind::Movable {
                continue;
            }
            let p = env.data().body_pos(inst.root_body);
            let q = env.data().body_quat(inst.root_body);
            s.extend(p.iter().map(|&v| v as f32));
            // q and −q are the same rotation.
            let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
            s.extend(q.iter().map(|&v| (sign * v) as f32));
        }
    }
    s
}

/// Runs the expert on `task` for `episodes` seeds from `seed` (rendering the agentview at `render_size`)
/// and records every observation as a [`Frame`] with a `side`×`side` image.
pub fn collect(
    task: &TaskSpec,
    episodes: usize,
    seed: u64,
    render_size: usize,
    side: usize,
) -> Result<Vec<Frame>, AliasingError> {
    if side == 0 || render_size < side {
        return Err(AliasingError::Argument(format!(
            "image side {side} must be between 1 and the render size {render_size}"
        )));
    }
    let mut env = Env::from_task(
        task,
        EnvConfig {
            image_size: render_size,
            ..EnvConfig::default()
        },
    )?;
    let mut frames = Vec::new();
    for e in 0..episodes {
        let s = seed + e as u64;
        let mut obs = env.reset(s)?;
        let mut ex = Expert::new(task, s);
        loop {
            let g = obs.goal.clone().unwrap_or_default();
            frames.push(Frame {
                episode: e,
                t: obs.step,
                image: downsample_grey(&obs.agentview_rgb, obs.image_size, side),
                state: state_of(&env, &obs),
                label: g.satisfied,
                label_text: g.pending.clone().unwrap_or_else(|| "done".into()),
            });
            if obs.step >= task.max_steps {
                break;
            }
            let Some(a) = ex.act(&env, &obs) else { break };
            obs = env.step(&a)?;
        }
    }
    Ok(frames)
}

/// Standardises each dimension over `rows` and scales the block so its squared norm averages 1.
fn standardise(rows: &[&[f32]]) -> Vec<Vec<f32>> {
    let d = rows.first().map(|r| r.len()).unwrap_or(0);
    let n = rows.len().max(1) as f64;
    let mut mean = vec![0f64; d];
    let mut var = vec![0f64; d];
    for r in rows {
        for (m, &v) in mean.iter_mut().zip(r.iter()) {
            *m += v as f64 / n;
        }
    }
    for r in rows {
        for ((s, &v), m) in var.iter_mut().zip(r.iter()).zip(&mean) {
            *s += (v as f64 - m).powi(2) / n;
        }
    }
    let live = var.iter().filter(|&&v| v > 1e-12).count().max(1) as f64;
    let scale: Vec<f64> = var
        .iter()
        .map(|&v| {
            if v > 1e-12 {
                1.0 / (v.sqrt() * live.sqrt())
            } else {
                0.0
            }
        })
        .collect();
    rows.iter()
        .map(|r| {
            r.iter()
                .zip(mean.iter().zip(&scale))
                .map(|(&v, (m, s))| ((v as f64 - m) * s) as f32)
                .collect()
        })
        .collect()
}

/// The feature vectors of `frames` for a feature choice.
pub fn features(frames: &[Frame], which: Features) -> Vec<Vec<f32>> {
    let img: Vec<&[f32]> = frames.iter().map(|f| f.image.as_slice()).collect();
    let st: Vec<&[f32]> = frames.iter().map(|f| f.state.as_slice()).collect();
    match which {
        Features::Image => standardise(&img),
        Features::State => standardise(&st),
        Features::Both => standardise(&img)
            .into_iter()
            .zip(standardise(&st))
            .map(|(mut a, b)| {
                a.extend(b);
                a
            })
            .collect(),
    }
}

/// Index of each frame's nearest admissible neighbour (another episode, or the same episode more than
/// `k` steps away); `None` when there is none.
pub fn nearest_neighbours(frames: &[Frame], feats: &[Vec<f32>], k: usize) -> Vec<Option<usize>> {
    (0..frames.len())
        .map(|i| {
            let mut best: Option<(f32, usize)> = None;
            for j in 0..frames.len() {
                if frames[j].episode == frames[i].episode && frames[j].t.abs_diff(frames[i].t) <= k
                {
                    continue;
                }
                let d: f32 = feats[i]
                    .iter()
                    .zip(&feats[j])
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
                if best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, j));
                }
            }
            best.map(|(_, j)| j)
        })
        .collect()
}

/// Aliasing figures of `frames` under a feature choice, excluding same-episode neighbours within ±`k`.
pub fn analyse(frames: &[Frame], which: Features, k: usize) -> Report {
    let feats = features(frames, which);
    let nn = nearest_neighbours(frames, &feats, k);
    let mut labels: Vec<(usize, String)> = frames
        .iter()
        .map(|f| (f.label, f.label_text.clone()))
        .collect();
    labels.sort();
    labels.dedup_by(|a, b| a.0 == b.0);
    let mut per: Vec<(usize, String, usize, usize)> =
        labels.into_iter().map(|(l, t)| (l, t, 0, 0)).collect();
    let (mut n, mut diff_idx, mut diff_text, mut cross) = (0usize, 0usize, 0usize, 0usize);
    for (i, j) in nn.iter().enumerate() {
        let Some(j) = *j else { continue };
        let (a, b) = (&frames[i], &frames[j]);
        n += 1;
        let d = a.label != b.label;
        diff_idx += d as usize;
        diff_text += (a.label_text != b.label_text) as usize;
        cross += (a.episode != b.episode) as usize;
        if let Some(row) = per.iter_mut().find(|r| r.0 == a.label) {
            row.2 += 1;
            row.3 += d as usize;
        }
    }
    let frac = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    Report {
        frames: n,
        index_fraction: frac(diff_idx, n),
        text_fraction: frac(diff_text, n),
        cross_episode: frac(cross, n),
        per_label: per
            .into_iter()
            .map(|(l, t, c, d)| (l, t, c, frac(d, c)))
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(episode: usize, t: usize, x: f32, label: usize) -> Frame {
        Frame {
            episode,
            t,
            image: vec![x, 0.5 * x],
            state: vec![x],
            label,
            label_text: format!("subgoal {}", label % 2),
        }
    }

    /// An out-and-back trajectory: the way back passes 0.3 beside the way out but needs the other
    /// subgoal. Alone, every frame's nearest admissible neighbour is on the other leg (fraction 1); with
    /// a twin episode shifted by 0.1 the nearest is always the twin's same frame (fraction 0).
    #[test]
    fn out_and_back_is_aliased_unless_a_twin_episode_exists() {
        let leg = |e: usize, shift: f32| -> Vec<Frame> {
            (0..20)
                .map(|t| {
                    let x = if t < 10 {
                        t as f32
                    } else {
                        (19 - t) as f32 + 0.3
                    };
                    frame(e, t, x + shift, t / 10)
                })
                .collect()
        };
        let alone = leg(0, 0.0);
        let r = analyse(&alone, Features::State, 3);
        assert_eq!(r.frames, 20);
        assert_eq!(r.index_fraction, 1.0);
        assert_eq!(r.cross_episode, 0.0);
        assert_eq!(
            r.per_label,
            vec![
                (0, "subgoal 0".to_string(), 10, 1.0),
                (1, "subgoal 1".to_string(), 10, 1.0)
            ]
        );

        let mut twins = leg(0, 0.0);
        twins.extend(leg(1, 0.1));
        for which in [Features::State, Features::Image, Features::Both] {
            let r = analyse(&twins, which, 3);
            assert_eq!(r.frames, 40);
            assert_eq!(r.index_fraction, 0.0, "{which:?}");
            assert_eq!(r.cross_episode, 1.0);
        }
    }

    /// A known answer: frames on two well separated clusters per label are never aliased; the same
    /// positions with labels swapped half-way through are aliased exactly for the swapped half.
    #[test]
    fn separated_labels_are_not_aliased_and_swapped_ones_are() {
        let mut frames = Vec::new();
        for e in 0..4 {
            for t in 0..20 {
                let label = t / 10;
                // Episode offsets 0, 0.011, 0.024, 0.039: nearest episodes 0↔1, 2→1, 3→2.
                let x = label as f32 * 100.0
                    + (t % 10) as f32 * 0.1
                    + (10 + e) as f32 * e as f32 * 0.001;
                frames.push(frame(e, t, x, label));
            }
        }
        let r = analyse(&frames, Features::Both, 2);
        assert_eq!(r.frames, 80);
        assert_eq!(r.index_fraction, 0.0);
        assert_eq!(r.per_label.len(), 2);
        assert_eq!(r.per_label[1].2, 40);

        // Episodes 2 and 3 now carry label 1 in their first half and 0 in their second.
        for f in frames.iter_mut().filter(|f| f.episode >= 2) {
            f.label = 1 - f.label;
        }
        let r = analyse(&frames, Features::State, 2);
        // Only episode 2's nearest (episode 1) carries the other labels: 20 of 80 frames.
        assert!((r.index_fraction - 0.25).abs() < 1e-12, "{r:?}");
        assert!((r.cross_episode - 1.0).abs() < 1e-12);
    }

    #[test]
    fn downsample_averages_blocks() {
        // 2×2 RGB: white, black / black, white → 1×1 grey 0.5.
        let rgb = [255, 255, 255, 0, 0, 0, 0, 0, 0, 255, 255, 255];
        let g = downsample_grey(&rgb, 2, 1);
        assert_eq!(g.len(), 1);
        assert!((g[0] - 0.5).abs() < 1e-6);
        let g = downsample_grey(&rgb, 2, 2);
        assert!((g[0] - 1.0).abs() < 1e-6 && g[1].abs() < 1e-6);
    }
}
