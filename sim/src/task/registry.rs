//! The shipped tasks (`sim/tasks/**.bddl`, embedded in the binary) and how ids resolve to them.
//!
//! Ids: `libero_mem/t1` … `libero_mem/t10` (aliases `t1` … `t10`) and `libero_goal/<file_stem>`.
//! The object-sequence family of LIBERO-Mem — T1/T3/T5/T6 (bowl back on plate 1) and T2/T4 (bottle back
//! on plate 2) — takes a repetition count: `t3@12` (or [`resolve_with_repeats`]) gives a Sequence of 12
//! copies of the task's subgoal, for temporal-scaling tests beyond ×7. Anything ending in `.bddl`, or an
//! existing file, is loaded as the user's own task.
//!
//! Step budgets (`max_steps`) live here, not in the BDDL: LIBERO-Mem's `TASK_LENGTHS` from upstream
//! `mem_6_run_evaluation_env_pred.py` (200/290/320/370/450/655/480/675/390/390), 300 for libero_goal
//! (OpenVLA's LIBERO-Goal budget), [`USER_MAX_STEPS`] for user files. For a repetition count that is not
//! one of the family's own, the budget is interpolated linearly between the family's budgets and
//! extrapolated beyond the last with the last segment's slope (bowl: 102.5 steps per extra repetition
//! after ×7; bottle: 40 per repetition), rounded up.

use std::fmt;
use std::path::Path;

use super::bddl::{self, Atom, BddlError, Goal, Problem};
use super::goal::{GoalError, GoalTracker};

/// Step budget for a user's own BDDL file.
pub const USER_MAX_STEPS: usize = 600;

/// Which suite a task comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Suite {
    /// The 10 LIBERO-Mem tasks (and their repetition variants).
    LiberoMem,
    /// The 10 LIBERO-Goal tasks.
    LiberoGoal,
    /// LIBERO-Spatial (from the LIBERO asset pack).
    LiberoSpatial,
    /// LIBERO-Object (from the LIBERO asset pack).
    LiberoObject,
    /// LIBERO-10 (LIBERO-Long; from the LIBERO asset pack).
    Libero10,
    /// LIBERO-90 (from the LIBERO asset pack).
    Libero90,
    /// A BDDL file given by path.
    User,
}

impl Suite {
    /// `libero_mem`, `libero_goal` or `user`.
    pub fn as_str(self) -> &'static str {
        match self {
            Suite::LiberoMem => "libero_mem",
            Suite::LiberoGoal => "libero_goal",
            Suite::LiberoSpatial => "libero_spatial",
            Suite::LiberoObject => "libero_object",
            Suite::Libero10 => "libero_10",
            Suite::Libero90 => "libero_90",
            Suite::User => "user",
        }
    }
}

impl Suite {
    /// The LIBERO suite of a folder name (`libero_spatial`, …); `None` for others.
    pub fn libero(name: &str) -> Option<Suite> {
        match name {
            "libero_goal" => Some(Suite::LiberoGoal),
            "libero_spatial" => Some(Suite::LiberoSpatial),
            "libero_object" => Some(Suite::LiberoObject),
            "libero_10" => Some(Suite::Libero10),
            "libero_90" => Some(Suite::Libero90),
            _ => None,
        }
    }

    /// Whether the suite's tasks only exist in LIBERO's asset pack (spatial, object, 10, 90): they
    /// always build from the pack.
    pub fn pack_only(self) -> bool {
        matches!(
            self,
            Suite::LiberoSpatial | Suite::LiberoObject | Suite::Libero10 | Suite::Libero90
        )
    }

    /// OpenVLA's step budget for a LIBERO suite (`run_libero_eval.py`, libero.md §6): spatial 220,
    /// object 280, goal 300, libero_10 520, libero_90 400.
    pub fn libero_budget(self) -> usize {
        match self {
            Suite::LiberoSpatial => 220,
            Suite::LiberoObject => 280,
            Suite::Libero10 => 520,
            Suite::Libero90 => 400,
            _ => 300,
        }
    }
}

