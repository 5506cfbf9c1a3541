//! Scene composition: a task description (BDDL, through [`SceneSpec`]) → one compiled MuJoCo world, and
//! seeded placement of fixtures and objects at every reset (libero.md §4).
//!
//! Assembly order follows LIBERO (§4.2), so qpos is the 7 arm joints, the 2 fingers, each movable object's
//! free joint in `:objects` order, then the fixtures' internal joints. Fixtures are mocap bodies: their poses
//! are drawn per episode like LIBERO's (which rewrites `body_pos`), without recompiling the model.
//!
//! Deliberate deviations from LIBERO, for valid starts: objects are dropped from 5 mm above their true
//! geometry (LIBERO's placement metadata leaves them several cm in the air), and candidates whose true
//! footprints overlap an already placed object or fixture are rejected too.

pub mod arena;
pub mod error;
mod place;
pub mod spec;
pub mod xml;

use std::collections::HashMap;
use std::sync::Arc;

use crate::engine::mujoco::{Model, ObjType};
use crate::task::Predicate;
use crate::world::assets::{self, Articulation, AssetDef, AssetKind};

pub use arena::{Arena, TABLE_TOP};
pub use error::SceneError;
pub use spec::{AtomSpec, InstanceSpec, RegionSpec, SceneSpec};
use xml::lookup;
pub use xml::{compose_xml, compose_xml_with, world_xml, world_xml_libero, world_xml_with_assets};

/// An instance in the compiled world.
#[derive(Debug, Clone)]
pub struct SceneInstance {
    /// Instance name.
    pub name: String,
    /// The asset.
    pub def: &'static AssetDef,
    /// Root body `<name>_main`.
    pub root_body: usize,
    /// qpos address of the free joint (movable objects).
    pub qpos_adr: Option<usize>,
    /// Mocap index (fixtures).
    pub mocap: Option<usize>,
    /// Geoms of the whole subtree.
    pub geoms: Vec<usize>,
    /// Internal joints: (joint id, qpos address, class).
    pub joints: Vec<(usize, usize, Articulation)>,
}

/// A region resolved against the compiled world.
#[derive(Debug, Clone)]
pub struct SceneRegion {
    /// The declaration.
    pub spec: RegionSpec,
    /// The site (TargetZone on the table, or the asset's site); `None` if the target has no such site
    /// (LIBERO silently ignores those).
    pub site: Option<usize>,
    /// Index into [`Scene::instances`] of the owning instance (object-attached regions).
    pub parent: Option<usize>,
    /// Joints that are direct children of the site's body (for Open/Close on a region).
    pub joints: Vec<(usize, usize, Articulation)>,
}

/// A compiled world ready for episodes.
pub struct Scene {
    /// The compiled model.
    pub model: Arc<Model>,
    /// Arena.
    pub arena: Arena,
    /// Movable objects (file order) then fixtures (file order, workspace excluded).
    pub instances: Vec<SceneInstance>,
    /// Regions by key.
    pub regions: HashMap<String, SceneRegion>,
    /// The task description.
    pub spec: SceneSpec,
    /// The MJCF it was compiled from.
    pub xml: String,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("arena", &self.arena)
            .field(
                "instances",
                &self.instances.iter().map(|i| &i.name).collect::<Vec<_>>(),
            )
            .finish()
    }
}

impl Scene {
    /// Composes and compiles the world of `spec`.
    pub fn build(spec: SceneSpec) -> Result<Scene, SceneError> {
        Self::build_with(spec, None)
    }

    /// [`Scene::build`] with the objects and fixtures from LIBERO's asset pack when `pack` is given.
    pub fn build_with(
        spec: SceneSpec,
        pack: Option<&crate::pack::LiberoPack>,
    ) -> Result<Scene, SceneError> {
        let arena = Arena::from_class(&spec.problem_class)?;
        let xml = compose_xml_with(&spec, pack)?;
        let model = Arc::new(Model::from_xml_str(&xml)?);
        let ws = arena.workspace();
        let mut instances = Vec::new();
        let fixtures = spec.fixtures.iter().filter(|f| {
            !(assets::WORKSPACE_CATEGORIES.contains(&f.category.as_str()) || f.name == ws)
        });
        let listed = spec
            .objects
            .iter()
            .map(|o| (o, true))
            .chain(fixtures.map(|f| (f, false)));
        for (inst, movable) in listed {
            let def = lookup(inst, pack, movable)?;
            let root_body = model.require(ObjType::Body, &format!("{}_main", inst.name))?;
            let geoms = (0..model.ngeom())
                .filter(|&g| model.body_root(model.geom_body(g)) == root_body)
                .collect();
            let qpos_adr = match def.kind {
                AssetKind::Movable => {
                    let j = model.require(ObjType::Joint, &format!("{}_joint0", inst.name))?;
                    Some(model.joint_qpos_adr(j))
                }
                AssetKind::Fixture => None,
            };
            let mut joints = Vec::new();
            for (jn, art) in def.joints {
                let j = model.require(ObjType::Joint, &format!("{}_{jn}", inst.name))?;
                joints.push((j, model.joint_qpos_adr(j), *art));
            }
            instances.push(SceneInstance {
                name: inst.name.clone(),
                def,
                root_body,
                qpos_adr,
                mocap: model.body_mocap(root_body),
                geoms,
                joints,
            });
        }
        let mut regions = HashMap::new();
        for r in &spec.regions {
            let key = r.key();
            let site = model.id(ObjType::Site, &key);
            let parent = instances.iter().position(|i| i.name == r.target);
            let joints = match (site, parent) {
                (Some(s), Some(pi)) => {
                    let body = model.site_body(s);
                    instances[pi]
                        .joints
                        .iter()
                        .filter(|(j, _, _)| model.joint_body(*j) == body)
                        .copied()
                        .collect()
                }
                _ => Vec::new(),
            };
            regions.insert(
                key,
                SceneRegion {
                    spec: r.clone(),
                    site,
                    parent,
                    joints,
                },
            );
        }
        Ok(Scene {
            model,
            arena,
            instances,
            regions,
            spec,
            xml,
        })
    }

    /// Checks that every argument of `(predicate args…)` names an instance or a region with a site here.
    pub fn check_atom(&self, predicate: Predicate, args: &[String]) -> Result<(), SceneError> {
        for a in args {
            let known =
                self.instance(a).is_some() || self.regions.get(a).is_some_and(|r| r.site.is_some());
            if !known {
                return Err(SceneError::Init(format!(
                    "({predicate} {}): '{a}' is neither an object nor a fixture nor a region with a site in this scene",
                    args.join(" ")
                )));
            }
        }
        Ok(())
    }

    /// Index of the named instance.
    pub fn instance(&self, name: &str) -> Option<usize> {
        self.instances.iter().position(|i| i.name == name)
    }

    /// Instance owning body `body` (via its root), if any.
    pub fn instance_of_body(&self, body: usize) -> Option<usize> {
        let root = self.model.body_root(body);
        self.instances.iter().position(|i| i.root_body == root)
    }
}
