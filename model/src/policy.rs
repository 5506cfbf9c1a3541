//! The policy model of every variant (model.md §9) and its training forward over windows.
//!
//! `e_slotssm`: encoder → slot attention → SlotSSM → windowed head and slot fusion → relation
//! tokens → decoder. `slotvla_h<N>`: encoder → slot attention → z = Linear(s) → relation tokens;
//! the decoder sees the tokens of the last N frames. `dense`: the decoder sees projected patch
//! tokens. One interface for all, so trainer and evaluator do not care which.

use std::path::Path;

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;

use crate::config::{ActionHead, ModelConfig, Variant};
use crate::decoder::{ActionDecoder, DecoderOutput};
use crate::encoder::VisualEncoder;
use crate::error::{ModelError, Result};
use crate::heads::{SlotDecoder, SlotFusion, WindowHead};
use crate::losses;
use crate::relation::RelationEncoder;
use crate::slot_attention::SlotAttention;
use crate::slot_ssm::{SlotSsm, SlotSsmState};
use crate::text::TextEncoder;

/// A training batch of windows.
#[derive(Clone, Debug)]
pub struct WindowBatch {
    /// Agentview RGB in [0, 1] `[B, T, 3, H, W]`.
    pub images: Tensor<5>,
    /// Normalised target chunks a*_{t..t+H_a−1} `[B, T, H_a, A]`.
    pub actions: Tensor<4>,
    /// 1 for valid frames, 0 for padding `[B, T]`.
    pub frame_mask: Tensor<2>,
    /// Which action entries count in L_act `[B, T, H_a, A]` (None: every entry of a valid frame).
    pub action_mask: Option<Tensor<4>>,
    /// Instruction token ids `[B, L_txt]` (see [`crate::text::Tokenizer`]).
    pub instruction: Tensor<2, Int>,
    /// Oracle subgoal token ids `[B, T, G, L_sg]`, G = 1 (shared by all slots) or K (per slot).
    pub subgoal: Option<Tensor<4, Int>>,
}

/// Everything the window forward computes.
#[derive(Clone, Debug)]
pub struct WindowOutput {
    /// Predicted normalised action chunks `[B, T, H_a, A]`.
    pub actions: Tensor<4>,
    /// Logits of the discrete head `[B, T, H_a, A, 256]`.
    pub logits: Option<Tensor<5>>,
    /// Slots s `[B, T, K, D]` (slot variants).
    pub slots: Option<Tensor<4>>,
    /// Slot attention masks `[B, T, K, M]` (slot variants).
    pub masks: Option<Tensor<4>>,
    /// SlotSSM predictions ŝ_{t+1} `[B, T, K, D]` (e_slotssm).
    pub predicted: Option<Tensor<4>>,
    /// Windowed predictions Ŝ `[B, T, K, P, D]` (e_slotssm).
    pub window: Option<Tensor<5>>,
}

/// The losses of a window batch; `None` where the variant has no such term.
#[derive(Clone, Debug)]
pub struct Losses {
    /// λ_act L_act + λ_tc L_tc + λ_win L_win + λ_sa L_sa `[1]`.
    pub total: Tensor<1>,
    /// L_act `[1]`.
    pub action: Tensor<1>,
    /// L_tc `[1]`.
    pub contrastive: Option<Tensor<1>>,
    /// L_win `[1]`.
    pub window: Option<Tensor<1>>,
    /// L_sa `[1]`.
    pub slot_recon: Option<Tensor<1>>,
}

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

/// Per-frame visual token types added before the decoder.
const TYPE_RELATION: usize = 0;
const TYPE_SLOT: usize = 1;
const TYPE_PATCH: usize = 2;

/// The policy network of any variant.
#[derive(Module, Debug)]
pub struct PolicyModel {
    /// Visual encoder.
    pub encoder: VisualEncoder,
    /// Slot attention (slot variants).
    pub slot_attention: Option<SlotAttention>,
    /// SlotSSM (e_slotssm).
    pub slot_ssm: Option<SlotSsm>,
    /// Windowed head (e_slotssm).
    pub window_head: Option<WindowHead>,
    /// Slot fusion (e_slotssm).
    pub fusion: Option<SlotFusion>,
    /// Learned null subgoal `[D_txt]` (e_slotssm without oracle subgoals).
    pub null_subgoal: Option<Param<Tensor<1>>>,
    /// z = Linear(s) `[D, D]` (SlotVLA).
    pub slot_proj: Option<Linear>,
    /// Relation encoder (slot variants).
    pub relation: Option<RelationEncoder>,
    /// Slot / relation tokens to the decoder width `[D, D_dec]` (slot variants).
    pub token_proj: Option<Linear>,
    /// Patch tokens W_p `[D_f, D_dec]` (dense).
    pub patch_proj: Option<Linear>,
    /// Visual token types (relation, slot, patch) `[3, D_dec]`.
    pub token_type: Param<Tensor<2>>,
    /// Frame-offset embedding of the history `[h, D_dec]` (h > 1).
    pub frame_offset: Option<Param<Tensor<2>>>,
    /// Language (and subgoal) embeddings, width D_dec.
    pub text: TextEncoder,
    /// Action decoder.
    pub decoder: ActionDecoder,
    /// Slot decoder of L_sa.
    pub slot_decoder: Option<SlotDecoder>,
    /// The configuration this model was built from.
    #[module(skip)]
    pub config: ModelConfig,
}

