//! What the policy observes, encoded into M feature tokens per frame: the visual encoder of
//! model.md §1 (a small CNN, a soft position embedding, LN and an MLP) for pixels, or the state
//! encoder (category embedding + linear map of each object's pose and grasp, LN and an MLP) for
//! the object state.

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Embedding, EmbeddingConfig, LayerNorm, Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::relu;
use burn::tensor::ops::PadMode;

use crate::blocks::{Act, Mlp, layer_norm};
use crate::config::{ModelConfig, Observation};
use crate::error::{ModelError, Result};

/// A window of observations, as the model's [`Observer`] reads them.
// Two tensor handles against one: one value per batch, not worth a Box.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Frames {
    /// Agentview RGB in [0, 1] `[B, T, 3, H, W]`.
    Pixels(Tensor<5>),
    /// Object and robot tokens: features `[B, T, N, F]` and category ids `[B, T, N]`
    /// (see [`crate::io::state`]).
    State(Tensor<4>, Tensor<3, Int>),
}

impl From<Tensor<5>> for Frames {
    fn from(images: Tensor<5>) -> Self {
        Frames::Pixels(images)
    }
}

impl Frames {
    /// Batch and time `[B, T]`.
    pub fn batch_time(&self) -> [usize; 2] {
        match self {
            Frames::Pixels(x) => {
                let [b, t, ..] = x.dims();
                [b, t]
            }
            Frames::State(x, _) => {
                let [b, t, ..] = x.dims();
                [b, t]
            }
        }
    }

    /// The images (None in state mode).
    pub fn pixels(&self) -> Option<Tensor<5>> {
        match self {
            Frames::Pixels(x) => Some(x.clone()),
            Frames::State(..) => None,
        }
    }

    /// The state tokens with batch and time flattened (None for pixels).
    ///
    /// # Shapes
    /// - output: features `[B·T, N, F]`, categories `[B·T, N]`
    pub fn state_tokens(&self) -> Option<(Tensor<3>, Tensor<2, Int>)> {
        match self {
            Frames::Pixels(_) => None,
            Frames::State(x, c) => {
                let [b, t, n, f] = x.dims();
                Some((
                    x.clone().reshape([b * t, n, f]),
                    c.clone().reshape([b * t, n]),
                ))
            }
        }
    }

    /// Frames `start..start + len` of every window.
    pub fn narrow(&self, start: usize, len: usize) -> Frames {
        match self {
            Frames::Pixels(x) => Frames::Pixels(x.clone().narrow(1, start, len)),
            Frames::State(x, c) => Frames::State(
                x.clone().narrow(1, start, len),
                c.clone().narrow(1, start, len),
            ),
        }
    }
}

/// The encoder of what the model observes: one token sequence `[B, T, M, D_f]` per window.
// One per model, like the variants' token builders.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Observer {
    /// The CNN of model.md §1.
    Pixels(VisualEncoder),
    /// The object-state encoder.
    State(StateEncoder),
}

impl Observer {
    /// The encoder of `config.observation`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        match config.observation {
            Observation::Pixels => Observer::Pixels(VisualEncoder::new(config, device)),
            Observation::State {
                tokens,
                categories,
                features,
            } => Observer::State(StateEncoder::new(
                tokens,
                categories,
                features,
                config.encoder.feature_dim,
                config.encoder.category_scale,
                device,
            )),
        }
    }

    /// Feature tokens of a window.
    ///
    /// # Shapes
    /// - frames: see [`Frames`]; output: `[B, T, M, D_f]`
    pub fn forward(&self, frames: Frames) -> Result<Tensor<4>> {
        match (self, frames) {
            (Observer::Pixels(enc), Frames::Pixels(images)) => {
                let [_, _, c, h, w] = images.dims();
                if c != 3 || [h, w] != enc.image_size {
                    return Err(ModelError::Input(format!(
                        "images {:?}, expected [B, T, 3, {}, {}]",
                        images.dims(),
                        enc.image_size[0],
                        enc.image_size[1]
                    )));
                }
                Ok(enc.forward(images))
            }
            (Observer::State(enc), Frames::State(x, c)) => enc.forward(x, c),
            (Observer::Pixels(_), Frames::State(..)) => Err(ModelError::Input(
                "the model reads pixels but was given object state".into(),
            )),
            (Observer::State(_), Frames::Pixels(_)) => Err(ModelError::Input(
                "the model reads object state but was given pixels".into(),
            )),
        }
    }
}

