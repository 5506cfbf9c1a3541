//! The LIBERO-style environment: a task's world (its BDDL scene from the builtin assets or LIBERO's
//! pack, with the goal tracked at every step — [`Env::from_task`], [`Env::from_task_with_assets`]), a
//! bare scene without a goal ([`Env::with_scene`]), or the minimal tabletop with one free box
//! ([`Env::new`], for benchmarks and rendering checks), each with the Panda.
//!
//! `reset(seed)` samples the initial state (fixtures, objects, articulations; the box) from a ChaCha
//! stream seeded by `seed`, or [`Env::reset_to_init`] starts from one of LIBERO's stored init states,
//! and puts the arm at LIBERO's nominal configuration; `step(action)` runs LIBERO's control loop (20 Hz over 25 physics substeps of 2 ms, OSC_POSE
//! goal on the first substep, gripper ramp on every substep) and returns an [`Observation`]. Same seed and
//! same actions give bit-identical observations, images included.

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::engine::mujoco::{Data, MjError, Model, ObjType};
use crate::engine::render::Decor;
use crate::engine::render::{Channels, RenderError, RenderQuality, Renderer};
use crate::task::{Atom, Category, GoalTracker, TaskSpec};
use crate::world::controller::{GripperRamp, OscPose, quat_to_axis_angle};
use crate::world::predicates::Predicates;
use crate::world::robot::{INIT_FINGERS, INIT_QPOS, PandaIds};
use crate::world::scene::{Arena, Scene, SceneError, SceneSpec};

/// Physics substeps per control step (0.05 s / 0.002 s).
pub const SUBSTEPS: usize = 25;
/// Control frequency in Hz.
pub const CONTROL_HZ: f64 = 20.0;
/// Name of the third-person camera.
pub const AGENTVIEW: &str = "agentview";
/// Name of the wrist camera.
pub const EYE_IN_HAND: &str = "robot0_eye_in_hand";

/// Errors from the environment.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// MuJoCo failed.
    #[error(transparent)]
    Mujoco(#[from] MjError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The action is not 7 finite numbers.
    #[error("invalid action: {0}")]
    Action(String),
    /// The configuration is invalid, or no valid start could be drawn.
    #[error("invalid environment config: {0}")]
    Config(String),
    /// The task scene could not be composed or placed.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The task could not be resolved or parsed.
    #[error(transparent)]
    Task(#[from] crate::task::TaskError),
    /// The scene of a task (its id: a `.bddl` path for a user's file) could not be built.
    #[error("task `{task}`: {source}")]
    TaskScene {
        /// The task id.
        task: String,
        /// Why.
        #[source]
        source: SceneError,
    },
}

impl EnvError {
    /// True when the input (a task file, the config, an action) is at fault rather than the
    /// simulator or the machine: the workspace's exit code 2.
    pub fn is_bad_input(&self) -> bool {
        match self {
            EnvError::Config(_) | EnvError::Action(_) | EnvError::Task(_) => true,
            EnvError::Render(r) => matches!(
                r,
                RenderError::UnknownCamera { .. } | RenderError::BadSize { .. }
            ),
            EnvError::Mujoco(m) => matches!(m, MjError::Load { .. }),
            EnvError::Scene(s) | EnvError::TaskScene { source: s, .. } => {
                !matches!(s, SceneError::Mujoco(_))
            }
        }
    }
}

/// Environment settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvConfig {
    /// Side of the square camera images in pixels (LIBERO: 128).
    pub image_size: usize,
    /// Render camera images at all (off: state-only, much faster).
    pub render: bool,
    /// Also return depth images (metres).
    pub depth: bool,
    /// Also return instance segmentation.
    pub segmentation: bool,
    /// Rendering quality (fast defaults).
    pub quality: RenderQuality,
    /// Standard deviation of Gaussian noise on the arm joints at reset (rad); LIBERO's eval uses 0.
    pub init_noise: f64,
    /// Idle control steps after placing a task scene (LIBERO-Mem's evaluation settles for 20).
    pub settle_steps: usize,
    /// The idle action used while settling (OpenVLA's: gripper opening, arm still).
    pub settle_action: [f32; 7],
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            image_size: 128,
            render: true,
            depth: false,
            segmentation: false,
            quality: RenderQuality::default(),
            init_noise: 0.0,
            settle_steps: 20,
            settle_action: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0],
        }
    }
}

