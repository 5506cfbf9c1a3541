//! Model configuration: serde structs with `tiny` (CPU) and `full` (GPU) presets (model.md §0).
//!
//! Every struct denies unknown fields, so a typo in a TOML file is an error, not a silent default.

use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};

/// Which policy the config builds (model.md §9). All variants share one interface.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(tag = "kind", deny_unknown_fields)]
pub enum Variant {
    #[serde(rename = "e_slotssm")]
    /// Embodied-SlotSSM: slot attention, SlotSSM memory, windowed head, slot fusion, relation tokens.
    ESlotSsm {
        /// Use per-frame oracle subgoal text (else a learned null subgoal vector).
        oracle_subgoal: bool,
    },
    /// SlotVLA: slots + relation tokens of the last `history` frames, no SSM (h = 1 is Markovian).
    #[serde(rename = "slotvla")]
    SlotVla {
        /// Number of frames whose tokens are concatenated (h ≥ 1).
        history: usize,
    },
    /// Dense patch tokens of the last `history` frames, no slots.
    #[serde(rename = "dense")]
    Dense {
        /// Number of frames whose patch tokens are concatenated (h ≥ 1).
        history: usize,
    },
}

impl Variant {
    /// Parses `e_slotssm`, `e_slotssm_oracle`, `slotvla_h<N>`, `dense` or `dense_h<N>`.
    pub fn from_name(name: &str) -> Result<Self> {
        let unknown = || ModelError::UnknownVariant(name.to_string());
        match name {
            "e_slotssm" => Ok(Variant::ESlotSsm {
                oracle_subgoal: false,
            }),
            "e_slotssm_oracle" => Ok(Variant::ESlotSsm {
                oracle_subgoal: true,
            }),
            "dense" => Ok(Variant::Dense { history: 1 }),
            _ => {
                if let Some(h) = name.strip_prefix("slotvla_h") {
                    let history = h.parse::<usize>().map_err(|_| unknown())?;
                    Ok(Variant::SlotVla { history })
                } else if let Some(h) = name.strip_prefix("dense_h") {
                    let history = h.parse::<usize>().map_err(|_| unknown())?;
                    Ok(Variant::Dense { history })
                } else {
                    Err(unknown())
                }
            }
        }
    }

    /// The canonical name (inverse of [`Variant::from_name`]).
    pub fn name(&self) -> String {
        match self {
            Variant::ESlotSsm {
                oracle_subgoal: false,
            } => "e_slotssm".into(),
            Variant::ESlotSsm {
                oracle_subgoal: true,
            } => "e_slotssm_oracle".into(),
            Variant::SlotVla { history } => format!("slotvla_h{history}"),
            Variant::Dense { history: 1 } => "dense".into(),
            Variant::Dense { history } => format!("dense_h{history}"),
        }
    }

    /// Frames of tokens the decoder sees per step (1 for the SSM model).
    pub fn history(&self) -> usize {
        match self {
            Variant::ESlotSsm { .. } => 1,
            Variant::SlotVla { history } | Variant::Dense { history } => *history,
        }
    }

    /// Whether the variant uses slot attention.
    pub fn has_slots(&self) -> bool {
        !matches!(self, Variant::Dense { .. })
    }

    /// Whether the variant reads the oracle subgoal text with every frame.
    pub fn needs_subgoal_text(&self) -> bool {
        matches!(
            self,
            Variant::ESlotSsm {
                oracle_subgoal: true
            }
        )
    }

    /// Whether the variant has the SlotSSM, windowed head and slot fusion.
    pub fn has_ssm(&self) -> bool {
        matches!(self, Variant::ESlotSsm { .. })
    }
}

/// What the policy observes per frame.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Observation {
    /// The agentview camera image (model.md §1): CNN features, slot attention.
    #[default]
    Pixels,
    /// The simulator's privileged object state (MIKASA-Robo's oracle-state mode): one token per
    /// object (category, position, orientation, grasp; see [`crate::io::state`]) plus one for the
    /// robot. The object tokens are the slots ("oracle slots"); no image, no slot attention.
    State {
        /// Tokens per frame N (objects padded to N − 1, then the robot); K = N for slot variants.
        tokens: usize,
        /// Category ids (padding, unknown and robot included).
        categories: usize,
        /// Numbers per token F ([`crate::io::state::FEATURES`] unless relative scales add more).
        #[serde(
            default = "base_state_features",
            skip_serializing_if = "is_base_state_features"
        )]
        features: usize,
    },
}

