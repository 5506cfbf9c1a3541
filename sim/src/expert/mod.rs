//! The scripted expert: physics-only manipulation through the same OSC_POSE action interface a policy
//! uses, driven by privileged state (object poses read from the simulation).
//!
//! An [`Expert`] turns the task's goal into a queue of low-level [`Op`]s (move to a live target, close or
//! open the gripper, hold, wait for the goal tracker) the first time [`Expert::act`] is called, and then
//! returns one action per control step until the plan is exhausted (`None`). Targets are evaluated on the
//! live state at every step (an object's pose, a held object's offset to its destination), so the plan
//! corrects itself as things move. Variation comes from a ChaCha stream seeded by the episode seed:
//! approach offsets, speed gains, short pauses and small Gaussian noise on the translation actions.
//!
//! The goal tracker's debouncing shapes the plans: a subgoal is appended only after the pending atom was
//! false for more than 15 counted steps and true for more than 5 since the previous append, so the expert
//! keeps a held object away long enough ([`Op::WaitNonlive`]) and holds a placed state until the tracker
//! appends it ([`Op::WaitSatisfied`]); once complete it releases and retreats without disturbing the scene.

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::task::{Atom, Category, TaskSpec};
use crate::world::controller::orientation_error;
use crate::world::env::{Env, EnvConfig, EnvError, Observation};
use crate::world::scene::Scene;

pub mod branch;
pub mod math;
pub mod op;
mod plan;

pub use branch::BranchRule;
use math::{add, gaussian, norm, qrot, sub};
pub use op::{Op, Point, Target};
pub use plan::subgoal_branches;

/// Expert settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertConfig {
    /// Standard deviation of the Gaussian noise added to translation actions while moving.
    pub action_noise: f64,
    /// Seeded variation (offsets, speeds, pauses) on; off gives one nominal demonstration per start.
    pub variation: bool,
    /// Control steps to keep observing after the plan has finished (the goal must still hold).
    pub hold_steps: usize,
    /// How an `Or` goal's branch is chosen (T7's and T8's bowl orders, T9/T10's baskets).
    pub branch_rule: BranchRule,
    /// Standard deviation of the Gaussian noise added to the *executed* translation while moving
    /// with the gripper open (DART: the arm is pushed off the nominal path, the recorded action
    /// stays the expert's noise-free correction); 0 = none. Seeded by the episode, own stream.
    pub exec_noise: f64,
}

impl Default for ExpertConfig {
    fn default() -> Self {
        ExpertConfig {
            action_noise: 0.03,
            variation: true,
            hold_steps: 5,
            branch_rule: BranchRule::Destination,
            exec_noise: 0.0,
        }
    }
}

/// Result of one expert episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeResult {
    /// Task id.
    pub task: String,
    /// Reset seed.
    pub seed: u64,
    /// Goal done (and not failed) at the end.
    pub success: bool,
    /// Control steps taken.
    pub steps: usize,
    /// The task's step budget.
    pub max_steps: usize,
    /// Satisfied / goal length at the end.
    pub tiered: f64,
    /// Over-repetition flagged.
    pub failed: bool,
    /// Why the episode ended.
    pub end: String,
}

/// The scripted expert for one episode.
pub struct Expert {
    task: TaskSpec,
    cfg: ExpertConfig,
    rng: ChaCha8Rng,
    /// The stream of the execution noise (separate, so that the plan does not depend on it).
    exec_rng: ChaCha8Rng,
    /// Translation offset of the latest action's execution (zero outside moves).
    perturb: [f32; 3],
    ops: Vec<Op>,
    cur: usize,
    op_steps: usize,
    op_start: Option<[f64; 3]>,
    planned: bool,
    init_rot: Option<Matrix3<f64>>,
    /// Orientation held during moves (set by [`Op::Orient`]).
    att: Option<Matrix3<f64>>,
    pending: Option<Atom>,
    nonlive: usize,
    last_satisfied: usize,
    /// Speed multiplier drawn per episode.
    speed: f64,
    finished_hold: usize,
    /// The branch (Or goals) the plan follows.
    pub branch: usize,
    /// Take over a running episode ([`Expert::resume`]): the hand's orientation at its start.
    resume_from: Option<[f64; 4]>,
}