impl PolicyModel {
    /// Builds a freshly initialised model (seed the device first for reproducibility).
    pub fn new(config: &ModelConfig, device: &Device) -> Result<Self> {
        config.validate()?;
        let variant = config.variant;
        let d = config.slots.dim;
        let w = config.decoder.width;
        let d_f = config.encoder.feature_dim;
        let slots = variant.has_slots();
        let ssm = variant.has_ssm();
        let oracle = matches!(
            variant,
            Variant::ESlotSsm {
                oracle_subgoal: true
            }
        );
        let h = variant.history();
        Ok(PolicyModel {
            encoder: VisualEncoder::new(config, device),
            slot_attention: slots.then(|| SlotAttention::new(config, device)),
            slot_ssm: ssm.then(|| SlotSsm::new(config, device)),
            window_head: ssm
                .then(|| WindowHead::new(d, config.window.past + config.window.future, device)),
            fusion: ssm.then(|| SlotFusion::new(d, w, device)),
            null_subgoal: (ssm && !oracle).then(|| {
                Param::from_tensor(Tensor::random([w], Distribution::Normal(0.0, 1.0), device))
            }),
            slot_proj: matches!(variant, Variant::SlotVla { .. })
                .then(|| LinearConfig::new(d, d).init(device)),
            relation: slots.then(|| RelationEncoder::new(config, device)),
            token_proj: slots.then(|| LinearConfig::new(d, w).init(device)),
            patch_proj: (!slots).then(|| LinearConfig::new(d_f, w).init(device)),
            token_type: Param::from_tensor(Tensor::random(
                [3, w],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
            frame_offset: (h > 1).then(|| {
                Param::from_tensor(Tensor::random(
                    [h, w],
                    Distribution::Normal(0.0, 0.02),
                    device,
                ))
            }),
            text: TextEncoder::new(&config.text, w, device),
            decoder: ActionDecoder::new(&config.decoder, device),
            slot_decoder: config.has_sa_decoder().then(|| {
                SlotDecoder::new(
                    config.num_patches(),
                    d,
                    config.loss.sa_hidden,
                    config.sa_target_dim(),
                    device,
                )
            }),
            config: config.clone(),
        })
    }

    /// Saves the weights as a burnpack record.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        self.clone()
            .save_file(path.as_ref())
            .map_err(|e| ModelError::Record(format!("{}: {e}", path.as_ref().display())))
    }

    /// Builds a model of `config` and loads its weights from `path` (never panics on a bad file).
    pub fn load(config: &ModelConfig, path: impl AsRef<Path>, device: &Device) -> Result<Self> {
        let model = PolicyModel::new(config, device)?;
        model
            .try_load_file(path.as_ref())
            .map_err(|e| ModelError::Record(format!("{}: {e}", path.as_ref().display())))
    }

    /// Embedding of one visual token type.
    ///
    /// # Shapes
    /// - output: `[1, 1, D_dec]`
    fn type_embedding(&self, kind: usize) -> Tensor<3> {
        self.token_type.val().narrow(0, kind, 1).unsqueeze_dim(0)
    }

    /// Subgoal embeddings g per slot.
    ///
    /// # Shapes
    /// - subgoal: `[N, G, L_sg]`, G ∈ {1, K}
    /// - output: `[N, K, D_txt]`
    pub(crate) fn subgoal_embedding(
        &self,
        subgoal: Option<Tensor<3, Int>>,
        n: usize,
        device: &Device,
    ) -> Result<Tensor<3>> {
        let k = self.config.slots.num_slots;
        let w = self.config.decoder.width;
        match (subgoal, &self.null_subgoal) {
            (_, Some(null)) => Ok(null
                .val()
                .reshape([1, 1, w])
                .repeat_dim(0, n)
                .repeat_dim(1, k)),
            (Some(ids), None) => {
                let [n2, g, l] = ids.dims();
                if n2 != n || (g != 1 && g != k) {
                    return Err(ModelError::Input(format!(
                        "subgoal ids have shape {:?}, expected [{n}, 1 or {k}, L]",
                        ids.dims()
                    )));
                }
                let e = self.text.pooled(ids.reshape([n * g, l])).reshape([n, g, w]);
                Ok(if g == 1 { e.repeat_dim(1, k) } else { e })
            }
            (None, None) => {
                // Oracle model without a subgoal: every slot gets the empty text (zeros).
                Ok(Tensor::zeros([n, k, w], device))
            }
        }
    }

    /// Decoder tokens of single frames.
    ///
    /// # Shapes
    /// - feats: `[N, M, D_f]`; z: `[N, K, D]` (slot variants)
    /// - output: `[N, V₁, D_dec]`, V₁ = L + K (slots) or M (dense)
    pub(crate) fn frame_tokens(&self, feats: Tensor<3>, z: Option<Tensor<3>>) -> Tensor<3> {
        match (&self.relation, &self.token_proj, z) {
            (Some(rel), Some(proj), Some(z)) => {
                let r = rel.forward(feats, z.clone());
                let r = proj.forward(r) + self.type_embedding(TYPE_RELATION);
                let z = proj.forward(z) + self.type_embedding(TYPE_SLOT);
                Tensor::cat(vec![r, z], 1)
            }
            _ => {
                let proj = self
                    .patch_proj
                    .as_ref()
                    .expect("dense model has a patch projection");
                proj.forward(feats) + self.type_embedding(TYPE_PATCH)
            }
        }
    }

    /// Adds the frame-offset embedding to `n_frames` frames of tokens that end at the current
    /// frame, and concatenates them (oldest first).
    ///
    /// # Shapes
    /// - frames: n_frames × `[N, V₁, D_dec]` (oldest first, n_frames ≤ h)
    /// - output: `[N, n_frames·V₁, D_dec]`
    pub(crate) fn stack_history(&self, frames: Vec<Tensor<3>>) -> Tensor<3> {
        let h = self.config.variant.history();
        let n_frames = frames.len();
        assert!(n_frames >= 1 && n_frames <= h);
        match &self.frame_offset {
            None => frames.into_iter().next().expect("one frame"),
            Some(emb) => {
                let emb = emb.val();
                let frames = frames
                    .into_iter()
                    .enumerate()
                    .map(|(i, f)| f + emb.clone().narrow(0, h - n_frames + i, 1).unsqueeze_dim(0))
                    .collect();
                Tensor::cat(frames, 1)
            }
        }
    }

    /// Decodes per frame given language ids.
    ///
    /// # Shapes
    /// - visual: `[N, V, D_dec]`, pad `[N, V]`; instruction: `[N, L_txt]`
    pub(crate) fn decode(
        &self,
        visual: Tensor<3>,
        pad: Option<Tensor<2, Bool>>,
        instruction: Tensor<2, Int>,
    ) -> DecoderOutput {
        let (lang, lang_pad) = self.text.tokens(instruction);
        self.decoder.forward(visual, pad, lang, lang_pad)
    }

    /// Prediction over windows that start at the episode start (no losses).
    ///
    /// # Shapes
    /// - images: `[B, T, 3, H, W]` in [0, 1]; instruction: `[B, L_txt]`;
    ///   subgoal: `[B, T, G, L_sg]`
    /// - output: see [`WindowOutput`]
    pub fn predict(
        &self,
        images: Tensor<5>,
        instruction: Tensor<2, Int>,
        subgoal: Option<Tensor<4, Int>>,
    ) -> Result<WindowOutput> {
        self.predict_from(images, instruction, subgoal, Carry::default())
            .map(|(out, _)| out)
    }

    /// Prediction over windows that continue from `carry` (the memory after the previous
    /// window); returns the memory after this window, detached.
    ///
    /// # Shapes
    /// - as [`PolicyModel::predict`]; carry slots `[B, K, D]`, SSM state over B·K sequences
    pub fn predict_from(
        &self,
        images: Tensor<5>,
        instruction: Tensor<2, Int>,
        subgoal: Option<Tensor<4, Int>>,
        carry: Carry,
    ) -> Result<(WindowOutput, Carry)> {
        let [b, t, c, h, w] = images.dims();
        let cfg = &self.config;
        if c != 3 || [h, w] != cfg.image_size {
            return Err(ModelError::Input(format!(
                "images {:?}, expected [B, T, 3, {}, {}]",
                images.dims(),
                cfg.image_size[0],
                cfg.image_size[1]
            )));
        }
        let [b2, l_txt] = instruction.dims();
        if b2 != b || l_txt > cfg.text.max_len {
            return Err(ModelError::Input(format!(
                "instruction ids {:?}, expected [{b}, ≤{}]",
                instruction.dims(),
                cfg.text.max_len
            )));
        }
        let device = images.device();
        let n = b * t;
        let feats = self.encoder.forward(images); // [B, T, M, D_f]
        let [_, _, m, d_f] = feats.dims();
        let flat_feats = feats.clone().reshape([n, m, d_f]);
        let k = cfg.slots.num_slots;
        let d = cfg.slots.dim;

        if let (Some(ssm), Some(state)) = (&self.slot_ssm, &carry.ssm) {
            let n_seq = b * cfg.slots.num_slots;
            let ok = state.blocks.len() == ssm.blocks.len()
                && state.blocks.iter().all(|s| {
                    s.h.dims() == [n_seq, cfg.ssm.inner, cfg.ssm.state]
                        && s.conv.dims() == [n_seq, cfg.ssm.inner, cfg.ssm.conv - 1]
                });
            if !ok {
                return Err(ModelError::Input(
                    "carried SlotSSM state does not match the model and batch".into(),
                ));
            }
        }
        let mut new_carry = Carry::default();
        let mut out = WindowOutput {
            actions: Tensor::zeros([1, 1, 1, 1], &device),
            logits: None,
            slots: None,
            masks: None,
            predicted: None,
            window: None,
        };
        let z = if let Some(sa) = &self.slot_attention {
            if let Some(prev) = &carry.slots
                && prev.dims() != [b, k, d]
            {
                return Err(ModelError::Input(format!(
                    "carried slots {:?}, expected [{b}, {k}, {d}]",
                    prev.dims()
                )));
            }
            let (slots, masks) = sa.forward(feats.clone(), carry.slots.clone());
            new_carry.slots = Some(
                slots
                    .clone()
                    .narrow(1, t - 1, 1)
                    .squeeze_dim::<3>(1)
                    .detach(),
            );
            out.masks = Some(masks);
            let z = if let (Some(ssm), Some(head), Some(fusion)) =
                (&self.slot_ssm, &self.window_head, &self.fusion)
            {
                let ssm_feats = cfg.ssm.cross_attention.then(|| feats.clone());
                let (pred, state) = ssm.forward(slots.clone(), ssm_feats, carry.ssm.clone());
                new_carry.ssm = Some(state.detach());
                out.window = Some(head.forward(pred.clone(), slots.clone()));
                let sub = subgoal.map(|s| {
                    let [_, _, g, l] = s.dims();
                    s.reshape([n, g, l])
                });
                let g = self.subgoal_embedding(sub, n, &device)?;
                let z = fusion.forward(
                    slots.clone().reshape([n, k, d]),
                    pred.clone().reshape([n, k, d]),
                    g,
                );
                out.predicted = Some(pred);
                z
            } else {
                let proj = self
                    .slot_proj
                    .as_ref()
                    .expect("SlotVLA has a slot projection");
                proj.forward(slots.clone().reshape([n, k, d]))
            };
            out.slots = Some(slots);
            Some(z)
        } else {
            None
        };
        let tokens = self.frame_tokens(flat_feats, z); // [N, V₁, D_dec]
        let (visual, pad) = self.window_history(tokens, b, t);
        let instr = instruction
            .unsqueeze_dim::<3>(1)
            .repeat_dim(1, t)
            .reshape([n, l_txt]);
        let dec = self.decode(visual, pad, instr);
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        out.actions = dec.actions.reshape([b, t, ha, a]);
        out.logits = dec
            .logits
            .map(|l| l.reshape([b, t, ha, a, crate::decoder::NUM_BINS]));
        Ok((out, new_carry))
    }

    /// History tokens for every frame of a window: frame t sees frames t−h+1 … t; frames before
    /// the window start repeat frame 0 and are masked.
    ///
    /// # Shapes
    /// - tokens: `[B·T, V₁, D_dec]`
    /// - output: (`[B·T, h·V₁, D_dec]`, pad `[B·T, h·V₁]` when h > 1)
    fn window_history(
        &self,
        tokens: Tensor<3>,
        b: usize,
        t: usize,
    ) -> (Tensor<3>, Option<Tensor<2, Bool>>) {
        let h = self.config.variant.history();
        if h == 1 {
            return (tokens, None);
        }
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
        let visual = self.stack_history(frames);
        (visual, Some(Tensor::cat(pads, 1).equal_elem(1.0)))
    }

    /// Training forward: predictions and all losses of a window batch (windows start from an
    /// empty memory).
    pub fn forward(&self, batch: &WindowBatch) -> Result<(WindowOutput, Losses)> {
        self.forward_from(batch, Carry::default())
            .map(|(out, losses, _)| (out, losses))
    }

    /// Training forward from carried memory (truncated BPTT); also returns the memory after
    /// the window, detached.
    pub fn forward_from(
        &self,
        batch: &WindowBatch,
        carry: Carry,
    ) -> Result<(WindowOutput, Losses, Carry)> {
        let cfg = &self.config;
        let [b, t, _, _, _] = batch.images.dims();
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        if batch.actions.dims() != [b, t, ha, a] || batch.frame_mask.dims() != [b, t] {
            return Err(ModelError::Input(format!(
                "actions {:?} / frame_mask {:?}, expected [{b}, {t}, {ha}, {a}] / [{b}, {t}]",
                batch.actions.dims(),
                batch.frame_mask.dims()
            )));
        }
        let (out, carry) = self.predict_from(
            batch.images.clone(),
            batch.instruction.clone(),
            batch.subgoal.clone(),
            carry,
        )?;
        let frame_mask = batch.frame_mask.clone();
        let action_mask = batch.action_mask.clone().unwrap_or_else(|| {
            frame_mask
                .clone()
                .reshape([b, t, 1, 1])
                .repeat_dim(2, ha)
                .repeat_dim(3, a)
        });
        let action = match (cfg.decoder.head, &out.logits) {
            (ActionHead::Bins, Some(logits)) => {
                losses::action_ce(logits.clone(), batch.actions.clone(), action_mask)
            }
            _ => losses::action_l1(out.actions.clone(), batch.actions.clone(), action_mask),
        };
        let mut total = action.clone().mul_scalar(cfg.loss.action);
        let contrastive = out
            .slots
            .as_ref()
            .map(|s| losses::temporal_contrastive(s.clone(), frame_mask.clone(), cfg.loss.tau));
        if let Some(l) = &contrastive {
            total = total + l.clone().mul_scalar(cfg.loss.contrastive);
        }
        let window = match (&out.window, &out.slots) {
            (Some(win), Some(s)) => Some(losses::windowed_recon(
                win.clone(),
                s.clone(),
                frame_mask.clone(),
                &cfg.window.offsets(),
            )),
            _ => None,
        };
        if let Some(l) = &window {
            total = total + l.clone().mul_scalar(cfg.loss.window);
        }
        let slot_recon = match (&self.slot_decoder, &out.slots) {
            (Some(dec), Some(s)) => {
                let [_, _, k, d] = s.dims();
                let (recon, _) = dec.forward(s.clone().reshape([b * t, k, d]));
                let [_, m, d_tgt] = recon.dims();
                let target = losses::image_patches(batch.images.clone(), cfg.grid());
                Some(losses::slot_recon(
                    recon.reshape([b, t, m, d_tgt]),
                    target,
                    frame_mask,
                ))
            }
            _ => None,
        };
        if let Some(l) = &slot_recon {
            total = total + l.clone().mul_scalar(cfg.loss.slot_recon);
        }
        Ok((
            out,
            Losses {
                total,
                action,
                contrastive,
                window,
                slot_recon,
            },
            carry,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streaming::StreamingPolicy;
    use crate::text::Tokenizer;
    use crate::{test_autodiff_device, test_device};
    use burn::module::ModuleVisitor;
    use burn::tensor::Distribution;
    use burn::tensor::Gradients;

    const INSTRUCTIONS: [&str; 2] = ["put the bowl on the plate", "open the top drawer"];

    fn tiny(variant: &str) -> ModelConfig {
        ModelConfig::tiny(Variant::from_name(variant).unwrap())
            .with_vocab_from(INSTRUCTIONS.iter().copied().chain(["bowl", "drawer"]))
    }

    /// A smaller-than-tiny config (32² images, narrow widths) for the slow tests.
    fn micro(variant: &str) -> ModelConfig {
        let mut cfg = tiny(variant);
        cfg.image_size = [32, 32];
        cfg.encoder.channels = vec![16, 32, 32];
        cfg.encoder.feature_dim = 32;
        cfg.slots.num_slots = 4;
        cfg.slots.dim = 32;
        cfg.ssm.inner = 64;
        cfg.ssm.state = 4;
        cfg.ssm.dt_rank = 2;
        cfg.relation.tokens = 4;
        cfg.relation.layers = 1;
        cfg.decoder.width = 64;
        cfg.decoder.layers = 1;
        cfg.decoder.horizon = 2;
        cfg.window = crate::config::WindowConfig { past: 2, future: 1 };
        cfg.loss.sa_hidden = 32;
        cfg.text.max_len = 8;
        cfg
    }

    fn batch(cfg: &ModelConfig, b: usize, t: usize, device: &Device) -> WindowBatch {
        let [h, w] = cfg.image_size;
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        let tok = Tokenizer::new(&cfg.text);
        let texts: Vec<&str> = (0..b).map(|i| INSTRUCTIONS[i % 2]).collect();
        let sub_texts: Vec<&str> = (0..b * t).map(|i| ["bowl", "drawer"][i % 2]).collect();
        let subgoal = tok
            .encode_batch(&sub_texts, device)
            .reshape([b, t, 1, cfg.text.max_len]);
        let mut mask = vec![1.0f32; b * t];
        mask[b * t - 1] = 0.0; // last frame of the last sample is padding
        WindowBatch {
            images: Tensor::random([b, t, 3, h, w], Distribution::Uniform(0.0, 1.0), device),
            actions: Tensor::random([b, t, ha, a], Distribution::Uniform(-1.0, 1.0), device),
            frame_mask: Tensor::from_data(TensorData::new(mask, [b, t]), device),
            action_mask: None,
            instruction: tok.encode_batch(&texts, device),
            subgoal: Some(subgoal),
        }
    }

    fn scalar(x: Tensor<1>) -> f32 {
        x.into_scalar::<f32>()
    }

    #[test]
    fn every_variant_has_the_documented_shapes_and_losses() {
        let (_guard, device) = test_device();
        let (b, t) = (2, 3);
        for name in [
            "e_slotssm",
            "e_slotssm_oracle",
            "slotvla_h1",
            "slotvla_h8",
            "dense",
        ] {
            let cfg = tiny(name);
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let (out, losses) = model.forward(&batch(&cfg, b, t, &device)).unwrap();
            assert_eq!(out.actions.dims(), [b, t, 4, 7], "{name}");
            let slots = cfg.variant.has_slots();
            let ssm = cfg.variant.has_ssm();
            assert_eq!(
                out.slots.as_ref().map(|s| s.dims()),
                slots.then_some([b, t, 8, 64])
            );
            assert_eq!(
                out.masks.as_ref().map(|s| s.dims()),
                slots.then_some([b, t, 8, 64])
            );
            assert_eq!(
                out.predicted.as_ref().map(|s| s.dims()),
                ssm.then_some([b, t, 8, 64])
            );
            assert_eq!(
                out.window.as_ref().map(|s| s.dims()),
                ssm.then_some([b, t, 8, 8, 64])
            );
            assert_eq!(losses.contrastive.is_some(), slots, "{name}");
            assert_eq!(losses.slot_recon.is_some(), slots, "{name}");
            assert_eq!(losses.window.is_some(), ssm, "{name}");
            let mut want = scalar(losses.action.clone());
            for (l, w) in [
                (&losses.contrastive, cfg.loss.contrastive),
                (&losses.window, cfg.loss.window),
                (&losses.slot_recon, cfg.loss.slot_recon),
            ] {
                if let Some(l) = l {
                    want += w as f32 * scalar(l.clone());
                }
            }
            let total = scalar(losses.total);
            assert!(total.is_finite() && (total - want).abs() < 1e-4, "{name}");
        }
        // The discrete head.
        let mut cfg = tiny("slotvla_h1");
        cfg.decoder.head = ActionHead::Bins;
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let (out, losses) = model.forward(&batch(&cfg, b, t, &device)).unwrap();
        assert_eq!(out.logits.unwrap().dims(), [b, t, 4, 7, 256]);
        // Near-uniform logits at init: CE ≈ ln 256.
        assert!((scalar(losses.action) - 256f32.ln()).abs() < 1.0);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (_guard, device) = test_device();
        let cfg = tiny("slotvla_h1");
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let mut bad = batch(&cfg, 1, 2, &device);
        bad.actions = Tensor::zeros([1, 2, 3, 7], &device);
        assert!(model.forward(&bad).is_err());
        let ids = Tokenizer::new(&cfg.text).encode_batch(&["x"], &device);
        let small = Tensor::<5>::zeros([1, 1, 3, 32, 32], &device);
        assert!(model.predict(small, ids, None).is_err());
        let mut cfg = tiny("e_slotssm_oracle");
        cfg.encoder.strides = vec![2];
        assert!(PolicyModel::new(&cfg, &device).is_err());
    }

    /// Collects the parameters whose gradient is missing or exactly zero.
    struct GradCheck<'a> {
        grads: &'a Gradients,
        path: Vec<String>,
        visited: usize,
        bad: Vec<String>,
    }

    impl ModuleVisitor for GradCheck<'_> {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }

        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }

        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.visited += 1;
            let tensor = param.val();
            let ok = tensor
                .grad(self.grads)
                .map(|g| g.abs().sum().into_scalar::<f32>() > 0.0)
                .unwrap_or(false);
            if !ok {
                self.bad
                    .push(format!("{} {:?}", self.path.join("."), tensor.dims()));
            }
        }
    }

