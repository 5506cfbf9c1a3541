//! Embodied-SlotSSM (model.md §2–§7): encoder → slot attention → SlotSSM → windowed head and
//! slot fusion with the subgoal → relation tokens → decoder. Its memory is the SlotSSM state
//! (constant size for any episode length) and the last slots.

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;

use super::slots::SlotCore;
use super::types::{Carry, Memory, Shared, Subgoal, WindowParts, WindowTokens};
use crate::config::ModelConfig;
use crate::error::{ModelError, Result};
use crate::heads::{SlotFusion, WindowHead};
use crate::slot_ssm::{SlotSsm, SlotSsmState};

/// The subgoal g given to every slot's fusion.
#[derive(Module, Debug)]
pub enum SubgoalReader {
    /// A learned null subgoal `[D_txt]` for every slot (no oracle text).
    Null(Param<Tensor<1>>),
    /// The oracle text as an ordered token sequence, projected `[L_sg · D_txt, D_txt]`.
    Text(Linear),
}

/// Embodied-SlotSSM's token builder.
#[derive(Module, Debug)]
pub struct SlotSsmTokens {
    /// Slot attention, relation tokens, projection.
    pub core: SlotCore,
    /// SlotSSM.
    pub slot_ssm: SlotSsm,
    /// Windowed head of L_win.
    pub window_head: WindowHead,
    /// Slot fusion of s_t, ŝ_{t+1} and the subgoal.
    pub fusion: SlotFusion,
    /// How the subgoal g of each slot is formed.
    pub subgoal: SubgoalReader,
    /// Cross-attention from slots to patches inside the SlotSSM.
    pub cross_attention: bool,
}

