//! Goal-tracker traces: each test is a sequence of per-step truth tables (the atoms that hold at that
//! step; every other atom is false), fed through `GoalTracker::step` as the evaluation loop would.

use sim::task::bddl::Atom;
use sim::task::goal::{Debounce, GoalTracker, Progress};
use sim::task::registry;

/// `(On a b)`.
fn on(a: &str, b: &str) -> Atom {
    Atom::new("on", &[a, b])
}

/// `(In a b)`.
fn inn(a: &str, b: &str) -> Atom {
    Atom::new("in", &[a, b])
}

/// A trace under construction: `k` steps with exactly `state` true.
#[derive(Default)]
struct Trace(Vec<Vec<Atom>>);

impl Trace {
    fn hold(mut self, state: &[Atom], k: usize) -> Trace {
        self.0.extend(std::iter::repeat_n(state.to_vec(), k));
        self
    }
}

/// Runs the trace and returns the progress after every step.
fn run(t: &mut GoalTracker, trace: &Trace) -> Vec<Progress> {
    trace
        .0
        .iter()
        .map(|state| t.step(&mut |a: &Atom| state.contains(a)))
        .collect()
}

/// Indices of the steps at which a subgoal was appended.
fn appends(p: &[Progress]) -> Vec<usize> {
    p.iter()
        .enumerate()
        .filter(|(_, p)| p.appended)
        .map(|(i, _)| i)
        .collect()
}

fn tracker(id: &str) -> GoalTracker {
    registry::resolve(id).unwrap().tracker()
}

const B1: &str = "akita_black_bowl_1";
const B2: &str = "akita_black_bowl_2";

#[test]
fn t1_pick_and_place_back() {
    let mut t = tracker("t1");
    assert_eq!(t.goal_len(), 1);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 1"));
    let b1p1 = on(B1, "plate_1");
    // On the plate for 10 steps, lifted for 20, back.
    let trace = Trace::default()
        .hold(std::slice::from_ref(&b1p1), 10)
        .hold(&[], 20)
        .hold(std::slice::from_ref(&b1p1), 5);
    let p = run(&mut t, &trace);
    assert_eq!(appends(&p), [30]);
    assert!(p[..30].iter().all(|p| !p.done && p.satisfied == 0));
    assert!(
        p[30..]
            .iter()
            .all(|p| p.done && !p.failed && p.tiered() == 1.0)
    );
    assert!(t.done() && t.completed() && !t.failed());
    assert_eq!(t.satisfied(), [b1p1]);
    assert_eq!(t.satisfied_texts(), ["one: bowl 1 on plate 1"]);
    assert_eq!(t.pending_text(), None);
}

#[test]
fn t3_three_times_first_append_only_after_more_than_15_steps_away() {
    let mut t = tracker("t3");
    assert_eq!(t.goal_len(), 3);
    let s = [on(B1, "plate_1")];
    // The bowl starts on its target: live builds up but nothing is appended while it stays.
    let mut trace = Trace::default().hold(&s, 40);
    // Away for exactly 15 steps, back: not enough.
    trace = trace.hold(&[], 15).hold(&s, 3);
    // One more step away (16 in total since the last append), back: appended at once.
    trace = trace.hold(&[], 1).hold(&s, 10);
    // Two more cycles.
    trace = trace.hold(&[], 16).hold(&s, 10).hold(&[], 16).hold(&s, 10);
    let p = run(&mut t, &trace);
    assert_eq!(appends(&p), [59, 85, 111]);
    assert_eq!(p[58].satisfied, 0);
    assert!((p[59].tiered() - 1.0 / 3.0).abs() < 1e-12);
    assert!(!p[85].done && p[111].done);
    assert_eq!(
        t.satisfied_texts(),
        [
            "one: bowl 1 on plate 1",
            "two: bowl 1 on plate 1",
            "three: bowl 1 on plate 1"
        ]
    );
    assert!(t.done() && !t.failed());
}

#[test]
fn the_append_step_counts_towards_the_next_subgoal() {
    // After an append at step A (true), A itself is the first counted "true" of the next subgoal
    // (upstream's inc check runs after env.step's appending check), so A + 5 more true steps suffice.
    let s = [on(B1, "plate_1")];
    let base = Trace::default().hold(&s, 6).hold(&[], 16).hold(&s, 1); // append at step 22
    let enough = Trace(base.0.clone()).hold(&s, 5).hold(&[], 16).hold(&s, 1);
    let short = Trace(base.0.clone()).hold(&s, 4).hold(&[], 16).hold(&s, 1);
    assert_eq!(appends(&run(&mut tracker("t3"), &enough)), [22, 44]);
    assert_eq!(appends(&run(&mut tracker("t3"), &short)), [22]);
    // A raw `check(inc = true)` loop does not count the appending step twice: it needs one more.
    let mut t = tracker("t3");
    let mut n = 0;
    for state in &enough.0 {
        if t.check(&mut |a: &Atom| state.contains(a), true) && !t.completed() {
            n = t.satisfied_len();
        }
    }
    assert_eq!(n, 1);
}

