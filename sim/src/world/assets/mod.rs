//! The built-in asset library: LIBERO's objects and fixtures rebuilt from primitives.
//!
//! Each asset is sized like LIBERO's (libero.md §3.2: collision AABB, placement offsets, masses) and exposes
//! the same sites under the same names (`contain_region`, `top_side`, `top_region`, `cook_region`, …), so LIBERO's
//! BDDL files work unchanged. Every element name gets the instance prefix (`plate_1_main`, `basket_1_contain_region`)
//! exactly as robosuite does. Two instances of one category differ only in their names: visually identical
//! objects are truly identical, which is the point of the benchmark.
//!
//! Fixtures are mocap bodies (welded to the world, their pose written per episode into `mocap_pos/quat`), so
//! one compiled model serves every reset. Movable objects carry a free joint `<inst>_joint0`.

pub mod bits;
mod build;
mod def;
mod library;

pub use build::{RIGHT_ANGLE, RackShelf, instance_xml, wine_rack_top_shelf, x_quat, yaw_quat};
pub use def::{Articulation, AssetDef, AssetKind, Extent, Handling, SiteDef};
pub use library::{asset, categories};

/// Workspace categories provided by the arena itself (`table` → `main_table`, `kitchen_table`, …).
pub use crate::task::bddl::WORKSPACE_CATEGORIES;

#[cfg(test)]
mod tests {
    use super::library::ASSETS;
    use super::*;
    use crate::engine::mujoco::{Data, Model, ObjType};
    use std::sync::Arc;

    fn world_with(def: &AssetDef, z: f64) -> String {
        format!(
            r#"<mujoco><compiler angle="radian" autolimits="true"/><option timestep="0.002"/>
<worldbody><geom name="floor" type="plane" size="1 1 0.1"/>{}</worldbody></mujoco>"#,
            instance_xml(
                def,
                &format!("{}_1", def.category),
                [0.0, 0.0, z],
                [1.0, 0.0, 0.0, 0.0]
            )
        )
    }

    #[test]
    fn every_asset_compiles_with_its_sites_and_joints() {
        for def in ASSETS {
            let model = Model::from_xml_str(&world_with(def, 0.1))
                .unwrap_or_else(|e| panic!("{}: {e}", def.category));
            let inst = format!("{}_1", def.category);
            assert!(model.id(ObjType::Body, &format!("{inst}_main")).is_some());
            for s in def.sites {
                assert!(
                    model
                        .id(ObjType::Site, &format!("{inst}_{}", s.name))
                        .is_some(),
                    "{inst} lacks {}",
                    s.name
                );
            }
            for (j, _) in def.joints {
                assert!(
                    model.id(ObjType::Joint, &format!("{inst}_{j}")).is_some(),
                    "{inst} lacks joint {j}"
                );
            }
        }
    }

    fn aabb(model: &Arc<Model>, data: &Data, body_root: usize) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::MAX; 3];
        let mut hi = [f64::MIN; 3];
        for g in 0..model.ngeom() {
            if model.body_root(model.geom_body(g)) != body_root {
                continue;
            }
            let r = unsafe { *model.raw().geom_rbound.add(g) };
            let c = data.geom_pos(g);
            for k in 0..3 {
                lo[k] = lo[k].min(c[k] - r);
                hi[k] = hi[k].max(c[k] + r);
            }
        }
        (lo, hi)
    }

    #[test]
    fn movable_objects_are_sized_like_liberos() {
        // Bounding-sphere AABB is a loose upper bound; the footprint checks below use known extents.
        for (cat, w, h) in [
            ("akita_black_bowl", 0.107, 0.052),
            ("plate", 0.138, 0.0164),
            ("basket", 0.170, 0.1457),
            ("wine_bottle", 0.043, 0.158),
        ] {
            let def = asset(cat).unwrap();
            let model = Arc::new(Model::from_xml_str(&world_with(def, 0.0)).unwrap());
            let mut d = Data::new(model.clone()).unwrap();
            d.forward().unwrap();
            let root = model.id(ObjType::Body, &format!("{cat}_1_main")).unwrap();
            let (lo, hi) = aabb(&model, &d, root);
            assert!(hi[0] - lo[0] >= w * 0.95, "{cat} width {}", hi[0] - lo[0]);
            assert!(hi[2] >= h * 0.98, "{cat} top {}", hi[2]);
        }
    }

    #[test]
    fn objects_rest_on_the_floor() {
        for cat in [
            "akita_black_bowl",
            "plate",
            "basket",
            "cream_cheese",
            "wine_bottle",
        ] {
            let def = asset(cat).unwrap();
            let model = Arc::new(Model::from_xml_str(&world_with(def, 0.05)).unwrap());
            let mut d = Data::new(model.clone()).unwrap();
            for _ in 0..500 {
                d.step().unwrap();
            }
            let root = model.id(ObjType::Body, &format!("{cat}_1_main")).unwrap();
            let q = d.body_quat(root);
            assert!(q[0].abs() > 0.99, "{cat} tipped over: {q:?}");
            let v: f64 = d.qvel().iter().map(|x| x.abs()).sum();
            assert!(v < 0.05, "{cat} still moving: {v}");
        }
    }

    #[test]
    fn articulation_thresholds_follow_libero() {
        let d = Articulation::CabinetDrawer;
        assert!(d.is_open(-0.15) && !d.is_open(-0.14) && d.is_close(0.001) && !d.is_close(0.0));
        let k = Articulation::StoveKnob;
        assert!(k.turn_on(0.5) && !k.turn_on(0.49) && k.turn_off(-0.001) && !k.turn_off(0.0));
    }
}
