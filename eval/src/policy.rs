//! Policies a rollout can be run with: the trained model (through the streaming policy), the scripted
//! expert and the two floors (zero and random actions).

use burn::prelude::Device;
use data::ObjectAnnotation;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sim::expert::Expert;
use sim::labels::LabelTracker;
use sim::task::TaskSpec;
use sim::{Env, Observation};

use crate::error::EvalError;

/// The action sent once a scripted policy has nothing left to do: stand still, gripper open.
pub const IDLE_ACTION: [f32; 7] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];

/// Something that maps observations to actions, step by step.
pub trait Policy {
    /// Called before each episode with its task and seed.
    fn reset(&mut self, task: &TaskSpec, seed: u64) -> Result<(), EvalError>;
    /// The next 7-D action for the state `env` is in (`obs` is its latest observation).
    fn act(&mut self, env: &Env, obs: &Observation) -> Result<[f32; 7], EvalError>;
    /// Whether the policy needs camera images (off: faster state-only rollouts).
    fn needs_images(&self) -> bool;
    /// Whether the policy needs the agentview segmentation (the objects' boxes) every step.
    fn needs_segmentation(&self) -> bool {
        false
    }
    /// Slot-attention masks of the latest step, `[K][rows·cols]` with the token grid's
    /// `(rows, cols)`; `None` for policies without slots.
    fn slot_masks(&self) -> Option<(Vec<Vec<f32>>, usize, usize)> {
        None
    }
}

/// Sends zeros with the gripper at 0: a floor for every table.
#[derive(Debug, Default, Clone, Copy)]
pub struct ZeroPolicy;

impl Policy for ZeroPolicy {
    fn reset(&mut self, _: &TaskSpec, _: u64) -> Result<(), EvalError> {
        Ok(())
    }
    fn act(&mut self, _: &Env, _: &Observation) -> Result<[f32; 7], EvalError> {
        Ok([0.0; 7])
    }
    fn needs_images(&self) -> bool {
        false
    }
}

/// Uniform random actions in [−1, 1], drawn from the episode seed.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    rng: ChaCha8Rng,
}

impl Default for RandomPolicy {
    fn default() -> Self {
        RandomPolicy {
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }
}

impl Policy for RandomPolicy {
    fn reset(&mut self, _: &TaskSpec, seed: u64) -> Result<(), EvalError> {
        self.rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0005_eed0_fa11);
        Ok(())
    }
    fn act(&mut self, _: &Env, _: &Observation) -> Result<[f32; 7], EvalError> {
        Ok(std::array::from_fn(|_| {
            self.rng.random_range(-1.0f32..=1.0)
        }))
    }
    fn needs_images(&self) -> bool {
        false
    }
}

/// The scripted expert of `sim::expert` (privileged state), re-planned per episode from its seed;
/// once its plan is finished it idles with the gripper open.
#[derive(Default)]
pub struct ExpertPolicy {
    expert: Option<Expert>,
}

impl Policy for ExpertPolicy {
    fn reset(&mut self, task: &TaskSpec, seed: u64) -> Result<(), EvalError> {
        self.expert = Some(Expert::new(task, seed));
        Ok(())
    }
    fn act(&mut self, env: &Env, obs: &Observation) -> Result<[f32; 7], EvalError> {
        let expert = self
            .expert
            .as_mut()
            .ok_or_else(|| EvalError::Argument("the expert acts only after reset".into()))?;
        Ok(expert.act(env, obs).unwrap_or(IDLE_ACTION))
    }
    fn needs_images(&self) -> bool {
        false
    }
}

/// The objects' annotations of every step as the recorder writes them: poses, grasps, boxes (from
/// the segmentation when rendered) and the oracle labels, which advance after every step (not at
/// reset). One per episode.
#[derive(Default)]
pub struct ObjectReader {
    labels: Option<LabelTracker>,
}

