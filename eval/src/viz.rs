//! Slot visualisation (the paper's slot figure): per step, the agentview frame, the frame coloured by
//! the slot that wins each token, and one tile per slot showing the frame weighted by that slot's
//! attention mask — written as `step_<N>.png` strips.

use std::path::{Path, PathBuf};

use sim::Observation;

use crate::error::EvalError;
use crate::policy::Policy;

/// Distinct slot colours (RGB), cycled when there are more slots.
pub const PALETTE: [[u8; 3]; 8] = [
    [230, 25, 75],
    [60, 180, 75],
    [0, 130, 200],
    [255, 225, 25],
    [145, 30, 180],
    [70, 240, 240],
    [245, 130, 48],
    [240, 50, 230],
];

/// Bilinearly upsamples a `rows × cols` grid (row-major) to `size × size` (half-pixel centres).
pub fn upsample(grid: &[f32], rows: usize, cols: usize, size: usize) -> Vec<f32> {
    let coord = |i: usize, n: usize| -> (usize, usize, f32) {
        let f = ((i as f32 + 0.5) * n as f32 / size as f32 - 0.5).clamp(0.0, (n - 1) as f32);
        let i0 = f.floor() as usize;
        (i0, (i0 + 1).min(n - 1), f - i0 as f32)
    };
    let mut out = vec![0.0; size * size];
    for y in 0..size {
        let (y0, y1, fy) = coord(y, rows);
        for x in 0..size {
            let (x0, x1, fx) = coord(x, cols);
            let g = |r: usize, c: usize| grid[r * cols + c];
            let top = g(y0, x0) * (1.0 - fx) + g(y0, x1) * fx;
            let bot = g(y1, x0) * (1.0 - fx) + g(y1, x1) * fx;
            out[y * size + x] = top * (1.0 - fy) + bot * fy;
        }
    }
    out
}

/// Composes one strip `[S, S·(K+2), 3]`: the frame, the arg-max slot colouring blended over it,
/// then each slot's mask (normalised to its maximum) multiplying the frame.
///
/// # Shapes
/// - rgb: `[S, S, 3]`; masks: `[K][rows·cols]`
pub fn strip(rgb: &[u8], size: usize, masks: &[Vec<f32>], rows: usize, cols: usize) -> Vec<u8> {
    let k = masks.len();
    let width = size * (k + 2);
    let mut out = vec![0u8; size * width * 3];
    let up: Vec<Vec<f32>> = masks
        .iter()
        .map(|m| upsample(m, rows, cols, size))
        .collect();
    for y in 0..size {
        for x in 0..size {
            let p = y * size + x;
            let px = &rgb[p * 3..p * 3 + 3];
            let put = |out: &mut Vec<u8>, tile: usize, c: [u8; 3]| {
                let o = (y * width + tile * size + x) * 3;
                out[o..o + 3].copy_from_slice(&c);
            };
            put(&mut out, 0, [px[0], px[1], px[2]]);
            let best = (0..k)
                .max_by(|&a, &b| up[a][p].total_cmp(&up[b][p]))
                .unwrap_or(0);
            let col = PALETTE[best % PALETTE.len()];
            let blend = |i: usize| (0.45 * px[i] as f32 + 0.55 * col[i] as f32) as u8;
            put(&mut out, 1, [blend(0), blend(1), blend(2)]);
            for (s, m) in up.iter().enumerate() {
                let peak = masks[s].iter().cloned().fold(1e-6f32, f32::max);
                let w = (m[p] / peak).clamp(0.0, 1.0);
                let f = |i: usize| (px[i] as f32 * w) as u8;
                put(&mut out, s + 2, [f(0), f(1), f(2)]);
            }
        }
    }
    out
}

/// Writes the strips of one rollout into a folder.
pub struct Writer {
    dir: PathBuf,
    every: usize,
    written: usize,
}

