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
        let text = std::fs::read_to_string(&path).map_err(|e| xml_err(e.to_string()))?;
        let doc = roxmltree::Document::parse(&text).map_err(|e| xml_err(e.to_string()))?;
        let root = Element::from_node(doc.root_element());
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
        let Ok(pack) = LiberoPack::locate_default() else {
            eprintln!("LIBERO pack not installed; skipping");
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
