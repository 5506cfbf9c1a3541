//! Seeded placement at every reset (libero.md §4.3): articulation atoms, workspace placements,
//! site-conditioned placements and stacking, by rejection sampling on true footprints.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::Scene;
use super::arena::Arena;
use super::error::SceneError;
use crate::engine::mujoco::Data;
use crate::task::Predicate;
use crate::world::assets::{self, Articulation, AssetKind};

impl Scene {
    /// Draws an initial state from `rng` into `data` (LIBERO's order, §4.3): articulation atoms, workspace
    /// placements in `:init` order, site-conditioned placements, then object-on-object stacking. Ends with
    /// a forward pass; velocities are zero.
    pub fn sample_init(&self, data: &mut Data, rng: &mut ChaCha8Rng) -> Result<(), SceneError> {
        self.sample(data, rng, true)
    }

    /// The part of [`Scene::sample_init`] that a stored init state does not overwrite: fixture poses
    /// (and articulation atoms, which the state then overrides). Movable objects are only parked.
    pub fn sample_fixtures(&self, data: &mut Data, rng: &mut ChaCha8Rng) -> Result<(), SceneError> {
        self.sample(data, rng, false)
    }

    fn sample(
        &self,
        data: &mut Data,
        rng: &mut ChaCha8Rng,
        objects: bool,
    ) -> Result<(), SceneError> {
        let ws = self.arena.workspace();
        // Park every movable object far away; unplaced ones stay there.
        for (k, inst) in self.instances.iter().enumerate() {
            if let Some(a) = inst.qpos_adr {
                let q = data.qpos_mut();
                q[a..a + 7].copy_from_slice(&[2.0 + 0.3 * k as f64, 2.0, 0.1, 1.0, 0.0, 0.0, 0.0]);
            }
            for &(_, adr, _) in &inst.joints {
                data.qpos_mut()[adr] = 0.0;
            }
        }
        // 1. Articulation atoms.
        for atom in &self.spec.init {
            let InitUse::Articulation(open) = init_use(atom.predicate) else {
                continue;
            };
            let target = atom
                .args
                .first()
                .ok_or_else(|| SceneError::Init(atom.to_string()))?;
            let joints = self
                .articulated_joints(target)
                .ok_or_else(|| SceneError::Init(atom.to_string()))?;
            for (_, adr, art) in joints {
                let [lo, hi] = if open {
                    art.open_range()
                } else {
                    art.close_range()
                };
                data.qpos_mut()[adr] = rng.random_range(lo..=hi);
            }
        }
        // 2. Workspace placements, in :init order.
        let mut placed: Vec<Placed> = Vec::new();
        for atom in &self.spec.init {
            if init_use(atom.predicate) != (InitUse::Place { on: true }) || atom.args.len() != 2 {
                continue;
            }
            let (what, region) = (&atom.args[0], &atom.args[1]);
            let Some(r) = self.regions.get(region) else {
                continue;
            };
            if r.spec.target != ws {
                continue;
            }
            let Some(ii) = self.instance(what) else {
                return Err(SceneError::Init(format!(
                    "{atom}: unknown instance '{what}'"
                )));
            };
            if !objects && self.instances[ii].qpos_adr.is_some() {
                continue;
            }
            let rect = *r
                .spec
                .ranges
                .first()
                .ok_or_else(|| SceneError::Init(format!("{atom}: region has no :ranges")))?;
            self.place_on_workspace(data, rng, ii, rect, r.spec.yaw, &mut placed)?;
        }
        data.forward()?;
        if !objects {
            data.qvel_mut().fill(0.0);
            return Ok(());
        }
        // 3. Site-conditioned placements (On/In a site of another instance).
        for atom in &self.spec.init {
            if !matches!(init_use(atom.predicate), InitUse::Place { .. }) || atom.args.len() != 2 {
                continue;
            }
            let Some(r) = self.regions.get(&atom.args[1]) else {
                continue;
            };
            if r.spec.target == ws {
                continue;
            }
            let (Some(site), Some(ii)) = (r.site, self.instance(&atom.args[0])) else {
                return Err(SceneError::Init(atom.to_string()));
            };
            let inst = &self.instances[ii];
            let adr = inst
                .qpos_adr
                .ok_or_else(|| SceneError::Init(format!("{atom}: not movable")))?;
            let p = data.site_pos(site);
            let half = self.model.site_size(site);
            let bottom = inst.def.extent.bottom;
            let z = p[2] - half[2].min(0.01) - bottom + 0.005;
            let q = inst.def.placement_quat;
            data.qpos_mut()[adr..adr + 7].copy_from_slice(&[p[0], p[1], z, q[0], q[1], q[2], q[3]]);
        }
        // 4. Object-on-object stacking, repeated so chains (a on b on c) settle in any order.
        for _ in 0..3 {
            for atom in &self.spec.init {
                if init_use(atom.predicate) != (InitUse::Place { on: true }) || atom.args.len() != 2
                {
                    continue;
                }
                let (Some(a), Some(b)) =
                    (self.instance(&atom.args[0]), self.instance(&atom.args[1]))
                else {
                    continue;
                };
                let (ia, ib) = (&self.instances[a], &self.instances[b]);
                let Some(aa) = ia.qpos_adr else {
                    return Err(SceneError::Init(format!(
                        "{atom}: '{}' is a fixture and cannot be stacked",
                        ia.name
                    )));
                };
                // On a movable object: its sampled position; on a fixture: its placed body.
                let qb: Vec<f64> = match ib.qpos_adr {
                    Some(ab) => data.qpos()[ab..ab + 3].to_vec(),
                    None => {
                        data.forward()?;
                        data.body_pos(ib.root_body).to_vec()
                    }
                };
                let top_b = ib.def.extent.top;
                let bot_a = ia.def.extent.bottom;
                let q = ia.def.placement_quat;
                data.qpos_mut()[aa..aa + 7].copy_from_slice(&[
                    qb[0],
                    qb[1],
                    qb[2] + top_b - bot_a + 0.005,
                    q[0],
                    q[1],
                    q[2],
                    q[3],
                ]);
            }
        }
        data.qvel_mut().fill(0.0);
        data.forward()?;
        Ok(())
    }

