//! The MJCF of a scene: arena, workspace with its TargetZone sites, cameras, the Panda, objects and
//! fixtures in LIBERO's assembly order, from the builtin assets or LIBERO's pack.

use std::fmt::Write;

use super::arena::Arena;
use super::error::SceneError;
use super::spec::{InstanceSpec, SceneSpec};
use crate::world::assets::{self, AssetDef, AssetKind};
use crate::world::robot::{ENV_CONAFFINITY, ENV_CONTYPE, panda_xml, v3, v4};

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
    let panda = crate::world::robot::panda_xml_dressed(arena.robot_base(), &visuals.geoms);
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
    panda: &'a crate::world::robot::PandaXml,
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
pub(super) fn lookup(
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