/// Object-state encoder: token i → LN(W x_i + s·E[c_i]) → MLP, x_i the F numbers of
/// [`crate::io::state`], c_i its category and s the configured category scale
/// ([`crate::config::EncoderConfig::category_scale`]).
///
/// With s = 1 the N(0, 1) category embedding is most of what the LayerNorm sees: a bowl that
/// lies 5 cm elsewhere moves its standardised offset by about a quarter, a few per cent of the
/// normalised token, and the micro state models learnt one reach for every scene (T1's first
/// action the same in every training episode after 3 000 steps; measured in the README).
#[derive(Module, Debug)]
pub struct StateEncoder {
    /// Category embeddings `[C, D_f]`.
    pub category: Embedding,
    /// Features to width `[F, D_f]`.
    pub input: Linear,
    /// Norm `[D_f]`.
    pub norm: LayerNorm,
    /// MLP D_f → D_f → D_f.
    pub mlp: Mlp,
    /// Tokens per frame N.
    pub tokens: usize,
    /// Factor s on the category embedding.
    pub category_scale: f64,
}

impl StateEncoder {
    /// An encoder of `tokens` tokens of `features` numbers over `categories` categories into
    /// width `d_f`, the category embedding at `category_scale`.
    pub fn new(
        tokens: usize,
        categories: usize,
        features: usize,
        d_f: usize,
        category_scale: f64,
        device: &Device,
    ) -> Self {
        StateEncoder {
            category: EmbeddingConfig::new(categories, d_f).init(device),
            input: LinearConfig::new(features, d_f).init(device),
            norm: layer_norm(d_f, device),
            mlp: Mlp::new(d_f, d_f, d_f, Act::Relu, device),
            tokens,
            category_scale,
        }
    }

    /// Encodes the tokens of a window.
    ///
    /// # Shapes
    /// - features: `[B, T, N, F]`; categories: `[B, T, N]`
    /// - output: `[B, T, N, D_f]`
    pub fn forward(&self, features: Tensor<4>, categories: Tensor<3, Int>) -> Result<Tensor<4>> {
        let [b, t, n, f] = features.dims();
        let [nf, d_f] = self.input.weight.dims();
        if n != self.tokens || f != nf || categories.dims() != [b, t, n] {
            return Err(ModelError::Input(format!(
                "state features {:?} / categories {:?}, expected [B, T, {}, {nf}] / [B, T, {}]",
                features.dims(),
                categories.dims(),
                self.tokens,
                self.tokens
            )));
        }
        let e = self
            .category
            .forward(categories.reshape([b * t, n]))
            .reshape([b, t, n, d_f]);
        // × 1 is exact, so runs without the option keep their numbers bit for bit.
        let x = self.input.forward(features) + e.mul_scalar(self.category_scale);
        Ok(self.mlp.forward(self.norm.forward(x)))
    }
}

/// ImageNet channel means.
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations.
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// CNN encoder mapping RGB frames in [0, 1] to M visual tokens of width D_f.
#[derive(Module, Debug)]
pub struct VisualEncoder {
    /// 5×5 convs with padding 2, ReLU after each.
    pub convs: Vec<Conv2d>,
    /// Final 3×3 stride-1 conv to D_f channels, ReLU.
    pub last: Conv2d,
    /// Soft position embedding `[4, D_f]` of the grid [x, y, 1−x, 1−y].
    pub pos: Linear,
    /// Norm `[D_f]`.
    pub norm: LayerNorm,
    /// MLP D_f → D_f → D_f.
    pub mlp: Mlp,
    /// Feature grid [gh, gw].
    pub grid: [usize; 2],
    /// Expected image size [H, W].
    pub image_size: [usize; 2],
}

