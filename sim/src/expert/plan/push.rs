//! Pushing a plate flat along the table into a region.

use super::{Builder, CLOSE, OPEN};
use crate::expert::op::{Op, Point, Target};

impl Builder<'_> {
    /// Move a plate onto a table region: pinch its +y rim (the side away from the cabinet), lift it a few
    /// centimetres (over low objects), carry it and set it down where its footprint clears the objects
    /// already standing in the region.
    pub(super) fn push_to(&mut self, obj: usize, site: usize, n: usize) {
        if self.held.is_some() {
            self.release();
        }
        let p = self.pos(obj);
        let s = self.env.data().site_pos(site);
        let gx = s[0] + self.jit(0.008);
        // Plate radius 0.069: keep its rim 1 cm clear of objects beside the region's near (−y) side.
        let mut gy = s[1] + 0.005;
        for (k, inst) in self.scene.instances.iter().enumerate() {
            if k == obj || inst.def.kind != crate::world::assets::AssetKind::Movable {
                continue;
            }
            let o = self.env.data().body_pos(inst.root_body);
            if (o[0] - gx).abs() < 0.069 + 0.045 && o[1] < gy {
                let r = inst.def.handling.push_clearance;
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
}
