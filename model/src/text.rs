//! Language: learned word embeddings over the task vocabulary (model.md §8); the ids come from
//! [`crate::io::Tokenizer`] (0 = padding, 1 = unknown word, word i of the vocabulary = i + 2).
//! The instruction gives the decoder's language tokens; a subgoal text is read as its ordered
//! token sequence ([`TextEncoder::sequence`]), so word order matters ("bowl 2 on plate 1" ≠
//! "bowl 1 on plate 2").

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
    /// Positions `[max_len, D_txt]`.
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

    /// The ordered token sequence of a text, flattened: word + position embedding per token,
    /// zeros at padding (an empty text is all zeros).
    ///
    /// # Shapes
    /// - ids: `[N, L]` → `[N, L · D_txt]`
    pub fn sequence(&self, ids: Tensor<2, Int>) -> Tensor<2> {
        let [n, l] = ids.dims();
        let keep = ids
            .clone()
            .not_equal_elem(PAD)
            .float()
            .unsqueeze_dim::<3>(2); // [N, L, 1]
        let (x, _) = self.tokens(ids);
        let [_, _, d] = x.dims();
        (x * keep).reshape([n, l * d])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Tokenizer;
    use crate::io::tests::cfg;
    use crate::test_device;

    #[test]
    fn encoder_shapes_mask_and_ordered_sequence() {
        let (_guard, device) = test_device();
        let tok = Tokenizer::new(&cfg());
        let enc = TextEncoder::new(&cfg(), 4, &device);
        let ids = tok.encode_batch(&["put the bowl", ""], &device);
        let (x, pad) = enc.tokens(ids.clone());
        assert_eq!(x.dims(), [2, 6, 4]);
        let pad = pad.into_data().try_to_vec::<bool>().unwrap();
        assert_eq!(&pad[..6], &[false, false, false, true, true, true]);
        let seq = enc.sequence(ids.clone());
        assert_eq!(seq.dims(), [2, 24]);
        // Token i of the text = word i + position i; padding and the empty text are zeros.
        let (x, _) = enc.tokens(ids);
        let want = x.narrow(0, 0, 1).narrow(1, 0, 3).reshape([1, 12]);
        let diff: f32 = (seq.clone().narrow(0, 0, 1).narrow(1, 0, 12) - want)
            .abs()
            .max()
            .into_scalar();
        assert!(diff < 1e-6);
        let rest: f32 = seq
            .clone()
            .narrow(0, 0, 1)
            .narrow(1, 12, 12)
            .abs()
            .max()
            .into_scalar();
        assert_eq!(rest, 0.0);
        let empty: f32 = seq.narrow(0, 1, 1).abs().max().into_scalar();
        assert_eq!(empty, 0.0);
        // Word order matters: the same words in another order give another sequence.
        let a = enc.sequence(tok.encode_batch(&["bowl on plate"], &device));
        let b = enc.sequence(tok.encode_batch(&["plate on bowl"], &device));
        let d: f32 = (a - b).abs().max().into_scalar();
        assert!(d > 1e-4);
    }
}
