//! The one input path of a policy (LeRobot's processor idea): tokenizer, subgoal text, action
//! normalisation with its mask, frame preparation and the assembly of model tensors, in one
//! [`Processor`] that is saved into the run directory (`processor.json`, see [`crate::run`]).
//!
//! Training builds its [`WindowBatch`]es with [`Processor::batch`] from `data`'s window samples;
//! the evaluator turns each environment observation into model inputs with
//! [`Processor::step`] and model outputs into actions with [`Processor::unnormalize`]. Both
//! prepare frames with `data::window::frame_chw` and read the goal as the policy observes it
//! (`data::window::observed_progress`), so train and eval cannot disagree about an input.

pub mod state;

use burn::prelude::*;
use data::{ActionNorm, GoalProgress, ObjectAnnotation, RgbImage, Vocab, WindowSample};
use serde::{Deserialize, Serialize};

use crate::config::{ModelConfig, Observation, TextConfig};
use crate::encoder::Frames;
use crate::error::{ModelError, Result};
use crate::policy::WindowBatch;
use crate::variants::Subgoal;
use state::StateSpec;

/// Format tag of `processor.json`.
pub const PROCESSOR_FORMAT: &str = "libero-mem-rs/processor/1";

/// Word-level tokenizer over the model's vocabulary (model.md §8): id 0 = padding, 1 = unknown,
/// word i of the vocabulary = i + 2. Built on `data`'s [`Vocab`], the only word splitter.
#[derive(Clone, Debug)]
pub struct Tokenizer {
    vocab: Vocab,
    max_len: usize,
}

impl Tokenizer {
    /// The tokenizer of a model's text config.
    pub fn new(config: &TextConfig) -> Self {
        let mut words = vec!["<pad>".to_string(), "<unk>".to_string()];
        words.extend(config.vocab.iter().map(|w| w.to_lowercase()));
        Tokenizer {
            vocab: Vocab::from_words(words),
            max_len: config.max_len,
        }
    }

    /// Vocabulary size including the two special ids.
    pub fn vocab_size(&self) -> usize {
        self.vocab.len()
    }

    /// Token ids of `text`, cut or padded to exactly `max_len`.
    pub fn encode(&self, text: &str) -> Vec<i64> {
        let (ids, _) = self.vocab.encode(text, self.max_len);
        ids.into_iter().map(i64::from).collect()
    }

    /// Token ids of several texts as a tensor.
    ///
    /// # Shapes
    /// - output: `[texts.len(), max_len]`
    pub fn encode_batch(&self, texts: &[&str], device: &Device) -> Tensor<2, Int> {
        let data: Vec<i64> = texts.iter().flat_map(|t| self.encode(t)).collect();
        Tensor::from_data(TensorData::new(data, [texts.len(), self.max_len]), device)
    }

    /// Token ids of instructions, cut after the last column that is padding in every row (at
    /// least one column): the decoder masks padded language tokens, so the columns dropped change
    /// no output, and its sequence is not padded to `max_len` (with T3's nine words 53 tokens
    /// instead of 76 in the tiny decoder).
    ///
    /// # Shapes
    /// - output: `[texts.len(), L]`, 1 ≤ L ≤ max_len
    pub fn encode_instructions(&self, texts: &[&str], device: &Device) -> Tensor<2, Int> {
        let rows: Vec<Vec<i64>> = texts.iter().map(|t| self.encode(t)).collect();
        let pad = crate::text::PAD;
        let len = rows
            .iter()
            .map(|r| r.iter().rposition(|&id| id != pad).map_or(0, |i| i + 1))
            .max()
            .unwrap_or(0)
            .max(1);
        let data: Vec<i64> = rows.iter().flat_map(|r| r[..len].iter().copied()).collect();
        Tensor::from_data(TensorData::new(data, [texts.len(), len]), device)
    }
}

