//! The streaming policy (model.md §10): `reset()`, then `act_input(step input)` once per
//! environment step, with inputs from [`crate::io::Processor::step`]. The carried state has a constant size for `e_slotssm` (slots,
//! SSM states, a step counter); SlotVLA(h)/dense(h) keep their last h frames of tokens, which is
//! what those baselines are.

use burn::prelude::*;

use crate::config::Variant;
use crate::encoder::Frames;
use crate::error::{ModelError, Result};
use crate::io::StepInput;
use crate::policy::PolicyModel;
use crate::variants::{Memory, Shared, Subgoal};

/// The state carried from step to step.
#[derive(Clone, Debug, Default)]
struct StreamState {
    /// Steps taken since the last reset.
    step: usize,
    /// The variant's memory (slots, SSM state, history tokens).
    memory: Memory,
    /// The latest frame's visual tokens `[1, V, D_dec]`, kept for the progress head (models
    /// trained with the progress loss; read on demand, off the step's path).
    last_tokens: Option<Tensor<3>>,
    /// The termination head's logit at the latest decoded step `[1]` (models trained with the
    /// termination loss).
    last_done: Option<Tensor<1>>,
}

/// A policy used step by step; its state lives inside and is reset per episode.
#[derive(Clone, Debug)]
pub struct StreamingPolicy {
    model: PolicyModel,
    device: Device,
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
        Ok(StreamingPolicy {
            model: model.valid(),
            device: device.clone().without_autodiff(),
            state: StreamState::default(),
        })
    }

    /// The device the policy computes on (without autodiff): build its inputs there.
    pub fn device(&self) -> &Device {
        &self.device
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
        let m = self.state.memory.masks.as_ref()?;
        let [_, k, n] = m.dims();
        let v = m.clone().into_data().try_to_vec::<f32>().ok()?;
        Some((0..k).map(|i| v[i * n..(i + 1) * n].to_vec()).collect())
    }

    /// What the progress head (models trained with `loss.progress` > 0) reads off the latest
    /// frame's tokens: its probability of each number of subgoals done, `[C]`; `None` before the
    /// first step or without the head. A diagnostic of what the memory keeps; actions do not
    /// depend on it.
    pub fn last_progress(&self) -> Result<Option<Vec<f32>>> {
        let (Some(head), Some(tokens)) = (&self.model.progress, &self.state.last_tokens) else {
            return Ok(None);
        };
        // As in training, over the frame's tokens (a streamed history holds only frames seen,
        // so nothing is padding).
        burn::tensor::activation::softmax(head.forward(tokens.clone(), None), 1)
            .into_data()
            .try_to_vec::<f32>()
            .map(Some)
            .map_err(|e| ModelError::Input(format!("progress head: {e:?}")))
    }

    /// The termination head's probability that the goal is done, read off the latest decoded
    /// step's action queries (models trained with `loss.done` > 0); `None` before the first
    /// decoded step or without the head.
    pub fn last_done(&self) -> Result<Option<f32>> {
        let Some(logit) = &self.state.last_done else {
            return Ok(None);
        };
        burn::tensor::activation::sigmoid(logit.clone())
            .try_into_scalar::<f32>()
            .map(Some)
            .map_err(|e| ModelError::Input(format!("termination head: {e:?}")))
    }

    /// Whether the model has a termination head.
    pub fn has_done_head(&self) -> bool {
        self.model.done.is_some()
    }

    /// Floats held in the carried state now (slots + SSM states + history tokens).
    pub fn state_floats(&self) -> usize {
        self.state.memory.num_floats()
    }

    /// One step: the normalised action chunk `[H_a][A]` predicted for this frame (un-normalise
    /// with [`crate::io::Processor::unnormalize`]).
    ///
    /// Call it at every environment step (also while executing an earlier chunk open-loop):
    /// the slots and SSM state must see every frame, as in training.
    pub fn act_input(&mut self, input: StepInput) -> Result<Vec<Vec<f32>>> {
        let chunk = self.act_frames(input.obs, input.instruction, input.subgoal)?;
        let [h, a] = chunk.dims();
        let data = chunk
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| ModelError::Input(format!("action chunk: {e:?}")))?;
        Ok((0..h).map(|i| data[i * a..(i + 1) * a].to_vec()).collect())
    }

    /// Updates the memory with a frame without decoding actions (e.g. while executing an earlier
    /// chunk open-loop): cheaper than [`StreamingPolicy::act_input`], same state afterwards.
    pub fn observe_input(&mut self, input: StepInput) -> Result<()> {
        self.advance(input.obs, input.subgoal).map(|_| ())
    }

    /// [`StreamingPolicy::observe_input`] on tensors.
    ///
    /// # Shapes
    /// - image: `[1, 3, H, W]` in [0, 1]; subgoal: `[1, G, L_sg]`
    pub fn observe_tensor(
        &mut self,
        image: Tensor<4>,
        subgoal: Option<Tensor<3, Int>>,
    ) -> Result<()> {
        self.advance(
            Frames::Pixels(image.unsqueeze_dim(1)),
            subgoal.map(Subgoal::from),
        )
        .map(|_| ())
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
        self.act_frames(
            Frames::Pixels(image.unsqueeze_dim(1)),
            instruction,
            subgoal.map(Subgoal::from),
        )
    }

    /// One step on an observation of one frame (pixels or state; normalised actions).
    ///
    /// # Shapes
    /// - obs: `[1, 1, …]` (see [`Frames`]); instruction: `[1, L_txt]`; subgoal: `[1, G, L_sg]`
    ///   (see [`Subgoal`])
    /// - output: `[H_a, A]`
    pub fn act_frames(
        &mut self,
        obs: Frames,
        instruction: Tensor<2, Int>,
        subgoal: Option<Subgoal<3>>,
    ) -> Result<Tensor<2>> {
        let state = obs.state_tokens();
        let visual = self.advance(obs, subgoal)?;
        let out = self.model.decode(visual, None, instruction, state)?;
        self.state.last_done = self.model.done_logits(out.queries.clone());
        let [_, ha, a] = out.actions.dims();
        Ok(out.actions.reshape([ha, a]))
    }

    /// Runs everything but the decoder on one frame and updates the carried state.
    ///
    /// # Shapes
    /// - obs: `[1, 1, …]` (see [`Frames`]); subgoal: `[1, G, L_sg]`
    /// - output: the decoder's visual tokens `[1, V, D_dec]` (history included)
    fn advance(&mut self, obs: Frames, subgoal: Option<Subgoal<3>>) -> Result<Tensor<3>> {
        let m = &self.model;
        if obs.batch_time() != [1, 1] {
            return Err(ModelError::Input(format!(
                "a streamed step is one frame of one episode, got [B, T] = {:?}",
                obs.batch_time()
            )));
        }
        let feats = m.encoder.forward(obs)?.squeeze_dim::<3>(1); // [1, M, D_f]
        let (token_type, text) = m.shared();
        let shared = Shared {
            token_type: &token_type,
            text,
        };
        let visual = m
            .tokens
            .step(feats, subgoal, &mut self.state.memory, shared)?;
        if m.progress.is_some() {
            self.state.last_tokens = Some(visual.clone());
        }
        self.state.step += 1;
        Ok(visual)
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
    use crate::io::{Processor, StepObservation};
    use crate::test_device;
    use burn::tensor::Distribution;

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
        let frame = data::RgbImage {
            width: 128,
            height: 128,
            channels: 3,
            data: img,
        };
        let processor = Processor::new(
            &cfg,
            data::ActionNorm {
                q01: [-1.0; 7],
                q99: [1.0; 7],
                mask: [true, true, true, true, true, true, false],
            },
        );
        let goal = data::GoalProgress {
            current_subgoal: "bowl".into(),
            ..Default::default()
        };
        let obs = StepObservation {
            agentview: Some(&frame),
            state: [0.0; 8],
            objects: &[],
            seed: 0,
            instruction: "put the bowl on the plate",
            goal: Some(&goal),
        };
        let input = |o: &StepObservation| processor.step(o, &device).unwrap();
        let chunk = policy.act_input(input(&obs)).unwrap();
        assert_eq!(chunk.len(), 4);
        assert_eq!(chunk[0].len(), 7);
        let floats = policy.state_floats();
        assert_eq!(floats, cfg.constant_state_floats());
        let masks = policy.last_masks().expect("slot variant keeps masks");
        assert_eq!(masks.len(), cfg.slots.num_slots);
        let m = masks[0].len();
        for j in 0..m {
            let total: f32 = masks.iter().map(|row| row[j]).sum();
            assert!((total - 1.0).abs() < 1e-4, "token {j}: {total}");
        }
        policy
            .act_input(input(&StepObservation { goal: None, ..obs }))
            .unwrap();
        policy.observe_input(input(&obs)).unwrap();
        assert_eq!(policy.step_count(), 3);
        assert_eq!(policy.state_floats(), floats);
        policy.reset();
        assert_eq!(policy.step_count(), 0);
        assert_eq!(policy.state_floats(), 0);
    }
}