impl Expert {
    /// An expert for `task`, varied by `seed` (the episode's reset seed is a natural choice).
    pub fn new(task: &TaskSpec, seed: u64) -> Expert {
        Expert::with_config(task, seed, ExpertConfig::default())
    }

    /// An expert with explicit settings.
    pub fn with_config(task: &TaskSpec, seed: u64, cfg: ExpertConfig) -> Expert {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6578_7065_7274);
        let speed = if cfg.variation {
            rng.random_range(0.85..1.15)
        } else {
            1.0
        };
        Expert {
            task: task.clone(),
            cfg,
            rng,
            exec_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x6461_7274),
            perturb: [0.0; 3],
            ops: Vec::new(),
            cur: 0,
            op_steps: 0,
            op_start: None,
            planned: false,
            init_rot: None,
            att: None,
            pending: None,
            nonlive: 0,
            last_satisfied: 0,
            speed,
            finished_hold: 0,
            branch: 0,
            resume_from: None,
        }
    }

    /// An expert that takes over an episode already under way (DAgger's relabelling: a policy has
    /// driven it so far). Its plan is built at the first [`act`](Self::act) from where the episode
    /// stands: the subgoals the goal tracker has appended are skipped (an `Or` goal keeps to a branch
    /// consistent with them), an object held by both fingers is carried on rather than grasped again,
    /// and otherwise the hand opens (when closed), rises clear of the objects (when low) and turns
    /// back to its starting orientation (when turned more than 0.15 rad away) first. Once the goal
    /// is complete it lets go and stays clear. `start_quat`: the hand's orientation (wxyz) at the
    /// episode's first observation, to which the plan's turns are relative.
    pub fn resume(task: &TaskSpec, seed: u64, cfg: ExpertConfig, start_quat: [f64; 4]) -> Expert {
        let mut e = Expert::with_config(task, seed, cfg);
        e.resume_from = Some(start_quat);
        e
    }

    /// The action to execute for `action`, the latest one [`act`](Self::act) returned: the same,
    /// or with [`ExpertConfig::exec_noise`] its translation pushed by a seeded Gaussian offset
    /// (clipped to [-1, 1]) while moving.
    pub fn executed(&self, action: [f32; 7]) -> [f32; 7] {
        let mut a = action;
        for (v, p) in a.iter_mut().zip(self.perturb) {
            *v = (*v + p).clamp(-1.0, 1.0);
        }
        a
    }

    /// The planned ops (empty before the first [`act`](Self::act)).
    pub fn ops(&self) -> &[Op] {
        &self.ops
    }

    /// Index of the op being executed.
    pub fn current_op(&self) -> usize {
        self.cur
    }

    /// The next action for the state `env` is in (`obs` is its latest observation), or `None` when the
    /// demonstration is finished. Call once per control step, after `reset` and after each `step`.
    pub fn act(&mut self, env: &Env, obs: &Observation) -> Option<[f32; 7]> {
        let scene = env.scene()?;
        if !self.planned {
            self.planned = true;
            self.init_rot = Some(quat_mat(self.resume_from.unwrap_or(obs.eef_quat)));
            let mut b = plan::Builder::new(scene, env, &mut self.rng, self.cfg.variation);
            b.branch_rule(self.cfg.branch_rule, obs.eef_pos);
            let (ops, branch) = match self.resume_from {
                None => b.build(&self.task),
                Some(_) => {
                    let from = resume_point(env, obs);
                    let (ops, branch) = b.build_from(&self.task, &from);
                    let start = self.init_rot.unwrap_or_else(Matrix3::identity);
                    let mut all = if from.held.is_none() {
                        take_over_prefix(obs, &start)
                    } else {
                        Vec::new()
                    };
                    all.extend(ops);
                    self.last_satisfied = from.done;
                    (all, branch)
                }
            };
            self.ops = ops;
            self.branch = branch;
        }
        // Tracker bookkeeping for WaitNonlive.
        let sat = obs.goal.as_ref().map(|g| g.satisfied).unwrap_or(0);
        if sat != self.last_satisfied {
            self.last_satisfied = sat;
            self.nonlive = 0;
        }
        if self.pending.is_some() && !self.pending_holds(env) {
            self.nonlive += 1;
        }
        self.perturb = [0.0; 3];
        loop {
            if self.cur >= self.ops.len() {
                if self.finished_hold >= self.cfg.hold_steps {
                    return None;
                }
                self.finished_hold += 1;
                return Some([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
            }
            if let Some(a) = self.exec(scene, env, obs) {
                if std::env::var("SIM_EXPERT_TRACE").is_ok_and(|v| v == "2") {
                    eprintln!(
                        "    step {:>3} op {:>2} eef {:.3?} fingers {:.4?} act {:.2?}",
                        obs.step,
                        self.cur,
                        obs.eef_pos,
                        &obs.state[6..8],
                        a
                    );
                }
                self.op_steps += 1;
                return Some(clip(a));
            }
            if std::env::var_os("SIM_EXPERT_TRACE").is_some() {
                let q: Vec<f64> = scene
                    .instances
                    .iter()
                    .flat_map(|i| i.joints.iter().map(|&(_, adr, _)| env.data().qpos()[adr]))
                    .collect();
                let objs: Vec<[f64; 3]> = scene
                    .instances
                    .iter()
                    .filter(|i| i.def.kind == crate::world::assets::AssetKind::Movable)
                    .map(|i| env.data().body_pos(i.root_body))
                    .collect();
                eprintln!(
                    "  step {:>3} op {:>2} done after {:>3} steps: {:?} eef {:.3?} sat {} q {:.3?} objs {:.3?}",
                    obs.step,
                    self.cur,
                    self.op_steps,
                    short(&self.ops[self.cur]),
                    obs.eef_pos,
                    sat,
                    q,
                    objs
                );
            }
            self.cur += 1;
            self.op_steps = 0;
            self.op_start = None;
        }
    }

    fn pending_holds(&self, env: &Env) -> bool {
        self.pending.as_ref().is_some_and(|a| {
            env.predicates()
                .and_then(|p| p.eval(a.predicate, &a.args).ok())
                .unwrap_or(false)
        })
    }

    fn exec(&mut self, scene: &Scene, env: &Env, obs: &Observation) -> Option<[f32; 7]> {
        let eef = obs.eef_pos;
        let start = *self.op_start.get_or_insert(eef);
        let still = |g: f32| [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g];
        let op = self.ops[self.cur].clone();
        match op {
            Op::Pending(a) => {
                self.pending = a;
                self.nonlive = 0;
                None
            }
            Op::Move {
                target,
                grip,
                tol,
                max,
                gain,
                until_pending,
            } => {
                let t = self.target(scene, env, &target, eef, start);
                let e = sub(t, eef);
                if norm(e) < tol || self.op_steps >= max {
                    return None;
                }
                if until_pending && self.pending_holds(env) {
                    return None;
                }
                let g = gain * self.speed;
                let mut a = [0f32; 7];
                for k in 0..3 {
                    let n = if self.cfg.action_noise > 0.0 {
                        gaussian(&mut self.rng) * self.cfg.action_noise
                    } else {
                        0.0
                    };
                    a[k] = ((g * e[k]).clamp(-1.0, 1.0) + n) as f32;
                }
                if until_pending
                    && e[2] < -0.002
                    && let Target::Carry { held, .. } = target
                    && scene.instances[held].def.builtin == Some(Category::WineBottle)
                    && plan::geometry::horizontal_reach(eef) > 0.74
                {
                    // Setting a bottle down far out: the stretched arm barely answers the small
                    // proportional command near the surface; keep pressing down until it touches.
                    a[2] = a[2].min(-0.2);
                }
                a[6] = grip;
                // Only while reaching with the gripper open: pushes while carrying knock held
                // objects into fixtures (σ = 0.2 failed 8 of 8 attempts of a bowl-into-drawer demo).
                if self.cfg.exec_noise > 0.0 && grip < 0.0 {
                    for p in &mut self.perturb {
                        *p = (gaussian(&mut self.exec_rng) * self.cfg.exec_noise) as f32;
                    }
                }
                if let Some(goal) = self.att {
                    let err = orientation_error(&goal, &quat_mat(obs.eef_quat));
                    for k in 0..3 {
                        a[3 + k] = (err[k] * 2.5).clamp(-1.0, 1.0) as f32;
                    }
                }
                Some(a)
            }
            Op::Orient {
                yaw,
                axis,
                tilt,
                grip,
                max,
                hold,
            } => {
                let r0 = self.init_rot.unwrap_or_else(Matrix3::identity);
                let rz = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw);
                let ax = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(
                    axis[0], axis[1], axis[2],
                ));
                let rt = nalgebra::Rotation3::from_axis_angle(&ax, tilt);
                let goal = rt.into_inner() * rz.into_inner() * r0;
                let err = orientation_error(&goal, &quat_mat(obs.eef_quat));
                if err.norm() < 0.03 || self.op_steps >= max {
                    self.att = hold.then_some(goal);
                    return None;
                }
                Some(rotate_in_place(err, start, eef, grip))
            }
            Op::Attitude {
                rot,
                grip,
                max,
                hold,
            } => {
                let r0 = self.init_rot.unwrap_or_else(Matrix3::identity);
                let goal = Matrix3::from_row_slice(&rot) * r0;
                let err = orientation_error(&goal, &quat_mat(obs.eef_quat));
                if err.norm() < 0.03 || self.op_steps >= max {
                    self.att = hold.then_some(goal);
                    return None;
                }
                Some(rotate_in_place(err, start, eef, grip))
            }
            Op::Yaw { yaw, grip, max } => {
                let r0 = self.init_rot.unwrap_or_else(Matrix3::identity);
                let goal = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw)
                    .into_inner()
                    * r0;
                let cur = quat_mat(obs.eef_quat);
                let err = orientation_error(&goal, &cur);
                if err.norm() < 0.02 || self.op_steps >= max {
                    self.att = None;
                    return None;
                }
                Some(rotate_in_place(err, start, eef, grip))
            }
            Op::Grip { cmd, steps } => (self.op_steps < steps).then_some(still(cmd)),
            Op::Hold { steps, grip } => (self.op_steps < steps).then_some(still(grip)),
            Op::WaitSatisfied { n, max, grip } => {
                let sat = obs.goal.as_ref().map(|g| g.satisfied).unwrap_or(0);
                (sat < n && self.op_steps < max).then_some(still(grip))
            }
            Op::SkipIfSatisfied { n, count } => {
                let sat = obs.goal.as_ref().map(|g| g.satisfied).unwrap_or(0);
                if sat >= n {
                    self.cur += count;
                }
                None
            }
            Op::WaitNonlive { n, max, grip } => {
                (self.nonlive < n && self.op_steps < max).then_some(still(grip))
            }
            Op::WaitAtom { atom, max, grip } => {
                let holds = env
                    .predicates()
                    .and_then(|p| p.eval(atom.predicate, &atom.args).ok())
                    .unwrap_or(false);
                (!holds && self.op_steps < max).then_some(still(grip))
            }
        }
    }

    fn target(
        &self,
        scene: &Scene,
        env: &Env,
        t: &Target,
        eef: [f64; 3],
        start: [f64; 3],
    ) -> [f64; 3] {
        match t {
            Target::Grip(p) => point(scene, env, p),
            Target::Carry { held, to } => {
                let o = carry_ref(scene, env, *held);
                let p = point(scene, env, to);
                add(eef, sub(p, o))
            }
            Target::Rel(d) => add(start, *d),
            Target::RelZ(z) => [start[0], start[1], *z],
            Target::PullIn { h, dz } => {
                let (sx, sy) = (plan::geometry::SHOULDER[0], plan::geometry::SHOULDER[1]);
                let d = ((start[0] - sx).powi(2) + (start[1] - sy).powi(2)).sqrt();
                let k = if d > *h { (d - h) / d } else { 0.0 };
                [
                    start[0] - (start[0] - sx) * k,
                    start[1] - (start[1] - sy) * k,
                    start[2] + dz,
                ]
            }
        }
    }
}

