//! The built-in library: one [`AssetDef`] per category, sized like LIBERO's.

use super::build::DRAWER_REGION_HALF;
use super::def::{Articulation, AssetDef, AssetKind, Extent, Handling, SiteDef};
use crate::task::Category;

const YAW_HALF_PI: [f64; 4] = [
    std::f64::consts::FRAC_1_SQRT_2,
    0.0,
    0.0,
    std::f64::consts::FRAC_1_SQRT_2,
];
const YAW_PI: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

pub(super) static ASSETS: &[AssetDef] = &[
    AssetDef {
        category: "akita_black_bowl",
        builtin: Some(Category::AkitaBlackBowl),
        extent: Extent {
            bottom: 0.0,
            top: 0.052,
            radius: 0.054,
            ..Extent::GENERIC
        },
        handling: Handling {
            finger_clearance: Some(0.055),
            site_bottom: 0.002,
            ..Handling::GENERIC
        },
        kind: AssetKind::Movable,
        bottom_offset: -0.06,
        top_offset: 0.04,
        horizontal_radius: 0.025,
        placement_quat: YAW_HALF_PI,
        sites: &[],
        joints: &[],
    },
    AssetDef {
        category: "plate",
        builtin: Some(Category::Plate),
        extent: Extent {
            bottom: 0.0,
            top: 0.0164,
            radius: 0.069,
            ..Extent::GENERIC
        },
        handling: Handling {
            flat: true,
            finger_clearance: None,
            ..Handling::GENERIC
        },
        kind: AssetKind::Movable,
        bottom_offset: -0.06,
        top_offset: 0.04,
        horizontal_radius: 0.025,
        placement_quat: YAW_HALF_PI,
        sites: &[],
        joints: &[],
    },
    AssetDef {
        category: "basket",
        builtin: Some(Category::Basket),
        extent: Extent {
            bottom: 0.0042,
            top: 0.1457,
            radius: 0.116,
            ..Extent::GENERIC
        },
        handling: Handling {
            tall: true,
            finger_clearance: Some(0.09),
            ..Handling::GENERIC
        },
        kind: AssetKind::Movable,
        bottom_offset: -0.06,
        top_offset: 0.04,
        horizontal_radius: 0.025,
        placement_quat: YAW_HALF_PI,
        sites: &[SiteDef {
            name: "contain_region",
            half: [0.06108, 0.06108, 0.06949],
        }],
        joints: &[],
    },
    AssetDef {
        category: "cream_cheese",
        builtin: Some(Category::CreamCheese),
        extent: Extent {
            bottom: -0.009,
            top: 0.009,
            radius: 0.046,
            ..Extent::GENERIC
        },
        handling: Handling {
            finger_clearance: Some(0.04),
            push_clearance: 0.0215,
            carry_height: 0.09,
            site_bottom: -0.009,
            ..Handling::GENERIC
        },
        kind: AssetKind::Movable,
        bottom_offset: -0.025,
        top_offset: 0.025,
        horizontal_radius: 0.03,
        placement_quat: YAW_PI,
        sites: &[],
        joints: &[],
    },
    AssetDef {
        category: "wine_bottle",
        builtin: Some(Category::WineBottle),
        extent: Extent {
            bottom: 0.001,
            top: 0.158,
            radius: 0.022,
            ..Extent::GENERIC
        },
        handling: Handling {
            tall: true,
            finger_clearance: Some(0.025),
            carry_height: 0.10,
            site_bottom: 0.001,
            ..Handling::GENERIC
        },
        kind: AssetKind::Movable,
        bottom_offset: -0.06,
        top_offset: 0.04,
        horizontal_radius: 0.025,
        placement_quat: YAW_PI,
        sites: &[],
        joints: &[],
    },
    AssetDef {
        category: "wine_rack",
        builtin: Some(Category::WineRack),
        extent: Extent {
            footprint: [-0.135, -0.127, 0.135, 0.127],
            ..Extent::GENERIC
        },
        handling: Handling {
            tall: true,
            finger_clearance: Some(0.19),
            hand_clearance: Some(0.19),
            ..Handling::GENERIC
        },
        kind: AssetKind::Fixture,
        bottom_offset: -0.06,
        top_offset: 0.04,
        horizontal_radius: 0.025,
        placement_quat: [1.0, 0.0, 0.0, 0.0],
        sites: &[SiteDef {
            name: "top_region",
            half: [0.10087, 0.022, 0.00251],
        }],
        joints: &[],
    },
    AssetDef {
        category: "flat_stove",
        builtin: Some(Category::FlatStove),
        extent: Extent {
            footprint: [-0.052, -0.095, 0.245, 0.095],
            ..Extent::GENERIC
        },
        handling: Handling {
            tall: true,
            finger_clearance: Some(0.1),
            clearance_centre: [0.1, 0.0, 0.0],
            ..Handling::GENERIC
        },
        kind: AssetKind::Fixture,
        bottom_offset: -0.045,
        top_offset: 0.045,
        horizontal_radius: 0.045,
        placement_quat: [1.0, 0.0, 0.0, 0.0],
        sites: &[SiteDef {
            name: "cook_region",
            half: [0.075, 0.075, 0.0025],
        }],
        joints: &[("button", Articulation::StoveKnob)],
    },
    AssetDef {
        category: "wooden_cabinet",
        builtin: Some(Category::WoodenCabinet),
        extent: Extent {
            // Drawers may open by 0.16 m toward local −y, handles stick out 3 cm more.
            footprint: [-0.128, -0.16, 0.128, 0.127],
            ..Extent::GENERIC
        },
        handling: Handling {
            tall: true,
            // The carcass's front corners (plus handles) reach 0.17 m from its origin; the
            // margin keeps a hand that then carries the bowl past a corner off it.
            finger_clearance: Some(0.23),
            hand_clearance: Some(0.17),
            ..Handling::GENERIC
        },
        kind: AssetKind::Fixture,
        bottom_offset: -0.045,
        top_offset: 0.045,
        horizontal_radius: 0.045,
        placement_quat: [1.0, 0.0, 0.0, 0.0],
        sites: &[
            SiteDef {
                name: "top_side",
                half: [0.12534, 0.09438, 0.00147],
            },
            SiteDef {
                name: "top_region",
                half: DRAWER_REGION_HALF,
            },
            SiteDef {
                name: "middle_region",
                half: DRAWER_REGION_HALF,
            },
            SiteDef {
                name: "bottom_region",
                half: DRAWER_REGION_HALF,
            },
        ],
        joints: &[
            ("top_level", Articulation::CabinetDrawer),
            ("middle_level", Articulation::CabinetDrawer),
            ("bottom_level", Articulation::CabinetDrawer),
        ],
    },
];

/// Looks up a category of the library.
pub fn asset(category: &str) -> Option<&'static AssetDef> {
    ASSETS.iter().find(|a| a.category == category)
}

/// Every category the library provides (objects and fixtures; tables come with the arena).
pub fn categories() -> Vec<&'static str> {
    ASSETS.iter().map(|a| a.category).collect()
}
