//! Deterministic synthetic episodes for tests, benches and examples (no simulator needed).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::schema::*;

/// Options of [`synthetic_steps`].
#[derive(Clone, Debug)]
pub struct SynthOptions {
    /// Image width and height (square).
    pub size: u32,
    /// Record segmentation (u16 ids).
    pub segmentation: bool,
    /// Record depth.
    pub depth: bool,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            size: 32,
            segmentation: true,
            depth: true,
        }
    }
}

/// Metadata of a synthetic episode with the given seed.
pub fn synthetic_meta(seed: u64) -> EpisodeMeta {
    EpisodeMeta {
        task_id: "libero_mem/t1".into(),
        instruction: "put the bowl on the plate".into(),
        bddl: "(define (problem synthetic))".into(),
        seed,
        sim_version: "synthetic".into(),
        asset_version: "none".into(),
        ..EpisodeMeta::default()
    }
}

/// `len` smooth, textured, seeded steps: images change slowly over time (like a robot video).
pub fn synthetic_steps(len: usize, seed: u64, o: &SynthOptions) -> Vec<StepRecord> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let phase: f32 = rng.random_range(0.0..std::f32::consts::TAU);
    let s = o.size;
    (0..len)
        .map(|k| {
            let t = k as f32 * 0.05;
            let img = |off: f32| {
                let mut data = Vec::with_capacity((s * s * 3) as usize);
                for y in 0..s {
                    for x in 0..s {
                        let fx = x as f32 / s as f32;
                        let fy = y as f32 / s as f32;
                        let r = 127.5 + 120.0 * (6.0 * fx + t + phase + off).sin();
                        let g = 127.5 + 120.0 * (5.0 * fy - t + off).cos();
                        let b = if (fx - 0.5 - 0.2 * t.sin()).abs() < 0.15 && fy > 0.5 {
                            220.0
                        } else {
                            40.0 + 100.0 * fx * fy
                        };
                        data.extend([r as u8, g as u8, b as u8]);
                    }
                }
                Image {
                    width: s,
                    height: s,
                    channels: 3,
                    data,
                }
            };
            let seg = o.segmentation.then(|| {
                let d = (0..s * s)
                    .map(|i| {
                        let (x, y) = (i % s, i / s);
                        if y > s / 2 {
                            if x < s / 2 { 10 } else { 20 }
                        } else {
                            0
                        }
                    })
                    .collect();
                Segmentation::U16(Image {
                    width: s,
                    height: s,
                    channels: 1,
                    data: d,
                })
            });
            let depth = o.depth.then(|| Image {
                width: s,
                height: s,
                channels: 1,
                data: (0..s * s)
                    .map(|i| 0.5 + (i % s) as f32 * 0.01 + t)
                    .collect(),
            });
            let mut state = [0f32; 8];
            let mut joint_state = [0f32; 7];
            let mut action = [0f32; 7];
            for (i, v) in state.iter_mut().enumerate() {
                *v = (t + i as f32 * 0.3 + phase).sin() * 0.4;
            }
            for (i, v) in joint_state.iter_mut().enumerate() {
                *v = (t * 0.5 + i as f32).cos();
            }
            for v in action.iter_mut().take(6) {
                *v = rng.random_range(-1.0f32..1.0);
            }
            action[6] = if (k / 20) % 2 == 0 { -1.0 } else { 1.0 };
            let satisfied = (k / 25) as u32;
            StepRecord {
                step: k as u64,
                agentview: img(0.0),
                eye_in_hand: img(1.0),
                segmentation: seg,
                depth,
                state,
                joint_state,
                action,
                objects: vec![
                    ObjectAnnotation {
                        instance_id: 10,
                        name: "bowl".into(),
                        bbox: [0.0, 0.5, 0.5, 0.5],
                        visible: true,
                        subgoal_label: if satisfied > 0 {
                            "one: bowl 1 on plate 1".into()
                        } else {
                            "0".into()
                        },
                        pose: Some([0.1, 0.01 * k as f32, 0.9, 1.0, 0.0, 0.0, 0.0]),
                        grasped: Some(k % 5 == 2),
                        parts: Vec::new(),
                    },
                    ObjectAnnotation {
                        instance_id: 20,
                        name: "plate".into(),
                        bbox: [0.5, 0.5, 0.5, 0.5],
                        visible: k % 7 != 3,
                        subgoal_label: "0".into(),
                        pose: None,
                        grasped: None,
                        parts: Vec::new(),
                    },
                ],
                progress: GoalProgress {
                    satisfied,
                    total: 3,
                    satisfied_subgoals: (0..satisfied)
                        .map(|i| format!("subgoal {i} done"))
                        .collect(),
                    current_subgoal: format!("bowl {} on plate {}", satisfied + 1, satisfied + 1),
                },
            }
        })
        .collect()
}

/// Writes `episodes` synthetic episodes to `dir` (even: PNG with segmentation and depth; odd:
/// JPEG without) and builds the index; returns the episode paths.
pub fn write_synthetic_dataset(
    dir: &std::path::Path,
    episodes: usize,
    steps: usize,
    size: u32,
) -> crate::Result<Vec<std::path::PathBuf>> {
    use crate::{EpisodeWriter, ImageCompression, IndexOptions, WriterOptions};
    std::fs::create_dir_all(dir).map_err(|e| crate::DataError::io(dir, e))?;
    let mut out = vec![];
    for e in 0..episodes {
        let even = e % 2 == 0;
        let o = SynthOptions {
            size,
            segmentation: even,
            depth: even,
        };
        let opts = WriterOptions {
            image_compression: if even {
                ImageCompression::Png
            } else {
                ImageCompression::Jpeg { quality: 90 }
            },
            chunk_size: 64 * 1024,
            ..WriterOptions::default()
        };
        let mut w = EpisodeWriter::create(
            dir.join(format!("synth_{e:03}.mcap")),
            synthetic_meta(e as u64),
            opts,
        )?;
        for s in synthetic_steps(steps, e as u64, &o) {
            w.write_step(&s)?;
        }
        out.push(w.finish()?);
    }
    crate::build_index(
        dir,
        &IndexOptions {
            val_fraction: 0.0,
            seed: 0,
        },
    )?;
    Ok(out)
}
