//! Small shared building blocks: MLPs, pre-LN attention blocks, a GRU cell.
//!
//! Attention never has a key bias: softmax is invariant to the constant that a key bias adds to
//! every score of a query, so such a bias would get an exactly zero gradient.

use burn::nn::attention::{MhaInput, MultiHeadAttention, MultiHeadAttentionConfig};
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::activation::{gelu, relu, sigmoid, tanh};

/// Multi-head attention without dropout and without key bias.
pub fn attention(d_model: usize, heads: usize, device: &Device) -> MultiHeadAttention {
    MultiHeadAttentionConfig::new(d_model, heads)
        .with_dropout(0.0)
        .with_key_bias(false)
        .init(device)
}

/// LayerNorm with eps 1e-5.
pub fn layer_norm(d: usize, device: &Device) -> LayerNorm {
    LayerNormConfig::new(d).init(device)
}

/// Activation of an [`Mlp`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Act {
    /// ReLU.
    Relu,
    /// GELU (exact).
    Gelu,
}

/// Two-layer perceptron `fc2(act(fc1(x)))`.
#[derive(Module, Debug)]
pub struct Mlp {
    /// `[d_in, d_hidden]`.
    pub fc1: Linear,
    /// `[d_hidden, d_out]`.
    pub fc2: Linear,
    /// Hidden activation.
    #[module(skip)]
    pub act: Act,
}

impl Mlp {
    /// Builds an MLP d_in → d_hidden → d_out with biases.
    pub fn new(d_in: usize, d_hidden: usize, d_out: usize, act: Act, device: &Device) -> Self {
        Mlp {
            fc1: LinearConfig::new(d_in, d_hidden).init(device),
            fc2: LinearConfig::new(d_hidden, d_out).init(device),
            act,
        }
    }

    /// # Shapes
    /// - x: `[..., d_in]` → `[..., d_out]`
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        let h = self.fc1.forward(x);
        let h = match self.act {
            Act::Relu => relu(h),
            Act::Gelu => gelu(h),
        };
        self.fc2.forward(h)
    }
}

/// Pre-LN residual feed-forward: `x + W₂ GELU(W₁ LN(x))`.
#[derive(Module, Debug)]
pub struct FfnBlock {
    /// Norm `[d]`.
    pub norm: LayerNorm,
    /// `d → hidden → d`.
    pub mlp: Mlp,
}

impl FfnBlock {
    /// Builds the block with hidden width `hidden`.
    pub fn new(d: usize, hidden: usize, device: &Device) -> Self {
        FfnBlock {
            norm: layer_norm(d, device),
            mlp: Mlp::new(d, hidden, d, Act::Gelu, device),
        }
    }

    /// # Shapes
    /// - x: `[N, S, d]` → `[N, S, d]`
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        x.clone() + self.mlp.forward(self.norm.forward(x))
    }
}

/// Pre-LN residual self-attention: `x + MHSA(LN(x))`, with an optional key padding mask.
#[derive(Module, Debug)]
pub struct SelfAttnBlock {
    /// Norm `[d]`.
    pub norm: LayerNorm,
    /// Attention.
    pub attn: MultiHeadAttention,
}

impl SelfAttnBlock {
    /// Builds the block.
    pub fn new(d: usize, heads: usize, device: &Device) -> Self {
        SelfAttnBlock {
            norm: layer_norm(d, device),
            attn: attention(d, heads, device),
        }
    }

    /// # Shapes
    /// - x: `[N, S, d]`
    /// - pad: `[N, S]`, true = masked key
    /// - output: `[N, S, d]`
    pub fn forward(&self, x: Tensor<3>, pad: Option<Tensor<2, Bool>>) -> Tensor<3> {
        let h = self.norm.forward(x.clone());
        let mut input = MhaInput::self_attn(h);
        if let Some(pad) = pad {
            input = input.mask_pad(pad);
        }
        x + self.attn.forward(input).context
    }

