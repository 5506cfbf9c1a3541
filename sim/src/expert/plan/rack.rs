//! Laying a wine bottle on the wine rack's top shelf: neck pinched from above, tipped over about the pinch.

use super::geometry::*;
use super::{Builder, CLOSE, OPEN};
use crate::expert::math::{add, qrot};
use crate::expert::op::{Op, Point, Target};

impl Builder<'_> {
    /// Lay a wine bottle in the rack: on the top shelf (inclined 31.3°, rising towards the rack's
    /// +y), along the incline with the neck up and the bottom against the stopper, beside the post,
    /// the way a wine rack holds bottles. The neck is pinched from above with the fingers closing along
    /// the shelf (the rack's x). A pinch is a free pivot about the finger axis, so the bottle hangs
    /// upright while carried; it is set down on its bottom rim a few centimetres up the shelf from the
    /// stopper, and the hand then carries the neck up and along the incline: the bottle tips over
    /// about the pinch and lies down, its bottom sliding down against the stopper.
    pub(super) fn lay_in_rack(&mut self, obj: usize, rack: usize, n: usize) {
        if self.held.is_some() {
            self.release();
        }
        let rb = self.scene.instances[rack].root_body;
        let rp = self.env.data().body_pos(rb);
        let rq = self.env.data().body_quat(rb);
        // The top shelf in the rack's frame (y, z); the bottom face goes 2 mm up from the stopper.
        let shelf = crate::world::assets::wine_rack_top_shelf();
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
}
