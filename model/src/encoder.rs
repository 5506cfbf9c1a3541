//! Visual encoder (model.md §1): a small CNN, a soft position embedding, LN and an MLP.

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{LayerNorm, Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::relu;

use crate::blocks::{Act, Mlp, layer_norm};
use crate::config::ModelConfig;

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
        for conv in &self.convs {
            x = relu(conv.forward(x));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::test_device;
    use burn::tensor::Distribution;

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
}
