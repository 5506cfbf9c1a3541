//! What every slot variant shares (model.md §2, §7, L_sa): the slots — slot attention with
//! temporally propagated initialisation, or in state mode the object tokens themselves ("oracle
//! slots") —, the relation encoder, the projection of slot and relation tokens to the decoder
//! width, and the optional slot decoder of L_sa.

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;

use super::types::{Memory, Shared, TYPE_RELATION, TYPE_SLOT};
use crate::config::ModelConfig;
use crate::error::{ModelError, Result};
use crate::heads::SlotDecoder;
use crate::relation::RelationEncoder;
use crate::slot_attention::SlotAttention;

/// Where the slots come from.
// One per model (the arms differ in size, as the token builders do).
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum SlotSource {
    /// Slot attention over the image features (pixels).
    SlotAttention(SlotAttention),
    /// One slot per object token (state mode): the tokens projected to the slot width.
    ObjectSlots(ObjectSlots),
}

/// Oracle slots: slot k of a frame is token k of the state encoder, projected `[D_f, D]`.
/// Token k is the same object through an episode, as a tracked slot is.
#[derive(Module, Debug)]
pub struct ObjectSlots {
    /// Projection `[D_f, D]`.
    pub proj: Linear,
    /// Slots (= tokens) per frame K.
    pub slots: usize,
}

impl ObjectSlots {
    /// Slots and their (one-hot) masks of a window.
    ///
    /// # Shapes
    /// - feats: `[B, T, K, D_f]`; output: slots `[B, T, K, D]`, masks `[B, T, K, K]`
    fn forward(&self, feats: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
        let [b, t, k, _] = feats.dims();
        let device = feats.device();
        let eye = Tensor::<2>::eye(k, &device)
            .reshape([1, 1, k, k])
            .repeat_dim(0, b)
            .repeat_dim(1, t);
        (self.proj.forward(feats), eye)
    }
}

/// Slots, relation tokens and their projection to the decoder.
#[derive(Module, Debug)]
pub struct SlotCore {
    /// Where the slots come from.
    pub source: SlotSource,
    /// Relation encoder.
    pub relation: RelationEncoder,
    /// Slot / relation tokens to the decoder width `[D, D_dec]`.
    pub token_proj: Linear,
    /// Slot decoder of L_sa (absent when λ_sa = 0).
    pub slot_decoder: Option<SlotDecoder>,
}

