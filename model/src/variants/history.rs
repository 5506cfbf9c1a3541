//! Frame history of SlotVLA(h) and dense(h) (model.md §9): the decoder sees the tokens of the
//! last h frames, each with a learned frame-offset embedding.

use std::collections::VecDeque;

use burn::module::Param;

use super::types::Carry;
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

    /// History tokens for every frame of a window: frame t sees frames t−h+1 … t. Frames before
    /// the window come from the carried history where a lane continues an episode; before an
    /// episode's start (no carry, or a `fresh` lane) they repeat frame 0 and are masked.
    ///
    /// # Shapes
    /// - tokens: `[B·T, V₁, D_dec]`; carry history `[B, h−1, V₁, D_dec]`, valid `[B, h−1]`,
    ///   fresh `[B]`
    /// - output: (`[B·T, h·V₁, D_dec]`, pad `[B·T, h·V₁]`, the history after the window and its
    ///   validity, detached)
    pub fn window(
        &self,
        tokens: Tensor<3>,
        b: usize,
        t: usize,
        carry: &Carry,
    ) -> (Tensor<3>, Tensor<2, Bool>, Tensor<4>, Tensor<2, Bool>) {
        let h = self.len();
        let [_, v, w] = tokens.dims();
        let device = tokens.device();
        let x = tokens.reshape([b, t, v, w]);
        // Before the window: frame 0 repeated, invalid ...
        let mut before = x.clone().narrow(1, 0, 1).repeat_dim(1, h - 1);
        let mut before_valid = Tensor::<2, Bool>::from_data(
            TensorData::new(vec![false; b * (h - 1)], [b, h - 1]),
            &device,
        );
        // ... unless the lane continues from carried frames.
        if let (Some(prev), Some(valid)) = (&carry.history, &carry.history_valid) {
            let keep = match &carry.fresh {
                Some(f) => f.clone().bool_not(),
                None => Tensor::<1, Bool>::from_data(TensorData::new(vec![true; b], [b]), &device),
            };
            let keep2 = keep.clone().reshape([b, 1]).repeat_dim(1, h - 1);
            let keep4 = keep2
                .clone()
                .reshape([b, h - 1, 1, 1])
                .repeat_dim(2, v)
                .repeat_dim(3, w);
            before = before.mask_where(keep4, prev.clone());
            before_valid = before_valid.mask_where(keep2, valid.clone());
        }
        let ext = Tensor::cat(vec![before, x], 1); // [B, h−1+T, V₁, D_dec]
        let ext_valid = Tensor::cat(
            vec![
                before_valid,
                Tensor::<2, Bool>::from_data(TensorData::new(vec![true; b * t], [b, t]), &device),
            ],
            1,
        ); // [B, h−1+T]
        let mut frames = Vec::with_capacity(h);
        let mut pads = Vec::with_capacity(h);
        for o in 0..h {
            frames.push(ext.clone().narrow(1, o, t).reshape([b * t, v, w]));
            pads.push(
                ext_valid
                    .clone()
                    .narrow(1, o, t)
                    .bool_not()
                    .reshape([b * t, 1])
                    .repeat_dim(1, v),
            );
        }
        let last = ext.clone().narrow(1, t, h - 1).detach();
        let last_valid = ext_valid.narrow(1, t, h - 1);
        (self.stack(frames), Tensor::cat(pads, 1), last, last_valid)
    }

    /// [`History::window`] for a variant whose history may be absent (h = 1: the tokens as they
    /// are, no padding, nothing carried).
    ///
    /// # Shapes
    /// - as [`History::window`]
    pub fn window_of(
        history: Option<&History>,
        tokens: Tensor<3>,
        b: usize,
        t: usize,
        carry: &Carry,
    ) -> WindowHistory {
        match history {
            Some(h) => {
                let (tokens, pad, last, valid) = h.window(tokens, b, t, carry);
                WindowHistory {
                    tokens,
                    pad: Some(pad),
                    last: Some(last),
                    valid: Some(valid),
                }
            }
            None => WindowHistory {
                tokens,
                pad: None,
                last: None,
                valid: None,
            },
        }
    }

    /// [`History::step`] for a variant whose history may be absent (the frame's tokens alone).
    ///
    /// # Shapes
    /// - tokens: `[1, V₁, D_dec]`; output: `[1, n·V₁, D_dec]`
    pub fn step_of(
        history: Option<&History>,
        tokens: Tensor<3>,
        frames: &mut VecDeque<Tensor<3>>,
    ) -> Tensor<3> {
        match history {
            Some(h) => h.step(tokens, frames),
            None => tokens,
        }
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

/// A window's decoder tokens with their history (see [`History::window_of`]).
pub struct WindowHistory {
    /// `[B·T, V, D_dec]`.
    pub tokens: Tensor<3>,
    /// `[B·T, V]` (None without a history).
    pub pad: Option<Tensor<2, Bool>>,
    /// The last h − 1 frames' tokens, to carry.
    pub last: Option<Tensor<4>>,
    /// Their validity, to carry.
    pub valid: Option<Tensor<2, Bool>>,
}