fn base_state_features() -> usize {
    crate::io::state::FEATURES
}

fn is_base_state_features(f: &usize) -> bool {
    *f == crate::io::state::FEATURES
}

impl Observation {
    /// Whether the policy reads the object state instead of pixels.
    pub fn is_state(&self) -> bool {
        matches!(self, Observation::State { .. })
    }

    /// Its name as in configs and on the command line (`pixels`, `state`).
    pub fn name(&self) -> &'static str {
        match self {
            Observation::Pixels => "pixels",
            Observation::State { .. } => "state",
        }
    }
}

/// Visual encoder (model.md §1): a CNN, soft position embedding, LN and MLP.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Output channels of each 5×5 conv (stride given by `strides`).
    pub channels: Vec<usize>,
    /// Stride of each 5×5 conv (same length as `channels`).
    pub strides: Vec<usize>,
    /// Feature width D_f (channels of the final 3×3 conv and of the output).
    pub feature_dim: usize,
    /// State mode: the factor the category embedding is multiplied by before it joins the
    /// projected token numbers under the token's LayerNorm (absent: 1, as configs and runs
    /// written before it). At 1 the N(0, 1) embedding outweighs the centimetres of an object's
    /// offset to the hand, and policies learn one reach whatever the scene (see
    /// [`crate::encoder::StateEncoder`]).
    #[serde(default = "one")]
    pub category_scale: f64,
}

fn one() -> f64 {
    1.0
}

/// Slot attention (model.md §2).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SlotConfig {
    /// Number of slots K.
    pub num_slots: usize,
    /// Slot / model width D.
    pub dim: usize,
    /// Iterations on the first frame.
    pub iters_first: usize,
    /// Iterations on later frames (initialised from the previous frame's slots).
    pub iters_later: usize,
    /// Layer-normalise (no affine) the previous frame's slots before they initialise the next
    /// frame [C]: the GRU keeps its state bounded but the residual MLP adds to it every frame, so
    /// over an episode of hundreds of frames the carried slots grow without bound (measured:
    /// episode-long training diverges through L_win without it). Windows of a few frames from
    /// Q₀ never show it.
    #[serde(default = "normalize_carried_default")]
    pub normalize_carried: bool,
}

fn normalize_carried_default() -> bool {
    true
}

/// SlotSSM stack and its Mamba mixer (model.md §4).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SsmConfig {
    /// Number of SlotSSM blocks.
    pub blocks: usize,
    /// Heads of the inter-slot attention.
    pub heads: usize,
    /// Mamba inner width E.
    pub inner: usize,
    /// Mamba state size S.
    pub state: usize,
    /// Causal conv kernel width.
    pub conv: usize,
    /// Rank of the Δ projection.
    pub dt_rank: usize,
    /// Cross-attention from slots to patches in every block.
    pub cross_attention: bool,
    /// Feed-forward sub-block (hidden 4D) in every block.
    pub ffn: bool,
}

/// Windowed prediction head (model.md §5).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WindowConfig {
    /// p: offsets −p+1 … 0.
    pub past: usize,
    /// q: offsets +1 … +q.
    pub future: usize,
}

impl WindowConfig {
    /// The P = p + q offsets o_j, in order (−p+1, …, 0, …, +q).
    pub fn offsets(&self) -> Vec<i64> {
        let p = self.past as i64;
        let q = self.future as i64;
        (-p + 1..=q).collect()
    }
}

/// Relation encoder (model.md §7).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RelationConfig {
    /// Number of relation tokens L.
    pub tokens: usize,
    /// Layers.
    pub layers: usize,
    /// Attention heads.
    pub heads: usize,
}

/// Which action head the decoder ends with (model.md §8).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ActionHead {
    /// Continuous chunk, L1 loss (OpenVLA-OFT).
    L1,
    /// The L1 head's continuous chunk with a squared-error loss: a few large errors (the
    /// reach's first steps) outweigh many small ones, where L1 settles on their median.
    L2,
    /// 256-bin classification per dimension, cross-entropy (OpenVLA).
    Bins,
}

/// What one action query of the decoder stands for.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum QueryLayout {
    /// One query per action value: H_a·A queries (OpenVLA-OFT's layout).
    #[default]
    Value,
    /// One query per chunk step: H_a queries, each read out to all A values (1/A of the query
    /// tokens). Measured worse on state-mode T1 (train/README.md).
    Step,
}