/// Which subgoal the model is given with each frame.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SubgoalInput {
    /// None (the model's own null subgoal).
    None,
    /// The pending subgoal's text, shared by every slot.
    Pending,
    /// The reference's oracle labels, one per slot: each object's latest satisfied subgoal with
    /// its ordinal (`"two: bowl 1 on plate 1"`, `"0"` before any), the robot's latest overall
    /// (state mode, where slot k is object token k).
    PerObject,
    /// The same per-object labels with the objects' boxes in the frame (pixels): the model
    /// gives each label to the slot whose attention mask matches the object's box (Hungarian
    /// matching, [`crate::matching`]), `"0"` to the other slots.
    Matched,
}

impl SubgoalInput {
    /// What the variant of `model` reads.
    pub fn of(model: &ModelConfig) -> Self {
        match (model.variant.needs_subgoal_text(), &model.observation) {
            (false, _) => SubgoalInput::None,
            (true, Observation::State { .. }) => SubgoalInput::PerObject,
            (true, Observation::Pixels) => SubgoalInput::Matched,
        }
    }

    /// Whether a processor that prepares `self` feeds a model that reads `wanted`: the same
    /// input, or the pending text of a pixel run saved before the labels were matched to slots
    /// (it keeps reading what it was trained on).
    fn feeds(self, wanted: SubgoalInput) -> bool {
        self == wanted || (self == SubgoalInput::Pending && wanted == SubgoalInput::Matched)
    }
}

/// Everything [`Processor`] needs, as saved in `processor.json`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ProcessorConfig {
    /// [`PROCESSOR_FORMAT`].
    pub format: String,
    /// Model input frame size `[H, W]` (square: frames are resized to it).
    pub image_size: [usize; 2],
    /// Text: vocabulary and token count.
    pub text: TextConfig,
    /// Action normalisation of the training data.
    pub action: ActionNorm,
    /// Which subgoal is fed.
    pub subgoal: SubgoalInput,
    /// The object-state tokens (state mode only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<StateSpec>,
}

/// One environment step as the policy sees it.
#[derive(Clone, Copy, Debug)]
pub struct StepObservation<'a> {
    /// Agentview RGB, upright, any size (resized as training frames are); None when nothing
    /// was rendered (state mode).
    pub agentview: Option<&'a RgbImage>,
    /// Proprio state (eef position, axis-angle, gripper qpos).
    pub state: [f32; 8],
    /// The objects in scene order, with poses and their oracle labels as observed at this step
    /// (state mode).
    pub objects: &'a [ObjectAnnotation],
    /// The episode's seed (state mode: the order of the object tokens).
    pub seed: u64,
    /// The task instruction.
    pub instruction: &'a str,
    /// Goal progress as the environment reports it with this observation (None: unknown).
    pub goal: Option<&'a GoalProgress>,
}

/// Model inputs of one step.
#[derive(Clone, Debug)]
pub struct StepInput {
    /// The observation of one frame: image `[1, 1, 3, H, W]` in [0, 1] or state tokens
    /// `[1, 1, N, F]` / `[1, 1, N]`.
    pub obs: Frames,
    /// Instruction ids `[1, L_txt]`.
    pub instruction: Tensor<2, Int>,
    /// Subgoal ids `[1, G, L_sg]` and, matched to slots, the objects' boxes `[1, J, 4]` (see
    /// [`Subgoal`]; None when the model reads none).
    pub subgoal: Option<Subgoal<3>>,
}

/// The policy's pre- and post-processing (see the module docs).
#[derive(Clone, Debug)]
pub struct Processor {
    config: ProcessorConfig,
    tokenizer: Tokenizer,
}

impl Processor {
    /// The processor of `model` with the action normalisation of its training data.
    pub fn new(model: &ModelConfig, action: ActionNorm) -> Self {
        Processor::from_config(Self::config_of(model, action))
            .expect("a pixel model config gives a valid processor")
    }

    fn config_of(model: &ModelConfig, action: ActionNorm) -> ProcessorConfig {
        let subgoal = SubgoalInput::of(model);
        ProcessorConfig {
            format: PROCESSOR_FORMAT.into(),
            image_size: model.image_size,
            text: model.text.clone(),
            action,
            subgoal,
            state: None,
        }
    }