#[test]
fn debounce_false_counts_15_vs_16() {
    let s = [on(B1, "plate_1")];
    // 6 true, then exactly 15 false, then true: no append (the true steps only add to live).
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&s, 6).hold(&[], 15).hold(&s, 10),
    );
    assert_eq!(appends(&p), Vec::<usize>::new());
    // 6 true, 16 false, true: appended on that step.
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&s, 6).hold(&[], 16).hold(&s, 1),
    );
    assert_eq!(appends(&p), [22]);
}

#[test]
fn debounce_true_counts_5_vs_6() {
    let s = [on(B1, "plate_1")];
    // 6 counted true before the append step: appended on the first true step after 16 false.
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&s, 6).hold(&[], 16).hold(&s, 2),
    );
    assert_eq!(appends(&p), [22]);
    // Only 5: the first true step after the 16 false becomes the 6th, and the next one appends.
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&s, 5).hold(&[], 16).hold(&s, 2),
    );
    assert_eq!(appends(&p), [22]);
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&s, 5).hold(&[], 16).hold(&s, 1),
    );
    assert_eq!(appends(&p), Vec::<usize>::new());
    // Starting away from the target: 16 false, then the append comes on the 7th true step.
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&[], 16).hold(&s, 7),
    );
    assert_eq!(appends(&p), [22]);
    let p = run(
        &mut tracker("t1"),
        &Trace::default().hold(&[], 16).hold(&s, 6),
    );
    assert_eq!(appends(&p), Vec::<usize>::new());
}

#[test]
fn debounce_counters_are_totals_not_streaks() {
    let s = [on(B1, "plate_1")];
    // Alternate true/false 16 times: 8 true and 8 false, never more than one in a row.
    let mut trace = Trace::default();
    for _ in 0..8 {
        trace = trace.hold(&s, 1).hold(&[], 1);
    }
    // 8 more false (16 false in total, at most 8 in a row), then true: appended.
    trace = trace.hold(&[], 8).hold(&s, 1);
    assert_eq!(appends(&run(&mut tracker("t1"), &trace)), [24]);
}

#[test]
fn debounce_is_configurable() {
    let problem = registry::resolve("t3").unwrap().problem;
    let d = Debounce {
        min_true: 0,
        min_false: 1,
        overshoot_false: 0,
    };
    let mut t = GoalTracker::with_debounce(&problem, d).unwrap();
    assert_eq!(t.debounce(), d);
    let s = [on(B1, "plate_1")];
    // live > 0 and nonlive > 1: one true, two false, true appends.
    let p = run(
        &mut t,
        &Trace::default().hold(&s, 1).hold(&[], 2).hold(&s, 1),
    );
    assert_eq!(appends(&p), [3]);
    assert_eq!(
        Debounce::default(),
        Debounce {
            min_true: 5,
            min_false: 15,
            overshoot_false: 5
        }
    );
}

/// T7's start: bowl 1 on plate 1, bowl 2 on plate 2.
fn t7_trace(moves: &[(&str, &str)]) -> (Trace, Vec<Atom>) {
    let mut where_ = vec![(B1, "plate_1"), (B2, "plate_2")];
    let state = |w: &[(&str, &str)]| w.iter().map(|(b, p)| on(b, p)).collect::<Vec<_>>();
    let mut trace = Trace::default().hold(&state(&where_), 10);
    for (bowl, plate) in moves {
        let others: Vec<_> = where_.iter().filter(|(b, _)| b != bowl).cloned().collect();
        trace = trace.hold(&state(&others), 20);
        where_ = others;
        where_.push((bowl, plate));
        trace = trace.hold(&state(&where_), 10);
    }
    (trace, state(&where_))
}