impl ObjectReader {
    /// The annotations of `obs` (call once per step, in order).
    pub fn read(&mut self, env: &Env, obs: &Observation) -> Vec<ObjectAnnotation> {
        match self.labels.as_mut() {
            Some(t) => t.update(env, obs.goal.as_ref()),
            None => self.labels = LabelTracker::new(env),
        }
        let labels = self.labels.as_ref().map_or(&[][..], LabelTracker::labels);
        sim::record::object_annotations(env, obs, labels)
    }
}

/// How the model's predicted action chunks (`[H_a]` actions per step) become executed actions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Execution {
    /// The first action of every step's chunk (the default, as upstream `mem_6`).
    #[default]
    First,
    /// ACT's temporal ensembling: each step's action is the mean of what the last H_a chunks
    /// predicted for that step (uniform weights), gripper binarised after averaging.
    Ensemble,
    /// openpi's `replan_steps`: the first N actions of a chunk run open-loop before the next
    /// chunk is used (N capped at H_a); the memory still reads every frame.
    Replan(usize),
}

impl std::str::FromStr for Execution {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "first" => Ok(Execution::First),
            "ensemble" => Ok(Execution::Ensemble),
            n => match n.parse::<usize>() {
                Ok(k) if k >= 1 => Ok(Execution::Replan(k)),
                _ => Err(format!(
                    "execution `{s}`: expected `first`, `ensemble` or a step count N ≥ 1"
                )),
            },
        }
    }
}

impl std::fmt::Display for Execution {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Execution::First => f.write_str("first"),
            Execution::Ensemble => f.write_str("ensemble"),
            Execution::Replan(n) => write!(f, "{n}"),
        }
    }
}

/// The executed action of this step from the newest normalised chunk `chunk` (`[H_a][A]`) and
/// the state `recent` of [`Execution`] (ensemble: earlier chunks, newest first; replan: the
/// actions still queued).
fn execute(
    execution: Execution,
    recent: &mut std::collections::VecDeque<Vec<Vec<f32>>>,
    chunk: Vec<Vec<f32>>,
) -> Option<Vec<f32>> {
    match execution {
        Execution::First => chunk.into_iter().next(),
        Execution::Ensemble => {
            let h = chunk.len();
            recent.push_front(chunk);
            recent.truncate(h);
            let mut sum = vec![0f32; recent.front()?.first()?.len()];
            let mut n = 0f32;
            for (age, c) in recent.iter().enumerate() {
                if let Some(a) = c.get(age) {
                    sum.iter_mut().zip(a).for_each(|(s, v)| *s += v);
                    n += 1.0;
                }
            }
            Some(sum.into_iter().map(|s| s / n).collect())
        }
        Execution::Replan(n) => {
            // `recent` holds one chunk: the actions still to run, the next one last.
            if recent.front().is_none_or(Vec::is_empty) {
                let mut queue = chunk;
                queue.truncate(n);
                queue.reverse();
                recent.clear();
                recent.push_front(queue);
            }
            recent.front_mut()?.pop()
        }
    }
}

/// A trained model run step by step through the policy's one input path
/// ([`model::Processor`], saved with the run): each step the agentview frame (with the oracle
/// variant also the objects' boxes and labels; in state mode instead the objects' poses, grasps
/// and oracle labels), the instruction and the goal progress
/// the environment reports go in (the processor decides what the variant reads of them, exactly
/// as in training); the action [`Execution`] picks from the predicted chunks (by default the
/// first of this step's chunk) comes out,
/// un-normalised by the processor, clamped to [−1, 1], with the gripper binarised by its sign
/// (as upstream `mem_6`).
pub struct ModelPolicy {
    policy: model::StreamingPolicy,
    processor: model::Processor,
    instruction: String,
    grid: [usize; 2],
    seed: u64,
    objects: ObjectReader,
    execution: Execution,
    recent: std::collections::VecDeque<Vec<Vec<f32>>>,
    stop: StopLatch,
}