/// The held object's origin as the hand sees it: a bottle held by the neck swings about the grasp
/// (a pendulum about the finger axis), so its origin is taken where it would be hanging straight below
/// the neck (chasing the swinging origin would pump the swing).
fn carry_ref(scene: &Scene, env: &Env, held: usize) -> [f64; 3] {
    let b = scene.instances[held].root_body;
    let p = env.data().body_pos(b);
    if scene.instances[held].def.builtin != Some(Category::WineBottle) {
        return p;
    }
    let c = [0.0, 0.0, plan::geometry::BOTTLE_NECK];
    add(p, sub(qrot(env.data().body_quat(b), c), c))
}

/// A world point from a [`Point`] on the live state.
pub fn point(scene: &Scene, env: &Env, p: &Point) -> [f64; 3] {
    match p {
        Point::Abs(v) => *v,
        Point::Body { inst, off, local } => {
            let b = scene.instances[*inst].root_body;
            let pos = env.data().body_pos(b);
            let o = if *local {
                qrot(env.data().body_quat(b), *off)
            } else {
                *off
            };
            add(pos, o)
        }
        Point::Site { site, off } => add(env.data().site_pos(*site), *off),
        Point::Rim {
            inst,
            off,
            coin,
            dest,
        } => {
            let pos = env.data().body_pos(scene.instances[*inst].root_body);
            let side =
                plan::geometry::clear_side_both(scene, env, *inst, pos, *dest, off[1], *coin);
            add(pos, [off[0], side * off[1], off[2]])
        }
    }
}