/// Action decoder (model.md §8).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DecoderConfig {
    /// Width D_dec.
    pub width: usize,
    /// Transformer layers.
    pub layers: usize,
    /// Attention heads.
    pub heads: usize,
    /// Chunk length H_a.
    pub horizon: usize,
    /// Action dims A (7).
    pub action_dim: usize,
    /// Head kind.
    pub head: ActionHead,
    /// Query layout (absent in configs written before it existed: `value`).
    #[serde(default)]
    pub queries: QueryLayout,
    /// FiLM the visual/object tokens with the pooled instruction before the first layer
    /// (γ, β from one linear map, zero-initialised), so that the learned queries' attention can
    /// depend on the instruction already in the first layer (absent: false).
    #[serde(default)]
    pub film: bool,
    /// State mode only: a pointer head adds to each chunk step's action a softmax-weighted sum,
    /// over the current frame's object tokens, of a linear map of each token's own input numbers
    /// (its offset to the gripper among them), so that "move to that object" is choosing a token
    /// rather than regressing its position (absent: false; see [`crate::decoder::PointerHead`]).
    #[serde(default)]
    pub pointer: bool,
    /// With the pointer head: its keys also read each token's own input numbers through a
    /// linear map (beside its decoder output), so that a rule on them — the object nearest the
    /// hand — is one linear score (absent: false).
    #[serde(default)]
    pub pointer_input_keys: bool,
    /// The decoder also reads the progress head's belief (its distribution over the subgoals
    /// done, detached, through a learned linear map) as one more token before the visual
    /// tokens: the policy conditions on the count its own memory keeps, as the oracle variant
    /// does on the recorded label, with nothing observed beyond the other variants' inputs.
    /// Needs `loss.progress` > 0 (absent: false).
    #[serde(default)]
    pub belief: bool,
    /// The termination head (`loss.done` > 0) reads the action queries detached: its loss then
    /// trains the head alone and leaves what the decoder and the memory compute to the other
    /// losses (absent: false, the loss reaches them).
    #[serde(default, skip_serializing_if = "is_false")]
    pub done_detach: bool,
}

/// Language: word-level tokenizer over a fixed vocabulary + learned embeddings (model.md §8).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TextConfig {
    /// Known words (lower case); id 0 is padding, 1 unknown, word i has id i + 2.
    pub vocab: Vec<String>,
    /// Maximum tokens per text (longer texts are cut).
    pub max_len: usize,
}

/// Left out of a written config when 0 (so runs without the option read in older builds).
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Left out of a written config when false (as [`is_zero`]).
fn is_false(x: &bool) -> bool {
    !*x
}

fn unit() -> f64 {
    1.0
}

/// Loss weights and the contrastive temperature (model.md §3, §8).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LossConfig {
    /// λ_act.
    pub action: f64,
    /// λ_tc.
    pub contrastive: f64,
    /// λ_win.
    pub window: f64,
    /// λ_sa (0 turns the slot decoder off: it is then not built).
    pub slot_recon: f64,
    /// Weight of the gripper (the last action dimension) in the action loss, the arm's six being
    /// 1: the loss is the weighted mean over the chunk's entries (1, the default: a plain mean).
    #[serde(default = "unit")]
    pub gripper: f64,
    /// λ_ptr: weight of the pointer head's cross-entropy to the demonstration's target object
    /// (needs `decoder.pointer`; 0, the default, leaves the head unsupervised).
    #[serde(default)]
    pub pointer: f64,
    /// λ_prog: weight of the progress head's cross-entropy to the number of subgoals done so far
    /// (the recorded goal progress), read off the decoder's visual tokens of each frame; a
    /// training-time signal only, the policy never observes the progress. 0, the default,
    /// builds no head.
    #[serde(default)]
    pub progress: f64,
    /// λ_done: weight of the termination head's binary cross-entropy to whether the episode's
    /// goal is done (every subgoal satisfied, as recorded in `/goal`), read off the decoder's
    /// action queries, so with the instruction (RT-1's "terminate" output). The evaluator holds
    /// the robot still once the head says done for a few steps in a row. 0, the default, builds
    /// no head.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub done: f64,
    /// Contrastive temperature τ.
    pub tau: f64,
    /// Hidden width of the spatial-broadcast slot decoder.
    pub sa_hidden: usize,
}

