//! The policy model of every variant (model.md §9) and its training forward over windows: the
//! shared encoder, language embeddings and action decoder around the variant's token builder
//! ([`crate::variants`]: `e_slotssm`, `slotvla_h<N>`, `dense`). One interface for all, so trainer
//! and evaluator do not care which.

use std::path::Path;

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;

use crate::config::{ActionHead, ModelConfig, Observation};
use crate::decoder::{ActionDecoder, DecoderOutput, PointerHead};
use crate::encoder::{Frames, Observer};
use crate::error::{ModelError, Result};
use crate::heads::ProgressHead;
use crate::losses;
use crate::text::TextEncoder;
pub use crate::variants::{Carry, Subgoal};
use crate::variants::{Shared, TokenBuilder};

/// A training batch of windows.
#[derive(Clone, Debug)]
pub struct WindowBatch {
    /// What the model observes: agentview RGB in [0, 1] `[B, T, 3, H, W]` or object state.
    pub obs: Frames,
    /// Normalised target chunks a*_{t..t+H_a−1} `[B, T, H_a, A]`.
    pub actions: Tensor<4>,
    /// 1 for valid frames, 0 for padding `[B, T]`.
    pub frame_mask: Tensor<2>,
    /// The weight of each action entry in L_act `[B, T, H_a, A]`: its window's
    /// `action_weights` (1, 0, the idle tail's weight, × the gripper-switch factor); None: 1 for
    /// every entry of a valid frame.
    pub action_mask: Option<Tensor<4>>,
    /// Instruction token ids `[B, L_txt]` (see [`crate::io::Tokenizer`]).
    pub instruction: Tensor<2, Int>,
    /// Oracle subgoal (token ids `[B, T, G, L_sg]`, see [`Subgoal`]).
    pub subgoal: Option<Subgoal<4>>,
    /// The pointer's target token of each frame, one-hot over the state tokens `[B, T, K]`
    /// (all zero where a frame has none); read by the pointer loss.
    pub pointer_target: Option<Tensor<3>>,
    /// Each frame's number of subgoals done (as observed before its action), clamped to the
    /// progress head's classes `[B, T]`; read by the progress loss.
    pub progress: Option<Tensor<2, Int>>,
    /// 1 where a frame's goal is done (every subgoal satisfied, as observed before its action),
    /// else 0 `[B, T]`; read by the termination loss.
    pub done: Option<Tensor<2>>,
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
    /// The pointer head's weights over the current frame's state tokens `[B, T, H_a, K]`.
    pub pointer: Option<Tensor<4>>,
    /// The progress head's logits over the subgoals done `[B, T, C]` (with `loss.progress` > 0).
    pub progress: Option<Tensor<3>>,
    /// The termination head's logits (goal done) `[B, T]` (with `loss.done` > 0).
    pub done: Option<Tensor<2>>,
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
    /// L_ptr `[1]`: the pointer's cross-entropy to the target tokens.
    pub pointer: Option<Tensor<1>>,
    /// L_prog `[1]`: the progress head's cross-entropy to the subgoals done.
    pub progress: Option<Tensor<1>>,
    /// L_done `[1]`: the termination head's binary cross-entropy to the goal being done.
    pub done: Option<Tensor<1>>,
}

/// The policy network of any variant: the shared encoder, language and decoder around the
/// variant's [`TokenBuilder`].
#[derive(Module, Debug)]
pub struct PolicyModel {
    /// Encoder of the observations (pixels or object state).
    pub encoder: Observer,
    /// The variant: visual features → decoder tokens, with its memory.
    pub tokens: TokenBuilder,
    /// Visual token types (relation, slot, patch) `[3, D_dec]`.
    pub token_type: Param<Tensor<2>>,
    /// Language (and subgoal) embeddings, width D_dec.
    pub text: TextEncoder,
    /// Action decoder.
    pub decoder: ActionDecoder,
    /// Pointer head over the object tokens (state mode with `decoder.pointer`).
    pub pointer: Option<PointerHead>,
    /// Progress head over each frame's visual tokens (with `loss.progress` > 0; training only).
    pub progress: Option<ProgressHead>,
    /// With `decoder.belief`: the map of the progress head's distribution to the belief token,
    /// [`crate::heads::PROGRESS_CLASSES`] → D_dec.
    pub belief: Option<Linear>,
    /// Termination head (with `loss.done` > 0): the mean of the decoder's action-query outputs
    /// → one logit that the goal is done, `[D_dec, 1]`.
    pub done: Option<Linear>,
    /// The configuration this model was built from.
    #[module(skip)]
    pub config: ModelConfig,
}