    /// The processor of a state-mode `model` over objects as `spec` describes them.
    pub fn with_state(model: &ModelConfig, action: ActionNorm, spec: StateSpec) -> Result<Self> {
        let mut config = Self::config_of(model, action);
        config.state = Some(spec);
        let p = Processor::from_config(config)?;
        p.check_model(model)?;
        Ok(p)
    }

    /// A processor from its saved config.
    pub fn from_config(config: ProcessorConfig) -> Result<Self> {
        if config.format != PROCESSOR_FORMAT {
            return Err(ModelError::Config(format!(
                "processor format `{}`, expected `{PROCESSOR_FORMAT}`",
                config.format
            )));
        }
        if let Some(spec) = &config.state {
            spec.validate()?;
        }
        let [h, w] = config.image_size;
        if h == 0 || h != w {
            return Err(ModelError::Config(format!(
                "processor image_size {:?}: frames are square and non-empty",
                config.image_size
            )));
        }
        if config.subgoal == SubgoalInput::PerObject && config.state.is_none() {
            return Err(ModelError::Config(
                "per-object oracle labels need the object-state observation".into(),
            ));
        }
        Ok(Processor {
            tokenizer: Tokenizer::new(&config.text),
            config,
        })
    }

    /// Its saved form.
    pub fn config(&self) -> &ProcessorConfig {
        &self.config
    }

    /// The tokenizer.
    pub fn tokenizer(&self) -> &Tokenizer {
        &self.tokenizer
    }

    /// The action normalisation.
    pub fn action_norm(&self) -> &ActionNorm {
        &self.config.action
    }

    /// Whether the model reads the object state (no images needed).
    pub fn reads_state(&self) -> bool {
        self.config.state.is_some()
    }

    /// Whether the model reads the objects' boxes and labels of every frame (pixels with the
    /// oracle labels matched to slots): the evaluator must then render the segmentation.
    pub fn reads_boxes(&self) -> bool {
        self.config.subgoal == SubgoalInput::Matched
    }

    /// Whether `model` reads inputs the way this processor prepares them.
    pub fn check_model(&self, model: &ModelConfig) -> Result<()> {
        let c = &self.config;
        let state = c
            .state
            .as_ref()
            .map(|s| (s.tokens(), s.num_categories(), s.features()));
        let wants = match model.observation {
            Observation::Pixels => None,
            Observation::State {
                tokens,
                categories,
                features,
            } => Some((tokens, categories, features)),
        };
        if state != wants {
            let say = |x: Option<(usize, usize, usize)>| {
                x.map_or("pixels".into(), |(n, c, f)| {
                    format!("{n} state tokens of {f} numbers and {c} categories")
                })
            };
            return Err(ModelError::Config(format!(
                "the processor gives {} but the `{}` model reads {}",
                say(state),
                model.variant.name(),
                say(wants),
            )));
        }
        if c.image_size != model.image_size
            || c.text != model.text
            || !c.subgoal.feeds(SubgoalInput::of(model))
        {
            return Err(ModelError::Config(format!(
                "the processor (image {:?}, {} words, subgoal {:?}) does not fit the `{}` model \
                 (image {:?}, {} words, subgoal {:?})",
                c.image_size,
                c.text.vocab.len(),
                c.subgoal,
                model.variant.name(),
                model.image_size,
                model.text.vocab.len(),
                SubgoalInput::of(model)
            )));
        }
        Ok(())
    }