impl fmt::Display for Suite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Everything needed to run a task.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskSpec {
    /// Canonical id, e.g. `libero_mem/t3`, `libero_mem/t3@12`, `libero_goal/turn_on_the_stove`, or the
    /// path of a user file.
    pub id: String,
    /// The suite.
    pub suite: Suite,
    /// Upstream task name (its BDDL file stem), e.g.
    /// `KITCHEN_SCENE1_3_lift_the_bowl_and_place_it_back_on_the_plate_3_times`.
    pub name: String,
    /// LIBERO's `task.language`, built from the file name (libero.md §0): underscores to spaces, everything
    /// up to `SCENEk_` dropped. LIBERO-Mem's keep their leading number, e.g. "3 lift the bowl ...".
    pub task_language: String,
    /// The instruction a policy is given: `task_language` without a leading all-digit word, as upstream
    /// `get_libero_env` strips it, e.g. "lift the bowl and place it back on the plate 3 times".
    pub instruction: String,
    /// The BDDL `(:language ...)`, lowercased (what LIBERO stores as `language_instruction`).
    pub bddl_language: String,
    /// The BDDL text.
    pub bddl_text: String,
    /// The parsed BDDL.
    pub problem: Problem,
    /// Step budget for one episode (after the settle steps).
    pub max_steps: usize,
    /// Goal length (number of subgoals; 1 for a plain LIBERO goal).
    pub goal_len: usize,
    /// The repetition count for the object-sequence family (T1–T6), `None` otherwise.
    pub repeats: Option<usize>,
}

impl TaskSpec {
    /// A fresh goal tracker for this task (upstream thresholds).
    pub fn tracker(&self) -> GoalTracker {
        GoalTracker::new(&self.problem).expect("a TaskSpec's goal was checked when it was built")
    }
}