/// The termination head's probability above which a step counts as "done".
pub const STOP_PROBABILITY: f32 = 0.5;
/// Consecutive "done" steps after which the policy holds the robot still for the rest of the
/// episode.
pub const STOP_STEPS: usize = 3;

/// What a model with a termination head does with its "done" probabilities: once
/// [`STOP_STEPS`] steps in a row exceed [`STOP_PROBABILITY`], the latch closes and stays closed
/// until the next episode; the policy then commands no motion and keeps the gripper as it was.
#[derive(Clone, Debug, PartialEq)]
pub struct StopLatch {
    /// Whether the latch is used at all (`eval --no-stop` turns it off).
    pub enabled: bool,
    /// "Done" steps in a row so far.
    run: usize,
    /// The gripper command held once stopped; `Some` once the latch closed.
    held: Option<f32>,
    /// The gripper command of the latest executed action.
    gripper: f32,
}

impl Default for StopLatch {
    fn default() -> Self {
        StopLatch {
            enabled: true,
            run: 0,
            held: None,
            gripper: -1.0,
        }
    }
}

impl StopLatch {
    /// Forgets the episode (keeps `enabled`).
    pub fn reset(&mut self) {
        *self = StopLatch {
            enabled: self.enabled,
            ..StopLatch::default()
        };
    }

    /// Whether the latch has closed.
    pub fn stopped(&self) -> bool {
        self.held.is_some()
    }

    /// The action executed this step: `action` (the policy's) while open, else no motion with
    /// the held gripper; `done` is this step's termination probability (None: no head).
    pub fn apply(&mut self, action: [f32; 7], done: Option<f32>) -> [f32; 7] {
        if self.enabled
            && self.held.is_none()
            && let Some(p) = done
        {
            self.run = if p > STOP_PROBABILITY {
                self.run + 1
            } else {
                0
            };
            if self.run >= STOP_STEPS {
                self.held = Some(self.gripper);
            }
        }
        match self.held {
            Some(g) => [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g],
            None => {
                self.gripper = action[6];
                action
            }
        }
    }
}

impl ModelPolicy {
    /// The same policy executing its chunks by `execution`.
    pub fn with_execution(mut self, execution: Execution) -> Self {
        self.execution = execution;
        self
    }

    /// The same policy with its termination head's stop latch on or off (on by default; no
    /// effect on a model without the head).
    pub fn with_stop(mut self, stop: bool) -> Self {
        self.stop.enabled = stop;
        self
    }

    /// Whether the stop latch has closed in this episode (the robot is held still).
    pub fn stopped(&self) -> bool {
        self.stop.stopped()
    }

    /// Wraps a loaded model with its run's processor.
    pub fn new(
        model: model::PolicyModel,
        processor: model::Processor,
        device: &Device,
    ) -> Result<Self, EvalError> {
        processor.check_model(&model.config)?;
        let grid = model.config.grid();
        let policy = model::StreamingPolicy::new(model, device)?;
        Ok(ModelPolicy {
            policy,
            processor,
            instruction: String::new(),
            grid,
            seed: 0,
            objects: ObjectReader::default(),
            execution: Execution::First,
            recent: std::collections::VecDeque::new(),
            stop: StopLatch::default(),
        })
    }

    /// The model inputs of the observation `obs` of `env` at the next step of the episode
    /// (call once per step, after [`Policy::reset`]; when the model reads objects it also
    /// advances the oracle labels, as the recorder does).
    pub fn input(&mut self, env: &Env, obs: &Observation) -> Result<model::StepInput, EvalError> {
        let objects = if self.reads_objects() {
            self.objects.read(env, obs)
        } else {
            Vec::new()
        };
        model_input(
            &self.processor,
            &self.instruction,
            obs,
            &objects,
            self.seed,
            self.policy.device(),
        )
    }

    /// Whether the model reads the objects' annotations (state mode, or boxes for the oracle).
    pub fn reads_objects(&self) -> bool {
        self.processor.reads_state() || self.processor.reads_boxes()
    }

    /// The run's input processor.
    pub fn processor(&self) -> &model::Processor {
        &self.processor
    }

