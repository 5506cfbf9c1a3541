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

use std::collections::HashMap;
use std::fmt::Write;
use std::sync::Arc;

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::assets::{self, Articulation, AssetDef, AssetKind};
use crate::mujoco::{Data, MjError, Model, ObjType};
use crate::robot::{BASE_POS, ENV_CONAFFINITY, ENV_CONTYPE, panda_xml, v3, v4};

/// Errors while composing or placing a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The task names a category the asset library lacks.
    #[error(
        "unknown object category '{category}' for '{instance}' (the asset library has: {known})"
    )]
    UnknownCategory {
        /// Instance name.
        instance: String,
        /// Category name.
        category: String,
        /// Known categories.
        known: String,
    },
    /// The problem class is not one we build.
    #[error(
        "unsupported problem class '{0}' (supported: libero_tabletop_manipulation, libero_kitchen_tabletop_manipulation, libero_living_room_tabletop_manipulation, libero_study_tabletop_manipulation, libero_floor_manipulation, libero_coffee_table_manipulation)"
    )]
    ProblemClass(String),
    /// An `:init` atom this composer cannot realise.
    #[error("cannot realise init atom ({0})")]
    Init(String),
    /// Placement failed after many tries.
    #[error("could not place '{0}' without collisions after {1} tries")]
    Placement(String, usize),
    /// MuJoCo failed.
    #[error(transparent)]
    Mujoco(#[from] MjError),
}

/// A region declared in the task (`(:regions (name (:target t) …))`).
#[derive(Debug, Clone, PartialEq)]
pub struct RegionSpec {
    /// Region name as written (`plate_region`).
    pub name: String,
    /// Target entity (`main_table`, `basket_1`).
    pub target: String,
    /// Rectangles `x0 y0 x1 y1`, relative to the workspace reference.
    pub ranges: Vec<[f64; 4]>,
    /// Yaw range (last pair in the file).
    pub yaw: [f64; 2],
    /// Colour (alpha 0 = invisible).
    pub rgba: [f64; 4],
}

impl RegionSpec {
    /// `<target>_<name>`, the key BDDL atoms use.
    pub fn key(&self) -> String {
        format!("{}_{}", self.target, self.name)
    }
}

/// A named instance of a category.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstanceSpec {
    /// Instance name (`plate_1`).
    pub name: String,
    /// Category (`plate`).
    pub category: String,
}

/// A ground atom `(pred arg…)`, predicate lowercase.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AtomSpec {
    /// Predicate name, lowercase.
    pub predicate: String,
    /// Arguments: instance names or region keys.
    pub args: Vec<String>,
}

impl std::fmt::Display for AtomSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.predicate)?;
        for a in &self.args {
            write!(f, " {a}")?;
        }
        Ok(())
    }
}

/// What the composer needs from a task description.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// BDDL problem class, lowercase.
    pub problem_class: String,
    /// Regions in file order.
    pub regions: Vec<RegionSpec>,
    /// Fixtures in file order (the workspace included).
    pub fixtures: Vec<InstanceSpec>,
    /// Movable objects in file order.
    pub objects: Vec<InstanceSpec>,
    /// Initial-state atoms.
    pub init: Vec<AtomSpec>,
}

impl SceneSpec {
    /// The scene part of a parsed BDDL problem.
    pub fn from_problem(p: &crate::task::Problem) -> SceneSpec {
        let inst = |i: &crate::task::Instance| InstanceSpec {
            name: i.name.clone(),
            category: i.category.clone(),
        };
        SceneSpec {
            problem_class: p.problem_class.lowercase_name(),
            regions: p
                .regions
                .iter()
                .map(|r| RegionSpec {
                    name: r.name.clone(),
                    target: r.target.clone(),
                    ranges: r.ranges.clone(),
                    yaw: r.yaw_or_default(),
                    rgba: r.rgba_or_default(),
                })
                .collect(),
            fixtures: p.fixtures.iter().map(inst).collect(),
            objects: p.objects.iter().map(inst).collect(),
            init: p
                .init
                .iter()
                .map(|a| AtomSpec {
                    predicate: a.predicate.clone(),
                    args: a.args.clone(),
                })
                .collect(),
        }
    }
}

