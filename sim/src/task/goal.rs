//! The goal tracker: the LIBERO-Mem paper's Algorithm 1 with the reference evaluator's exact semantics
//! (libero-mem-reference.md §1 "Evaluator algorithm", "Partial credit and success", timings).
//!
//! Predicates come from a caller-supplied oracle (`&mut dyn FnMut(&Atom) -> bool`), so this module knows
//! nothing about MuJoCo. Goal shapes it runs:
//! * **plain** LIBERO goals, an atom or `(And atom...)`: one subgoal, the conjunction (goal length 1), no
//!   counters; [`GoalTracker::check`] returns the conjunction, and the first time it holds the subgoal is
//!   recorded as satisfied (LIBERO's own evaluation latches success the same way);
//! * `(Sequence s...)`, each `s` an `(And atom...)` (the reference asserts exactly one atom; we accept
//!   several and treat the conjunction as the subgoal) or a bare atom;
//! * `(Or b...)`, each branch a `Sequence` (or a single subgoal); `(And (Sequence ...))` and
//!   `(And (Or ...))` unwrap as LIBERO's goal packer does.
//!
//! State (`_satisfied_subgoals`, `_sub_goal_live_time`, `_sub_goal_nonlive_time`, `_overshot` upstream):
//! the satisfied list, two counters and the overshoot flag. A **Sequence** node, on each check:
//! 1. returns false if overshot;
//! 2. looks at subgoal `len(satisfied)` (once all are satisfied, at the last one again);
//! 3. if it holds: when complete, resets `nonlive` and returns true; otherwise, when
//!    `live > min_true && nonlive > min_false`, appends it, zeroes both counters and returns true (also
//!    for an intermediate subgoal); otherwise `live += 1` if `inc`;
//! 4. if it does not hold: when complete and `nonlive > overshoot_false`, sets the overshoot flag for
//!    good and returns false; otherwise `nonlive += 1` if `inc`.
//!
//! An **Or** node visits branches in file order, skips a branch unless the atoms already satisfied are a
//! subset of the branch's atoms, and returns true at the first branch whose Sequence returns true. All
//! branches share one satisfied list and one pair of counters, so before a branch is committed one
//! `inc` check can bump the counters once per consistent branch — as upstream. The goal length is the
//! first branch's length even when branches differ (upstream `get_goal_sequence_len()`), so tiered credit
//! follows upstream there too; `done` means the branch that returned true is complete.
//!
//! Timing. Upstream checks every control step three times: twice without `inc` inside `env.step`
//! (`reward()`, where appends normally happen, and `done`), then once with `inc` at the top of the
//! evaluation loop. [`GoalTracker::step`] reproduces that (an `inc = false` check, then an `inc = true`
//! check, on the same predicate values), which gives the measured timings: an append needs at least 16
//! counted "not true" and at least 6 counted "true" steps since the previous append (totals, not
//! streaks) and happens on the next step where the subgoal holds; over-repetition is flagged on the 7th
//! consecutive "not true" step after completion. The step on which a subgoal is appended also counts
//! towards the next subgoal, as upstream.
//!
//! Reset: [`GoalTracker::reset`] clears everything, the overshoot flag included. Upstream's
//! `reset_subgoal_progress()` forgets the flag, so one overshoot there blocks every later episode of a
//! reused env; we treat that as a bug and do not copy it.

use std::collections::{HashMap, HashSet};

use super::bddl::{Atom, Goal, Predicate, Problem, short_words};

/// Debounce thresholds. The comparisons are strict: a subgoal is appended when it holds and
/// `live > min_true && nonlive > min_false`; overshoot when the final subgoal does not hold and
/// `nonlive > overshoot_false`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Debounce {
    /// Counted "true" steps since the previous append must exceed this (upstream 5).
    pub min_true: u32,
    /// Counted "not true" steps since the previous append must exceed this (upstream 15).
    pub min_false: u32,
    /// After completion, counted "not true" steps beyond this set the overshoot flag (upstream 5).
    pub overshoot_false: u32,
}

impl Default for Debounce {
    fn default() -> Debounce {
        Debounce {
            min_true: 5,
            min_false: 15,
            overshoot_false: 5,
        }
    }
}

