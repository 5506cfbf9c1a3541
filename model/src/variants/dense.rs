//! Dense patch tokens (model.md §9): no slots; the decoder sees W_p F of the last h frames
//! (OpenVLA feeds its patch tokens the same way).

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;

use super::history::History;
use super::types::{Carry, Memory, Shared, TYPE_PATCH, WindowParts, WindowTokens};
use crate::config::ModelConfig;
use crate::error::Result;

/// The dense variant's token builder.
#[derive(Module, Debug)]
pub struct DenseTokens {
    /// Patch tokens W_p `[D_f, D_dec]`.
    pub patch_proj: Linear,
    /// Frame-offset embeddings (h > 1).
    pub history: Option<History>,
}

impl DenseTokens {
    /// Builds the dense variant of `config`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        DenseTokens {
            patch_proj: LinearConfig::new(config.encoder.feature_dim, config.decoder.width)
                .init(device),
            history: History::new(config.variant.history(), config.decoder.width, device),
        }
    }

    fn tokens(&self, feats: Tensor<3>, shared: Shared) -> Tensor<3> {
        self.patch_proj.forward(feats) + shared.type_embedding(TYPE_PATCH)
    }

    /// # Shapes
    /// - feats: `[B, T, M, D_f]`; output: see [`WindowTokens`]
    pub fn window(&self, feats: Tensor<4>, carry: Carry, shared: Shared) -> Result<WindowTokens> {
        let [b, t, m, d_f] = feats.dims();
        let tokens = self.tokens(feats.reshape([b * t, m, d_f]), shared);
        let h = History::window_of(self.history.as_ref(), tokens, b, t, &carry);
        Ok(WindowTokens {
            tokens: h.tokens,
            pad: h.pad,
            parts: WindowParts::default(),
            carry: Carry {
                history: h.last,
                history_valid: h.valid,
                ..Carry::default()
            },
        })
    }

    /// # Shapes
    /// - feats: `[1, M, D_f]`; output: `[1, V, D_dec]`
    pub fn step(&self, feats: Tensor<3>, memory: &mut Memory, shared: Shared) -> Tensor<3> {
        let tokens = self.tokens(feats, shared);
        History::step_of(self.history.as_ref(), tokens, &mut memory.history)
    }
}