/// Runs one expert episode of `task` from `seed` with rendering off; stops when the expert is done,
/// the goal fails, or the step budget runs out.
pub fn run_episode(
    task: &TaskSpec,
    seed: u64,
    cfg: &ExpertConfig,
) -> Result<EpisodeResult, EnvError> {
    let mut env = Env::from_task(
        task,
        EnvConfig {
            render: false,
            ..EnvConfig::default()
        },
    )?;
    run_episode_in(&mut env, task, seed, cfg)
}

/// [`run_episode`] in an existing environment of `task` (reused across episodes).
pub fn run_episode_in(
    env: &mut Env,
    task: &TaskSpec,
    seed: u64,
    cfg: &ExpertConfig,
) -> Result<EpisodeResult, EnvError> {
    let mut obs = env.reset(seed)?;
    let mut ex = Expert::with_config(task, seed, cfg.clone());
    let mut end = "budget".to_string();
    while obs.step < task.max_steps {
        let Some(a) = ex.act(env, &obs) else {
            end = "plan finished".into();
            break;
        };
        obs = env.step(&a)?;
        if obs.goal.as_ref().is_some_and(|g| g.failed) {
            end = "over-repetition".into();
            break;
        }
    }
    let g = obs.goal.clone();
    let done = g.as_ref().is_some_and(|g| g.done && !g.failed);
    Ok(EpisodeResult {
        task: task.id.clone(),
        seed,
        success: done,
        steps: obs.step,
        max_steps: task.max_steps,
        tiered: g.as_ref().map(|g| g.tiered()).unwrap_or(0.0),
        failed: g.as_ref().is_some_and(|g| g.failed),
        end,
    })
}