    /// Starts an episode of `instruction` from `seed` without a task (what [`Policy::reset`]
    /// does; the policy server's reset).
    pub fn start(&mut self, instruction: &str, seed: u64) {
        self.policy.reset();
        self.instruction = instruction.to_string();
        self.seed = seed;
        self.objects = ObjectReader::default();
        self.recent.clear();
        self.stop.reset();
    }

    /// The whole action chunk for one step's observation, each action un-normalised and
    /// finished as [`Policy::act`] finishes the one it executes (`[H_a]` actions).
    pub fn act_chunk(&mut self, step: &model::StepObservation) -> Result<Vec<[f32; 7]>, EvalError> {
        let input = self.processor.step(step, self.policy.device())?;
        let chunk = self.policy.act_input(input)?;
        let chunk: Vec<[f32; 7]> = chunk
            .into_iter()
            .map(|a| {
                let a: [f32; 7] = a
                    .as_slice()
                    .try_into()
                    .map_err(|_| EvalError::Model("the model returned no 7-D action".into()))?;
                Ok(finish_action(self.processor.unnormalize(a)))
            })
            .collect::<Result<_, EvalError>>()?;
        // The stop latch counts requests here (one per returned chunk); once closed, every
        // action of the chunk holds still.
        let done = self.policy.last_done()?;
        let first = chunk.first().copied().unwrap_or([0.0; 7]);
        let held = self.stop.apply(first, done);
        Ok(if self.stop.stopped() {
            vec![held; chunk.len()]
        } else {
            chunk
        })
    }

    /// The number of subgoals done that the progress head reads off the latest frame (its most
    /// probable class) with that probability; `None` before the first step or for a model
    /// trained without the progress loss.
    pub fn progress_belief(&self) -> Result<Option<(usize, f32)>, EvalError> {
        Ok(self
            .policy
            .last_progress()?
            .and_then(|p| p.into_iter().enumerate().max_by(|a, b| a.1.total_cmp(&b.1))))
    }

    /// Whether the oracle subgoal is fed to the model.
    pub fn uses_oracle_subgoal(&self) -> bool {
        self.processor.config().subgoal != model::io::SubgoalInput::None
    }
}

/// Eval's input path: one simulator observation → the model's inputs, through `processor`
/// (`objects` and `seed` are read in state mode only).
pub fn model_input(
    processor: &model::Processor,
    instruction: &str,
    obs: &Observation,
    objects: &[ObjectAnnotation],
    seed: u64,
    device: &Device,
) -> Result<model::StepInput, EvalError> {
    let s = obs.image_size as u32;
    let rendered = s > 0 && obs.agentview_rgb.len() == (s * s * 3) as usize;
    if !rendered && !processor.reads_state() {
        return Err(EvalError::Model(
            "the model needs rendered agentview frames".into(),
        ));
    }
    let frame = rendered.then(|| data::RgbImage {
        width: s,
        height: s,
        channels: 3,
        data: obs.agentview_rgb.clone(),
    });
    let goal = obs.goal.as_ref().map(sim::GoalStatus::progress);
    let step = model::StepObservation {
        agentview: frame.as_ref(),
        state: obs.state,
        objects,
        seed,
        instruction,
        goal: goal.as_ref(),
    };
    Ok(processor.step(&step, device)?)
}

/// Post-processes one un-normalised action: dims 0–5 clamped to [−1, 1], gripper to ±1 by sign.
pub fn finish_action(a: [f32; 7]) -> [f32; 7] {
    let mut out = a;
    for v in out.iter_mut().take(6) {
        *v = if v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
    }
    out[6] = if out[6] > 0.0 { 1.0 } else { -1.0 };
    out
}

impl Policy for ModelPolicy {
    fn reset(&mut self, task: &TaskSpec, seed: u64) -> Result<(), EvalError> {
        self.start(&task.instruction, seed);
        Ok(())
    }