    fn check_all_gradients(name: &str) {
        let (_guard, device) = test_autodiff_device();
        device.seed(1);
        let cfg = micro(name);
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let (_, losses) = model.forward(&batch(&cfg, 2, 4, &device)).unwrap();
        let grads = losses.total.backward();
        let mut check = GradCheck {
            grads: &grads,
            path: Vec::new(),
            visited: 0,
            bad: Vec::new(),
        };
        model.visit(&mut check);
        assert!(check.visited > 50, "{name}: visited only {}", check.visited);
        // Every word of the batch is used, but the vocabulary also holds special ids and
        // words absent from this batch: embedding rows are one parameter, so it still counts.
        assert!(
            check.bad.is_empty(),
            "{name}: no gradient for {:?}",
            check.bad
        );
    }

    #[test]
    fn every_parameter_gets_a_gradient_e_slotssm() {
        check_all_gradients("e_slotssm");
    }

    #[test]
    fn every_parameter_gets_a_gradient_e_slotssm_oracle() {
        check_all_gradients("e_slotssm_oracle");
    }

    #[test]
    fn every_parameter_gets_a_gradient_slotvla_h8() {
        check_all_gradients("slotvla_h8");
    }

    #[test]
    fn every_parameter_gets_a_gradient_dense() {
        check_all_gradients("dense");
    }

