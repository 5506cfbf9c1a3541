//! Per-task plans: the goal's subgoal sequence (one `Or` branch) turned into [`Op`]s.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{Op, Point, Target, add, qrot};
use crate::env::Env;
use crate::mujoco::ObjType;
use crate::scene::{Scene, TABLE_TOP};
use crate::task::{Atom, Goal, TaskSpec};

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

enum GraspAt {
    Fixed {
        off: [f64; 3],
        local: bool,
        above: f64,
    },
    Rim {
        off: [f64; 3],
        coin: bool,
        above: f64,
        dest: Option<[f64; 3]>,
    },
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
        }
    }

    fn inst(&self, name: &str) -> Option<usize> {
        self.scene.instance(name)
    }

    fn cat(&self, i: usize) -> &'static str {
        self.scene.instances[i].def.category
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
        let branches = subgoal_branches(&task.problem.goal);
        let branch = self.choose_branch(&branches);
        let subgoals = branches[branch].clone();
        let atoms: Vec<(usize, Atom)> = subgoals
            .iter()
            .enumerate()
            .flat_map(|(i, s)| s.iter().map(move |a| (i, a.clone())))
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

    fn choose_branch(&mut self, branches: &[Vec<Vec<Atom>>]) -> usize {
        if branches.len() <= 1 {
            return 0;
        }
        // Baskets (T9/T10): the branch that puts the cheese into the basket nearest to it.
        let first_in = |b: &Vec<Vec<Atom>>| -> Option<(String, String)> {
            let a = b.first()?.first()?;
            (a.predicate == "in").then(|| (a.args[0].clone(), a.args[1].clone()))
        };
        if branches.iter().all(|b| first_in(b).is_some()) {
            let mut best = (f64::MAX, 0);
            for (k, b) in branches.iter().enumerate() {
                let (obj, region) = first_in(b).unwrap();
                let (Some(o), Some(r)) = (self.inst(&obj), self.scene.regions.get(&region)) else {
                    continue;
                };
                let Some(site) = r.site else { continue };
                let p = self.pos(o);
                let s = self.env.data().site_pos(site);
                let d = (p[0] - s[0]).powi(2) + (p[1] - s[1]).powi(2);
                if d < best.0 {
                    best = (d, k);
                }
            }
            return best.1;
        }
        self.rng.random_range(0..branches.len())
    }

    fn subgoal(&mut self, atom: &Atom, n: usize, next_obj: Option<usize>) {
        match atom.predicate.as_str() {
            "on" => {
                let Some(obj) = self.inst(&atom.args[0]) else {
                    return;
                };
                let cat = self.cat(obj);
                let dest = &atom.args[1];
                if let Some(d) = self.inst(dest) {
                    // Object on object.
                    let dz = place_height(cat, self.cat(d));
                    let drop = self.cat(d) == "akita_black_bowl";
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
                        .is_some_and(|p| self.scene.instances[p].def.category == "wine_rack");
                    match cat {
                        "wine_bottle" if on_rack => {
                            self.lay_in_rack(obj, r.parent.unwrap_or_default(), n)
                        }
                        "plate" => self.push_to(obj, site, n),
                        "basket" => self.drag_basket(obj, site, n),
                        _ => {
                            let dz = site_place_height(cat, dest);
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
            "in" => {
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
            "open" => {
                let _ = self.open_drawer(&atom.args[0]);
                self.ops.push(Op::WaitSatisfied {
                    n,
                    max: 30,
                    grip: self.grip_now(),
                });
            }
            "turnon" => {
                if let Some(stove) = self.inst(&atom.args[0]) {
                    self.turn_knob(stove, n);
                }
            }
            _ => {}
        }
    }

    /// Grasp offset (in the object's frame when `.1`) and approach height for a category.
    /// Where `obj` will be when the plan reaches it (after the moves planned so far).
    fn expected_pos(&self, obj: usize) -> [f64; 3] {
        self.expected
            .iter()
            .rev()
            .find(|(o, _)| *o == obj)
            .map(|(_, p)| *p)
            .unwrap_or_else(|| self.pos(obj))
    }

    fn grasp_offset(&mut self, obj: usize) -> GraspAt {
        let cat = self.cat(obj);
        let (off, local, above) = match cat {
            "akita_black_bowl"
                if self.near_rim || horizontal_reach(self.expected_pos(obj)) > 0.72 =>
            {
                // Far out (or under an open drawer): yaw the hand by 90° and pinch the near (−x) rim.
                (
                    [-0.0485, self.jit(0.003), 0.041 + self.jit(0.003)],
                    false,
                    0.07,
                )
            }
            "akita_black_bowl" => {
                // Pinch the rim wall at ±y (fingers open along world y). Where both sides are free here,
                // take the one that is free at the destination (the hand keeps that side there).
                let mut coin = self.vary && self.rng.random_bool(0.5);
                if let Some(d) = self.next_dest {
                    coin = clear_side(self.scene, self.env, obj, d, 0.0485, coin) > 0.0;
                }
                let off = [self.jit(0.004), 0.0485, 0.041 + self.jit(0.003)];
                return GraspAt::Rim {
                    off,
                    coin,
                    above: 0.07,
                    dest: self.next_dest,
                };
            }
            "wine_bottle" => (
                [
                    self.jit(0.002),
                    self.jit(0.002),
                    BOTTLE_NECK + self.jit(0.006),
                ],
                false,
                0.08,
            ),
            "cream_cheese" => ([self.jit(0.006), self.jit(0.002), 0.003], false, 0.08),
            "basket" => {
                // The walls at local ±x face world ±y (placement yaw π/2); pinch the one nearer y = 0.
                let p = self.pos(obj);
                let q = self
                    .env
                    .data()
                    .body_quat(self.scene.instances[obj].root_body);
                let wx = qrot(q, [1.0, 0.0, 0.0]);
                let side = if (p[1] + wx[1] * 0.082).abs() < (p[1] - wx[1] * 0.082).abs() {
                    1.0
                } else {
                    -1.0
                };
                ([side * 0.082, self.jit(0.01), 0.122], true, 0.08)
            }
            _ => ([0.0, 0.0, 0.02], false, 0.08),
        };
        GraspAt::Fixed { off, local, above }
    }

    fn grasp(&mut self, obj: usize) {
        let (pre, at) = match self.grasp_offset(obj) {
            GraspAt::Fixed { off, local, above } => (
                Point::Body {
                    inst: obj,
                    off: [off[0], off[1], off[2] + above],
                    local,
                },
                Point::Body {
                    inst: obj,
                    off,
                    local,
                },
            ),
            GraspAt::Rim {
                off,
                coin,
                above,
                dest,
            } => (
                Point::Rim {
                    inst: obj,
                    off: [off[0], off[1], off[2] + above],
                    coin,
                    dest,
                },
                Point::Rim {
                    inst: obj,
                    off,
                    coin,
                    dest,
                },
            ),
        };
        let far = self.cat(obj) == "akita_black_bowl"
            && (self.near_rim || horizontal_reach(self.expected_pos(obj)) > 0.72);
        let want_yaw = if far
            || (self.cat(obj) == "wine_bottle" && self.hand_blocked_along_y(self.expected_pos(obj)))
        {
            std::f64::consts::FRAC_PI_2
        } else {
            0.0
        };
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 0,
        });
        if (want_yaw - self.yaw).abs() > 1e-6 {
            self.yaw = want_yaw;
            // Just released beside the cabinet, the turning hand (20 cm long) would sweep its
            // drawer handles: turn above the cabinet's top instead.
            let by_cabinet = self.last_dest.is_some_and(|d| {
                self.scene.instances.iter().any(|i| {
                    let q = self.env.data().body_pos(i.root_body);
                    i.def.category == "wooden_cabinet"
                        && ((q[0] - d[0]).powi(2) + (q[1] - d[1]).powi(2)).sqrt() < 0.32
                })
            });
            if by_cabinet {
                self.mv(Target::RelZ(1.16), 0.015, 25, 12.0);
            }
            self.ops.push(Op::Yaw {
                yaw: want_yaw,
                grip: OPEN,
                max: 25,
            });
        }
        if self.near_rim && self.cat(obj) == "akita_black_bowl" {
            // Under an open drawer: the hand (along x) reaches 10 cm past the rim, so it comes down
            // 7.5 cm further out, below the drawer's bottom, and slides in.
            let body = |x: f64, z: f64| Point::Body {
                inst: obj,
                off: [x, 0.0, z],
                local: false,
            };
            self.mv(Target::Grip(body(-0.125, 0.28)), 0.03, 40, 12.0);
            self.mv(Target::Grip(body(-0.125, 0.066)), 0.01, 40, 14.0);
            self.mv(Target::Grip(body(-0.0485, 0.062)), 0.008, 30, 14.0);
            self.mv(Target::Grip(at), 0.005, 30, 16.0);
        } else {
            self.mv(Target::Grip(pre), 0.02, 90, 12.0);
            self.pause(OPEN);
            // Far out and low the stretched arm drifts outwards under large commands: come down slower.
            if horizontal_reach(self.expected_pos(obj)) > 0.66 {
                self.mv(Target::Grip(at), 0.005, 60, 8.0);
            } else {
                self.mv(Target::Grip(at), 0.005, 40, 13.0);
            }
        }
        let extra = if self.vary {
            self.rng.random_range(0..3)
        } else {
            0
        };
        self.ops.push(Op::Grip {
            cmd: CLOSE,
            steps: 9 + extra,
        });
        self.held = Some(obj);
        let p = self.pos(obj);
        self.held_grasp_xy = Some([p[0], p[1]]);
    }

    /// Whether the hand (20 cm long along its finger axis) would meet a tall fixture when held with that
    /// axis along y over `p` while the same hand along x would not.
    fn hand_blocked_along_y(&self, p: [f64; 3]) -> bool {
        let clearance = |dx: f64, dy: f64| -> f64 {
            let mut best = f64::MAX;
            for inst in &self.scene.instances {
                let rad = match inst.def.category {
                    "wine_rack" => 0.19,
                    "wooden_cabinet" => 0.17,
                    _ => continue,
                };
                let q = self.env.data().body_pos(inst.root_body);
                for t in [-1.0, -0.5, 0.0, 0.5, 1.0] {
                    let g = [p[0] + t * dx, p[1] + t * dy];
                    let d = ((q[0] - g[0]).powi(2) + (q[1] - g[1]).powi(2)).sqrt() - rad;
                    best = best.min(d);
                }
            }
            best
        };
        let along_y = clearance(0.0, 0.1);
        along_y < 0.0 && clearance(0.1, 0.0) > along_y
    }

    /// Whether the straight way of `obj` from `from` to `to` passes within 12 cm of another object
    /// that stands up from the table (plates do not), other than at its two ends.
    fn crosses_object(&self, obj: usize, from: [f64; 3], to: [f64; 3]) -> bool {
        let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
        let len2 = dx * dx + dy * dy;
        if len2 < 1e-6 {
            return false;
        }
        self.scene.instances.iter().enumerate().any(|(k, inst)| {
            if k == obj
                || inst.def.kind != crate::assets::AssetKind::Movable
                || inst.def.category == "plate"
            {
                return false;
            }
            let q = self.expected_pos(k);
            let t = (((q[0] - from[0]) * dx + (q[1] - from[1]) * dy) / len2).clamp(0.0, 1.0);
            let (px, py) = (from[0] + t * dx - q[0], from[1] + t * dy - q[1]);
            let d = (px * px + py * py).sqrt();
            let near_end =
                |e: [f64; 3]| ((q[0] - e[0]).powi(2) + (q[1] - e[1]).powi(2)).sqrt() < 0.03;
            d < 0.12 && !near_end(from) && !near_end(to)
        })
    }

    fn release(&mut self) {
        let extra = if self.vary {
            self.rng.random_range(0..3)
        } else {
            0
        };
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 7 + extra,
        });
        self.held = None;
        let up = 0.07 + self.jit(0.015);
        self.mv(Target::Rel([0.0, 0.0, up]), 0.015, 30, 12.0);
        // Far out the arm is nearly straight (a singularity OSC cannot leave): come back in towards
        // the shoulder before the next move (no motion when already within reach).
        self.mv(Target::PullIn { h: 0.66, dz: 0.0 }, 0.015, 25, 12.0);
    }

    /// Height of the held object's origin while carrying.
    fn carry_z(&self, obj: usize, over_basket: bool) -> f64 {
        let base = match self.cat(obj) {
            "wine_bottle" => TABLE_TOP + 0.10,
            "cream_cheese" => TABLE_TOP + 0.09,
            _ => TABLE_TOP + 0.115,
        };
        if over_basket { TABLE_TOP + 0.17 } else { base }
    }

    /// Pick `obj` (unless held), carry it over `to` and put it down; wait for subgoal `n`; release unless
    /// the next subgoal moves the same object. `drop`: release from above (into a container).
    fn pick_place(&mut self, obj: usize, to: Point, n: usize, next_obj: Option<usize>, drop: bool) {
        if self.held != Some(obj) {
            if self.held.is_some() {
                self.release();
            }
            self.next_dest = Some(match &to {
                Point::Body { inst, .. } | Point::Rim { inst, .. } => self.pos(*inst),
                Point::Site { site, .. } => self.env.data().site_pos(*site),
                Point::Abs(p) => *p,
            });
            self.grasp(obj);
            self.next_dest = None;
        }
        self.last_dest = Some(match &to {
            Point::Body { inst, .. } | Point::Rim { inst, .. } => self.pos(*inst),
            Point::Site { site, .. } => self.env.data().site_pos(*site),
            Point::Abs(p) => *p,
        });
        let into_basket =
            drop && matches!(&to, Point::Site { .. }) && self.cat(obj) == "cream_cheese";
        let to = self.within_reach(to);
        let before = self.expected_pos(obj);
        if let Point::Body { inst, .. } = &to {
            let p = self.pos(*inst);
            self.expected.push((obj, p));
        }
        let mut cz = self.carry_z(obj, into_basket);
        let dest_p = match &to {
            Point::Body { inst, .. } => self.pos(*inst),
            Point::Site { site, .. } => self.env.data().site_pos(*site),
            Point::Abs(p) => *p,
            Point::Rim { inst, .. } => self.pos(*inst),
        };
        let far = horizontal_reach(dest_p) > 0.68 || horizontal_reach(self.pos(obj)) > 0.68;
        // Another bowl (or taller object) under the way there: a held bowl hangs tilted by the rim and
        // would sweep it along at the lowered far-out carry height.
        if far && !into_basket && !self.crosses_object(obj, before, dest_p) {
            cz -= 0.035;
        }
        if self.into_drawer
            && let Point::Site { site, .. } = &to
        {
            // Over the drawer's front panel (its top is ~3 cm above the region's centre).
            cz = cz.max(self.env.data().site_pos(*site)[2] + 0.06);
        }
        // Raised destinations (cabinet top, stove): clear them by a few centimetres.
        if let Point::Site { site, .. } = &to {
            let sz = self.env.data().site_pos(*site)[2];
            if !into_basket && !drop {
                cz = cz.max(sz + 0.05);
            }
        }
        if self.near_rim && self.cat(obj) == "akita_black_bowl" {
            // Out from under the open drawer before lifting.
            self.mv(Target::Rel([-0.06, 0.0, 0.004]), 0.01, 20, 12.0);
        }
        // Lift straight up first.
        let o = self.pos(obj);
        let lift = cz - o[2];
        let lz = lift.max(0.05) + self.jit(0.01);
        // Put back where it was taken from, far out: lift just clear and stay out there (pulling in and
        // lifting high would leave the object out of reach for the way back).
        let back_in_place = matches!(&to, Point::Body { .. })
            && ((before[0] - dest_p[0]).powi(2) + (before[1] - dest_p[1]).powi(2)).sqrt() < 0.02
            && horizontal_reach(dest_p) > 0.68;
        if back_in_place {
            cz = before[2] + 0.045 + self.jit(0.005);
            self.mv(Target::Rel([0.0, 0.0, cz - before[2]]), 0.01, 30, 12.0);
        } else {
            // Far out, first pull in towards the shoulder at low height (a straight arm is a singularity
            // OSC cannot leave; high poses reach less far), then lift.
            self.mv(Target::PullIn { h: 0.63, dz: 0.03 }, 0.015, 30, 12.0);
            self.mv(
                Target::Rel([0.0, 0.0, (lz - 0.03).max(0.02)]),
                0.02,
                40,
                12.0,
            );
        }
        if self.into_drawer {
            // All the way up before moving over the drawer's front panel.
            self.mv(Target::RelZ(cz + 0.045), 0.008, 30, 12.0);
        }
        // Over the destination at carry height.
        let (mut jx, mut jy) = (self.jit(0.004), self.jit(0.004));
        // Far out, set objects down on the near side of an object destination (On allows 3 cm): the
        // arm stays less stretched and can come back.
        let reach = horizontal_reach(dest_p);
        if matches!(&to, Point::Body { .. }) && reach > 0.7 {
            let k = (reach - 0.7).min(0.015) / reach;
            jx += (SHOULDER[0] - dest_p[0]) * k;
            jy += (SHOULDER[1] - dest_p[1]) * k;
        }
        let hover = match &to {
            Point::Body { inst, off, local } => Point::Body {
                inst: *inst,
                off: [off[0] + jx, off[1] + jy, cz - self.pos(*inst)[2]],
                local: *local,
            },
            Point::Site { site, off } => {
                let s = self.env.data().site_pos(*site);
                Point::Site {
                    site: *site,
                    off: [off[0] + jx, off[1] + jy, cz - s[2]],
                }
            }
            Point::Abs(p) => Point::Abs([p[0] + jx, p[1] + jy, cz]),
            Point::Rim { .. } => to.clone(),
        };
        self.mv(
            Target::Carry {
                held: obj,
                to: hover,
            },
            0.012,
            90,
            12.0,
        );
        self.ops.push(Op::WaitNonlive {
            n: 17,
            max: 40,
            grip: CLOSE,
        });
        let (down, drop_z) = if drop {
            let s = match &to {
                Point::Site { site, .. } => self.env.data().site_pos(*site),
                _ => [0.0; 3],
            };
            // Into a basket: release from just above the rim; into a drawer: low.
            let z = if into_basket {
                TABLE_TOP + 0.165 - s[2]
            } else {
                0.045
            };
            (true, z)
        } else {
            (false, 0.0)
        };
        let place = match &to {
            Point::Body { inst, off, local } => Point::Body {
                inst: *inst,
                off: [
                    off[0] + jx,
                    off[1] + jy,
                    off[2] - if drop { 0.0 } else { 0.006 },
                ],
                local: *local,
            },
            Point::Site { site, off } => Point::Site {
                site: *site,
                off: [
                    off[0] + jx,
                    off[1] + jy,
                    if down { drop_z } else { off[2] - 0.006 },
                ],
            },
            Point::Abs(p) => Point::Abs([p[0] + jx, p[1] + jy, p[2]]),
            Point::Rim { .. } => to.clone(),
        };
        if drop {
            let g = if self.into_drawer { 14.0 } else { 10.0 };
            self.mv(
                Target::Carry {
                    held: obj,
                    to: place,
                },
                0.006,
                45,
                g,
            );
            self.release();
            self.ops.push(Op::WaitSatisfied {
                n,
                max: 40,
                grip: OPEN,
            });
            return;
        }
        self.place_mv(
            Target::Carry {
                held: obj,
                to: place.clone(),
            },
            45,
        );
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 25,
            grip: CLOSE,
        });
        // Not appended (set down off-centre, or not touching): lift a little, re-centre and set it down
        // again. Skipped when the tracker has appended.
        self.ops.push(Op::SkipIfSatisfied { n, count: 4 });
        self.mv(Target::Rel([0.0, 0.0, 0.025]), 0.006, 15, 12.0);
        let above = match &place {
            Point::Body { inst, off, local } => Point::Body {
                inst: *inst,
                off: [off[0], off[1], off[2] + 0.02],
                local: *local,
            },
            Point::Site { site, off } => Point::Site {
                site: *site,
                off: [off[0], off[1], off[2] + 0.02],
            },
            other => other.clone(),
        };
        self.mv(
            Target::Carry {
                held: obj,
                to: above,
            },
            0.004,
            30,
            10.0,
        );
        self.place_mv(
            Target::Carry {
                held: obj,
                to: place,
            },
            30,
        );
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 30,
            grip: CLOSE,
        });
        self.pause(CLOSE);
        if next_obj != Some(obj) {
            self.release();
        }
    }

    /// A large raised surface (the cabinet top) near the edge of the reach: move the target towards the
    /// shoulder, keeping 4.5 cm inside the region.
    fn within_reach(&self, to: Point) -> Point {
        let Point::Site { site, off } = to else {
            return to;
        };
        let s = self.env.data().site_pos(site);
        let half = self.scene.model.site_size(site);
        let far = horizontal_reach(s) - 0.6;
        if far <= 0.0 || half[0].min(half[1]) < 0.08 {
            return Point::Site { site, off };
        }
        let (ux, uy) = (SHOULDER[0] - s[0], SHOULDER[1] - s[1]);
        let n = (ux * ux + uy * uy).sqrt();
        let mut d = [ux / n * far, uy / n * far];
        // Sites of fixtures placed at yaw 0 or π: half sizes stay along x and y.
        for k in 0..2 {
            let lim = half[k] - 0.045;
            d[k] = d[k].clamp(-lim, lim);
        }
        Point::Site {
            site,
            off: [off[0] + d[0], off[1] + d[1], off[2]],
        }
    }

    /// Grasp a basket's wall and slide it (lifted a little) so its origin reaches `site`'s xy.
    fn drag_basket(&mut self, basket: usize, site: usize, n: usize) {
        if self.held != Some(basket) {
            if self.held.is_some() {
                self.release();
            }
            self.grasp(basket);
        }
        let p0 = self.pos(basket);
        let s = self.env.data().site_pos(site);
        let (jx, jy) = (self.jit(0.02), self.jit(0.02));
        self.mv(Target::Rel([0.0, 0.0, 0.015]), 0.006, 20, 12.0);
        let to = Point::Abs([s[0] + jx, s[1] + jy, p0[2] + 0.015]);
        self.mv(Target::Carry { held: basket, to }, 0.012, 100, 10.0);
        let down = Point::Abs([s[0] + jx, s[1] + jy, p0[2] - 0.002]);
        self.place_mv(
            Target::Carry {
                held: basket,
                to: down,
            },
            20,
        );
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 40,
            grip: CLOSE,
        });
        self.release();
    }

    /// Move a plate onto a table region: pinch its +y rim (the side away from the cabinet), lift it a few
    /// centimetres (over low objects), carry it and set it down where its footprint clears the objects
    /// already standing in the region.
    fn push_to(&mut self, obj: usize, site: usize, n: usize) {
        if self.held.is_some() {
            self.release();
        }
        let p = self.pos(obj);
        let s = self.env.data().site_pos(site);
        let gx = s[0] + self.jit(0.008);
        // Plate radius 0.069: keep its rim 1 cm clear of objects beside the region's near (−y) side.
        let mut gy = s[1] + 0.005;
        for (k, inst) in self.scene.instances.iter().enumerate() {
            if k == obj || inst.def.kind != crate::assets::AssetKind::Movable {
                continue;
            }
            let o = self.env.data().body_pos(inst.root_body);
            if (o[0] - gx).abs() < 0.069 + 0.045 && o[1] < gy {
                let r = if inst.def.category == "cream_cheese" {
                    0.0215
                } else {
                    0.055
                };
                gy = gy.max(o[1] + r + 0.069 + 0.01);
            }
        }
        let gy = gy.min(s[1] + 0.034) + self.jit(0.003);
        // The rim wall's mid-height (r 0.0625, z 0.009) between the pads.
        let zg = 0.006 + self.jit(0.001);
        let rim = [self.jit(0.004), 0.0625 + self.jit(0.002)];
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 0,
        });
        if self.yaw.abs() > 1e-6 {
            self.yaw = 0.0;
            self.ops.push(Op::Yaw {
                yaw: 0.0,
                grip: OPEN,
                max: 25,
            });
        }
        self.mv(
            Target::Grip(Point::Body {
                inst: obj,
                off: [rim[0], rim[1], zg + 0.06],
                local: false,
            }),
            0.015,
            80,
            12.0,
        );
        self.mv(
            Target::Grip(Point::Body {
                inst: obj,
                off: [rim[0], rim[1], zg],
                local: false,
            }),
            0.004,
            40,
            10.0,
        );
        self.ops.push(Op::Grip {
            cmd: CLOSE,
            steps: 12,
        });
        self.held = Some(obj);
        // Held by one edge the plate tilts: lift it well clear of low objects before moving.
        let lift = p[2] + 0.08;
        self.mv(Target::Rel([0.0, 0.0, 0.08]), 0.01, 30, 12.0);
        self.mv(
            Target::Carry {
                held: obj,
                to: Point::Abs([gx, gy, lift]),
            },
            0.008,
            90,
            12.0,
        );
        self.mv(
            Target::Carry {
                held: obj,
                to: Point::Abs([gx, gy, p[2] + 0.001]),
            },
            0.004,
            40,
            8.0,
        );
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 30,
            grip: CLOSE,
        });
        self.release();
    }

    /// Open the drawer owning region `region`: the hand, yawed so the fingers close along the handle bar
    /// and tilted ~40° so it stays out in front of the drawers above, slides in around the bar's ends,
    /// pinches them and pulls the drawer out along its slide.
    fn open_drawer(&mut self, region: &str) -> [f64; 3] {
        let Some(r) = self.scene.regions.get(region) else {
            return [0.0; 3];
        };
        let Some(cab) = r.parent else {
            return [0.0; 3];
        };
        let Some(&(_, qadr, _)) = r.joints.first() else {
            return [0.0; 3];
        };
        let level = region.trim_start_matches(&format!("{}_", self.scene.instances[cab].name));
        let n0 = match level {
            "top_region" => 20,
            "middle_region" => 30,
            _ => 40,
        };
        let name = format!("{}_g{}", self.scene.instances[cab].name, n0 + 5);
        let Some(geom) = self.scene.model.id(ObjType::Geom, &name) else {
            return [0.0; 3];
        };
        let hp = self.env.data().geom_pos(geom);
        let q = self
            .env
            .data()
            .body_quat(self.scene.instances[cab].root_body);
        let out = qrot(q, [0.0, -1.0, 0.0]);
        let q0 = self.env.data().qpos()[qadr];
        let yaw = out[1].atan2(out[0]);
        let axis = [out[1], -out[0], 0.0];
        let phi = 0.7 + self.jit(0.05);
        // Where the fingers point once tilted: into the cabinet and down.
        let app = [-out[0] * phi.sin(), -out[1] * phi.sin(), -phi.cos()];
        let at = [
            hp[0] + self.jit(0.002),
            hp[1] + self.jit(0.002),
            hp[2] + self.jit(0.002),
        ];
        let back = |d: f64| [at[0] - app[0] * d, at[1] - app[1] * d, at[2] - app[2] * d];
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 0,
        });
        // Turn while moving to a point out in front of the handle; finish the turn there.
        self.yaw = yaw;
        for max in [0, 20] {
            self.ops.push(Op::Orient {
                yaw,
                axis,
                tilt: -phi,
                grip: OPEN,
                max,
                hold: true,
            });
            if max == 0 {
                self.mv(Target::Grip(Point::Abs(back(0.12))), 0.02, 80, 12.0);
            }
        }
        self.mv(Target::Grip(Point::Abs(at)), 0.004, 50, 14.0);
        self.ops.push(Op::Grip {
            cmd: CLOSE,
            steps: 10,
        });
        let pull = 0.165 + q0;
        let dst = add(at, [out[0] * pull, out[1] * pull, 0.0]);
        self.ops.push(Op::Move {
            target: Target::Grip(Point::Abs(dst)),
            grip: CLOSE,
            tol: 0.008,
            max: 60,
            gain: 10.0,
            until_pending: false,
        });
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 8,
        });
        self.held = None;
        self.mv(
            Target::Rel([-app[0] * 0.06, -app[1] * 0.06, -app[2] * 0.06 + 0.03]),
            0.015,
            30,
            12.0,
        );
        // Level the hand (same yaw) during the next move.
        self.ops.push(Op::Orient {
            yaw,
            axis,
            tilt: 0.0,
            grip: OPEN,
            max: 0,
            hold: true,
        });
        out
    }

    /// Lay a wine bottle in the rack: on the top shelf (inclined 31.3°, rising towards the rack's
    /// +y), along the incline with the neck up and the bottom against the stopper, beside the post,
    /// the way a wine rack holds bottles. The neck is pinched from above with the fingers closing along
    /// the shelf (the rack's x). A pinch is a free pivot about the finger axis, so the bottle hangs
    /// upright while carried; it is set down on its bottom rim a few centimetres up the shelf from the
    /// stopper, and the hand then carries the neck up and along the incline: the bottle tips over
    /// about the pinch and lies down, its bottom sliding down against the stopper.
    fn lay_in_rack(&mut self, obj: usize, rack: usize, n: usize) {
        if self.held.is_some() {
            self.release();
        }
        let rb = self.scene.instances[rack].root_body;
        let rp = self.env.data().body_pos(rb);
        let rq = self.env.data().body_quat(rb);
        // The top shelf in the rack's frame (y, z); the bottom face goes 2 mm up from the stopper.
        let shelf = crate::assets::wine_rack_top_shelf();
        let (p0, t, nrm) = (shelf.surface, shelf.incline, shelf.normal);
        let radius = 0.0215;
        let s_stop = shelf.stopper + 0.002;
        let gh = BOTTLE_NECK + self.jit(0.004);
        // Beside the post (x = 0), on the side nearer the bottle, clear of the opening fingers.
        let b = self.pos(obj);
        let ex = qrot(rq, [1.0, 0.0, 0.0]);
        let side = if (b[0] - rp[0]) * ex[0] + (b[1] - rp[1]) * ex[1] >= 0.0 {
            1.0
        } else {
            -1.0
        };
        let x = side * (0.06 + self.jit(0.005));
        // Fingers closing along the rack's x: yaw 0 closes them along world y.
        let yaw = wrap_half_turn(ex[1].atan2(ex[0]) - std::f64::consts::FRAC_PI_2);
        // The pinch when the bottle's axis is at `beta` from the shelf normal (tilted up the shelf)
        // and its bottom rim touches the shelf at `s`, lifted `lift` off it along the normal.
        let pinch = |beta: f64, s: f64, lift: f64| -> [f64; 3] {
            let (cb, sb) = (beta.cos(), beta.sin());
            let ax = [cb * nrm[0] + sb * t[0], cb * nrm[1] + sb * t[1]];
            let k = |j: usize| {
                p0[j] + s * t[j] - radius * cb * t[j] + (radius * sb + lift) * nrm[j] + gh * ax[j]
            };
            add(rp, qrot(rq, [x, k(0), k(1)]))
        };
        let upright = (t[1] / t[0]).atan().abs(); // the vertical, at 31.3° from the normal
        let s_touch = s_stop + 0.04 + self.jit(0.004);
        let touch = pinch(upright, s_touch, 0.0);
        let above = [touch[0], touch[1], touch[2] + 0.03];

        // Take the neck from above.
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 0,
        });
        if (yaw - self.yaw).abs() > 1e-6 {
            self.yaw = yaw;
            self.ops.push(Op::Yaw {
                yaw,
                grip: OPEN,
                max: 25,
            });
        }
        let neck = |dz: f64| Point::Body {
            inst: obj,
            off: [0.0, 0.0, gh + dz],
            local: false,
        };
        self.mv(Target::Grip(neck(0.08)), 0.02, 90, 12.0);
        self.pause(OPEN);
        self.mv(Target::Grip(neck(0.0)), 0.005, 40, 13.0);
        self.ops.push(Op::Grip {
            cmd: CLOSE,
            steps: 12,
        });
        self.held = Some(obj);
        // Up, over to above the touch-down point (the bottle hangs upright below the pinch), down.
        let high = (above[2] + 0.02).max(b[2] + gh + 0.1);
        self.mv(Target::RelZ(high), 0.015, 40, 12.0);
        self.mv(
            Target::Grip(Point::Abs([above[0], above[1], high])),
            0.012,
            90,
            9.0,
        );
        self.mv(Target::Grip(Point::Abs(above)), 0.01, 40, 10.0);
        self.mv(Target::Grip(Point::Abs(touch)), 0.006, 20, 10.0);
        // Tip it over up the shelf: the rim slides down to the stopper as the neck goes up the
        // incline and down, until the bottle lies along it (axis at 90° from the normal).
        let k_max = 4;
        for k in 1..=k_max {
            let f = k as f64 / k_max as f64;
            let beta = upright + f * (std::f64::consts::FRAC_PI_2 - upright);
            let s = s_touch + f * (s_stop - s_touch);
            let w = pinch(beta, s, 0.003);
            if k == k_max {
                self.mv(Target::Grip(Point::Abs(w)), 0.005, 30, 10.0);
            } else {
                self.mv(Target::Grip(Point::Abs(w)), 0.01, 15, 12.0);
            }
        }
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 10,
        });
        self.held = None;
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 25,
            grip: OPEN,
        });
        // Straight up: the open fingers leave the neck sideways.
        self.mv(Target::Rel([0.0, 0.0, 0.08]), 0.015, 30, 12.0);
    }

    /// Turn a stove knob on: pinch its pointer bar across its thickness with the hand yawed along the
    /// bar, then twist the wrist about the knob's axis.
    fn turn_knob(&mut self, stove: usize, n: usize) {
        let Some(knob) = self.scene.model.id(
            ObjType::Body,
            &format!("{}_knob", self.scene.instances[stove].name),
        ) else {
            return;
        };
        let c = self.env.data().body_pos(knob);
        let q = self.env.data().body_quat(knob);
        // The bar runs along the knob's local y; the fingers (opening along world y at yaw 0) must close
        // across it, i.e. along the knob's local x.
        let bx = qrot(q, [1.0, 0.0, 0.0]);
        let bar_yaw = bx[1].atan2(bx[0]) - std::f64::consts::FRAC_PI_2;
        let yaw0 = wrap_half_turn(bar_yaw);
        let z = c[2] + 0.026 + self.jit(0.002);
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 0,
        });
        let pre = [c[0], c[1], z + 0.07];
        self.mv(Target::Grip(Point::Abs(pre)), 0.015, 80, 12.0);
        self.yaw = yaw0;
        self.ops.push(Op::Yaw {
            yaw: yaw0,
            grip: OPEN,
            max: 30,
        });
        self.mv(Target::Grip(Point::Abs([c[0], c[1], z])), 0.004, 40, 10.0);
        self.ops.push(Op::Grip {
            cmd: CLOSE,
            steps: 10,
        });
        // Positive knob angle = counter-clockwise about the (upward) knob axis.
        let turn = 0.75 + self.jit(0.05);
        self.yaw = yaw0 + turn;
        self.ops.push(Op::Yaw {
            yaw: self.yaw,
            grip: CLOSE,
            max: 40,
        });
        self.ops.push(Op::WaitSatisfied {
            n,
            max: 20,
            grip: CLOSE,
        });
        self.ops.push(Op::Grip {
            cmd: OPEN,
            steps: 8,
        });
        self.mv(Target::Rel([0.0, 0.0, 0.07]), 0.015, 25, 12.0);
    }
}