/// Errors for goal shapes the tracker cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unsupported goal structure: {0}")]
pub struct GoalError(pub String);

/// Progress after one control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// The env's `done`: every subgoal satisfied, the final one holds now, and no overshoot.
    pub done: bool,
    /// A subgoal was appended during this step.
    pub appended: bool,
    /// Number of satisfied subgoals.
    pub satisfied: usize,
    /// Goal length (first `Or` branch, or the `Sequence`, or 1).
    pub goal_len: usize,
    /// Over-repetition after completion (the overshoot flag).
    pub failed: bool,
}

impl Progress {
    /// Tiered credit, `satisfied / goal_len`.
    pub fn tiered(&self) -> f64 {
        self.satisfied as f64 / self.goal_len as f64
    }
}

/// One subgoal: a conjunction of atoms.
type Subgoal = Vec<Atom>;

/// The goal in the shape the evaluator runs.
#[derive(Clone, Debug)]
enum Plan {
    Plain(Subgoal),
    Sequence(Vec<Subgoal>),
    Or(Vec<Vec<Subgoal>>),
}

#[derive(Clone, Debug, Default)]
struct State {
    satisfied: Vec<Subgoal>,
    live: u32,
    nonlive: u32,
    overshot: bool,
    last_done: bool,
}

/// Tracks subgoal progress through an episode. Build one per task, [`reset`](Self::reset) per episode,
/// [`step`](Self::step) once per control step.
#[derive(Clone, Debug)]
pub struct GoalTracker {
    plan: Plan,
    debounce: Debounce,
    namer: Namer,
    state: State,
    satisfied_atoms: Vec<Atom>,
}

impl GoalTracker {
    /// A tracker for `problem.goal` with upstream's thresholds.
    pub fn new(problem: &Problem) -> Result<GoalTracker, GoalError> {
        GoalTracker::with_debounce(problem, Debounce::default())
    }

    /// A tracker with custom thresholds.
    pub fn with_debounce(problem: &Problem, debounce: Debounce) -> Result<GoalTracker, GoalError> {
        Ok(GoalTracker {
            plan: plan(&problem.goal)?,
            debounce,
            namer: Namer::new(problem),
            state: State::default(),
            satisfied_atoms: Vec::new(),
        })
    }

    /// Clears all progress for a new episode: satisfied list, counters, `done` and the overshoot flag.
    pub fn reset(&mut self) {
        self.state = State::default();
        self.satisfied_atoms.clear();
    }

    /// The thresholds in use.
    pub fn debounce(&self) -> Debounce {
        self.debounce
    }

    /// Upstream's `_check_success(inc)`: evaluates the goal once; counters move only when `inc`.
    /// Returns true when the goal is done, and also on the check that appends an intermediate subgoal
    /// (as upstream). Prefer [`step`](Self::step), which runs the checks of one control step.
    pub fn check(&mut self, oracle: &mut dyn FnMut(&Atom) -> bool, inc: bool) -> bool {
        let d = self.debounce;
        let st = &mut self.state;
        // `r` is upstream's return value; `done` additionally requires that the sequence which returned
        // it is complete (an append of an intermediate subgoal also returns true).
        let (r, done) = match &self.plan {
            Plan::Plain(atoms) => {
                let r = conj(atoms, oracle);
                if r && st.satisfied.is_empty() {
                    st.satisfied.push(atoms.clone());
                }
                (r, r)
            }
            Plan::Sequence(seq) => {
                let r = eval_sequence(st, seq, d, oracle, inc);
                (r, r && st.satisfied.len() >= seq.len())
            }
            Plan::Or(branches) => {
                let mut out = (false, false);
                for b in branches {
                    if consistent(&st.satisfied, b) && eval_sequence(st, b, d, oracle, inc) {
                        out = (true, st.satisfied.len() >= b.len());
                        break;
                    }
                }
                out
            }
        };
        if self.satisfied_atoms.len() != st.satisfied.iter().map(Vec::len).sum::<usize>() {
            self.satisfied_atoms = st.satisfied.iter().flatten().cloned().collect();
        }
        st.last_done = done;
        r
    }

