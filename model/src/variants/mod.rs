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
mod types;

use burn::prelude::*;

pub use dense::DenseTokens;
pub use e_slotssm::SlotSsmTokens;
pub use history::History;
pub use slots::{ObjectSlots, SlotCore, SlotSource};
pub use slotvla::SlotVlaTokens;
pub use types::{
    Carry, CarryRecord, Memory, Shared, Subgoal, TensorRecord, WindowParts, WindowTokens,
};

use crate::config::{ModelConfig, Variant};
use crate::error::Result;

/// The variant-specific part of the policy: visual features → decoder tokens, with memory.
// One per model: the size difference of the arms costs nothing worth a Box (which Burn's
// derive does not see through).
#[allow(clippy::large_enum_variant)]
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
    /// - feats: `[B, T, M, D_f]`; subgoal: see [`Subgoal`]
    /// - output: see [`WindowTokens`]
    pub fn window(
        &self,
        feats: Tensor<4>,
        subgoal: Option<Subgoal<4>>,
        carry: Carry,
        shared: Shared,
    ) -> Result<WindowTokens> {
        match self {
            TokenBuilder::SlotSsm(v) => v.window(feats, subgoal, carry, shared),
            TokenBuilder::SlotVla(v) => v.window(feats, carry, shared),
            TokenBuilder::Dense(v) => v.window(feats, carry, shared),
        }
    }

    /// Decoder tokens of one frame (all the frames the decoder sees, history included);
    /// updates `memory`.
    ///
    /// # Shapes
    /// - feats: `[1, M, D_f]`; subgoal: see [`Subgoal`]
    /// - output: `[1, V, D_dec]`
    pub fn step(
        &self,
        feats: Tensor<3>,
        subgoal: Option<Subgoal<3>>,
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