/// Where a taken-over episode stands: the goal tracker's appended subgoals and the movable object
/// both fingers hold (if any).
fn resume_point(env: &Env, obs: &Observation) -> plan::From {
    let (done, satisfied) = env
        .tracker()
        .map(|t| (t.satisfied_len(), t.satisfied().to_vec()))
        .unwrap_or_default();
    let held = env.scene().and_then(|scene| {
        obs.objects.iter().enumerate().position(|(i, o)| {
            o.grasped
                && scene
                    .instances
                    .get(i)
                    .is_some_and(|inst| inst.def.kind == crate::world::assets::AssetKind::Movable)
        })
    });
    plan::From {
        done,
        satisfied,
        held,
    }
}

/// Height above the table from which a take-over needs no rise first.
const TAKE_OVER_CLEAR: f64 = 0.10;

/// Finger opening (sum of both finger joints, m) below which the hand counts as closed.
const FINGERS_OPEN: f32 = 0.06;

/// Whether the fingers are closed (or closing), from the observation's finger joints.
fn fingers_closed(obs: &Observation) -> bool {
    obs.state[6].abs() + obs.state[7].abs() < FINGERS_OPEN
}

/// Whether [`Expert::resume`] can take over at `obs` with a plan that goes on as the
/// demonstrations do from such a state: the goal complete, an object held, the fingers closed on
/// nothing (a missed grasp: open and start again), or the hand at least 10 cm above the table. Low
/// with the hand open — on the way down to a grasp, or just let go — its plan would first rise,
/// a label at odds with the demonstrations' at those states.
pub fn can_take_over(obs: &Observation) -> bool {
    let complete = obs.goal.as_ref().is_some_and(|g| g.satisfied >= g.goal_len);
    complete
        || obs.objects.iter().any(|o| o.grasped)
        || fingers_closed(obs)
        || obs.eef_pos[2] >= crate::world::scene::TABLE_TOP + TAKE_OVER_CLEAR
}

