//! LIBERO's object and fixture XMLs turned into MJCF fragments, as robosuite's `MujocoXMLObject`
//! with LIBERO's wrappers loads them (libero.md §3.1): only the `object` subtree enters the scene,
//! renamed `main`; every name gets the prefix `<instance>_`; the sibling sites `bottom_site`,
//! `top_site` and `horizontal_radius_site` become placement metadata; movable objects get a free joint
//! `<instance>_joint0` (damping 0.0005), fixtures none. Assets (meshes, textures, materials) keep their
//! files by absolute path, repeated names keep the first definition (as robosuite's merge does), and
//! `<default>` classes are inlined into the elements that use them.

pub mod arena;
pub mod error;
pub mod object;
pub mod robot;
mod xml;

pub use arena::{ArenaXml, arena_xml};
pub use error::ComposeError;
pub use object::{LiberoObject, Placement, asset_path, pack_asset_def};
pub use robot::{RobotVisuals, robot_visuals};

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::robot::{LIGHT_MESH_CELL, light_mesh, read_obj, read_stl};
    use super::xml::*;
    use super::*;
    use crate::cache::LiberoPack;

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
            let m = crate::engine::mujoco::Model::from_xml_str(&xml)
                .unwrap_or_else(|e| panic!("{c}: {e}"));
            assert!(
                m.id(crate::engine::mujoco::ObjType::Body, "a_1_main")
                    .is_some(),
                "{c}"
            );
            assert_eq!(
                m.id(crate::engine::mujoco::ObjType::Joint, "a_1_joint0")
                    .is_some(),
                *movable,
                "{c}"
            );
        }
        let bowl = LiberoObject::load(&pack, "akita_black_bowl").unwrap();
        assert_eq!(bowl.placement.bottom_offset, [0.0, 0.0, -0.06]);
        assert_eq!(bowl.placement.horizontal_radius, 0.025);
    }
}