/// Arena (LIBERO problem class, libero.md §4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arena {
    /// `LIBERO_Tabletop_Manipulation`: `main_table`, friction 0.6, TargetZones at z 0.895.
    Tabletop,
    /// `LIBERO_Kitchen_Tabletop_Manipulation`: `kitchen_table`, friction 1.0, TargetZones at z 0.875.
    Kitchen,
    /// `LIBERO_Living_Room_Tabletop_Manipulation`: `living_room_table` (top at 0.41), robot on the ground.
    LivingRoom,
    /// `LIBERO_Study_Tabletop_Manipulation`: `study_table`, workspace offset (−0.2, 0, 0.867).
    Study,
    /// `LIBERO_Floor_Manipulation`: objects on the `floor`, robot on the ground.
    Floor,
    /// `LIBERO_Coffee_Table_Manipulation`: `coffee_table` (top at 0.41), robot on the ground.
    CoffeeTable,
}

impl Arena {
    /// The arena of a (lowercase) BDDL problem class.
    pub fn from_class(class: &str) -> Result<Arena, SceneError> {
        match class {
            "libero_tabletop_manipulation" => Ok(Arena::Tabletop),
            "libero_kitchen_tabletop_manipulation" => Ok(Arena::Kitchen),
            "libero_living_room_tabletop_manipulation" => Ok(Arena::LivingRoom),
            "libero_study_tabletop_manipulation" => Ok(Arena::Study),
            "libero_floor_manipulation" => Ok(Arena::Floor),
            "libero_coffee_table_manipulation" => Ok(Arena::CoffeeTable),
            other => Err(SceneError::ProblemClass(other.to_string())),
        }
    }