impl SlotSsmTokens {
    /// Builds Embodied-SlotSSM of `config`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        let w = config.decoder.width;
        SlotSsmTokens {
            core: SlotCore::new(config, device),
            slot_ssm: SlotSsm::new(config, device),
            window_head: WindowHead::new(d, config.window.past + config.window.future, device),
            fusion: SlotFusion::new(d, w, device),
            subgoal: if config.variant.needs_subgoal_text() {
                SubgoalReader::Text(LinearConfig::new(config.text.max_len * w, w).init(device))
            } else {
                SubgoalReader::Null(Param::from_tensor(Tensor::random(
                    [w],
                    Distribution::Normal(0.0, 1.0),
                    device,
                )))
            },
            cross_attention: config.ssm.cross_attention,
        }
    }

    /// Subgoal embeddings g per slot.
    ///
    /// # Shapes
    /// - subgoal: `[N, G, L_sg]`, G ∈ {1, K}
    /// - output: `[N, K, D_txt]`
    fn subgoal_embedding(
        &self,
        subgoal: Option<Tensor<3, Int>>,
        n: usize,
        shared: Shared,
        device: &Device,
    ) -> Result<Tensor<3>> {
        let k = self.core.num_slots();
        let [_, w] = shared.token_type.dims();
        match (subgoal, &self.subgoal) {
            (_, SubgoalReader::Null(null)) => Ok(null
                .val()
                .reshape([1, 1, w])
                .repeat_dim(0, n)
                .repeat_dim(1, k)),
            (Some(ids), SubgoalReader::Text(proj)) => {
                let [n2, g, l] = ids.dims();
                if n2 != n || (g != 1 && g != k) {
                    return Err(ModelError::Input(format!(
                        "subgoal ids have shape {:?}, expected [{n}, 1 or {k}, L]",
                        ids.dims()
                    )));
                }
                let e = proj
                    .forward(shared.text.sequence(ids.reshape([n * g, l])))
                    .reshape([n, g, w]);
                Ok(if g == 1 { e.repeat_dim(1, k) } else { e })
            }
            // Oracle model without a subgoal: every slot gets the empty text (zeros).
            (None, SubgoalReader::Text(_)) => Ok(Tensor::zeros([n, k, w], device)),
        }
    }

    /// The subgoal ids of N frames as the slots read them, `[N, G, L_sg]` with G ∈ {1, K}: with
    /// object boxes, each slot gets the label of the object its mask is matched to
    /// ([`crate::matching`]) and the others the `"0"` row.
    ///
    /// # Shapes
    /// - subgoal: ids `[N, G, L_sg]` (with boxes `[N, J, 4]`: G = J + 1); masks: `[N, K, M]`
    fn slot_ids(&self, subgoal: Subgoal<3>, masks: &Tensor<3>) -> Result<Tensor<3, Int>> {
        let Some(boxes) = subgoal.boxes else {
            return Ok(subgoal.ids);
        };
        let [n, g, _] = subgoal.ids.dims();
        let [n2, j, _] = boxes.dims();
        if n2 != n || g != j + 1 {
            return Err(ModelError::Input(format!(
                "subgoal ids {:?} with object boxes {:?}: expected J + 1 label rows for J boxes",
                subgoal.ids.dims(),
                boxes.dims()
            )));
        }
        let [_, _, m] = masks.dims();
        let side = m.isqrt();
        if side * side != m {
            return Err(ModelError::Input(format!(
                "slot masks over {m} tokens are not a square grid: cannot match them to boxes"
            )));
        }
        let rows = crate::matching::label_rows(masks.clone(), boxes, [side, side])?;
        Ok(crate::matching::gather_labels(subgoal.ids, rows))
    }

    fn check_state(&self, state: &SlotSsmState, b: usize, device: &Device) -> Result<()> {
        let k = self.core.num_slots();
        let want = self.slot_ssm.zero_state(b, k, device);
        let ok = state.blocks.len() == want.blocks.len()
            && state
                .blocks
                .iter()
                .zip(&want.blocks)
                .all(|(s, z)| s.h.dims() == z.h.dims() && s.conv.dims() == z.conv.dims());
        if ok {
            Ok(())
        } else {
            Err(ModelError::Input(
                "carried SlotSSM state does not match the model and batch".into(),
            ))
        }
    }

    /// # Shapes
    /// - feats: `[B, T, M, D_f]`; subgoal: see [`Subgoal`]; output: see [`WindowTokens`]
    pub fn window(
        &self,
        feats: Tensor<4>,
        subgoal: Option<Subgoal<4>>,
        carry: Carry,
        shared: Shared,
    ) -> Result<WindowTokens> {
        let [b, t, m, d_f] = feats.dims();
        let n = b * t;
        let device = feats.device();
        if let Some(state) = &carry.ssm {
            self.check_state(state, b, &device)?;
        }
        let (slots, masks, last) =
            self.core
                .window(feats.clone(), carry.slots.clone(), carry.fresh.clone())?;
        let [_, _, k, d] = slots.dims();
        let ssm_feats = self.cross_attention.then(|| feats.clone());
        // Fresh lanes start from the zero state, as at an episode start.
        let state = match (carry.ssm, &carry.fresh) {
            (Some(s), Some(fresh)) => Some(zero_lanes(s, fresh, k)),
            (s, _) => s,
        };
        let (pred, state) = self.slot_ssm.forward(slots.clone(), ssm_feats, state);
        let window = self.window_head.forward(pred.clone(), slots.clone());
        let sub = match subgoal {
            Some(s) => {
                let [_, _, _, mm] = masks.dims();
                Some(self.slot_ids(s.frames(), &masks.clone().reshape([n, k, mm]))?)
            }
            None => None,
        };
        let g = self.subgoal_embedding(sub, n, shared, &device)?;
        let z = self.fusion.forward(
            slots.clone().reshape([n, k, d]),
            pred.clone().reshape([n, k, d]),
            g,
        );
        let tokens = self.core.tokens(feats.reshape([n, m, d_f]), z, shared);
        Ok(WindowTokens {
            tokens,
            pad: None,
            parts: WindowParts {
                slots: Some(slots),
                masks: Some(masks),
                predicted: Some(pred),
                window: Some(window),
            },
            carry: Carry {
                slots: Some(last),
                ssm: Some(state.detach()),
                ..Carry::default()
            },
        })
    }

    /// # Shapes
    /// - feats: `[1, M, D_f]`; subgoal: see [`Subgoal`]; output: `[1, L + K, D_dec]`
    pub fn step(
        &self,
        feats: Tensor<3>,
        subgoal: Option<Subgoal<3>>,
        memory: &mut Memory,
        shared: Shared,
    ) -> Result<Tensor<3>> {
        let device = feats.device();
        let slots = self.core.step(feats.clone(), memory);
        let k = self.core.num_slots();
        let state = memory
            .ssm
            .take()
            .unwrap_or_else(|| self.slot_ssm.zero_state(1, k, &device));
        let ssm_feats = self.cross_attention.then(|| feats.clone());
        let (pred, state) = self.slot_ssm.step(slots.clone(), ssm_feats, state);
        memory.ssm = Some(state);
        let sub = match (subgoal, &memory.masks) {
            (Some(s), Some(masks)) => Some(self.slot_ids(s, masks)?),
            (Some(s), None) => Some(s.ids),
            (None, _) => None,
        };
        let g = self.subgoal_embedding(sub, 1, shared, &device)?;
        let z = self.fusion.forward(slots, pred, g);
        Ok(self.core.tokens(feats, z, shared))
    }
}

/// The state with the rows of the `fresh` lanes (each K sequences) set to zero.
///
/// # Shapes
/// - state: per block over B·K sequences; fresh: `[B]`
fn zero_lanes(state: SlotSsmState, fresh: &Tensor<1, Bool>, k: usize) -> SlotSsmState {
    let [b] = fresh.dims();
    let rows = fresh
        .clone()
        .reshape([b, 1])
        .repeat_dim(1, k)
        .reshape([b * k, 1, 1]);
    SlotSsmState {
        blocks: state
            .blocks
            .into_iter()
            .map(|mut s| {
                let [_, e, n] = s.h.dims();
                s.h =
                    s.h.mask_fill(rows.clone().repeat_dim(1, e).repeat_dim(2, n), 0.0);
                let [_, e, c] = s.conv.dims();
                s.conv = s
                    .conv
                    .mask_fill(rows.clone().repeat_dim(1, e).repeat_dim(2, c), 0.0);
                s
            })
            .collect(),
    }
}