impl Writer {
    /// Creates (or reuses) `dir`; a frame is written every `every` steps.
    pub fn create(dir: &Path, every: usize) -> Result<Writer, EvalError> {
        std::fs::create_dir_all(dir).map_err(|e| EvalError::Output {
            path: dir.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(Writer {
            dir: dir.to_path_buf(),
            every: every.max(1),
            written: 0,
        })
    }

    /// Strips written so far.
    pub fn written(&self) -> usize {
        self.written
    }

    /// Writes the strip of `step` (if it is due) from `obs` and the masks `policy` just used.
    pub fn frame(
        &mut self,
        step: usize,
        obs: &Observation,
        policy: &dyn Policy,
    ) -> Result<(), EvalError> {
        if !step.is_multiple_of(self.every) {
            return Ok(());
        }
        let Some((masks, rows, cols)) = policy.slot_masks() else {
            return Err(EvalError::Argument(
                "--viz needs a slot policy (a run of a slot model)".into(),
            ));
        };
        let size = obs.image_size;
        if size == 0 {
            return Err(EvalError::Argument("--viz needs rendered frames".into()));
        }
        let img = strip(&obs.agentview_rgb, size, &masks, rows, cols);
        let path = self.dir.join(format!("step_{step:04}.png"));
        let width = (size * (masks.len() + 2)) as u32;
        let buf = image::RgbImage::from_raw(width, size as u32, img).ok_or_else(|| {
            EvalError::Output {
                path: path.clone(),
                message: "strip size mismatch".into(),
            }
        })?;
        let mut bytes = Vec::new();
        buf.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| EvalError::Output {
            path: path.clone(),
            message: e.to_string(),
        })?;
        data::fsio::write_atomic(&path, &bytes)?;
        self.written += 1;
        Ok(())
    }
}

/// The video of one rollout: a frame per step (the observation the policy acted on) and the
/// last observation, with its first frame as a poster image beside it.
pub struct Video {
    writer: Option<data::video::VideoWriter>,
    path: PathBuf,
    budget: usize,
}

impl Video {
    /// A video to be written to `path` for an episode of `budget` steps.
    pub fn new(path: &Path, budget: usize) -> Self {
        Video {
            writer: None,
            path: path.to_path_buf(),
            budget,
        }
    }

    /// Appends the frame of `obs` at `step`.
    pub fn frame(&mut self, obs: &Observation, step: usize) -> Result<(), EvalError> {
        let (rgb, w, h) = sim::generate::video_frame(obs, step, self.budget).ok_or_else(|| {
            EvalError::Output {
                path: self.path.clone(),
                message: "the environment renders no camera images".into(),
            }
        })?;
        if self.writer.is_none() {
            self.writer = Some(data::video::VideoWriter::create(&self.path, w, h, 20)?);
            // The first frame as the video's poster (`<stem>.png` beside it), which a page shows
            // before the video plays.
            let poster = self.path.with_extension("png");
            let img =
                image::RgbImage::from_raw(w as u32, h as u32, rgb.clone()).ok_or_else(|| {
                    EvalError::Output {
                        path: poster.clone(),
                        message: "frame size".into(),
                    }
                })?;
            data::fsio::write_png(&poster, &img)?;
        }
        self.writer.as_mut().expect("created").push(&rgb)?;
        Ok(())
    }

    /// Finishes the file.
    pub fn finish(self) -> Result<(), EvalError> {
        if let Some(w) = self.writer {
            w.finish()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upsample_keeps_constants_and_corners() {
        let g = upsample(&[0.25; 4], 2, 2, 8);
        assert!(g.iter().all(|&v| (v - 0.25).abs() < 1e-6));
        let g = upsample(&[0.0, 1.0, 0.0, 1.0], 2, 2, 4);
        assert_eq!(g[0], 0.0);
        assert_eq!(g[3], 1.0);
        assert!(g[1] > 0.0 && g[1] < g[2]);
    }

    #[test]
    fn strip_layout_and_argmax_colours() {
        // 2 slots over a 1×2 grid: slot 0 owns the left token, slot 1 the right one.
        let size = 4;
        let rgb = vec![200u8; size * size * 3];
        let masks = vec![vec![1.0, 0.0], vec![0.0, 1.0]];
        let s = strip(&rgb, size, &masks, 1, 2);
        let width = size * 4;
        assert_eq!(s.len(), size * width * 3);
        let px = |x: usize, y: usize| &s[(y * width + x) * 3..(y * width + x) * 3 + 3];
        assert_eq!(px(0, 0), [200, 200, 200]);
        // Arg-max tile: left blended with slot 0's colour, right with slot 1's.
        let c0 = PALETTE[0];
        assert_eq!(px(size, 0)[0], (0.45 * 200.0 + 0.55 * c0[0] as f32) as u8);
        let c1 = PALETTE[1];
        assert_eq!(
            px(2 * size - 1, 0)[1],
            (0.45 * 200.0 + 0.55 * c1[1] as f32) as u8
        );
        // Slot 0's tile is bright on the left, dark on the right.
        assert_eq!(px(2 * size, 0), [200, 200, 200]);
        assert_eq!(px(3 * size - 1, 0), [0, 0, 0]);
    }
}