    /// Name of the workspace instance.
    pub fn workspace(self) -> &'static str {
        match self {
            Arena::Tabletop => "main_table",
            Arena::Kitchen => "kitchen_table",
            Arena::LivingRoom => "living_room_table",
            Arena::Study => "study_table",
            Arena::Floor => "floor",
            Arena::CoffeeTable => "coffee_table",
        }
    }

    /// LIBERO's `workspace_offset`: the reference that region rectangles are relative to; its z is
    /// the height of the working surface.
    pub fn workspace_offset(self) -> [f64; 3] {
        match self {
            Arena::Tabletop | Arena::Kitchen => [0.0, 0.0, TABLE_TOP],
            Arena::LivingRoom | Arena::CoffeeTable => [0.0, 0.0, 0.41],
            Arena::Study => [-0.2, 0.0, 0.867],
            Arena::Floor => [0.0, 0.0, 0.0],
        }
    }

    /// Height of the working surface objects stand on.
    pub fn surface_z(self) -> f64 {
        self.workspace_offset()[2]
    }

    /// LIBERO's fixture `z_offset` (0.01 − table thickness; −0.025 on the floor).
    fn fixture_z_offset(self) -> f64 {
        match self {
            Arena::Tabletop | Arena::Kitchen | Arena::Study => -0.04,
            Arena::LivingRoom | Arena::CoffeeTable => -0.014,
            Arena::Floor => -0.025,
        }
    }

    /// World z of the TargetZone sites' centres.
    fn target_zone_z(self) -> f64 {
        match self {
            Arena::Tabletop => 0.895,
            Arena::Kitchen => 0.875,
            other => other.surface_z() - 0.005,
        }
    }

    /// Friction of the working surface.
    fn friction(self) -> &'static str {
        match self {
            Arena::Tabletop => "0.6 0.005 0.0001",
            Arena::Kitchen => "1 0.005 0.0001",
            _ => "0.95 0.3 0.1",
        }
    }

    /// World position of the robot's root (`MountedPanda` on the tables, `OnTheGroundPanda` in the
    /// living room, on the coffee table and on the floor; robosuite's `base_xpos_offset`).
    pub fn robot_base(self) -> [f64; 3] {
        match self {
            Arena::Tabletop | Arena::Kitchen => BASE_POS,
            Arena::Study => [-0.25 - 0.5, 0.0, BASE_POS[2]],
            Arena::LivingRoom => [-0.16 - 0.35, 0.0, 0.42],
            Arena::CoffeeTable => [-0.16 - 0.35, 0.0, 0.41],
            Arena::Floor => [-0.6, 0.0, 0.0],
        }
    }

    /// The working surface as a box: (centre, half sizes), `None` on the floor.
    fn table_box(self) -> Option<([f64; 3], [f64; 3])> {
        let top = self.surface_z();
        let off = self.workspace_offset();
        match self {
            Arena::Tabletop | Arena::Kitchen | Arena::Study => {
                Some(([off[0], off[1], top - 0.025], [0.5, 0.6, 0.025]))
            }
            Arena::LivingRoom => Some(([off[0], off[1], top - 0.012], [0.35, 0.8, 0.012])),
            Arena::CoffeeTable => Some(([off[0], off[1], top - 0.012], [0.35, 0.6, 0.012])),
            Arena::Floor => None,
        }
    }

    /// Position of the workspace body (the table's centre; the origin for the floor).
    fn workspace_body_pos(self) -> [f64; 3] {
        match self.table_box() {
            Some((c, _)) => c,
            None => [0.0, 0.0, 0.0],
        }
    }

    /// The `agentview` camera: (pos, quat wxyz), as each problem class sets it.
    fn agentview(self) -> ([f64; 3], [f64; 4]) {
        const TABLE_Q: [f64; 4] = [
            0.6380177736282349,
            0.3048497438430786,
            0.30484986305236816,
            0.6380177736282349,
        ];
        const LOW_Q: [f64; 4] = [
            0.6182166934013367,
            0.3432307541370392,
            0.3432314395904541,
            0.6182177066802979,
        ];
        match self {
            Arena::Tabletop | Arena::Kitchen => {
                ([0.6586131746834771, 0.0, 1.6103500240372423], TABLE_Q)
            }
            Arena::Study => ([0.4586131746834771, 0.0, 1.6103500240372423], TABLE_Q),
            Arena::LivingRoom | Arena::CoffeeTable => ([0.6065773716836134, 0.0, 0.96], LOW_Q),
            Arena::Floor => ([0.8965773716836134, 5.216182733499864e-07, 0.65], LOW_Q),
        }
    }
}

/// Height of the table top (tabletop and kitchen arenas).
pub const TABLE_TOP: f64 = 0.90;

/// True geometry of the built-in assets: (bottom z, top z, footprint radius) relative to the origin.
fn true_extent(category: &str) -> (f64, f64, f64) {
    match category {
        "akita_black_bowl" => (0.0, 0.052, 0.054),
        "plate" => (0.0, 0.0164, 0.069),
        "basket" => (0.0042, 0.1457, 0.116),
        "cream_cheese" => (-0.009, 0.009, 0.046),
        "wine_bottle" => (0.001, 0.158, 0.022),
        _ => (0.0, 0.1, 0.05),
    }
}

/// Fixture footprint: local AABB (x0, y0, x1, y1) with drawers closed / knob home.
fn fixture_footprint(category: &str) -> [f64; 4] {
    match category {
        // Drawers may open by 0.16 m toward local −y, handles stick out 3 cm more.
        "wooden_cabinet" => [-0.128, -0.16, 0.128, 0.127],
        "flat_stove" => [-0.052, -0.095, 0.245, 0.095],
        "wine_rack" => [-0.135, -0.127, 0.135, 0.127],
        _ => [-0.05, -0.05, 0.05, 0.05],
    }
}

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

/// Builds the MJCF of the arena, robot, objects and fixtures of `spec`.
pub fn compose_xml(spec: &SceneSpec) -> Result<String, SceneError> {
    compose_xml_with(spec, None)
}