    /// The subgoal text fed with a frame whose observed goal is `goal` (None when the model
    /// reads none; the empty text when the goal is unknown or complete).
    pub fn subgoal_text<'g>(&self, goal: Option<&'g GoalProgress>) -> Option<&'g str> {
        match self.config.subgoal {
            SubgoalInput::None | SubgoalInput::PerObject | SubgoalInput::Matched => None,
            SubgoalInput::Pending => Some(goal.map_or("", |g| g.current_subgoal.as_str())),
        }
    }

    /// The robot's oracle label at a frame whose observed goal is `goal`: the latest satisfied
    /// subgoal with its ordinal, `"0"` before any.
    pub fn robot_label(goal: Option<&GoalProgress>) -> &str {
        goal.and_then(|g| g.satisfied_subgoals.last())
            .map_or("0", String::as_str)
    }

    /// The state tokens of one frame (state mode).
    fn state_tokens(
        &self,
        objects: &[ObjectAnnotation],
        proprio: &[f32; 8],
        goal: Option<&GoalProgress>,
        seed: u64,
    ) -> Result<state::StateTokens> {
        let spec =
            self.config.state.as_ref().ok_or_else(|| {
                ModelError::Input("the processor has no object-state spec".into())
            })?;
        let order = state::order(seed, spec.object_tokens(objects));
        state::tokens(spec, objects, proprio, Self::robot_label(goal), &order)
    }

    /// The token of object `object` (index into `objects`) in a frame of the episode of `seed`
    /// (state mode; see [`state::object_token`]).
    fn target_token(
        &self,
        objects: &[ObjectAnnotation],
        seed: u64,
        object: usize,
    ) -> Option<usize> {
        let spec = self.config.state.as_ref()?;
        let order = state::order(seed, spec.object_tokens(objects));
        state::object_token(spec, objects, &order, object)
    }

    /// An upright frame as model input `[3, H, W]` (values in [0, 1]).
    pub fn frame(&self, img: &RgbImage) -> Result<Vec<f32>> {
        if img.channels != 3 || img.data.len() != (img.width * img.height * 3) as usize {
            return Err(ModelError::Input(format!(
                "frame of {}×{}×{} with {} bytes",
                img.height,
                img.width,
                img.channels,
                img.data.len()
            )));
        }
        Ok(data::window::frame_chw(
            img.clone(),
            self.config.image_size[0] as u32,
        ))
    }

    /// Model inputs of one environment step.
    ///
    /// # Shapes
    /// - output: image `[1, 3, H, W]`, instruction `[1, L_txt]`, subgoal `[1, G, L_sg]`
    ///   (G = 1 pending text, N state tokens' labels, or J + 1 with boxes `[1, J, 4]`)
    pub fn step(&self, obs: &StepObservation, device: &Device) -> Result<StepInput> {
        let instruction = self
            .tokenizer
            .encode_instructions(&[obs.instruction], device);
        if self.reads_state() {
            let t = self.state_tokens(obs.objects, &obs.state, obs.goal, obs.seed)?;
            let n = t.categories.len();
            let nf = t.features.len() / n;
            let subgoal = (self.config.subgoal == SubgoalInput::PerObject).then(|| {
                let labels: Vec<&str> = t.labels.iter().map(String::as_str).collect();
                let l = self.config.text.max_len;
                self.tokenizer
                    .encode_batch(&labels, device)
                    .reshape([1, n, l])
                    .into()
            });
            return Ok(StepInput {
                obs: Frames::State(
                    Tensor::from_data(TensorData::new(t.features, [1, 1, n, nf]), device),
                    Tensor::from_data(TensorData::new(t.categories, [1, 1, n]), device),
                ),
                instruction,
                subgoal,
            });
        }
        let [h, w] = self.config.image_size;
        let frame = obs.agentview.ok_or_else(|| {
            ModelError::Input("the model reads pixels but no frame was rendered".into())
        })?;
        let image = Tensor::from_data(TensorData::new(self.frame(frame)?, [1, 1, 3, h, w]), device);
        let subgoal = if self.reads_boxes() {
            let j = obs.objects.len().max(1);
            let (labels, boxes) = object_labels(obs.objects, j);
            Some(Subgoal {
                ids: self.tokenizer.encode_batch(&labels, device).reshape([
                    1,
                    j + 1,
                    self.config.text.max_len,
                ]),
                boxes: Some(Tensor::from_data(TensorData::new(boxes, [1, j, 4]), device)),
            })
        } else {
            self.subgoal_text(obs.goal).map(|s| {
                self.tokenizer
                    .encode_batch(&[s], device)
                    .unsqueeze_dim::<3>(1)
                    .into()
            })
        };
        Ok(StepInput {
            obs: Frames::Pixels(image),
            instruction,
            subgoal,
        })
    }

    /// Training windows as one model batch: frames as `data` prepared them, the normalised
    /// action chunks, masks, the instruction and the subgoal of every frame.
    ///
    /// # Shapes
    /// - output: images `[B, T, 3, H, W]`, actions `[B, T, H_a, 7]`, frame mask `[B, T]`,
    ///   action weights `[B, T, H_a, 7]`, instruction `[B, L_txt]`, subgoal `[B, T, G, L_sg]`
    ///   (as in [`Processor::step`]; with boxes `[B, T, J, 4]`, J the most objects of a frame)
    pub fn batch(&self, samples: &[WindowSample], device: &Device) -> Result<WindowBatch> {
        let first = samples
            .first()
            .ok_or_else(|| ModelError::Input("cannot batch zero samples".into()))?;
        let (b, t) = (samples.len(), first.frame_mask.len());
        let ha = first.action_mask.len() / t.max(1);
        let [h, w] = self.config.image_size;
        let pixels = if self.reads_state() { 0 } else { t * 3 * h * w };
        for s in samples {
            if s.frame_mask.len() != t
                || s.images.len() != pixels
                || s.objects.len() != t
                || s.states.len() != t * 8
                || s.actions.len() != t * ha * 7
                || s.action_mask.len() != t * ha
                || s.action_weights.len() != t * ha
            {
                return Err(ModelError::Input(format!(
                    "window of episode {} at step {}: {} frames, {} image values, {} actions; \
                     expected {t} frames of 3×{h}×{w} and {ha}-step chunks",
                    s.episode,
                    s.t,
                    s.frame_mask.len(),
                    s.images.len(),
                    s.actions.len()
                )));
            }
        }
        let cat = |f: &dyn Fn(&WindowSample) -> &[f32]| -> Vec<f32> {
            samples.iter().flat_map(|s| f(s).iter().copied()).collect()
        };
        let actions = cat(&|s| &s.actions);
        let frame: Vec<f32> = samples
            .iter()
            .flat_map(|s| s.frame_mask.iter().map(|&m| f32::from(u8::from(m))))
            .collect();
        let mut action_mask = Vec::with_capacity(b * t * ha * 7);
        for s in samples {
            for j in 0..t {
                for k in 0..ha {
                    let w = if s.frame_mask[j] {
                        s.action_weights[j * ha + k]
                    } else {
                        0.0
                    };
                    action_mask.extend([w; 7]);
                }
            }
        }
        let instructions: Vec<&str> = samples.iter().map(|s| s.instruction.as_str()).collect();
        let l = self.config.text.max_len;
        let (obs, labels, pointer_target) = match &self.config.state {
            None => (
                Frames::Pixels(Tensor::from_data(
                    TensorData::new(cat(&|s| &s.images), [b, t, 3, h, w]),
                    device,
                )),
                None,
                None,
            ),
            Some(spec) => {
                let n = spec.tokens();
                let nf = spec.features();
                let mut features = Vec::with_capacity(b * t * n * nf);
                let mut categories = Vec::with_capacity(b * t * n);
                let mut labels = Vec::with_capacity(b * t * n);
                for s in samples {
                    for j in 0..t {
                        let proprio: [f32; 8] = s.states[j * 8..(j + 1) * 8]
                            .try_into()
                            .expect("8 numbers per state");
                        let tok = self
                            .state_tokens(&s.objects[j], &proprio, s.goals.get(j), s.seed)
                            .map_err(|e| {
                                ModelError::Input(format!(
                                    "episode {} step {}: {e}",
                                    s.episode, s.frame_steps[j]
                                ))
                            })?;
                        features.extend(tok.features);
                        categories.extend(tok.categories);
                        labels.extend(tok.labels);
                    }
                }
                // One-hot target tokens where the windows carry pointer targets.
                let targeted = samples.iter().any(|s| !s.targets.is_empty());
                let mut target = vec![0.0f32; if targeted { b * t * n } else { 0 }];
                for (i, s) in samples.iter().enumerate() {
                    for (j, goal) in s.targets.iter().enumerate().take(t) {
                        let Some(o) = *goal else { continue };
                        let k = self.target_token(&s.objects[j], s.seed, o).ok_or_else(|| {
                            ModelError::Input(format!(
                                "episode {} step {}: pointer target {o} is not one of its {} objects",
                                s.episode,
                                s.frame_steps[j],
                                s.objects[j].len()
                            ))
                        })?;
                        target[(i * t + j) * n + k] = 1.0;
                    }
                }
                (
                    Frames::State(
                        Tensor::from_data(TensorData::new(features, [b, t, n, nf]), device),
                        Tensor::from_data(TensorData::new(categories, [b, t, n]), device),
                    ),
                    Some((labels, n)),
                    targeted.then(|| Tensor::from_data(TensorData::new(target, [b, t, n]), device)),
                )
            }
        };
        let subgoal = match self.config.subgoal {
            SubgoalInput::None => None,
            SubgoalInput::PerObject => {
                let (labels, n) = labels.ok_or_else(|| {
                    ModelError::Input("per-object labels need the state observation".into())
                })?;
                let texts: Vec<&str> = labels.iter().map(String::as_str).collect();
                Some(
                    self.tokenizer
                        .encode_batch(&texts, device)
                        .reshape([b, t, n, l])
                        .into(),
                )
            }
            SubgoalInput::Matched => {
                // Every frame padded to the most objects of the batch (unseen, "0").
                let j = samples
                    .iter()
                    .flat_map(|s| s.objects.iter().map(Vec::len))
                    .max()
                    .unwrap_or(0)
                    .max(1);
                let mut texts = Vec::with_capacity(b * t * (j + 1));
                let mut boxes = Vec::with_capacity(b * t * j * 4);
                for objects in samples.iter().flat_map(|s| &s.objects) {
                    let (l, x) = object_labels(objects, j);
                    texts.extend(l);
                    boxes.extend(x);
                }
                Some(Subgoal {
                    ids: self
                        .tokenizer
                        .encode_batch(&texts, device)
                        .reshape([b, t, j + 1, l]),
                    boxes: Some(Tensor::from_data(
                        TensorData::new(boxes, [b, t, j, 4]),
                        device,
                    )),
                })
            }
            SubgoalInput::Pending => {
                let texts: Vec<&str> = samples
                    .iter()
                    .flat_map(|s| {
                        s.goals
                            .iter()
                            .map(|g| self.subgoal_text(Some(g)).unwrap_or(""))
                    })
                    .collect();
                if texts.len() != b * t {
                    return Err(ModelError::Input(format!(
                        "{} goal entries for {b} windows of {t} frames",
                        texts.len()
                    )));
                }
                Some(
                    self.tokenizer
                        .encode_batch(&texts, device)
                        .reshape([b, t, 1, l])
                        .into(),
                )
            }
        };
        // Subgoals done per frame (as observed), the progress head's targets, clamped to its
        // last class; windows without goal progress leave them out.
        let top = (crate::heads::PROGRESS_CLASSES - 1) as u32;
        let progress = samples.iter().all(|s| s.goals.len() >= t).then(|| {
            let done: Vec<i64> = samples
                .iter()
                .flat_map(|s| s.goals[..t].iter().map(|g| i64::from(g.satisfied.min(top))))
                .collect();
            Tensor::from_data(TensorData::new(done, [b, t]), device)
        });
        // Whether each frame's goal is done (every subgoal satisfied), the termination head's
        // targets; windows without goal progress leave them out.
        let done = samples.iter().all(|s| s.goals.len() >= t).then(|| {
            let done: Vec<f32> = samples
                .iter()
                .flat_map(|s| {
                    s.goals[..t]
                        .iter()
                        .map(|g| f32::from(u8::from(g.total > 0 && g.satisfied >= g.total)))
                })
                .collect();
            Tensor::from_data(TensorData::new(done, [b, t]), device)
        });
        Ok(WindowBatch {
            obs,
            actions: Tensor::from_data(TensorData::new(actions, [b, t, ha, 7]), device),
            frame_mask: Tensor::from_data(TensorData::new(frame, [b, t]), device),
            action_mask: Some(Tensor::from_data(
                TensorData::new(action_mask, [b, t, ha, 7]),
                device,
            )),
            instruction: self.tokenizer.encode_instructions(&instructions, device),
            subgoal,
            pointer_target,
            progress,
            done,
        })
    }

    /// A normalised action (model output) in the environment's units: the inverse of the
    /// training targets' normalisation on its masked dimensions.
    pub fn unnormalize(&self, a: [f32; 7]) -> [f32; 7] {
        self.config.action.denormalize(&a)
    }
}