    /// One control step, as upstream evaluates it: `env.step`'s checks without `inc` (where appends
    /// happen), then the evaluation loop's `inc = true` check, all on the same predicate values (each atom
    /// is asked of the oracle at most once per step).
    ///
    /// Upstream's schedule, reproduced exactly: after `reset`, `set_init_state` and the 20 settle steps,
    /// call [`reset`](Self::reset), then `step` once on that first state, then `step` after every
    /// `env.step`. (The first call only counts, since nothing can be appended with zeroed counters.)
    pub fn step(&mut self, oracle: &mut dyn FnMut(&Atom) -> bool) -> Progress {
        let before = self.state.satisfied.len();
        let mut cache: Vec<(Atom, bool)> = Vec::new();
        let mut memo = |a: &Atom| -> bool {
            if let Some((_, v)) = cache.iter().find(|(k, _)| k == a) {
                return *v;
            }
            let v = oracle(a);
            cache.push((a.clone(), v));
            v
        };
        self.check(&mut memo, false);
        self.check(&mut memo, true);
        Progress {
            done: self.state.last_done,
            appended: self.state.satisfied.len() > before,
            satisfied: self.state.satisfied.len(),
            goal_len: self.goal_len(),
            failed: self.state.overshot,
        }
    }

    /// Atoms of the satisfied subgoals, in the order they were satisfied (one atom per subgoal for the
    /// LIBERO-Mem tasks).
    pub fn satisfied(&self) -> &[Atom] {
        &self.satisfied_atoms
    }

    /// Number of satisfied subgoals.
    pub fn satisfied_len(&self) -> usize {
        self.state.satisfied.len()
    }

    /// Goal length: the first `Or` branch's length, the `Sequence` length, or 1 for a plain goal
    /// (upstream `get_goal_sequence_len()`).
    pub fn goal_len(&self) -> usize {
        match &self.plan {
            Plan::Plain(_) => 1,
            Plan::Sequence(s) => s.len(),
            Plan::Or(b) => b[0].len(),
        }
    }

    /// Tiered credit, `satisfied / goal_len`.
    pub fn tiered(&self) -> f64 {
        self.satisfied_len() as f64 / self.goal_len() as f64
    }

    /// The env's `done` from the latest check: all subgoals satisfied and the final one holding, with no
    /// overshoot.
    pub fn done(&self) -> bool {
        self.state.last_done
    }

    /// Every subgoal has been satisfied at some point (tiered credit 1), whether or not it still holds.
    pub fn completed(&self) -> bool {
        self.state.satisfied.len() >= self.goal_len()
    }

    /// Over-repetition after completion (the overshoot flag); stays set until [`reset`](Self::reset).
    pub fn failed(&self) -> bool {
        self.state.overshot
    }

    /// The pending subgoal's atoms: the next subgoal of the Sequence, or of the first `Or` branch
    /// consistent with what is satisfied; `None` once complete.
    pub fn pending(&self) -> Option<&[Atom]> {
        let n = self.state.satisfied.len();
        match &self.plan {
            Plan::Plain(atoms) => (n == 0).then_some(atoms.as_slice()),
            Plan::Sequence(seq) => seq.get(n).map(Vec::as_slice),
            Plan::Or(branches) => branches
                .iter()
                .filter(|b| consistent(&self.state.satisfied, b))
                .find_map(|b| b.get(n))
                .map(Vec::as_slice),
        }
    }

    /// The pending subgoal as text, e.g. `"bowl 1 on plate 3"`.
    pub fn pending_text(&self) -> Option<String> {
        self.pending().map(|s| self.subgoal_text(s))
    }

    /// Satisfied subgoals as upstream's strings, e.g. `["one: bowl 1 on plate 1", "two: ..."]`, keeping
    /// instance numbers as they are (upstream renumbers by first appearance, which makes tasks 9 and 10
    /// print the same strings for different baskets).
    pub fn satisfied_texts(&self) -> Vec<String> {
        self.state
            .satisfied
            .iter()
            .enumerate()
            .map(|(i, s)| format!("{}: {}", ordinal(i + 1), self.subgoal_text(s)))
            .collect()
    }