/// The MJCF of `spec` with its objects and fixtures from LIBERO's asset pack when `pack` is given
/// (same names, joints and region sites as the builtin assets, LIBERO's meshes and collision boxes),
/// else from the builtin primitives.
pub fn compose_xml_with(
    spec: &SceneSpec,
    pack: Option<&crate::pack::LiberoPack>,
) -> Result<String, SceneError> {
    let mut extra_assets = String::new();
    let mut body = |def: &AssetDef, name: &str, pos: [f64; 3]| -> Result<String, SceneError> {
        match pack {
            None => Ok(assets::instance_xml(def, name, pos, [1.0, 0.0, 0.0, 0.0])),
            Some(pack) => {
                let o = crate::pack::compose::LiberoObject::load(pack, def.category)
                    .map_err(|e| SceneError::Init(e.to_string()))?;
                extra_assets.push_str(&o.asset_xml(name));
                Ok(o.body_xml(
                    name,
                    pos,
                    [1.0, 0.0, 0.0, 0.0],
                    def.kind == AssetKind::Movable,
                ))
            }
        }
    };
    let arena = Arena::from_class(&spec.problem_class)?;
    let ws = arena.workspace();
    let mut zones = String::new();
    for r in &spec.regions {
        if r.target != ws {
            continue;
        }
        let Some(rect) = r.ranges.first() else {
            continue;
        };
        // Sites live in the workspace body (at `workspace_body_pos`); rectangles are relative to the
        // workspace offset.
        let (off, body) = (arena.workspace_offset(), arena.workspace_body_pos());
        let (cx, cy) = (
            (rect[0] + rect[2]) / 2.0 + off[0] - body[0],
            (rect[1] + rect[3]) / 2.0 + off[1] - body[1],
        );
        let (hx, hy) = (
            ((rect[2] - rect[0]) / 2.0).abs(),
            ((rect[3] - rect[1]) / 2.0).abs(),
        );
        let rgba = r.rgba;
        let _ = writeln!(
            zones,
            r#"<site name="{}" type="box" pos="{cx} {cy} {}" size="{} {} 0.007" rgba="{} {} {} {}" group="3"/>"#,
            r.key(),
            arena.target_zone_z() - body[2],
            hx.max(1e-4),
            hy.max(1e-4),
            rgba[0],
            rgba[1],
            rgba[2],
            rgba[3]
        );
    }
    let mut bodies = String::new();
    for o in &spec.objects {
        let def = lookup(o, pack, true)?;
        if def.kind != AssetKind::Movable {
            return Err(SceneError::Init(format!(
                "'{}' ({}) is a fixture in this library but is listed under :objects",
                o.name, o.category
            )));
        }
        bodies.push_str(&body(def, &o.name, [0.0, 0.0, 1.5])?);
    }
    for fx in &spec.fixtures {
        if assets::WORKSPACE_CATEGORIES.contains(&fx.category.as_str()) || fx.name == ws {
            continue;
        }
        let def = lookup(fx, pack, false)?;
        if def.kind != AssetKind::Fixture {
            return Err(SceneError::Init(format!(
                "'{}' ({}) is a movable object in this library but is listed under :fixtures",
                fx.name, fx.category
            )));
        }
        bodies.push_str(&body(def, &fx.name, [0.0, 0.0, -2.0])?);
    }
    match pack {
        None => Ok(world_xml_with_assets(
            arena,
            &spec.problem_class,
            &zones,
            &bodies,
            &extra_assets,
        )),
        Some(pack) => world_xml_libero(
            pack,
            arena,
            &spec.problem_class,
            &zones,
            &bodies,
            &extra_assets,
        ),
    }
}