#[test]
fn t7_swap_via_the_first_branch() {
    let mut t = tracker("t7");
    assert_eq!(t.goal_len(), 3);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 3"));
    let (trace, _) = t7_trace(&[(B1, "plate_3"), (B2, "plate_1"), (B1, "plate_2")]);
    let p = run(&mut t, &trace);
    assert_eq!(appends(&p).len(), 3);
    assert!(p.last().unwrap().done);
    assert_eq!(
        t.satisfied_texts(),
        [
            "one: bowl 1 on plate 3",
            "two: bowl 2 on plate 1",
            "three: bowl 1 on plate 2"
        ]
    );
    assert_eq!(
        t.satisfied(),
        [on(B1, "plate_3"), on(B2, "plate_1"), on(B1, "plate_2")]
    );
}

#[test]
fn t7_swap_via_the_second_branch() {
    let mut t = tracker("t7");
    let (trace, _) = t7_trace(&[(B2, "plate_3"), (B1, "plate_2")]);
    let p = run(&mut t, &trace);
    assert_eq!(appends(&p).len(), 2);
    // Committed to branch 2: its next subgoal is pending.
    assert_eq!(t.pending_text().as_deref(), Some("bowl 2 on plate 1"));
    let (trace, _) = t7_trace(&[(B2, "plate_3"), (B1, "plate_2"), (B2, "plate_1")]);
    let mut t = tracker("t7");
    let p = run(&mut t, &trace);
    assert!(p.last().unwrap().done && t.completed());
    assert_eq!(
        t.satisfied_texts(),
        [
            "one: bowl 2 on plate 3",
            "two: bowl 1 on plate 2",
            "three: bowl 2 on plate 1"
        ]
    );
}

#[test]
fn t7_out_of_order_moves_do_not_count() {
    // Bowl 2 to plate 1 first is no branch's first subgoal: nothing is appended.
    let mut t = tracker("t7");
    let trace = Trace::default()
        .hold(&[on(B2, "plate_1")], 40)
        .hold(&[], 20);
    assert_eq!(appends(&run(&mut t, &trace)), Vec::<usize>::new());
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 3"));
}

#[test]
fn t7_shared_counters_before_a_branch_is_committed() {
    // Before any append both branches are consistent and each bumps the shared counters in one step:
    // 8 steps with both first subgoals false give nonlive = 16.
    let trace = Trace::default().hold(&[], 8).hold(&[on(B1, "plate_3")], 7);
    // True steps: branch 1 adds live, branch 2 (false) still adds nonlive; the 7th true step appends.
    assert_eq!(appends(&run(&mut tracker("t7"), &trace)), [14]);
    let trace = Trace::default().hold(&[], 7).hold(&[on(B1, "plate_3")], 7);
    // nonlive = 14 after the false steps, 15 after the first true one, 16 after the second…
    assert_eq!(appends(&run(&mut tracker("t7"), &trace)), [13]);
}

const CC: &str = "cream_cheese_1";
const CENTER: &str = "kitchen_table_the_center";

fn basket_trace(basket_in: usize, basket_centered: usize) -> Trace {
    let cc_in = inn(CC, &format!("basket_{basket_in}_contain_region"));
    let centered = on(&format!("basket_{basket_centered}"), CENTER);
    Trace::default()
        .hold(&[], 20)
        .hold(std::slice::from_ref(&cc_in), 10)
        .hold(&[], 20)
        .hold(&[cc_in.clone(), centered], 10)
}

#[test]
fn t9_either_basket() {
    for b in [1, 2] {
        let mut t = tracker("t9");
        assert_eq!(
            t.pending_text().as_deref(),
            Some("cream cheese 1 in basket 1")
        );
        let p = run(&mut t, &basket_trace(b, b));
        assert_eq!(appends(&p).len(), 2, "basket {b}");
        assert!(p.last().unwrap().done);
        assert_eq!(
            t.satisfied_texts(),
            [
                format!("one: cream cheese 1 in basket {b}"),
                format!("two: basket {b} in center")
            ]
        );
        // The other basket in the centre does not complete T9.
        let mut t = tracker("t9");
        let p = run(&mut t, &basket_trace(b, 3 - b));
        assert_eq!(appends(&p).len(), 1, "basket {b}");
        assert_eq!(t.pending_text(), Some(format!("basket {b} in center")));
    }
}

#[test]
fn t10_the_empty_basket_goes_to_the_center() {
    for b in [1, 2] {
        let mut t = tracker("t10");
        let p = run(&mut t, &basket_trace(b, 3 - b));
        assert_eq!(appends(&p).len(), 2, "basket {b}");
        assert!(p.last().unwrap().done);
        assert_eq!(
            t.satisfied_texts(),
            [
                format!("one: cream cheese 1 in basket {b}"),
                format!("two: basket {} in center", 3 - b)
            ]
        );
        let mut t = tracker("t10");
        let p = run(&mut t, &basket_trace(b, b));
        assert_eq!(appends(&p).len(), 1);
        assert!(!p.last().unwrap().done);
    }
}