/// Largest contact penetration accepted in a settled start (m).
pub const MAX_PENETRATION: f64 = 0.004;

/// What the policy sees after `reset` or `step`. Images are upright (row 0 = top), `[H, W, 3]` row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Control steps taken since reset.
    pub step: usize,
    /// Image side in pixels (0 when rendering is off).
    pub image_size: usize,
    /// Third-person RGB `[H, W, 3]` (empty when rendering is off).
    pub agentview_rgb: Vec<u8>,
    /// Wrist RGB `[H, W, 3]` (empty when rendering is off).
    pub eye_in_hand_rgb: Vec<u8>,
    /// Third-person depth in metres `[H, W]`, if enabled.
    pub agentview_depth: Option<Vec<f32>>,
    /// Wrist depth in metres `[H, W]`, if enabled.
    pub eye_in_hand_depth: Option<Vec<f32>>,
    /// Third-person instance ids `[H, W]` (top-level body id of the visible geom, −1 background), if enabled.
    pub agentview_segmentation: Option<Vec<i32>>,
    /// Wrist instance ids `[H, W]`, if enabled.
    pub eye_in_hand_segmentation: Option<Vec<i32>>,
    /// Proprio: eef position (3) + eef axis-angle (3) + finger qpos (2).
    pub state: [f32; 8],
    /// Arm joint positions.
    pub joint_state: [f32; 7],
    /// End-effector (grip site) position, full precision.
    pub eef_pos: [f64; 3],
    /// End-effector orientation (`robot0_right_hand` body), quaternion wxyz.
    pub eef_quat: [f64; 4],
    /// Goal progress (task environments).
    pub goal: Option<GoalStatus>,
    /// Privileged state of every scene instance, in the scene's instance order (task
    /// environments; empty for the minimal scene).
    pub objects: Vec<ObjectState>,
}

/// The simulator's privileged state of one scene instance (object or fixture) at an observation.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectState {
    /// Position of the instance's root body, world frame (m).
    pub pos: [f64; 3],
    /// Orientation of the root body, quaternion (w, x, y, z).
    pub quat: [f64; 4],
    /// Both gripper fingers touch one of the instance's geoms.
    pub grasped: bool,
    /// The instance's articulated parts, one per internal joint, in joint order.
    pub parts: Vec<PartPose>,
}

/// The privileged state of one articulated part of an instance (a drawer, a knob, a door).
#[derive(Debug, Clone, PartialEq)]
pub struct PartPose {
    /// Part name within the instance's category: `top_handle`, `middle_handle` and
    /// `bottom_handle` for a wooden cabinet's drawers, `knob` for a stove, else the joint's name
    /// without the instance prefix.
    pub name: String,
    /// Where the part is taken: the handle bar's centre for a wooden cabinet's drawer, the
    /// knob's centre for a stove, else the origin of the joint's body (world frame, m).
    pub pos: [f64; 3],
    /// Orientation of the joint's body, quaternion (w, x, y, z).
    pub quat: [f64; 4],
    /// The joint's position (m for a slide, rad for a hinge).
    pub joint: f64,
}

impl PartPose {
    /// Position and quaternion as 7 floats (the episode files' part `pose`).
    pub fn pose(&self) -> [f32; 7] {
        let [x, y, z] = self.pos;
        let [w, a, b, c] = self.quat;
        [x, y, z, w, a, b, c].map(|v| v as f32)
    }
}

impl ObjectState {
    /// Position and quaternion as 7 floats (the episode files' `pose`).
    pub fn pose(&self) -> [f32; 7] {
        let [x, y, z] = self.pos;
        let [w, a, b, c] = self.quat;
        [x, y, z, w, a, b, c].map(|v| v as f32)
    }
}