    /// Streaming the frames one by one gives the actions of the full window forward.
    fn streaming_equals_window(cfg: ModelConfig, frames: usize) {
        let (_guard, device) = test_device();
        device.seed(9);
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let tok = Tokenizer::new(&cfg.text);
        let [h, w] = cfg.image_size;
        let images = Tensor::<5>::random(
            [1, frames, 3, h, w],
            Distribution::Uniform(0.0, 1.0),
            &device,
        );
        let instr = tok.encode_batch(&[INSTRUCTIONS[0]], &device);
        let sub_texts: Vec<&str> = (0..frames)
            .map(|i| if i < frames / 2 { "bowl" } else { "drawer" })
            .collect();
        let subgoal =
            tok.encode_batch(&sub_texts, &device)
                .reshape([1, frames, 1, cfg.text.max_len]);
        let full = model
            .predict(images.clone(), instr.clone(), Some(subgoal.clone()))
            .unwrap()
            .actions;
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        let mut worst = 0.0f32;
        for t in 0..frames {
            let img = images.clone().narrow(1, t, 1).squeeze_dim::<4>(1);
            let sg = subgoal.clone().narrow(1, t, 1).squeeze_dim::<3>(1);
            let chunk = policy.act_tensor(img, instr.clone(), Some(sg)).unwrap();
            let want = full.clone().narrow(1, t, 1).reshape(chunk.dims());
            worst = worst.max((chunk - want).abs().max().into_scalar::<f32>());
        }
        assert!(worst < 1e-4, "{}: max diff {worst}", cfg.variant.name());
    }