    /// A subgoal (conjunction) as text, atoms joined by " and ".
    pub fn subgoal_text(&self, atoms: &[Atom]) -> String {
        atoms
            .iter()
            .map(|a| self.namer.atom(a))
            .collect::<Vec<_>>()
            .join(" and ")
    }

    /// One atom as text, e.g. `"cream cheese 1 in basket 2"`, `"basket 1 in center"`, `"open cabinet 1 middle"`.
    pub fn atom_text(&self, atom: &Atom) -> String {
        self.namer.atom(atom)
    }
}

/// Evaluates every atom (no short circuit, as upstream) and returns their conjunction.
fn conj(atoms: &[Atom], oracle: &mut dyn FnMut(&Atom) -> bool) -> bool {
    atoms.iter().fold(true, |acc, a| {
        let v = oracle(a);
        acc && v
    })
}

/// Upstream's `is_subgoal_trajectory_possible`: satisfied atoms ⊆ branch atoms, as sets.
fn consistent(satisfied: &[Subgoal], branch: &[Subgoal]) -> bool {
    let b: HashSet<&Atom> = branch.iter().flatten().collect();
    satisfied.iter().flatten().all(|a| b.contains(a))
}

/// The Sequence node (see the module docs for the rules).
fn eval_sequence(
    st: &mut State,
    seq: &[Subgoal],
    d: Debounce,
    oracle: &mut dyn FnMut(&Atom) -> bool,
    inc: bool,
) -> bool {
    if st.overshot {
        return false;
    }
    let n = seq.len();
    let complete = st.satisfied.len() >= n;
    let sub = &seq[st.satisfied.len().min(n - 1)];
    if conj(sub, oracle) {
        if complete {
            st.nonlive = 0;
            return true;
        }
        if st.live > d.min_true && st.nonlive > d.min_false {
            st.live = 0;
            st.nonlive = 0;
            st.satisfied.push(sub.clone());
            return true;
        }
        if inc {
            st.live += 1;
        }
    } else {
        if complete && st.nonlive > d.overshoot_false {
            st.overshot = true;
            return false;
        }
        if inc {
            st.nonlive += 1;
        }
    }
    false
}

