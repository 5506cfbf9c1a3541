//! LIBERO's object and fixture XMLs turned into MJCF fragments, as robosuite's `MujocoXMLObject`
//! with LIBERO's wrappers loads them (libero.md §3.1): only the `object` subtree enters the scene,
//! renamed `main`; every name gets the prefix `<instance>_`; the sibling sites `bottom_site`,
//! `top_site` and `horizontal_radius_site` become placement metadata; movable objects get a free joint
//! `<instance>_joint0` (damping 0.0005), fixtures none. Assets (meshes, textures, materials) keep their
//! files by absolute path, repeated names keep the first definition (as robosuite's merge does), and
//! `<default>` classes are inlined into the elements that use them.

use std::collections::HashMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};

use super::LiberoPack;

/// Errors composing an object.
#[derive(Debug, thiserror::Error)]
pub enum ComposeError {
    /// No asset of that category in the pack.
    #[error("the LIBERO pack has no asset for category `{0}`")]
    Unknown(String),
    /// The XML cannot be read or lacks what LIBERO expects.
    #[error("{}: {message}", path.display())]
    Xml {
        /// The asset file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

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

/// A parsed element (tag, attributes in document order, children).
#[derive(Debug, Clone, PartialEq)]
struct Element {
    tag: String,
    attrs: Vec<(String, String)>,
    children: Vec<Element>,
}

impl Element {
    fn attr(&self, k: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.as_str())
    }
    fn set(&mut self, k: &str, v: String) {
        match self.attrs.iter_mut().find(|(key, _)| key == k) {
            Some(slot) => slot.1 = v,
            None => self.attrs.push((k.to_string(), v)),
        }
    }
    fn from_node(n: roxmltree::Node) -> Element {
        Element {
            tag: n.tag_name().name().to_string(),
            attrs: n
                .attributes()
                .map(|a| {
                    (
                        a.name().to_string(),
                        a.value().split_whitespace().collect::<Vec<_>>().join(" "),
                    )
                })
                .collect(),
            children: n
                .children()
                .filter(|c| c.is_element())
                .map(Element::from_node)
                .collect(),
        }
    }
    fn write(&self, out: &mut String, depth: usize) {
        let pad = "  ".repeat(depth);
        let _ = write!(out, "{pad}<{}", self.tag);
        for (k, v) in &self.attrs {
            let v = v
                .replace('&', "&amp;")
                .replace('"', "&quot;")
                .replace('<', "&lt;");
            let _ = write!(out, " {k}=\"{v}\"");
        }
        if self.children.is_empty() {
            out.push_str("/>\n");
        } else {
            out.push_str(">\n");
            for c in &self.children {
                c.write(out, depth + 1);
            }
            let _ = writeln!(out, "{pad}</{}>", self.tag);
        }
    }
}

/// Reads and parses an XML file into an [`Element`] tree; errors name the file.
fn read_element(path: &Path) -> Result<Element, ComposeError> {
    let xml_err = |message: String| ComposeError::Xml {
        path: path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| xml_err(e.to_string()))?;
    let doc = roxmltree::Document::parse(&text).map_err(|e| xml_err(e.to_string()))?;
    Ok(Element::from_node(doc.root_element()))
}

/// Attributes that name something (and so get the instance prefix).
const NAME_REFS: [&str; 6] = ["name", "mesh", "material", "texture", "joint", "site"];

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

fn parse_vec3(s: &str) -> Option<[f64; 3]> {
    let v: Vec<f64> = s
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Default classes: class name → (parent class, tag → attributes).
type Defaults = HashMap<String, (Option<String>, HashMap<String, Vec<(String, String)>>)>;

fn collect_defaults(e: &Element, parent: Option<&str>, out: &mut Defaults) {
    let class = e.attr("class").unwrap_or("main").to_string();
    let mut per_tag = HashMap::new();
    for c in &e.children {
        if c.tag != "default" {
            per_tag.insert(c.tag.clone(), c.attrs.clone());
        }
    }
    out.insert(class.clone(), (parent.map(str::to_string), per_tag));
    for c in e.children.iter().filter(|c| c.tag == "default") {
        collect_defaults(c, Some(&class), out);
    }
}

/// Fills attributes an element lacks from its class chain, then drops `class`/`childclass`.
fn inline_defaults(e: &mut Element, defaults: &Defaults, inherited: Option<&str>) {
    let child_class = e
        .attr("childclass")
        .map(str::to_string)
        .or(inherited.map(str::to_string));
    let class = e
        .attr("class")
        .map(str::to_string)
        .or_else(|| child_class.clone());
    let mut chain = class;
    while let Some(c) = chain {
        let Some((parent, per_tag)) = defaults.get(&c) else {
            break;
        };
        if let Some(attrs) = per_tag.get(&e.tag) {
            for (k, v) in attrs {
                if e.attr(k).is_none() {
                    e.attrs.push((k.clone(), v.clone()));
                }
            }
        }
        chain = parent.clone();
    }
    e.attrs.retain(|(k, _)| k != "class" && k != "childclass");
    for c in &mut e.children {
        inline_defaults(c, defaults, child_class.as_deref());
    }
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

/// An [`AssetDef`](crate::assets::AssetDef) for a category the builtin library lacks, read from its
/// LIBERO XML: placement metadata from the sibling sites, box sites as regions, internal joints with
/// the class LIBERO judges them by (joints of unclassified categories are left out of the
/// predicates). `movable` follows the task's listing (`:objects` or `:fixtures`). Definitions are
/// made once per (category, movable) and kept for the process (a few dozen at most), so scenes can
/// hold `&'static` references as they do for the builtin library.
pub fn pack_asset_def(
    pack: &LiberoPack,
    category: &str,
    movable: bool,
) -> Result<&'static crate::assets::AssetDef, ComposeError> {
    use crate::assets::{Articulation, AssetDef, AssetKind, SiteDef};
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

/// robosuite's Panda, PandaGripper and RethinkMount visual meshes, ready to dress the builtin
/// Panda's bodies (whose names, frames and joints are robosuite's): the `<asset>` children the visual
/// geoms use, and the visual geoms (group 1, no collision, massless) of each body, by prefixed body
/// name. Collision geoms are not taken: the builtin Panda keeps its own.
#[derive(Debug, Clone, Default)]
pub struct RobotVisuals {
    /// `<asset>` children (meshes, materials, textures), names prefixed.
    pub assets: String,
    /// (body name, `<geom>` elements) in document order.
    pub geoms: Vec<(String, String)>,
}

/// Reads robosuite's Panda (`robot0_`), its gripper (`gripper0_`) and the Rethink mount (`mount0_`)
/// from the pack's robosuite wheel. Visual geoms of the mount's sub-bodies go to `mount0_base`,
/// shifted by robosuite's mount offset (+0.01 m in z).
pub fn robot_visuals(pack: &LiberoPack) -> Result<RobotVisuals, ComposeError> {
    let root = pack.robosuite_assets();
    let parts = [
        ("robots/panda/robot.xml", "robot0", None),
        ("grippers/panda_gripper.xml", "gripper0", None),
        (
            "mounts/rethink_mount.xml",
            "mount0",
            Some(("mount0_base", 0.01)),
        ),
    ];
    let mut out = RobotVisuals::default();
    for (rel, pfx, collapse) in parts {
        let path = root.join(rel);
        let xml_err = |message: String| ComposeError::Xml {
            path: path.clone(),
            message,
        };
        let doc_root = read_element(&path)?;
        let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let mut defaults = Defaults::new();
        for d in doc_root.children.iter().filter(|c| c.tag == "default") {
            collect_defaults(d, None, &mut defaults);
        }
        // Visual geoms by body.
        let mut geoms: Vec<(String, Element)> = Vec::new();
        fn walk(e: &Element, out: &mut Vec<(String, Element)>) {
            for c in &e.children {
                if c.tag != "body" {
                    continue;
                }
                let name = c.attr("name").unwrap_or_default().to_string();
                for g in c.children.iter().filter(|g| g.tag == "geom") {
                    if g.attr("group") == Some("1") {
                        out.push((name.clone(), g.clone()));
                    }
                }
                walk(c, out);
            }
        }
        for w in doc_root.children.iter().filter(|c| c.tag == "worldbody") {
            walk(w, &mut geoms);
        }
        let used: Vec<String> = geoms
            .iter()
            .filter_map(|(_, g)| g.attr("mesh").map(str::to_string))
            .collect();
        for a in doc_root.children.iter().filter(|c| c.tag == "asset") {
            for c in &a.children {
                if c.tag == "mesh" && !used.iter().any(|u| Some(u.as_str()) == c.attr("name")) {
                    continue; // collision meshes: not needed, and costly to compile
                }
                let mut c = c.clone();
                if let Some(f) = c.attr("file") {
                    let mut abs = dir.join(f);
                    if !abs.exists() {
                        return Err(xml_err(format!("{} `{f}` not found", c.tag)));
                    }
                    if c.tag == "mesh" && pack.light_robot {
                        abs = light_mesh(pack, &root, &abs)?;
                    }
                    c.set("file", abs.display().to_string());
                }
                inline_defaults(&mut c, &defaults, None);
                prefix(&mut c, pfx);
                c.write(&mut out.assets, 1);
            }
        }
        for (body, mut g) in geoms {
            inline_defaults(&mut g, &defaults, None);
            prefix(&mut g, pfx);
            g.set("mass", "0".into());
            g.set("contype", "0".into());
            g.set("conaffinity", "0".into());
            let body = match collapse {
                Some((target, dz)) => {
                    let p = g.attr("pos").and_then(parse_vec3).unwrap_or([0.0; 3]);
                    g.set("pos", format!("{} {} {}", p[0], p[1], p[2] + dz));
                    target.to_string()
                }
                None => format!("{pfx}_{body}"),
            };
            let mut s = String::new();
            g.write(&mut s, 0);
            match out.geoms.iter_mut().find(|(b, _)| *b == body) {
                Some((_, acc)) => acc.push_str(&s),
                None => out.geoms.push((body, s)),
            }
        }
    }
    Ok(out)
}

/// Grid cell (m) of the light robot meshes' vertex clustering: about a pixel of the 128² agentview
/// at the robot.
const LIGHT_MESH_CELL: f64 = 0.008;

/// Meshes with fewer vertices keep their full version.
const LIGHT_MESH_MIN_VERTICES: usize = 1000;

/// The light version of a robot visual mesh (OBJ or STL): vertices clustered on a
/// [`LIGHT_MESH_CELL`] grid (each cell's vertices merged to their mean, collapsed triangles
/// dropped), written once as OBJ under `<pack>/lod/` (atomically) and reused. robosuite's Panda
/// visuals are about 318k vertices, which llvmpipe transforms on the CPU for every camera; the light
/// meshes keep the silhouette at a fraction of the cost. Written by hand: vertex clustering is a few
/// lines, and it keeps the build free of a C++ mesh library.
fn light_mesh(pack: &LiberoPack, base: &Path, src: &Path) -> Result<PathBuf, ComposeError> {
    let err = |message: String| ComposeError::Xml {
        path: src.to_path_buf(),
        message,
    };
    let rel = src
        .strip_prefix(base)
        .unwrap_or(src)
        .to_string_lossy()
        .replace(['/', '\\'], "__");
    let out = pack.root.join("lod").join(format!("{rel}.light.obj"));
    if out.is_file() {
        return Ok(out);
    }
    let bytes = std::fs::read(src).map_err(|e| err(e.to_string()))?;
    let (verts, tris) = if src
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"))
    {
        read_obj(&String::from_utf8_lossy(&bytes))
    } else {
        read_stl(&bytes)
    }
    .map_err(err)?;
    // Small parts are not what costs; they keep their own mesh (and would collapse).
    if verts.len() < LIGHT_MESH_MIN_VERTICES {
        return Ok(src.to_path_buf());
    }
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let mut sums: Vec<([f64; 3], f64)> = Vec::new();
    let remap: Vec<usize> = verts
        .iter()
        .map(|v| {
            let key = v.map(|x| (x / LIGHT_MESH_CELL).floor() as i64);
            *cells.entry(key).or_insert_with(|| {
                sums.push(([0.0; 3], 0.0));
                sums.len() - 1
            })
        })
        .collect();
    for (v, &k) in verts.iter().zip(&remap) {
        let (sum, n) = &mut sums[k];
        for (s, x) in sum.iter_mut().zip(v) {
            *s += x;
        }
        *n += 1.0;
    }
    let mut seen = std::collections::HashSet::new();
    let mut text = String::new();
    for (p, n) in &sums {
        let _ = writeln!(text, "v {} {} {}", p[0] / n, p[1] / n, p[2] / n);
    }
    let mut faces = 0usize;
    for t in &tris {
        let [a, b, c] = t.map(|i| remap[i]);
        if a == b || b == c || a == c {
            continue;
        }
        let mut key = [a, b, c];
        key.sort_unstable();
        if seen.insert(key) {
            let _ = writeln!(text, "f {} {} {}", a + 1, b + 1, c + 1);
            faces += 1;
        }
    }
    if faces < 16 {
        return Ok(src.to_path_buf());
    }
    let dir = out.parent().expect("lod/ has a parent");
    std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    // Written beside the final name and renamed, so a reader never sees half a file; the name is
    // unique per process and thread, as two workers may make the same mesh at once.
    let tmp = dir.join(format!(
        "{rel}.{}.{:?}.partial",
        std::process::id(),
        std::thread::current().id()
    ));
    std::fs::write(&tmp, text).map_err(|e| err(e.to_string()))?;
    std::fs::rename(&tmp, &out).map_err(|e| err(e.to_string()))?;
    Ok(out)
}

/// A triangle mesh: vertices and vertex-index triples.
type MeshData = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// Vertices and triangles of an OBJ file (`v` and `f` lines; polygons fanned; negative indices).
fn read_obj(text: &str) -> Result<MeshData, String> {
    let (mut verts, mut tris) = (Vec::new(), Vec::new());
    for (n, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let v: Vec<f64> = it.take(3).filter_map(|x| x.parse().ok()).collect();
                if v.len() != 3 {
                    return Err(format!("line {}: a vertex needs 3 numbers", n + 1));
                }
                verts.push([v[0], v[1], v[2]]);
            }
            Some("f") => {
                let idx: Result<Vec<usize>, String> = it
                    .map(|tok| {
                        let i: i64 = tok
                            .split('/')
                            .next()
                            .and_then(|x| x.parse().ok())
                            .ok_or_else(|| format!("line {}: bad face index `{tok}`", n + 1))?;
                        let i = if i < 0 { verts.len() as i64 + i } else { i - 1 };
                        usize::try_from(i)
                            .ok()
                            .filter(|&i| i < verts.len())
                            .ok_or_else(|| format!("line {}: face index {tok} out of range", n + 1))
                    })
                    .collect();
                let idx = idx?;
                for k in 1..idx.len().saturating_sub(1) {
                    tris.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok((verts, tris))
}

/// Vertices and triangles of a binary STL file.
fn read_stl(bytes: &[u8]) -> Result<MeshData, String> {
    let n = bytes
        .get(80..84)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .ok_or("shorter than an STL header")?;
    if bytes.len() < 84 + 50 * n {
        return Err(format!(
            "truncated: {n} triangles need {} bytes",
            84 + 50 * n
        ));
    }
    let f =
        |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as f64;
    let (mut verts, mut tris) = (Vec::with_capacity(3 * n), Vec::with_capacity(n));
    for t in 0..n {
        let o = 84 + 50 * t + 12;
        for k in 0..3 {
            let p = o + 12 * k;
            verts.push([f(p), f(p + 4), f(p + 8)]);
        }
        tris.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    Ok((verts, tris))
}

/// LIBERO's arena from the pack's scene XML: `<asset>` children and the `<worldbody>` children
/// (floor, walls, decorations, lights, the scene's own furniture).
#[derive(Debug, Clone, Default)]
pub struct ArenaXml {
    /// `<asset>` children.
    pub assets: String,
    /// `<worldbody>` children.
    pub world: String,
}

/// Reads the scene XML of `arena` as LIBERO's problem class configures it (libero.md §4.1): floor and
/// wall textures from the class's style, the scene's cameras left out (the composer places LIBERO's),
/// the robosuite `table` body left out (the composer builds it as robosuite's `TableArena` does), the
/// body named like the workspace renamed `<name>_arena` (the composer's workspace body carries the
/// regions), and colliding geoms given the environment's collision bits.
pub fn arena_xml(pack: &LiberoPack, arena: crate::scene::Arena) -> Result<ArenaXml, ComposeError> {
    use crate::scene::Arena;
    let (file, floor, wall) = match arena {
        Arena::Tabletop => (
            "libero_tabletop_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::Kitchen => (
            "libero_kitchen_tabletop_base_style.xml",
            "gray_ceramic_tile.png",
            "yellow_linen_wall_texture.png",
        ),
        Arena::LivingRoom => (
            "libero_living_room_tabletop_base_style.xml",
            "seamless_wood_planks_floor.png",
            "light-gray-plaster.png",
        ),
        Arena::Study => (
            "libero_study_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::Floor => (
            "libero_floor_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::CoffeeTable => (
            "libero_coffee_table_base_style.xml",
            "seamless_wood_planks_floor.png",
            "light-gray-plaster.png",
        ),
    };
    let path = pack.assets_dir().join("scenes").join(file);
    let xml_err = |message: String| ComposeError::Xml {
        path: path.clone(),
        message,
    };
    let root = read_element(&path)?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let textures = pack.assets_dir().join("textures");
    let mut out = ArenaXml::default();
    for a in root.children.iter().filter(|c| c.tag == "asset") {
        for c in &a.children {
            let mut c = c.clone();
            let style = match (c.tag.as_str(), c.attr("name")) {
                ("texture", Some("texplane")) => Some(floor),
                ("texture", Some("tex-wall")) => Some(wall),
                _ => None,
            };
            let file = match style {
                Some(f) => Some(textures.join(f)),
                None => c.attr("file").map(|f| dir.join(f)),
            };
            if let Some(abs) = file {
                if !abs.exists() {
                    return Err(xml_err(format!("{} `{}` not found", c.tag, abs.display())));
                }
                c.set("file", abs.display().to_string());
            }
            c.write(&mut out.assets, 1);
        }
    }
    let ws = arena.workspace();
    for w in root.children.iter().filter(|c| c.tag == "worldbody") {
        for c in &w.children {
            if c.tag == "camera" || (c.tag == "body" && c.attr("name") == Some("table")) {
                continue;
            }
            let mut c = c.clone();
            if c.tag == "body" && c.attr("name") == Some(ws) {
                c.set("name", format!("{ws}_arena"));
            }
            arena_collision_bits(&mut c);
            c.write(&mut out.world, 1);
        }
    }
    Ok(out)
}

/// Gives colliding arena geoms the environment's collision bits.
fn arena_collision_bits(e: &mut Element) {
    if e.tag == "geom" {
        let visual_only = e.attr("contype") == Some("0") && e.attr("conaffinity") == Some("0");
        if !visual_only {
            e.set("contype", crate::robot::ENV_CONTYPE.to_string());
            e.set("conaffinity", crate::robot::ENV_CONAFFINITY.to_string());
        }
    }
    for c in &mut e.children {
        arena_collision_bits(c);
    }
}

fn hide_site(e: &mut Element, name: &str) {
    for c in &mut e.children {
        if c.tag == "site" && c.attr("name") == Some(name) {
            let rgba = c.attr("rgba").unwrap_or("0.5 0.5 0.5 1").to_string();
            let mut v: Vec<&str> = rgba.split_whitespace().collect();
            if v.len() == 4 {
                v[3] = "0";
                c.set("rgba", v.join(" "));
            }
        }
        hide_site(c, name);
    }
}

/// Sets contype/conaffinity of colliding geoms and zeroes the mass of non-group-0 geoms.
fn collision_bits(b: &mut Element, movable: bool, under_joint: bool) {
    use crate::assets::bits;
    let under_joint = under_joint || b.children.iter().any(|c| c.tag == "joint");
    for c in &mut b.children {
        match c.tag.as_str() {
            "geom" => {
                let group = c.attr("group").unwrap_or("0").to_string();
                if group != "0" && c.attr("mass").is_none() {
                    c.set("mass", "0".into());
                }
                let visual_only =
                    c.attr("contype") == Some("0") && c.attr("conaffinity") == Some("0");
                if !visual_only {
                    let (t, a) = if movable {
                        (bits::OBJECT_TYPE, bits::OBJECT_AFFINITY)
                    } else if under_joint {
                        (bits::PART_TYPE, bits::FIXTURE_AFFINITY)
                    } else {
                        (bits::FRAME_TYPE, bits::FIXTURE_AFFINITY)
                    };
                    c.set("contype", t.to_string());
                    c.set("conaffinity", a.to_string());
                }
            }
            "body" => collision_bits(c, movable, under_joint),
            _ => {}
        }
    }
}

fn prefix(e: &mut Element, instance: &str) {
    for (k, v) in e.attrs.iter_mut() {
        if NAME_REFS.contains(&k.as_str()) {
            *v = format!("{instance}_{v}");
        }
    }
    for c in &mut e.children {
        prefix(c, instance);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_and_stl_readers_fan_polygons_and_resolve_indices() {
        let (v, t) = read_obj(
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1/1/1 2/2/2 3/3/3 4/4/4\nf -4 -3 -1\n",
        )
        .unwrap();
        assert_eq!(v.len(), 4);
        assert_eq!(t, vec![[0, 1, 2], [0, 2, 3], [0, 1, 3]]);
        assert!(read_obj("v 0 0\n").unwrap_err().contains("line 1"));
        assert!(
            read_obj("v 0 0 0\nf 1 2 3\n")
                .unwrap_err()
                .contains("out of range")
        );
        let mut stl = vec![0u8; 84];
        stl[80] = 1;
        stl.extend(std::iter::repeat_n(0u8, 12));
        for x in [1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] {
            stl.extend(x.to_le_bytes());
        }
        stl.extend([0, 0]);
        let (v, t) = read_stl(&stl).unwrap();
        assert_eq!(v, vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        assert_eq!(t, vec![[0, 1, 2]]);
        assert!(read_stl(&stl[..100]).unwrap_err().contains("truncated"));
    }

    /// With the pack installed: the light robot meshes cut the vertex count several-fold and keep
    /// the mesh's extent to within a clustering cell.
    #[test]
    fn light_robot_meshes_are_smaller_and_keep_their_extent() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let base = pack.robosuite_assets();
        let src = base.join("robots/panda/obj_meshes/link1_vis/link1_vis.obj");
        let light = light_mesh(&pack, &base, &src).unwrap();
        assert_ne!(light, src);
        let read = |p: &Path| read_obj(&std::fs::read_to_string(p).unwrap()).unwrap();
        let ((v0, t0), (v1, t1)) = (read(&src), read(&light));
        assert!(
            t1.len() * 2 < t0.len() && v1.len() * 4 < v0.len(),
            "{} → {}",
            v0.len(),
            v1.len()
        );
        let extent = |v: &[[f64; 3]], d: usize| {
            let lo = v.iter().map(|p| p[d]).fold(f64::INFINITY, f64::min);
            let hi = v.iter().map(|p| p[d]).fold(f64::NEG_INFINITY, f64::max);
            (lo, hi)
        };
        for d in [0, 1, 2] {
            let ((a0, b0), (a1, b1)) = (extent(&v0, d), extent(&v1, d));
            assert!((a0 - a1).abs() < LIGHT_MESH_CELL && (b0 - b1).abs() < LIGHT_MESH_CELL);
        }
        // A second call reuses the file.
        assert_eq!(light_mesh(&pack, &base, &src).unwrap(), light);
    }

    #[test]
    fn defaults_are_inlined_along_the_class_chain() {
        let doc = roxmltree::Document::parse(
            r#"<default><geom rgba="1 0 0 1" group="1"/><default class="col"><geom group="0"/></default></default>"#,
        )
        .unwrap();
        let mut d = Defaults::new();
        collect_defaults(&Element::from_node(doc.root_element()), None, &mut d);
        let doc = roxmltree::Document::parse(r#"<body><geom class="col" size="1"/><geom/></body>"#)
            .unwrap();
        let mut b = Element::from_node(doc.root_element());
        inline_defaults(&mut b, &d, None);
        assert_eq!(b.children[0].attr("group"), Some("0"));
        assert_eq!(b.children[0].attr("rgba"), Some("1 0 0 1"));
        assert_eq!(b.children[0].attr("class"), None);
        assert_eq!(
            b.children[1].attr("group"),
            None,
            "no class, no childclass: MuJoCo's own default"
        );
    }

    /// With the pack installed, every category LIBERO's 130 tasks use composes and loads in
    /// MuJoCo 2.2.2 (two instances of each, one movable, one fixed).
    #[test]
    fn every_category_loads_in_mujoco() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let tasks = super::super::libero_tasks(&pack).unwrap();
        let arena = |c: &str| {
            matches!(
                c,
                "table"
                    | "kitchen_table"
                    | "study_table"
                    | "living_room_table"
                    | "floor"
                    | "coffee_table"
            )
        };
        // (category, movable): objects get a free joint, fixtures are welded.
        let mut cats: Vec<(String, bool)> = tasks
            .iter()
            .flat_map(|t| {
                let objs = t.problem.objects.iter().map(|i| (i.category.clone(), true));
                let fix = t
                    .problem
                    .fixtures
                    .iter()
                    .map(|i| (i.category.clone(), false));
                objs.chain(fix).collect::<Vec<_>>()
            })
            .filter(|(c, _)| !arena(c))
            .collect();
        cats.sort();
        cats.dedup();
        assert!(cats.len() >= 30, "{cats:?}");
        for (c, movable) in &cats {
            let o = LiberoObject::load(&pack, c).unwrap_or_else(|e| panic!("{c}: {e}"));
            let xml = format!(
                "<mujoco><compiler angle=\"radian\" inertiagrouprange=\"0 0\"/><asset>\n{}{}</asset><worldbody><geom type=\"plane\" size=\"3 3 0.1\"/>\n{}{}</worldbody></mujoco>",
                o.asset_xml("a_1"),
                o.asset_xml("b_1"),
                o.body_xml("a_1", [0.0, 0.0, 0.5], [1.0, 0.0, 0.0, 0.0], *movable),
                o.body_xml("b_1", [0.5, 0.0, 0.5], [1.0, 0.0, 0.0, 0.0], false),
            );
            let m = crate::mujoco::Model::from_xml_str(&xml).unwrap_or_else(|e| panic!("{c}: {e}"));
            assert!(
                m.id(crate::mujoco::ObjType::Body, "a_1_main").is_some(),
                "{c}"
            );
            assert_eq!(
                m.id(crate::mujoco::ObjType::Joint, "a_1_joint0").is_some(),
                *movable,
                "{c}"
            );
        }
        let bowl = LiberoObject::load(&pack, "akita_black_bowl").unwrap();
        assert_eq!(bowl.placement.bottom_offset, [0.0, 0.0, -0.06]);
        assert_eq!(bowl.placement.horizontal_radius, 0.025);
    }
}
