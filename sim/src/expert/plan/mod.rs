//! Per-task plans: the goal's subgoal sequence (one `Or` branch) turned into [`Op`]s.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::expert::branch::BranchRule;
use crate::expert::op::{Op, Point, Target};
use crate::task::{Atom, Category, Goal, Predicate, TaskSpec};
use crate::world::env::Env;
use crate::world::scene::{Scene, TABLE_TOP};
use geometry::*;

mod basket;
mod drawer;
pub(super) mod geometry;
mod grasp;
mod knob;
mod pick_place;
mod push;
mod rack;

const OPEN: f32 = -1.0;
const CLOSE: f32 = 1.0;

/// The goal as branches of subgoals (each a conjunction of atoms): a plain goal is one branch with one
/// subgoal, a `Sequence` one branch, an `Or` one branch per alternative.
pub fn subgoal_branches(g: &Goal) -> Vec<Vec<Vec<Atom>>> {
    fn subgoal(g: &Goal) -> Vec<Atom> {
        g.atoms().into_iter().cloned().collect()
    }
    match g {
        Goal::Atom(a) => vec![vec![vec![a.clone()]]],
        Goal::And(v) => {
            if v.len() == 1 && matches!(v[0], Goal::Sequence(_) | Goal::Or(_) | Goal::And(_)) {
                subgoal_branches(&v[0])
            } else {
                vec![vec![subgoal(g)]]
            }
        }
        Goal::Sequence(v) => vec![v.iter().map(subgoal).collect()],
        Goal::Or(v) => v.iter().flat_map(subgoal_branches).collect(),
    }
}

/// Where a plan starts: the default is an episode's first step (nothing satisfied, nothing held).
#[derive(Debug, Clone, Default)]
pub(super) struct From {
    /// Subgoals the goal tracker has appended.
    pub done: usize,
    /// Their atoms, in order (an `Or` goal's branch must contain them).
    pub satisfied: Vec<Atom>,
    /// The instance the fingers hold.
    pub held: Option<usize>,
}

/// Builds a plan on the state at the first step.
pub(super) struct Builder<'a> {
    scene: &'a Scene,
    env: &'a Env,
    rng: &'a mut ChaCha8Rng,
    vary: bool,
    ops: Vec<Op>,
    held: Option<usize>,
    yaw: f64,
    held_grasp_xy: Option<[f64; 2]>,
    expected: Vec<(usize, [f64; 3])>,
    /// Take bowls by the near (−x) rim with the hand along x.
    near_rim: bool,
    /// Where the object about to be grasped is going (for the choice of its rim side).
    next_dest: Option<[f64; 3]>,
    /// The destination is inside an open drawer (carry above its front, drop low).
    into_drawer: bool,
    /// Where the last object was set down (the hand is above it when the next grasp starts).
    last_dest: Option<[f64; 3]>,
    /// How an `Or` branch is chosen, with the hand's position at the start.
    branch_rule: (BranchRule, [f64; 3]),
}