/// An angle wrapped into (−π/2, π/2] (a parallel gripper is symmetric under a half turn).
fn wrap_half_turn(a: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let mut a = a.rem_euclid(pi);
    if a > pi / 2.0 {
        a -= pi;
    }
    a
}

/// The ±y side of `obj` whose neighbourhood is freer: the hand (20 cm long along y) reaches past the
/// grasp point on that side, so fixtures and other objects there are scored by clearance (seeded
/// tie-break).
pub(super) fn clear_side(
    scene: &Scene,
    env: &Env,
    obj: usize,
    p: [f64; 3],
    r: f64,
    coin: bool,
) -> f64 {
    pick_side(side_clearance(scene, env, obj, p, r, true), coin)
}

/// [`clear_side`] over both the bowl's place `p` and (when given) its destination `dest`: a side
/// scores its smaller clearance of the two (a hand that fits at the source can still meet a fixture
/// where the bowl is set down). A side where the hand meets something here while the other is free
/// is never taken.
pub(super) fn clear_side_both(
    scene: &Scene,
    env: &Env,
    obj: usize,
    p: [f64; 3],
    dest: Option<[f64; 3]>,
    r: f64,
    coin: bool,
) -> f64 {
    let free = side_clearance(scene, env, obj, p, r, false);
    if (free[0] < 0.0) != (free[1] < 0.0) {
        return if free[0] >= 0.0 { 1.0 } else { -1.0 };
    }
    let mut best = side_clearance(scene, env, obj, p, r, true);
    if let Some(d) = dest {
        let at = side_clearance(scene, env, obj, d, r, true);
        for s in 0..2 {
            best[s] = best[s].min(at[s]);
        }
    }
    pick_side(best, coin)
}

