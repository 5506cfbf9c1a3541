//! Slot-level heads: the windowed prediction head "Past MLP" (model.md §5), Slot Fusion (§6),
//! the spatial-broadcast slot decoder of L_sa (§2) and the training-only progress head.

use burn::module::Param;
use burn::nn::{LayerNorm, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;
use burn::tensor::activation::{relu, softmax};

use crate::blocks::{Act, Mlp, layer_norm};

/// Windowed prediction head: Ŝ = MLP([ŝ_{t+1} ‖ s_t]) predicts s_{t+o_j} for the P offsets.
#[derive(Module, Debug)]
pub struct WindowHead {
    /// MLP 2D → 2D → P·D (GELU).
    pub mlp: Mlp,
    /// P.
    pub window: usize,
}

impl WindowHead {
    /// Builds the head for slots of width `d` and `window` = P offsets.
    pub fn new(d: usize, window: usize, device: &Device) -> Self {
        WindowHead {
            mlp: Mlp::new(2 * d, 2 * d, window * d, Act::Gelu, device),
            window,
        }
    }

    /// # Shapes
    /// - pred (ŝ_{t+1}): `[B, T, K, D]`, slots (s_t): `[B, T, K, D]`
    /// - output: `[B, T, K, P, D]`
    pub fn forward(&self, pred: Tensor<4>, slots: Tensor<4>) -> Tensor<5> {
        let [b, t, k, d] = slots.dims();
        assert_shape!(pred, [b, t, k, d]);
        self.mlp
            .forward(Tensor::cat(vec![pred, slots], 3))
            .reshape([b, t, k, self.window, d])
    }
}

/// Slot Fusion: z = W_o[W₁ LN(s) ‖ W₂ LN(ŝ) ‖ W₃ LN(g)].
#[derive(Module, Debug)]
pub struct SlotFusion {
    /// Norm of s `[D]`.
    pub norm_s: LayerNorm,
    /// Norm of ŝ `[D]`.
    pub norm_pred: LayerNorm,
    /// Norm of g `[D_g]`.
    pub norm_g: LayerNorm,
    /// W₁ `[D, D]`.
    pub w_s: Linear,
    /// W₂ `[D, D]`.
    pub w_pred: Linear,
    /// W₃ `[D_g, D]`.
    pub w_g: Linear,
    /// W_o `[3D, D]`.
    pub out: Linear,
}

impl SlotFusion {
    /// Builds the fusion of slots of width `d` and subgoal embeddings of width `d_g`.
    pub fn new(d: usize, d_g: usize, device: &Device) -> Self {
        SlotFusion {
            norm_s: layer_norm(d, device),
            norm_pred: layer_norm(d, device),
            norm_g: layer_norm(d_g, device),
            w_s: LinearConfig::new(d, d).init(device),
            w_pred: LinearConfig::new(d, d).init(device),
            w_g: LinearConfig::new(d_g, d).init(device),
            out: LinearConfig::new(3 * d, d).init(device),
        }
    }

    /// # Shapes
    /// - slots, pred: `[..., K, D]`; subgoal: `[..., K, D_g]`
    /// - output: `[..., K, D]`
    pub fn forward<const N: usize>(
        &self,
        slots: Tensor<N>,
        pred: Tensor<N>,
        subgoal: Tensor<N>,
    ) -> Tensor<N> {
        let a = self.w_s.forward(self.norm_s.forward(slots));
        let b = self.w_pred.forward(self.norm_pred.forward(pred));
        let c = self.w_g.forward(self.norm_g.forward(subgoal));
        self.out.forward(Tensor::cat(vec![a, b, c], N - 1))
    }
}

/// Spatial-broadcast slot decoder (DINOSAUR-style): every slot plus a learned position embedding
/// goes through an MLP to (f̂_{k,m}, logit_{k,m}); the reconstruction is Σ_k softmax_k(logit) f̂.
#[derive(Module, Debug)]
pub struct SlotDecoder {
    /// Position embedding P `[M, D]`.
    pub pos: Param<Tensor<2>>,
    /// `[D, hidden]`.
    pub fc1: Linear,
    /// `[hidden, hidden]`.
    pub fc2: Linear,
    /// `[hidden, D_tgt + 1]`.
    pub fc3: Linear,
}

impl SlotDecoder {
    /// Builds a decoder for `m` positions, slots of width `d`, targets of width `d_tgt`.
    pub fn new(m: usize, d: usize, hidden: usize, d_tgt: usize, device: &Device) -> Self {
        SlotDecoder {
            pos: Param::from_tensor(Tensor::random(
                [m, d],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
            fc1: LinearConfig::new(d, hidden).init(device),
            fc2: LinearConfig::new(hidden, hidden).init(device),
            fc3: LinearConfig::new(hidden, d_tgt + 1).init(device),
        }
    }

    /// # Shapes
    /// - slots: `[N, K, D]`
    /// - output: (reconstruction `[N, M, D_tgt]`, masks `[N, K, M]`)
    ///
    /// Computed in an order that never forms the `[N, K, M, D_tgt]` per-slot features: fc1 of
    /// slot + position is fc1(slot) + W₁·position (`[N, K, H]` and `[M, H]` instead of a matmul
    /// over N·K·M rows), and since the masks sum to 1 over the slots,
    /// Σ_k m_k (W h_k + b) = W (Σ_k m_k h_k) + b, so fc3's feature columns act once per position
    /// on the mask-weighted hidden state (8× fewer rows at K = 8). Equal to the plain form up to
    /// float rounding ([`SlotDecoder::forward_plain`]).
    pub fn forward(&self, slots: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let [n, k, _] = slots.dims();
        let [m, _] = self.pos.dims();
        let [hidden, d_out] = self.fc3.weight.dims();
        let a = self.fc1.forward(slots); // [N, K, H]
        let p = self.pos.val().matmul(self.fc1.weight.val()); // [M, H]
        let x = relu(a.reshape([n, k, 1, hidden]) + p.reshape([1, 1, m, hidden]));
        let x = relu(self.fc2.forward(x)); // [N, K, M, H]
        let w3 = self.fc3.weight.val();
        let b3 = self.fc3.bias.as_ref().map(|b| b.val());
        let w_logit = w3.clone().narrow(1, d_out - 1, 1); // [H, 1]
        let mut logits = x.clone().matmul(w_logit.reshape([1, 1, hidden, 1])); // [N, K, M, 1]
        if let Some(b) = &b3 {
            logits = logits + b.clone().narrow(0, d_out - 1, 1).reshape([1, 1, 1, 1]);
        }
        let masks = softmax(logits, 1);
        let mixed = (x * masks.clone()).sum_dim(1).reshape([n, m, hidden]); // [N, M, H]
        let mut recon = mixed.matmul(w3.narrow(1, 0, d_out - 1).unsqueeze_dim(0)); // [N, M, D_tgt]
        if let Some(b) = b3 {
            recon = recon + b.narrow(0, 0, d_out - 1).reshape([1, 1, d_out - 1]);
        }
        (recon, masks.reshape([n, k, m]))
    }

    /// The decoder in its textbook order (per-slot features `[N, K, M, D_tgt]`, then the masked
    /// sum): the reference [`SlotDecoder::forward`] is checked against.
    ///
    /// # Shapes
    /// - as [`SlotDecoder::forward`]
    pub fn forward_plain(&self, slots: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let [n, k, d] = slots.dims();
        let [m, _] = self.pos.dims();
        let x = slots.reshape([n, k, 1, d]) + self.pos.val().reshape([1, 1, m, d]);
        let x = relu(self.fc1.forward(x));
        let x = relu(self.fc2.forward(x));
        let x = self.fc3.forward(x); // [N, K, M, D_tgt + 1]
        let d_out = x.dims()[3];
        let feats = x.clone().narrow(3, 0, d_out - 1);
        let logits = x.narrow(3, d_out - 1, 1); // [N, K, M, 1]
        let masks = softmax(logits, 1);
        let recon = (feats * masks.clone()).sum_dim(1).squeeze_dim::<3>(1);
        (recon, masks.squeeze_dim::<3>(3))
    }
}

/// Classes of the progress head: subgoals done 0 … 15 (more are counted as 15).
pub const PROGRESS_CLASSES: usize = 16;

/// Progress head: logits over the number of subgoals done so far, read from one frame's visual
/// tokens (their mean and their maximum, through an MLP). Trained with L_prog only; nothing at
/// inference reads it, so it can only shape what the tokens (and the memory behind them) keep.
#[derive(Module, Debug)]
pub struct ProgressHead {
    /// MLP 2D → D → [`PROGRESS_CLASSES`] (GELU).
    pub mlp: Mlp,
}

impl ProgressHead {
    /// Builds the head for tokens of width `d`.
    pub fn new(d: usize, device: &Device) -> Self {
        ProgressHead {
            mlp: Mlp::new(2 * d, d, PROGRESS_CLASSES, Act::Gelu, device),
        }
    }

    /// # Shapes
    /// - tokens: `[N, V, D]`; pad: `[N, V]` (true = not a token of this frame: a history
    ///   frame before the window start), at least one token of each row unpadded
    /// - output: logits `[N, C]`
    pub fn forward(&self, tokens: Tensor<3>, pad: Option<Tensor<2, Bool>>) -> Tensor<2> {
        let [n, v, _] = tokens.dims();
        let (mean, max) = match pad {
            None => (tokens.clone().mean_dim(1), tokens.max_dim(1)),
            Some(pad) => {
                assert_shape!(pad, [n, v]);
                let keep = pad.bool_not().float().reshape([n, v, 1]);
                let count = keep.clone().sum_dim(1).clamp_min(1.0);
                let mean = (tokens.clone() * keep.clone()).sum_dim(1) / count;
                // Padded tokens pushed far below any real value before the maximum.
                let max = (tokens + (keep - 1.0) * 1e9).max_dim(1);
                (mean, max)
            }
        };
        self.mlp
            .forward(Tensor::cat(vec![mean, max], 2))
            .reshape([n, PROGRESS_CLASSES])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_device;

    #[test]
    fn head_shapes() {
        let (_guard, device) = test_device();
        let s = Tensor::<4>::random([2, 3, 4, 8], Distribution::Default, &device);
        let w = WindowHead::new(8, 5, &device).forward(s.clone(), s.clone());
        assert_eq!(w.dims(), [2, 3, 4, 5, 8]);
        let g = Tensor::<4>::random([2, 3, 4, 6], Distribution::Default, &device);
        let z = SlotFusion::new(8, 6, &device).forward(s.clone(), s.clone(), g);
        assert_eq!(z.dims(), [2, 3, 4, 8]);
        let (recon, masks) =
            SlotDecoder::new(16, 8, 12, 192, &device).forward(s.reshape([6, 4, 8]));
        assert_eq!(recon.dims(), [6, 16, 192]);
        assert_eq!(masks.dims(), [6, 4, 16]);
        let sums = masks.sum_dim(1).into_data().try_to_vec::<f32>().unwrap();
        assert!(sums.iter().all(|v| (v - 1.0).abs() < 1e-5));
    }

    #[test]
    fn slot_decoder_equals_its_plain_form_with_gradients() {
        let (_guard, device) = crate::test_autodiff_device();
        let dec = SlotDecoder::new(16, 8, 12, 192, &device);
        let s = Tensor::<3>::random([3, 4, 8], Distribution::Normal(0.0, 1.0), &device);
        let (r1, m1) = dec.forward(s.clone());
        let (r2, m2) = dec.forward_plain(s);
        assert_eq!(r1.dims(), [3, 16, 192]);
        assert_eq!(m1.dims(), [3, 4, 16]);
        let max = |t: Tensor<3>| t.abs().max().into_scalar::<f32>();
        assert!(max(r1.clone() - r2.clone()) < 1e-5);
        assert!(max(m1 - m2) < 1e-6);
        // The same gradients for every weight (L_sa as the loss is formed).
        let g1 = r1.powi_scalar(2).mean().backward();
        let g2 = r2.powi_scalar(2).mean().backward();
        for (name, p) in [
            ("pos", dec.pos.val()),
            ("fc1", dec.fc1.weight.val()),
            ("fc2", dec.fc2.weight.val()),
            ("fc3", dec.fc3.weight.val()),
        ] {
            let a = p.grad(&g1).expect("gradient");
            let b = p.grad(&g2).expect("gradient");
            let scale = b.clone().abs().max().into_scalar::<f32>().max(1e-6);
            let diff = (a - b).abs().max().into_scalar::<f32>();
            assert!(
                diff / scale < 1e-4,
                "{name}: gradients differ by {diff} (scale {scale})"
            );
        }
    }

    #[test]
    fn progress_head_ignores_padded_tokens() {
        let (_guard, device) = test_device();
        let head = ProgressHead::new(8, &device);
        let real = Tensor::<3>::random([2, 3, 8], Distribution::Default, &device);
        let junk = Tensor::<3>::random([2, 2, 8], Distribution::Uniform(50.0, 60.0), &device);
        let padded = Tensor::cat(vec![junk, real.clone()], 1); // [2, 5, 8]
        let pad = Tensor::<2, Bool>::from_data(
            TensorData::new([true, true, false, false, false].repeat(2), [2, 5]),
            &device,
        );
        let a = head.forward(real, None);
        let b = head.forward(padded.clone(), Some(pad));
        assert_eq!(a.dims(), [2, PROGRESS_CLASSES]);
        let diff = (a.clone() - b).abs().max().into_scalar::<f32>();
        assert!(diff < 1e-4, "padded tokens changed the logits by {diff}");
        // Unmasked, the junk does change them.
        let c = head.forward(padded, None);
        assert!((a - c).abs().max().into_scalar::<f32>() > 1e-2);
    }
}