/// Errors from resolving a task.
#[derive(Debug, thiserror::Error)]
pub enum TaskError {
    /// Not a known id nor a `.bddl` path.
    #[error("unknown task `{id}`; known tasks: {}", known.join(", "))]
    UnknownTask {
        /// What was asked for.
        id: String,
        /// Every known id (aliases `t1`…`t10` also work).
        known: Vec<String>,
    },
    /// A user file could not be read.
    #[error("cannot read BDDL file `{path}`: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A BDDL syntax or structure error (`file:line:col: message`).
    #[error(transparent)]
    Bddl(#[from] BddlError),
    /// A task of LIBERO's pack was asked for, but the pack is not usable.
    #[error("task `{id}`: {message}")]
    Pack {
        /// The task.
        id: String,
        /// Why (names the install command when the pack is missing).
        message: String,
    },
    /// A repetition count that cannot be used.
    #[error("task `{id}`: {message}")]
    BadRepeat {
        /// The id as given.
        id: String,
        /// What is wrong and what is expected.
        message: String,
    },
    /// A goal the tracker cannot run.
    #[error("task `{id}`: {source}")]
    Goal {
        /// The task.
        id: String,
        /// Why.
        #[source]
        source: GoalError,
    },
}

/// A repetition family: one subgoal repeated; `budgets` are (count, TASK_LENGTHS) of its shipped tasks.
struct Family {
    budgets: &'static [(usize, usize)],
}

const BOWL: Family = Family {
    budgets: &[(1, 200), (3, 320), (5, 450), (7, 655)],
};
const BOTTLE: Family = Family {
    budgets: &[(1, 290), (3, 370)],
};

struct Shipped {
    short: &'static str,
    suite: Suite,
    name: &'static str,
    text: &'static str,
    max_steps: usize,
    family: Option<(&'static Family, usize)>,
}

macro_rules! mem {
    ($n:literal, $name:literal, $steps:literal, $family:expr) => {
        Shipped {
            short: concat!("t", $n),
            suite: Suite::LiberoMem,
            name: $name,
            text: include_str!(concat!("../../tasks/libero_mem/t", $n, ".bddl")),
            max_steps: $steps,
            family: $family,
        }
    };
}

macro_rules! goal {
    ($stem:literal) => {
        Shipped {
            short: $stem,
            suite: Suite::LiberoGoal,
            name: $stem,
            text: include_str!(concat!("../../tasks/libero_goal/", $stem, ".bddl")),
            max_steps: 300,
            family: None,
        }
    };
}

/// The 20 shipped tasks in benchmark order (libero_mem task order 22, then libero_goal order 0).
static SHIPPED: [Shipped; 20] = [
    mem!(
        "1",
        "KITCHEN_SCENE1_1_pick_up_the_bowl_and_place_it_back_on_the_plate",
        200,
        Some((&BOWL, 1))
    ),
    mem!(
        "2",
        "KITCHEN_SCENE1_2_lift_the_bottle_and_put_it_down_on_the_plate",
        290,
        Some((&BOTTLE, 1))
    ),
    mem!(
        "3",
        "KITCHEN_SCENE1_3_lift_the_bowl_and_place_it_back_on_the_plate_3_times",
        320,
        Some((&BOWL, 3))
    ),
    mem!(
        "4",
        "KITCHEN_SCENE1_4_pick_up_the_bottle_and_put_it_down_the_plate_3_times",
        370,
        Some((&BOTTLE, 3))
    ),
    mem!(
        "5",
        "KITCHEN_SCENE1_5_lift_the_bowl_and_place_it_back_on_the_plate_5_times",
        450,
        Some((&BOWL, 5))
    ),
    mem!(
        "6",
        "KITCHEN_SCENE1_6_pick_up_the_bowl_and_place_it_on_the_plate_7_times",
        655,
        Some((&BOWL, 7))
    ),
    mem!(
        "7",
        "KITCHEN_SCENE1_7_swap_the_2_bowls_on_their_plates_using_the_empty_plate",
        480,
        None
    ),
    mem!(
        "8",
        "KITCHEN_SCENE1_8_rotate_the_3_bowls_on_their_plates_from_left_to_right_using_the_empty_plate",
        675,
        None
    ),
    mem!(
        "9",
        "KITCHEN_SCENE1_9_put_the_cream_cheese_in_the_nearest_basket_and_place_that_basket_in_the_center",
        390,
        None
    ),
    mem!(
        "10",
        "KITCHEN_SCENE1_10_put_the_cream_cheese_in_the_nearest_basket_and_place_the_empty_basket_in_the_center",
        390,
        None
    ),
    goal!("open_the_middle_drawer_of_the_cabinet"),
    goal!("put_the_bowl_on_the_stove"),
    goal!("put_the_wine_bottle_on_top_of_the_cabinet"),
    goal!("open_the_top_drawer_and_put_the_bowl_inside"),
    goal!("put_the_bowl_on_top_of_the_cabinet"),
    goal!("push_the_plate_to_the_front_of_the_stove"),
    goal!("put_the_cream_cheese_in_the_bowl"),
    goal!("turn_on_the_stove"),
    goal!("put_the_bowl_on_the_plate"),
    goal!("put_the_wine_bottle_on_the_rack"),
];

impl Shipped {
    fn id(&self) -> String {
        format!("{}/{}", self.suite, self.short)
    }

    fn path(&self) -> String {
        format!("sim/tasks/{}/{}.bddl", self.suite, self.short)
    }

    fn spec(&self) -> TaskSpec {
        let problem =
            bddl::parse_named(&self.path(), self.text).expect("shipped BDDL files parse (tested)");
        let goal_len = GoalTracker::new(&problem)
            .expect("shipped goals are supported (tested)")
            .goal_len();
        let task_language = language_from_file_stem(self.name);
        TaskSpec {
            id: self.id(),
            suite: self.suite,
            name: self.name.to_string(),
            instruction: strip_leading_number(&task_language),
            task_language,
            bddl_language: problem.language.clone(),
            bddl_text: self.text.to_string(),
            problem,
            max_steps: self.max_steps,
            goal_len,
            repeats: self.family.map(|(_, n)| n),
        }
    }