/// The oracle labels and boxes of one frame's objects for slot matching, padded to `j`
/// objects: `j` labels then the `"0"` label, and `j` boxes `[x, y, w, h]` (zero when unseen).
fn object_labels(objects: &[ObjectAnnotation], j: usize) -> (Vec<&str>, Vec<f32>) {
    let mut labels = Vec::with_capacity(j + 1);
    let mut boxes = Vec::with_capacity(j * 4);
    for o in objects.iter().take(j) {
        labels.push(o.subgoal_label.as_str());
        boxes.extend(if o.visible { o.bbox } else { [0.0; 4] });
    }
    // Padding objects (unseen, "0"), then the "0" row of the unmatched slots.
    let pad = j - objects.len().min(j);
    labels.extend(std::iter::repeat_n("0", pad + 1));
    boxes.resize(j * 4, 0.0);
    (labels, boxes)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::config::Variant;

    /// A five-word vocabulary, six tokens (shared with the text encoder's tests).
    pub(crate) fn cfg() -> TextConfig {
        TextConfig {
            vocab: vec![
                "bowl".into(),
                "on".into(),
                "plate".into(),
                "put".into(),
                "the".into(),
            ],
            max_len: 6,
        }
    }

    #[test]
    fn tokenizer_maps_words_pads_and_cuts() {
        let tok = Tokenizer::new(&cfg());
        assert_eq!(tok.vocab_size(), 7);
        assert_eq!(
            tok.encode("Put the bowl on the PLATE."),
            vec![5, 6, 2, 3, 6, 4]
        );
        assert_eq!(tok.encode("put the mug"), vec![5, 6, 1, 0, 0, 0]);
        assert_eq!(tok.encode("the the the the the the the").len(), 6);
    }

    fn norm() -> ActionNorm {
        ActionNorm {
            q01: [-2.0; 7],
            q99: [2.0; 7],
            mask: [true, true, true, true, true, true, false],
        }
    }

    #[test]
    fn unnormalize_inverts_the_training_targets_and_leaves_the_gripper() {
        let model = ModelConfig::tiny(Variant::from_name("slotvla_h1").unwrap());
        let p = Processor::new(&model, norm());
        let a = [1.5, -0.3, 0.0, 2.0, -2.0, 0.7, -1.0];
        let n = norm().normalize(&a);
        let back = p.unnormalize(n);
        for (x, y) in back.iter().zip(a) {
            assert!((x - y).abs() < 1e-5, "{back:?}");
        }
        assert_eq!(
            p.unnormalize([1.0, -1.0, 0.0, 0.5, 0.0, 0.0, 0.3]),
            [2.0, -2.0, 0.0, 1.0, 0.0, 0.0, 0.3]
        );
    }

    #[test]
    fn config_round_trips_and_bad_configs_are_errors() {
        let model = ModelConfig::tiny(Variant::from_name("e_slotssm_oracle").unwrap())
            .with_vocab_from(["put the bowl on the plate"]);
        let p = Processor::new(&model, norm());
        assert_eq!(p.config().subgoal, SubgoalInput::Matched);
        assert!(p.reads_boxes());
        let json = serde_json::to_string(p.config()).unwrap();
        assert!(json.contains(r#""subgoal":"matched""#), "{json}");
        let back = Processor::from_config(serde_json::from_str(&json).unwrap()).unwrap();
        assert_eq!(back.config(), p.config());
        back.check_model(&model).unwrap();
        let other = ModelConfig::tiny(Variant::from_name("e_slotssm").unwrap())
            .with_vocab_from(["put the bowl on the plate"]);
        assert!(back.check_model(&other).is_err());
        // A pixel run saved before the labels were matched to slots keeps its pending text.
        let old = Processor::from_config(ProcessorConfig {
            subgoal: SubgoalInput::Pending,
            ..p.config().clone()
        })
        .unwrap();
        old.check_model(&model).unwrap();
        assert!(!old.reads_boxes());
        let mut bad = p.config().clone();
        bad.image_size = [64, 32];
        assert!(Processor::from_config(bad).is_err());
        let mut bad = p.config().clone();
        bad.format = "other".into();
        assert!(Processor::from_config(bad).is_err());
    }

    #[test]
    fn subgoal_text_follows_the_variant() {
        let goal = GoalProgress {
            current_subgoal: "put the bowl on the plate".into(),
            ..Default::default()
        };
        let plain = Processor::new(
            &ModelConfig::tiny(Variant::from_name("e_slotssm").unwrap()),
            norm(),
        );
        assert_eq!(plain.subgoal_text(Some(&goal)), None);
        let oracle = Processor::new(
            &ModelConfig::tiny(Variant::from_name("e_slotssm_oracle").unwrap()),
            norm(),
        );
        // Pixels: per-object labels matched to slots, no shared text.
        assert_eq!(oracle.subgoal_text(Some(&goal)), None);
        let pending = Processor::from_config(ProcessorConfig {
            subgoal: SubgoalInput::Pending,
            ..oracle.config().clone()
        })
        .unwrap();
        assert_eq!(
            pending.subgoal_text(Some(&goal)),
            Some("put the bowl on the plate")
        );
        assert_eq!(pending.subgoal_text(None), Some(""));
    }

    #[test]
    fn a_pixel_oracle_step_gives_each_objects_label_and_box_then_zero() {
        let device = Device::flex();
        let mut model = ModelConfig::tiny(Variant::from_name("e_slotssm_oracle").unwrap());
        model.text = cfg();
        let p = Processor::new(&model, norm());
        let object = |label: &str, bbox: [f32; 4], visible: bool| ObjectAnnotation {
            instance_id: 1,
            name: "bowl_1".into(),
            bbox,
            visible,
            subgoal_label: label.into(),
            pose: None,
            grasped: None,
            parts: Vec::new(),
        };
        let objects = [
            object("bowl on plate", [0.25, 0.5, 0.125, 0.25], true),
            // Unseen: its box is zeroed whatever was recorded.
            object("0", [0.5, 0.5, 0.1, 0.1], false),
        ];
        let [h, w] = model.image_size;
        let frame = RgbImage {
            width: w as u32,
            height: h as u32,
            channels: 3,
            data: vec![0; h * w * 3],
        };
        let input = p
            .step(
                &StepObservation {
                    agentview: Some(&frame),
                    state: [0.0; 8],
                    objects: &objects,
                    seed: 0,
                    instruction: "put the bowl on the plate",
                    goal: None,
                },
                &device,
            )
            .unwrap();
        let sub = input.subgoal.unwrap();
        assert_eq!(sub.ids.dims(), [1, 3, 6]);
        let ids = sub
            .ids
            .into_data()
            .convert::<i64>()
            .try_to_vec::<i64>()
            .unwrap();
        let tok = Tokenizer::new(&cfg());
        let want = [
            tok.encode("bowl on plate"),
            tok.encode("0"),
            tok.encode("0"),
        ]
        .concat();
        assert_eq!(ids, want);
        let boxes = sub.boxes.unwrap();
        assert_eq!(boxes.dims(), [1, 2, 4]);
        assert_eq!(
            boxes.into_data().try_to_vec::<f32>().unwrap(),
            vec![0.25, 0.5, 0.125, 0.25, 0.0, 0.0, 0.0, 0.0]
        );
    }
}
