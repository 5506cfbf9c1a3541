//! Turning a stove's knob on: grip the knob's bar and twist the wrist about its axis.

use super::geometry::*;
use super::{Builder, CLOSE, OPEN};
use crate::engine::mujoco::ObjType;
use crate::expert::math::qrot;
use crate::expert::op::{Op, Point, Target};

impl Builder<'_> {
    /// Turn a stove knob on: pinch its pointer bar across its thickness with the hand yawed along the
    /// bar, then twist the wrist about the knob's axis.
    pub(super) fn turn_knob(&mut self, stove: usize, n: usize) {
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