/// The MJCF of LIBERO's own arena (the pack's scene XML, robosuite's `TableArena` table on the
/// tabletop and kitchen arenas), the Panda in robosuite's visual meshes, LIBERO's cameras and
/// lighting (MuJoCo's default headlight), and the given bodies, in LIBERO's assembly order.
pub fn world_xml_libero(
    pack: &crate::pack::LiberoPack,
    arena: Arena,
    model_name: &str,
    zones: &str,
    bodies: &str,
    extra_assets: &str,
) -> Result<String, SceneError> {
    use crate::pack::compose::{arena_xml, robot_visuals};
    let err = |e: crate::pack::compose::ComposeError| SceneError::Init(e.to_string());
    let scene = arena_xml(pack, arena).map_err(err)?;
    let visuals = robot_visuals(pack).map_err(err)?;
    let panda = crate::robot::panda_xml_dressed(arena.robot_base(), &visuals.geoms);
    let ws = arena.workspace();
    let body = arena.workspace_body_pos();
    let mut table = String::new();
    if matches!(arena, Arena::Tabletop | Arena::Kitchen)
        && let Some((_, h)) = arena.table_box()
    {
        // robosuite's TableArena: a collision box (group 0, hidden), the textured visual box and four
        // visual legs down to the floor.
        let leg = body[2] / 2.0;
        let _ = writeln!(
            table,
            r#"<geom name="{ws}_collision" type="box" size="{} {} {}" friction="{}" rgba="0.5 0.5 0 1" group="0" contype="{ENV_CONTYPE}" conaffinity="{ENV_CONAFFINITY}"/>
<geom name="{ws}_visual" type="box" size="{} {} {}" contype="0" conaffinity="0" group="1" material="table_texture"/>"#,
            h[0],
            h[1],
            h[2],
            arena.friction(),
            h[0],
            h[1],
            h[2],
        );
        for (k, (sx, sy)) in [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
            .into_iter()
            .enumerate()
        {
            let _ = writeln!(
                table,
                r#"<geom name="{ws}_leg{}_visual" type="cylinder" size="0.025 {leg}" pos="{} {} {}" contype="0" conaffinity="0" group="1" material="table_legs"/>"#,
                k + 1,
                sx * (h[0] - 0.1),
                sy * (h[1] - 0.1),
                -leg
            );
        }
    }
    Ok(assemble(&World {
        arena,
        model_name,
        // MuJoCo's default tessellation, as LIBERO's worlds: lighting is per vertex, so the
        // spotlight on the table needs the 4×4 quads per box face.
        visual: r#"<quality offsamples="0"/><map znear="0.001"/>"#,
        assets: &format!("{}{}{extra_assets}", scene.assets, visuals.assets),
        arena_world: &scene.world,
        workspace_geoms: &table,
        zones,
        panda: &panda,
        bodies,
    }))
}

/// The MJCF of an arena (floor, walls, lights, table with its TargetZone sites `zones`, cameras) with the
/// Panda and the given extra `<body>` elements, in LIBERO's assembly order.
pub fn world_xml(arena: Arena, model_name: &str, zones: &str, bodies: &str) -> String {
    world_xml_with_assets(arena, model_name, zones, bodies, "")
}

/// [`world_xml`] with extra `<asset>` children (meshes, textures, materials of the bodies).
pub fn world_xml_with_assets(
    arena: Arena,
    model_name: &str,
    zones: &str,
    bodies: &str,
    extra_assets: &str,
) -> String {
    let ws = arena.workspace();
    let panda = panda_xml(arena.robot_base());
    let (wall, floor1, floor2, table) = match arena {
        Arena::Tabletop | Arena::Study => (
            "0.82 0.82 0.80 1",
            "0.62 0.62 0.62",
            "0.56 0.56 0.56",
            "0.62 0.45 0.30 1",
        ),
        Arena::Kitchen => (
            "0.86 0.84 0.78 1",
            "0.55 0.5 0.45",
            "0.5 0.45 0.4",
            "0.70 0.55 0.38 1",
        ),
        Arena::LivingRoom | Arena::CoffeeTable | Arena::Floor => (
            "0.84 0.82 0.78 1",
            "0.55 0.42 0.30",
            "0.50 0.38 0.27",
            "0.45 0.32 0.22 1",
        ),
    };
    let body = arena.workspace_body_pos();
    let mut table_geoms = String::new();
    if let Some((c, h)) = arena.table_box() {
        let (cx, cy, cz) = (c[0] - body[0], c[1] - body[1], c[2] - body[2]);
        let _ = writeln!(
            table_geoms,
            r#"<geom name="{ws}_collision" type="box" pos="{cx} {cy} {cz}" size="{} {} {}" friction="{friction}" material="table_mat" contype="{ct}" conaffinity="{ca}" group="1"/>"#,
            h[0],
            h[1],
            h[2],
            friction = arena.friction(),
            ct = ENV_CONTYPE,
            ca = ENV_CONAFFINITY,
        );
        let (lx, ly, top) = (h[0] - 0.1, h[1] - 0.1, cz - h[2]);
        for (k, (sx, sy)) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
            .into_iter()
            .enumerate()
        {
            let (x, y) = (cx + sx * lx, cy + sy * ly);
            let _ = writeln!(
                table_geoms,
                r#"<geom name="{ws}_leg{}" type="cylinder" fromto="{x} {y} {top} {x} {y} {}" size="0.025" contype="0" conaffinity="0" group="1" rgba="0.3 0.3 0.3 1"/>"#,
                k + 1,
                -body[2],
            );
        }
    }
    let assets = format!(
        r#"<texture name="floor_tex" type="2d" builtin="checker" rgb1="{floor1}" rgb2="{floor2}" width="64" height="64"/>
<material name="floor_mat" texture="floor_tex" texrepeat="12 12" reflectance="0"/>
<material name="table_mat" rgba="{table}" reflectance="0"/>
<material name="wall_mat" rgba="{wall}" reflectance="0"/>
{extra_assets}"#
    );
    let arena_world = format!(
        r#"<light name="light0" pos="1 1 4" dir="-0.24 -0.24 -0.94" diffuse="0.55 0.55 0.55" specular="0.2 0.2 0.2" castshadow="false"/>
<light name="light1" pos="-3 -3 4" dir="0.51 0.51 -0.69" diffuse="0.55 0.55 0.55" specular="0.2 0.2 0.2" castshadow="false"/>
<geom name="floor" type="plane" size="3 3 0.125" material="floor_mat" friction="{floor_friction}" contype="{ENV_CONTYPE}" conaffinity="{ENV_CONAFFINITY}" group="1"/>
<geom name="wall_back" type="box" pos="-1.6 0 1.5" size="0.01 3 1.5" material="wall_mat" contype="0" conaffinity="0" group="1"/>
<geom name="wall_left" type="box" pos="0 3 1.5" size="3 0.01 1.5" material="wall_mat" contype="0" conaffinity="0" group="1"/>
<geom name="wall_right" type="box" pos="0 -3 1.5" size="3 0.01 1.5" material="wall_mat" contype="0" conaffinity="0" group="1"/>
"#,
        floor_friction = if arena == Arena::Floor {
            arena.friction()
        } else {
            "1 0.005 0.0001"
        },
    );
    assemble(&World {
        arena,
        model_name,
        visual: r#"<quality offsamples="0" numslices="16" numstacks="8" numquads="1"/><headlight ambient="0.25 0.25 0.25" diffuse="0.3 0.3 0.3" specular="0.1 0.1 0.1"/>"#,
        assets: &assets,
        arena_world: &arena_world,
        workspace_geoms: &table_geoms,
        zones,
        panda: &panda,
        bodies,
    })
}

/// The parts of a world MJCF.
struct World<'a> {
    arena: Arena,
    model_name: &'a str,
    /// Extra `<visual>` children (headlight, map).
    visual: &'a str,
    /// `<asset>` children.
    assets: &'a str,
    /// Arena `<worldbody>` children before the workspace body (lights, floor, walls, furniture).
    arena_world: &'a str,
    /// Geoms of the workspace body (the table).
    workspace_geoms: &'a str,
    /// TargetZone sites of the workspace body.
    zones: &'a str,
    panda: &'a crate::robot::PandaXml,
    /// Objects and fixtures.
    bodies: &'a str,
}

