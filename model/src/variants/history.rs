//! Frame history of SlotVLA(h) and dense(h) (model.md §9): the decoder sees the tokens of the
//! last h frames, each with a learned frame-offset embedding.

use std::collections::VecDeque;

use burn::module::Param;
use burn::prelude::*;
use burn::tensor::Distribution;

/// Frame-offset embeddings of an h-frame history (h > 1).
#[derive(Module, Debug)]
pub struct History {
    /// Frame-offset embedding `[h, D_dec]` (row h−1 = the current frame).
    pub frame_offset: Param<Tensor<2>>,
}

impl History {
    /// A history of `h` frames of width `width`; None for h = 1 (no history).
    pub fn new(h: usize, width: usize, device: &Device) -> Option<Self> {
        (h > 1).then(|| History {
            frame_offset: Param::from_tensor(Tensor::random(
                [h, width],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
        })
    }

    /// Frames of history h.
    pub fn len(&self) -> usize {
        self.frame_offset.dims()[0]
    }

    /// Always false (h > 1).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Adds the frame-offset embedding to `frames` frames of tokens that end at the current
    /// frame, and concatenates them (oldest first).
    ///
    /// # Shapes
    /// - frames: n × `[N, V₁, D_dec]` (oldest first, 1 ≤ n ≤ h)
    /// - output: `[N, n·V₁, D_dec]`
    pub fn stack(&self, frames: Vec<Tensor<3>>) -> Tensor<3> {
        let h = self.len();
        let n = frames.len();
        assert!(n >= 1 && n <= h, "{n} frames for a history of {h}");
        let emb = self.frame_offset.val();
        let frames = frames
            .into_iter()
            .enumerate()
            .map(|(i, f)| f + emb.clone().narrow(0, h - n + i, 1).unsqueeze_dim(0))
            .collect();
        Tensor::cat(frames, 1)
    }

    /// History tokens for every frame of a window: frame t sees frames t−h+1 … t; frames before
    /// the window start repeat frame 0 and are masked.
    ///
    /// # Shapes
    /// - tokens: `[B·T, V₁, D_dec]`
    /// - output: (`[B·T, h·V₁, D_dec]`, pad `[B·T, h·V₁]`)
    pub fn window(&self, tokens: Tensor<3>, b: usize, t: usize) -> (Tensor<3>, Tensor<2, Bool>) {
        let h = self.len();
        let [_, v, w] = tokens.dims();
        let device = tokens.device();
        let x = tokens.reshape([b, t, v, w]);
        let first = x.clone().narrow(1, 0, 1);
        let mut frames = Vec::with_capacity(h);
        let mut pads = Vec::with_capacity(h);
        for o in 0..h {
            let lag = h - 1 - o;
            let shifted = if lag == 0 {
                x.clone()
            } else if lag >= t {
                first.clone().repeat_dim(1, t)
            } else {
                Tensor::cat(
                    vec![
                        first.clone().repeat_dim(1, lag),
                        x.clone().narrow(1, 0, t - lag),
                    ],
                    1,
                )
            };
            frames.push(shifted.reshape([b * t, v, w]));
            let pad: Vec<f32> = (0..t).map(|ti| if ti < lag { 1.0 } else { 0.0 }).collect();
            pads.push(
                Tensor::<1>::from_data(TensorData::new(pad, [t]), &device)
                    .reshape([1, t, 1])
                    .repeat_dim(0, b)
                    .repeat_dim(2, v)
                    .reshape([b * t, v]),
            );
        }
        (self.stack(frames), Tensor::cat(pads, 1).equal_elem(1.0))
    }

    /// Appends this frame's tokens to a streaming history and returns what the decoder sees.
    ///
    /// # Shapes
    /// - tokens: `[1, V₁, D_dec]`; output: `[1, n·V₁, D_dec]`, n ≤ h
    pub fn step(&self, tokens: Tensor<3>, history: &mut VecDeque<Tensor<3>>) -> Tensor<3> {
        history.push_back(tokens);
        while history.len() > self.len() {
            history.pop_front();
        }
        self.stack(history.iter().cloned().collect())
    }
}