    /// Joints an articulation atom refers to: a region's site joints or an instance's joints.
    fn articulated_joints(&self, target: &str) -> Option<Vec<(usize, usize, Articulation)>> {
        if let Some(r) = self.regions.get(target) {
            return Some(r.joints.clone());
        }
        self.instance(target)
            .map(|i| self.instances[i].joints.clone())
    }

    fn place_on_workspace(
        &self,
        data: &mut Data,
        rng: &mut ChaCha8Rng,
        ii: usize,
        rect: [f64; 4],
        yaw: [f64; 2],
        placed: &mut Vec<Placed>,
    ) -> Result<(), SceneError> {
        let inst = &self.instances[ii];
        let def = inst.def;
        match def.kind {
            AssetKind::Fixture => {
                // MultiRegionRandomSampler: uniform, no shrink, no collision check; yaw about z.
                let x = uniform(rng, rect[0], rect[2]);
                let y = uniform(rng, rect[1], rect[3]);
                let a = uniform(rng, yaw[0], yaw[1]);
                let off = self.arena.workspace_offset();
                let (x, y) = (x + off[0], y + off[1]);
                let z = off[2] + self.arena.fixture_z_offset() - def.bottom_offset;
                let m = inst.mocap.expect("fixtures are mocap bodies");
                data.mocap_pos_mut()[3 * m..3 * m + 3].copy_from_slice(&[x, y, z]);
                data.mocap_quat_mut()[4 * m..4 * m + 4].copy_from_slice(&assets::yaw_quat(a));
                placed.push(Placed::fixture(def.extent.footprint, x, y, off[2], a));
                Ok(())
            }
            AssetKind::Movable => {
                let r = def.horizontal_radius;
                let (x0, x1, y0, y1) = match self.arena {
                    // TableRegionSampler shrinks by the radius (numpy accepts low > high, so a region
                    // narrower than 2r widens to [x1 − r, x0 + r]).
                    Arena::Tabletop => (rect[0] + r, rect[2] - r, rect[1] + r, rect[3] - r),
                    Arena::Floor => (rect[0] + r, rect[2] - r, rect[1] + r, rect[3] - r),
                    // Libero100TableRegionSampler uses the plain range.
                    _ => (rect[0], rect[2], rect[1], rect[3]),
                };
                // The widened range can leave the region, making the `:init` atom false from the start;
                // we keep draws inside the region (1 mm margin) so every init relation holds.
                let (x0, x1) = clip_range(x0, x1, rect[0], rect[2]);
                let (y0, y1) = clip_range(y0, y1, rect[1], rect[3]);
                let (bottom, foot) = (def.extent.bottom, def.extent.radius);
                let off = self.arena.workspace_offset();
                let z = off[2] - bottom + 0.005;
                const TRIES: usize = 5000;
                // First with our true-footprint rule too; if the region is too tight for it (some
                // LIBERO-Spatial/Object layouts), with LIBERO's own rule alone.
                for k in 0..2 * TRIES {
                    let strict = k < TRIES;
                    let x = uniform(rng, x0, x1) + off[0];
                    let y = uniform(rng, y0, y1) + off[1];
                    let ok = placed
                        .iter()
                        .all(|p| !p.blocks(x, y, z, r, def.bottom_offset, foot, strict));
                    if ok {
                        let adr = inst.qpos_adr.expect("movable objects have a free joint");
                        let q = def.placement_quat;
                        data.qpos_mut()[adr..adr + 7]
                            .copy_from_slice(&[x, y, z, q[0], q[1], q[2], q[3]]);
                        placed.push(Placed::object(x, y, z, r, def.top_offset, foot));
                        return Ok(());
                    }
                }
                Err(SceneError::Placement(inst.name.clone(), 2 * TRIES))
            }
        }
    }
}