/// Builds the MJCF of the minimal scene: LIBERO's tabletop arena, cameras, the Panda, one box.
pub fn minimal_scene_xml() -> String {
    let cube = format!(
        r#"<body name="cube" pos="0 0 0.92">
<freejoint name="cube_joint"/>
<geom name="cube_g" type="box" size="0.02 0.02 0.02" mass="0.1" friction="1 0.005 0.0001" rgba="0.85 0.15 0.12 1" contype="{}" conaffinity="{}" group="1"/>
</body>
"#,
        crate::world::assets::bits::OBJECT_TYPE,
        crate::world::assets::bits::OBJECT_AFFINITY
    );
    crate::world::scene::world_xml(Arena::Tabletop, "libero_tabletop_box", "", &cube)
}

/// What the environment simulates besides the robot.
enum World {
    /// The minimal scene: one free box (qpos address of its free joint).
    Minimal { cube_qpos: usize },
    /// A task scene composed from BDDL, with its goal tracker when it comes from a task.
    Task(Box<Scene>, Option<Box<GoalTracker>>),
}

/// Goal progress reported with each observation of a task environment.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GoalStatus {
    /// Satisfied subgoals.
    pub satisfied: usize,
    /// Goal length.
    pub goal_len: usize,
    /// Every subgoal satisfied and the final one holds now, with no over-repetition.
    pub done: bool,
    /// Over-repetition after completion.
    pub failed: bool,
    /// Text of the pending subgoal ("bowl 1 on plate 3"), `None` once complete.
    pub pending: Option<String>,
    /// Texts of the satisfied subgoals ("one: bowl 1 on plate 1", …).
    pub satisfied_texts: Vec<String>,
}

impl GoalStatus {
    /// The progress in the episode files' terms: what the recorder writes and what a policy's
    /// input processor reads at evaluation.
    pub fn progress(&self) -> data::GoalProgress {
        data::GoalProgress {
            satisfied: self.satisfied as u32,
            total: self.goal_len as u32,
            satisfied_subgoals: self.satisfied_texts.clone(),
            current_subgoal: self.pending.clone().unwrap_or_default(),
        }
    }

    /// Tiered credit, satisfied / goal length.
    pub fn tiered(&self) -> f64 {
        self.satisfied as f64 / self.goal_len.max(1) as f64
    }
}

/// The environment: LIBERO's control loop over the minimal scene or a task scene.
pub struct Env {
    model: Arc<Model>,
    data: Data,
    renderer: Option<Renderer>,
    ids: PandaIds,
    osc: OscPose,
    gripper: GripperRamp,
    cfg: EnvConfig,
    steps: usize,
    world: World,
    cams: [usize; 2],
    burners: Vec<(usize, usize)>,
    /// Geoms of the left and the right finger (for the grasp flag of [`ObjectState`]).
    fingers: [Vec<usize>; 2],
}

impl Env {
    /// The minimal scene (table, robot, one box). Call [`Env::reset`] before stepping.
    pub fn new(cfg: EnvConfig) -> Result<Env, EnvError> {
        let model = Arc::new(Model::from_xml_str(&minimal_scene_xml())?);
        let cube_joint = model.require(ObjType::Joint, "cube_joint")?;
        let cube_qpos = model.joint_qpos_adr(cube_joint);
        Self::build(model, World::Minimal { cube_qpos }, cfg)
    }

    /// A task scene (see [`Scene::build`]) without goal tracking. `reset` samples a valid initial state
    /// and settles it.
    pub fn with_scene(scene: Scene, cfg: EnvConfig) -> Result<Env, EnvError> {
        let model = scene.model.clone();
        Self::build(model, World::Task(Box::new(scene), None), cfg)
    }

    /// A shipped or user task: its scene, and its goal tracked at every step (reported in
    /// [`Observation::goal`]). Every `:init` and `:goal` atom is checked against the scene here.
    pub fn from_task(task: &TaskSpec, cfg: EnvConfig) -> Result<Env, EnvError> {
        Self::from_task_with_assets(task, cfg, crate::pack::AssetPack::Builtin)
    }