fn pick_side(best: [f64; 2], coin: bool) -> f64 {
    if (best[0] - best[1]).abs() < 0.02 || best[0].min(best[1]) > 0.08 {
        if coin { 1.0 } else { -1.0 }
    } else if best[0] > best[1] {
        1.0
    } else {
        -1.0
    }
}

/// Clearance of the hand on the +y and −y side of `p` (see [`clear_side`]).
fn side_clearance(
    scene: &Scene,
    env: &Env,
    obj: usize,
    p: [f64; 3],
    r: f64,
    reach: bool,
) -> [f64; 2] {
    let mut best = [f64::MAX; 2];
    for (s, side) in [1.0, -1.0].iter().enumerate() {
        for reach in [r, r + 0.06, r + 0.1] {
            let g = [p[0], p[1] + side * reach, p[2]];
            for (k, inst) in scene.instances.iter().enumerate() {
                if k == obj {
                    continue;
                }
                let tall = matches!(
                    inst.def.category,
                    "wine_bottle" | "basket" | "wooden_cabinet" | "wine_rack" | "flat_stove"
                );
                if reach > r && !tall {
                    // The hand box passes over low objects; only the fingers reach them.
                    continue;
                }
                let rad = match inst.def.category {
                    "plate" => continue,
                    "akita_black_bowl" => 0.055,
                    "wine_bottle" => 0.025,
                    "cream_cheese" => 0.04,
                    "basket" => 0.09,
                    // The carcass's front corners (plus handles) reach 0.17 m from its origin; the
                    // margin keeps a hand that then carries the bowl past a corner off it.
                    "wooden_cabinet" => 0.23,
                    "flat_stove" => 0.1,
                    "wine_rack" => 0.19,
                    _ => 0.05,
                };
                let mut q = env.data().body_pos(scene.instances[k].root_body);
                if inst.def.kind == crate::assets::AssetKind::Movable
                    && ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt() < 0.03
                {
                    // Standing at `p` itself (a destination still occupied when the plan is made):
                    // it will have been moved away by then.
                    continue;
                }
                if inst.def.category == "flat_stove" {
                    let b = scene.instances[k].root_body;
                    let o = qrot(env.data().body_quat(b), [0.1, 0.0, 0.0]);
                    q = add(q, o);
                }
                let d = ((q[0] - g[0]).powi(2) + (q[1] - g[1]).powi(2)).sqrt() - rad;
                best[s] = best[s].min(d);
            }
        }
    }
    // Reach: the arm straightens (a singularity OSC cannot leave) beyond ~0.72 m from the shoulder.
    for (s, side) in [1.0, -1.0].iter().enumerate() {
        if !reach {
            break;
        }
        let h = horizontal_reach([p[0], p[1] + side * r, p[2]]);
        if h > 0.69 {
            best[s] -= 10.0 * (h - 0.69) + 0.05;
        }
    }
    best
}