/// How an `:init` atom's predicate takes part in sampling (an exhaustive match: a new predicate must
/// say what it does here).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum InitUse {
    /// Sets an articulation: open (`open`, `turnon`) or closed (`close`, `turnoff`).
    Articulation(bool),
    /// Places an object in a region or site; `on` also places on the workspace and on objects.
    Place {
        /// `on` (else `in`).
        on: bool,
    },
    /// Not used by sampling.
    Ignored,
}

fn init_use(p: Predicate) -> InitUse {
    match p {
        Predicate::Open | Predicate::TurnOn => InitUse::Articulation(true),
        Predicate::Close | Predicate::TurnOff => InitUse::Articulation(false),
        Predicate::On => InitUse::Place { on: true },
        Predicate::In => InitUse::Place { on: false },
        Predicate::Up | Predicate::True | Predicate::False | Predicate::PrintJointState => {
            InitUse::Ignored
        }
    }
}

/// `[lo, hi]` (either order) intersected with the rectangle side `[a, b]` shrunk by 1 mm.
fn clip_range(lo: f64, hi: f64, a: f64, b: f64) -> (f64, f64) {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let (a, b) = (a.min(b) + 0.001, a.max(b) - 0.001);
    let (l, h) = (lo.max(a), hi.min(b));
    if l <= h {
        (l, h)
    } else {
        ((a + b) / 2.0, (a + b) / 2.0)
    }
}

/// numpy's `uniform(low, high)`: also valid (and symmetric) when low > high.
fn uniform(rng: &mut ChaCha8Rng, low: f64, high: f64) -> f64 {
    let u: f64 = rng.random();
    low + (high - low) * u
}

/// An already placed item, for rejection sampling.
struct Placed {
    x: f64,
    y: f64,
    z: f64,
    /// LIBERO's horizontal radius and top offset (its own rejection rule).
    radius: f64,
    top_offset: f64,
    /// True footprint: a circle radius (objects) or an oriented box (fixtures).
    foot: Foot,
}

enum Foot {
    Circle(f64),
    Box { rect: [f64; 4], yaw: f64 },
}

impl Placed {
    fn object(x: f64, y: f64, z: f64, radius: f64, top_offset: f64, foot: f64) -> Placed {
        Placed {
            x,
            y,
            z,
            radius,
            top_offset,
            foot: Foot::Circle(foot),
        }
    }

    fn fixture(footprint: [f64; 4], x: f64, y: f64, z: f64, yaw: f64) -> Placed {
        Placed {
            x,
            y,
            z,
            radius: 0.0,
            top_offset: 0.0,
            foot: Foot::Box {
                rect: footprint,
                yaw,
            },
        }
    }

    /// LIBERO's rule (xy distance ≤ r + r' and z − z' ≤ top' − bottom) or overlapping true footprints.
    #[allow(clippy::too_many_arguments)]
    fn blocks(
        &self,
        x: f64,
        y: f64,
        z: f64,
        r: f64,
        bottom_offset: f64,
        foot: f64,
        strict: bool,
    ) -> bool {
        let d = ((x - self.x).powi(2) + (y - self.y).powi(2)).sqrt();
        let libero = self.radius > 0.0
            && d <= self.radius + r
            && z - self.z <= self.top_offset - bottom_offset;
        if !strict {
            return libero;
        }
        let overlap = match self.foot {
            Foot::Circle(rr) => d < rr + foot + 0.005,
            Foot::Box { rect, yaw } => {
                // Into the fixture's frame, then distance from the circle centre to the rectangle.
                let (c, s) = (yaw.cos(), yaw.sin());
                let (dx, dy) = (x - self.x, y - self.y);
                let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
                let qx = lx.clamp(rect[0], rect[2]);
                let qy = ly.clamp(rect[1], rect[3]);
                ((lx - qx).powi(2) + (ly - qy).powi(2)).sqrt() < foot + 0.005
            }
        };
        libero || overlap
    }
}
