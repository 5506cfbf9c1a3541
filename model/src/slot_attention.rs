//! Slot Attention with a GRU update and slots carried across frames (model.md §2).
//!
//! Frame 0 starts from learned queries Q₀; every later frame starts from the previous frame's
//! slots, detached (temporal propagation).

use burn::module::Param;
use burn::nn::{LayerNorm, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;
use burn::tensor::activation::softmax;

use crate::blocks::{Act, GruCell, Mlp, layer_norm};
use crate::config::ModelConfig;

/// Added to the attention before the weighted mean (Locatello et al.).
const ATTN_EPS: f32 = 1e-8;

/// Slot Attention module.
#[derive(Module, Debug)]
pub struct SlotAttention {
    /// Norm of the input features `[D_f]`.
    pub norm_input: LayerNorm,
    /// Keys `[D_f, D]`, no bias.
    pub to_k: Linear,
    /// Values `[D_f, D]`, no bias.
    pub to_v: Linear,
    /// Norm of the slots before the query `[D]`.
    pub norm_slots: LayerNorm,
    /// Queries `[D, D]`, no bias.
    pub to_q: Linear,
    /// GRU update.
    pub gru: GruCell,
    /// Norm before the residual MLP `[D]`.
    pub norm_mlp: LayerNorm,
    /// Residual MLP D → 2D → D (ReLU).
    pub mlp: Mlp,
    /// Learned initial slots Q₀ `[K, D]`.
    pub init_slots: Param<Tensor<2>>,
    /// Iterations on the first frame.
    pub iters_first: usize,
    /// Iterations on later frames.
    pub iters_later: usize,
    /// Layer-normalise carried slots (see `SlotConfig::normalize_carried`).
    pub normalize_carried: bool,
}

impl SlotAttention {
    /// Builds slot attention for `config` (K slots of width D over D_f features).
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        let d_f = config.encoder.feature_dim;
        let k = config.slots.num_slots;
        SlotAttention {
            norm_input: layer_norm(d_f, device),
            to_k: LinearConfig::new(d_f, d).with_bias(false).init(device),
            to_v: LinearConfig::new(d_f, d).with_bias(false).init(device),
            norm_slots: layer_norm(d, device),
            to_q: LinearConfig::new(d, d).with_bias(false).init(device),
            gru: GruCell::new(d, d, device),
            norm_mlp: layer_norm(d, device),
            mlp: Mlp::new(d, 2 * d, d, Act::Relu, device),
            init_slots: Param::from_tensor(Tensor::random(
                [k, d],
                Distribution::Normal(0.0, 1.0),
                device,
            )),
            iters_first: config.slots.iters_first,
            iters_later: config.slots.iters_later,
            normalize_carried: config.slots.normalize_carried,
        }
    }

    /// Number of slots K.
    pub fn num_slots(&self) -> usize {
        self.init_slots.dims()[0]
    }

    /// Slot width D.
    pub fn dim(&self) -> usize {
        self.init_slots.dims()[1]
    }

    /// One refinement iteration.
    ///
    /// # Shapes
    /// - slots: `[B, K, D]`, k and v: `[B, M, D]`
    /// - output: (slots `[B, K, D]`, attention over slots `[B, K, M]`)
    fn iterate(&self, slots: Tensor<3>, k: Tensor<3>, v: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let [b, n_slots, d] = slots.dims();
        let q = self.to_q.forward(self.norm_slots.forward(slots.clone()));
        let logits = k.matmul(q.swap_dims(1, 2)).div_scalar((d as f32).sqrt()); // [B, M, K]
        let attn = softmax(logits, 2).add_scalar(ATTN_EPS); // over slots
        let weights = attn.clone() / attn.clone().sum_dim(1); // weighted mean over M
        let updates = weights.swap_dims(1, 2).matmul(v); // [B, K, D]
        let slots = self
            .gru
            .forward(
                updates.reshape([b * n_slots, d]),
                slots.reshape([b * n_slots, d]),
            )
            .reshape([b, n_slots, d]);
        let slots = slots.clone() + self.mlp.forward(self.norm_mlp.forward(slots));
        (slots, attn.swap_dims(1, 2))
    }

    /// Slot attention on one frame.
    ///
    /// `prev` = None starts from the learned Q₀ with `iters_first` iterations; otherwise from
    /// `sg(prev)` (layer-normalised, without affine, when `normalize_carried`) with
    /// `iters_later` iterations.
    ///
    /// # Shapes
    /// - features: `[B, M, D_f]`
    /// - prev: `[B, K, D]`
    /// - output: (slots `[B, K, D]`, masks `[B, K, M]`)
    pub fn step(&self, features: Tensor<3>, prev: Option<Tensor<3>>) -> (Tensor<3>, Tensor<3>) {
        let [b, m, _] = features.dims();
        let (kk, d) = (self.num_slots(), self.dim());
        let x = self.norm_input.forward(features);
        let k = self.to_k.forward(x.clone());
        let v = self.to_v.forward(x);
        let (mut slots, iters) = match prev {
            None => (
                self.init_slots.val().unsqueeze_dim::<3>(0).repeat_dim(0, b),
                self.iters_first,
            ),
            Some(p) => {
                assert_shape!(p, [b, kk, d]);
                let p = p.detach();
                let p = if self.normalize_carried {
                    let mean = p.clone().mean_dim(2);
                    let centred = p - mean;
                    let var = centred.clone().powi_scalar(2).mean_dim(2);
                    centred / var.add_scalar(1e-5).sqrt()
                } else {
                    p
                };
                (p, self.iters_later)
            }
        };
        let mut masks = Tensor::zeros([b, kk, m], &k.device());
        for _ in 0..iters.max(1) {
            let (s, a) = self.iterate(slots, k.clone(), v.clone());
            slots = s;
            masks = a;
        }
        (slots, masks)
    }

    /// Slot attention over a window, carrying slots from frame to frame.
    ///
    /// # Shapes
    /// - features: `[B, T, M, D_f]`
    /// - prev: slots of the frame before the window `[B, K, D]` (None: the window starts an episode)
    /// - output: (slots `[B, T, K, D]`, masks `[B, T, K, M]`)
    pub fn forward(&self, features: Tensor<4>, prev: Option<Tensor<3>>) -> (Tensor<4>, Tensor<4>) {
        let [_, t, _, _] = features.dims();
        let mut prev = prev;
        let mut slots = Vec::with_capacity(t);
        let mut masks = Vec::with_capacity(t);
        for i in 0..t {
            let f = features.clone().narrow(1, i, 1).squeeze_dim::<3>(1);
            let (s, a) = self.step(f, prev);
            prev = Some(s.clone());
            slots.push(s);
            masks.push(a);
        }
        (Tensor::stack(slots, 1), Tensor::stack(masks, 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::test_device;

    fn setup() -> (std::sync::MutexGuard<'static, ()>, SlotAttention, Device) {
        let (guard, device) = test_device();
        let cfg = ModelConfig::tiny(Variant::SlotVla { history: 1 });
        (guard, SlotAttention::new(&cfg, &device), device)
    }

    #[test]
    fn shapes_and_masks_are_distributions_over_slots() {
        let (_guard, sa, device) = setup();
        let f = Tensor::<4>::random([2, 3, 64, 64], Distribution::Default, &device);
        let (slots, masks) = sa.forward(f, None);
        assert_eq!(slots.dims(), [2, 3, 8, 64]);
        assert_eq!(masks.dims(), [2, 3, 8, 64]);
        // Softmax over K (plus ε each): every pixel's masks sum to 1 + K·ε.
        let sums = masks.sum_dim(2).into_data().try_to_vec::<f32>().unwrap();
        assert!(sums.iter().all(|s| (s - 1.0).abs() < 1e-5));
    }

    #[test]
    fn window_forward_equals_frame_steps() {
        let (_guard, sa, device) = setup();
        let f = Tensor::<4>::random([1, 4, 64, 64], Distribution::Default, &device);
        let (slots, _) = sa.forward(f.clone(), None);
        let mut prev = None;
        for t in 0..4 {
            let (s, _) = sa.step(f.clone().narrow(1, t, 1).squeeze_dim(1), prev);
            let diff = (s.clone() - slots.clone().narrow(1, t, 1).squeeze_dim::<3>(1))
                .abs()
                .max()
                .into_scalar::<f32>();
            assert!(diff < 1e-6);
            prev = Some(s);
        }
    }
}
