//! Opening a cabinet drawer: pinch its handle and pull along the slide.

use super::{Builder, CLOSE, OPEN};
use crate::engine::mujoco::ObjType;
use crate::expert::math::{add, qrot};
use crate::expert::op::{Op, Point, Target};

impl Builder<'_> {
    /// Open the drawer owning region `region`: the hand, yawed so the fingers close along the handle bar
    /// and tilted ~40° so it stays out in front of the drawers above, slides in around the bar's ends,
    /// pinches them and pulls the drawer out along its slide.
    pub(super) fn open_drawer(&mut self, region: &str) -> [f64; 3] {
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
}