fn plan(goal: &Goal) -> Result<Plan, GoalError> {
    match goal {
        Goal::Atom(a) => Ok(Plan::Plain(vec![a.clone()])),
        Goal::And(v) if v.iter().all(|g| matches!(g, Goal::Atom(_))) => {
            if v.is_empty() {
                return Err(GoalError("empty `(And)`".into()));
            }
            Ok(Plan::Plain(atoms_of(v)))
        }
        // LIBERO unpacks the top-level And; a single Sequence/Or inside it is the goal.
        Goal::And(v) if v.len() == 1 => plan(&v[0]),
        Goal::And(_) => Err(GoalError(
            "a top-level `And` may hold atoms, or one `Sequence`/`Or`".into(),
        )),
        Goal::Sequence(v) => Ok(Plan::Sequence(sequence(v)?)),
        Goal::Or(branches) => {
            if branches.is_empty() {
                return Err(GoalError("empty `(Or)`".into()));
            }
            let b = branches
                .iter()
                .map(|g| match g {
                    Goal::Sequence(v) => sequence(v),
                    g => Ok(vec![subgoal(g)?]),
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(Plan::Or(b))
        }
    }
}

fn atoms_of(v: &[Goal]) -> Vec<Atom> {
    v.iter()
        .filter_map(|g| match g {
            Goal::Atom(a) => Some(a.clone()),
            _ => None,
        })
        .collect()
}

fn sequence(v: &[Goal]) -> Result<Vec<Subgoal>, GoalError> {
    if v.is_empty() {
        return Err(GoalError("empty `(Sequence)`".into()));
    }
    v.iter().map(subgoal).collect()
}

fn subgoal(g: &Goal) -> Result<Subgoal, GoalError> {
    match g {
        Goal::Atom(a) => Ok(vec![a.clone()]),
        Goal::And(v) if !v.is_empty() && v.iter().all(|g| matches!(g, Goal::Atom(_))) => {
            Ok(atoms_of(v))
        }
        _ => Err(GoalError(
            "a subgoal must be an atom or `(And atom...)`".into(),
        )),
    }
}

/// Ordinals as upstream writes them ("one" … "ten"), extended past ten.
fn ordinal(n: usize) -> String {
    const ONES: [&str; 20] = [
        "zero",
        "one",
        "two",
        "three",
        "four",
        "five",
        "six",
        "seven",
        "eight",
        "nine",
        "ten",
        "eleven",
        "twelve",
        "thirteen",
        "fourteen",
        "fifteen",
        "sixteen",
        "seventeen",
        "eighteen",
        "nineteen",
    ];
    const TENS: [&str; 10] = [
        "", "", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety",
    ];
    match n {
        0..20 => ONES[n].to_string(),
        20..100 if n.is_multiple_of(10) => TENS[n / 10].to_string(),
        20..100 => format!("{}-{}", TENS[n / 10], ONES[n % 10]),
        _ => n.to_string(),
    }
}

/// Turns instance names and region keys into short words.
#[derive(Clone, Debug)]
struct Namer {
    categories: HashMap<String, String>,
    regions: HashMap<String, (String, String)>,
    workspaces: HashSet<String>,
}

impl Namer {
    fn new(p: &Problem) -> Namer {
        let workspaces = p
            .regions
            .iter()
            .map(|r| r.target.clone())
            .chain(p.instances().map(|i| i.name.clone()))
            .filter(|n| p.is_workspace(n))
            .collect();
        Namer {
            categories: p
                .instances()
                .map(|i| (i.name.clone(), i.category.clone()))
                .collect(),
            regions: p
                .regions
                .iter()
                .map(|r| (r.key(), (r.target.clone(), r.name.clone())))
                .collect(),
            workspaces,
        }
    }

    fn is_workspace_region(&self, key: &str) -> bool {
        self.regions
            .get(key)
            .is_some_and(|(t, _)| self.workspaces.contains(t))
    }

    fn entity(&self, name: &str) -> String {
        if let Some(cat) = self.categories.get(name) {
            if let Some(rest) = name
                .strip_prefix(cat.as_str())
                .and_then(|r| r.strip_prefix('_'))
            {
                return format!("{} {}", short_words(cat), rest.replace('_', " "));
            }
            return name.replace('_', " ");
        }
        if let Some((target, rname)) = self.regions.get(name) {
            if self.workspaces.contains(target) {
                return rname
                    .strip_prefix("the_")
                    .unwrap_or(rname)
                    .replace('_', " ");
            }
            let t = self.entity(target);
            return match rname.as_str() {
                "contain_region" | "cook_region" => t,
                r => format!(
                    "{t} {}",
                    r.strip_suffix("_region").unwrap_or(r).replace('_', " ")
                ),
            };
        }
        name.replace('_', " ")
    }

    fn atom(&self, a: &Atom) -> String {
        let e: Vec<String> = a.args.iter().map(|x| self.entity(x)).collect();
        let p = a.predicate;
        let words = |prefix: &str, suffix: &str| match e.as_slice() {
            [x] => Some(format!("{prefix}{x}{suffix}")),
            _ => None,
        };
        let text = match p {
            Predicate::On | Predicate::In => match e.as_slice() {
                [x, y] if p == Predicate::On && self.is_workspace_region(&a.args[1]) => {
                    Some(format!("{x} in {y}"))
                }
                [x, y] => Some(format!("{x} {p} {y}")),
                _ => None,
            },
            Predicate::Open => words("open ", ""),
            Predicate::Close => words("close ", ""),
            Predicate::TurnOn => words("turn on ", ""),
            Predicate::TurnOff => words("turn off ", ""),
            Predicate::Up => words("", " up"),
            Predicate::True | Predicate::False | Predicate::PrintJointState => None,
        };
        text.unwrap_or_else(|| match e.as_slice() {
            [] => p.to_string(),
            e => format!("{p} {}", e.join(" ")),
        })
    }
}
