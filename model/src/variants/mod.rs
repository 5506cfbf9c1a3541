//! The policy variants of model.md §9 as types. Each variant turns visual features into the
//! decoder's visual tokens with its own memory: over a training window ([`TokenBuilder::window`])
//! and one frame at a time ([`TokenBuilder::step`]). Everything around it — encoder, language,
//! decoder, losses, streaming — is shared by [`crate::policy::PolicyModel`].
//!
//! Adding a variant: one file here (its module: `new` from the [`ModelConfig`], `window`,
//! `step`), one arm of [`TokenBuilder`] and of [`crate::config::Variant`].

mod dense;
mod e_slotssm;
mod history;
mod slots;
mod slotvla;

use std::collections::VecDeque;

use burn::prelude::*;

pub use dense::DenseTokens;
pub use e_slotssm::SlotSsmTokens;
pub use history::History;
pub use slots::SlotCore;
pub use slotvla::SlotVlaTokens;

use crate::config::{ModelConfig, Variant};
use crate::error::Result;
use crate::slot_ssm::SlotSsmState;
use crate::text::TextEncoder;

/// Visual token types added before the decoder (rows of `PolicyModel::token_type`).
pub(crate) const TYPE_RELATION: usize = 0;
pub(crate) const TYPE_SLOT: usize = 1;
pub(crate) const TYPE_PATCH: usize = 2;

/// Memory carried from one window to the next of the same episodes (truncated BPTT, model.md
/// §10): the last frame's slots and the SlotSSM state, both detached.
///
/// SlotVLA(h > 1) and dense(h > 1) windows still start their history at the window's first frame.
#[derive(Clone, Debug, Default)]
pub struct Carry {
    /// Slots of the last frame `[B, K, D]` (slot variants).
    pub slots: Option<Tensor<3>>,
    /// SlotSSM state after the last frame (e_slotssm).
    pub ssm: Option<SlotSsmState>,
}

/// The state a streaming policy carries from step to step (reset per episode).
#[derive(Clone, Debug, Default)]
pub struct Memory {
    /// Slots of the previous frame `[1, K, D]` (slot variants).
    pub slots: Option<Tensor<3>>,
    /// SlotSSM state (e_slotssm).
    pub ssm: Option<SlotSsmState>,
    /// Decoder tokens of the last h frames, oldest first, each `[1, V₁, D_dec]` (h > 1 only).
    pub history: VecDeque<Tensor<3>>,
    /// Slot-attention masks of the latest frame `[1, K, M]` (slot variants).
    pub masks: Option<Tensor<3>>,
}

impl Memory {
    /// Floats held (slots + SSM states + history tokens).
    pub fn num_floats(&self) -> usize {
        self.slots.as_ref().map_or(0, |t| t.shape().num_elements())
            + self.ssm.as_ref().map_or(0, SlotSsmState::num_floats)
            + self
                .history
                .iter()
                .map(|t| t.shape().num_elements())
                .sum::<usize>()
    }
}

/// What a variant computes over a window besides the decoder tokens.
#[derive(Clone, Debug, Default)]
pub struct WindowParts {
    /// Slots s `[B, T, K, D]` (slot variants).
    pub slots: Option<Tensor<4>>,
    /// Slot attention masks `[B, T, K, M]` (slot variants).
    pub masks: Option<Tensor<4>>,
    /// SlotSSM predictions ŝ_{t+1} `[B, T, K, D]` (e_slotssm).
    pub predicted: Option<Tensor<4>>,
    /// Windowed predictions Ŝ `[B, T, K, P, D]` (e_slotssm).
    pub window: Option<Tensor<5>>,
}

/// The decoder's visual input of a window.
#[derive(Clone, Debug)]
pub struct WindowTokens {
    /// Visual tokens per frame `[B·T, V, D_dec]` (V = h·V₁ with a history).
    pub tokens: Tensor<3>,
    /// Padding of the history `[B·T, V]` (true = frame before the window start).
    pub pad: Option<Tensor<2, Bool>>,
    /// The variant's intermediate results (for the losses and inspection).
    pub parts: WindowParts,
    /// The memory after the window, detached.
    pub carry: Carry,
}

/// Shared modules a variant reads but does not own.
#[derive(Clone, Copy, Debug)]
pub struct Shared<'a> {
    /// Visual token type embeddings `[3, D_dec]`.
    pub token_type: &'a Tensor<2>,
    /// Word embeddings (for subgoal texts).
    pub text: &'a TextEncoder,
}

impl Shared<'_> {
    /// Embedding of one visual token type.
    ///
    /// # Shapes
    /// - output: `[1, 1, D_dec]`
    pub(crate) fn type_embedding(&self, kind: usize) -> Tensor<3> {
        self.token_type.clone().narrow(0, kind, 1).unsqueeze_dim(0)
    }
}

/// The variant-specific part of the policy: visual features → decoder tokens, with memory.
#[derive(Module, Debug)]
pub enum TokenBuilder {
    /// Embodied-SlotSSM (model.md §2–§7).
    SlotSsm(SlotSsmTokens),
    /// SlotVLA(h): slots and relation tokens of the last h frames, no memory beyond them.
    SlotVla(SlotVlaTokens),
    /// Dense patch tokens of the last h frames.
    Dense(DenseTokens),
}

impl TokenBuilder {
    /// The builder of `config.variant`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        match config.variant {
            Variant::ESlotSsm { .. } => TokenBuilder::SlotSsm(SlotSsmTokens::new(config, device)),
            Variant::SlotVla { .. } => TokenBuilder::SlotVla(SlotVlaTokens::new(config, device)),
            Variant::Dense { .. } => TokenBuilder::Dense(DenseTokens::new(config, device)),
        }
    }

    /// Decoder tokens of every frame of a window that continues from `carry`.
    ///
    /// # Shapes
    /// - feats: `[B, T, M, D_f]`; subgoal: `[B, T, G, L_sg]`, G ∈ {1, K}
    /// - output: see [`WindowTokens`]
    pub fn window(
        &self,
        feats: Tensor<4>,
        subgoal: Option<Tensor<4, Int>>,
        carry: Carry,
        shared: Shared,
    ) -> Result<WindowTokens> {
        match self {
            TokenBuilder::SlotSsm(v) => v.window(feats, subgoal, carry, shared),
            TokenBuilder::SlotVla(v) => v.window(feats, carry, shared),
            TokenBuilder::Dense(v) => Ok(v.window(feats, shared)),
        }
    }

    /// Decoder tokens of one frame (all the frames the decoder sees, history included);
    /// updates `memory`.
    ///
    /// # Shapes
    /// - feats: `[1, M, D_f]`; subgoal: `[1, G, L_sg]`
    /// - output: `[1, V, D_dec]`
    pub fn step(
        &self,
        feats: Tensor<3>,
        subgoal: Option<Tensor<3, Int>>,
        memory: &mut Memory,
        shared: Shared,
    ) -> Result<Tensor<3>> {
        match self {
            TokenBuilder::SlotSsm(v) => v.step(feats, subgoal, memory, shared),
            TokenBuilder::SlotVla(v) => Ok(v.step(feats, memory, shared)),
            TokenBuilder::Dense(v) => Ok(v.step(feats, memory, shared)),
        }
    }

    /// The slot machinery, for the slot losses (None for dense).
    pub fn slot_core(&self) -> Option<&SlotCore> {
        match self {
            TokenBuilder::SlotSsm(v) => Some(&v.core),
            TokenBuilder::SlotVla(v) => Some(&v.core),
            TokenBuilder::Dense(_) => None,
        }
    }
}