impl VisualEncoder {
    /// Builds the encoder of `config`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let enc = &config.encoder;
        let mut convs = Vec::new();
        let mut c_in = 3;
        for (&c, &s) in enc.channels.iter().zip(&enc.strides) {
            convs.push(
                Conv2dConfig::new([c_in, c], [5, 5])
                    .with_stride([s, s])
                    .with_padding(PaddingConfig2d::Explicit(2, 2, 2, 2))
                    .init(device),
            );
            c_in = c;
        }
        let d_f = enc.feature_dim;
        let last = Conv2dConfig::new([c_in, d_f], [3, 3])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(device);
        VisualEncoder {
            convs,
            last,
            pos: LinearConfig::new(4, d_f).init(device),
            norm: layer_norm(d_f, device),
            mlp: Mlp::new(d_f, d_f, d_f, Act::Relu, device),
            grid: config.grid(),
            image_size: config.image_size,
        }
    }

    /// The position grid `[M, 4]` with rows [x, y, 1−x, 1−y], x and y in [0, 1].
    fn grid_tensor(&self, device: &Device) -> Tensor<2> {
        let [gh, gw] = self.grid;
        let lin = |i: usize, n: usize| {
            if n > 1 {
                i as f32 / (n - 1) as f32
            } else {
                0.5
            }
        };
        let mut data = Vec::with_capacity(gh * gw * 4);
        for r in 0..gh {
            for c in 0..gw {
                let (x, y) = (lin(c, gw), lin(r, gh));
                data.extend_from_slice(&[x, y, 1.0 - x, 1.0 - y]);
            }
        }
        Tensor::from_data(TensorData::new(data, [gh * gw, 4]), device)
    }

    /// Encodes frames.
    ///
    /// # Shapes
    /// - images: `[N, 3, H, W]`, RGB in [0, 1] (ImageNet normalisation happens here)
    /// - output: `[N, M, D_f]`
    pub fn forward_frames(&self, images: Tensor<4>) -> Tensor<3> {
        let [h, w] = self.image_size;
        assert_shape!(images, [_, 3, h, w]);
        let device = images.device();
        let n = images.dims()[0];
        let mean = Tensor::<1>::from_floats(IMAGENET_MEAN, &device).reshape([1, 3, 1, 1]);
        let std = Tensor::<1>::from_floats(IMAGENET_STD, &device).reshape([1, 3, 1, 1]);
        let mut x = (images - mean) / std;
        for (i, conv) in self.convs.iter().enumerate() {
            // The first conv reads the images, which need no gradient: as one matmul over
            // their patches, its backward is a single matmul for the weights (Burn's conv2d
            // computes that gradient as a convolution, 3–10× slower at these sizes).
            x = relu(if i == 0 {
                conv_as_matmul(conv, x)
            } else {
                conv.forward(x)
            });
        }
        let x = relu(self.last.forward(x));
        let [_, d_f, gh, gw] = x.dims();
        debug_assert_eq!([gh, gw], self.grid);
        let x = x.reshape([n, d_f, gh * gw]).swap_dims(1, 2);
        let x = x + self.pos.forward(self.grid_tensor(&device)).unsqueeze_dim(0);
        self.mlp.forward(self.norm.forward(x))
    }

    /// Encodes a window of frames.
    ///
    /// # Shapes
    /// - images: `[B, T, 3, H, W]` in [0, 1]
    /// - output: `[B, T, M, D_f]`
    pub fn forward(&self, images: Tensor<5>) -> Tensor<4> {
        let [b, t, c, h, w] = images.dims();
        let f = self.forward_frames(images.reshape([b * t, c, h, w]));
        let [_, m, d_f] = f.dims();
        f.reshape([b, t, m, d_f])
    }
}

