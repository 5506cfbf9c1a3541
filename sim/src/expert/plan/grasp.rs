//! Grasping: where to take each object (fixed offset or a bowl's rim), the approach, the pinch, and letting go.

use rand::Rng;

use super::geometry::*;
use super::{Builder, CLOSE, OPEN};
use crate::expert::math::qrot;
use crate::expert::op::{Op, Point, Target};
use crate::task::Category;

/// Where and how to take an object.
pub(super) enum GraspAt {
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

impl Builder<'_> {
    /// Grasp offset (in the object's frame when `.1`) and approach height for a category.
    pub(super) fn grasp_offset(&mut self, obj: usize) -> GraspAt {
        let cat = self.cat(obj);
        let (off, local, above) = match cat {
            Some(Category::AkitaBlackBowl)
                if self.near_rim || horizontal_reach(self.expected_pos(obj)) > 0.72 =>
            {
                // Far out (or under an open drawer): yaw the hand by 90° and pinch the near (−x) rim.
                (
                    [-0.0485, self.jit(0.003), 0.041 + self.jit(0.003)],
                    false,
                    0.07,
                )
            }
            Some(Category::AkitaBlackBowl) => {
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
            Some(Category::WineBottle) => (
                [
                    self.jit(0.002),
                    self.jit(0.002),
                    BOTTLE_NECK + self.jit(0.006),
                ],
                false,
                0.08,
            ),
            Some(Category::CreamCheese) => ([self.jit(0.006), self.jit(0.002), 0.003], false, 0.08),
            Some(Category::Basket) => {
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
            Some(
                Category::Plate
                | Category::WineRack
                | Category::FlatStove
                | Category::WoodenCabinet
                | Category::WhiteCabinet,
            )
            | None => ([0.0, 0.0, 0.02], false, 0.08),
        };
        GraspAt::Fixed { off, local, above }
    }

    pub(super) fn grasp(&mut self, obj: usize) {
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
        let far = self.cat(obj) == Some(Category::AkitaBlackBowl)
            && (self.near_rim || horizontal_reach(self.expected_pos(obj)) > 0.72);
        let want_yaw = if far
            || (self.cat(obj) == Some(Category::WineBottle)
                && self.hand_blocked_along_y(self.expected_pos(obj)))
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
                    i.def.builtin == Some(Category::WoodenCabinet)
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
        if self.near_rim && self.cat(obj) == Some(Category::AkitaBlackBowl) {
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
    pub(super) fn hand_blocked_along_y(&self, p: [f64; 3]) -> bool {
        let clearance = |dx: f64, dy: f64| -> f64 {
            let mut best = f64::MAX;
            for inst in &self.scene.instances {
                let Some(rad) = inst.def.handling.hand_clearance else {
                    continue;
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
    pub(super) fn crosses_object(&self, obj: usize, from: [f64; 3], to: [f64; 3]) -> bool {
        let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
        let len2 = dx * dx + dy * dy;
        if len2 < 1e-6 {
            return false;
        }
        self.scene.instances.iter().enumerate().any(|(k, inst)| {
            if k == obj
                || inst.def.kind != crate::world::assets::AssetKind::Movable
                || inst.def.handling.flat
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

    pub(super) fn release(&mut self) {
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
}
