//! The streaming policy (model.md §10): `reset()`, then `act(observation, instruction, subgoal)`
//! once per environment step. The carried state has a constant size for `e_slotssm` (slots,
//! SSM states, a step counter); SlotVLA(h)/dense(h) keep their last h frames of tokens, which is
//! what those baselines are.

use std::collections::VecDeque;

use burn::prelude::*;

use crate::config::Variant;
use crate::error::{ModelError, Result};
use crate::policy::PolicyModel;
use crate::slot_ssm::SlotSsmState;
use crate::text::Tokenizer;

/// One environment observation: an upright RGB image (row 0 = top), optionally more.
#[derive(Clone, Copy, Debug)]
pub struct Observation<'a> {
    /// Agentview RGB, `height · width · 3` bytes, row-major.
    pub rgb: &'a [u8],
    /// Image height.
    pub height: usize,
    /// Image width.
    pub width: usize,
    /// Eye-in-hand RGB of the same layout (not used by the current variants).
    pub wrist_rgb: Option<&'a [u8]>,
    /// Proprio state, 8-D (not used by the current variants).
    pub state: Option<[f32; 8]>,
}

/// Per-dimension action statistics for BOUNDS_Q99 un-normalisation (model.md §8).
#[derive(Clone, Debug, PartialEq)]
pub struct ActionStats {
    /// 1st percentiles, one per dimension.
    pub q01: [f32; 7],
    /// 99th percentiles, one per dimension.
    pub q99: [f32; 7],
}

impl ActionStats {
    /// ā = clip(2(a − q01)/(q99 − q01 + 1e-8) − 1, −1, 1) for dims 0–5; the gripper is left as is.
    pub fn normalize(&self, a: [f32; 7]) -> [f32; 7] {
        let mut out = a;
        for i in 0..6 {
            let v = 2.0 * (a[i] - self.q01[i]) / (self.q99[i] - self.q01[i] + 1e-8) - 1.0;
            out[i] = v.clamp(-1.0, 1.0);
        }
        out
    }

    /// a = (ā + 1)/2 · (q99 − q01) + q01 for dims 0–5; the gripper (dim 6) is left as is.
    pub fn unnormalize(&self, a: [f32; 7]) -> [f32; 7] {
        let mut out = a;
        for i in 0..6 {
            out[i] = (a[i] + 1.0) * 0.5 * (self.q99[i] - self.q01[i]) + self.q01[i];
        }
        out
    }
}

/// Converts an RGB byte image to a `[1, 3, H, W]` tensor in [0, 1], bilinearly resized
/// (half-pixel centres) when the size differs.
///
/// # Shapes
/// - output: `[1, 3, size[0], size[1]]`
pub fn image_tensor(obs: &Observation, size: [usize; 2], device: &Device) -> Result<Tensor<4>> {
    let (sh, sw) = (obs.height, obs.width);
    if sh == 0 || sw == 0 || obs.rgb.len() != sh * sw * 3 {
        return Err(ModelError::Input(format!(
            "rgb has {} bytes, expected {sh}·{sw}·3",
            obs.rgb.len()
        )));
    }
    let [dh, dw] = size;
    let px = |y: usize, x: usize, c: usize| obs.rgb[(y * sw + x) * 3 + c] as f32 / 255.0;
    let mut data = vec![0.0f32; 3 * dh * dw];
    let coord = |i: usize, dst: usize, src: usize| -> (usize, usize, f32) {
        let f = ((i as f32 + 0.5) * src as f32 / dst as f32 - 0.5).clamp(0.0, (src - 1) as f32);
        let i0 = f.floor() as usize;
        let i1 = (i0 + 1).min(src - 1);
        (i0, i1, f - i0 as f32)
    };
    for y in 0..dh {
        let (y0, y1, fy) = coord(y, dh, sh);
        for x in 0..dw {
            let (x0, x1, fx) = coord(x, dw, sw);
            for c in 0..3 {
                let top = px(y0, x0, c) * (1.0 - fx) + px(y0, x1, c) * fx;
                let bot = px(y1, x0, c) * (1.0 - fx) + px(y1, x1, c) * fx;
                data[(c * dh + y) * dw + x] = top * (1.0 - fy) + bot * fy;
            }
        }
    }
    Ok(Tensor::from_data(
        TensorData::new(data, [1, 3, dh, dw]),
        device,
    ))
}