/// A 2-D convolution (groups 1, dilation 1, symmetric explicit padding) as a matmul over the
/// input's patches (im2col: on the flex backend, for an input without gradient, copied on the
/// host by [`host_patches`]; otherwise a strided view of the padded input, copied once). The same
/// function as `conv.forward(x)` up to float rounding; meant for an input that needs no gradient
/// (its patches' backward would be a slice-by-slice fold). Any other convolution (groups,
/// dilation, other padding) is `conv.forward(x)`.
///
/// # Shapes
/// - x: `[N, C, H, W]` → `[N, C_out, H_out, W_out]`
pub fn conv_as_matmul(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let [c_out, c_in, kh, kw] = conv.weight.dims();
    let [sh, sw] = conv.stride;
    let pads = match conv.padding {
        PaddingConfig2d::Explicit(top, left, bottom, right) if top == bottom && left == right => {
            Some([top, left])
        }
        PaddingConfig2d::Valid => Some([0, 0]),
        _ => None,
    };
    let Some([ph, pw]) = pads.filter(|_| c == c_in && conv.groups == 1 && conv.dilation == [1, 1])
    else {
        return conv.forward(x);
    };
    let geometry = PatchGeometry {
        kernel: [kh, kw],
        stride: [sh, sw],
        padding: [ph, pw],
    };
    let [ho, wo] = geometry.output([h, w]);
    let patches = if x.device().inner() == Device::flex() && !x.is_require_grad() {
        host_patches(x, &geometry)
    } else {
        unfolded_patches(x, &geometry)
    };
    // W [C_out, C·kh·kw] times each frame's patches: the output comes out contiguous in NCHW
    // order, as the next conv reads it.
    let weight = conv.weight.val().reshape([1, c_out, c * kh * kw]);
    let mut y = weight.matmul(patches); // [N, C_out, Ho·Wo]
    if let Some(b) = &conv.bias {
        y = y + b.val().reshape([1, c_out, 1]);
    }
    y.reshape([n, c_out, ho, wo])
}

/// Kernel, stride and (symmetric) padding of a patch extraction.
struct PatchGeometry {
    kernel: [usize; 2],
    stride: [usize; 2],
    padding: [usize; 2],
}

impl PatchGeometry {
    /// The output grid [Ho, Wo] over an input of [H, W].
    fn output(&self, [h, w]: [usize; 2]) -> [usize; 2] {
        let ([kh, kw], [sh, sw], [ph, pw]) = (self.kernel, self.stride, self.padding);
        [(h + 2 * ph - kh) / sh + 1, (w + 2 * pw - kw) / sw + 1]
    }
}

/// The patches of [`conv_as_matmul`] as a strided view of the padded input, copied once (any
/// backend; gradients flow through it).
///
/// # Shapes
/// - x: `[N, C, H, W]` → `[N, C·kh·kw, Ho·Wo]`
fn unfolded_patches(x: Tensor<4>, g: &PatchGeometry) -> Tensor<3> {
    let [n, c, h, w] = x.dims();
    let ([kh, kw], [sh, sw], [ph, pw]) = (g.kernel, g.stride, g.padding);
    let [ho, wo] = g.output([h, w]);
    x.pad([(ph, ph), (pw, pw)], PadMode::Constant(0.0)) // [N, C, H+2p, W+2p]
        .unfold::<5, _>(2, kh, sh) // [N, C, Ho, W+2p, kh]
        .unfold::<6, _>(3, kw, sw) // [N, C, Ho, Wo, kh, kw]
        .permute([0, 1, 4, 5, 2, 3])
        .reshape([n, c * kh * kw, ho * wo])
}