    #[test]
    fn streaming_over_50_frames_equals_full_forward_e_slotssm() {
        streaming_equals_window(tiny("e_slotssm"), 50);
    }

    #[test]
    fn streaming_over_50_frames_equals_full_forward_e_slotssm_oracle_cross_attention() {
        let mut cfg = tiny("e_slotssm_oracle");
        cfg.ssm.cross_attention = true;
        streaming_equals_window(cfg, 50);
    }

    #[test]
    fn streaming_over_50_frames_equals_full_forward_slotvla_h8() {
        streaming_equals_window(tiny("slotvla_h8"), 50);
    }

    #[test]
    fn streaming_equals_full_forward_dense_h3() {
        streaming_equals_window(micro("dense_h3"), 10);
    }

    #[test]
    fn observe_then_act_equals_acting_every_step() {
        let (_guard, device) = test_device();
        for name in ["e_slotssm", "slotvla_h8"] {
            let cfg = micro(name);
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let x = batch(&cfg, 1, 6, &device);
            let frame = |t: usize| x.images.clone().narrow(1, t, 1).squeeze_dim::<4>(1);
            let mut a = StreamingPolicy::new(model.clone(), &device).unwrap();
            let mut b = StreamingPolicy::new(model, &device).unwrap();
            let mut last_a = None;
            for t in 0..6 {
                last_a = Some(a.act_tensor(frame(t), x.instruction.clone(), None).unwrap());
                if t < 5 {
                    b.observe_tensor(frame(t), None).unwrap();
                }
            }
            let last_b = b.act_tensor(frame(5), x.instruction.clone(), None).unwrap();
            let diff: f32 = (last_a.unwrap() - last_b).abs().max().into_scalar();
            assert_eq!(diff, 0.0, "{name}");
            assert_eq!(a.state_floats(), b.state_floats());
        }
    }