/// Largest image side accepted (the full preset is 224; LIBERO renders at most 512).
pub const MAX_IMAGE_SIDE: usize = 1024;
/// Largest feature width accepted (channels, slot and decoder widths; the full preset's is 512).
pub const MAX_WIDTH: usize = 8192;
/// Largest frame count accepted for windows, histories and action horizons.
pub const MAX_FRAMES: usize = 1024;

/// The whole model.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// Which policy.
    pub variant: Variant,
    /// What it observes (pixels unless said otherwise).
    #[serde(default)]
    pub observation: Observation,
    /// Input image size [H, W] (agentview, RGB).
    pub image_size: [usize; 2],
    /// Visual encoder.
    pub encoder: EncoderConfig,
    /// Slot attention.
    pub slots: SlotConfig,
    /// SlotSSM.
    pub ssm: SsmConfig,
    /// Windowed head.
    pub window: WindowConfig,
    /// Relation encoder.
    pub relation: RelationConfig,
    /// Action decoder.
    pub decoder: DecoderConfig,
    /// Text.
    pub text: TextConfig,
    /// Losses.
    pub loss: LossConfig,
}

impl ModelConfig {
    /// The tiny CPU config of model.md §0 (64×64, K = 8, D = 64, T = 16 windows).
    pub fn tiny(variant: Variant) -> Self {
        ModelConfig {
            variant,
            observation: Observation::Pixels,
            image_size: [64, 64],
            encoder: EncoderConfig {
                channels: vec![32, 64, 64],
                strides: vec![2, 2, 2],
                feature_dim: 64,
                category_scale: 1.0,
            },
            slots: SlotConfig {
                num_slots: 8,
                dim: 64,
                iters_first: 3,
                iters_later: 1,
                normalize_carried: true,
            },
            ssm: SsmConfig {
                blocks: 2,
                heads: 4,
                inner: 128,
                state: 8,
                conv: 4,
                dt_rank: 4,
                cross_attention: false,
                ffn: true,
            },
            window: WindowConfig { past: 6, future: 2 },
            relation: RelationConfig {
                tokens: 8,
                layers: 2,
                heads: 4,
            },
            decoder: DecoderConfig {
                width: 128,
                layers: 2,
                heads: 4,
                horizon: 4,
                action_dim: 7,
                head: ActionHead::L1,
                queries: QueryLayout::Value,
                film: false,
                pointer: false,
                pointer_input_keys: false,
                belief: false,
                done_detach: false,
            },
            text: TextConfig {
                vocab: Vec::new(),
                max_len: 32,
            },
            loss: LossConfig {
                action: 1.0,
                contrastive: 0.5,
                window: 1.0,
                slot_recon: 1.0,
                gripper: 1.0,
                pointer: 0.0,
                progress: 0.0,
                done: 0.0,
                tau: 1.0,
                sa_hidden: 64,
            },
        }
    }

    /// The full GPU config of model.md §0 (K = 16, D = 512, P = 32, 16 relation tokens).
    ///
    /// The visual encoder is a CNN trained from scratch (224 → 14×14 patches, D_f = 256): the
    /// frozen DINOv2+SigLIP backbone of the paper is not available in Rust.
    pub fn full(variant: Variant) -> Self {
        ModelConfig {
            variant,
            observation: Observation::Pixels,
            image_size: [224, 224],
            encoder: EncoderConfig {
                channels: vec![64, 128, 256, 256],
                strides: vec![2, 2, 2, 2],
                feature_dim: 256,
                category_scale: 1.0,
            },
            slots: SlotConfig {
                num_slots: 16,
                dim: 512,
                iters_first: 3,
                iters_later: 1,
                normalize_carried: true,
            },
            ssm: SsmConfig {
                blocks: 3,
                heads: 8,
                inner: 1024,
                state: 16,
                conv: 4,
                dt_rank: 32,
                cross_attention: true,
                ffn: true,
            },
            window: WindowConfig {
                past: 26,
                future: 6,
            },
            relation: RelationConfig {
                tokens: 16,
                layers: 3,
                heads: 4,
            },
            decoder: DecoderConfig {
                width: 512,
                layers: 6,
                heads: 8,
                horizon: 8,
                action_dim: 7,
                head: ActionHead::L1,
                queries: QueryLayout::Value,
                film: false,
                pointer: false,
                pointer_input_keys: false,
                belief: false,
                done_detach: false,
            },
            text: TextConfig {
                vocab: Vec::new(),
                max_len: 32,
            },
            loss: LossConfig {
                action: 1.0,
                contrastive: 0.5,
                window: 1.0,
                slot_recon: 1.0,
                gripper: 1.0,
                pointer: 0.0,
                progress: 0.0,
                done: 0.0,
                tau: 1.0,
                sa_hidden: 1024,
            },
        }
    }

