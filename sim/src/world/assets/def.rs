//! What an asset is: movable or fixture, its articulations, region sites, true extent and the
//! expert's facts ([`AssetDef`]).

use crate::task::Category;

/// Movable object or fixture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AssetKind {
    /// Free-jointed object.
    Movable,
    /// Welded to the world (a mocap body); may have internal joints.
    Fixture,
}

/// How an articulated joint is judged by the `Open`/`Close`/`TurnOn`/`TurnOff` predicates (libero.md §2.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Articulation {
    /// WoodenCabinet drawers: open iff q < −0.14, closed iff q > 0.
    CabinetDrawer,
    /// FlatStove knob: on iff q ≥ 0.5, off iff q < 0.
    StoveKnob,
    /// Microwave door hinge: open iff q < −1.3, closed iff q > −0.005.
    MicrowaveDoor,
    /// ShortCabinet drawers: open iff q > 0.10, closed iff q < 0.
    ShortCabinetDrawer,
    /// ShortFridge door hinge: open iff q > 2.0, closed iff q < 0.
    FridgeDoor,
}

impl Articulation {
    /// `is_open(q)`.
    pub fn is_open(self, q: f64) -> bool {
        match self {
            Articulation::CabinetDrawer => q < -0.14,
            Articulation::StoveKnob => q >= 0.5,
            Articulation::MicrowaveDoor => q < -1.3,
            Articulation::ShortCabinetDrawer => q > 0.10,
            Articulation::FridgeDoor => q > 2.0,
        }
    }

    /// `is_close(q)`.
    pub fn is_close(self, q: f64) -> bool {
        match self {
            Articulation::CabinetDrawer => q > 0.0,
            Articulation::StoveKnob => q < 0.0,
            Articulation::MicrowaveDoor => q > -0.005,
            Articulation::ShortCabinetDrawer | Articulation::FridgeDoor => q < 0.0,
        }
    }

    /// `turn_on(q)`.
    pub fn turn_on(self, q: f64) -> bool {
        self.is_open(q)
    }

    /// `turn_off(q)`.
    pub fn turn_off(self, q: f64) -> bool {
        self.is_close(q)
    }

    /// Init sampling range for an `Open`/`Turnon` atom.
    pub fn open_range(self) -> [f64; 2] {
        match self {
            Articulation::CabinetDrawer => [-0.16, -0.14],
            Articulation::StoveKnob => [0.5, 2.1],
            Articulation::MicrowaveDoor => [-2.094, -1.3],
            Articulation::ShortCabinetDrawer => [0.10, 0.16],
            Articulation::FridgeDoor => [2.0, 2.7],
        }
    }

    /// Init sampling range for a `Close`/`Turnoff` atom.
    pub fn close_range(self) -> [f64; 2] {
        match self {
            Articulation::CabinetDrawer => [0.0, 0.005],
            Articulation::StoveKnob => [-0.005, 0.0],
            Articulation::MicrowaveDoor => [-0.005, 0.0],
            Articulation::ShortCabinetDrawer | Articulation::FridgeDoor => [-0.005, 0.0],
        }
    }
}

impl Articulation {
    /// The class LIBERO judges `category`'s internal joints by, if it is articulated.
    pub fn of_category(category: &str) -> Option<Articulation> {
        match category {
            "wooden_cabinet" | "white_cabinet" => Some(Articulation::CabinetDrawer),
            "flat_stove" => Some(Articulation::StoveKnob),
            "microwave" => Some(Articulation::MicrowaveDoor),
            "short_cabinet" => Some(Articulation::ShortCabinetDrawer),
            "short_fridge" => Some(Articulation::FridgeDoor),
            _ => None,
        }
    }
}

/// A region site exposed by an asset (its MJCF name before the instance prefix).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteDef {
    /// Region name (`contain_region`, `top_side`, …).
    pub name: &'static str,
    /// Half-sizes of the box site.
    pub half: [f64; 3],
}

/// True geometry of an asset about its origin (not LIBERO's placement metadata): what placement
/// rejects overlaps with and drops objects from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// z of the geometry's lowest point, relative to the origin.
    pub bottom: f64,
    /// z of its highest point.
    pub top: f64,
    /// Radius of the footprint circle about the origin (movable objects).
    pub radius: f64,
    /// Footprint box `[x0, y0, x1, y1]` in the body frame, drawers closed and knob home (fixtures).
    pub footprint: [f64; 4],
}

impl Extent {
    /// What an asset without known geometry (one read from LIBERO's pack) is taken to be.
    pub const GENERIC: Extent = Extent {
        bottom: 0.0,
        top: 0.1,
        radius: 0.05,
        footprint: [-0.05, -0.05, 0.05, 0.05],
    };
}

/// What the scripted expert knows of an asset when it plans around and with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handling {
    /// Stands up from the table, so the hand's box (not only the fingers) can meet it.
    pub tall: bool,
    /// Lies flat (a plate): carried objects and fingers pass over it.
    pub flat: bool,
    /// Radius the fingers keep from it beside a grasp; `None` when they pass over it.
    pub finger_clearance: Option<f64>,
    /// Centre of that circle in the body frame (the stove's burner is off its origin).
    pub clearance_centre: [f64; 3],
    /// Radius a hand held with its finger axis along y keeps from it; `None` when not in the way.
    pub hand_clearance: Option<f64>,
    /// Radius kept around it when a plate is pushed past it.
    pub push_clearance: f64,
    /// Height of its origin above the table top while carried.
    pub carry_height: f64,
    /// Its bottom's height above the origin as the expert sets it on a region site.
    pub site_bottom: f64,
}

impl Handling {
    /// The expert's assumptions for an asset it has no facts for.
    pub const GENERIC: Handling = Handling {
        tall: false,
        flat: false,
        finger_clearance: Some(0.05),
        clearance_centre: [0.0; 3],
        hand_clearance: None,
        push_clearance: 0.055,
        carry_height: 0.115,
        site_bottom: 0.0,
    };
}

/// One asset of the library.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetDef {
    /// BDDL category (`akita_black_bowl`, `wooden_cabinet`, …).
    pub category: &'static str,
    /// The known category (`None` for one read from LIBERO's pack): what skills the expert uses.
    pub builtin: Option<Category>,
    /// True geometry.
    pub extent: Extent,
    /// The expert's facts.
    pub handling: Handling,
    /// Movable or fixture.
    pub kind: AssetKind,
    /// LIBERO's `bottom_offset.z` (placement metadata, not the true geometry).
    pub bottom_offset: f64,
    /// LIBERO's `top_offset.z`.
    pub top_offset: f64,
    /// LIBERO's `horizontal_radius`.
    pub horizontal_radius: f64,
    /// Free-joint quaternion (wxyz) LIBERO's placement sampler writes for this category.
    pub placement_quat: [f64; 4],
    /// Region sites.
    pub sites: &'static [SiteDef],
    /// Internal joints (name without prefix) and their articulation class.
    pub joints: &'static [(&'static str, Articulation)],
}
