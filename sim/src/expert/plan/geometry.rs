//! Free geometry of planning, on the live state but without a plan: which side of an object has
//! room for the fingers, the arm's reach from the shoulder, place heights, angle wrapping.

use crate::expert::math::{add, qrot};
use crate::task::Category;
use crate::world::assets::AssetDef;
use crate::world::env::Env;
use crate::world::scene::Scene;

/// An angle wrapped into (−π/2, π/2] (a parallel gripper is symmetric under a half turn).
pub(crate) fn wrap_half_turn(a: f64) -> f64 {
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
pub(crate) fn clear_side(
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
pub(crate) fn clear_side_both(
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

pub(crate) fn pick_side(best: [f64; 2], coin: bool) -> f64 {
    if (best[0] - best[1]).abs() < 0.02 || best[0].min(best[1]) > 0.08 {
        if coin { 1.0 } else { -1.0 }
    } else if best[0] > best[1] {
        1.0
    } else {
        -1.0
    }
}

/// Clearance of the hand on the +y and −y side of `p` (see [`clear_side`]).
pub(crate) fn side_clearance(
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
                let h = &inst.def.handling;
                if reach > r && !h.tall {
                    // The hand box passes over low objects; only the fingers reach them.
                    continue;
                }
                let Some(rad) = h.finger_clearance else {
                    continue;
                };
                let mut q = env.data().body_pos(scene.instances[k].root_body);
                if inst.def.kind == crate::world::assets::AssetKind::Movable
                    && ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt() < 0.03
                {
                    // Standing at `p` itself (a destination still occupied when the plan is made):
                    // it will have been moved away by then.
                    continue;
                }
                if h.clearance_centre != [0.0; 3] {
                    let b = scene.instances[k].root_body;
                    let o = qrot(env.data().body_quat(b), h.clearance_centre);
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
pub(crate) const BOTTLE_NECK: f64 = 0.13;

/// The Panda's shoulder (joint 2 axis) in the world.
pub(crate) const SHOULDER: [f64; 3] = [-0.66, 0.0, 1.245];

/// Horizontal distance of a point from the shoulder.
pub(crate) fn horizontal_reach(p: [f64; 3]) -> f64 {
    ((p[0] - SHOULDER[0]).powi(2) + (p[1] - SHOULDER[1]).powi(2)).sqrt()
}

/// Height of a held object's origin above the destination object's origin when placed.
pub(crate) fn place_height(obj: Option<Category>, dest: Option<Category>) -> f64 {
    match (obj, dest) {
        (_, Some(Category::Plate)) => 0.0015,
        (Some(Category::CreamCheese), Some(Category::AkitaBlackBowl)) => 0.05,
        _ => 0.02,
    }
}

/// Height of a held object's origin above a region site when placed.
pub(crate) fn site_place_height(obj: &AssetDef, region: &str) -> f64 {
    let bottom = obj.handling.site_bottom;
    let surface = if region.ends_with("cook_region") {
        0.006
    } else if region.ends_with("top_side") {
        0.0015
    } else {
        0.0
    };
    surface - bottom
}