#[test]
fn t8_rotation_pending_texts() {
    let mut t = tracker("t8");
    assert_eq!(t.goal_len(), 4);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 4"));
    let p = run(
        &mut t,
        &Trace::default().hold(&[], 16).hold(&[on(B1, "plate_4")], 7),
    );
    assert_eq!(appends(&p), [22]);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 2 on plate 1"));
}

#[test]
fn over_repetition_fails_on_the_7th_false_step_after_completion() {
    let s = [on(B1, "plate_1")];
    let done = || Trace::default().hold(&s, 6).hold(&[], 16).hold(&s, 3);
    // 6 false steps after completion: not failed (but not done either).
    let mut t = tracker("t1");
    let p = run(&mut t, &done().hold(&[], 6));
    assert!(p[22].done);
    let last = p.last().unwrap();
    assert!(!last.failed && !last.done && last.tiered() == 1.0);
    // Back on the plate: done again, and the false count starts over.
    let p = run(
        &mut t,
        &Trace::default().hold(&s, 1).hold(&[], 6).hold(&s, 1),
    );
    assert!(p.iter().all(|p| !p.failed) && p.last().unwrap().done);
    // The 7th consecutive false step sets the flag, for good.
    let mut t = tracker("t1");
    let p = run(&mut t, &done().hold(&[], 7).hold(&s, 5));
    let n = p.len();
    assert!(!p[n - 7].failed && p[n - 6].failed);
    assert!(
        p[n - 6..]
            .iter()
            .all(|p| p.failed && !p.done && p.tiered() == 1.0)
    );
    assert!(t.failed() && !t.done() && t.completed());
}

#[test]
fn reset_clears_everything_including_the_overshoot_flag() {
    let s = [on(B1, "plate_1")];
    let trace = Trace::default()
        .hold(&s, 6)
        .hold(&[], 16)
        .hold(&s, 3)
        .hold(&[], 10);
    let mut t = tracker("t3");
    let first = run(&mut t, &trace);
    let mut t1 = tracker("t1");
    run(&mut t1, &trace);
    assert!(t1.failed());
    t1.reset();
    assert!(!t1.failed() && !t1.done() && !t1.completed());
    assert_eq!(t1.satisfied_len(), 0);
    assert!(t1.satisfied().is_empty() && t1.satisfied_texts().is_empty());
    assert_eq!(t1.pending_text().as_deref(), Some("bowl 1 on plate 1"));
    // Counters are cleared too: a reset tracker behaves exactly like a fresh one.
    t.reset();
    assert_eq!(run(&mut t, &trace), first);
    let mut fresh = tracker("t1");
    assert_eq!(run(&mut t1, &trace), run(&mut fresh, &trace));
}

#[test]
fn plain_libero_goal_is_one_subgoal() {
    let mut t = tracker("libero_goal/put_the_bowl_on_the_plate");
    assert_eq!(t.goal_len(), 1);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 1"));
    let g = on(B1, "plate_1");
    // No debounce: done on the first step the conjunction holds.
    let p = run(
        &mut t,
        &Trace::default()
            .hold(&[], 3)
            .hold(std::slice::from_ref(&g), 1)
            .hold(&[], 1),
    );
    assert_eq!(appends(&p), [3]);
    assert!(!p[2].done && p[3].done && !p[4].done);
    // Satisfied (tiered credit) latches, as LIBERO's evaluation latches success.
    assert_eq!(p[4].tiered(), 1.0);
    assert!(!p[4].failed);
    assert_eq!(t.satisfied_texts(), ["one: bowl 1 on plate 1"]);
    assert!(t.check(&mut |a: &Atom| *a == g, false));
}

#[test]
fn plain_conjunction_evaluates_every_atom() {
    let text = include_str!("fixtures/bddl/libero_10_kitchen_close_drawer_with_bowl.bddl");
    let problem = sim::task::parse(text).unwrap();
    let mut t = GoalTracker::new(&problem).unwrap();
    assert_eq!(t.goal_len(), 1);
    let close = Atom::new("close", &["white_cabinet_1_bottom_region"]);
    let inside = inn(B1, "white_cabinet_1_bottom_region");
    let mut asked = Vec::new();
    let r = t.check(
        &mut |a: &Atom| {
            asked.push(a.clone());
            false
        },
        true,
    );
    assert!(!r);
    // Both atoms are asked even though the first is already false (no short circuit, as upstream).
    assert_eq!(asked, [close.clone(), inside.clone()]);
    assert!(!t.check(&mut |a: &Atom| *a == close, true));
    assert!(t.check(&mut |a: &Atom| *a == close || *a == inside, true));
    assert_eq!(t.pending_text(), None);
    assert_eq!(
        t.satisfied_texts(),
        ["one: close cabinet 1 bottom and bowl 1 in cabinet 1 bottom"]
    );
}