impl<'a> Builder<'a> {
    pub(super) fn new(
        scene: &'a Scene,
        env: &'a Env,
        rng: &'a mut ChaCha8Rng,
        vary: bool,
    ) -> Builder<'a> {
        Builder {
            scene,
            env,
            rng,
            vary,
            ops: Vec::new(),
            held: None,
            yaw: 0.0,
            held_grasp_xy: None,
            expected: Vec::new(),
            near_rim: false,
            into_drawer: false,
            next_dest: None,
            last_dest: None,
            branch_rule: (BranchRule::Destination, [0.0; 3]),
        }
    }

    /// Chooses `Or` branches by `rule`, the hand being at `eef` (world frame) at the start.
    pub(super) fn branch_rule(&mut self, rule: BranchRule, eef: [f64; 3]) {
        self.branch_rule = (rule, eef);
    }

    fn inst(&self, name: &str) -> Option<usize> {
        self.scene.instance(name)
    }

    fn cat(&self, i: usize) -> Option<Category> {
        self.scene.instances[i].def.builtin
    }

    fn pos(&self, i: usize) -> [f64; 3] {
        self.env.data().body_pos(self.scene.instances[i].root_body)
    }

    fn jit(&mut self, r: f64) -> f64 {
        if self.vary {
            self.rng.random_range(-r..r)
        } else {
            0.0
        }
    }

    fn pause(&mut self, grip: f32) {
        if self.vary {
            let n = self.rng.random_range(0..4usize);
            if n > 0 {
                self.ops.push(Op::Hold { steps: n, grip });
            }
        }
    }

    fn grip_now(&self) -> f32 {
        if self.held.is_some() { CLOSE } else { OPEN }
    }

    fn mv(&mut self, target: Target, tol: f64, max: usize, gain: f64) {
        let grip = self.grip_now();
        self.ops.push(Op::Move {
            target,
            grip,
            tol,
            max,
            gain,
            until_pending: false,
        });
    }

    fn place_mv(&mut self, target: Target, max: usize) {
        self.ops.push(Op::Move {
            target,
            grip: CLOSE,
            tol: 0.003,
            max,
            gain: 8.0,
            until_pending: true,
        });
    }

    /// Chooses the branch and builds its ops. Returns (ops, branch index).
    pub(super) fn build(&mut self, task: &TaskSpec) -> (Vec<Op>, usize) {
        self.build_from(task, &From::default())
    }

    /// Builds the ops that finish the goal from `from` (the progress a goal tracker has seen, what
    /// the hand holds): the subgoals already satisfied are skipped, an `Or` goal keeps to a branch
    /// consistent with them, a held object is carried on rather than grasped again. Returns (ops,
    /// branch index).
    pub(super) fn build_from(&mut self, task: &TaskSpec, from: &From) -> (Vec<Op>, usize) {
        let branches = subgoal_branches(&task.problem.goal);
        let consistent: Vec<usize> = (0..branches.len())
            .filter(|&b| {
                from.satisfied
                    .iter()
                    .all(|a| branches[b].iter().flatten().any(|x| x == a))
            })
            .collect();
        let branch = if from.done == 0 || consistent.len() == branches.len() {
            self.choose_branch(&branches)
        } else {
            consistent.first().copied().unwrap_or(0)
        };
        let subgoals = branches[branch].clone();
        self.held = from.held;
        let env = self.env;
        let atoms: Vec<(usize, Atom)> = subgoals
            .iter()
            .enumerate()
            .skip(from.done)
            .flat_map(|(i, s)| {
                // Within a conjunction, a state already reached (a drawer open, a stove on) needs
                // no motion; positions (On, In) count only once the tracker has seen them.
                let several = s.len() > 1;
                s.iter()
                    .filter(move |a| {
                        !(several
                            && matches!(a.predicate, Predicate::Open | Predicate::TurnOn)
                            && env
                                .predicates()
                                .and_then(|p| p.eval(a.predicate, &a.args).ok())
                                .unwrap_or(false))
                    })
                    .map(move |a| (i, a.clone()))
            })
            .collect();
        for (k, (i, atom)) in atoms.iter().enumerate() {
            let next_obj = atoms
                .get(k + 1)
                .and_then(|(_, a)| a.args.first())
                .and_then(|n| self.inst(n));
            self.ops.push(Op::Pending(Some(atom.clone())));
            self.subgoal(atom, *i + 1, next_obj);
        }
        self.ops.push(Op::Pending(None));
        if self.held.is_some() {
            self.release();
        }
        let t = TABLE_TOP + 0.0;
        let _ = t;
        let up = 0.06 + self.jit(0.02);
        self.mv(Target::Rel([0.0, 0.0, up]), 0.01, 30, 12.0);
        (std::mem::take(&mut self.ops), branch)
    }

    /// The `Or` branch to follow. When every branch starts by putting an object in or on something
    /// (T7's two bowl orders, T8's, T9/T10's two baskets), by [`BranchRule`]: the branch whose
    /// first object is nearest, in the table plane, to where it goes, or (`Gripper`) nearest to
    /// the hand, ties broken by the destination (and then file order). Both are rules the scene
    /// shows, so a policy that sees the objects can tell which branch its demonstrations follow; a
    /// draw from the seed cannot be told apart (T7's two bowls look alike and carry no instance
    /// id). Other goals: a branch drawn from the seed.
    fn choose_branch(&mut self, branches: &[Vec<Vec<Atom>>]) -> usize {
        if branches.len() <= 1 {
            return 0;
        }
        let (rule, eef) = self.branch_rule;
        // (distance² to the hand (Gripper rule) or 0, distance² to the destination).
        let first_move = |b: &Vec<Vec<Atom>>| -> Option<(f64, f64)> {
            let a = b.first()?.first()?;
            if !matches!(a.predicate, Predicate::In | Predicate::On) || a.args.len() < 2 {
                return None;
            }
            let p = self.pos(self.inst(&a.args[0])?);
            let dest = match self.inst(&a.args[1]) {
                Some(d) => self.pos(d),
                None => self
                    .env
                    .data()
                    .site_pos(self.scene.regions.get(&a.args[1])?.site?),
            };
            let plane = |q: [f64; 3]| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
            let hand = match rule {
                BranchRule::Destination => 0.0,
                BranchRule::Gripper => plane(eef),
            };
            Some((hand, plane(dest)))
        };
        let distances: Option<Vec<(f64, f64)>> = branches.iter().map(first_move).collect();
        if let Some(d) = distances {
            let mut best = 0;
            for (k, dk) in d.iter().enumerate() {
                if dk.0 < d[best].0 || (dk.0 == d[best].0 && dk.1 < d[best].1) {
                    best = k;
                }
            }
            return best;
        }
        self.rng.random_range(0..branches.len())
    }

    fn subgoal(&mut self, atom: &Atom, n: usize, next_obj: Option<usize>) {
        match atom.predicate {
            Predicate::On => {
                let Some(obj) = self.inst(&atom.args[0]) else {
                    return;
                };
                let cat = self.cat(obj);
                let dest = &atom.args[1];
                if let Some(d) = self.inst(dest) {
                    // Object on object.
                    let dz = place_height(cat, self.cat(d));
                    let drop = self.cat(d) == Some(Category::AkitaBlackBowl);
                    self.pick_place(
                        obj,
                        Point::Body {
                            inst: d,
                            off: [0.0, 0.0, dz],
                            local: false,
                        },
                        n,
                        next_obj,
                        drop,
                    );
                } else if let Some(r) = self.scene.regions.get(dest) {
                    let Some(site) = r.site else { return };
                    let on_rack = r
                        .parent
                        .is_some_and(|p| self.cat(p) == Some(Category::WineRack));
                    match cat {
                        Some(Category::WineBottle) if on_rack => {
                            self.lay_in_rack(obj, r.parent.unwrap_or_default(), n)
                        }
                        Some(Category::Plate) => self.push_to(obj, site, n),
                        Some(Category::Basket) => self.drag_basket(obj, site, n),
                        Some(
                            Category::AkitaBlackBowl
                            | Category::CreamCheese
                            | Category::WineBottle
                            | Category::WineRack
                            | Category::FlatStove
                            | Category::WoodenCabinet
                            | Category::WhiteCabinet,
                        )
                        | None => {
                            let dz = site_place_height(self.scene.instances[obj].def, dest);
                            self.pick_place(
                                obj,
                                Point::Site {
                                    site,
                                    off: [0.0, 0.0, dz],
                                },
                                n,
                                next_obj,
                                false,
                            );
                        }
                    }
                }
            }
            Predicate::In => {
                let Some(obj) = self.inst(&atom.args[0]) else {
                    return;
                };
                let Some(r) = self.scene.regions.get(&atom.args[1]) else {
                    return;
                };
                let Some(site) = r.site else { return };
                if !r.joints.is_empty() {
                    // A drawer: open it first; the open drawer overhangs the table in front of the
                    // cabinet, so the object is taken from the robot's side and dropped a little
                    // outwards of the region's centre (clear of the carcass).
                    let out = self.open_drawer(&atom.args[1]);
                    self.near_rim = true;
                    self.into_drawer = true;
                    self.pick_place(
                        obj,
                        Point::Site {
                            site,
                            off: [out[0] * 0.015, out[1] * 0.015, 0.0],
                        },
                        n,
                        next_obj,
                        true,
                    );
                    self.near_rim = false;
                    self.into_drawer = false;
                } else {
                    self.pick_place(
                        obj,
                        Point::Site {
                            site,
                            off: [0.0, 0.0, 0.0],
                        },
                        n,
                        next_obj,
                        true,
                    );
                }
            }
            Predicate::Open => {
                let _ = self.open_drawer(&atom.args[0]);
                self.ops.push(Op::WaitSatisfied {
                    n,
                    max: 30,
                    grip: self.grip_now(),
                });
            }
            Predicate::TurnOn => {
                if let Some(stove) = self.inst(&atom.args[0]) {
                    self.turn_knob(stove, n);
                }
            }
            // No skill yet: the plan skips these subgoals (closing, turning off and lifting are not
            // in the shipped tasks; true/false/printjointstate need no motion).
            Predicate::Close
            | Predicate::TurnOff
            | Predicate::Up
            | Predicate::True
            | Predicate::False
            | Predicate::PrintJointState => {}
        }
    }

    /// Where `obj` will be when the plan reaches it (after the moves planned so far).
    fn expected_pos(&self, obj: usize) -> [f64; 3] {
        self.expected
            .iter()
            .rev()
            .find(|(o, _)| *o == obj)
            .map(|(_, p)| *p)
            .unwrap_or_else(|| self.pos(obj))
    }
}
