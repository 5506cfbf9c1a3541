//! BDDL parser: fixtures covering the constructs of LIBERO's five suites and LIBERO-Mem, error
//! positions, and the print → parse round trip over generated problems.

use std::f64::consts::PI;

use proptest::prelude::*;
use sim::task::bddl::{
    self, Atom, BddlError, Goal, Instance, PREDICATES, Predicate, Problem, ProblemClass, Region,
    Span,
};

fn fixture(name: &str) -> Problem {
    let path = format!(
        "{}/tests/fixtures/bddl/{name}.bddl",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let p = bddl::parse_named(&path, &text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        bddl::parse(&bddl::print(&p)).unwrap(),
        p,
        "{name} round trip"
    );
    p
}

fn inst(p: &[Instance]) -> Vec<(&str, &str)> {
    p.iter()
        .map(|i| (i.name.as_str(), i.category.as_str()))
        .collect()
}

fn atoms(v: &[Atom]) -> Vec<String> {
    v.iter().map(|a| a.to_string()).collect()
}

#[test]
fn libero_spatial_tabletop() {
    let p = fixture("libero_spatial_tabletop");
    assert_eq!(p.problem_class, ProblemClass::Tabletop);
    assert_eq!(p.problem_class.workspace(), "main_table");
    assert_eq!(p.domain, "robosuite");
    assert_eq!(
        inst(&p.objects),
        [
            ("akita_black_bowl_1", "akita_black_bowl"),
            ("akita_black_bowl_2", "akita_black_bowl"),
            ("cookies_1", "cookies"),
            (
                "glazed_rim_porcelain_ramekin_1",
                "glazed_rim_porcelain_ramekin"
            ),
            ("plate_1", "plate")
        ]
    );
    assert_eq!(
        p.region("main_table_akita_black_bowl_middle_region")
            .unwrap()
            .yaw_rotation,
        Some([0.0, 0.0])
    );
    let cook = p.region("flat_stove_1_cook_region").unwrap();
    assert_eq!(
        (
            cook.target.as_str(),
            cook.ranges.len(),
            cook.yaw_rotation,
            cook.rgba
        ),
        ("flat_stove_1", 0, None, None)
    );
    assert_eq!(
        (cook.yaw_or_default(), cook.rgba_or_default()),
        ([0.0; 2], [0.0, 0.0, 1.0, 0.0])
    );
    assert_eq!(
        p.problem_class.lowercase_name(),
        "libero_tabletop_manipulation"
    );
    assert_eq!(
        p.goal,
        Goal::And(vec![Goal::Atom(Atom::new(
            "on",
            &["akita_black_bowl_1", "plate_1"]
        ))])
    );
    // Region spans point at the region's `(`.
    assert_eq!((p.regions[0].span.line, p.regions[0].span.col), (5, 7));
    assert_eq!((p.init[1].span.line, p.init[1].span.col), (55, 5));
}

#[test]
fn libero_object_floor() {
    let p = fixture("libero_object_floor");
    assert_eq!(p.problem_class, ProblemClass::Floor);
    assert_eq!(p.language, "pick the milk and place it in the basket");
    assert_eq!(p.language_raw, "Pick the milk and place it in the basket");
    assert_eq!(inst(&p.fixtures), [("floor", "floor")]);
    let bin = p.region("floor_bin_region").unwrap();
    assert_eq!(bin.ranges, [[-0.01, 0.25, 0.01, 0.27]]);
    assert_eq!(bin.yaw_rotation, None);
    assert_eq!(
        atoms(&p.goal.atoms().into_iter().cloned().collect::<Vec<_>>()),
        ["(In milk_1 basket_1_contain_region)"]
    );
}

#[test]
fn libero_10_kitchen_open_init_and_two_atom_goal() {
    let p = fixture("libero_10_kitchen_close_drawer_with_bowl");
    assert_eq!(p.problem_class, ProblemClass::KitchenTabletop);
    assert_eq!(atoms(&p.init)[3], "(Open white_cabinet_1_bottom_region)");
    assert_eq!(
        p.goal,
        Goal::And(vec![
            Goal::Atom(Atom::new("close", &["white_cabinet_1_bottom_region"])),
            Goal::Atom(Atom::new(
                "in",
                &["akita_black_bowl_1", "white_cabinet_1_bottom_region"]
            )),
        ])
    );
    let rack = p.region("kitchen_table_wine_rack_init_region").unwrap();
    assert_eq!(rack.ranges[0][2], -0.09000000000000001);
    assert_eq!(rack.yaw_rotation, Some([PI, PI]));
}

#[test]
fn libero_10_living_room() {
    let p = fixture("libero_10_living_room_two_in_basket");
    assert_eq!(p.problem_class, ProblemClass::LivingRoomTabletop);
    assert_eq!(p.problem_class.workspace(), "living_room_table");
    assert_eq!(p.goal.atoms().len(), 2);
    assert_eq!(
        p.obj_of_interest,
        ["alphabet_soup_1", "cream_cheese_1", "basket_1"]
    );
}

#[test]
fn libero_90_study_yaw_values_and_expressions() {
    let p = fixture("libero_90_study_caddy_yaw");
    assert_eq!(p.problem_class, ProblemClass::StudyTabletop);
    let lit = p
        .region("study_table_black_book_init_region")
        .unwrap()
        .yaw_rotation
        .unwrap();
    let expr = p
        .region("study_table_black_book_expr_region")
        .unwrap()
        .yaw_rotation
        .unwrap();
    assert_eq!(lit, [-PI / 2.0, -PI / 4.0]);
    assert_eq!(expr, lit);
    assert_eq!(
        p.region("study_table_desk_caddy_right_region")
            .unwrap()
            .yaw_rotation,
        Some([2.6614, 2.7242])
    );
    assert!(p.region("desk_caddy_1_front_contain_region").is_some());
}

#[test]
fn libero_90_kitchen_turnon_close_in_inits() {
    let p = fixture("libero_90_kitchen_turn_off_stove");
    assert_eq!(atoms(&p.init)[3], "(Turnon flat_stove_1)");
    assert_eq!(
        p.goal,
        Goal::And(vec![Goal::Atom(Atom::new("turnoff", &["flat_stove_1"]))])
    );
    assert_eq!(
        inst(&p.objects),
        [("moka_pot_1", "moka_pot"), ("moka_pot_2", "moka_pot")]
    );

    let p = fixture("libero_90_kitchen_microwave_close_in");
    assert_eq!(
        atoms(&p.init)[2..],
        [
            "(In white_yellow_mug_1 microwave_1_heating_region)",
            "(Open microwave_1)",
            "(Close wooden_cabinet_1_top_region)",
            "(In akita_black_bowl_1 wooden_cabinet_1_top_region)"
        ]
    );
    // A region without :yaw_rotation next to ones with it.
    assert_eq!(
        p.region("kitchen_table_plate_init_region")
            .unwrap()
            .yaw_rotation,
        None
    );
    assert_eq!(
        p.region("kitchen_table_microwave_init_region")
            .unwrap()
            .yaw_rotation,
        Some([-PI / 2.0; 2])
    );
}

#[test]
fn comments_mixed_case_and_extras() {
    let p = fixture("comments_mixed_case_and_extras");
    assert_eq!(p.problem_class, ProblemClass::CoffeeTable);
    assert_eq!(p.language, "put the mug on the table");
    assert_eq!(p.language_raw, "Put The MUG on the Table");
    assert_eq!(
        inst(&p.fixtures),
        [
            ("coffee_table", "coffee_table"),
            ("cabinet_thing", "fixture")
        ]
    );
    assert_eq!(
        inst(&p.objects),
        [("mug_1", "mug"), ("loose_thing", "object")]
    );
    let r = &p.regions[0];
    assert_eq!(r.key(), "coffee_table_mug_region");
    assert_eq!(r.ranges, [[-0.1, -0.1, 0.1, 0.1], [0.2, 0.2, 0.3, 0.3]]);
    assert_eq!(
        r.yaw_rotation,
        Some([PI / 4.0, PI]),
        "the last yaw pair wins"
    );
    assert_eq!(r.rgba, Some([0.0, 1.0, 0.0, 0.5]));
    assert_eq!(p.regions[1].key(), "cabinet_thing_bare_region");
    assert_eq!(
        p.regions[2].yaw_rotation, None,
        "an empty yaw list is no yaw"
    );
    assert_eq!(
        atoms(&p.init),
        [
            "(On mug_1 coffee_table_mug_region)",
            "(True)",
            "(Close cabinet_thing)"
        ]
    );
    assert_eq!(p.goal, Goal::Atom(Atom::new("up", &["mug_1"])));
    assert_eq!(p.obj_of_interest, ["mug_1", "coffee_table_mug_region"]);
}

#[test]
fn libero_mem_nested_goals() {
    let p = fixture("libero_mem_nested_goal");
    let Goal::Or(branches) = &p.goal else {
        panic!("{:?}", p.goal)
    };
    assert_eq!(branches.len(), 3);
    let Goal::Sequence(first) = &branches[0] else {
        panic!()
    };
    assert_eq!(first.len(), 2);
    assert!(matches!(&first[1], Goal::And(v) if v.len() == 2));
    let Goal::Sequence(second) = &branches[1] else {
        panic!()
    };
    assert!(matches!(&second[1], Goal::Atom(_)));
    assert!(matches!(&branches[2], Goal::And(_)));
    let t = sim::task::GoalTracker::new(&p).unwrap();
    assert_eq!(t.goal_len(), 2);
    assert_eq!(t.pending_text().as_deref(), Some("bowl 1 on plate 2"));
}

#[test]
fn shipped_files_use_only_known_constructs() {
    for t in sim::task::list() {
        let p = &t.problem;
        assert!(
            p.goal
                .atoms()
                .iter()
                .all(|a| ["on", "in", "open", "turnon"].contains(&a.predicate.as_str()))
        );
        assert!(!p.regions.is_empty() && !p.init.is_empty(), "{}", t.id);
        bddl::check_scene(&t.id, p).unwrap();
    }
}

#[test]
fn scene_checks_name_the_file_and_region() {
    let t1 = include_str!("../tasks/libero_mem/t1.bddl");
    // Region plate_1_region's rectangle with x_min and x_max swapped.
    let start = t1.find("(plate_1_region").unwrap();
    let rect = "(-0.25 -0.15 0.12 -0.01)";
    assert_eq!(t1.matches(rect).count(), 1);
    let text = t1.replace(rect, "(0.12 -0.15 -0.25 -0.01)");
    let p = bddl::parse_named("inv.bddl", &text).unwrap();
    let e = bddl::check_scene("inv.bddl", &p).unwrap_err();
    let line = t1[..start].matches('\n').count() as u32 + 1;
    assert_eq!(e.line, line, "{e}");
    assert!(
        e.to_string().starts_with(&format!("inv.bddl:{line}:")),
        "{e}"
    );
    assert!(
        e.message
            .contains("region `plate_1_region`: inverted rectangle"),
        "{e}"
    );
    // No fixtures section: the fixtures declared as objects instead.
    let head = "(:fixtures\n    kitchen_table - kitchen_table\n    wooden_cabinet_1 - wooden_cabinet\n  )\n\n  (:objects\n";
    assert_eq!(t1.matches(head).count(), 1);
    let text = t1.replace(
        head,
        "(:objects\n    kitchen_table - kitchen_table\n    wooden_cabinet_1 - wooden_cabinet\n",
    );
    let p = bddl::parse_named("nofix.bddl", &text).unwrap();
    let e = bddl::check_scene("nofix.bddl", &p).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("nofix.bddl:1:1: no `(:fixtures ...)` section"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Errors: exact positions and messages.

fn error(text: &str) -> BddlError {
    bddl::parse_named("x.bddl", text).expect_err("should not parse")
}

fn at(text: &str) -> (u32, u32, String) {
    let e = error(text);
    (e.line, e.col, e.message)
}

const HEAD: &str = "(define (problem LIBERO_Tabletop_Manipulation)\n";

#[test]
fn error_display_is_file_line_col_message() {
    let e = error("(define (problem LIBERO_Tabletop_Manipulation)))");
    assert_eq!(e.to_string(), format!("x.bddl:1:48: {}", e.message));
    assert_eq!(bddl::parse(")").unwrap_err().file, "<input>");
}

#[test]
fn error_unbalanced_parentheses() {
    // An extra `)`: reported where it is.
    let (l, c, m) = at(&format!(
        "{HEAD}  (:objects a - plate)\n  (:goal (On a a))))\n"
    ));
    assert_eq!((l, c), (3, 20));
    assert!(m.contains("no matching `(`"), "{m}");
    // A `(` never closed: the innermost one still open at the end.
    let (l, c, m) = at(&format!(
        "{HEAD}  (:objects a - plate)\n  (:goal (And (On a a)\n"
    ));
    assert_eq!((l, c), (3, 10));
    assert!(
        m.contains("never closed") && m.contains("expected `)`"),
        "{m}"
    );
    // Comments do not hide parentheses from the count, and a `)` inside a comment does not count.
    let (l, c, _) = at("(define ; )\n");
    assert_eq!((l, c), (1, 1));
}

#[test]
fn error_nesting_too_deep_is_an_error_not_a_stack_overflow() {
    // A goal nested 10 000 deep: refused at the first `(` past the limit, which is on line 2.
    let deep = format!(
        "{HEAD}  (:objects a - plate)\n(:goal {}(On a a){}))",
        "(And ".repeat(10_000),
        ")".repeat(10_000)
    );
    let (l, c, m) = at(&deep);
    let limit = bddl::MAX_DEPTH;
    // `(define` is level 1 and `(:goal` level 2, so the goal's `(And` number limit - 1 is refused.
    assert_eq!((l, c), (3, 8 + 5 * (limit as u32 - 2)));
    assert_eq!(m, format!("parentheses nested deeper than {limit} levels"));
    // 100 000 balanced pairs, nothing else: the same error, at the first `(` too deep.
    let parens = format!("{}{}", "(".repeat(100_000), ")".repeat(100_000));
    assert_eq!(at(&parens), (1, limit as u32 + 1, m));
    // LIBERO's depth is far below the limit: a goal nested 40 deep still parses.
    let ok = format!(
        "{HEAD}  (:objects a - plate)\n(:goal {}(On a a){}))",
        "(And ".repeat(40),
        ")".repeat(40)
    );
    bddl::parse(&ok).expect("40 levels parse");
}

#[test]
fn error_missing_target() {
    let text = format!(
        "{HEAD}  (:regions\n    (plate_region\n      (:ranges ((0 0 1 1))))\n  )\n  (:goal (True)))"
    );
    let (l, c, m) = at(&text);
    assert_eq!((l, c), (3, 5));
    assert_eq!(
        m,
        "region `plate_region` has no `(:target <entity>)`; expected one"
    );
}

#[test]
fn error_bad_number() {
    let text = format!(
        "{HEAD}  (:regions\n    (r (:target main_table)\n       (:ranges ((0 0 1 x1)))))\n  (:goal (True)))"
    );
    let (l, c, m) = at(&text);
    assert_eq!((l, c), (4, 25));
    assert_eq!(
        m,
        "bad number `x1`: expected a finite decimal number such as `-0.25`"
    );
    // Rectangles need four numbers.
    let text = format!(
        "{HEAD}  (:regions (r (:target main_table) (:ranges ((0 0 1)))))\n  (:goal (True)))"
    );
    let (l, c, m) = at(&text);
    assert_eq!((l, c), (2, 47));
    assert!(m.starts_with("expected 4 numbers"), "{m}");
    // Yaw values are expressions, but not arbitrary ones.
    let text = format!(
        "{HEAD}  (:regions (r (:target main_table) (:yaw_rotation ((0 np.tau)))))\n  (:goal (True)))"
    );
    let (l, c, m) = at(&text);
    assert_eq!((l, c), (2, 56));
    assert!(m.starts_with("bad yaw value `np.tau`"), "{m}");
    // Non-finite numbers are refused.
    let text = format!(
        "{HEAD}  (:regions (r (:target main_table) (:rgba (0 0 inf 1))))\n  (:goal (True)))"
    );
    assert_eq!(at(&text).0, 2);
}

#[test]
fn error_unknown_section() {
    let (l, c, m) = at(&format!("{HEAD}  (:goal (True))\n  (:scenery nice)\n)"));
    assert_eq!((l, c), (3, 3));
    assert!(
        m.starts_with("unknown section `:scenery`; expected one of :domain,"),
        "{m}"
    );
    // Duplicates are refused too.
    let (l, c, m) = at(&format!("{HEAD}  (:goal (True))\n  (:goal (True))\n)"));
    assert_eq!((l, c), (3, 3));
    assert_eq!(m, "duplicate section `:goal` (first at line 2, column 3)");
}

#[test]
fn error_wrong_top_level() {
    let (l, c, m) = at("(problem LIBERO_Tabletop_Manipulation)");
    assert_eq!((l, c), (1, 2));
    assert!(
        m.starts_with("expected `(define (problem <ProblemClass>) <section>...)`, found `problem`"),
        "{m}"
    );
    let (l, c, m) = at("define");
    assert_eq!((l, c), (1, 1));
    assert!(m.contains("found `define`"), "{m}");
    let (l, c, m) = at(&format!("{HEAD}  (:goal (True)))\n\n  (define)"));
    assert_eq!((l, c), (4, 3));
    assert!(
        m.starts_with("expected exactly one top-level expression"),
        "{m}"
    );
    let (l, c, m) = at("; nothing here\n");
    assert_eq!((l, c), (2, 1));
    assert!(m.contains("end of the file"), "{m}");
    let (l, c, m) = at("(define (problem LIBERO_Moon_Manipulation) (:goal (True)))");
    assert_eq!((l, c), (1, 18));
    assert!(
        m.starts_with(
            "unknown problem class `libero_moon_manipulation`; expected one of LIBERO_Tabletop"
        ),
        "{m}"
    );
    let (l, c, m) =
        at("(define (problem LIBERO_Tabletop_Manipulation) (:domain pddl) (:goal (True)))");
    assert_eq!((l, c), (1, 57));
    assert_eq!(m, "expected the domain `robosuite`, found `pddl`");
    let (_, _, m) = at("(define (problem LIBERO_Tabletop_Manipulation))");
    assert_eq!(m, "missing section `(:goal ...)`");
}

#[test]
fn error_atoms() {
    let objs = "  (:objects a b - plate)\n";
    let (l, c, m) = at(&format!(
        "{HEAD}{objs}  (:init (On a c))\n  (:goal (True)))"
    ));
    assert_eq!((l, c), (3, 16));
    assert_eq!(
        m,
        "unknown name `c`; expected a declared fixture, object or region key"
    );
    let (l, c, m) = at(&format!(
        "{HEAD}{objs}  (:init (Stack a b))\n  (:goal (True)))"
    ));
    assert_eq!((l, c), (3, 10));
    assert!(
        m.starts_with("unknown predicate `stack`; expected one of true, false, in, on"),
        "{m}"
    );
    let (l, c, m) = at(&format!("{HEAD}{objs}  (:goal (On a)))"));
    assert_eq!((l, c), (3, 10));
    assert_eq!(m, "predicate `on` takes 2 argument(s), found 1");
    let (l, c, m) = at(&format!("{HEAD}{objs}  (:goal (Not (On a b))))"));
    assert_eq!((l, c), (3, 10));
    assert!(m.starts_with("`not` is not supported"), "{m}");
    let (l, c, m) = at(&format!("{HEAD}{objs}  (:goal (And On)))"));
    assert_eq!((l, c), (3, 15));
    assert!(m.starts_with("expected a goal"), "{m}");
    let (l, c, m) = at(&format!(
        "{HEAD}  (:objects a - plate a - bowl)\n  (:goal (True)))"
    ));
    assert_eq!((l, c), (2, 23));
    assert_eq!(
        m,
        "duplicate name `a` (first declared at line 2, column 13)"
    );
    let (l, c, m) = at(&format!("{HEAD}  (:objects a -)\n  (:goal (True)))"));
    assert_eq!((l, c), (2, 15));
    assert_eq!(
        m,
        "expected a category after `-`, found the end of the section"
    );
    let (l, c, m) = at(&format!(
        "{HEAD}  (:regions (r (:target t) (:color red)))\n  (:goal (True)))"
    ));
    assert_eq!((l, c), (2, 28));
    assert!(m.starts_with("unknown region attribute `:color`"), "{m}");
}

// ---------------------------------------------------------------------------------------------
// Round trip over generated problems.

fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>().prop_filter("finite", |x| x.is_finite()),
        -1.0f64..1.0,
        Just(0.0),
        Just(-0.0),
        Just(PI),
    ]
}

fn arb_atom(names: Vec<String>) -> impl Strategy<Value = Atom> {
    (
        0..PREDICATES.len(),
        prop::collection::vec(prop::sample::select(names), 2),
    )
        .prop_flat_map(|(i, args)| {
            let (pred, lo, hi) = PREDICATES[i];
            let predicate = Predicate::from_name(pred).unwrap();
            (lo..=hi).prop_map(move |n| Atom {
                predicate,
                args: args[..n].to_vec(),
                span: Span::default(),
            })
        })
}

fn arb_goal(names: Vec<String>) -> impl Strategy<Value = Goal> {
    arb_atom(names)
        .prop_map(Goal::Atom)
        .prop_recursive(3, 24, 4, |inner| {
            prop_oneof![
                prop::collection::vec(inner.clone(), 0..4).prop_map(Goal::And),
                prop::collection::vec(inner.clone(), 0..4).prop_map(Goal::Or),
                prop::collection::vec(inner, 0..4).prop_map(Goal::Sequence),
            ]
        })
}

prop_compose! {
    fn arb_region(targets: Vec<String>, j: usize)(
        target in prop::sample::select(targets),
        suffix in "[a-z0-9_]{0,6}",
        ranges in prop::collection::vec(prop::array::uniform4(finite()), 0..3),
        yaw_rotation in prop::option::of(prop::array::uniform2(finite())),
        rgba in prop::option::of(prop::array::uniform4(finite())),
    ) -> Region {
        Region { name: format!("r{j}{suffix}"), target, ranges, yaw_rotation, rgba, span: Span::default() }
    }
}

fn arb_problem() -> impl Strategy<Value = Problem> {
    let fixtures = prop::collection::vec(
        prop::sample::select(vec!["table", "wooden_cabinet", "fixture", "flat_stove"]),
        0..4,
    );
    let objects = prop::collection::vec(
        prop::sample::select(vec!["akita_black_bowl", "plate", "object", "basket"]),
        1..5,
    );
    (
        fixtures,
        objects,
        0usize..4,
        prop::sample::select(ProblemClass::ALL.to_vec()),
    )
        .prop_flat_map(|(fx, ob, n_regions, class)| {
            let fixtures: Vec<Instance> = fx
                .iter()
                .enumerate()
                .map(|(i, c)| Instance {
                    name: format!("fx{i}"),
                    category: c.to_string(),
                })
                .collect();
            let objects: Vec<Instance> = ob
                .iter()
                .enumerate()
                .map(|(i, c)| Instance {
                    name: format!("ob{i}"),
                    category: c.to_string(),
                })
                .collect();
            let mut targets: Vec<String> = fixtures
                .iter()
                .chain(&objects)
                .map(|i| i.name.clone())
                .collect();
            targets.push(class.workspace().to_string());
            let regions: Vec<_> = (0..n_regions)
                .map(|j| arb_region(targets.clone(), j))
                .collect();
            (Just((class, fixtures, objects)), regions)
        })
        .prop_flat_map(|((class, fixtures, objects), regions)| {
            let mut names: Vec<String> = fixtures
                .iter()
                .chain(&objects)
                .map(|i| i.name.clone())
                .collect();
            names.extend(regions.iter().map(Region::key));
            (
                Just((class, fixtures, objects, regions)),
                prop::collection::vec("[A-Za-z0-9.,'!?-]{1,8}", 0..6),
                prop::collection::vec(prop::sample::select(names.clone()), 0..3),
                prop::collection::vec(arb_atom(names.clone()), 0..5),
                arb_goal(names),
            )
        })
        .prop_map(
            |((problem_class, fixtures, objects, regions), words, obj_of_interest, init, goal)| {
                let language_raw = words.join(" ");
                Problem {
                    problem_class,
                    domain: "robosuite".to_string(),
                    language: language_raw.to_lowercase(),
                    language_raw,
                    regions,
                    fixtures,
                    objects,
                    obj_of_interest,
                    init,
                    goal,
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn print_then_parse_is_identity(p in arb_problem()) {
        let text = bddl::print(&p);
        let back = bddl::parse(&text).map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        prop_assert_eq!(back, p);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Fuzzing the parser: any text from BDDL's own characters, and any real file mutated (bytes
    /// replaced, cut, duplicated), gives a problem or an error with a position inside the text,
    /// never a panic.
    #[test]
    fn any_text_parses_or_gives_a_positioned_error(
        text in "[()a-zA-Z0-9_:;. \n\t+*/-]{0,400}",
    ) {
        check_no_panic(&text)?;
    }

    #[test]
    fn mutated_real_files_parse_or_give_a_positioned_error(
        file in 0usize..4,
        edits in proptest::collection::vec((any::<usize>(), 0u8..4, any::<u8>()), 1..6),
    ) {
        let mut bytes = FUZZ_SEEDS[file].as_bytes().to_vec();
        for (at, kind, b) in edits {
            let i = at % bytes.len().max(1);
            match kind {
                0 => if i < bytes.len() { bytes[i] = b"()a :-;\n0"[b as usize % 9] },
                1 => bytes.truncate(i),
                2 => { let tail = bytes[i..].to_vec(); bytes.extend_from_slice(&tail[..tail.len().min(64)]) }
                _ => if i < bytes.len() { bytes.remove(i); },
            }
        }
        check_no_panic(&String::from_utf8_lossy(&bytes))?;
    }
}

/// Real files the mutation fuzzer starts from.
const FUZZ_SEEDS: [&str; 4] = [
    include_str!("fixtures/bddl/libero_spatial_tabletop.bddl"),
    include_str!("fixtures/bddl/libero_10_kitchen_close_drawer_with_bowl.bddl"),
    include_str!("fixtures/bddl/libero_90_study_caddy_yaw.bddl"),
    include_str!("../tasks/libero_mem/t8.bddl"),
];

fn check_no_panic(text: &str) -> Result<(), TestCaseError> {
    match bddl::parse_named("f.bddl", text) {
        Ok(p) => {
            // What parses prints and parses back to itself.
            let back =
                bddl::parse(&bddl::print(&p)).map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(back, p);
        }
        Err(e) => {
            let lines = text.lines().count().max(1) as u32 + 1;
            prop_assert!(
                e.line >= 1 && e.line <= lines,
                "line {} of {}",
                e.line,
                lines
            );
            prop_assert!(e.col >= 1, "col {}", e.col);
            prop_assert!(e.to_string().starts_with("f.bddl:"), "{e}");
        }
    }
    Ok(())
}