/// One MJCF document in LIBERO's assembly order: arena, workspace body with its regions, cameras,
/// robot, objects and fixtures.
fn assemble(w: &World) -> String {
    let ws = w.arena.workspace();
    let body = w.arena.workspace_body_pos();
    let top_site = w.arena.surface_z() - body[2];
    let (cam_pos, cam_q) = w.arena.agentview();
    format!(
        r#"<mujoco model="{model_name}"><compiler angle="radian" autolimits="true"/>
<option timestep="0.002" impratio="20" cone="elliptic" density="1.2" viscosity="2e-5"/>
<size njmax="5000" nconmax="5000"/>
<visual><global offwidth="256" offheight="256"/>{visual}</visual>
<asset>
{assets}</asset>
<default>
{defaults}</default>
<worldbody>
{arena_world}<body name="{ws}" pos="{body_pos}">
{workspace_geoms}<site name="{ws}_top" pos="0 0 {top_site}" size="0.001" rgba="0 0 0 0"/>
{zones}</body>
<camera name="agentview" pos="{cam_pos}" quat="{cam_quat}" fovy="45"/>
<camera name="frontview" pos="1.0 0 1.48" quat="0.56 0.43 0.43 0.56" fovy="45"/>
{robot}{bodies}</worldbody>
<actuator>
{actuators}</actuator>
</mujoco>
"#,
        model_name = w.model_name,
        visual = w.visual,
        assets = w.assets,
        defaults = w.panda.defaults,
        arena_world = w.arena_world,
        workspace_geoms = w.workspace_geoms,
        zones = w.zones,
        robot = w.panda.body,
        bodies = w.bodies,
        actuators = w.panda.actuators,
        body_pos = v3(body),
        cam_pos = v3(cam_pos),
        cam_quat = v4(cam_q),
    )
}

