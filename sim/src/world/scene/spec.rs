//! What the composer needs from a task: regions, instances and init atoms ([`SceneSpec`]), taken
//! from a parsed BDDL problem.

use crate::task::Predicate;

/// A region declared in the task (`(:regions (name (:target t) …))`).
#[derive(Debug, Clone, PartialEq)]
pub struct RegionSpec {
    /// Region name as written (`plate_region`).
    pub name: String,
    /// Target entity (`main_table`, `basket_1`).
    pub target: String,
    /// Rectangles `x0 y0 x1 y1`, relative to the workspace reference.
    pub ranges: Vec<[f64; 4]>,
    /// Yaw range (last pair in the file).
    pub yaw: [f64; 2],
    /// Colour (alpha 0 = invisible).
    pub rgba: [f64; 4],
}

impl RegionSpec {
    /// `<target>_<name>`, the key BDDL atoms use.
    pub fn key(&self) -> String {
        format!("{}_{}", self.target, self.name)
    }
}

/// A named instance of a category.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstanceSpec {
    /// Instance name (`plate_1`).
    pub name: String,
    /// Category (`plate`).
    pub category: String,
}

/// A ground atom `(pred arg…)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AtomSpec {
    /// The predicate.
    pub predicate: Predicate,
    /// Arguments: instance names or region keys.
    pub args: Vec<String>,
}

impl std::fmt::Display for AtomSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.predicate)?;
        for a in &self.args {
            write!(f, " {a}")?;
        }
        Ok(())
    }
}

/// What the composer needs from a task description.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// BDDL problem class, lowercase.
    pub problem_class: String,
    /// Regions in file order.
    pub regions: Vec<RegionSpec>,
    /// Fixtures in file order (the workspace included).
    pub fixtures: Vec<InstanceSpec>,
    /// Movable objects in file order.
    pub objects: Vec<InstanceSpec>,
    /// Initial-state atoms.
    pub init: Vec<AtomSpec>,
}

impl SceneSpec {
    /// The scene part of a parsed BDDL problem.
    pub fn from_problem(p: &crate::task::Problem) -> SceneSpec {
        let inst = |i: &crate::task::Instance| InstanceSpec {
            name: i.name.clone(),
            category: i.category.clone(),
        };
        SceneSpec {
            problem_class: p.problem_class.lowercase_name(),
            regions: p
                .regions
                .iter()
                .map(|r| RegionSpec {
                    name: r.name.clone(),
                    target: r.target.clone(),
                    ranges: r.ranges.clone(),
                    yaw: r.yaw_or_default(),
                    rgba: r.rgba_or_default(),
                })
                .collect(),
            fixtures: p.fixtures.iter().map(inst).collect(),
            objects: p.objects.iter().map(inst).collect(),
            init: p
                .init
                .iter()
                .map(|a| AtomSpec {
                    predicate: a.predicate,
                    args: a.args.clone(),
                })
                .collect(),
        }
    }
}