    #[test]
    fn two_carried_windows_equal_one_long_window() {
        let (_guard, device) = test_device();
        for name in ["e_slotssm", "slotvla_h1"] {
            let cfg = micro(name);
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let x = batch(&cfg, 2, 8, &device);
            let sub = x.subgoal.clone();
            let long = model
                .predict(x.images.clone(), x.instruction.clone(), sub.clone())
                .unwrap()
                .actions;
            let half = |i: usize| x.images.clone().narrow(1, 4 * i, 4);
            let sub_half = |i: usize| sub.clone().map(|s| s.narrow(1, 4 * i, 4));
            let (first, carry) = model
                .predict_from(
                    half(0),
                    x.instruction.clone(),
                    sub_half(0),
                    Carry::default(),
                )
                .unwrap();
            assert!(carry.slots.is_some());
            assert_eq!(carry.ssm.is_some(), cfg.variant.has_ssm());
            let (second, _) = model
                .predict_from(half(1), x.instruction.clone(), sub_half(1), carry)
                .unwrap();
            let joined = Tensor::cat(vec![first.actions, second.actions], 1);
            let diff: f32 = (joined - long).abs().max().into_scalar();
            assert!(diff < 1e-4, "{name}: {diff}");
        }
        // A carry of the wrong batch size is an error, not a panic.
        let cfg = micro("e_slotssm");
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let x = batch(&cfg, 2, 2, &device);
        let (_, _, carry) = model.forward_from(&x, Carry::default()).unwrap();
        let y = batch(&cfg, 1, 2, &device);
        assert!(model.forward_from(&y, carry).is_err());
    }