impl SlotCore {
    /// Builds the slot machinery of `config`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        SlotCore {
            source: if config.observation.is_state() {
                SlotSource::ObjectSlots(ObjectSlots {
                    proj: LinearConfig::new(config.encoder.feature_dim, config.slots.dim)
                        .init(device),
                    slots: config.slots.num_slots,
                })
            } else {
                SlotSource::SlotAttention(SlotAttention::new(config, device))
            },
            relation: RelationEncoder::new(config, device),
            token_proj: LinearConfig::new(config.slots.dim, config.decoder.width).init(device),
            slot_decoder: config.has_sa_decoder().then(|| {
                SlotDecoder::new(
                    config.num_patches(),
                    config.slots.dim,
                    config.loss.sa_hidden,
                    config.sa_target_dim(),
                    device,
                )
            }),
        }
    }

    /// Slots per frame K.
    pub fn num_slots(&self) -> usize {
        match &self.source {
            SlotSource::SlotAttention(sa) => sa.num_slots(),
            SlotSource::ObjectSlots(o) => o.slots,
        }
    }

    /// Slot width D.
    pub fn dim(&self) -> usize {
        match &self.source {
            SlotSource::SlotAttention(sa) => sa.dim(),
            SlotSource::ObjectSlots(o) => o.proj.weight.dims()[1],
        }
    }

    /// Slot attention (None for oracle slots).
    pub fn slot_attention(&self) -> Option<&SlotAttention> {
        match &self.source {
            SlotSource::SlotAttention(sa) => Some(sa),
            SlotSource::ObjectSlots(_) => None,
        }
    }

    /// Slots of a window that continues from `prev` (the carried last slots); lanes marked
    /// `fresh` start from the learned initial slots instead, as at an episode start.
    ///
    /// # Shapes
    /// - feats: `[B, T, M, D_f]`; prev: `[B, K, D]`; fresh: `[B]`
    /// - output: (slots `[B, T, K, D]`, masks `[B, T, K, M]`, last slots `[B, K, D]` detached)
    pub fn window(
        &self,
        feats: Tensor<4>,
        prev: Option<Tensor<3>>,
        fresh: Option<Tensor<1, Bool>>,
    ) -> Result<(Tensor<4>, Tensor<4>, Tensor<3>)> {
        let [b, t, _, _] = feats.dims();
        let (k, d) = (self.num_slots(), self.dim());
        let sa = match &self.source {
            SlotSource::SlotAttention(sa) => sa,
            SlotSource::ObjectSlots(o) => {
                let [_, _, n, _] = feats.dims();
                if n != k {
                    return Err(ModelError::Input(format!(
                        "{n} object tokens per frame, expected {k}"
                    )));
                }
                let (slots, masks) = o.forward(feats);
                let last = slots
                    .clone()
                    .narrow(1, t - 1, 1)
                    .squeeze_dim::<3>(1)
                    .detach();
                return Ok((slots, masks, last));
            }
        };
        if let Some(p) = &prev
            && p.dims() != [b, k, d]
        {
            return Err(ModelError::Input(format!(
                "carried slots {:?}, expected [{b}, {k}, {d}]",
                p.dims()
            )));
        }
        let (slots, masks) = match (prev, fresh) {
            (Some(p), Some(fresh)) => {
                // Frame 0 both ways (fresh: Q₀ with iters_first; carried: iters_later), chosen
                // per lane; the rest of the window continues from the chosen slots.
                let [_, _, m, _] = feats.dims();
                let f0 = feats.clone().narrow(1, 0, 1).squeeze_dim::<3>(1);
                let (s_new, a_new) = sa.step(f0.clone(), None);
                let (s_old, a_old) = sa.step(f0, Some(p));
                let lane = |w: usize| {
                    fresh
                        .clone()
                        .reshape([b, 1, 1])
                        .repeat_dim(1, k)
                        .repeat_dim(2, w)
                };
                let s0 = s_old.mask_where(lane(d), s_new);
                let a0 = a_old.mask_where(lane(m), a_new);
                if t == 1 {
                    (s0.unsqueeze_dim(1), a0.unsqueeze_dim(1))
                } else {
                    let (s, a) = sa.forward(feats.narrow(1, 1, t - 1), Some(s0.clone()));
                    (
                        Tensor::cat(vec![s0.unsqueeze_dim(1), s], 1),
                        Tensor::cat(vec![a0.unsqueeze_dim(1), a], 1),
                    )
                }
            }
            (prev, _) => sa.forward(feats, prev),
        };
        let last = slots
            .clone()
            .narrow(1, t - 1, 1)
            .squeeze_dim::<3>(1)
            .detach();
        Ok((slots, masks, last))
    }

    /// Slots of one streamed frame, continuing from the memory's slots; updates the memory's
    /// slots and masks.
    ///
    /// # Shapes
    /// - feats: `[1, M, D_f]`; output: slots `[1, K, D]`
    pub fn step(&self, feats: Tensor<3>, memory: &mut Memory) -> Tensor<3> {
        let (slots, masks) = match &self.source {
            SlotSource::SlotAttention(sa) => sa.step(feats, memory.slots.take()),
            SlotSource::ObjectSlots(o) => {
                let (s, m) = o.forward(feats.unsqueeze_dim(1));
                (s.squeeze_dim::<3>(1), m.squeeze_dim::<3>(1))
            }
        };
        memory.slots = Some(slots.clone());
        memory.masks = Some(masks);
        slots
    }

    /// Slot and relation tokens of single frames for the decoder.
    ///
    /// # Shapes
    /// - feats: `[N, M, D_f]`; z: `[N, K, D]`
    /// - output: `[N, L + K, D_dec]` (relation tokens first)
    pub fn tokens(&self, feats: Tensor<3>, z: Tensor<3>, shared: Shared) -> Tensor<3> {
        let r = self.relation.forward(feats, z.clone());
        let r = self.token_proj.forward(r) + shared.type_embedding(TYPE_RELATION);
        let z = self.token_proj.forward(z) + shared.type_embedding(TYPE_SLOT);
        Tensor::cat(vec![r, z], 1)
    }
}
