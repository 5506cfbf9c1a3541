//! Relation Encoder (model.md §7): L relation tokens that cross-attend to the visual patches and
//! to the slot latents z_t.

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;

use crate::blocks::{CrossAttnBlock, FfnBlock};
use crate::config::ModelConfig;

/// One relation layer: cross-attention to patches, cross-attention to slots, FFN.
#[derive(Module, Debug)]
pub struct RelationLayer {
    /// R += MHA(LN(R), LN(W_f F)).
    pub to_patches: CrossAttnBlock,
    /// R += MHA(LN(R), LN(z)).
    pub to_slots: CrossAttnBlock,
    /// R += FFN(LN(R)).
    pub ffn: FfnBlock,
}

/// The relation encoder.
#[derive(Module, Debug)]
pub struct RelationEncoder {
    /// Learned relation embeddings E_rel `[L, D]`.
    pub tokens: Param<Tensor<2>>,
    /// W_z `[D, D]`, added per slot when L = K.
    pub slot_init: Option<Linear>,
    /// W_f `[D_f, D]`.
    pub feat_proj: Linear,
    /// Layers.
    pub layers: Vec<RelationLayer>,
}

impl RelationEncoder {
    /// Builds the encoder of `config`.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let d = config.slots.dim;
        let rel = &config.relation;
        RelationEncoder {
            tokens: Param::from_tensor(Tensor::random(
                [rel.tokens, d],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
            slot_init: (rel.tokens == config.slots.num_slots)
                .then(|| LinearConfig::new(d, d).init(device)),
            feat_proj: LinearConfig::new(config.encoder.feature_dim, d).init(device),
            layers: (0..rel.layers)
                .map(|_| RelationLayer {
                    to_patches: CrossAttnBlock::new(d, rel.heads, device),
                    to_slots: CrossAttnBlock::new(d, rel.heads, device),
                    ffn: FfnBlock::new(d, 4 * d, device),
                })
                .collect(),
        }
    }

    /// # Shapes
    /// - feats: `[N, M, D_f]`, z: `[N, K, D]` (N = frames)
    /// - output: `[N, L, D]`
    pub fn forward(&self, feats: Tensor<3>, z: Tensor<3>) -> Tensor<3> {
        let [n, k, d] = z.dims();
        let [l, _] = self.tokens.dims();
        let mut r = self.tokens.val().unsqueeze_dim::<3>(0).repeat_dim(0, n);
        if let Some(w) = &self.slot_init {
            debug_assert_eq!(l, k);
            r = r + w.forward(z.clone());
        }
        let f = self.feat_proj.forward(feats);
        for layer in &self.layers {
            r = layer.to_patches.forward(r, f.clone());
            r = layer.to_slots.forward(r, z.clone());
            r = layer.ffn.forward(r);
        }
        assert_shape!(r, [n, l, d]);
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Variant;
    use crate::test_device;

    #[test]
    fn relation_tokens_shape_with_and_without_slot_init() {
        let (_guard, device) = test_device();
        let mut cfg = ModelConfig::tiny(Variant::SlotVla { history: 1 });
        let f = Tensor::<3>::random([3, 64, 64], Distribution::Default, &device);
        let z = Tensor::<3>::random([3, 8, 64], Distribution::Default, &device);
        let enc = RelationEncoder::new(&cfg, &device);
        assert!(enc.slot_init.is_some());
        assert_eq!(enc.forward(f.clone(), z.clone()).dims(), [3, 8, 64]);
        cfg.relation.tokens = 5;
        let enc = RelationEncoder::new(&cfg, &device);
        assert!(enc.slot_init.is_none());
        assert_eq!(enc.forward(f, z).dims(), [3, 5, 64]);
    }
}
