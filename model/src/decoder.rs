//! Action decoder (model.md §8): a bidirectional pre-LN transformer over
//! [visual tokens ; language tokens ; action queries] — H_a·A queries, one per action value, or
//! H_a, one per chunk step ([`QueryLayout`]) —, then a continuous L1 chunk head (MLP-ResNet,
//! OpenVLA-OFT) or a 256-bin classification head (OpenVLA).

use burn::module::Param;
use burn::nn::{Initializer, LayerNorm, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;
use burn::tensor::activation::{gelu, softmax};

use crate::blocks::{FfnBlock, SelfAttnBlock, layer_norm};
use crate::config::{ActionHead, DecoderConfig, QueryLayout};

/// Number of classes of the discrete head (bins 1..=256 of numpy's digitize).
pub const NUM_BINS: usize = 256;

/// Class (0..=255) of a normalised action value: digitize(clip(a, −1, 1), linspace(−1, 1, 256)) − 1.
pub fn action_to_class(a: f32) -> usize {
    let a = a.clamp(-1.0, 1.0);
    (((a + 1.0) * 127.5).floor() as usize).min(NUM_BINS - 1)
}

/// Action value of a class: the centre of bin min(class, 254) (255 centres between 256 edges).
pub fn class_to_action(class: usize) -> f32 {
    let c = class.min(NUM_BINS - 2) as f32;
    let lo = -1.0 + 2.0 * c / 255.0;
    lo + 1.0 / 255.0
}

/// Tensor form of [`action_to_class`].
///
/// # Shapes
/// - actions: any → same, Int
pub fn actions_to_classes<const D: usize>(actions: Tensor<D>) -> Tensor<D, Int> {
    actions
        .clamp(-1.0, 1.0)
        .add_scalar(1.0)
        .mul_scalar(127.5)
        .floor()
        .int()
        .clamp(0, NUM_BINS as i64 - 1)
}

/// Tensor form of [`class_to_action`].
///
/// # Shapes
/// - classes: any → same, Float
pub fn classes_to_actions<const D: usize>(classes: Tensor<D, Int>) -> Tensor<D> {
    classes
        .clamp(0, NUM_BINS as i64 - 2)
        .float()
        .mul_scalar(2.0 / 255.0)
        .add_scalar(-1.0 + 1.0 / 255.0)
}

/// One encoder layer: self-attention and FFN, both pre-LN residual.
#[derive(Module, Debug)]
pub struct DecoderLayer {
    /// Self-attention.
    pub attn: SelfAttnBlock,
    /// Feed-forward (hidden 4·D_dec).
    pub ffn: FfnBlock,
}

/// Pre-LN residual block of the MLP-ResNet head.
#[derive(Module, Debug)]
pub struct ResBlock {
    /// Norm `[D_dec]`.
    pub norm: LayerNorm,
    /// `[D_dec, D_dec]`.
    pub fc1: Linear,
    /// `[D_dec, D_dec]`.
    pub fc2: Linear,
}

/// Continuous chunk head: per chunk step [A·D_dec] (value queries) or [D_dec] (step queries)
/// → Linear → 2 residual blocks → LN → Linear → A.
#[derive(Module, Debug)]
pub struct L1Head {
    /// `[A·D_dec, D_dec]` (value queries) or `[D_dec, D_dec]` (step queries).
    pub input: Linear,
    /// Residual blocks.
    pub blocks: Vec<ResBlock>,
    /// Final norm.
    pub norm: LayerNorm,
    /// `[D_dec, A]`.
    pub output: Linear,
}

/// Output of the decoder for N frames.
#[derive(Clone, Debug)]
pub struct DecoderOutput {
    /// Normalised action chunk `[N, H_a, A]` (bin centres for the discrete head).
    pub actions: Tensor<3>,
    /// Logits `[N, H_a, A, 256]` (discrete head only).
    pub logits: Option<Tensor<4>>,
    /// The normed outputs of the action queries `[N, Q, D_dec]`.
    pub queries: Tensor<3>,
    /// The last layer's outputs at the visual tokens `[N, V, D_dec]` (before the final norm;
    /// computed only for a decoder built with `pointer`, which reads them).
    pub visual: Option<Tensor<3>>,
    /// The pointer head's weights over the state tokens `[N, H_a, K]` (set by the policy when
    /// it has the head; see [`PointerHead::weights`]).
    pub pointer: Option<Tensor<3>>,
}

/// Pointer head (state mode): per chunk step h, attention weights a_h over the current frame's
/// K state tokens — objects, parts and the robot, padding excluded — (query: step h's decoder
/// output; keys: the tokens' decoder outputs), and the action term Σ_k a_hk · (W_v x_k + b_v),
/// x_k token k's own input numbers (`[F]`, standardised: its offset to the gripper among them).
/// Moving to an object is then choosing its token, and the offset it is read from is exact
/// instead of regressed through the network. W_v and b_v start at zero, so the head starts as
/// no term at all.
#[derive(Module, Debug)]
pub struct PointerHead {
    /// Norm of the token outputs `[D_dec]`.
    pub norm: LayerNorm,
    /// Query map `[D_dec, D_dec]`.
    pub query: Linear,
    /// Key map `[D_dec, D_dec]`.
    pub key: Linear,
    /// Value map `[F, A]` (zero-initialised).
    pub value: Linear,
    /// Key map of the tokens' input numbers `[F, D_dec]` (`decoder.pointer_input_keys`).
    pub input_key: Option<Linear>,
}

impl PointerHead {
    /// A head over tokens of `features` numbers for actions of `action_dim` values at width `w`;
    /// with `input_keys`, keys also read the tokens' input numbers.
    pub fn new(
        w: usize,
        features: usize,
        action_dim: usize,
        input_keys: bool,
        device: &Device,
    ) -> Self {
        PointerHead {
            input_key: input_keys.then(|| LinearConfig::new(features, w).init(device)),
            norm: layer_norm(w, device),
            query: LinearConfig::new(w, w).init(device),
            key: LinearConfig::new(w, w).init(device),
            value: LinearConfig::new(features, action_dim)
                .with_initializer(Initializer::Zeros)
                .init(device),
        }
    }

    /// The pointer's attention weights over the tokens.
    ///
    /// # Shapes
    /// - queries: `[N, H_a, D_dec]`; tokens: `[N, K, D_dec]`; features: `[N, K, F]`;
    ///   pad: `[N, K]` (true = padding)
    /// - output: `[N, H_a, K]`, each row summing to 1 over the unpadded tokens
    pub fn weights(
        &self,
        queries: Tensor<3>,
        tokens: Tensor<3>,
        features: Tensor<3>,
        pad: Tensor<2, Bool>,
    ) -> Tensor<3> {
        let [n, h, w] = queries.dims();
        let [_, k, _] = tokens.dims();
        let q = self.query.forward(queries);
        let mut keys = self.key.forward(self.norm.forward(tokens));
        if let Some(input_key) = &self.input_key {
            keys = keys + input_key.forward(features);
        }
        let logits = q.matmul(keys.swap_dims(1, 2)).div_scalar((w as f32).sqrt()); // [N, H, K]
        let pad = pad.reshape([n, 1, k]).repeat_dim(1, h);
        softmax(logits.mask_fill(pad, -1e9), 2)
    }

    /// The action term of each chunk step for its weights ([`PointerHead::weights`]): Σ_k a_hk (W_v x_k + b_v).
    ///
    /// # Shapes
    /// - weights: `[N, H_a, K]`; features: `[N, K, F]`
    /// - output: `[N, H_a, A]`
    pub fn term(&self, weights: Tensor<3>, features: Tensor<3>) -> Tensor<3> {
        weights.matmul(self.value.forward(features))
    }
}

/// The action decoder.
#[derive(Module, Debug)]
pub struct ActionDecoder {
    /// Segment embeddings of the language and query segments `[2, D_dec]`.
    pub segment: Param<Tensor<2>>,
    /// Learned action queries (with their positions) `[H_a·A, D_dec]` or `[H_a, D_dec]`.
    pub queries: Param<Tensor<2>>,
    /// Transformer layers.
    pub layers: Vec<DecoderLayer>,
    /// Final norm.
    pub norm: LayerNorm,
    /// Continuous head.
    pub l1: Option<L1Head>,
    /// Discrete head `[D_dec, 256]` (value queries) or `[D_dec, A·256]` (step queries).
    pub bins: Option<Linear>,
    /// H_a.
    pub horizon: usize,
    /// A.
    pub action_dim: usize,
    /// One query per chunk step (else one per action value).
    pub step_queries: bool,
    /// FiLM of the visual tokens from the pooled instruction `[D_dec, 2·D_dec]` (γ | β).
    pub film: Option<Linear>,
    /// Whether the last layer's outputs at the visual tokens are kept (for the pointer head);
    /// else the last layer computes the query rows only.
    pub keep_visual: bool,
}

impl ActionDecoder {
    /// Builds the decoder of `config`.
    pub fn new(config: &DecoderConfig, device: &Device) -> Self {
        let w = config.width;
        let (h, a) = (config.horizon, config.action_dim);
        let normal = Distribution::Normal(0.0, 0.02);
        let step = config.queries == QueryLayout::Step;
        let (q, per_query) = if step { (h, a) } else { (h * a, 1) };
        ActionDecoder {
            segment: Param::from_tensor(Tensor::random([2, w], normal, device)),
            queries: Param::from_tensor(Tensor::random([q, w], normal, device)),
            layers: (0..config.layers)
                .map(|_| DecoderLayer {
                    attn: SelfAttnBlock::new(w, config.heads, device),
                    ffn: FfnBlock::new(w, 4 * w, device),
                })
                .collect(),
            norm: layer_norm(w, device),
            l1: (config.head != ActionHead::Bins).then(|| L1Head {
                input: LinearConfig::new(if step { w } else { a * w }, w).init(device),
                blocks: (0..2)
                    .map(|_| ResBlock {
                        norm: layer_norm(w, device),
                        fc1: LinearConfig::new(w, w).init(device),
                        fc2: LinearConfig::new(w, w).init(device),
                    })
                    .collect(),
                norm: layer_norm(w, device),
                output: LinearConfig::new(w, a).init(device),
            }),
            bins: (config.head == ActionHead::Bins)
                .then(|| LinearConfig::new(w, per_query * NUM_BINS).init(device)),
            horizon: h,
            action_dim: a,
            step_queries: step,
            film: config.film.then(|| {
                LinearConfig::new(w, 2 * w)
                    .with_initializer(Initializer::Zeros)
                    .init(device)
            }),
            keep_visual: config.pointer,
        }
    }

    /// The visual tokens modulated by the instruction: x·(1 + γ) + β with [γ | β] a linear map of
    /// the mean of the unpadded language tokens (unchanged without FiLM).
    ///
    /// # Shapes
    /// - visual: `[N, V, D_dec]`; lang: `[N, L_txt, D_dec]`, lang_pad: `[N, L_txt]` → `[N, V, D_dec]`
    fn modulate(&self, visual: Tensor<3>, lang: Tensor<3>, lang_pad: Tensor<2, Bool>) -> Tensor<3> {
        let Some(film) = &self.film else {
            return visual;
        };
        let w = visual.dims()[2];
        let keep = lang_pad.bool_not().float().unsqueeze_dim::<3>(2); // [N, L_txt, 1]
        let pooled = (lang * keep.clone()).sum_dim(1) / keep.sum_dim(1).clamp_min(1.0); // [N, 1, D]
        let gb = film.forward(pooled); // [N, 1, 2·D]
        let gamma = gb.clone().narrow(2, 0, w);
        let beta = gb.narrow(2, w, w);
        visual * (gamma + 1.0) + beta
    }

    /// Width D_dec.
    pub fn width(&self) -> usize {
        self.queries.dims()[1]
    }

    /// Decodes one action chunk per frame.
    ///
    /// # Shapes
    /// - visual: `[N, V, D_dec]` (segment/frame embeddings already added)
    /// - visual_pad: `[N, V]`, true = masked (history frames before the episode start)
    /// - lang: `[N, L_txt, D_dec]`, lang_pad: `[N, L_txt]`
    /// - output: actions `[N, H_a, A]` (+ logits `[N, H_a, A, 256]`)
    pub fn forward(
        &self,
        visual: Tensor<3>,
        visual_pad: Option<Tensor<2, Bool>>,
        lang: Tensor<3>,
        lang_pad: Tensor<2, Bool>,
    ) -> DecoderOutput {
        let [n, v, w] = visual.dims();
        let [_, l_txt, _] = lang.dims();
        assert_shape!(lang, [n, l_txt, w]);
        assert_shape!(lang_pad, [n, l_txt]);
        let (h, a) = (self.horizon, self.action_dim);
        let q = if self.step_queries { h } else { h * a };
        let device = visual.device();
        let visual = self.modulate(visual, lang.clone(), lang_pad.clone());
        let seg = self.segment.val();
        let lang = lang + seg.clone().narrow(0, 0, 1).unsqueeze_dim::<3>(0);
        let queries = (self.queries.val() + seg.narrow(0, 1, 1))
            .unsqueeze_dim::<3>(0)
            .repeat_dim(0, n);
        let x = Tensor::cat(vec![visual, lang, queries], 1);
        let visual_pad =
            visual_pad.unwrap_or_else(|| Tensor::<2>::zeros([n, v], &device).equal_elem(1.0));
        let query_pad = Tensor::<2>::zeros([n, q], &device).equal_elem(1.0);
        let pad = Tensor::cat(vec![visual_pad, lang_pad, query_pad], 1);
        let (last, rest) = match self.layers.split_last() {
            Some((last, rest)) => (Some(last), rest),
            None => (None, &self.layers[..]),
        };
        let mut x = x;
        for layer in rest {
            x = layer.attn.forward(x, Some(pad.clone()));
            x = layer.ffn.forward(x);
        }
        // The rows read after the decoder: the queries, and the visual tokens for the pointer
        // head. The last layer computes only those (the language rows' outputs would be dropped).
        let queries = x.clone().narrow(1, v + l_txt, q);
        let read = if self.keep_visual {
            Tensor::cat(vec![x.clone().narrow(1, 0, v), queries], 1)
        } else {
            queries
        };
        let read = match last {
            Some(layer) => layer
                .ffn
                .forward(layer.attn.forward_rows(x, read, Some(pad.clone()))),
            None => read,
        };
        let (hidden, out) = if self.keep_visual {
            (Some(read.clone().narrow(1, 0, v)), read.narrow(1, v, q)) // [N, V, D_dec], [N, Q, D_dec]
        } else {
            (None, read)
        };
        let out = self.norm.forward(out); // [N, Q, D_dec]
        let queries_out = out.clone();
        if let Some(head) = &self.l1 {
            let per_step = if self.step_queries { w } else { a * w };
            let mut y = head.input.forward(out.reshape([n, h, per_step]));
            for blk in &head.blocks {
                let r = blk
                    .fc2
                    .forward(gelu(blk.fc1.forward(blk.norm.forward(y.clone()))));
                y = y + r;
            }
            DecoderOutput {
                actions: head.output.forward(head.norm.forward(y)),
                logits: None,
                queries: queries_out,
                visual: hidden,
                pointer: None,
            }
        } else {
            let logits = self
                .bins
                .as_ref()
                .expect("decoder has a head")
                .forward(out)
                .reshape([n, h, a, NUM_BINS]);
            let classes = logits.clone().argmax(3).squeeze_dim::<3>(3);
            DecoderOutput {
                actions: classes_to_actions(classes),
                logits: Some(logits),
                queries: queries_out,
                visual: hidden,
                pointer: None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_device;

    fn cfg(head: ActionHead) -> DecoderConfig {
        DecoderConfig {
            width: 16,
            layers: 1,
            heads: 2,
            horizon: 3,
            action_dim: 7,
            head,
            queries: QueryLayout::Value,
            film: false,
            pointer: false,
            pointer_input_keys: false,
            belief: false,
            done_detach: false,
        }
    }

    #[test]
    fn bins_follow_openvla() {
        assert_eq!(action_to_class(-1.0), 0);
        assert_eq!(action_to_class(-2.0), 0);
        assert_eq!(action_to_class(1.0), 255);
        assert_eq!(action_to_class(0.0), 127);
        assert!((class_to_action(0) - (-1.0 + 1.0 / 255.0)).abs() < 1e-6);
        assert_eq!(class_to_action(255), class_to_action(254));
        // Decoding a value's class lands within half a bin of it.
        for i in 0..=200 {
            let a = -1.0 + i as f32 / 100.0;
            assert!((class_to_action(action_to_class(a)) - a).abs() <= 1.0 / 255.0 + 1e-6);
        }
        let (_guard, device) = test_device();
        let t = Tensor::<1>::from_floats([-1.0, -0.3, 0.0, 0.7, 1.0], &device);
        let classes = actions_to_classes(t.clone());
        let want: Vec<i64> = [-1.0f32, -0.3, 0.0, 0.7, 1.0]
            .iter()
            .map(|&a| action_to_class(a) as i64)
            .collect();
        assert_eq!(
            classes.clone().into_data().try_to_vec_as::<i64>().unwrap(),
            want
        );
        let back = classes_to_actions(classes)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for (b, &c) in back.iter().zip(&want) {
            assert!((b - class_to_action(c as usize)).abs() < 1e-6);
        }
    }

    #[test]
    fn last_layer_on_the_read_rows_equals_every_row() {
        let (_guard, device) = test_device();
        let vis = Tensor::<3>::random([3, 5, 16], Distribution::Default, &device);
        let lang = Tensor::<3>::random([3, 6, 16], Distribution::Default, &device);
        // Some language keys padded, as for instructions of different lengths.
        let pad = Tensor::<2, Bool>::from_data(
            TensorData::new([false, false, false, false, true, true].repeat(3), [3, 6]),
            &device,
        );
        for pointer in [false, true] {
            let c = DecoderConfig {
                layers: 2,
                pointer,
                ..cfg(ActionHead::L1)
            };
            let dec = ActionDecoder::new(&c, &device);
            let out = dec.forward(vis.clone(), None, lang.clone(), pad.clone());
            // Every row through every layer, as a plain encoder stack computes it.
            let seg = dec.segment.val();
            let q = dec.queries.dims()[0];
            let x = Tensor::cat(
                vec![
                    vis.clone(),
                    lang.clone() + seg.clone().narrow(0, 0, 1).unsqueeze_dim::<3>(0),
                    (dec.queries.val() + seg.narrow(0, 1, 1))
                        .unsqueeze_dim::<3>(0)
                        .repeat_dim(0, 3),
                ],
                1,
            );
            let full_pad = Tensor::cat(
                vec![
                    Tensor::<2>::zeros([3, 5], &device).equal_elem(1.0),
                    pad.clone(),
                    Tensor::<2>::zeros([3, q], &device).equal_elem(1.0),
                ],
                1,
            );
            let mut x = x;
            for layer in &dec.layers {
                x = layer
                    .ffn
                    .forward(layer.attn.forward(x, Some(full_pad.clone())));
            }
            let want = dec.norm.forward(x.clone().narrow(1, 11, q));
            let diff = (out.queries.clone() - want)
                .abs()
                .max()
                .into_scalar::<f32>();
            assert!(diff < 1e-5, "query outputs differ by {diff}");
            match out.visual {
                Some(visual) => {
                    assert!(pointer);
                    let d = (visual - x.narrow(1, 0, 5))
                        .abs()
                        .max()
                        .into_scalar::<f32>();
                    assert!(d < 1e-5, "visual outputs differ by {d}");
                }
                None => assert!(
                    !pointer,
                    "the pointer head's decoder keeps its visual outputs"
                ),
            }
        }
    }

    #[test]
    fn decoder_shapes_for_both_heads_and_query_layouts() {
        let (_guard, device) = test_device();
        let vis = Tensor::<3>::random([4, 5, 16], Distribution::Default, &device);
        let lang = Tensor::<3>::random([4, 6, 16], Distribution::Default, &device);
        let pad = Tensor::<2>::zeros([4, 6], &device).equal_elem(1.0);
        for (queries, n_queries) in [(QueryLayout::Value, 21), (QueryLayout::Step, 3)] {
            let c = DecoderConfig {
                queries,
                ..cfg(ActionHead::L1)
            };
            let dec = ActionDecoder::new(&c, &device);
            assert_eq!(dec.queries.dims(), [n_queries, 16]);
            let out = dec.forward(vis.clone(), None, lang.clone(), pad.clone());
            assert_eq!(out.actions.dims(), [4, 3, 7]);
            assert!(out.logits.is_none());
            let c = DecoderConfig {
                queries,
                ..cfg(ActionHead::Bins)
            };
            let out = ActionDecoder::new(&c, &device).forward(
                vis.clone(),
                None,
                lang.clone(),
                pad.clone(),
            );
            assert_eq!(out.actions.dims(), [4, 3, 7]);
            assert_eq!(out.logits.unwrap().dims(), [4, 3, 7, 256]);
        }
    }

    #[test]
    fn film_starts_as_identity_and_reads_only_unpadded_words() {
        let (_guard, device) = test_device();
        let c = DecoderConfig {
            film: true,
            ..cfg(ActionHead::L1)
        };
        let mut dec = ActionDecoder::new(&c, &device);
        let vis = Tensor::<3>::random([2, 5, 16], Distribution::Default, &device);
        let lang = Tensor::<3>::random([2, 6, 16], Distribution::Default, &device);
        let pad =
            Tensor::<2>::from_floats([[0.0; 6], [0., 0., 0., 0., 1., 1.]], &device).equal_elem(1.0);
        let with = dec
            .forward(vis.clone(), None, lang.clone(), pad.clone())
            .actions;
        let film = dec.film.take();
        let without = dec
            .forward(vis.clone(), None, lang.clone(), pad.clone())
            .actions;
        with.into_data()
            .assert_approx_eq::<f32>(&without.into_data(), burn::tensor::Tolerance::default());
        // With trained (here random) weights the instruction modulates the tokens, and padded
        // words do not.
        dec.film = film.map(|_| LinearConfig::new(16, 32).init(&device));
        let base = dec.modulate(vis.clone(), lang.clone(), pad.clone());
        assert!(
            (base.clone() - vis.clone())
                .abs()
                .max()
                .into_scalar::<f32>()
                > 1e-3
        );
        let noise = Tensor::<3>::random([2, 2, 16], Distribution::Default, &device);
        let mut lang2 = lang.clone();
        lang2 = lang2.slice_assign([1..2, 4..6, 0..16], noise.narrow(0, 1, 1));
        let padded_changed = dec.modulate(vis.clone(), lang2, pad.clone());
        base.clone().into_data().assert_approx_eq::<f32>(
            &padded_changed.into_data(),
            burn::tensor::Tolerance::default(),
        );
        let other = dec.modulate(vis, lang + 1.0, pad);
        assert!((base - other).abs().max().into_scalar::<f32>() > 1e-3);
    }

    #[test]
    fn configs_without_a_query_layout_read_as_value_queries() {
        let c: DecoderConfig = serde_json::from_str(
            r#"{"width":16,"layers":1,"heads":2,"horizon":3,"action_dim":7,"head":"l1"}"#,
        )
        .unwrap();
        assert_eq!(c.queries, QueryLayout::Value);
        let back = serde_json::to_string(&DecoderConfig {
            queries: QueryLayout::Step,
            ..c
        })
        .unwrap();
        assert!(back.contains(r#""queries":"step""#), "{back}");
    }

    #[test]
    fn masked_visual_tokens_do_not_change_the_actions() {
        let (_guard, device) = test_device();
        let dec = ActionDecoder::new(&cfg(ActionHead::L1), &device);
        let vis = Tensor::<3>::random([1, 5, 16], Distribution::Default, &device);
        let lang = Tensor::<3>::random([1, 6, 16], Distribution::Default, &device);
        let lpad = Tensor::<2>::zeros([1, 6], &device).equal_elem(1.0);
        // Tokens 0..2 masked: replacing them by anything, or dropping them, changes nothing.
        let vpad = Tensor::<2>::from_floats([[1.0, 1.0, 0.0, 0.0, 0.0]], &device).equal_elem(1.0);
        let other = Tensor::cat(
            vec![
                Tensor::random([1, 2, 16], Distribution::Default, &device),
                vis.clone().narrow(1, 2, 3),
            ],
            1,
        );
        let a = dec
            .forward(vis.clone(), Some(vpad.clone()), lang.clone(), lpad.clone())
            .actions;
        let b = dec
            .forward(other, Some(vpad), lang.clone(), lpad.clone())
            .actions;
        let c = dec.forward(vis.narrow(1, 2, 3), None, lang, lpad).actions;
        let d1: f32 = (a.clone() - b).abs().max().into_scalar();
        let d2: f32 = (a - c).abs().max().into_scalar();
        assert!(d1 < 1e-5 && d2 < 1e-5, "{d1} {d2}");
    }
}