    /// [`Env::from_task`] with the world from an asset pack: `Builtin` (the primitives) or `Libero`
    /// (from the installed pack: LIBERO's arena, objects and fixtures with their meshes and collision
    /// boxes under the same names, joints and region sites, and the Panda in robosuite's meshes, so
    /// predicates, init states and the tracker work unchanged). Tasks of the pack-only suites always
    /// use `Libero`.
    pub fn from_task_with_assets(
        task: &TaskSpec,
        cfg: EnvConfig,
        assets: crate::pack::AssetPack,
    ) -> Result<Env, EnvError> {
        // The pack-only suites cannot be built from the builtin primitives.
        let assets = if task.suite.pack_only() {
            crate::pack::AssetPack::Libero
        } else {
            assets
        };
        let pack = match assets {
            crate::pack::AssetPack::Builtin => None,
            crate::pack::AssetPack::Libero => {
                let mut p = crate::pack::LiberoPack::locate_default()
                    .map_err(|e| EnvError::Config(e.to_string()))?;
                // The full robot meshes with the LIBERO look (high quality), light ones otherwise.
                p.light_robot = cfg.quality != RenderQuality::high();
                Some(p)
            }
        };
        let in_task = |source: SceneError| EnvError::TaskScene {
            task: task.id.clone(),
            source,
        };
        let scene = Scene::build_with(SceneSpec::from_problem(&task.problem), pack.as_ref())
            .map_err(in_task)?;
        for a in task.problem.init.iter().chain(task.problem.goal.atoms()) {
            scene.check_atom(a.predicate, &a.args).map_err(in_task)?;
        }
        let tracker = task.tracker();
        let model = scene.model.clone();
        Self::build(
            model,
            World::Task(Box::new(scene), Some(Box::new(tracker))),
            cfg,
        )
    }

    fn build(model: Arc<Model>, world: World, cfg: EnvConfig) -> Result<Env, EnvError> {
        if cfg.render && (cfg.image_size == 0 || cfg.image_size > 4096) {
            return Err(EnvError::Config(format!(
                "image_size must be 1..=4096, got {}",
                cfg.image_size
            )));
        }
        if !(cfg.init_noise >= 0.0 && cfg.init_noise.is_finite()) {
            return Err(EnvError::Config(format!(
                "init_noise must be a finite non-negative number, got {}",
                cfg.init_noise
            )));
        }
        let ids = PandaIds::find(&model)?;
        let mut data = Data::new(model.clone())?;
        data.forward()?;
        let renderer = if cfg.render {
            Some(Renderer::new(
                &model,
                cfg.image_size,
                cfg.image_size,
                cfg.quality,
            )?)
        } else {
            None
        };
        let cams = [
            model.require(ObjType::Camera, AGENTVIEW)?,
            model.require(ObjType::Camera, EYE_IN_HAND)?,
        ];
        // Stoves glow when on (LIBERO's `_post_process`): (burner site, instance index).
        let burners = match &world {
            World::Task(scene, _) => scene
                .instances
                .iter()
                .enumerate()
                .filter(|(_, i)| i.def.builtin == Some(Category::FlatStove))
                .filter_map(|(k, i)| {
                    model
                        .id(ObjType::Site, &format!("{}_burner", i.name))
                        .map(|s| (s, k))
                })
                .collect(),
            World::Minimal { .. } => Vec::new(),
        };
        let osc = OscPose::new(ids.clone(), &mut data);
        // Finger geoms by their bodies: robosuite's Panda hand and ours name them alike.
        let finger_of = |g: usize| {
            let body = model.name(ObjType::Body, model.geom_body(g)).unwrap_or("");
            match body {
                "gripper0_leftfinger" | "gripper0_finger_joint1_tip" => Some(0),
                "gripper0_rightfinger" | "gripper0_finger_joint2_tip" => Some(1),
                _ => None,
            }
        };
        let mut fingers = [Vec::new(), Vec::new()];
        for g in 0..model.ngeom() {
            if let Some(side) = finger_of(g) {
                fingers[side].push(g);
            }
        }
        Ok(Env {
            model,
            data,
            renderer,
            ids,
            osc,
            gripper: GripperRamp::default(),
            cfg,
            steps: 0,
            world,
            cams,
            burners,
            fingers,
        })
    }

    /// The task scene, if this is a task environment.
    pub fn scene(&self) -> Option<&Scene> {
        match &self.world {
            World::Task(s, _) => Some(s),
            World::Minimal { .. } => None,
        }
    }