/// Height of the bottle's neck grasp above its origin (bottom centre).
pub(super) const BOTTLE_NECK: f64 = 0.13;

/// The Panda's shoulder (joint 2 axis) in the world.
pub(super) const SHOULDER: [f64; 3] = [-0.66, 0.0, 1.245];

/// Horizontal distance of a point from the shoulder.
pub(super) fn horizontal_reach(p: [f64; 3]) -> f64 {
    ((p[0] - SHOULDER[0]).powi(2) + (p[1] - SHOULDER[1]).powi(2)).sqrt()
}

/// Height of a held object's origin above the destination object's origin when placed.
fn place_height(obj: &str, dest: &str) -> f64 {
    match (obj, dest) {
        (_, "plate") => 0.0015,
        ("cream_cheese", "akita_black_bowl") => 0.05,
        _ => 0.02,
    }
}

/// Height of a held object's origin above a region site when placed.
fn site_place_height(obj: &str, region: &str) -> f64 {
    let bottom = match obj {
        "akita_black_bowl" => 0.002,
        "wine_bottle" => 0.001,
        "cream_cheese" => -0.009,
        _ => 0.0,
    };
    let surface = if region.ends_with("cook_region") {
        0.006
    } else if region.ends_with("top_side") {
        0.0015
    } else {
        0.0
    };
    surface - bottom
}
