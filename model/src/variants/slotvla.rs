//! SlotVLA(h) (model.md §9): encoder → slot attention → z = Linear(s) → relation tokens; the
//! decoder sees the slot and relation tokens of the last h frames (h = 1: Markovian).

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;

use super::history::History;
use super::slots::SlotCore;
use super::types::{Carry, Memory, Shared, WindowParts, WindowTokens};
use crate::config::ModelConfig;
use crate::error::Result;

/// SlotVLA's token builder.
#[derive(Module, Debug)]
pub struct SlotVlaTokens {
    /// Slot attention, relation tokens, projection.
    pub core: SlotCore,
    /// z = Linear(s) `[D, D]`.
    pub slot_proj: Linear,
    /// Frame-offset embeddings (h > 1).
    pub history: Option<History>,
}

impl SlotVlaTokens {
    /// Builds SlotVLA of `config` (history h from its variant).
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        SlotVlaTokens {
            core: SlotCore::new(config, device),
            slot_proj: LinearConfig::new(d, d).init(device),
            history: History::new(config.variant.history(), config.decoder.width, device),
        }
    }

    /// # Shapes
    /// - feats: `[B, T, M, D_f]`; output: see [`WindowTokens`]
    pub fn window(&self, feats: Tensor<4>, carry: Carry, shared: Shared) -> Result<WindowTokens> {
        let [b, t, m, d_f] = feats.dims();
        let (slots, masks, last) =
            self.core
                .window(feats.clone(), carry.slots.clone(), carry.fresh.clone())?;
        let [_, _, k, d] = slots.dims();
        let z = self.slot_proj.forward(slots.clone().reshape([b * t, k, d]));
        let tokens = self.core.tokens(feats.reshape([b * t, m, d_f]), z, shared);
        let h = History::window_of(self.history.as_ref(), tokens, b, t, &carry);
        Ok(WindowTokens {
            tokens: h.tokens,
            pad: h.pad,
            parts: WindowParts {
                slots: Some(slots),
                masks: Some(masks),
                ..Default::default()
            },
            carry: Carry {
                slots: Some(last),
                history: h.last,
                history_valid: h.valid,
                ..Carry::default()
            },
        })
    }

    /// # Shapes
    /// - feats: `[1, M, D_f]`; output: `[1, V, D_dec]`
    pub fn step(&self, feats: Tensor<3>, memory: &mut Memory, shared: Shared) -> Tensor<3> {
        let slots = self.core.step(feats.clone(), memory);
        let tokens = self
            .core
            .tokens(feats, self.slot_proj.forward(slots), shared);
        History::step_of(self.history.as_ref(), tokens, &mut memory.history)
    }
}