/// Orientation error (rad) from the start beyond which a take-over turns the hand back first;
/// below it the moves go on with the hand as it is, as the demonstrations' moves do (they send
/// no rotation).
const TAKE_OVER_TURN: f64 = 0.15;

/// The first ops of a take-over with nothing held: open the hand when closed, rise to 10 cm above
/// the table when lower, turn back to the starting orientation when turned away from it.
fn take_over_prefix(obs: &Observation, start: &Matrix3<f64>) -> Vec<Op> {
    let mut ops = Vec::new();
    if fingers_closed(obs) {
        ops.push(Op::Grip {
            cmd: -1.0,
            steps: 3,
        });
    }
    let clear = crate::world::scene::TABLE_TOP + TAKE_OVER_CLEAR;
    if obs.eef_pos[2] < clear {
        ops.push(Op::Move {
            target: Target::RelZ(clear),
            grip: -1.0,
            tol: 0.01,
            max: 30,
            gain: 12.0,
            until_pending: false,
        });
    }
    if orientation_error(start, &quat_mat(obs.eef_quat)).norm() > TAKE_OVER_TURN {
        ops.push(Op::Yaw {
            yaw: 0.0,
            grip: -1.0,
            max: 25,
        });
    }
    ops
}

fn short(op: &Op) -> String {
    let s = format!("{op:?}");
    s.chars().take(90).collect()
}

/// Turns the hand by the orientation error `err` while holding the grip site at `start` (it is at
/// `eef` now), gripper at `grip`.
fn rotate_in_place(err: Vector3<f64>, start: [f64; 3], eef: [f64; 3], grip: f32) -> [f32; 7] {
    let mut a = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, grip];
    for k in 0..3 {
        a[3 + k] = (err[k] * 2.5).clamp(-1.0, 1.0) as f32;
    }
    let e = sub(start, eef);
    for k in 0..3 {
        a[k] = (e[k] * 15.0).clamp(-1.0, 1.0) as f32;
    }
    a
}

fn clip(a: [f32; 7]) -> [f32; 7] {
    a.map(|v| v.clamp(-1.0, 1.0))
}

fn quat_mat(q: [f64; 4]) -> Matrix3<f64> {
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[0], q[1], q[2], q[3],
    ));
    uq.to_rotation_matrix().into_inner()
}

/// How the expert works and what it cannot do yet; appended to `docs/expert.md` by `sim expert-eval
/// --markdown`.
pub const NOTES: &str = r#"## How the expert works

`sim::expert` drives the robot only through `Env::step` (OSC_POSE deltas, clipped to [−1, 1]; physics
grasps, no welds, no state writes), reading privileged state (body, site and geom poses) to set targets.

```rust
let task = sim::task::resolve("t3")?;
let mut env = sim::Env::from_task(&task, sim::EnvConfig { render: false, ..Default::default() })?;
let mut obs = env.reset(seed)?;
let mut expert = sim::expert::Expert::new(&task, seed);      // seeded variation
while let Some(action) = expert.act(&env, &obs) {             // None: demonstration finished
    obs = env.step(&action)?;                                 // stop also at task.max_steps
}
// or: sim::expert::run_episode(&task, seed, &ExpertConfig::default())? -> EpisodeResult
```

