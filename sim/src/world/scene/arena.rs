//! The arenas of LIBERO's problem classes: workspace, surface height, robot base, cameras.

use super::error::SceneError;
use crate::world::robot::BASE_POS;

/// Arena (LIBERO problem class, libero.md §4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arena {
    /// `LIBERO_Tabletop_Manipulation`: `main_table`, friction 0.6, TargetZones at z 0.895.
    Tabletop,
    /// `LIBERO_Kitchen_Tabletop_Manipulation`: `kitchen_table`, friction 1.0, TargetZones at z 0.875.
    Kitchen,
    /// `LIBERO_Living_Room_Tabletop_Manipulation`: `living_room_table` (top at 0.41), robot on the ground.
    LivingRoom,
    /// `LIBERO_Study_Tabletop_Manipulation`: `study_table`, workspace offset (−0.2, 0, 0.867).
    Study,
    /// `LIBERO_Floor_Manipulation`: objects on the `floor`, robot on the ground.
    Floor,
    /// `LIBERO_Coffee_Table_Manipulation`: `coffee_table` (top at 0.41), robot on the ground.
    CoffeeTable,
}

impl Arena {
    /// The arena of a (lowercase) BDDL problem class.
    pub fn from_class(class: &str) -> Result<Arena, SceneError> {
        match class {
            "libero_tabletop_manipulation" => Ok(Arena::Tabletop),
            "libero_kitchen_tabletop_manipulation" => Ok(Arena::Kitchen),
            "libero_living_room_tabletop_manipulation" => Ok(Arena::LivingRoom),
            "libero_study_tabletop_manipulation" => Ok(Arena::Study),
            "libero_floor_manipulation" => Ok(Arena::Floor),
            "libero_coffee_table_manipulation" => Ok(Arena::CoffeeTable),
            other => Err(SceneError::ProblemClass(other.to_string())),
        }
    }

    /// Name of the workspace instance.
    pub fn workspace(self) -> &'static str {
        match self {
            Arena::Tabletop => "main_table",
            Arena::Kitchen => "kitchen_table",
            Arena::LivingRoom => "living_room_table",
            Arena::Study => "study_table",
            Arena::Floor => "floor",
            Arena::CoffeeTable => "coffee_table",
        }
    }

    /// LIBERO's `workspace_offset`: the reference that region rectangles are relative to; its z is
    /// the height of the working surface.
    pub fn workspace_offset(self) -> [f64; 3] {
        match self {
            Arena::Tabletop | Arena::Kitchen => [0.0, 0.0, TABLE_TOP],
            Arena::LivingRoom | Arena::CoffeeTable => [0.0, 0.0, 0.41],
            Arena::Study => [-0.2, 0.0, 0.867],
            Arena::Floor => [0.0, 0.0, 0.0],
        }
    }

    /// Height of the working surface objects stand on.
    pub fn surface_z(self) -> f64 {
        self.workspace_offset()[2]
    }

    /// LIBERO's fixture `z_offset` (0.01 − table thickness; −0.025 on the floor).
    pub(super) fn fixture_z_offset(self) -> f64 {
        match self {
            Arena::Tabletop | Arena::Kitchen | Arena::Study => -0.04,
            Arena::LivingRoom | Arena::CoffeeTable => -0.014,
            Arena::Floor => -0.025,
        }
    }

    /// World z of the TargetZone sites' centres.
    pub(super) fn target_zone_z(self) -> f64 {
        match self {
            Arena::Tabletop => 0.895,
            Arena::Kitchen => 0.875,
            other => other.surface_z() - 0.005,
        }
    }

    /// Friction of the working surface.
    pub(super) fn friction(self) -> &'static str {
        match self {
            Arena::Tabletop => "0.6 0.005 0.0001",
            Arena::Kitchen => "1 0.005 0.0001",
            _ => "0.95 0.3 0.1",
        }
    }

    /// World position of the robot's root (`MountedPanda` on the tables, `OnTheGroundPanda` in the
    /// living room, on the coffee table and on the floor; robosuite's `base_xpos_offset`).
    pub fn robot_base(self) -> [f64; 3] {
        match self {
            Arena::Tabletop | Arena::Kitchen => BASE_POS,
            Arena::Study => [-0.25 - 0.5, 0.0, BASE_POS[2]],
            Arena::LivingRoom => [-0.16 - 0.35, 0.0, 0.42],
            Arena::CoffeeTable => [-0.16 - 0.35, 0.0, 0.41],
            Arena::Floor => [-0.6, 0.0, 0.0],
        }
    }

    /// The working surface as a box: (centre, half sizes), `None` on the floor.
    pub(super) fn table_box(self) -> Option<([f64; 3], [f64; 3])> {
        let top = self.surface_z();
        let off = self.workspace_offset();
        match self {
            Arena::Tabletop | Arena::Kitchen | Arena::Study => {
                Some(([off[0], off[1], top - 0.025], [0.5, 0.6, 0.025]))
            }
            Arena::LivingRoom => Some(([off[0], off[1], top - 0.012], [0.35, 0.8, 0.012])),
            Arena::CoffeeTable => Some(([off[0], off[1], top - 0.012], [0.35, 0.6, 0.012])),
            Arena::Floor => None,
        }
    }

    /// Position of the workspace body (the table's centre; the origin for the floor).
    pub(super) fn workspace_body_pos(self) -> [f64; 3] {
        match self.table_box() {
            Some((c, _)) => c,
            None => [0.0, 0.0, 0.0],
        }
    }

    /// The `agentview` camera: (pos, quat wxyz), as each problem class sets it.
    pub(super) fn agentview(self) -> ([f64; 3], [f64; 4]) {
        const TABLE_Q: [f64; 4] = [
            0.6380177736282349,
            0.3048497438430786,
            0.30484986305236816,
            0.6380177736282349,
        ];
        const LOW_Q: [f64; 4] = [
            0.6182166934013367,
            0.3432307541370392,
            0.3432314395904541,
            0.6182177066802979,
        ];
        match self {
            Arena::Tabletop | Arena::Kitchen => {
                ([0.6586131746834771, 0.0, 1.6103500240372423], TABLE_Q)
            }
            Arena::Study => ([0.4586131746834771, 0.0, 1.6103500240372423], TABLE_Q),
            Arena::LivingRoom | Arena::CoffeeTable => ([0.6065773716836134, 0.0, 0.96], LOW_Q),
            Arena::Floor => ([0.8965773716836134, 5.216182733499864e-07, 0.65], LOW_Q),
        }
    }
}

/// Height of the table top (tabletop and kitchen arenas).
pub const TABLE_TOP: f64 = 0.90;