/// The state carried from step to step.
#[derive(Clone, Debug, Default)]
struct StreamState {
    /// Steps taken since the last reset.
    step: usize,
    /// Slots of the previous frame `[1, K, D]`.
    slots: Option<Tensor<3>>,
    /// SlotSSM state.
    ssm: Option<SlotSsmState>,
    /// Decoder tokens of the last h frames, oldest first, each `[1, V₁, D_dec]` (h > 1 only).
    history: VecDeque<Tensor<3>>,
    /// Slot-attention masks of the latest frame `[1, K, M]` (slot variants).
    masks: Option<Tensor<3>>,
}

/// A policy used step by step; its state lives inside and is reset per episode.
#[derive(Clone, Debug)]
pub struct StreamingPolicy {
    model: PolicyModel,
    tokenizer: Tokenizer,
    device: Device,
    stats: Option<ActionStats>,
    state: StreamState,
}

impl StreamingPolicy {
    /// Wraps a trained model (its weights are used as they are, without autodiff; an autodiff
    /// `device` is used without it too).
    pub fn new(model: PolicyModel, device: &Device) -> Result<Self> {
        if model.config.decoder.action_dim != 7 {
            return Err(ModelError::Config(
                "the streaming policy returns 7-D actions".into(),
            ));
        }
        let tokenizer = Tokenizer::new(&model.config.text);
        Ok(StreamingPolicy {
            model: model.valid(),
            tokenizer,
            device: device.clone().without_autodiff(),
            stats: None,
            state: StreamState::default(),
        })
    }

    /// Un-normalise returned actions with these statistics (else they stay in [−1, 1]).
    pub fn with_action_stats(mut self, stats: ActionStats) -> Self {
        self.stats = Some(stats);
        self
    }

    /// The wrapped model.
    pub fn model(&self) -> &PolicyModel {
        &self.model
    }

    /// Starts a new episode: forgets slots, SSM states and history.
    pub fn reset(&mut self) {
        self.state = StreamState::default();
    }

    /// Steps taken since the last reset.
    pub fn step_count(&self) -> usize {
        self.state.step
    }

    /// The slot-attention masks of the latest frame, `[K][M]` with M = the encoder's token grid
    /// (row-major, `rows × cols` of the feature map); `None` before the first step or for the
    /// dense variant. Each token's weights sum to 1 over the slots.
    pub fn last_masks(&self) -> Option<Vec<Vec<f32>>> {
        let m = self.state.masks.as_ref()?;
        let [_, k, n] = m.dims();
        let v = m.clone().into_data().try_to_vec::<f32>().ok()?;
        Some((0..k).map(|i| v[i * n..(i + 1) * n].to_vec()).collect())
    }

    /// Floats held in the carried state now (slots + SSM states + history tokens).
    pub fn state_floats(&self) -> usize {
        let s = &self.state;
        s.slots.as_ref().map_or(0, |t| t.shape().num_elements())
            + s.ssm.as_ref().map_or(0, SlotSsmState::num_floats)
            + s.history
                .iter()
                .map(|t| t.shape().num_elements())
                .sum::<usize>()
    }