#[test]
fn step_asks_each_atom_once() {
    let mut t = tracker("t7");
    let mut calls = 0;
    t.step(&mut |_: &Atom| {
        calls += 1;
        false
    });
    // Two checks of two branches, but only two distinct atoms.
    assert_eq!(calls, 2);
}

#[test]
fn subgoal_texts_for_libero_goal() {
    let want = [
        (
            "open_the_middle_drawer_of_the_cabinet",
            "open cabinet 1 middle",
        ),
        ("put_the_bowl_on_the_stove", "bowl 1 on stove 1"),
        (
            "put_the_wine_bottle_on_top_of_the_cabinet",
            "bottle 1 on cabinet 1 top side",
        ),
        (
            "open_the_top_drawer_and_put_the_bowl_inside",
            "bowl 1 in cabinet 1 top",
        ),
        (
            "push_the_plate_to_the_front_of_the_stove",
            "plate 1 in stove front region",
        ),
        (
            "put_the_cream_cheese_in_the_bowl",
            "cream cheese 1 on bowl 1",
        ),
        ("turn_on_the_stove", "turn on stove 1"),
        ("put_the_wine_bottle_on_the_rack", "bottle 1 on rack 1 top"),
    ];
    for (stem, text) in want {
        let t = tracker(&format!("libero_goal/{stem}"));
        assert_eq!(t.pending_text().as_deref(), Some(text), "{stem}");
    }
}

#[test]
fn long_sequences_have_ordinals() {
    let mut t = registry::resolve("t3@12").unwrap().tracker();
    let s = [on(B1, "plate_1")];
    let mut trace = Trace::default().hold(&s, 6);
    for _ in 0..12 {
        trace = trace.hold(&[], 16).hold(&s, 6);
    }
    let p = run(&mut t, &trace);
    assert_eq!(appends(&p).len(), 12);
    assert!(p.last().unwrap().done);
    let texts = t.satisfied_texts();
    assert_eq!(texts[10], "eleven: bowl 1 on plate 1");
    assert_eq!(texts[11], "twelve: bowl 1 on plate 1");
}

#[test]
fn unsupported_goal_shapes_are_errors() {
    let head = "(define (problem LIBERO_Tabletop_Manipulation) (:objects a b - plate) ";
    for goal in [
        "(:goal (Sequence))",
        "(:goal (Or))",
        "(:goal (Sequence (Sequence (On a b))))",
        "(:goal (Or (Or (On a b))))",
        "(:goal (And (On a b) (Sequence (On a b))))",
    ] {
        let p = sim::task::parse(&format!("{head}{goal})")).unwrap();
        assert!(GoalTracker::new(&p).is_err(), "{goal}");
    }
    // LIBERO unpacks the top-level And: a single Sequence inside it is the goal.
    let p = sim::task::parse(&format!(
        "{head}(:goal (And (Sequence (And (On a b)) (And (On b a))))))"
    ))
    .unwrap();
    assert_eq!(GoalTracker::new(&p).unwrap().goal_len(), 2);
}

#[test]
fn or_branches_of_different_lengths_follow_upstream() {
    // Branch 3 of this fixture is a single subgoal while goal_len comes from branch 1 (2 subgoals):
    // completing branch 3 makes the env `done`, and tiered credit is 1/2, as upstream computes it.
    let text = include_str!("fixtures/bddl/libero_mem_nested_goal.bddl");
    let mut t = GoalTracker::new(&sim::task::parse(text).unwrap()).unwrap();
    assert_eq!(t.goal_len(), 2);
    let p = run(
        &mut t,
        &Trace::default().hold(&[], 6).hold(&[on(B2, "plate_2")], 8),
    );
    // Three consistent branches each count the false steps: nonlive passes 15 after 6 steps.
    assert_eq!(appends(&p), [12]);
    assert!(p[12].done && !p[11].done);
    assert_eq!(p[12].tiered(), 0.5);
    assert_eq!(t.satisfied_texts(), ["one: bowl 2 on plate 2"]);
    assert_eq!(t.pending_text(), None);
}