    #[test]
    fn records_round_trip_and_bad_files_are_errors() {
        let (_guard, device) = test_device();
        let cfg = micro("e_slotssm");
        device.seed(21);
        let a = PolicyModel::new(&cfg, &device).unwrap();
        device.seed(22);
        let b = PolicyModel::new(&cfg, &device).unwrap();
        let dir = std::env::temp_dir().join(format!("model-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("weights.bpk");
        a.save(&path).unwrap();
        let loaded = PolicyModel::load(&cfg, &path, &device).unwrap();
        let x = batch(&cfg, 1, 2, &device);
        let run = |m: &PolicyModel| {
            m.predict(x.images.clone(), x.instruction.clone(), None)
                .unwrap()
                .actions
        };
        let same: f32 = (run(&a) - run(&loaded)).abs().max().into_scalar();
        let other: f32 = (run(&a) - run(&b)).abs().max().into_scalar();
        assert_eq!(same, 0.0);
        assert!(other > 0.0);
        std::fs::write(dir.join("junk.bpk"), b"not a record").unwrap();
        assert!(PolicyModel::load(&cfg, dir.join("junk.bpk"), &device).is_err());
        assert!(PolicyModel::load(&cfg, dir.join("missing.bpk"), &device).is_err());
        // A record of another architecture does not load either.
        let other_cfg = micro("dense");
        assert!(PolicyModel::load(&other_cfg, &path, &device).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn same_seed_same_model() {
        // Burn initialises most parameters lazily (at their first use), so "same seed" means:
        // same seed, then the same sequence of calls.
        let (_guard, device) = test_device();
        let cfg = micro("slotvla_h8");
        device.seed(6);
        let x = batch(&cfg, 1, 3, &device);
        let run = |seed: u64| {
            device.seed(seed);
            let m = PolicyModel::new(&cfg, &device).unwrap();
            scalar(m.forward(&x).unwrap().1.total)
        };
        let (a, b, c) = (run(5), run(5), run(7));
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn tiny_model_overfits_one_batch() {
        use burn::grad_clipping::GradientClippingConfig;
        use burn::optim::{AdamWConfig, GradientsParams};
        let (_guard, device) = test_autodiff_device();
        device.seed(3);
        let cfg = micro("e_slotssm");
        let mut model = PolicyModel::new(&cfg, &device).unwrap();
        let x = batch(&cfg, 2, 4, &device);
        let mut optim = AdamWConfig::new()
            .with_weight_decay(0.0)
            .with_grad_clipping(Some(GradientClippingConfig::Norm(1.0)))
            .init();
        let mut first = None;
        let mut last = f32::INFINITY;
        for step in 0..400 {
            let (_, losses) = model.forward(&x).unwrap();
            let act = scalar(losses.action.clone());
            let initial = *first.get_or_insert(act);
            last = act;
            if act < 0.1 * initial {
                eprintln!("overfit: L_act {initial:.4} → {act:.4} in {step} steps");
                break;
            }
            let grads = GradientsParams::from_grads(losses.total.backward(), &model);
            model = optim.step(1e-3, model, grads);
        }
        let initial = first.unwrap();
        assert!(last < 0.1 * initial, "L_act {initial} → {last}");

        // The trained weights act through the streaming policy too (autodiff device given).
        let plain = Device::flex();
        let instr = Tokenizer::new(&cfg.text).encode_batch(&[INSTRUCTIONS[0]], &plain);
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        let mut err = 0.0;
        for t in 0..4 {
            let img = x
                .images
                .clone()
                .narrow(0, 0, 1)
                .narrow(1, t, 1)
                .squeeze_dim::<4>(1);
            let chunk = policy.act_tensor(img.inner(), instr.clone(), None).unwrap();
            let target = x.actions.clone().narrow(0, 0, 1).narrow(1, t, 1).inner();
            err += (chunk - target.reshape([2, 7]))
                .abs()
                .mean()
                .into_scalar::<f32>()
                / 4.0;
        }
        assert!(
            err < 0.1 * initial,
            "streamed L1 {err} vs initial {initial}"
        );
    }
}