    /// One step: returns the action chunk `[H_a][7]` predicted for this frame.
    ///
    /// Call it at every environment step (also while executing an earlier chunk open-loop):
    /// the slots and SSM state must see every frame, as in training.
    pub fn act(
        &mut self,
        obs: &Observation,
        instruction: &str,
        subgoal: Option<&str>,
    ) -> Result<Vec<[f32; 7]>> {
        let image = image_tensor(obs, self.model.config.image_size, &self.device)?;
        let instruction = self.tokenizer.encode_batch(&[instruction], &self.device);
        let subgoal = subgoal.map(|s| {
            self.tokenizer
                .encode_batch(&[s], &self.device)
                .unsqueeze_dim::<3>(1)
        });
        let chunk = self.act_tensor(image, instruction, subgoal)?;
        let [h, a] = chunk.dims();
        let data = chunk
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| ModelError::Input(format!("action chunk: {e:?}")))?;
        Ok((0..h)
            .map(|i| {
                let mut row = [0.0f32; 7];
                row.copy_from_slice(&data[i * a..(i + 1) * a]);
                match &self.stats {
                    Some(s) => s.unnormalize(row),
                    None => row,
                }
            })
            .collect())
    }

    /// Updates the memory with a frame without decoding actions (e.g. while executing an earlier
    /// chunk open-loop): cheaper than [`StreamingPolicy::act`], same state afterwards.
    pub fn observe(&mut self, obs: &Observation, subgoal: Option<&str>) -> Result<()> {
        let image = image_tensor(obs, self.model.config.image_size, &self.device)?;
        let subgoal = subgoal.map(|s| {
            self.tokenizer
                .encode_batch(&[s], &self.device)
                .unsqueeze_dim::<3>(1)
        });
        self.observe_tensor(image, subgoal)
    }

    /// [`StreamingPolicy::observe`] on tensors.
    ///
    /// # Shapes
    /// - image: `[1, 3, H, W]` in [0, 1]; subgoal: `[1, G, L_sg]`
    pub fn observe_tensor(
        &mut self,
        image: Tensor<4>,
        subgoal: Option<Tensor<3, Int>>,
    ) -> Result<()> {
        self.advance(image, subgoal).map(|_| ())
    }

    /// One step on tensors (normalised actions).
    ///
    /// # Shapes
    /// - image: `[1, 3, H, W]` in [0, 1]; instruction: `[1, L_txt]`; subgoal: `[1, G, L_sg]`
    /// - output: `[H_a, A]`
    pub fn act_tensor(
        &mut self,
        image: Tensor<4>,
        instruction: Tensor<2, Int>,
        subgoal: Option<Tensor<3, Int>>,
    ) -> Result<Tensor<2>> {
        let tokens = self.advance(image, subgoal)?;
        let m = &self.model;
        let visual = if m.config.variant.history() > 1 {
            m.stack_history(self.state.history.iter().cloned().collect())
        } else {
            tokens
        };
        let out = m.decode(visual, None, instruction);
        let [_, ha, a] = out.actions.dims();
        Ok(out.actions.reshape([ha, a]))
    }

    /// Runs everything but the decoder on one frame and updates the carried state.
    ///
    /// # Shapes
    /// - image: `[1, 3, H, W]`; subgoal: `[1, G, L_sg]`
    /// - output: this frame's decoder tokens `[1, V₁, D_dec]`
    fn advance(&mut self, image: Tensor<4>, subgoal: Option<Tensor<3, Int>>) -> Result<Tensor<3>> {
        let m = &self.model;
        let cfg = &m.config;
        let [h, w] = cfg.image_size;
        if image.dims() != [1, 3, h, w] {
            return Err(ModelError::Input(format!(
                "image {:?}, expected [1, 3, {h}, {w}]",
                image.dims()
            )));
        }
        let feats = m.encoder.forward_frames(image); // [1, M, D_f]
        let z = match &m.slot_attention {
            Some(sa) => {
                let (slots, masks) = sa.step(feats.clone(), self.state.slots.take());
                self.state.slots = Some(slots.clone());
                self.state.masks = Some(masks);
                Some(match (&m.slot_ssm, &m.fusion) {
                    (Some(ssm), Some(fusion)) => {
                        let k = cfg.slots.num_slots;
                        let state = self
                            .state
                            .ssm
                            .take()
                            .unwrap_or_else(|| ssm.zero_state(1, k, &self.device));
                        let ssm_feats = cfg.ssm.cross_attention.then(|| feats.clone());
                        let (pred, state) = ssm.step(slots.clone(), ssm_feats, state);
                        self.state.ssm = Some(state);
                        let g = m.subgoal_embedding(subgoal, 1, &self.device)?;
                        fusion.forward(slots, pred, g)
                    }
                    _ => m
                        .slot_proj
                        .as_ref()
                        .expect("SlotVLA has a slot projection")
                        .forward(slots),
                })
            }
            None => None,
        };
        let tokens = m.frame_tokens(feats, z);
        let history = cfg.variant.history();
        if history > 1 {
            self.state.history.push_back(tokens.clone());
            while self.state.history.len() > history {
                self.state.history.pop_front();
            }
        }
        self.state.step += 1;
        Ok(tokens)
    }

    /// Whether the carried state of this variant stays the same size for any episode length.
    pub fn has_constant_state(&self) -> bool {
        matches!(self.model.config.variant, Variant::ESlotSsm { .. })
            || self.model.config.variant.history() == 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ModelConfig;
    use crate::test_device;
    use burn::tensor::Distribution;

    #[test]
    fn image_tensor_keeps_same_size_and_averages_when_halving() {
        let (_guard, device) = test_device();
        // 2×2 image: red, green / blue, white.
        let rgb = [255u8, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255];
        let obs = Observation {
            rgb: &rgb,
            height: 2,
            width: 2,
            wrist_rgb: None,
            state: None,
        };
        let same = image_tensor(&obs, [2, 2], &device).unwrap();
        let v = same.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(
            v,
            vec![1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0]
        );
        let half = image_tensor(&obs, [1, 1], &device).unwrap();
        let v = half.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(v, vec![0.5, 0.5, 0.5]);
        let bad = Observation { height: 3, ..obs };
        assert!(image_tensor(&bad, [2, 2], &device).is_err());
    }

    #[test]
    fn normalization_round_trips_clips_and_leaves_the_gripper() {
        let stats = ActionStats {
            q01: [-2.0; 7],
            q99: [2.0; 7],
        };
        let a = stats.unnormalize([1.0, -1.0, 0.0, 0.5, 0.0, 0.0, -1.0]);
        assert_eq!(a, [2.0, -2.0, 0.0, 1.0, 0.0, 0.0, -1.0]);
        let n = stats.normalize([2.0, -2.0, 0.0, 1.0, 9.0, -9.0, 1.0]);
        let want = [1.0, -1.0, 0.0, 0.5, 1.0, -1.0, 1.0];
        for (x, y) in n.iter().zip(want) {
            assert!((x - y).abs() < 1e-6, "{n:?}");
        }
    }

    #[test]
    fn act_returns_a_chunk_and_counts_steps() {
        let (_guard, device) = test_device();
        let cfg = ModelConfig::tiny(Variant::ESlotSsm {
            oracle_subgoal: true,
        })
        .with_vocab_from(["put the bowl on the plate"]);
        let model = PolicyModel::new(&cfg, &device).unwrap();
        let mut policy = StreamingPolicy::new(model, &device).unwrap();
        let img = Tensor::<1>::random([128 * 128 * 3], Distribution::Uniform(0.0, 255.0), &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
            .into_iter()
            .map(|v| v as u8)
            .collect::<Vec<_>>();
        let obs = Observation {
            rgb: &img,
            height: 128,
            width: 128,
            wrist_rgb: None,
            state: None,
        };
        let chunk = policy
            .act(&obs, "put the bowl on the plate", Some("bowl"))
            .unwrap();
        assert_eq!(chunk.len(), 4);
        let floats = policy.state_floats();
        assert_eq!(floats, cfg.constant_state_floats());
        let masks = policy.last_masks().expect("slot variant keeps masks");
        assert_eq!(masks.len(), cfg.slots.num_slots);
        let m = masks[0].len();
        for j in 0..m {
            let total: f32 = masks.iter().map(|row| row[j]).sum();
            assert!((total - 1.0).abs() < 1e-4, "token {j}: {total}");
        }
        policy.act(&obs, "put the bowl on the plate", None).unwrap();
        policy.observe(&obs, Some("bowl")).unwrap();
        assert_eq!(policy.step_count(), 3);
        assert_eq!(policy.state_floats(), floats);
        policy.reset();
        assert_eq!(policy.step_count(), 0);
        assert_eq!(policy.state_floats(), 0);
    }
}
