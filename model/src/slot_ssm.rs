//! SlotSSM (model.md §4): per-slot Mamba over time (shared weights, separate states), then
//! attention across slots; optional cross-attention to patches and FFN. Pre-LN residual blocks.
//!
//! The output ŝ_{t+1} = W_o LN(U)_t is the latent predicted at t for t + 1; every operation is
//! causal in t.

use burn::nn::{LayerNorm, Linear, LinearConfig};
use burn::prelude::*;

use crate::blocks::{CrossAttnBlock, FfnBlock, SelfAttnBlock, layer_norm};
use crate::config::ModelConfig;
use crate::mamba::{Mamba, MambaState};

/// Streaming state of a SlotSSM stack: one Mamba state per block, over B·K sequences.
#[derive(Clone, Debug)]
pub struct SlotSsmState {
    /// Per block, `h [B·K, E, S]` and `conv [B·K, E, d_conv − 1]`.
    pub blocks: Vec<MambaState>,
}

impl SlotSsmState {
    /// Detaches every tensor (truncated BPTT between windows).
    pub fn detach(self) -> Self {
        SlotSsmState {
            blocks: self.blocks.into_iter().map(MambaState::detach).collect(),
        }
    }

    /// Number of floats held.
    pub fn num_floats(&self) -> usize {
        self.blocks.iter().map(MambaState::num_floats).sum()
    }
}

/// One SlotSSM block.
#[derive(Module, Debug)]
pub struct SsmBlock {
    /// Projection W_f of the patches `[D_f, D]` (with cross-attention only).
    pub feat_proj: Option<Linear>,
    /// Cross-attention slots → patches.
    pub cross: Option<CrossAttnBlock>,
    /// Norm before the Mamba mixer `[D]`.
    pub norm_time: LayerNorm,
    /// Time mixing.
    pub mamba: Mamba,
    /// Slot mixing (self-attention across the K slots of a frame, no positions).
    pub slot_mix: SelfAttnBlock,
    /// Optional FFN, hidden 4D.
    pub ffn: Option<FfnBlock>,
}

impl SsmBlock {
    fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        let ssm = &config.ssm;
        SsmBlock {
            feat_proj: ssm
                .cross_attention
                .then(|| LinearConfig::new(config.encoder.feature_dim, d).init(device)),
            cross: ssm
                .cross_attention
                .then(|| CrossAttnBlock::new(d, ssm.heads, device)),
            norm_time: layer_norm(d, device),
            mamba: Mamba::new(d, ssm, device),
            slot_mix: SelfAttnBlock::new(d, ssm.heads, device),
            ffn: ssm.ffn.then(|| FfnBlock::new(d, 4 * d, device)),
        }
    }

    /// Cross-attention, slot mixing and FFN: everything but time mixing, per frame.
    ///
    /// # Shapes
    /// - u: `[N, K, D]` (N = B·T frames), feats: `[N, M, D_f]` → `[N, K, D]`
    fn frame_part_before(&self, u: Tensor<3>, feats: Option<Tensor<3>>) -> Tensor<3> {
        match (&self.cross, &self.feat_proj, feats) {
            (Some(cross), Some(proj), Some(f)) => cross.forward(u, proj.forward(f)),
            (Some(_), _, None) => panic!("SlotSSM with cross-attention needs the patch features"),
            _ => u,
        }
    }

    fn frame_part_after(&self, u: Tensor<3>) -> Tensor<3> {
        let u = self.slot_mix.forward(u, None);
        match &self.ffn {
            Some(ffn) => ffn.forward(u),
            None => u,
        }
    }
}

/// The SlotSSM stack with its output head W_o LN(·).
#[derive(Module, Debug)]
pub struct SlotSsm {
    /// Blocks.
    pub blocks: Vec<SsmBlock>,
    /// Final norm `[D]`.
    pub norm_out: LayerNorm,
    /// W_o `[D, D]`.
    pub out: Linear,
}

