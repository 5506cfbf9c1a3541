//! Moving a basket: grasp its wall and slide it, lifted a little, onto a region.

use super::{Builder, CLOSE};
use crate::expert::op::{Op, Point, Target};

impl Builder<'_> {
    /// Grasp a basket's wall and slide it (lifted a little) so its origin reaches `site`'s xy.
    pub(super) fn drag_basket(&mut self, basket: usize, site: usize, n: usize) {
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
}