    /// The block's outputs at some of its rows only: `rows` (rows of `x`) attend to every row of
    /// `x`, as in [`SelfAttnBlock::forward`], whose outputs at those rows these equal.
    ///
    /// # Shapes
    /// - x: `[N, S, d]`; rows: `[N, R, d]`; pad: `[N, S]`, true = masked key
    /// - output: `[N, R, d]`
    pub fn forward_rows(
        &self,
        x: Tensor<3>,
        rows: Tensor<3>,
        pad: Option<Tensor<2, Bool>>,
    ) -> Tensor<3> {
        let h = self.norm.forward(x);
        let mut input = MhaInput::new(self.norm.forward(rows.clone()), h.clone(), h);
        if let Some(pad) = pad {
            input = input.mask_pad(pad);
        }
        rows + self.attn.forward(input).context
    }
}

/// Pre-LN residual cross-attention: `q + MHA(LN_q(q), LN_kv(kv))`.
#[derive(Module, Debug)]
pub struct CrossAttnBlock {
    /// Norm of the queries `[d]`.
    pub norm_q: LayerNorm,
    /// Norm of keys/values `[d]`.
    pub norm_kv: LayerNorm,
    /// Attention.
    pub attn: MultiHeadAttention,
}

impl CrossAttnBlock {
    /// Builds the block.
    pub fn new(d: usize, heads: usize, device: &Device) -> Self {
        CrossAttnBlock {
            norm_q: layer_norm(d, device),
            norm_kv: layer_norm(d, device),
            attn: attention(d, heads, device),
        }
    }

    /// # Shapes
    /// - q: `[N, Sq, d]`, kv: `[N, Skv, d]` → `[N, Sq, d]`
    pub fn forward(&self, q: Tensor<3>, kv: Tensor<3>) -> Tensor<3> {
        let kv = self.norm_kv.forward(kv);
        let input = MhaInput::new(self.norm_q.forward(q.clone()), kv.clone(), kv);
        q + self.attn.forward(input).context
    }
}

/// GRU cell in PyTorch's convention (model.md §2):
/// r = σ(W_ir x + W_hr h), z = σ(W_iz x + W_hz h), n = tanh(W_in x + r ⊙ W_hn h),
/// h' = (1 − z) ⊙ n + z ⊙ h. The three input and three hidden Linears are stored fused.
#[derive(Module, Debug)]
pub struct GruCell {
    /// [W_ir ‖ W_iz ‖ W_in] with biases, `[d_in, 3·d]`.
    pub input: Linear,
    /// [W_hr ‖ W_hz ‖ W_hn] with biases, `[d, 3·d]`.
    pub hidden: Linear,
    /// Hidden width d.
    pub d: usize,
}

impl GruCell {
    /// Builds a cell with input width `d_in` and hidden width `d`.
    pub fn new(d_in: usize, d: usize, device: &Device) -> Self {
        GruCell {
            input: LinearConfig::new(d_in, 3 * d).init(device),
            hidden: LinearConfig::new(d, 3 * d).init(device),
            d,
        }
    }

