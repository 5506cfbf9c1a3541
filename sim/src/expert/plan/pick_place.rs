//! Pick and place: lift, carry at a safe height, set down on an object or in a region (or drop into a container).

use super::geometry::*;
use super::{Builder, CLOSE, OPEN};
use crate::expert::op::{Op, Point, Target};
use crate::task::Category;
use crate::world::scene::TABLE_TOP;

impl Builder<'_> {
    /// Height of the held object's origin while carrying.
    pub(super) fn carry_z(&self, obj: usize, over_basket: bool) -> f64 {
        let base = TABLE_TOP + self.scene.instances[obj].def.handling.carry_height;
        if over_basket { TABLE_TOP + 0.17 } else { base }
    }

    /// Pick `obj` (unless held), carry it over `to` and put it down; wait for subgoal `n`; release unless
    /// the next subgoal moves the same object. `drop`: release from above (into a container).
    pub(super) fn pick_place(
        &mut self,
        obj: usize,
        to: Point,
        n: usize,
        next_obj: Option<usize>,
        drop: bool,
    ) {
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
        let into_basket = drop
            && matches!(&to, Point::Site { .. })
            && self.cat(obj) == Some(Category::CreamCheese);
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
        if self.near_rim && self.cat(obj) == Some(Category::AkitaBlackBowl) {
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
    pub(super) fn within_reach(&self, to: Point) -> Point {
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
}
