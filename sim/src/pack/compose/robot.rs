//! robosuite's Panda visuals from the pack (and their light, vertex-clustered copies) to dress the
//! builtin Panda.

use std::collections::HashMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};

use super::error::ComposeError;
use super::xml::*;
use crate::cache::LiberoPack;

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
pub(super) const LIGHT_MESH_CELL: f64 = 0.008;

/// Meshes with fewer vertices keep their full version.
pub(super) const LIGHT_MESH_MIN_VERTICES: usize = 1000;

/// The light version of a robot visual mesh (OBJ or STL): vertices clustered on a
/// [`LIGHT_MESH_CELL`] grid (each cell's vertices merged to their mean, collapsed triangles
/// dropped), written once as OBJ under `<pack>/lod/` (atomically) and reused. robosuite's Panda
/// visuals are about 318k vertices, which llvmpipe transforms on the CPU for every camera; the light
/// meshes keep the silhouette at a fraction of the cost. Written by hand: vertex clustering is a few
/// lines, and it keeps the build free of a C++ mesh library.
pub(super) fn light_mesh(
    pack: &LiberoPack,
    base: &Path,
    src: &Path,
) -> Result<PathBuf, ComposeError> {
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
    // Atomic (a unique temporary beside it, then a rename): a reader never sees half a file, and
    // two workers making the same mesh at once do not clash.
    data::fsio::write_atomic(&out, text.as_bytes()).map_err(|e| err(e.to_string()))?;
    Ok(out)
}

/// A triangle mesh: vertices and vertex-index triples.
pub(super) type MeshData = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// Vertices and triangles of an OBJ file (`v` and `f` lines; polygons fanned; negative indices).
pub(super) fn read_obj(text: &str) -> Result<MeshData, String> {
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
pub(super) fn read_stl(bytes: &[u8]) -> Result<MeshData, String> {
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