    /// Predicates on the current state (task environments).
    pub fn predicates(&self) -> Option<Predicates<'_>> {
        self.scene().map(|s| Predicates::new(s, &self.data))
    }

    /// The compiled model.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The simulation state (read-only).
    pub fn data(&self) -> &Data {
        &self.data
    }

    /// The Panda's indices.
    pub fn robot(&self) -> &PandaIds {
        &self.ids
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.cfg
    }

    /// The renderer, if rendering is on.
    pub fn renderer_mut(&mut self) -> Option<(&mut Renderer, &mut Data)> {
        self.renderer.as_mut().map(|r| (r, &mut self.data))
    }

    /// Resets from `seed` and observes. The minimal scene places the box; a task scene samples LIBERO's
    /// placement, settles it with `settle_steps` idle steps, and redraws (continuing the same seeded stream)
    /// until every `:init` relation holds and nothing interpenetrates.
    pub fn reset(&mut self, seed: u64) -> Result<Observation, EnvError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        const ATTEMPTS: usize = 20;
        let mut last_problem = String::new();
        for _ in 0..ATTEMPTS {
            self.data.reset();
            self.place_robot(&mut rng);
            match &self.world {
                World::Minimal { cube_qpos } => {
                    let c = *cube_qpos;
                    let x = rng.random_range(-0.10..0.10);
                    let y = rng.random_range(-0.15..0.15);
                    let yaw: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                    self.data.qpos_mut()[c..c + 7].copy_from_slice(&[
                        x,
                        y,
                        0.92,
                        (yaw / 2.0).cos(),
                        0.0,
                        0.0,
                        (yaw / 2.0).sin(),
                    ]);
                }
                World::Task(scene, _) => scene.sample_init(&mut self.data, &mut rng)?,
            }
            self.data.qvel_mut().fill(0.0);
            self.restart_control()?;
            if let World::Task(..) = self.world {
                self.settle_physics()?;
                if let Some(p) = self.start_problem() {
                    last_problem = p;
                    continue;
                }
            }
            return self.start_episode();
        }
        Err(EnvError::Config(format!(
            "no valid initial state after {ATTEMPTS} draws from seed {seed}: {last_problem}"
        )))
    }

    /// Resets to a stored state, as LIBERO's `set_init_state` after `reset()`: the fixtures are
    /// placed from `seed` (LIBERO re-draws them at every reset; init states do not hold them), then
    /// `qpos` and `qvel` are written verbatim and the model is forwarded. As in robosuite, the
    /// controller is the one made at the reset pose (before the state is written): its orientation
    /// goal and nullspace posture stay those of the nominal start until a rotation is commanded
    /// (libero.md §5.5), and the gripper command is at rest. No settling: call [`Env::settle`] for
    /// the evaluators' idle steps. A state of another layout is an error naming both sizes.
    pub fn reset_to_init(
        &mut self,
        seed: u64,
        qpos: &[f64],
        qvel: &[f64],
    ) -> Result<Observation, EnvError> {
        let (nq, nv) = (self.model.nq(), self.model.nv());
        if qpos.len() != nq || qvel.len() != nv {
            return Err(EnvError::Config(format!(
                "init state has nq {} and nv {}, this model has nq {nq} and nv {nv}",
                qpos.len(),
                qvel.len()
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        self.data.reset();
        self.place_robot(&mut rng);
        if let World::Task(scene, _) = &self.world {
            scene.sample_fixtures(&mut self.data, &mut rng)?;
        }
        self.restart_control()?;
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.data.forward()?;
        self.start_episode()
    }

    /// Poses the fixture `name` (a welded instance) at `pos` with orientation `quat` (wxyz), forwards
    /// and observes: to reproduce the fixture poses of a LIBERO run, which init states do not hold.
    /// Call it after [`Env::reset_to_init`]; the episode (step count, goal tracker) restarts, the
    /// controller is kept.
    pub fn set_fixture_pose(
        &mut self,
        name: &str,
        pos: [f64; 3],
        quat: [f64; 4],
    ) -> Result<Observation, EnvError> {
        let scene = self
            .scene()
            .ok_or_else(|| EnvError::Config("this env has no task scene".into()))?;
        let m = scene
            .instance(name)
            .and_then(|i| scene.instances[i].mocap)
            .ok_or_else(|| EnvError::Config(format!("'{name}' is not a fixture of this scene")))?;
        self.data.mocap_pos_mut()[3 * m..3 * m + 3].copy_from_slice(&pos);
        self.data.mocap_quat_mut()[4 * m..4 * m + 4].copy_from_slice(&quat);
        self.data.forward()?;
        self.start_episode()
    }

    /// Runs the configured settle steps (`settle_steps` × `settle_action`, not counted as policy
    /// steps) and restarts the goal tracker on the settled state, as [`Env::reset`] does.
    pub fn settle(&mut self) -> Result<Observation, EnvError> {
        self.settle_physics()?;
        self.start_episode()
    }

    /// Zero controls, forward, and restart the controller as robosuite re-creates it at reset: goal =
    /// current pose, posture = current arm qpos, gripper command at rest.
    fn restart_control(&mut self) -> Result<(), EnvError> {
        self.data.ctrl_mut().fill(0.0);
        self.data.forward()?;
        self.osc = OscPose::new(self.ids.clone(), &mut self.data);
        self.gripper = GripperRamp::default();
        Ok(())
    }

    /// `settle_steps` control steps of `settle_action`.
    fn settle_physics(&mut self) -> Result<(), EnvError> {
        let action = self.cfg.settle_action;
        for _ in 0..self.cfg.settle_steps {
            self.step_physics(&action)?;
        }
        Ok(())
    }

    /// Step counter to 0 and the goal tracker restarted on the current state (LIBERO-Mem counts from the
    /// settled start), then the first observation.
    fn start_episode(&mut self) -> Result<Observation, EnvError> {
        self.steps = 0;
        if let World::Task(_, Some(t)) = &mut self.world {
            t.reset();
        }
        self.track_goal();
        self.observe()
    }

    /// Why the settled start is invalid (an `:init` relation false, or interpenetration), if it is.
    fn start_problem(&self) -> Option<String> {
        let scene = self.scene()?;
        let p = Predicates::new(scene, &self.data);
        for atom in &scene.spec.init {
            match p.eval(atom.predicate, &atom.args) {
                Ok(true) => {}
                Ok(false) => return Some(format!("({atom}) is false after settling")),
                Err(e) => return Some(format!("({atom}): {e}")),
            }
        }
        for c in self.data.contacts() {
            if c.dist < -MAX_PENETRATION {
                return Some(format!(
                    "geoms {} and {} interpenetrate by {:.1} mm",
                    self.model.name(ObjType::Geom, c.geom1).unwrap_or("?"),
                    self.model.name(ObjType::Geom, c.geom2).unwrap_or("?"),
                    -c.dist * 1e3
                ));
            }
        }
        None
    }

    fn place_robot(&mut self, rng: &mut ChaCha8Rng) {
        let noise = self.cfg.init_noise;
        let ids = &self.ids;
        let qpos = self.data.qpos_mut();
        for i in 0..7 {
            let n = if noise > 0.0 {
                gaussian(rng) * noise
            } else {
                0.0
            };
            qpos[ids.arm_qpos[i]] = INIT_QPOS[i] + n;
        }
        qpos[ids.finger_qpos[0]] = INIT_FINGERS[0];
        qpos[ids.finger_qpos[1]] = INIT_FINGERS[1];
    }

    /// Applies one 7-D action `[dx, dy, dz, dax, day, daz, gripper]` in [−1, 1] for one control step.
    pub fn step(&mut self, action: &[f32]) -> Result<Observation, EnvError> {
        self.step_physics(action)?;
        self.track_goal();
        self.observe()
    }

    /// One goal-tracker step on the current state (LIBERO-Mem's once-per-control-step check).
    fn track_goal(&mut self) {
        if let World::Task(scene, Some(tracker)) = &mut self.world {
            let p = Predicates::new(scene, &self.data);
            // Atoms were checked against the scene at construction; LIBERO's own evaluation errors
            // (In with an object container while touching) count as false.
            tracker.step(&mut |a: &Atom| p.eval(a.predicate, &a.args).unwrap_or(false));
        }
    }

    /// The goal tracker (task environments built from a task): the atoms satisfied so far.
    pub fn tracker(&self) -> Option<&crate::task::GoalTracker> {
        match &self.world {
            World::Task(_, Some(t)) => Some(t),
            _ => None,
        }
    }

    /// Goal progress now (task environments built from a task).
    pub fn goal(&self) -> Option<GoalStatus> {
        match &self.world {
            World::Task(_, Some(t)) => Some(GoalStatus {
                satisfied: t.satisfied_len(),
                goal_len: t.goal_len(),
                done: t.done(),
                failed: t.failed(),
                pending: t.pending_text(),
                satisfied_texts: t.satisfied_texts(),
            }),
            _ => None,
        }
    }

    /// Runs the control loop for one action without rendering or observing.
    pub fn step_physics(&mut self, action: &[f32]) -> Result<(), EnvError> {
        if action.len() != 7 {
            return Err(EnvError::Action(format!(
                "expected 7 values, got {}",
                action.len()
            )));
        }
        if let Some(i) = action.iter().position(|a| !a.is_finite()) {
            return Err(EnvError::Action(format!("value {i} is {}", action[i])));
        }
        let a: Vec<f64> = action.iter().map(|&v| v as f64).collect();
        // Invariant: positions and velocities are computed (forward at reset, step1 after each substep).
        for sub in 0..SUBSTEPS {
            if sub == 0 {
                self.osc
                    .set_goal(&self.data, [a[0], a[1], a[2], a[3], a[4], a[5]]);
            }
            let tau = self.osc.torques(&mut self.data);
            let fingers = self.gripper.substep(a[6]);
            let ids = &self.ids;
            let ctrl = self.data.ctrl_mut();
            for i in 0..7 {
                ctrl[ids.arm_act[i]] = tau[i];
            }
            ctrl[ids.finger_act[0]] = fingers[0];
            ctrl[ids.finger_act[1]] = fingers[1];
            self.data.step2()?;
            self.data.step1()?;
        }
        self.steps += 1;
        Ok(())
    }

    /// The privileged state of every scene instance now (empty for the minimal scene).
    pub fn object_states(&self) -> Vec<ObjectState> {
        let World::Task(scene, _) = &self.world else {
            return Vec::new();
        };
        let contacts = self.data.contacts();
        scene
            .instances
            .iter()
            .map(|inst| {
                let touches = |side: usize| {
                    contacts.iter().any(|c| {
                        let f = &self.fingers[side];
                        (f.contains(&c.geom1) && inst.geoms.contains(&c.geom2))
                            || (f.contains(&c.geom2) && inst.geoms.contains(&c.geom1))
                    })
                };
                ObjectState {
                    pos: self.data.body_pos(inst.root_body),
                    quat: self.data.body_quat(inst.root_body),
                    grasped: touches(0) && touches(1),
                    parts: self.part_poses(&inst.name, &inst.joints),
                }
            })
            .collect()
    }

    /// The articulated parts of the instance `name` with internal `joints` (joint id, qpos
    /// address, class), in joint order.
    fn part_poses(
        &self,
        name: &str,
        joints: &[(usize, usize, crate::world::assets::Articulation)],
    ) -> Vec<PartPose> {
        use crate::world::assets::Articulation;
        let model = self.data.model();
        let q = self.data.qpos();
        joints
            .iter()
            .map(|&(j, adr, art)| {
                let body = model.joint_body(j);
                let joint = model.name(ObjType::Joint, j).unwrap_or_default();
                let local = joint
                    .strip_prefix(name)
                    .map_or(joint, |s| s.trim_start_matches('_'));
                // The builtin cabinet's handle bars are the first geom of each drawer's handle
                // group (`<name>_g25`, `_g35`, `_g45`), the stove's knob its own body.
                let handle = match (art, local) {
                    (Articulation::CabinetDrawer, "top_level") => Some(("top_handle", 25)),
                    (Articulation::CabinetDrawer, "middle_level") => Some(("middle_handle", 35)),
                    (Articulation::CabinetDrawer, "bottom_level") => Some(("bottom_handle", 45)),
                    _ => None,
                }
                .and_then(|(part, g)| {
                    model
                        .id(ObjType::Geom, &format!("{name}_g{g}"))
                        .map(|g| (part.to_string(), self.data.geom_pos(g)))
                });
                let (part, pos) = match (art, handle) {
                    (_, Some(h)) => h,
                    (Articulation::StoveKnob, None) => ("knob".into(), self.data.body_pos(body)),
                    _ => (local.to_string(), self.data.body_pos(body)),
                };
                PartPose {
                    name: part,
                    pos,
                    quat: self.data.body_quat(body),
                    joint: q[adr],
                }
            })
            .collect()
    }

    /// Observes the current state (renders the cameras if enabled).
    pub fn observe(&mut self) -> Result<Observation, EnvError> {
        let eef_pos = self.data.site_pos(self.ids.grip_site);
        let eef_quat = self.data.body_quat(self.ids.hand_body);
        let aa = quat_to_axis_angle(eef_quat);
        let qpos = self.data.qpos();
        let f = [qpos[self.ids.finger_qpos[0]], qpos[self.ids.finger_qpos[1]]];
        let state = [
            eef_pos[0] as f32,
            eef_pos[1] as f32,
            eef_pos[2] as f32,
            aa[0] as f32,
            aa[1] as f32,
            aa[2] as f32,
            f[0] as f32,
            f[1] as f32,
        ];
        let mut joint_state = [0f32; 7];
        for i in 0..7 {
            joint_state[i] = qpos[self.ids.arm_qpos[i]] as f32;
        }
        let mut obs = Observation {
            step: self.steps,
            image_size: 0,
            agentview_rgb: Vec::new(),
            eye_in_hand_rgb: Vec::new(),
            agentview_depth: None,
            eye_in_hand_depth: None,
            agentview_segmentation: None,
            eye_in_hand_segmentation: None,
            state,
            joint_state,
            eef_pos,
            eef_quat,
            goal: self.goal(),
            objects: self.object_states(),
        };
        if let Some(r) = self.renderer.as_mut() {
            if let World::Task(scene, _) = &self.world {
                let q = self.data.qpos();
                let decor = self
                    .burners
                    .iter()
                    .filter(|&&(_, k)| {
                        scene.instances[k]
                            .joints
                            .iter()
                            .any(|&(_, a, art)| art.turn_on(q[a]))
                    })
                    .map(|&(site, _)| Decor {
                        pos: self.data.site_pos(site),
                        mat: self.data.site_mat(site),
                        size: [0.0625, 0.0005],
                        rgba: [1.0, 0.15, 0.05, 1.0],
                    })
                    .collect();
                r.set_decor(decor);
            }
            let s = self.cfg.image_size;
            let ch = Channels {
                rgb: true,
                depth: self.cfg.depth,
                segmentation: self.cfg.segmentation,
            };
            let mut frames = Vec::with_capacity(2);
            for &cam in &self.cams {
                frames.push(r.render(&mut self.data, cam, s, s, ch)?);
            }
            let model = &self.model;
            let to_instances = |seg: Vec<i32>| -> Vec<i32> {
                seg.into_iter()
                    .map(|g| {
                        if g < 0 {
                            -1
                        } else {
                            model.body_root(model.geom_body(g as usize)) as i32
                        }
                    })
                    .collect()
            };
            let eye = frames.pop().expect("two frames");
            let agent = frames.pop().expect("two frames");
            obs.image_size = s;
            obs.agentview_rgb = agent.rgb.unwrap_or_default();
            obs.eye_in_hand_rgb = eye.rgb.unwrap_or_default();
            obs.agentview_depth = agent.depth;
            obs.eye_in_hand_depth = eye.depth;
            obs.agentview_segmentation = agent.segmentation.map(to_instances);
            obs.eye_in_hand_segmentation = eye.segmentation.map(to_instances);
        }
        Ok(obs)
    }

    /// World position of the box (minimal scene only).
    pub fn cube_pos(&self) -> Option<[f64; 3]> {
        match self.world {
            World::Minimal { cube_qpos: c } => {
                let q = &self.data.qpos()[c..c + 3];
                Some([q[0], q[1], q[2]])
            }
            World::Task(..) => None,
        }
    }
}

/// Standard normal sample (Box–Muller) from the episode's ChaCha stream.
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
