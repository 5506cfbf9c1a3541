//! LIBERO's objects and fixtures: a category's XML as an MJCF fragment under an instance name, its
//! placement metadata, and an asset definition for categories the builtin library lacks.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::error::ComposeError;
use super::xml::*;
use crate::cache::LiberoPack;

/// Placement metadata of an object (robosuite's `bottom_offset`, `top_offset`, `horizontal_radius`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Position of `bottom_site`.
    pub bottom_offset: [f64; 3],
    /// Position of `top_site`.
    pub top_offset: [f64; 3],
    /// x of `horizontal_radius_site`.
    pub horizontal_radius: f64,
}

/// One object or fixture of a category, ready to be placed under an instance name.
#[derive(Debug, Clone)]
pub struct LiberoObject {
    /// Category (`akita_black_bowl`, `wooden_cabinet`, …).
    pub category: String,
    /// The asset XML it came from.
    pub path: PathBuf,
    /// Placement metadata.
    pub placement: Placement,
    /// The `<asset>` children, serialised with absolute file paths and unprefixed names.
    assets: Vec<Element>,
    /// The `object` body, defaults inlined.
    body: Element,
}

/// Where a category's XML lives in LIBERO's asset tree.
pub fn asset_path(pack: &LiberoPack, category: &str) -> Option<PathBuf> {
    [
        format!("articulated_objects/{category}.xml"),
        format!("stable_hope_objects/{category}/{category}.xml"),
        format!("stable_scanned_objects/{category}/{category}.xml"),
        format!("turbosquid_objects/{category}/{category}.xml"),
    ]
    .iter()
    .find_map(|rel| pack.asset(rel))
}

impl LiberoObject {
    /// Loads category `category` from the pack.
    pub fn load(pack: &LiberoPack, category: &str) -> Result<LiberoObject, ComposeError> {
        let path =
            asset_path(pack, category).ok_or_else(|| ComposeError::Unknown(category.into()))?;
        let xml_err = |message: String| ComposeError::Xml {
            path: path.clone(),
            message,
        };
        let root = read_element(&path)?;
        let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let meshdir = root
            .children
            .iter()
            .filter(|c| c.tag == "compiler")
            .find_map(|c| c.attr("meshdir"))
            .map(|m| dir.join(m))
            .unwrap_or_else(|| dir.clone());
        let mut defaults = Defaults::new();
        for d in root.children.iter().filter(|c| c.tag == "default") {
            collect_defaults(d, None, &mut defaults);
        }
        let mut assets: Vec<Element> = Vec::new();
        for a in root.children.iter().filter(|c| c.tag == "asset") {
            for c in &a.children {
                let mut c = c.clone();
                if assets
                    .iter()
                    .any(|x| x.tag == c.tag && x.attr("name") == c.attr("name"))
                {
                    continue; // robosuite keeps the first definition of a repeated name
                }
                if let Some(f) = c.attr("file") {
                    let base = if c.tag == "mesh" { &meshdir } else { &dir };
                    let abs = base.join(f);
                    if !abs.exists() {
                        return Err(xml_err(format!("{} `{f}` not found", c.tag)));
                    }
                    c.set("file", abs.display().to_string());
                }
                inline_defaults(&mut c, &defaults, None);
                assets.push(c);
            }
        }
        let world = root
            .children
            .iter()
            .find(|c| c.tag == "worldbody")
            .ok_or_else(|| xml_err("no worldbody".into()))?;
        let holder = world
            .children
            .iter()
            .find(|b| {
                b.tag == "body" && b.children.iter().any(|c| c.attr("name") == Some("object"))
            })
            .ok_or_else(|| xml_err("no body holding a body named `object`".into()))?;
        let mut body = holder
            .children
            .iter()
            .find(|c| c.attr("name") == Some("object"))
            .cloned()
            .expect("checked above");
        inline_defaults(&mut body, &defaults, None);
        let site = |name: &str| {
            holder
                .children
                .iter()
                .find(|c| c.tag == "site" && c.attr("name") == Some(name))
                .and_then(|s| s.attr("pos"))
                .and_then(parse_vec3)
        };
        let placement = Placement {
            bottom_offset: site("bottom_site").unwrap_or([0.0, 0.0, -0.06]),
            top_offset: site("top_site").unwrap_or([0.0, 0.0, 0.04]),
            horizontal_radius: site("horizontal_radius_site").map_or(0.025, |p| p[0]),
        };
        Ok(LiberoObject {
            category: category.to_string(),
            path,
            placement,
            assets,
            body,
        })
    }

    /// The `<asset>` children for `instance` (names prefixed).
    pub fn asset_xml(&self, instance: &str) -> String {
        let mut out = String::new();
        for a in &self.assets {
            let mut a = a.clone();
            prefix(&mut a, instance);
            a.write(&mut out, 1);
        }
        out
    }