* **Plan.** On the first `act` the goal is split into subgoals (`subgoal_branches`; an `Or` branch is
  chosen by where things are: the branch whose first object is nearest to where it goes — T7: the bowl
  nearer the empty plate moves first; T9/T10: the cheese goes into the basket nearest to it; a rule a
  policy can see, unlike a draw from the seed; `ExpertConfig::branch_rule = Gripper`, `sim generate
  --branch-rule gripper`, takes instead the first object nearest to the hand, ties by destination, so
  that each object's own offset to the hand decides T7's first bowl) and turned into a queue of ops: move (proportional, gain ≈ 12 action units per
  metre, to a live target: a point on an object, or *carry* — the held object's origin to a destination),
  yaw, gripper open/close (10–12 steps, fully closed before lifting), hold, wait for the tracker.
* **Grasps.** Bowl: pinch the rim wall on the ±y side whose neighbourhood is freer (the 20 cm hand box is
  checked against tall objects and fixtures, decided on the live state, scored at the source and at
  the destination; a side blocked at the source while the other is free is never taken); bowls beyond
  ~0.72 m from the shoulder, or under an open drawer, are pinched at the near (−x) rim with the hand
  yawed 90°. Bottle: the neck (hand yawed 90° when the rack is beside it); a neck pinch is a pivot, so
  a carried bottle is steered by the point hanging straight below the neck, not by its swinging origin.
  Cream cheese: across its 4.3 cm width. Basket: the wall facing ±y, then slid 1.5 cm above the
  table. Plate: its +y rim pinched, lifted 8 cm (over the cream cheese) and set down in the region
  where its footprint clears the objects already there.
* **Articulated fixtures.** Drawers: the hand is yawed so the fingers close along the handle bar and
  tilted ~40° about the horizontal so it stays in front of the drawer above; it slides in around the
  bar's ends, pinches them and pulls 16 cm along the slide (moves hold that orientation). Stove: the
  fingers pinch the knob's pointer bar across its thickness and the wrist twists 0.75 rad.
* **Wine rack.** The rack is a post with two shelves inclined 31° and a stopper along each lower edge
  (LIBERO's collision model); `top_region` starts at the top stopper and reaches 10 cm up the shelf.
  The bottle is laid on the top shelf beside the post, along the incline, neck up and bottom against
  the stopper, as a wine rack holds bottles. The neck is pinched from above with the fingers closing
  along the shelf: a pinch is a free pivot about the finger axis, so the bottle hangs upright while
  carried, is set down on its bottom rim 4 cm up the shelf from the stopper, and the hand then carries
  the neck up and along the incline in four waypoints: the bottle tips over about the pinch and lies
  down, its bottom sliding down against the stopper. The fingers open sideways and the hand rises.
* **Reach.** A straight arm is a singularity the OSC cannot leave: far out the expert first pulls in
  towards the shoulder before lifting and carries lower (unless another bowl stands near the way),
  comes down slower for far grasps, keeps pressing a far bottle down until it touches, pulls in again
  after releasing far out, aims far object destinations 1.5 cm towards the shoulder (On allows 3 cm),
  puts an object back where it was taken from with a short 4.5 cm lift instead, and sets things on the
  cabinet top on its near half. After releasing beside the cabinet the hand rises over its top before
  turning (a turning hand sweeps the drawer handles).
* **Tracker timing.** The expert follows the tracker's debounce: it keeps a lifted object away until the
  pending atom has been false ≥ 17 steps since the last append, holds the placed state until the tracker
  appends it, and moves the same object on without releasing when the next subgoal is about it (the
  repetition family never lets go of the bowl/bottle). A placement the tracker did not register within
  25 steps is retried once (lift 2.5 cm, re-centre, set down). After the last subgoal it releases,
  retreats 6 cm and holds 5 steps; nothing is disturbed after completion.
* **Variation** (ChaCha8 from the episode seed): approach/placement offsets (±2–6 mm), grasp height, a
  per-episode speed factor (0.85–1.15), 0–3-step pauses, Gaussian noise σ = 0.03 on translation actions
  while moving, rim side on ties, drawer tilt (±0.05 rad), knob twist (±0.05 rad).

## Asset changes made for the expert

* `wooden_cabinet`: the drawer handles are 5 cm bars standing 2.5 cm proud of the drawer fronts on two
  posts (they stood 9 mm proud, too little for a fingertip; LIBERO's handles protrude similarly).
* `wine_rack`: the builtin rack is laid out as LIBERO's collision boxes (base, post, two 31° shelves,
  1.4 cm stoppers). An earlier builtin rack put a cradle in the plane of the region site (tilted 62.5°),
  which is not where LIBERO's shelf is and held a bottle only lying crosswise in a trough.
* `flat_stove`: the knob joint is a light part (0.1 kg, inertia 2·10⁻⁴ kg·m², damping 0.02, armature
  5·10⁻⁴) instead of LIBERO's placeholder inertial (3 kg, 1 kg·m², damping 1), which no fingertip could
  turn by 0.5 rad within the budget. The `turn_on` threshold (q ≥ 0.5) is unchanged.

## Known limitations

* `open_the_top_drawer_and_put_the_bowl_inside` runs close to its 300-step budget (open, take the bowl
  from under the open drawer, drop it in).
* Long multi-object tasks (T7, T8) use most of their step budget (transport speed is bounded by OSC_POSE's
  ~1.5 cm per step); the remaining failures there are arm poses near full stretch the OSC cannot leave.
"#;
