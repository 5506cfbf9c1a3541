//! The typed form of a BDDL problem: [`Problem`] with its regions, instances, atoms and goal.

use std::fmt;

use super::error::Span;
use super::predicate::Predicate;

/// LIBERO's registered problem classes (libero.md §1.1). The class fixes the arena and its workspace.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ProblemClass {
    /// `LIBERO_Tabletop_Manipulation` (libero_goal, libero_spatial); workspace `main_table`.
    Tabletop,
    /// `LIBERO_Kitchen_Tabletop_Manipulation` (LIBERO-Mem, kitchen scenes); workspace `kitchen_table`.
    KitchenTabletop,
    /// `LIBERO_Living_Room_Tabletop_Manipulation`; workspace `living_room_table`.
    LivingRoomTabletop,
    /// `LIBERO_Study_Tabletop_Manipulation`; workspace `study_table`.
    StudyTabletop,
    /// `LIBERO_Floor_Manipulation` (libero_object); workspace `floor`.
    Floor,
    /// `LIBERO_Coffee_Table_Manipulation`; workspace `coffee_table`.
    CoffeeTable,
}

impl ProblemClass {
    /// Every class, in LIBERO's registration order.
    pub const ALL: [ProblemClass; 6] = [
        ProblemClass::Tabletop,
        ProblemClass::KitchenTabletop,
        ProblemClass::LivingRoomTabletop,
        ProblemClass::StudyTabletop,
        ProblemClass::Floor,
        ProblemClass::CoffeeTable,
    ];

    /// The class name as LIBERO's files spell it, e.g. `LIBERO_Tabletop_Manipulation`.
    pub fn name(self) -> &'static str {
        match self {
            ProblemClass::Tabletop => "LIBERO_Tabletop_Manipulation",
            ProblemClass::KitchenTabletop => "LIBERO_Kitchen_Tabletop_Manipulation",
            ProblemClass::LivingRoomTabletop => "LIBERO_Living_Room_Tabletop_Manipulation",
            ProblemClass::StudyTabletop => "LIBERO_Study_Tabletop_Manipulation",
            ProblemClass::Floor => "LIBERO_Floor_Manipulation",
            ProblemClass::CoffeeTable => "LIBERO_Coffee_Table_Manipulation",
        }
    }

    /// Looks a class up case-insensitively, as LIBERO does.
    pub fn from_name(name: &str) -> Option<ProblemClass> {
        let lower = name.to_lowercase();
        ProblemClass::ALL
            .into_iter()
            .find(|c| c.name().to_lowercase() == lower)
    }

    /// The lowercased name LIBERO matches against, e.g. `libero_tabletop_manipulation`.
    pub fn lowercase_name(self) -> String {
        self.name().to_lowercase()
    }

    /// The workspace fixture whose regions become table sites (`main_table`, `kitchen_table`, …).
    pub fn workspace(self) -> &'static str {
        match self {
            ProblemClass::Tabletop => "main_table",
            ProblemClass::KitchenTabletop => "kitchen_table",
            ProblemClass::LivingRoomTabletop => "living_room_table",
            ProblemClass::StudyTabletop => "study_table",
            ProblemClass::Floor => "floor",
            ProblemClass::CoffeeTable => "coffee_table",
        }
    }
}

impl fmt::Display for ProblemClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One BDDL problem file.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// `(problem <Class>)`.
    pub problem_class: ProblemClass,
    /// `(:domain ...)`; always `robosuite` (the default when the section is absent).
    pub domain: String,
    /// `(:language ...)`, lowercased, words joined by single spaces (LIBERO's `language_instruction`).
    pub language: String,
    /// The same words in their original case (what the file says before LIBERO lowercases it).
    pub language_raw: String,
    /// `(:regions ...)` in file order.
    pub regions: Vec<Region>,
    /// `(:fixtures ...)` in file order (the workspace, e.g. `main_table - table`, included).
    pub fixtures: Vec<Instance>,
    /// `(:objects ...)` in file order (the order fixes the qpos layout, libero.md §4.2).
    pub objects: Vec<Instance>,
    /// `(:obj_of_interest ...)`: instance names or region keys (visualisation only).
    pub obj_of_interest: Vec<String>,
    /// `(:init ...)` ground atoms, in file order.
    pub init: Vec<Atom>,
    /// `(:goal ...)`.
    pub goal: Goal,
}

impl Problem {
    /// The region whose key (`<target>_<name>`) is `key`.
    pub fn region(&self, key: &str) -> Option<&Region> {
        self.regions.iter().find(|r| r.key() == key)
    }

    /// Fixtures then objects.
    pub fn instances(&self) -> impl Iterator<Item = &Instance> {
        self.fixtures.iter().chain(self.objects.iter())
    }