impl PolicyModel {
    /// Builds a freshly initialised model (seed the device first for reproducibility).
    pub fn new(config: &ModelConfig, device: &Device) -> Result<Self> {
        config.validate()?;
        let w = config.decoder.width;
        Ok(PolicyModel {
            encoder: Observer::new(config, device),
            tokens: TokenBuilder::new(config, device),
            token_type: Param::from_tensor(Tensor::random(
                [3, w],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
            text: TextEncoder::new(&config.text, w, device),
            decoder: ActionDecoder::new(&config.decoder, device),
            pointer: match config.observation {
                _ if !config.decoder.pointer => None,
                Observation::State { features, .. } => Some(PointerHead::new(
                    w,
                    features,
                    config.decoder.action_dim,
                    config.decoder.pointer_input_keys,
                    device,
                )),
                Observation::Pixels => {
                    return Err(ModelError::Config(
                        "decoder.pointer: only state mode has object tokens to point at".into(),
                    ));
                }
            },
            progress: (config.loss.progress > 0.0).then(|| ProgressHead::new(w, device)),
            belief: config
                .decoder
                .belief
                .then(|| LinearConfig::new(crate::heads::PROGRESS_CLASSES, w).init(device)),
            done: (config.loss.done > 0.0).then(|| LinearConfig::new(w, 1).init(device)),
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

    /// The modules the variant reads but does not own.
    pub(crate) fn shared(&self) -> (Tensor<2>, &TextEncoder) {
        (self.token_type.val(), &self.text)
    }

    /// The termination head's logits from the decoder's action-query outputs (None without the
    /// head).
    ///
    /// # Shapes
    /// - queries: `[N, Q, D_dec]` → `[N]`
    pub(crate) fn done_logits(&self, queries: Tensor<3>) -> Option<Tensor<1>> {
        let head = self.done.as_ref()?;
        let [n, _, _] = queries.dims();
        let pooled = queries.mean_dim(1);
        let pooled = if self.config.decoder.done_detach {
            pooled.detach()
        } else {
            pooled
        };
        Some(head.forward(pooled).reshape([n]))
    }

    /// With `decoder.belief`, the visual tokens with the belief token before them: the progress
    /// head's distribution over the subgoals done, read off these tokens and detached, mapped to
    /// the decoder width; else the tokens as they are.
    ///
    /// # Shapes
    /// - visual: `[N, V, D_dec]`, pad `[N, V]` → `[N, V + 1, D_dec]`, `[N, V + 1]`
    fn with_belief(
        &self,
        visual: Tensor<3>,
        pad: Option<Tensor<2, Bool>>,
    ) -> (Tensor<3>, Option<Tensor<2, Bool>>) {
        let (Some(map), Some(head)) = (&self.belief, &self.progress) else {
            return (visual, pad);
        };
        let [n, _, d] = visual.dims();
        let probs = burn::tensor::activation::softmax(head.forward(visual.clone(), pad.clone()), 1);
        let token = map.forward(probs.detach()).reshape([n, 1, d]);
        let pad = pad.map(|p| {
            let open = Tensor::<2>::zeros([n, 1], &p.device()).greater_elem(0.5);
            Tensor::cat(vec![open, p], 1)
        });
        (Tensor::cat(vec![token, visual], 1), pad)
    }

    /// Decodes per frame given language ids; with a pointer head, `state` is each frame's
    /// object tokens (features and categories), the last K of the visual tokens.
    ///
    /// # Shapes
    /// - visual: `[N, V, D_dec]`, pad `[N, V]`; instruction: `[N, L_txt]`;
    ///   state: `[N, K, F]` and `[N, K]`
    pub(crate) fn decode(
        &self,
        visual: Tensor<3>,
        pad: Option<Tensor<2, Bool>>,
        instruction: Tensor<2, Int>,
        state: Option<(Tensor<3>, Tensor<2, Int>)>,
    ) -> Result<DecoderOutput> {
        let (lang, lang_pad) = self.text.tokens(instruction);
        let (visual, pad) = self.with_belief(visual, pad);
        let mut out = self.decoder.forward(visual, pad, lang, lang_pad);
        if let Some(pointer) = &self.pointer {
            let Some((features, categories)) = state else {
                return Err(ModelError::Input(
                    "the pointer head reads object state but was given none".into(),
                ));
            };
            let Some(visual) = out.visual.as_ref() else {
                return Err(ModelError::Input(
                    "the decoder kept no visual outputs for the pointer head".into(),
                ));
            };
            let [n, v, _] = visual.dims();
            let [_, k, _] = features.dims();
            let tokens = visual.clone().narrow(1, v - k, k);
            debug_assert_eq!(categories.dims(), [n, k]);
            let pad = categories.equal_elem(crate::io::state::PAD);
            let weights = pointer.weights(out.queries.clone(), tokens, features.clone(), pad);
            out.actions = out.actions + pointer.term(weights.clone(), features);
            out.pointer = Some(weights);
        }
        Ok(out)
    }

    /// Prediction over windows that start at the episode start (no losses).
    ///
    /// # Shapes
    /// - obs: images `[B, T, 3, H, W]` in [0, 1] or state (see [`Frames`]);
    ///   instruction: `[B, L_txt]`; subgoal: `[B, T, G, L_sg]`
    /// - output: see [`WindowOutput`]
    pub fn predict(
        &self,
        images: impl Into<Frames>,
        instruction: Tensor<2, Int>,
        subgoal: Option<Subgoal<4>>,
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
        obs: impl Into<Frames>,
        instruction: Tensor<2, Int>,
        subgoal: Option<Subgoal<4>>,
        carry: Carry,
    ) -> Result<(WindowOutput, Carry)> {
        let obs = obs.into();
        let [b, t] = obs.batch_time();
        let cfg = &self.config;
        let [b2, l_txt] = instruction.dims();
        if b2 != b || l_txt > cfg.text.max_len {
            return Err(ModelError::Input(format!(
                "instruction ids {:?}, expected [{b}, ≤{}]",
                instruction.dims(),
                cfg.text.max_len
            )));
        }
        let state = obs.state_tokens();
        let feats = self.encoder.forward(obs)?; // [B, T, M, D_f]
        let (token_type, text) = self.shared();
        let shared = Shared {
            token_type: &token_type,
            text,
        };
        let win = self.tokens.window(feats, subgoal, carry, shared)?;
        let instr = instruction
            .unsqueeze_dim::<3>(1)
            .repeat_dim(1, t)
            .reshape([b * t, l_txt]);
        let progress = self.progress.as_ref().map(|head| {
            head.forward(win.tokens.clone(), win.pad.clone()).reshape([
                b,
                t,
                crate::heads::PROGRESS_CLASSES,
            ])
        });
        let dec = self.decode(win.tokens, win.pad, instr, state)?;
        let done = self
            .done_logits(dec.queries.clone())
            .map(|d| d.reshape([b, t]));
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        let parts = win.parts;
        let out = WindowOutput {
            actions: dec.actions.reshape([b, t, ha, a]),
            logits: dec
                .logits
                .map(|l| l.reshape([b, t, ha, a, crate::decoder::NUM_BINS])),
            slots: parts.slots,
            masks: parts.masks,
            predicted: parts.predicted,
            window: parts.window,
            pointer: dec.pointer.map(|p| {
                let k = p.dims()[2];
                p.reshape([b, t, ha, k])
            }),
            progress,
            done,
        };
        Ok((out, win.carry))
    }

    /// Training forward: predictions and all losses of a window batch (windows start from an
    /// empty memory).
    pub fn forward(&self, batch: &WindowBatch) -> Result<(WindowOutput, Losses)> {
        self.forward_from(batch, Carry::default())
            .map(|(out, losses, _)| (out, losses))
    }

    /// The weights of the action loss's entries: the batch's action mask (else its frame mask
    /// over the whole chunk), the gripper column weighted by `loss.gripper`.
    ///
    /// # Shapes
    /// - → `[B, T, H_a, A]`
    fn action_mask(&self, batch: &WindowBatch) -> Tensor<4> {
        let cfg = &self.config;
        let [b, t] = batch.frame_mask.dims();
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        let mask = batch.action_mask.clone().unwrap_or_else(|| {
            batch
                .frame_mask
                .clone()
                .reshape([b, t, 1, 1])
                .repeat_dim(2, ha)
                .repeat_dim(3, a)
        });
        losses::weight_gripper(mask, cfg.loss.gripper)
    }

    /// The total weight of the action loss's entries in `batch` (the denominator of its masked
    /// mean): data-parallel replicas weight their losses by their shares of it, so that their
    /// sum is the whole batch's action loss.
    pub fn action_mass(&self, batch: &WindowBatch) -> Result<f64> {
        self.action_mask(batch)
            .sum()
            .try_into_scalar::<f32>()
            .map(f64::from)
            .map_err(|e| ModelError::Input(format!("action mask: {e:?}")))
    }

    /// Training forward from carried memory (truncated BPTT); also returns the memory after
    /// the window, detached.
    pub fn forward_from(
        &self,
        batch: &WindowBatch,
        carry: Carry,
    ) -> Result<(WindowOutput, Losses, Carry)> {
        let cfg = &self.config;
        let [b, t] = batch.obs.batch_time();
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        if batch.actions.dims() != [b, t, ha, a] || batch.frame_mask.dims() != [b, t] {
            return Err(ModelError::Input(format!(
                "actions {:?} / frame_mask {:?}, expected [{b}, {t}, {ha}, {a}] / [{b}, {t}]",
                batch.actions.dims(),
                batch.frame_mask.dims()
            )));
        }
        let (out, carry) = self.predict_from(
            batch.obs.clone(),
            batch.instruction.clone(),
            batch.subgoal.clone(),
            carry,
        )?;
        let frame_mask = batch.frame_mask.clone();
        let action_mask = self.action_mask(batch);
        let action = match (cfg.decoder.head, &out.logits) {
            (ActionHead::Bins, Some(logits)) => {
                losses::action_ce(logits.clone(), batch.actions.clone(), action_mask)
            }
            (ActionHead::L2, _) => {
                losses::action_l2(out.actions.clone(), batch.actions.clone(), action_mask)
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
        let slot_decoder = self
            .tokens
            .slot_core()
            .and_then(|c| c.slot_decoder.as_ref());
        let slot_recon = match (slot_decoder, &out.slots, batch.obs.pixels()) {
            (Some(dec), Some(s), Some(images)) => {
                let [_, _, k, d] = s.dims();
                let (recon, _) = dec.forward(s.clone().reshape([b * t, k, d]));
                let [_, m, d_tgt] = recon.dims();
                let target = losses::image_patches(images, cfg.grid());
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
        let pointer = match (&out.pointer, &batch.pointer_target) {
            (Some(weights), Some(target)) => Some(losses::pointer_ce(
                weights.clone(),
                target.clone(),
                batch.frame_mask.clone(),
            )),
            _ => None,
        };
        if let Some(l) = &pointer {
            total = total + l.clone().mul_scalar(cfg.loss.pointer);
        }
        let progress = match (&out.progress, &batch.progress) {
            (Some(logits), Some(target)) => Some(losses::progress_ce(
                logits.clone(),
                target.clone(),
                batch.frame_mask.clone(),
            )),
            (Some(_), None) => {
                return Err(ModelError::Input(
                    "loss.progress > 0, and the batch carries no progress targets".into(),
                ));
            }
            _ => None,
        };
        if let Some(l) = &progress {
            total = total + l.clone().mul_scalar(cfg.loss.progress);
        }
        let done = match (&out.done, &batch.done) {
            (Some(logits), Some(target)) => Some(losses::done_bce(
                logits.clone(),
                target.clone(),
                batch.frame_mask.clone(),
            )),
            (Some(_), None) => {
                return Err(ModelError::Input(
                    "loss.done > 0, and the batch carries no goal-done targets".into(),
                ));
            }
            _ => None,
        };
        if let Some(l) = &done {
            total = total + l.clone().mul_scalar(cfg.loss.done);
        }
        Ok((
            out,
            Losses {
                total,
                action,
                contrastive,
                window,
                slot_recon,
                pointer,
                progress,
                done,
            },
            carry,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::io::Tokenizer;
    use crate::streaming::StreamingPolicy;
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
            obs: Tensor::random([b, t, 3, h, w], Distribution::Uniform(0.0, 1.0), device).into(),
            actions: Tensor::random([b, t, ha, a], Distribution::Uniform(-1.0, 1.0), device),
            frame_mask: Tensor::from_data(TensorData::new(mask, [b, t]), device),
            action_mask: None,
            instruction: tok.encode_batch(&texts, device),
            subgoal: Some(subgoal.into()),
            pointer_target: None,
            progress: None,
            done: None,
        }
    }

    #[test]
    fn instructions_cut_to_their_longest_give_the_padded_outputs() {
        let (_guard, device) = test_device();
        let tok = Tokenizer::new(&micro("e_slotssm").text);
        let cut = tok.encode_instructions(&INSTRUCTIONS, &device);
        // "put the bowl on the plate": 6 words; the other 4.
        assert_eq!(cut.dims(), [2, 6]);
        assert_eq!(
            tok.encode_instructions(&["", ""], &device).dims(),
            [2, 1],
            "at least one column"
        );
        let ids = |t: Tensor<2, Int>| t.into_data().try_to_vec_as::<i64>().unwrap();
        let full = ids(tok.encode_batch(&INSTRUCTIONS, &device));
        assert_eq!(ids(cut), [&full[..6], &full[8..14]].concat());
        for (variant, film) in [("e_slotssm", true), ("slotvla_h3", false), ("dense", false)] {
            let mut cfg = micro(variant);
            cfg.decoder.film = film;
            let mut model = PolicyModel::new(&cfg, &device).unwrap();
            if let Some(film) = model.decoder.film.as_mut() {
                // FiLM starts at zero: give it weights so that the pooled language matters.
                let w = film
                    .weight
                    .val()
                    .random_like(Distribution::Normal(0.0, 0.1));
                film.weight = burn::module::Param::from_tensor(w);
            }
            check_cut(&model, &mut batch(&cfg, 2, 3, &device), &tok, &device);
        }
    }

    fn check_cut(model: &PolicyModel, b: &mut WindowBatch, tok: &Tokenizer, device: &Device) {
        let texts: Vec<&str> = (0..b.frame_mask.dims()[0])
            .map(|i| INSTRUCTIONS[i % 2])
            .collect();
        b.instruction = tok.encode_batch(&texts, device);
        let (padded, lp) = model.forward(b).unwrap();
        b.instruction = tok.encode_instructions(&texts, device);
        assert!(b.instruction.dims()[1] < model.config.text.max_len);
        let (cut, lc) = model.forward(b).unwrap();
        let diff = (padded.actions - cut.actions)
            .abs()
            .max()
            .into_scalar::<f32>();
        assert!(diff < 1e-5, "actions differ by {diff}");
        let dl = (lp.total - lc.total).abs().into_scalar::<f32>();
        assert!(dl < 1e-5, "losses differ by {dl}");
    }

    /// λ_tc L_tc + λ_win L_win + λ_sa L_sa of the terms the variant computes.
    fn slot_terms(losses: &Losses, cfg: &ModelConfig) -> f32 {
        [
            (&losses.contrastive, cfg.loss.contrastive),
            (&losses.window, cfg.loss.window),
            (&losses.slot_recon, cfg.loss.slot_recon),
        ]
        .into_iter()
        .filter_map(|(l, w)| l.as_ref().map(|l| w as f32 * scalar(l.clone())))
        .sum()
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
            let want = scalar(losses.action.clone()) + slot_terms(&losses, &cfg);
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
        // The squared-error head: the L1 head's outputs (same weights, same actions), its loss
        // the masked mean squared error of them.
        let l1 = tiny("slotvla_h1");
        let mut l2 = l1.clone();
        l2.decoder.head = ActionHead::L2;
        let model_l1 = PolicyModel::new(&l1, &device).unwrap();
        let model_l2 = PolicyModel::new(&l2, &device)
            .unwrap()
            .load_record(model_l1.clone().into_record());
        let x = batch(&l1, b, t, &device);
        let (out1, loss1) = model_l1.forward(&x).unwrap();
        let (out2, loss2) = model_l2.forward(&x).unwrap();
        assert_eq!(out1.actions.to_data(), out2.actions.to_data());
        let mask = model_l2.action_mask(&x);
        let want = scalar(losses::action_l2(
            out2.actions,
            x.actions.clone(),
            mask.clone(),
        ));
        assert!((scalar(loss2.action.clone()) - want).abs() < 1e-6);
        let l1_loss = scalar(losses::action_l1(out1.actions, x.actions.clone(), mask));
        assert!((scalar(loss1.action) - l1_loss).abs() < 1e-6);
        assert!(
            (scalar(loss2.action) - l1_loss).abs() > 1e-3,
            "the two losses differ"
        );
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

    impl<'a> GradCheck<'a> {
        /// Visits every parameter of `model` against `grads`.
        fn run(model: &PolicyModel, grads: &'a Gradients) -> Self {
            let mut check = GradCheck {
                grads,
                path: Vec::new(),
                visited: 0,
                bad: Vec::new(),
            };
            model.visit(&mut check);
            check
        }
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
        let check = GradCheck::run(&model, &grads);
        assert!(check.visited > 50, "{name}: visited only {}", check.visited);
        // Every word of the batch is used, but the vocabulary also holds special ids and
        // words absent from this batch: embedding rows are one parameter, so it still counts.
        assert!(
            check.bad.is_empty(),
            "{name}: no gradient for {:?}",
            check.bad
        );
    }

    /// The full preset (model.md §0: 224², K = 16, D = 512, 3 SSM blocks, 6 decoder layers)
    /// builds and runs one forward + backward at batch 1 over a reduced window on the CPU, every
    /// parameter getting a gradient (the GPU window is 32 frames; `cargo bench -p model` prints
    /// the memory estimate for it).
    #[test]
    fn full_preset_trains_at_batch_1() {
        let (_guard, device) = test_autodiff_device();
        device.seed(2);
        let cfg = ModelConfig::full(Variant::from_name("e_slotssm").unwrap())
            .with_vocab_from(INSTRUCTIONS.iter().copied().chain(["bowl", "drawer"]));
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let params = model.num_params();
        assert!(
            params > 30_000_000,
            "full preset has only {params} parameters"
        );
        let t = 3; // two valid frames (the helper pads the last one)
        let (out, losses) = model.forward(&batch(&cfg, 1, t, &device)).unwrap();
        assert_eq!(out.actions.dims(), [1, t, 8, 7]);
        assert_eq!(out.slots.as_ref().unwrap().dims(), [1, t, 16, 512]);
        assert_eq!(out.masks.as_ref().unwrap().dims(), [1, t, 16, 196]);
        let total = scalar(losses.total.clone());
        assert!(total.is_finite() && total > 0.0, "loss {total}");
        let grads = losses.total.backward();
        let check = GradCheck::run(&model, &grads);
        assert!(check.visited > 100, "visited only {}", check.visited);
        assert!(check.bad.is_empty(), "no gradient for {:?}", check.bad);
    }

    /// The progress head: built only with λ_prog > 0, its loss in the total with its weight,
    /// its gradient reaching the memory (e_slotssm's SlotSSM; slotvla_h8's history padding
    /// handled), and a batch without targets an error.
    #[test]
    fn progress_loss_reads_the_tokens_and_reaches_the_memory() {
        let (_guard, device) = test_autodiff_device();
        device.seed(4);
        let (b, t) = (2, 4);
        let plain = micro("e_slotssm");
        let model = PolicyModel::new(&plain, &device).unwrap();
        assert!(model.progress.is_none());
        let (out, losses) = model.forward(&batch(&plain, b, t, &device)).unwrap();
        assert!(out.progress.is_none() && losses.progress.is_none());
        for name in ["e_slotssm", "slotvla_h8"] {
            let mut cfg = micro(name);
            cfg.loss.progress = 0.5;
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let mut x = batch(&cfg, b, t, &device);
            assert!(
                model
                    .forward(&x)
                    .unwrap_err()
                    .to_string()
                    .contains("no progress targets"),
                "{name}"
            );
            x.progress = Some(Tensor::from_ints([[0, 0, 1, 1], [2, 2, 2, 3]], &device));
            let (out, losses) = model.forward(&x).unwrap();
            assert_eq!(
                out.progress.as_ref().map(|p| p.dims()),
                Some([b, t, crate::heads::PROGRESS_CLASSES]),
                "{name}"
            );
            let prog = scalar(losses.progress.clone().expect("L_prog"));
            assert!(prog.is_finite() && prog > 0.0, "{name}: {prog}");
            let want = scalar(losses.action.clone()) + 0.5 * prog + slot_terms(&losses, &cfg);
            let total = scalar(losses.total.clone());
            assert!((total - want).abs() < 1e-4, "{name}: {total} vs {want}");
            // L_prog alone moves the layers below the tokens, the memory among them.
            let grads = losses.progress.unwrap().backward();
            let check = GradCheck::run(&model, &grads);
            let moved = |part: &str| !check.bad.iter().any(|p| p.contains(part));
            assert!(moved("progress"), "{name}: {:?}", check.bad);
            if name == "e_slotssm" {
                assert!(moved("slot_ssm"), "{name}: {:?}", check.bad);
            }
            // Nothing above the tokens: the action decoder gets no gradient from it.
            assert!(
                check.bad.iter().any(|p| p.starts_with("decoder")),
                "{name}: the decoder moved"
            );
        }
    }

    /// The termination head: built only with λ_done > 0, refused a batch without targets, its
    /// loss in the total with its weight, reaching the decoder and the memory below it; streamed,
    /// its probability equals the window forward's frame by frame.
    #[test]
    fn termination_head_reads_the_queries_and_reaches_the_memory() {
        {
            let (_guard, device) = test_autodiff_device();
            device.seed(5);
            let (b, t) = (2, 4);
            let plain = micro("e_slotssm");
            let model = PolicyModel::new(&plain, &device).unwrap();
            assert!(model.done.is_none());
            let (out, losses) = model.forward(&batch(&plain, b, t, &device)).unwrap();
            assert!(out.done.is_none() && losses.done.is_none());
            for name in ["e_slotssm", "slotvla_h8"] {
                let mut cfg = micro(name);
                cfg.loss.done = 0.25;
                let model = PolicyModel::new(&cfg, &device).unwrap();
                let mut x = batch(&cfg, b, t, &device);
                let err = model.forward(&x).unwrap_err().to_string();
                assert!(err.contains("no goal-done targets"), "{name}: {err}");
                x.done = Some(Tensor::from_floats(
                    [[0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 1.0, 1.0]],
                    &device,
                ));
                let (out, losses) = model.forward(&x).unwrap();
                assert_eq!(out.done.as_ref().map(|d| d.dims()), Some([b, t]), "{name}");
                let done = scalar(losses.done.clone().expect("L_done"));
                // An untrained head sits near p = ½: the BCE near ln 2.
                assert!((done - 2f32.ln()).abs() < 0.2, "{name}: {done}");
                let want = scalar(losses.action.clone()) + 0.25 * done + slot_terms(&losses, &cfg);
                let total = scalar(losses.total.clone());
                assert!((total - want).abs() < 1e-4, "{name}: {total} vs {want}");
                // L_done alone moves the head, the decoder and the memory below the tokens.
                let grads = losses.done.unwrap().backward();
                let check = GradCheck::run(&model, &grads);
                let moved = |part: &str| !check.bad.iter().any(|p| p.starts_with(part));
                assert!(
                    moved("done") && moved("decoder.queries"),
                    "{name}: {:?}",
                    check.bad
                );
                if name == "e_slotssm" {
                    assert!(
                        !check.bad.iter().any(|p| p.contains("slot_ssm")),
                        "{name}: {:?}",
                        check.bad
                    );
                }
                // Detached, the same loss value trains the head alone.
                let mut det = model.clone();
                det.config.decoder.done_detach = true;
                let (_, losses) = det.forward(&x).unwrap();
                assert_eq!(scalar(losses.done.clone().unwrap()), done, "{name}");
                let grads = losses.done.unwrap().backward();
                let check = GradCheck::run(&det, &grads);
                assert!(
                    check.bad.iter().all(|p| !p.starts_with("done"))
                        && check.bad.iter().any(|p| p.starts_with("decoder"))
                        && check.bad.iter().any(|p| p.starts_with("encoder")),
                    "{name}: {:?}",
                    check.bad
                );
            }
        }
        for name in ["e_slotssm", "slotvla_h3"] {
            let mut cfg = micro(name);
            cfg.loss.done = 1.0;
            streaming_equals_window(cfg, 10);
        }
    }

    /// The belief token: the decoder reads the progress head's distribution (detached), so the
    /// action loss moves its map but never the progress head through it; a belief without the
    /// progress loss is refused; the streamed policy reads the same belief as the window forward.
    #[test]
    fn belief_token_feeds_the_progress_head_to_the_decoder() {
        let cfg = belief_checks();
        // (after the autodiff device's lock is released)
        streaming_equals_window(cfg, 10);
    }

    /// The window-forward half of the belief test; returns the config it checked.
    fn belief_checks() -> ModelConfig {
        let (_guard, device) = test_autodiff_device();
        device.seed(6);
        let (b, t) = (2, 4);
        let mut cfg = micro("e_slotssm");
        cfg.decoder.belief = true;
        assert!(
            cfg.validate()
                .unwrap_err()
                .to_string()
                .contains("decoder.belief reads the progress head"),
        );
        cfg.loss.progress = 0.5;
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let mut x = batch(&cfg, b, t, &device);
        x.progress = Some(Tensor::from_ints([[0, 0, 1, 1], [2, 2, 2, 3]], &device));
        let (out, losses) = model.forward(&x).unwrap();
        assert_eq!(out.actions.dims(), [b, t, cfg.decoder.horizon, 7]);
        // The same weights without the belief token act differently.
        let mut plain_cfg = cfg.clone();
        plain_cfg.decoder.belief = false;
        let mut plain = PolicyModel::new(&plain_cfg, &device).unwrap();
        plain.encoder = model.encoder.clone();
        plain.tokens = model.tokens.clone();
        plain.token_type = model.token_type.clone();
        plain.text = model.text.clone();
        plain.decoder = model.decoder.clone();
        plain.progress = model.progress.clone();
        let (plain_out, _) = plain.forward(&x).unwrap();
        let diff = scalar(
            (out.actions.clone() - plain_out.actions)
                .abs()
                .max()
                .reshape([1]),
        );
        assert!(diff > 1e-4, "the belief token changed nothing ({diff})");
        // The action loss reaches the belief map and the decoder, not the progress head.
        let grads = losses.action.backward();
        let check = GradCheck::run(&model, &grads);
        let moved = |part: &str| !check.bad.iter().any(|p| p.starts_with(part));
        assert!(moved("belief") && moved("decoder."), "{:?}", check.bad);
        assert!(
            check.bad.iter().any(|p| p.starts_with("progress")),
            "the action loss moved the progress head: {:?}",
            check.bad
        );
        cfg
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
        let out = model
            .predict(images.clone(), instr.clone(), Some(subgoal.clone().into()))
            .unwrap();
        let full = out.actions;
        // The termination head's probability per frame `[T]` (models with the head).
        let done: Option<Vec<f32>> = out.done.map(|d| {
            burn::tensor::activation::sigmoid(d)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap()
        });
        // The progress head's distribution per frame `[T, C]` (models with the head).
        let progress = out.progress.map(|p| {
            let c = p.dims()[2];
            burn::tensor::activation::softmax(p.reshape([frames, c]), 1)
        });
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        assert!(policy.last_progress().unwrap().is_none());
        let mut worst = 0.0f32;
        let mut worst_progress = 0.0f32;
        let mut worst_done = 0.0f32;
        assert!(policy.last_done().unwrap().is_none());
        assert_eq!(policy.has_done_head(), done.is_some());
        for t in 0..frames {
            let img = images.clone().narrow(1, t, 1).squeeze_dim::<4>(1);
            let sg = subgoal.clone().narrow(1, t, 1).squeeze_dim::<3>(1);
            let chunk = policy.act_tensor(img, instr.clone(), Some(sg)).unwrap();
            let want = full.clone().narrow(1, t, 1).reshape(chunk.dims());
            worst = worst.max((chunk - want).abs().max().into_scalar::<f32>());
            match (&progress, policy.last_progress().unwrap()) {
                (Some(p), Some(got)) => {
                    let want = p
                        .clone()
                        .narrow(0, t, 1)
                        .into_data()
                        .try_to_vec::<f32>()
                        .unwrap();
                    for (a, b) in got.iter().zip(&want) {
                        worst_progress = worst_progress.max((a - b).abs());
                    }
                }
                (None, None) => {}
                _ => panic!("the window forward and the stream disagree on the progress head"),
            }
            match (&done, policy.last_done().unwrap()) {
                (Some(d), Some(got)) => worst_done = worst_done.max((d[t] - got).abs()),
                (None, None) => {}
                _ => panic!("the window forward and the stream disagree on the termination head"),
            }
        }
        assert!(
            worst_done < 1e-5,
            "{}: termination max diff {worst_done}",
            cfg.variant.name()
        );
        assert!(worst < 1e-4, "{}: max diff {worst}", cfg.variant.name());
        assert!(
            worst_progress < 1e-4,
            "{}: progress max diff {worst_progress}",
            cfg.variant.name()
        );
    }

    /// The progress head read while streaming equals the window forward's, frame by frame
    /// (e_slotssm's memory; slotvla_h3's history of frames seen).
    #[test]
    fn streamed_progress_equals_the_window_forward() {
        for name in ["e_slotssm", "slotvla_h3"] {
            let mut cfg = micro(name);
            cfg.loss.progress = 0.5;
            streaming_equals_window(cfg, 12);
        }
    }

    /// Per-object labels and boxes of `frames` frames of 2 objects (object 1 unseen in every
    /// third frame): ids `[1, T, 3, L]` (the 2 labels, then "0"), boxes `[1, T, 2, 4]`.
    fn matched_subgoal(cfg: &ModelConfig, frames: usize, device: &Device) -> Subgoal<4> {
        let tok = Tokenizer::new(&cfg.text);
        let mut texts = Vec::new();
        let mut boxes = Vec::new();
        for t in 0..frames {
            texts.extend([if t < frames / 2 { "0" } else { "bowl" }, "drawer", "0"]);
            let x = 0.05 * (t % 8) as f32;
            boxes.extend([x, 0.1, 0.3, 0.25]);
            boxes.extend(if t % 3 == 2 {
                [0.0; 4]
            } else {
                [0.5, 0.55, 0.4, 0.4]
            });
        }
        Subgoal {
            ids: tok
                .encode_batch(&texts, device)
                .reshape([1, frames, 3, cfg.text.max_len]),
            boxes: Some(Tensor::from_data(
                TensorData::new(boxes, [1, frames, 2, 4]),
                device,
            )),
        }
    }

    #[test]
    fn streaming_equals_full_forward_with_labels_matched_to_slots() {
        let (_guard, device) = test_device();
        device.seed(9);
        let cfg = micro("e_slotssm_oracle");
        let frames = 12;
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let x = batch(&cfg, 1, frames, &device);
        let images = x.obs.pixels().unwrap();
        let sub = matched_subgoal(&cfg, frames, &device);
        let full = model
            .predict(images.clone(), x.instruction.clone(), Some(sub.clone()))
            .unwrap()
            .actions;
        // The labels reach the slots: all-"0" labels give other actions.
        let zeros = Subgoal {
            ids: Tokenizer::new(&cfg.text)
                .encode_batch(&vec!["0"; frames * 3], &device)
                .reshape([1, frames, 3, cfg.text.max_len]),
            ..sub.clone()
        };
        let blank = model
            .predict(images.clone(), x.instruction.clone(), Some(zeros))
            .unwrap()
            .actions;
        let moved: f32 = (blank - full.clone()).abs().max().into_scalar();
        assert!(moved > 1e-5, "matched labels changed nothing");
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        let mut worst = 0.0f32;
        for t in 0..frames {
            let img = images.clone().narrow(1, t, 1);
            let step = sub.clone().narrow_time(t, 1).frames();
            let chunk = policy
                .act_frames(Frames::Pixels(img), x.instruction.clone(), Some(step))
                .unwrap();
            let want = full.clone().narrow(1, t, 1).reshape(chunk.dims());
            worst = worst.max((chunk - want).abs().max().into_scalar::<f32>());
        }
        assert!(worst < 1e-4, "max diff {worst}");
        // Label rows that do not fit the boxes are an error, not a panic.
        let bad = Subgoal {
            ids: sub.ids.narrow(2, 0, 2),
            ..sub
        };
        let e = PolicyModel::new(&cfg, &device)
            .unwrap()
            .predict(images, x.instruction, Some(bad))
            .unwrap_err()
            .to_string();
        assert!(e.contains("J + 1 label rows"), "{e}");
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
            let frame = |t: usize| x.obs.pixels().unwrap().narrow(1, t, 1).squeeze_dim::<4>(1);
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

    /// Lanes of a batch never see each other: predicting lanes 0–1 and 2–3 as two batches gives
    /// what the batch of four gives them (data-parallel replicas split batches this way).
    #[test]
    fn lanes_of_a_batch_are_independent() {
        let (_guard, device) = test_device();
        for name in ["e_slotssm", "slotvla_h1", "slotvla_h8", "dense"] {
            let cfg = micro(name);
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let x = batch(&cfg, 4, 3, &device);
            let pix = x.obs.pixels().unwrap();
            let whole = model
                .predict(pix.clone(), x.instruction.clone(), None)
                .unwrap()
                .actions;
            let part = |i: usize| {
                model
                    .predict(
                        pix.clone().narrow(0, 2 * i, 2),
                        x.instruction.clone().narrow(0, 2 * i, 2),
                        None,
                    )
                    .unwrap()
                    .actions
            };
            let joined = Tensor::cat(vec![part(0), part(1)], 0);
            let diff: f32 = (joined - whole).abs().max().into_scalar();
            assert!(diff < 1e-4, "{name}: {diff}");
        }
    }

    /// Halves of a batch with different numbers of valid frames (the last frame of the last
    /// lane is padding), weighted by their shares of the action mass, give the batch's action loss.
    #[test]
    fn halves_weighted_by_action_mass_give_the_batch_action_loss() {
        let (_guard, device) = test_device();
        let cfg = micro("e_slotssm");
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let x = batch(&cfg, 4, 3, &device);
        let half = |i: usize| WindowBatch {
            obs: x.obs.pixels().unwrap().narrow(0, 2 * i, 2).into(),
            actions: x.actions.clone().narrow(0, 2 * i, 2),
            frame_mask: x.frame_mask.clone().narrow(0, 2 * i, 2),
            action_mask: None,
            instruction: x.instruction.clone().narrow(0, 2 * i, 2),
            subgoal: None,
            pointer_target: None,
            progress: None,
            done: None,
        };
        let whole = WindowBatch {
            subgoal: None,
            ..x.clone()
        };
        let (_, all, _) = model.forward_from(&whole, Carry::default()).unwrap();
        let masses: Vec<f64> = (0..2)
            .map(|i| model.action_mass(&half(i)).unwrap())
            .collect();
        let (ha, a) = (cfg.decoder.horizon, cfg.decoder.action_dim);
        assert_eq!(masses, vec![(6 * ha * a) as f64, (5 * ha * a) as f64]);
        let total: f64 = masses.iter().sum();
        let weighted: f64 = (0..2)
            .map(|i| {
                let (_, l, _) = model.forward_from(&half(i), Carry::default()).unwrap();
                masses[i] / total * f64::from(scalar(l.action))
            })
            .sum();
        let plain_mean: f64 = (0..2)
            .map(|i| {
                let (_, l, _) = model.forward_from(&half(i), Carry::default()).unwrap();
                0.5 * f64::from(scalar(l.action))
            })
            .sum();
        let want = f64::from(scalar(all.action));
        assert!((weighted - want).abs() < 1e-5, "{weighted} vs {want}");
        // The plain mean of the halves' means is another number.
        assert!((plain_mean - want).abs() > 1e-4, "{plain_mean} vs {want}");
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
                .predict(x.obs.pixels().unwrap(), x.instruction.clone(), sub.clone())
                .unwrap()
                .actions;
            let half = |i: usize| x.obs.pixels().unwrap().narrow(1, 4 * i, 4);
            let sub_half = |i: usize| sub.clone().map(|s| s.narrow_time(4 * i, 4));
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

    /// Truncated BPTT over consecutive chunks (model.md §10): two lanes walk episodes chunk by
    /// chunk with the carried memory; lane 1 finishes an episode and starts another (a fresh
    /// lane). Every frame's actions equal a streaming policy run over its own episode.
    fn chunks_equal_streaming(cfg: ModelConfig) {
        let (_guard, device) = test_device();
        device.seed(4);
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let tok = Tokenizer::new(&cfg.text);
        let [h, w] = cfg.image_size;
        let frames = |n: usize| {
            Tensor::<5>::random([1, n, 3, h, w], Distribution::Uniform(0.0, 1.0), &device)
        };
        // Lane 0: one episode of 8 frames; lane 1: episodes of 4 and 4 frames. Chunks of 2.
        let (e0, e1a, e1b) = (frames(8), frames(4), frames(4));
        let lane1 = Tensor::cat(vec![e1a.clone(), e1b.clone()], 1);
        let instr = tok.encode_batch(&[INSTRUCTIONS[0], INSTRUCTIONS[0]], &device);
        let mut carry = Carry::default();
        let mut chunked = [vec![], vec![]];
        for c in 0..4 {
            let images = Tensor::cat(
                vec![
                    e0.clone().narrow(1, 2 * c, 2),
                    lane1.clone().narrow(1, 2 * c, 2),
                ],
                0,
            );
            if c == 2 {
                let fresh = TensorData::new(vec![false, true], [2]);
                carry = carry.with_fresh(Tensor::from_data(fresh, &device));
            }
            let (out, next) = model
                .predict_from(images, instr.clone(), None, carry)
                .unwrap();
            carry = next;
            for (lane, acts) in chunked.iter_mut().enumerate() {
                acts.push(out.actions.clone().narrow(0, lane, 1));
            }
        }
        let streamed = |episode: Tensor<5>| {
            let mut policy = StreamingPolicy::new(model.clone(), &device).unwrap();
            let n = episode.dims()[1];
            (0..n)
                .map(|t| {
                    let img = episode.clone().narrow(1, t, 1).squeeze_dim::<4>(1);
                    policy
                        .act_tensor(img, instr.clone().narrow(0, 0, 1), None)
                        .unwrap()
                })
                .collect::<Vec<_>>()
        };
        let want = [
            streamed(e0),
            streamed(e1a).into_iter().chain(streamed(e1b)).collect(),
        ];
        let mut worst = 0.0f32;
        for lane in 0..2 {
            let got = Tensor::cat(chunked[lane].clone(), 1); // [1, 8, H_a, A]
            for (t, chunk) in want[lane].iter().enumerate() {
                let g = got.clone().narrow(1, t, 1).reshape(chunk.dims());
                worst = worst.max((g - chunk.clone()).abs().max().into_scalar::<f32>());
            }
        }
        assert!(worst < 1e-4, "{}: max diff {worst}", cfg.variant.name());
    }

    #[test]
    fn chunked_training_with_carried_memory_equals_streaming_e_slotssm() {
        chunks_equal_streaming(micro("e_slotssm"));
    }

    #[test]
    fn chunked_training_with_carried_memory_equals_streaming_slotvla_h3() {
        chunks_equal_streaming(micro("slotvla_h3"));
    }

    #[test]
    fn chunked_training_with_carried_memory_equals_streaming_dense_h3() {
        chunks_equal_streaming(micro("dense_h3"));
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
            m.predict(x.obs.pixels().unwrap(), x.instruction.clone(), None)
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
        // Fuzzing the loader: damaged copies (bytes flipped, the file cut) load or fail, and
        // never panic. The run contract's manifest refuses them before this point; the loader
        // itself must still be safe on any bytes.
        let good = std::fs::read(&path).unwrap();
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let bad = dir.join("bad.bpk");
        let (mut loaded_ok, mut refused) = (0, 0);
        for case in 0..200 {
            let mut b = good.clone();
            if case % 4 == 0 {
                b.truncate(next() as usize % b.len());
            } else {
                for _ in 0..1 + case % 8 {
                    let i = next() as usize % b.len();
                    b[i] ^= 1 << (next() % 8);
                }
            }
            std::fs::write(&bad, &b).unwrap();
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                PolicyModel::load(&cfg, &bad, &device).is_ok()
            }));
            match r {
                Ok(true) => loaded_ok += 1,
                Ok(false) => refused += 1,
                Err(_) => panic!("case {case}: the loader panicked on a damaged file"),
            }
        }
        assert_eq!(loaded_ok + refused, 200);
        assert!(
            refused >= 50,
            "every cut file is refused ({refused} refused)"
        );
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

    /// Trains `model` on the one batch `x` (AdamW without decay, global-norm clip 1) for up to
    /// `steps` steps at `lr`, stopping once L_act falls below `stop` × its first value; returns
    /// the model, the first and the last L_act measured, and the steps taken.
    fn fit_one_batch(
        mut model: PolicyModel,
        x: &WindowBatch,
        steps: usize,
        lr: f64,
        stop: f32,
    ) -> (PolicyModel, f32, f32, usize) {
        use burn::grad_clipping::GradientClippingConfig;
        use burn::optim::{AdamWConfig, GradientsParams};
        let mut optim = AdamWConfig::new()
            .with_weight_decay(0.0)
            .with_grad_clipping(Some(GradientClippingConfig::Norm(1.0)))
            .init();
        let mut first = None;
        let mut last = f32::INFINITY;
        for step in 0..steps {
            let (_, losses) = model.forward(x).unwrap();
            let act = scalar(losses.action.clone());
            let initial = *first.get_or_insert(act);
            last = act;
            if act < stop * initial {
                return (model, initial, last, step);
            }
            let grads = GradientsParams::from_grads(losses.total.backward(), &model);
            model = optim.step(lr, model, grads);
        }
        (model, first.unwrap_or(last), last, steps)
    }

    #[test]
    fn tiny_model_overfits_one_batch() {
        let (_guard, device) = test_autodiff_device();
        device.seed(3);
        let cfg = micro("e_slotssm");
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let x = batch(&cfg, 2, 4, &device);
        // Fitted to 5 % of the first L_act, so that the streamed error of one sample (the
        // batch's mean hides how its two samples split) stays below 10 %.
        let (model, initial, last, steps) = fit_one_batch(model, &x, 400, 1e-3, 0.05);
        eprintln!("overfit: L_act {initial:.4} → {last:.4} in {steps} steps");
        assert!(last < 0.05 * initial, "L_act {initial} → {last}");

        // The trained weights act through the streaming policy too (autodiff device given).
        let plain = Device::flex();
        let instr = Tokenizer::new(&cfg.text).encode_batch(&[INSTRUCTIONS[0]], &plain);
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        let mut err = 0.0;
        for t in 0..4 {
            let img = x
                .obs
                .pixels()
                .unwrap()
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

    /// State frames of `feats` `[B, T, K, F]` whose first `objects` tokens are objects, one of
    /// category 4 at a place that varies by window and the others distractors of category 3, and
    /// the rest padding; with the features of the category-4 token `[B, T, 1, F]`.
    fn one_of_category_4(feats: Tensor<4>, objects: usize) -> (Frames, Tensor<4>) {
        let [b, t, k, _] = feats.dims();
        let place: Vec<usize> = (0..b).map(|i| (i * 3 + 1) % objects).collect();
        let mut cats = vec![crate::io::state::PAD; b * t * k];
        for (i, &p) in place.iter().enumerate() {
            for j in 0..t {
                let frame = &mut cats[(i * t + j) * k..][..k];
                frame[..objects].fill(3);
                frame[p] = 4;
            }
        }
        let picked: Vec<Tensor<4>> = place
            .iter()
            .enumerate()
            .map(|(i, &p)| feats.clone().narrow(0, i, 1).narrow(2, p, 1))
            .collect();
        let device = feats.device();
        let cats = Tensor::from_data(TensorData::new(cats, [b, t, k]), &device);
        (Frames::State(feats, cats), Tensor::cat(picked, 0))
    }

    /// State mode learns actions that only the object tokens explain (not the text).
    #[test]
    fn state_model_learns_from_the_object_tokens() {
        use crate::io::state::FEATURES;
        let (_guard, device) = test_autodiff_device();
        device.seed(5);
        for variant in ["e_slotssm_oracle", "slotvla_h1"] {
            let cfg = micro(variant).with_state(4, 6, FEATURES);
            let model = PolicyModel::new(&cfg, &device).unwrap();
            let (b, t) = (4, 4);
            let mut x = batch(&cfg, b, t, &device);
            let feats =
                Tensor::<4>::random([b, t, 4, FEATURES], Distribution::Normal(0.0, 2.0), &device);
            // Target: feature a of the one token of category 4, at a random place per window
            // (the others are distractors of category 3): the model has to find it.
            let (obs, picked) = one_of_category_4(feats, 4);
            let target = picked
                .narrow(3, 0, 7)
                .mul_scalar(0.5)
                .tanh()
                .reshape([b, t, 1, 7])
                .repeat_dim(2, cfg.decoder.horizon);
            x.obs = obs;
            x.actions = target;
            x.subgoal = variant
                .ends_with("oracle")
                .then(|| Tensor::ones([b, t, 4, cfg.text.max_len], &device).into());
            let (_, initial, last, _) = fit_one_batch(model, &x, 300, 2e-3, 0.0);
            eprintln!("{variant}: L_act {initial} → {last}");
            assert!(last < 0.3 * initial, "{variant}: L_act {initial} → {last}");
        }
    }

    /// A micro state-mode config with the pointer head (step queries, L1 head) over `tokens`
    /// tokens of which the categories 3 and 4 are objects.
    fn pointer_config(variant: &str, tokens: usize) -> ModelConfig {
        let mut cfg = micro(variant).with_state(tokens, 6, crate::io::state::FEATURES);
        cfg.decoder.queries = crate::config::QueryLayout::Step;
        cfg.decoder.pointer = true;
        cfg
    }

    /// Random state frames `[B, T, K, F]` whose last token of every frame is padding (zeros,
    /// category PAD) and the others objects of category 3 or 4.
    fn state_frames(b: usize, t: usize, k: usize, device: &Device) -> Frames {
        use crate::io::state::{FEATURES, PAD};
        let feats =
            Tensor::<4>::random([b, t, k, FEATURES], Distribution::Normal(0.0, 1.0), device);
        let cats: Vec<i64> = (0..b * t * k)
            .map(|i| match i % k {
                j if j == k - 1 => PAD,
                j => 3 + (j % 2) as i64,
            })
            .collect();
        let keep = Tensor::<4>::ones([b, t, k - 1, FEATURES], device);
        let keep = Tensor::cat(vec![keep, Tensor::zeros([b, t, 1, FEATURES], device)], 2);
        Frames::State(
            feats * keep,
            Tensor::from_data(TensorData::new(cats, [b, t, k]), device),
        )
    }

    #[test]
    fn pointer_needs_state_step_queries_and_the_l1_head() {
        let (_guard, device) = test_device();
        let ok = pointer_config("e_slotssm_oracle", 4);
        ok.validate().unwrap();
        let mut pixels = micro("e_slotssm_oracle");
        pixels.decoder.queries = crate::config::QueryLayout::Step;
        pixels.decoder.pointer = true;
        pixels.validate().unwrap();
        let e = PolicyModel::new(&pixels, &device).unwrap_err().to_string();
        assert!(e.contains("decoder.pointer: only state mode"), "{e}");
        let mut value = ok.clone();
        value.decoder.queries = crate::config::QueryLayout::Value;
        let mut bins = ok.clone();
        bins.decoder.head = ActionHead::Bins;
        for bad in [value, bins] {
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains("decoder.pointer needs a continuous head"), "{e}");
        }
        // Configs written before it read as without.
        let mut json = serde_json::to_value(&ok.decoder).unwrap();
        json.as_object_mut().unwrap().remove("pointer");
        json.as_object_mut().unwrap().remove("pointer_input_keys");
        let old: crate::config::DecoderConfig = serde_json::from_value(json).unwrap();
        assert!(!old.pointer && !old.pointer_input_keys);
        // Its input keys and its loss need the head.
        let mut keys = micro("e_slotssm_oracle");
        keys.decoder.pointer_input_keys = true;
        let e = keys.validate().unwrap_err().to_string();
        assert!(
            e.contains("decoder.pointer_input_keys needs decoder.pointer"),
            "{e}"
        );
        let mut loss = micro("e_slotssm_oracle");
        loss.loss.pointer = 1.0;
        let e = loss.validate().unwrap_err().to_string();
        assert!(e.contains("loss.pointer > 0 needs the pointer head"), "{e}");
        let mut nan = ok.clone();
        nan.loss.pointer = f64::NAN;
        let e = nan.validate().unwrap_err().to_string();
        assert!(e.contains("loss.pointer must be a finite number"), "{e}");
    }

    /// With input keys, the weights read the tokens' own numbers: with the decoder's keys and
    /// the queries' map at zero, a key map on one input number makes the token with the largest
    /// such number win.
    #[test]
    fn pointer_input_keys_score_the_tokens_own_numbers() {
        let (_guard, device) = test_device();
        device.seed(9);
        let (n, h, k, w, f, a) = (2, 3, 4, 8, 15, 7);
        let mut head = PointerHead::new(w, f, a, true, &device);
        let queries = Tensor::<3>::ones([n, h, w], &device);
        let tokens = Tensor::<3>::random([n, k, w], Distribution::Normal(0.0, 1.0), &device);
        let features = Tensor::<3>::random([n, k, f], Distribution::Normal(0.0, 1.0), &device);
        let pad =
            Tensor::<2, Bool>::from_data(TensorData::new(vec![false; n * k], [n, k]), &device);
        head.query.weight = burn::module::Param::from_tensor(Tensor::eye(w, &device));
        head.query.bias = None;
        head.key.weight = burn::module::Param::from_tensor(Tensor::zeros([w, w], &device));
        head.key.bias = None;
        // Key = 100 · feature 3 along every width: score ∝ feature 3.
        let mut map = vec![0.0f32; f * w];
        map[3 * w..4 * w].fill(100.0);
        let input_key = head.input_key.as_mut().expect("input keys");
        input_key.weight = burn::module::Param::from_tensor(Tensor::from_data(
            TensorData::new(map, [f, w]),
            &device,
        ));
        input_key.bias = None;
        let wts = head.weights(queries, tokens, features.clone(), pad);
        let best = features.narrow(2, 3, 1).argmax(1).reshape([n, 1]); // [N, 1]
        let picked = wts.argmax(2).reshape([n, h]);
        let want = best.repeat_dim(1, h);
        let ints = |x: Tensor<2, Int>| x.into_data().iter::<i64>().collect::<Vec<_>>();
        assert_eq!(ints(picked), ints(want));
    }

    /// The pointer's weights are a distribution over the unpadded tokens, and its term is their
    /// weighted value: with one token's key made dominant, the term is that token's value.
    #[test]
    fn pointer_weights_skip_padding_and_pick_by_key() {
        let (_guard, device) = test_device();
        device.seed(4);
        let (n, h, k, w, f, a) = (3, 2, 5, 8, 15, 7);
        let mut head = PointerHead::new(w, f, a, false, &device);
        let queries = Tensor::<3>::random([n, h, w], Distribution::Normal(0.0, 1.0), &device);
        let tokens = Tensor::<3>::random([n, k, w], Distribution::Normal(0.0, 1.0), &device);
        let features = Tensor::<3>::random([n, k, f], Distribution::Normal(0.0, 1.0), &device);
        let pad: Vec<bool> = (0..n * k).map(|i| i % k == 0 || i == k + 3).collect();
        let pad = Tensor::<2, Bool>::from_data(TensorData::new(pad.clone(), [n, k]), &device);
        let wts = head.weights(
            queries.clone(),
            tokens.clone(),
            features.clone(),
            pad.clone(),
        );
        assert_eq!(wts.dims(), [n, h, k]);
        let v = wts.clone().into_data().try_to_vec::<f32>().unwrap();
        for row in v.chunks(k) {
            assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-5, "{row:?}");
        }
        for (i, x) in v.iter().enumerate() {
            let (lane, tok) = (i / (h * k), i % k);
            if tok == 0 || (lane == 1 && tok == 3) {
                assert!(*x < 1e-12, "padding token {tok} of lane {lane} weighs {x}");
            }
        }
        // Zero-initialised values: no term at first.
        let term = head.term(wts, features.clone());
        assert_eq!(term.dims(), [n, h, a]);
        assert_eq!(term.clone().abs().max().into_scalar::<f32>(), 0.0);
        // Identity values on the first 7 numbers; every query and token 2 (after the norm) along
        // one direction, keys scaled up: the weight goes to token 2.
        let eye = Tensor::<2>::eye(f, &device).narrow(1, 0, a);
        head.value.weight = burn::module::Param::from_tensor(eye);
        head.query.weight = burn::module::Param::from_tensor(Tensor::eye(w, &device));
        head.key.weight = burn::module::Param::from_tensor(Tensor::eye(w, &device).mul_scalar(1e3));
        let sign: Vec<f32> = (0..w)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let dir = Tensor::<1>::from_floats(sign.as_slice(), &device).reshape([1, 1, w]);
        let q = dir.clone().repeat_dim(0, n).repeat_dim(1, h);
        let toks = tokens.slice_assign([0..n, 2..3, 0..w], dir.repeat_dim(0, n));
        let wts = head.weights(q, toks, features.clone(), pad);
        let term = head.term(wts, features.clone());
        let want = features.narrow(1, 2, 1).narrow(2, 0, a).repeat_dim(1, h);
        let diff = (term - want).abs().max().into_scalar::<f32>();
        assert!(diff < 1e-3, "max diff {diff}");
    }

    /// With the pointer head, streaming state frames one by one gives the window's actions.
    #[test]
    fn pointer_streaming_equals_window() {
        let (_guard, device) = test_device();
        device.seed(6);
        for variant in ["e_slotssm_oracle", "slotvla_h3"] {
            let cfg = pointer_config(variant, 5);
            let mut model = PolicyModel::new(&cfg, &device).unwrap();
            let p = model.pointer.as_mut().unwrap();
            let [f, a] = p.value.weight.dims();
            p.value.weight = burn::module::Param::from_tensor(Tensor::random(
                [f, a],
                Distribution::Normal(0.0, 0.5),
                &device,
            ));
            let frames = 6;
            let obs = state_frames(1, frames, 5, &device);
            let tok = Tokenizer::new(&cfg.text);
            let instr = tok.encode_batch(&[INSTRUCTIONS[0]], &device);
            let subgoal = cfg
                .variant
                .needs_subgoal_text()
                .then(|| Tensor::<4, Int>::ones([1, frames, 5, cfg.text.max_len], &device));
            let full = model
                .predict(obs.clone(), instr.clone(), subgoal.clone().map(Into::into))
                .unwrap()
                .actions;
            let without = {
                let mut m = model.clone();
                m.pointer = None;
                m.predict(obs.clone(), instr.clone(), subgoal.clone().map(Into::into))
                    .unwrap()
                    .actions
            };
            let effect = (full.clone() - without).abs().max().into_scalar::<f32>();
            assert!(effect > 1e-2, "{variant}: the pointer adds only {effect}");
            let mut policy = StreamingPolicy::new(model, &device).unwrap();
            let mut worst = 0.0f32;
            for t in 0..frames {
                let sg = subgoal
                    .clone()
                    .map(|s| Subgoal::from(s.narrow(1, t, 1).squeeze_dim::<3>(1)));
                let chunk = policy
                    .act_frames(obs.narrow(t, 1), instr.clone(), sg)
                    .unwrap();
                let want = full.clone().narrow(1, t, 1).reshape(chunk.dims());
                worst = worst.max((chunk - want).abs().max().into_scalar::<f32>());
            }
            assert!(worst < 1e-4, "{variant}: max diff {worst}");
        }
    }

    /// The pointer head learns to move to "the token of category 4" among distractors: the
    /// target is a linear map of that token's numbers, at a random place per window.
    #[test]
    fn pointer_learns_to_pick_the_token() {
        let (_guard, device) = test_autodiff_device();
        device.seed(7);
        let (b, t, k) = (4, 4, 5);
        let cfg = pointer_config("e_slotssm_oracle", k);
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let mut x = batch(&cfg, b, t, &device);
        let Frames::State(feats, _) = state_frames(b, t, k, &device) else {
            unreachable!()
        };
        let (obs, picked) = one_of_category_4(feats, k - 1);
        x.actions = picked
            .narrow(3, 0, 7)
            .mul_scalar(0.4)
            .reshape([b, t, 1, 7])
            .repeat_dim(2, cfg.decoder.horizon);
        x.obs = obs;
        x.subgoal = Some(Tensor::<4, Int>::ones([b, t, k, cfg.text.max_len], &device).into());
        let (_, initial, last, _) = fit_one_batch(model, &x, 300, 2e-3, 0.0);
        eprintln!("pointer: L_act {initial} → {last}");
        assert!(last < 0.2 * initial, "L_act {initial} → {last}");
    }

    /// The pointer loss alone draws the weights to the target token (the category-4 one among
    /// distractors), with no action loss at all; frames without a target add nothing.
    #[test]
    fn pointer_loss_draws_the_weights_to_the_target() {
        use burn::optim::{AdamWConfig, GradientsParams};
        let (_guard, device) = test_autodiff_device();
        device.seed(8);
        let (b, t, k) = (4, 4, 5);
        let mut cfg = pointer_config("e_slotssm_oracle", k);
        cfg.loss.action = 0.0;
        cfg.loss.pointer = 1.0;
        let mut model = PolicyModel::new(&cfg, &device).unwrap();
        let mut x = batch(&cfg, b, t, &device);
        let Frames::State(feats, _) = state_frames(b, t, k, &device) else {
            unreachable!()
        };
        let (obs, _) = one_of_category_4(feats, k - 1);
        let Frames::State(_, cats) = &obs else {
            unreachable!()
        };
        // Every frame targets its category-4 token, except frame 0 of window 0 (none) and the
        // batch's padding frame (the last of the last window), which the loss leaves out anyway.
        let mut keep = vec![1.0f32; b * t];
        keep[0] = 0.0;
        keep[b * t - 1] = 0.0;
        let keep = Tensor::<3>::from_data(TensorData::new(keep, [b, t, 1]), &device);
        let target = cats.clone().equal_elem(4).float() * keep;
        x.obs = obs;
        x.subgoal = Some(Tensor::<4, Int>::ones([b, t, k, cfg.text.max_len], &device).into());
        x.pointer_target = Some(target.clone());
        let mass = |model: &PolicyModel| -> f32 {
            let (out, losses) = model.forward(&x).unwrap();
            let w = out.pointer.expect("the pointer's weights");
            assert_eq!(w.dims(), [b, t, cfg.decoder.horizon, k]);
            // L_ptr is the mean −log weight of the targets over the targeted frames' steps.
            let want = -(w.clone().clamp_min(1e-9).log() * target.clone().reshape([b, t, 1, k]))
                .sum()
                .into_scalar::<f32>()
                / ((b * t - 2) * cfg.decoder.horizon) as f32;
            let got = scalar(losses.pointer.clone().expect("L_ptr"));
            assert!((got - want).abs() < 1e-4 * want.max(1.0), "{got} vs {want}");
            // The mean weight of the targets.
            (w * target.clone().reshape([b, t, 1, k]))
                .sum()
                .into_scalar::<f32>()
                / ((b * t - 2) * cfg.decoder.horizon) as f32
        };
        let before = mass(&model);
        let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
        for _ in 0..60 {
            let (_, losses) = model.forward(&x).unwrap();
            let grads = GradientsParams::from_grads(losses.total.backward(), &model);
            model = optim.step(2e-3, model, grads);
        }
        let after = mass(&model);
        eprintln!("pointer loss: target weight {before} → {after}");
        assert!(
            before < 0.5 && after > 0.9,
            "target weight {before} → {after}"
        );
        // Without targets the loss is absent.
        x.pointer_target = None;
        assert!(model.forward(&x).unwrap().1.pointer.is_none());
    }
}