    /// Replaces the vocabulary by the words of `texts` (lower-cased, sorted, unique).
    pub fn with_vocab_from<'a>(mut self, texts: impl IntoIterator<Item = &'a str>) -> Self {
        let mut words: Vec<String> = texts.into_iter().flat_map(data::text::words).collect();
        words.sort();
        words.dedup();
        self.text.vocab = words;
        self
    }

    /// The loss weights by name, for checks and reports.
    fn loss_weights(&self) -> [(&'static str, f64); 5] {
        let l = &self.loss;
        [
            ("action", l.action),
            ("contrastive", l.contrastive),
            ("window", l.window),
            ("slot_recon", l.slot_recon),
            ("gripper", l.gripper),
        ]
    }

    /// Feature grid [gh, gw] of the encoder for `image_size` (M = gh · gw).
    pub fn grid(&self) -> [usize; 2] {
        let mut g = self.image_size;
        for &s in &self.encoder.strides {
            // 5×5 conv, padding 2: out = floor((n + 4 − 5) / s) + 1
            g = [(g[0] - 1) / s + 1, (g[1] - 1) / s + 1];
        }
        g
    }

    /// Visual tokens per frame M (state mode: the object and robot tokens N).
    pub fn num_patches(&self) -> usize {
        match self.observation {
            Observation::Pixels => {
                let [h, w] = self.grid();
                h * w
            }
            Observation::State { tokens, .. } => tokens,
        }
    }

    /// The same model reading the object state: N = `tokens` tokens per frame (K = N slots) of
    /// `features` numbers, `categories` category ids, no slot reconstruction (there is no image).
    pub fn with_state(mut self, tokens: usize, categories: usize, features: usize) -> Self {
        self.observation = Observation::State {
            tokens,
            categories,
            features,
        };
        self.slots.num_slots = tokens;
        self.loss.slot_recon = 0.0;
        self
    }

    /// Width of one slot-reconstruction target: one RGB patch (patch_h · patch_w · 3).
    pub fn sa_target_dim(&self) -> usize {
        let [gh, gw] = self.grid();
        (self.image_size[0] / gh) * (self.image_size[1] / gw) * 3
    }

    /// Whether the slot decoder (L_sa) is built.
    pub fn has_sa_decoder(&self) -> bool {
        self.variant.has_slots() && self.loss.slot_recon > 0.0 && !self.observation.is_state()
    }

    /// Floats of streaming state that do not depend on the episode length (model.md §10):
    /// K·(D + n_ssm·E·(S + d_conv − 1)) for the SSM model, K·D for SlotVLA (its frame buffer
    /// comes on top and grows up to h frames).
    pub fn constant_state_floats(&self) -> usize {
        let k = self.slots.num_slots;
        let d = self.slots.dim;
        match self.variant {
            Variant::ESlotSsm { .. } => {
                k * (d + self.ssm.blocks * self.ssm.inner * (self.ssm.state + self.ssm.conv - 1))
            }
            Variant::SlotVla { .. } => k * d,
            Variant::Dense { .. } => 0,
        }
    }

    /// Checks the config for consistency.
    pub fn validate(&self) -> Result<()> {
        let err = |m: String| Err(ModelError::Config(m));
        // Sizes are bounded first, so that nothing below (or the allocation of the weights) meets
        // a zero image or a multi-gigabyte tensor.
        let c = &self.encoder.channels;
        for (key, value, max) in [
            ("image_size[0]", self.image_size[0], MAX_IMAGE_SIDE),
            ("image_size[1]", self.image_size[1], MAX_IMAGE_SIDE),
            (
                "encoder.channels",
                c.iter().copied().max().unwrap_or(1),
                MAX_WIDTH,
            ),
            ("encoder.feature_dim", self.encoder.feature_dim, MAX_WIDTH),
            ("slots.num_slots", self.slots.num_slots, 256),
            ("slots.dim", self.slots.dim, MAX_WIDTH),
            ("slots.iters_first", self.slots.iters_first, 64),
            ("ssm.blocks", self.ssm.blocks, 64),
            ("ssm.inner", self.ssm.inner, 4 * MAX_WIDTH),
            ("ssm.state", self.ssm.state, 1024),
            ("window.past", self.window.past, MAX_FRAMES),
            ("window.future", self.window.future, MAX_FRAMES),
            ("relation.tokens", self.relation.tokens, 256),
            ("relation.layers", self.relation.layers, 64),
            ("decoder.width", self.decoder.width, MAX_WIDTH),
            ("decoder.layers", self.decoder.layers, 64),
            ("decoder.horizon", self.decoder.horizon, MAX_FRAMES),
            ("text.max_len", self.text.max_len, 4096),
            ("history", self.variant.history(), MAX_FRAMES),
        ] {
            if value > max {
                return err(format!("{key} = {value} is above the limit {max}"));
            }
        }
        if self.image_size.iter().any(|&s| s < 8) {
            return err(format!(
                "image_size {:?}: each side must be ≥ 8 pixels",
                self.image_size
            ));
        }
        let weights = self.loss_weights();
        if let Some((key, v)) = weights.iter().find(|(_, v)| !(*v >= 0.0 && v.is_finite())) {
            return err(format!("loss.{key} = {v}: must be a finite number ≥ 0"));
        }
        if self.encoder.channels.is_empty()
            || self.encoder.channels.len() != self.encoder.strides.len()
        {
            return err(
                "encoder.channels and encoder.strides must be non-empty and of equal length".into(),
            );
        }
        if self.encoder.strides.contains(&0) {
            return err("encoder.strides must be ≥ 1".into());
        }
        let cs = self.encoder.category_scale;
        if !(cs.is_finite() && (0.0..=100.0).contains(&cs)) {
            return err(format!(
                "encoder.category_scale = {cs}: must be a finite number in [0, 100]"
            ));
        }
        let [gh, gw] = self.grid();
        if !self.image_size[0].is_multiple_of(gh) || !self.image_size[1].is_multiple_of(gw) {
            return err(format!(
                "image_size {:?} must be a multiple of the feature grid {:?} (slot reconstruction targets are patches)",
                self.image_size,
                [gh, gw]
            ));
        }
        if self.slots.num_slots == 0 || self.slots.dim == 0 || self.slots.iters_first == 0 {
            return err("slots: num_slots, dim and iters_first must be ≥ 1".into());
        }
        if self.ssm.heads == 0 || self.relation.heads == 0 || self.decoder.heads == 0 {
            return err("ssm.heads, relation.heads and decoder.heads must be ≥ 1".into());
        }
        if !self.slots.dim.is_multiple_of(self.ssm.heads)
            || !self.slots.dim.is_multiple_of(self.relation.heads)
        {
            return err("slots.dim must be divisible by ssm.heads and relation.heads".into());
        }
        if !self.decoder.width.is_multiple_of(self.decoder.heads) {
            return err("decoder.width must be divisible by decoder.heads".into());
        }
        if self.ssm.conv == 0 || self.ssm.state == 0 || self.ssm.inner == 0 || self.ssm.dt_rank == 0
        {
            return err("ssm: inner, state, conv and dt_rank must be ≥ 1".into());
        }
        if self.window.past == 0 {
            return err("window.past must be ≥ 1 (offset 0 is the current frame)".into());
        }
        if self.variant.history() == 0 {
            return err("history must be ≥ 1".into());
        }
        if self.decoder.horizon == 0 || self.decoder.action_dim == 0 {
            return err("decoder.horizon and decoder.action_dim must be ≥ 1".into());
        }
        if self.text.max_len == 0 {
            return err("text.max_len must be ≥ 1".into());
        }
        if !(self.loss.tau > 0.0 && self.loss.tau.is_finite()) {
            return err("loss.tau must be a finite number > 0".into());
        }
        // (Its observation, state, is checked where the model is built: configs are validated
        // before the dataset tells their observation.)
        if self.decoder.pointer
            && (self.decoder.head == ActionHead::Bins || self.decoder.queries != QueryLayout::Step)
        {
            return err(
                "decoder.pointer needs a continuous head (decoder.head = \"l1\" or \"l2\") and step \
                 queries (decoder.queries = \"step\")"
                    .into(),
            );
        }
        if self.decoder.belief && self.loss.progress <= 0.0 {
            return err(
                "decoder.belief reads the progress head, which `loss.progress` > 0 builds".into(),
            );
        }
        if self.decoder.pointer_input_keys && !self.decoder.pointer {
            return err("decoder.pointer_input_keys needs decoder.pointer = true".into());
        }
        if !(self.loss.pointer >= 0.0 && self.loss.pointer.is_finite()) {
            return err("loss.pointer must be a finite number ≥ 0".into());
        }
        if self.loss.pointer > 0.0 && !self.decoder.pointer {
            return err("loss.pointer > 0 needs the pointer head (decoder.pointer = true)".into());
        }
        if !(self.loss.progress >= 0.0 && self.loss.progress.is_finite()) {
            return err("loss.progress must be a finite number ≥ 0".into());
        }
        if !(self.loss.done >= 0.0 && self.loss.done.is_finite()) {
            return err("loss.done must be a finite number ≥ 0".into());
        }
        if let Observation::State {
            tokens,
            categories,
            features,
        } = self.observation
        {
            if features < crate::io::state::FEATURES {
                return err(format!(
                    "observation: {features} features per state token, at least {} expected",
                    crate::io::state::FEATURES
                ));
            }
            if tokens < 2 || categories < 3 {
                return err(format!(
                    "observation: {tokens} tokens and {categories} categories; state mode needs \
                     ≥ 2 tokens (an object and the robot) and ≥ 3 categories"
                ));
            }
            if self.variant.has_slots() && self.slots.num_slots != tokens {
                return err(format!(
                    "observation: state mode gives one slot per token: slots.num_slots = {} but \
                     {tokens} tokens",
                    self.slots.num_slots
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_names_round_trip() {
        for name in [
            "e_slotssm",
            "e_slotssm_oracle",
            "slotvla_h1",
            "slotvla_h8",
            "dense",
            "dense_h4",
        ] {
            assert_eq!(Variant::from_name(name).unwrap().name(), name);
        }
        assert!(Variant::from_name("slotvla").is_err());
        assert!(Variant::from_name("slotvla_hx").is_err());
    }

    #[test]
    fn tiny_and_full_are_valid_and_match_the_spec() {
        let tiny = ModelConfig::tiny(Variant::from_name("e_slotssm").unwrap());
        tiny.validate().unwrap();
        assert_eq!(tiny.grid(), [8, 8]);
        assert_eq!(tiny.num_patches(), 64);
        assert_eq!(tiny.sa_target_dim(), 192);
        assert_eq!(tiny.window.offsets(), vec![-5, -4, -3, -2, -1, 0, 1, 2]);
        // model.md §10: tiny 8·(64 + 2·128·11) floats.
        assert_eq!(tiny.constant_state_floats(), 8 * (64 + 2 * 128 * 11));
        let full = ModelConfig::full(Variant::SlotVla { history: 8 });
        full.validate().unwrap();
        assert_eq!(full.grid(), [14, 14]);
        assert_eq!(full.window.offsets().len(), 32);
        let full_ssm = ModelConfig::full(Variant::ESlotSsm {
            oracle_subgoal: true,
        });
        assert_eq!(full_ssm.constant_state_floats(), 16 * (512 + 3 * 1024 * 19));
    }

    #[test]
    fn config_round_trips_through_json_and_rejects_unknown_fields() {
        let cfg = ModelConfig::tiny(Variant::SlotVla { history: 8 })
            .with_vocab_from(["Put the bowl on the plate", "open the drawer"]);
        assert_eq!(
            cfg.text.vocab,
            vec!["bowl", "drawer", "on", "open", "plate", "put", "the"]
        );
        let json = serde_json::to_string(&cfg).unwrap();
        let back: ModelConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, cfg);
        // The termination options are written only when used (older builds read the rest).
        assert!(!json.contains("done"), "{json}");
        let mut with = cfg.clone();
        with.loss.done = 0.5;
        with.decoder.done_detach = true;
        let with_json = serde_json::to_string(&with).unwrap();
        assert!(with_json.contains("\"done\":0.5") && with_json.contains("\"done_detach\":true"));
        assert_eq!(
            serde_json::from_str::<ModelConfig>(&with_json).unwrap(),
            with
        );
        let bad = json.replacen("\"image_size\"", "\"imagesize\"", 1);
        assert!(serde_json::from_str::<ModelConfig>(&bad).is_err());
        let v: Variant = serde_json::from_str(r#"{"kind": "slotvla", "history": 8}"#).unwrap();
        assert_eq!(v, Variant::SlotVla { history: 8 });
        let v: Variant =
            serde_json::from_str(r#"{"kind": "e_slotssm", "oracle_subgoal": true}"#).unwrap();
        assert_eq!(v.name(), "e_slotssm_oracle");
        assert!(serde_json::from_str::<Variant>(r#"{"kind": "dense", "histroy": 2}"#).is_err());
        assert!(serde_json::from_str::<Variant>(r#"{"kind": "slotssm"}"#).is_err());
    }

    #[test]
    fn validate_rejects_bad_values() {
        let mut cfg = ModelConfig::tiny(Variant::Dense { history: 1 });
        cfg.encoder.strides.pop();
        assert!(cfg.validate().is_err());
        let mut cfg = ModelConfig::tiny(Variant::SlotVla { history: 0 });
        assert!(cfg.validate().is_err());
        cfg.variant = Variant::SlotVla { history: 2 };
        cfg.loss.tau = 0.0;
        assert!(cfg.validate().is_err());
        let mut cfg = ModelConfig::tiny(Variant::Dense { history: 1 });
        cfg.decoder.heads = 0;
        assert!(cfg.validate().is_err());
        cfg.decoder.heads = 3; // 128 is not a multiple of 3
        assert!(cfg.validate().is_err());
        for bad in [f64::NAN, -0.1, 1e9] {
            let mut cfg = ModelConfig::tiny(Variant::Dense { history: 1 });
            cfg.encoder.category_scale = bad;
            let e = cfg.validate().unwrap_err().to_string();
            assert!(
                e.contains("encoder.category_scale") && e.contains("[0, 100]"),
                "{e}"
            );
        }
    }

    #[test]
    fn category_scale_reads_as_one_when_absent() {
        let e: EncoderConfig =
            serde_json::from_str(r#"{"channels": [32], "strides": [2], "feature_dim": 16}"#)
                .unwrap();
        assert_eq!(e.category_scale, 1.0);
        let e: EncoderConfig = serde_json::from_str(
            r#"{"channels": [32], "strides": [2], "feature_dim": 16, "category_scale": 0.1}"#,
        )
        .unwrap();
        assert_eq!(e.category_scale, 0.1);
        assert_eq!(
            ModelConfig::tiny(Variant::Dense { history: 1 })
                .encoder
                .category_scale,
            1.0
        );
    }

    #[test]
    fn validate_bounds_sizes_and_refuses_non_finite_numbers() {
        let msg = |f: &dyn Fn(&mut ModelConfig)| {
            let mut cfg = ModelConfig::tiny(Variant::ESlotSsm {
                oracle_subgoal: false,
            });
            f(&mut cfg);
            cfg.validate().unwrap_err().to_string()
        };
        assert!(
            msg(&|c| c.image_size = [0, 0]).contains("image_size [0, 0]: each side must be ≥ 8")
        );
        assert!(
            msg(&|c| c.image_size = [100_000, 100_000])
                .contains("image_size[0] = 100000 is above the limit 1024")
        );
        assert!(
            msg(&|c| c.window.past = 100_000)
                .contains("window.past = 100000 is above the limit 1024")
        );
        assert!(
            msg(&|c| c.slots.dim = 1 << 20).contains("slots.dim = 1048576 is above the limit 8192")
        );
        assert!(
            msg(&|c| c.loss.window = f64::NAN)
                .contains("loss.window = NaN: must be a finite number ≥ 0")
        );
        assert!(msg(&|c| c.loss.action = -1.0).contains("loss.action = -1"));
        assert!(
            msg(&|c| c.loss.tau = f64::INFINITY).contains("loss.tau must be a finite number > 0")
        );
        // The presets are inside every bound.
        for v in [
            Variant::ESlotSsm {
                oracle_subgoal: true,
            },
            Variant::SlotVla { history: 8 },
            Variant::Dense { history: 1 },
        ] {
            ModelConfig::tiny(v).validate().unwrap();
            ModelConfig::full(v).validate().unwrap();
        }
    }
}