    /// # Shapes
    /// - x: `[N, d_in]`, h: `[N, d]` → `[N, d]`
    pub fn forward(&self, x: Tensor<2>, h: Tensor<2>) -> Tensor<2> {
        let d = self.d;
        assert_shape!(h, [_, d]);
        let gi = self.input.forward(x);
        let gh = self.hidden.forward(h.clone());
        let r = sigmoid(gi.clone().narrow(1, 0, d) + gh.clone().narrow(1, 0, d));
        let z = sigmoid(gi.clone().narrow(1, d, d) + gh.clone().narrow(1, d, d));
        let n = tanh(gi.narrow(1, 2 * d, d) + r * gh.narrow(1, 2 * d, d));
        let one_minus_z = z.clone().neg().add_scalar(1.0);
        one_minus_z * n + z * h
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{test_autodiff_device, test_device};

    /// A Linear's weight and bias gradients are the same whether its input is `[B, T, K, D]` or
    /// the same numbers reshaped to `[B·T, K, D]` or `[B·T·K, D]` (the oracle slots project 4-d
    /// token tensors, the dense tokens 3-d ones), and equal x^T·g summed by hand.
    #[test]
    fn linear_gradients_do_not_depend_on_the_input_rank() {
        let (_guard, device) = test_autodiff_device();
        let lin = LinearConfig::new(5, 3).init(&device);
        let x = Tensor::<4>::random([2, 3, 4, 5], burn::tensor::Distribution::Default, &device);
        let g = Tensor::<4>::random([2, 3, 4, 3], burn::tensor::Distribution::Default, &device);
        fn grad_of<const D: usize>(
            p: &burn::module::Param<Tensor<D>>,
            grads: &burn::tensor::Gradients,
        ) -> Vec<f32> {
            p.val()
                .grad(grads)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap()
        }
        let grads_of = |y: Tensor<2>| {
            let grads = (y * g.clone().reshape([24, 3])).sum().backward();
            (
                grad_of(&lin.weight, &grads),
                grad_of(lin.bias.as_ref().unwrap(), &grads),
            )
        };
        let r4 = grads_of(lin.forward(x.clone()).reshape([24, 3]));
        let r3 = grads_of(lin.forward(x.clone().reshape([6, 4, 5])).reshape([24, 3]));
        let r2 = grads_of(lin.forward(x.clone().reshape([24, 5])));
        let xs = x.into_data().try_to_vec::<f32>().unwrap();
        let gs = g.into_data().try_to_vec::<f32>().unwrap();
        let mut w = vec![0.0f32; 15];
        let mut b = vec![0.0f32; 3];
        for n in 0..24 {
            for o in 0..3 {
                b[o] += gs[n * 3 + o];
                for i in 0..5 {
                    w[i * 3 + o] += xs[n * 5 + i] * gs[n * 3 + o];
                }
            }
        }
        for (name, (gw, gb)) in [("4-d", &r4), ("3-d", &r3), ("2-d", &r2)] {
            for (a, e) in gw.iter().zip(&w).chain(gb.iter().zip(&b)) {
                assert!(
                    (a - e).abs() < 1e-4,
                    "{name}: {gw:?} / {gb:?} vs {w:?} / {b:?}"
                );
            }
        }
    }

    #[test]
    fn gru_cell_matches_hand_computation() {
        let (_guard, device) = test_device();
        let cell = GruCell::new(2, 1, &device);
        // Write known weights: all input weights 1, hidden weights 0.5, biases 0.
        let w_in = Tensor::<2>::ones([2, 3], &device);
        let w_h = Tensor::<2>::ones([1, 3], &device).mul_scalar(0.5);
        let cell = GruCell {
            input: Linear {
                weight: burn::module::Param::from_tensor(w_in),
                bias: Some(burn::module::Param::from_tensor(Tensor::zeros(
                    [3],
                    &device,
                ))),
            },
            hidden: Linear {
                weight: burn::module::Param::from_tensor(w_h),
                bias: Some(burn::module::Param::from_tensor(Tensor::zeros(
                    [3],
                    &device,
                ))),
            },
            d: cell.d,
        };
        let x = Tensor::<2>::from_floats([[0.2, -0.1]], &device);
        let h = Tensor::<2>::from_floats([[0.4]], &device);
        let out: f32 = cell.forward(x, h).into_scalar();
        let s = |v: f32| 1.0 / (1.0 + (-v).exp());
        let (xs, h0) = (0.1f32, 0.4f32);
        let r = s(xs + 0.5 * h0);
        let z = s(xs + 0.5 * h0);
        let n = (xs + r * 0.5 * h0).tanh();
        let want = (1.0 - z) * n + z * h0;
        assert!((out - want).abs() < 1e-6, "{out} vs {want}");
    }

    #[test]
    fn blocks_keep_shapes() {
        let (_guard, device) = test_device();
        let x = Tensor::<3>::random([2, 5, 8], burn::tensor::Distribution::Default, &device);
        let kv = Tensor::<3>::random([2, 3, 8], burn::tensor::Distribution::Default, &device);
        assert_eq!(
            SelfAttnBlock::new(8, 2, &device)
                .forward(x.clone(), None)
                .dims(),
            [2, 5, 8]
        );
        assert_eq!(
            CrossAttnBlock::new(8, 2, &device)
                .forward(x.clone(), kv)
                .dims(),
            [2, 5, 8]
        );
        assert_eq!(
            FfnBlock::new(8, 32, &device).forward(x.clone()).dims(),
            [2, 5, 8]
        );
        assert_eq!(
            Mlp::new(8, 16, 3, Act::Relu, &device).forward(x).dims(),
            [2, 5, 3]
        );
    }
}