    /// The body `<instance>_main` at `pos`/`quat` (wxyz): with a free joint `<instance>_joint0`
    /// (damping 0.0005) when `movable`, else a mocap body (welded; posed at reset), as the builtin
    /// scenes place fixtures. Collision geoms get this crate's collision bits (objects; fixture frames;
    /// fixture parts under a joint), and geoms outside group 0 get `mass="0"` unless they state a
    /// mass, which is what LIBERO's `inertiagrouprange="0 0"` does.
    pub fn body_xml(&self, instance: &str, pos: [f64; 3], quat: [f64; 4], movable: bool) -> String {
        let mut b = self.body.clone();
        b.set("name", "main".into());
        prefix(&mut b, instance);
        b.set("pos", format!("{} {} {}", pos[0], pos[1], pos[2]));
        b.set(
            "quat",
            format!("{} {} {} {}", quat[0], quat[1], quat[2], quat[3]),
        );
        collision_bits(&mut b, movable, false);
        // LIBERO's `_post_process` shows a stove's `burner` site only while it is on; the env draws
        // that glow itself, so the site starts invisible (as the builtin stove's).
        hide_site(&mut b, &format!("{instance}_burner"));
        if movable {
            b.children.insert(
                0,
                Element {
                    tag: "joint".into(),
                    attrs: vec![
                        ("name".into(), format!("{instance}_joint0")),
                        ("type".into(), "free".into()),
                        ("damping".into(), "0.0005".into()),
                    ],
                    children: vec![],
                },
            );
        } else {
            b.set("mocap", "true".into());
        }
        let mut out = String::new();
        b.write(&mut out, 1);
        out
    }
}

impl LiberoObject {
    /// Internal joints of the `object` subtree (names without prefix), in document order.
    pub fn joint_names(&self) -> Vec<String> {
        fn walk(e: &Element, out: &mut Vec<String>) {
            for c in &e.children {
                match c.tag.as_str() {
                    "joint" => out.extend(c.attr("name").map(str::to_string)),
                    "body" => walk(c, out),
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.body, &mut out);
        out
    }

    /// Named box sites of the `object` subtree (names without prefix) with their half-sizes.
    pub fn box_sites(&self) -> Vec<(String, [f64; 3])> {
        fn walk(e: &Element, out: &mut Vec<(String, [f64; 3])>) {
            for c in &e.children {
                match c.tag.as_str() {
                    "site" => {
                        if let (Some(n), Some(h)) =
                            (c.attr("name"), c.attr("size").and_then(parse_vec3))
                        {
                            out.push((n.to_string(), h));
                        }
                    }
                    "body" => walk(c, out),
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.body, &mut out);
        out
    }
}

/// The free-joint quaternion (wxyz slots, written verbatim as LIBERO's samplers do, libero.md §4.3)
/// for a category's default placement rotation.
fn placement_quat(category: &str) -> [f64; 4] {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    match category {
        // rotation (π/2, π/2) about "x"
        "akita_black_bowl"
        | "plate"
        | "basket"
        | "white_bowl"
        | "bbq_sauce"
        | "chefmate_8_frypan"
        | "glazed_rim_porcelain_ramekin"
        | "rack" => [h, 0.0, 0.0, h],
        // dict {x: π/2, z: π/2}
        "ketchup" | "salad_dressing" | "new_salad_dressing" | "milk" | "orange_juice" => {
            [0.5, 0.5, 0.5, 0.5]
        }
        // (π/2, π/2) about "z"
        "tomato_sauce" | "alphabet_soup" => [0.0, 0.0, h, h],
        // (0, 0) about "x": the identity written into wxyz slots, a yaw of π
        _ => [0.0, 0.0, 0.0, 1.0],
    }
}

/// An [`AssetDef`](crate::world::assets::AssetDef) for a category the builtin library lacks, read from its
/// LIBERO XML: placement metadata from the sibling sites, box sites as regions, internal joints with
/// the class LIBERO judges them by (joints of unclassified categories are left out of the
/// predicates). `movable` follows the task's listing (`:objects` or `:fixtures`). Definitions are
/// made once per (category, movable) and kept for the process (a few dozen at most), so scenes can
/// hold `&'static` references as they do for the builtin library.
pub fn pack_asset_def(
    pack: &LiberoPack,
    category: &str,
    movable: bool,
) -> Result<&'static crate::world::assets::AssetDef, ComposeError> {
    use crate::task::Category;
    use crate::world::assets::{Articulation, AssetDef, AssetKind, Extent, Handling, SiteDef};
    use std::sync::{Mutex, OnceLock};
    type Cache = Mutex<HashMap<(String, bool), &'static AssetDef>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (category.to_string(), movable);
    if let Some(d) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok(d);
    }
    let o = LiberoObject::load(pack, category)?;
    let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
    let sites: Vec<SiteDef> = o
        .box_sites()
        .into_iter()
        .map(|(name, half)| SiteDef {
            name: leak(name),
            half,
        })
        .collect();
    let joints: Vec<(&'static str, Articulation)> = match Articulation::of_category(category) {
        Some(art) => o
            .joint_names()
            .into_iter()
            .map(|j| (leak(j), art))
            .collect(),
        None => Vec::new(),
    };
    let def: &'static AssetDef = Box::leak(Box::new(AssetDef {
        category: leak(category.to_string()),
        builtin: Category::from_name(category),
        extent: Extent::GENERIC,
        handling: Handling::GENERIC,
        kind: if movable {
            AssetKind::Movable
        } else {
            AssetKind::Fixture
        },
        bottom_offset: o.placement.bottom_offset[2],
        top_offset: o.placement.top_offset[2],
        horizontal_radius: o.placement.horizontal_radius,
        placement_quat: placement_quat(category),
        sites: Box::leak(sites.into_boxed_slice()),
        joints: Box::leak(joints.into_boxed_slice()),
    }));
    cache
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, def);
    Ok(def)
}