    /// This family task with `n` repetitions of its subgoal.
    fn repeated(&self, n: usize) -> TaskSpec {
        let (family, native) = self.family.expect("only called for family tasks");
        let base = self.spec();
        if n == native {
            return base;
        }
        let Goal::Sequence(subgoals) = &base.problem.goal else {
            unreachable!("family tasks are Sequences (tested)")
        };
        let mut problem = base.problem.clone();
        problem.goal = Goal::Sequence(vec![subgoals[0].clone(); n]);
        let stem = base
            .bddl_language
            .strip_suffix(&format!(" {native} times"))
            .unwrap_or(&base.bddl_language);
        let language = if n == 1 {
            stem.to_string()
        } else {
            format!("{stem} {n} times")
        };
        problem.language = language.clone();
        problem.language_raw = language.clone();
        let number = self.short.trim_start_matches('t');
        let name = format!("KITCHEN_SCENE1_{number}_{}", language.replace(' ', "_"));
        TaskSpec {
            id: format!("{}@{n}", self.id()),
            suite: self.suite,
            name,
            task_language: format!("{number} {language}"),
            instruction: language.clone(),
            bddl_language: language,
            bddl_text: bddl::print(&problem),
            problem,
            max_steps: family_budget(family, n),
            goal_len: n,
            repeats: Some(n),
        }
    }
}

/// Piecewise-linear budget through the family's (count, steps) points, extrapolated with the last
/// segment's slope, rounded up.
fn family_budget(f: &Family, n: usize) -> usize {
    let pts = f.budgets;
    let seg = pts
        .windows(2)
        .find(|w| n <= w[1].0)
        .unwrap_or(&pts[pts.len() - 2..]);
    let ((x0, y0), (x1, y1)) = (seg[0], seg[1]);
    let slope = (y1 as f64 - y0 as f64) / (x1 as f64 - x0 as f64);
    (y0 as f64 + slope * (n as f64 - x0 as f64)).ceil() as usize
}

/// LIBERO's `task.language` from a BDDL file stem (`grab_language_from_filename`): for names that start
/// with a capital letter, everything up to and including `SCENE<k>_` is dropped; underscores become spaces.
pub fn language_from_file_stem(stem: &str) -> String {
    let mut rest = stem;
    if stem.starts_with(|c: char| c.is_ascii_uppercase())
        && let Some(i) = stem.find("SCENE")
    {
        let after = stem[i + 5..].trim_start_matches(|c: char| c.is_ascii_digit());
        rest = after.strip_prefix('_').unwrap_or(after);
    }
    rest.split('_')
        .filter(|w| !w.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Drops a leading all-digit word, as upstream `get_libero_env` does for LIBERO-Mem task names.
pub fn strip_leading_number(language: &str) -> String {
    match language.split_once(' ') {
        Some((first, rest)) if first.chars().all(|c| c.is_ascii_digit()) => rest.to_string(),
        _ => language.to_string(),
    }
}

/// The 20 shipped tasks in benchmark order: `libero_mem/t1` … `t10`, then the libero_goal tasks.
pub fn list() -> Vec<TaskSpec> {
    SHIPPED.iter().map(Shipped::spec).collect()
}

/// Every known id, in benchmark order.
pub fn known_ids() -> Vec<String> {
    SHIPPED.iter().map(Shipped::id).collect()
}

fn find(id: &str) -> Option<&'static Shipped> {
    let id = id.to_lowercase();
    SHIPPED
        .iter()
        .find(|s| s.id() == id || (s.suite == Suite::LiberoMem && s.short == id))
}

/// Resolves an id (`t3`, `libero_mem/t3`, `t3@12`, `libero_goal/turn_on_the_stove`) or a path to a user's
/// `.bddl` file.
pub fn resolve(id_or_path: &str) -> Result<TaskSpec, TaskError> {
    let s = id_or_path.trim();
    if let Some(t) = find(s) {
        return Ok(t.spec());
    }
    if let Some((base, count)) = s.rsplit_once('@')
        && let Some(t) = find(base)
    {
        let n = count.parse::<usize>().map_err(|_| TaskError::BadRepeat {
            id: s.to_string(),
            message: format!(
                "bad repetition count `{count}`: expected a whole number ≥ 1, as in `t3@12`"
            ),
        })?;
        return with_repeats(t, s, n);
    }
    if s.ends_with(".bddl") || Path::new(s).is_file() {
        return load_user(s);
    }
    if let Some((suite, stem)) = s.split_once('/')
        && let Some(suite) = Suite::libero(suite)
        && suite != Suite::LiberoGoal
    {
        return load_pack_task(suite, stem, s);
    }
    Err(TaskError::UnknownTask {
        id: s.to_string(),
        known: known_ids(),
    })
}

/// Resolves a family task (T1–T6) with `n` repetitions of its subgoal; `n` equal to the task's own count
/// gives the shipped task.
pub fn resolve_with_repeats(id: &str, n: usize) -> Result<TaskSpec, TaskError> {
    let t = find(id.trim()).ok_or_else(|| TaskError::UnknownTask {
        id: id.trim().to_string(),
        known: known_ids(),
    })?;
    with_repeats(t, id.trim(), n)
}

fn with_repeats(t: &Shipped, asked: &str, n: usize) -> Result<TaskSpec, TaskError> {
    if t.family.is_none() {
        return Err(TaskError::BadRepeat {
            id: asked.to_string(),
            message: format!(
                "`{}` takes no repetition count; only the object-sequence family t1–t6 does (e.g. `t3@12`)",
                t.id()
            ),
        });
    }
    if n == 0 {
        return Err(TaskError::BadRepeat {
            id: asked.to_string(),
            message: "repetition count 0: expected a whole number ≥ 1".to_string(),
        });
    }
    Ok(t.repeated(n))
}

/// A task of LIBERO's pack (`libero_spatial/<stem>`, …): its BDDL from the installed pack, LIBERO's
/// plain `And` goal, OpenVLA's step budget for the suite.
fn load_pack_task(suite: Suite, stem: &str, asked: &str) -> Result<TaskSpec, TaskError> {
    let pack = crate::cache::LiberoPack::locate_default().map_err(|e| TaskError::Pack {
        id: asked.to_string(),
        message: e.to_string(),
    })?;
    let path = pack
        .bddl_dir()
        .join(suite.as_str())
        .join(format!("{stem}.bddl"));
    if !path.is_file() {
        return Err(TaskError::Pack {
            id: asked.to_string(),
            message: format!(
                "no task `{stem}` in {}; `sim assets tasks` lists the 130 LIBERO tasks",
                suite.as_str()
            ),
        });
    }
    let (text, problem) = read_bddl(&path)?;
    let goal_len = checked_goal_len(&problem, asked)?;
    let task_language = language_from_file_stem(stem);
    Ok(TaskSpec {
        id: format!("{}/{stem}", suite.as_str()),
        suite,
        name: stem.to_string(),
        instruction: task_language.clone(),
        task_language,
        bddl_language: problem.language.clone(),
        bddl_text: text,
        problem,
        max_steps: suite.libero_budget(),
        goal_len,
        repeats: None,
    })
}

/// Reads and parses a BDDL file; errors name the file (and, for parse errors, the line).
pub(crate) fn read_bddl(path: &Path) -> Result<(String, Problem), TaskError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| TaskError::Io {
        path: name.clone(),
        source,
    })?;
    let problem = bddl::parse_named(&name, &text)?;
    bddl::check_scene(&name, &problem)?;
    Ok((text, problem))
}

/// The goal length of a parsed task, checking that the goal tracker accepts its goal.
fn checked_goal_len(problem: &Problem, id: &str) -> Result<usize, TaskError> {
    Ok(GoalTracker::new(problem)
        .map_err(|source| TaskError::Goal {
            id: id.to_string(),
            source,
        })?
        .goal_len())
}

/// Loads a user's BDDL file.
fn load_user(path: &str) -> Result<TaskSpec, TaskError> {
    let (text, problem) = read_bddl(Path::new(path))?;
    let goal_len = checked_goal_len(&problem, path)?;
    let stem = Path::new(path)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(path)
        .to_string();
    let task_language = language_from_file_stem(&stem);
    Ok(TaskSpec {
        id: path.to_string(),
        suite: Suite::User,
        instruction: strip_leading_number(&task_language),
        task_language,
        name: stem,
        bddl_language: problem.language.clone(),
        bddl_text: text,
        problem,
        max_steps: USER_MAX_STEPS,
        goal_len,
        repeats: None,
    })
}

/// The subgoal atom a family task repeats (`On akita_black_bowl_1 plate_1` or `On wine_bottle_1 plate_2`).
pub fn family_subgoal(spec: &TaskSpec) -> Option<Atom> {
    spec.repeats?;
    spec.problem.goal.atoms().first().map(|a| (*a).clone())
}