/// The patches of [`conv_as_matmul`] copied on the host, for a tensor on the CPU backend: flex's
/// strided copy of the unfolded view took 57–79 ms for a t3 batch (128 frames, 64², 5×5 stride 2)
/// where this loop takes a few; the same numbers (pure copies, zeros for the padding). The input
/// leaves any autodiff graph (the caller's input needs no gradient).
///
/// # Shapes
/// - x: `[N, C, H, W]` → `[N, C·kh·kw, Ho·Wo]`
fn host_patches(x: Tensor<4>, g: &PatchGeometry) -> Tensor<3> {
    let device = x.device();
    let [n, c, h, w] = x.dims();
    let ([kh, kw], [sh, sw], [ph, pw]) = (g.kernel, g.stride, g.padding);
    let [ho, wo] = g.output([h, w]);
    let src = x
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("data converted to f32 reads as f32");
    let mut out = vec![0.0f32; n * c * kh * kw * ho * wo];
    for (frame, dst) in out.chunks_mut(c * kh * kw * ho * wo).enumerate() {
        let frame_src = &src[frame * c * h * w..(frame + 1) * c * h * w];
        for (row, dst_row) in dst.chunks_mut(ho * wo).enumerate() {
            // row = (channel, ky, kx) in the weight's flattening order
            let (ch, ky, kx) = (row / (kh * kw), row / kw % kh, row % kw);
            let plane = &frame_src[ch * h * w..(ch + 1) * h * w];
            for oy in 0..ho {
                let Some(iy) = (oy * sh + ky).checked_sub(ph).filter(|&iy| iy < h) else {
                    continue; // a padding row: zeros
                };
                let src_row = &plane[iy * w..(iy + 1) * w];
                let dst_line = &mut dst_row[oy * wo..(oy + 1) * wo];
                for (ox, d) in dst_line.iter_mut().enumerate() {
                    if let Some(ix) = (ox * sw + kx).checked_sub(pw).filter(|&ix| ix < w) {
                        *d = src_row[ix];
                    }
                }
            }
        }
    }
    Tensor::from_data(TensorData::new(out, [n, c * kh * kw, ho * wo]), &device)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::test_device;
    use burn::tensor::Distribution;

    #[test]
    fn conv_as_matmul_equals_conv2d_with_gradients() {
        let (_guard, device) = crate::test_autodiff_device();
        for (c_in, side, k, stride, pad) in [(3, 16, 5, 2, 2), (4, 9, 3, 1, 1), (2, 8, 3, 2, 0)] {
            let padding = if pad == 0 {
                PaddingConfig2d::Valid
            } else {
                PaddingConfig2d::Explicit(pad, pad, pad, pad)
            };
            let conv = Conv2dConfig::new([c_in, 6], [k, k])
                .with_stride([stride, stride])
                .with_padding(padding)
                .init(&device);
            let x = Tensor::<4>::random([2, c_in, side, side], Distribution::Default, &device);
            let a = conv_as_matmul(&conv, x.clone());
            let b = conv.forward(x);
            assert_eq!(a.dims(), b.dims());
            let diff = (a.clone() - b.clone()).abs().max().into_scalar::<f32>();
            assert!(diff < 1e-5, "outputs differ by {diff}");
            let ga = a.powi_scalar(2).sum().backward();
            let gb = b.powi_scalar(2).sum().backward();
            let w = |g| conv.weight.val().grad(g).expect("weight gradient");
            let bias = |g| {
                conv.bias
                    .as_ref()
                    .unwrap()
                    .val()
                    .grad(g)
                    .expect("bias gradient")
            };
            let rel = |p: Tensor<4>, q: Tensor<4>| {
                let scale = q.clone().abs().max().into_scalar::<f32>();
                (p - q).abs().max().into_scalar::<f32>() / scale
            };
            assert!(rel(w(&ga), w(&gb)) < 1e-5, "weight gradients differ");
            let db = (bias(&ga) - bias(&gb)).abs().max().into_scalar::<f32>();
            assert!(db < 1e-3, "bias gradients differ by {db}");
        }
    }

    /// The host copy of the patches is the unfolded view's, number for number (padding,
    /// strides, rectangular kernels and images).
    #[test]
    fn host_patches_equal_the_unfolded_view() {
        let (_guard, device) = test_device();
        for (c, [h, w], [kh, kw], [sh, sw], [ph, pw]) in [
            (3, [16, 16], [5, 5], [2, 2], [2, 2]),
            (2, [9, 7], [3, 2], [1, 2], [1, 0]),
            (1, [8, 8], [3, 3], [3, 1], [0, 1]),
        ] {
            let x = Tensor::<4>::random([2, c, h, w], Distribution::Default, &device);
            let geometry = PatchGeometry {
                kernel: [kh, kw],
                stride: [sh, sw],
                padding: [ph, pw],
            };
            let [ho, wo] = geometry.output([h, w]);
            let want = unfolded_patches(x.clone(), &geometry);
            let got = host_patches(x, &geometry);
            assert_eq!(got.dims(), [2, c * kh * kw, ho * wo]);
            assert_eq!(got.dims(), want.dims());
            got.into_data().assert_eq(&want.into_data(), true);
        }
    }

    #[test]
    fn tiny_encoder_output_shape() {
        let (_guard, device) = test_device();
        let cfg = ModelConfig::tiny(Variant::Dense { history: 1 });
        let enc = VisualEncoder::new(&cfg, &device);
        let x = Tensor::<5>::random([2, 3, 3, 64, 64], Distribution::Default, &device);
        assert_eq!(enc.forward(x).dims(), [2, 3, 64, 64]);
    }

    #[test]
    fn small_images_give_a_smaller_grid() {
        let (_guard, device) = test_device();
        let mut cfg = ModelConfig::tiny(Variant::Dense { history: 1 });
        cfg.image_size = [32, 32];
        let enc = VisualEncoder::new(&cfg, &device);
        assert_eq!(cfg.grid(), [4, 4]);
        let x = Tensor::<4>::random([1, 3, 32, 32], Distribution::Default, &device);
        assert_eq!(enc.forward_frames(x).dims(), [1, 16, 64]);
    }

    #[test]
    fn state_encoder_tells_categories_apart() {
        use crate::io::state::FEATURES;
        let (_guard, device) = test_device();
        let enc = StateEncoder::new(3, 6, FEATURES, 16, 1.0, &device);
        let x = Tensor::<4>::ones([1, 1, 3, FEATURES], &device);
        let c = Tensor::<3, Int>::from_data(TensorData::new(vec![3i64, 4, 3], [1, 1, 3]), &device);
        let y = enc.forward(x, c).unwrap().reshape([3, 16]);
        let d = |i: usize, j: usize| -> f32 {
            (y.clone().narrow(0, i, 1) - y.clone().narrow(0, j, 1))
                .abs()
                .sum()
                .into_scalar()
        };
        assert!(d(0, 1) > 1e-3, "different categories, same features");
        assert_eq!(d(0, 2), 0.0, "same category, same features");
    }

    #[test]
    fn category_scale_weighs_the_embedding_against_the_numbers() {
        use crate::io::state::FEATURES;
        let (_guard, device) = test_device();
        let enc = StateEncoder::new(2, 6, FEATURES, 16, 1.0, &device);
        // Two tokens of one category whose numbers differ: how far apart are their normalised
        // sums (the LayerNorm's output, before the MLP)?
        let mut v = vec![0.0f32; 2 * FEATURES];
        v[FEATURES] = 0.5;
        let x = Tensor::<4>::from_data(TensorData::new(v, [1, 1, 2, FEATURES]), &device);
        let c = Tensor::<3, Int>::from_data(TensorData::new(vec![3i64, 3], [1, 1, 2]), &device);
        // The LayerNorm's output `[1, 2, D_f]` with the embedding at `scale`, computed by hand.
        let normed = |scale: f64| {
            let e = enc.category.forward(c.clone().reshape([1, 2]));
            let h = enc.input.forward(x.clone()).reshape([1, 2, 16]) + e.mul_scalar(scale);
            enc.norm.forward(h)
        };
        let spread = |scale: f64| -> f32 {
            let y = normed(scale).reshape([2, 16]);
            (y.clone().narrow(0, 0, 1) - y.narrow(0, 1, 1))
                .abs()
                .sum()
                .into_scalar()
        };
        // The encoder's own forward at scale s equals the sum computed with s.
        let scaled = StateEncoder {
            category_scale: 0.1,
            ..enc.clone()
        };
        let direct = scaled.forward(x.clone(), c.clone()).unwrap();
        let by_hand = enc.mlp.forward(normed(0.1)).reshape([1, 1, 2, 16]);
        let diff: f32 = (direct - by_hand).abs().max().into_scalar();
        assert!(diff < 1e-6, "forward at scale 0.1 differs by {diff}");
        // A smaller embedding leaves the numbers more of the normalised token.
        assert!(
            spread(0.1) > 2.0 * spread(1.0),
            "{} vs {}",
            spread(0.1),
            spread(1.0)
        );
    }
}
