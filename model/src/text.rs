//! Language: learned word embeddings over the task vocabulary (model.md §8); the ids come from
//! [`crate::io::Tokenizer`] (0 = padding, 1 = unknown word, word i of the vocabulary = i + 2).
//! The instruction gives the decoder's language tokens; a subgoal text is mean-pooled into one
//! embedding g.

use burn::module::Param;
use burn::nn::{Embedding, EmbeddingConfig};
use burn::prelude::*;
use burn::tensor::Distribution;

use crate::config::TextConfig;

/// Padding id.
pub const PAD: i64 = data::text::PAD as i64;
/// Learned word embeddings with learned positions.
#[derive(Module, Debug)]
pub struct TextEncoder {
    /// Word embeddings `[V, D_txt]`.
    pub embed: Embedding,
    /// Positions `[max_len, D_txt]` (used for the token sequence, not the pooled vector).
    pub pos: Param<Tensor<2>>,
}

impl TextEncoder {
    /// Builds embeddings of width `d` for the vocabulary of `config`.
    pub fn new(config: &TextConfig, d: usize, device: &Device) -> Self {
        TextEncoder {
            embed: EmbeddingConfig::new(config.vocab.len() + 2, d).init(device),
            pos: Param::from_tensor(Tensor::random(
                [config.max_len, d],
                Distribution::Normal(0.0, 0.02),
                device,
            )),
        }
    }

    /// Token embeddings with positions, and the padding mask.
    ///
    /// # Shapes
    /// - ids: `[N, L]` (L ≤ max_len)
    /// - output: (`[N, L, D_txt]`, pad `[N, L]` true = padding)
    pub fn tokens(&self, ids: Tensor<2, Int>) -> (Tensor<3>, Tensor<2, Bool>) {
        let [_, l] = ids.dims();
        let [max_len, d] = self.pos.dims();
        assert!(l <= max_len, "{l} tokens > max_len {max_len}");
        let pad = ids.clone().equal_elem(PAD);
        let x = self.embed.forward(ids) + self.pos.val().narrow(0, 0, l).reshape([1, l, d]);
        (x, pad)
    }

    /// Mean of the word embeddings of the non-padding tokens (zeros for an empty text).
    ///
    /// # Shapes
    /// - ids: `[N, L]` → `[N, D_txt]`
    pub fn pooled(&self, ids: Tensor<2, Int>) -> Tensor<2> {
        let keep = ids
            .clone()
            .not_equal_elem(PAD)
            .float()
            .unsqueeze_dim::<3>(2); // [N, L, 1]
        let x = self.embed.forward(ids) * keep.clone();
        let count = keep.sum_dim(1).clamp_min(1.0); // [N, 1, 1]
        (x.sum_dim(1) / count).squeeze_dim::<2>(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Tokenizer;
    use crate::io::tests::cfg;
    use crate::test_device;

    #[test]
    fn encoder_shapes_mask_and_pooling() {
        let (_guard, device) = test_device();
        let tok = Tokenizer::new(&cfg());
        let enc = TextEncoder::new(&cfg(), 4, &device);
        let ids = tok.encode_batch(&["put the bowl", ""], &device);
        let (x, pad) = enc.tokens(ids.clone());
        assert_eq!(x.dims(), [2, 6, 4]);
        let pad = pad.into_data().try_to_vec::<bool>().unwrap();
        assert_eq!(&pad[..6], &[false, false, false, true, true, true]);
        let pooled = enc.pooled(ids);
        assert_eq!(pooled.dims(), [2, 4]);
        // Pooled = mean of the three word embeddings; the empty text pools to zeros.
        let w = enc.embed.weight.val();
        let want = (w.clone().narrow(0, 5, 1) + w.clone().narrow(0, 6, 1) + w.narrow(0, 2, 1))
            .div_scalar(3.0);
        let diff: f32 = (pooled.clone().narrow(0, 0, 1) - want)
            .abs()
            .max()
            .into_scalar();
        assert!(diff < 1e-6);
        let empty: f32 = pooled.narrow(0, 1, 1).abs().max().into_scalar();
        assert_eq!(empty, 0.0);
    }
}