    fn act(&mut self, env: &Env, obs: &Observation) -> Result<[f32; 7], EvalError> {
        let input = self.input(env, obs)?;
        let chunk = self.policy.act_input(input)?;
        let action: [f32; 7] = execute(self.execution, &mut self.recent, chunk)
            .and_then(|a| a.as_slice().try_into().ok())
            .ok_or_else(|| EvalError::Model("the model returned no 7-D action".into()))?;
        let action = finish_action(self.processor.unnormalize(action));
        let done = self.policy.last_done()?;
        Ok(self.stop.apply(action, done))
    }

    fn needs_images(&self) -> bool {
        !self.processor.reads_state()
    }

    fn needs_segmentation(&self) -> bool {
        self.processor.reads_boxes()
    }

    fn slot_masks(&self) -> Option<(Vec<Vec<f32>>, usize, usize)> {
        let masks = self.policy.last_masks()?;
        let [rows, cols] = self.grid;
        (masks.first()?.len() == rows * cols).then_some((masks, rows, cols))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stop latch: closes after STOP_STEPS "done" steps in a row (a dip resets the count),
    /// then holds still with the gripper of the last executed action until reset; off or
    /// without a head it passes actions through.
    #[test]
    fn stop_latch_holds_after_consecutive_done_steps() {
        let act = |g: f32| [0.5, -0.5, 0.1, 0.0, 0.0, 0.2, g];
        let mut latch = StopLatch::default();
        assert_eq!(latch.apply(act(1.0), Some(0.9)), act(1.0));
        assert_eq!(latch.apply(act(1.0), Some(0.9)), act(1.0));
        // A dip below the threshold starts the count again.
        assert_eq!(latch.apply(act(-1.0), Some(0.2)), act(-1.0));
        assert_eq!(latch.apply(act(-1.0), Some(0.9)), act(-1.0));
        assert_eq!(latch.apply(act(-1.0), Some(0.9)), act(-1.0));
        assert!(!latch.stopped());
        // The third in a row closes it: no motion, the previous step's gripper (open).
        let hold = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
        assert_eq!(latch.apply(act(1.0), Some(0.9)), hold);
        assert!(latch.stopped());
        // Closed whatever the head says next.
        assert_eq!(latch.apply(act(1.0), Some(0.0)), hold);
        latch.reset();
        assert!(!latch.stopped() && latch.enabled);
        assert_eq!(latch.apply(act(1.0), Some(0.1)), act(1.0));
        // Off, or no head: never stops.
        let mut off = StopLatch {
            enabled: false,
            ..StopLatch::default()
        };
        let mut none = StopLatch::default();
        for _ in 0..10 {
            assert_eq!(off.apply(act(1.0), Some(1.0)), act(1.0));
            assert_eq!(none.apply(act(1.0), None), act(1.0));
        }
        assert!(!off.stopped() && !none.stopped());
    }

    /// A chunk of `h` one-dimensional actions `base + i`.
    fn chunk(base: f32, h: usize) -> Vec<Vec<f32>> {
        (0..h).map(|i| vec![base + i as f32]).collect()
    }

    #[test]
    fn execution_modes_pick_first_ensemble_or_queued_actions() {
        let mut recent = std::collections::VecDeque::new();
        let run = |e: Execution, recent: &mut std::collections::VecDeque<Vec<Vec<f32>>>| {
            recent.clear();
            (0..5)
                .map(|t| execute(e, recent, chunk(10.0 * t as f32, 3)).unwrap()[0])
                .collect::<Vec<f32>>()
        };
        assert_eq!(
            run(Execution::First, &mut recent),
            [0.0, 10.0, 20.0, 30.0, 40.0]
        );
        // Step t averages chunk t's action 0, chunk t−1's action 1 and chunk t−2's action 2.
        assert_eq!(
            run(Execution::Ensemble, &mut recent),
            [0.0, 5.5, 11.0, 21.0, 31.0]
        );
        // Two actions of chunk 0, two of chunk 2, then chunk 4's first.
        assert_eq!(
            run(Execution::Replan(2), &mut recent),
            [0.0, 1.0, 20.0, 21.0, 40.0]
        );
        // N past the horizon runs the whole chunk, then replans.
        assert_eq!(
            run(Execution::Replan(9), &mut recent),
            [0.0, 1.0, 2.0, 30.0, 31.0]
        );
        assert_eq!("ensemble".parse(), Ok(Execution::Ensemble));
        assert_eq!("5".parse(), Ok(Execution::Replan(5)));
        assert_eq!(Execution::Replan(5).to_string(), "5");
        let e = "0".parse::<Execution>().unwrap_err();
        assert!(e.contains("`first`, `ensemble` or a step count"), "{e}");
    }

    #[test]
    fn finish_action_clamps_and_binarises() {
        assert_eq!(
            finish_action([2.0, -3.0, 0.5, f32::NAN, 0.0, -0.25, 0.3]),
            [1.0, -1.0, 0.5, 0.0, 0.0, -0.25, 1.0]
        );
        assert_eq!(finish_action([0.0; 7])[6], -1.0);
        assert_eq!(finish_action([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.7])[6], -1.0);
    }

    #[test]
    fn expert_policy_solves_t1_through_the_same_loop() {
        let task = sim::task::resolve("t1").unwrap();
        let cfg = sim::EnvConfig {
            render: false,
            ..sim::EnvConfig::default()
        };
        let mut env = Env::from_task(&task, cfg).unwrap();
        let mut p = ExpertPolicy::default();
        let first = env.reset(0).unwrap();
        assert!(p.act(&env, &first).is_err(), "act before reset");
        p.reset(&task, 3).unwrap();
        let mut obs = env.reset(3).unwrap();
        let mut done = false;
        for _ in 0..task.max_steps {
            obs = env.step(&p.act(&env, &obs).unwrap()).unwrap();
            if obs.goal.as_ref().unwrap().done {
                done = true;
                break;
            }
        }
        assert!(done, "the expert finishes T1 within its budget");
    }

    #[test]
    fn a_pixel_oracle_model_gets_an_environment_with_segmentation_and_reads_boxes() {
        let task = sim::task::resolve("t1").unwrap();
        let device = Device::flex();
        let policy = |variant: &str| {
            let cfg = model::ModelConfig::tiny(model::Variant::from_name(variant).unwrap())
                .with_vocab_from([task.instruction.as_str()]);
            let m = model::PolicyModel::new(&cfg, &device).unwrap();
            let norm = data::ActionNorm {
                q01: [-1.0; 7],
                q99: [1.0; 7],
                mask: [true, true, true, true, true, true, false],
            };
            let p = model::Processor::new(&cfg, norm);
            ModelPolicy::new(m, p, &device).unwrap()
        };
        let eval_cfg = crate::EvalConfig {
            image_size: 64,
            ..Default::default()
        };
        let mut oracle = policy("e_slotssm_oracle");
        assert!(oracle.needs_segmentation());
        let mut env = crate::env_for(&task, &oracle, &eval_cfg).unwrap();
        assert!(env.config().segmentation && env.config().render);
        oracle.reset(&task, 5).unwrap();
        let obs = env.reset(5).unwrap();
        let input = oracle.input(&env, &obs).unwrap();
        let sub = input.subgoal.expect("the oracle reads labels");
        let boxes = sub.boxes.expect("matched to slots by boxes");
        let [_, j, _] = boxes.dims();
        assert_eq!(j, env.scene().unwrap().instances.len());
        let seen = boxes
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
            .chunks(4)
            .filter(|b| b[2] > 0.0 && b[3] > 0.0)
            .count();
        assert!(seen >= 2, "{seen} objects seen at the start of T1");
        let plain = policy("e_slotssm");
        assert!(!plain.needs_segmentation());
        let env = crate::env_for(&task, &plain, &eval_cfg).unwrap();
        assert!(!env.config().segmentation);
    }
}