impl SlotSsm {
    /// Builds the stack of `config.ssm.blocks` blocks.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        SlotSsm {
            blocks: (0..config.ssm.blocks)
                .map(|_| SsmBlock::new(config, device))
                .collect(),
            norm_out: layer_norm(d, device),
            out: LinearConfig::new(d, d).init(device),
        }
    }

    /// Zero state for `batch` environments of `slots` slots each.
    pub fn zero_state(&self, batch: usize, slots: usize, device: &Device) -> SlotSsmState {
        SlotSsmState {
            blocks: self
                .blocks
                .iter()
                .map(|b| b.mamba.zero_state(batch * slots, device))
                .collect(),
        }
    }

    /// Parallel form over a window (training).
    ///
    /// # Shapes
    /// - slots: `[B, T, K, D]`
    /// - feats: `[B, T, M, D_f]` (needed only with cross-attention)
    /// - state: per block over B·K sequences (None = zeros)
    /// - output: (ŝ `[B, T, K, D]`, state after the last frame)
    pub fn forward(
        &self,
        slots: Tensor<4>,
        feats: Option<Tensor<4>>,
        state: Option<SlotSsmState>,
    ) -> (Tensor<4>, SlotSsmState) {
        let [b, t, k, d] = slots.dims();
        let feats = feats.map(|f| {
            let [_, _, m, d_f] = f.dims();
            f.reshape([b * t, m, d_f])
        });
        let mut states = state.map(|s| s.blocks.into_iter().map(Some).collect::<Vec<_>>());
        let mut new_states = Vec::with_capacity(self.blocks.len());
        let mut u = slots.reshape([b * t, k, d]);
        for (i, block) in self.blocks.iter().enumerate() {
            u = block.frame_part_before(u, feats.clone());
            // Time mixing over [(B·K), T, D].
            let seq = u
                .clone()
                .reshape([b, t, k, d])
                .swap_dims(1, 2)
                .reshape([b * k, t, d]);
            let st = states.as_mut().and_then(|s| s[i].take());
            let (y, st) = block
                .mamba
                .forward(block.norm_time.forward(seq.clone()), st);
            new_states.push(st);
            let seq = seq + y;
            u = seq
                .reshape([b, k, t, d])
                .swap_dims(1, 2)
                .reshape([b * t, k, d]);
            u = block.frame_part_after(u);
        }
        let out = self
            .out
            .forward(self.norm_out.forward(u))
            .reshape([b, t, k, d]);
        (out, SlotSsmState { blocks: new_states })
    }

    /// Step form: one frame (inference).
    ///
    /// # Shapes
    /// - slots: `[B, K, D]`, feats: `[B, M, D_f]`
    /// - output: (ŝ `[B, K, D]`, the next state)
    pub fn step(
        &self,
        slots: Tensor<3>,
        feats: Option<Tensor<3>>,
        state: SlotSsmState,
    ) -> (Tensor<3>, SlotSsmState) {
        let [b, k, d] = slots.dims();
        assert_eq!(
            state.blocks.len(),
            self.blocks.len(),
            "state has the wrong block count"
        );
        let mut u = slots;
        let mut new_states = Vec::with_capacity(self.blocks.len());
        for (block, st) in self.blocks.iter().zip(state.blocks) {
            u = block.frame_part_before(u, feats.clone());
            let flat = u.reshape([b * k, d]);
            let (y, st) = block.mamba.step(block.norm_time.forward(flat.clone()), st);
            new_states.push(st);
            u = (flat + y).reshape([b, k, d]);
            u = block.frame_part_after(u);
        }
        (
            self.out.forward(self.norm_out.forward(u)),
            SlotSsmState { blocks: new_states },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::test_device;
    use burn::tensor::Distribution;

    fn check_parallel_equals_steps(cross: bool, random_state: bool) {
        let (_guard, device) = test_device();
        device.seed(3);
        let mut cfg = ModelConfig::tiny(Variant::ESlotSsm {
            oracle_subgoal: false,
        });
        cfg.ssm.cross_attention = cross;
        let ssm = SlotSsm::new(&cfg, &device);
        let (b, t, k, d, m) = (2, 7, 8, 64, 64);
        let slots = Tensor::<4>::random([b, t, k, d], Distribution::Normal(0.0, 1.0), &device);
        let feats = Tensor::<4>::random([b, t, m, 64], Distribution::Normal(0.0, 1.0), &device);
        let init = if random_state {
            let mut s = ssm.zero_state(b, k, &device);
            for blk in &mut s.blocks {
                blk.h = Tensor::random(blk.h.dims(), Distribution::Normal(0.0, 1.0), &device);
                blk.conv = Tensor::random(blk.conv.dims(), Distribution::Normal(0.0, 1.0), &device);
            }
            s
        } else {
            ssm.zero_state(b, k, &device)
        };
        let f = cross.then(|| feats.clone());
        let (par, _) = ssm.forward(slots.clone(), f, Some(init.clone()));
        assert_eq!(par.dims(), [b, t, k, d]);
        let mut st = init;
        for i in 0..t {
            let fi = cross.then(|| feats.clone().narrow(1, i, 1).squeeze_dim::<3>(1));
            let (y, next) = ssm.step(slots.clone().narrow(1, i, 1).squeeze_dim(1), fi, st);
            st = next;
            let diff: f32 = (y - par.clone().narrow(1, i, 1).squeeze_dim::<3>(1))
                .abs()
                .max()
                .into_scalar();
            assert!(diff < 1e-4, "frame {i}: {diff}");
        }
    }

    #[test]
    fn parallel_equals_steps_zero_state() {
        check_parallel_equals_steps(false, false);
    }

    #[test]
    fn parallel_equals_steps_random_state_with_cross_attention() {
        check_parallel_equals_steps(true, true);
    }

    #[test]
    fn output_is_causal() {
        let (_guard, device) = test_device();
        let cfg = ModelConfig::tiny(Variant::ESlotSsm {
            oracle_subgoal: false,
        });
        let ssm = SlotSsm::new(&cfg, &device);
        let a = Tensor::<4>::random([1, 6, 8, 64], Distribution::Normal(0.0, 1.0), &device);
        // Change only the last frame: outputs of earlier frames must not move.
        let b = Tensor::cat(
            vec![
                a.clone().narrow(1, 0, 5),
                Tensor::random([1, 1, 8, 64], Distribution::Normal(0.0, 1.0), &device),
            ],
            1,
        );
        let (ya, _) = ssm.forward(a, None, None);
        let (yb, _) = ssm.forward(b, None, None);
        let diff: f32 = (ya.narrow(1, 0, 5) - yb.narrow(1, 0, 5))
            .abs()
            .max()
            .into_scalar();
        assert!(diff < 1e-6);
    }
}
