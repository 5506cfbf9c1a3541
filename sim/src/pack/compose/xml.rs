//! A small XML element tree for LIBERO's MJCF files: reading, `<default>` classes inlined, instance
//! prefixes, collision bits, writing back.

use std::collections::HashMap;
use std::fmt::Write;
use std::path::Path;

use super::error::ComposeError;

/// A parsed element (tag, attributes in document order, children).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Element {
    pub(super) tag: String,
    pub(super) attrs: Vec<(String, String)>,
    pub(super) children: Vec<Element>,
}

impl Element {
    pub(super) fn attr(&self, k: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.as_str())
    }
    pub(super) fn set(&mut self, k: &str, v: String) {
        match self.attrs.iter_mut().find(|(key, _)| key == k) {
            Some(slot) => slot.1 = v,
            None => self.attrs.push((k.to_string(), v)),
        }
    }
    pub(super) fn from_node(n: roxmltree::Node) -> Element {
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
    pub(super) fn write(&self, out: &mut String, depth: usize) {
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
pub(super) fn read_element(path: &Path) -> Result<Element, ComposeError> {
    let xml_err = |message: String| ComposeError::Xml {
        path: path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| xml_err(e.to_string()))?;
    let doc = roxmltree::Document::parse(&text).map_err(|e| xml_err(e.to_string()))?;
    Ok(Element::from_node(doc.root_element()))
}

/// Attributes that name something (and so get the instance prefix).
pub(super) const NAME_REFS: [&str; 6] = ["name", "mesh", "material", "texture", "joint", "site"];

pub(super) fn parse_vec3(s: &str) -> Option<[f64; 3]> {
    let v: Vec<f64> = s
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Default classes: class name → (parent class, tag → attributes).
pub(super) type Defaults =
    HashMap<String, (Option<String>, HashMap<String, Vec<(String, String)>>)>;

pub(super) fn collect_defaults(e: &Element, parent: Option<&str>, out: &mut Defaults) {
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
pub(super) fn inline_defaults(e: &mut Element, defaults: &Defaults, inherited: Option<&str>) {
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

/// Gives colliding arena geoms the environment's collision bits.
pub(super) fn arena_collision_bits(e: &mut Element) {
    if e.tag == "geom" {
        let visual_only = e.attr("contype") == Some("0") && e.attr("conaffinity") == Some("0");
        if !visual_only {
            e.set("contype", crate::world::robot::ENV_CONTYPE.to_string());
            e.set(
                "conaffinity",
                crate::world::robot::ENV_CONAFFINITY.to_string(),
            );
        }
    }
    for c in &mut e.children {
        arena_collision_bits(c);
    }
}

pub(super) fn hide_site(e: &mut Element, name: &str) {
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
pub(super) fn collision_bits(b: &mut Element, movable: bool, under_joint: bool) {
    use crate::world::assets::bits;
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

pub(super) fn prefix(e: &mut Element, instance: &str) {
    for (k, v) in e.attrs.iter_mut() {
        if NAME_REFS.contains(&k.as_str()) {
            *v = format!("{instance}_{v}");
        }
    }
    for c in &mut e.children {
        prefix(c, instance);
    }
}