/// The asset of `inst`: the builtin library's, else (with LIBERO's pack) one read from the pack's
/// XML, movable or a fixture as the task lists it.
fn lookup(
    inst: &InstanceSpec,
    pack: Option<&crate::pack::LiberoPack>,
    movable: bool,
) -> Result<&'static AssetDef, SceneError> {
    if let Some(def) = assets::asset(&inst.category) {
        return Ok(def);
    }
    let unknown = || SceneError::UnknownCategory {
        instance: inst.name.clone(),
        category: inst.category.clone(),
        known: assets::categories().join(", "),
    };
    let pack = pack.ok_or_else(unknown)?;
    crate::pack::compose::pack_asset_def(pack, &inst.category, movable).map_err(|e| match e {
        crate::pack::compose::ComposeError::Unknown(_) => unknown(),
        other => SceneError::Init(other.to_string()),
    })
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
    pub fn check_atom(&self, predicate: &str, args: &[String]) -> Result<(), SceneError> {
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
            let p = atom.predicate.as_str();
            if !matches!(p, "open" | "close" | "turnon" | "turnoff") {
                continue;
            }
            let target = atom
                .args
                .first()
                .ok_or_else(|| SceneError::Init(atom.to_string()))?;
            let joints = self
                .articulated_joints(target)
                .ok_or_else(|| SceneError::Init(atom.to_string()))?;
            for (_, adr, art) in joints {
                let [lo, hi] = if matches!(p, "open" | "turnon") {
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
            if atom.predicate != "on" || atom.args.len() != 2 {
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
            if !matches!(atom.predicate.as_str(), "on" | "in") || atom.args.len() != 2 {
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
            let (bottom, _, _) = true_extent(inst.def.category);
            let z = p[2] - half[2].min(0.01) - bottom + 0.005;
            let q = inst.def.placement_quat;
            data.qpos_mut()[adr..adr + 7].copy_from_slice(&[p[0], p[1], z, q[0], q[1], q[2], q[3]]);
        }
        // 4. Object-on-object stacking, repeated so chains (a on b on c) settle in any order.
        for _ in 0..3 {
            for atom in &self.spec.init {
                if atom.predicate != "on" || atom.args.len() != 2 {
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
                let (_, top_b, _) = true_extent(ib.def.category);
                let (bot_a, _, _) = true_extent(ia.def.category);
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
                placed.push(Placed::fixture(def.category, x, y, off[2], a));
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
                let (bottom, _, foot) = true_extent(def.category);
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

    fn fixture(category: &str, x: f64, y: f64, z: f64, yaw: f64) -> Placed {
        Placed {
            x,
            y,
            z,
            radius: 0.0,
            top_offset: 0.0,
            foot: Foot::Box {
                rect: fixture_footprint(category),
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