    /// The fixture or object called `name`.
    pub fn instance(&self, name: &str) -> Option<&Instance> {
        self.instances().find(|i| i.name == name)
    }

    /// Whether `name` is the workspace of this problem class or one of the names LIBERO treats as a
    /// workspace (`main_table`, `kitchen_table`, `living_room_table`, `study_table`, `floor`,
    /// `coffee_table`).
    pub fn is_workspace(&self, name: &str) -> bool {
        name == self.problem_class.workspace()
            || ProblemClass::ALL.iter().any(|c| c.workspace() == name)
    }
}

/// A named region (libero.md §1.2): a workspace region (target = the workspace, with rectangles) or an
/// object-attached region (target = an instance; the key must match a site of that instance).
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// The region name as written, e.g. `plate_region`, `contain_region`.
    pub name: String,
    /// `(:target ...)`: the workspace or an instance name.
    pub target: String,
    /// `(:ranges ...)`: rectangles `[x_min, y_min, x_max, y_max]` relative to the workspace centre.
    pub ranges: Vec<[f64; 4]>,
    /// `(:yaw_rotation ...)`: the last `(lo hi)` pair; `None` when absent (LIBERO's default is `[0, 0]`).
    pub yaw_rotation: Option<[f64; 2]>,
    /// `(:rgba ...)`; `None` when absent (LIBERO's default is `0 0 1 0`, invisible).
    pub rgba: Option<[f64; 4]>,
    /// Where the region was declared.
    pub span: Span,
}

impl Region {
    /// The key atoms use to name this region: `<target>_<name>`, e.g. `main_table_plate_region`,
    /// `basket_1_contain_region`.
    pub fn key(&self) -> String {
        format!("{}_{}", self.target, self.name)
    }

    /// The yaw range with LIBERO's default `[0, 0]` when absent.
    pub fn yaw_or_default(&self) -> [f64; 2] {
        self.yaw_rotation.unwrap_or([0.0, 0.0])
    }

    /// The colour with LIBERO's default `0 0 1 0` (invisible) when absent.
    pub fn rgba_or_default(&self) -> [f64; 4] {
        self.rgba.unwrap_or([0.0, 0.0, 1.0, 0.0])
    }
}

/// An instance declared in `:fixtures` or `:objects`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Instance {
    /// Instance name, e.g. `akita_black_bowl_1`.
    pub name: String,
    /// Category (asset class in snake case), e.g. `akita_black_bowl`; `object`/`fixture` when untyped.
    pub category: String,
}

/// A ground atom `(pred arg...)`, e.g. `(On akita_black_bowl_1 plate_1)`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Atom {
    /// The predicate, one of LIBERO's registry.
    pub predicate: Predicate,
    /// Instance names or region keys.
    pub args: Vec<String>,
    /// Where the atom was written.
    pub span: Span,
}

impl Atom {
    /// An atom with no source position; `predicate` is a name of LIBERO's registry in any case
    /// (`on`, `On`, `turnon`, …).
    ///
    /// # Panics
    /// If `predicate` is not in LIBERO's registry.
    pub fn new(predicate: &str, args: &[&str]) -> Atom {
        Atom {
            predicate: Predicate::from_name(&predicate.to_lowercase())
                .unwrap_or_else(|| panic!("unknown predicate `{predicate}`")),
            args: args.iter().map(|a| a.to_string()).collect(),
            span: Span::default(),
        }
    }
}

impl fmt::Display for Atom {
    /// BDDL form with LIBERO's capitalisation, e.g. `(On akita_black_bowl_1 plate_1)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "({}", self.predicate.bddl_name())?;
        for a in &self.args {
            write!(f, " {a}")?;
        }
        f.write_str(")")
    }
}

/// A goal expression.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Goal {
    /// A single atom.
    Atom(Atom),
    /// `(And g...)`: all hold (LIBERO's top-level conjunction, or one LIBERO-Mem subgoal).
    And(Vec<Goal>),
    /// `(Or g...)`: LIBERO-Mem alternatives, usually Sequences.
    Or(Vec<Goal>),
    /// `(Sequence g...)`: LIBERO-Mem subgoals to reach one after another.
    Sequence(Vec<Goal>),
}

impl Goal {
    /// Every atom in the goal, depth first, in file order.
    pub fn atoms(&self) -> Vec<&Atom> {
        let mut out = Vec::new();
        fn walk<'a>(g: &'a Goal, out: &mut Vec<&'a Atom>) {
            match g {
                Goal::Atom(a) => out.push(a),
                Goal::And(v) | Goal::Or(v) | Goal::Sequence(v) => {
                    v.iter().for_each(|g| walk(g, out))
                }
            }
        }
        walk(self, &mut out);
        out
    }
}
