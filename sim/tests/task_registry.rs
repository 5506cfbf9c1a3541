//! The shipped tasks and id resolution.

use sim::task::bddl::{Goal, ProblemClass};
use sim::task::registry::{self, Suite, TaskError};

#[test]
fn twenty_tasks_in_benchmark_order() {
    let tasks = registry::list();
    assert_eq!(tasks.len(), 20);
    let ids: Vec<&str> = tasks.iter().map(|t| t.id.as_str()).collect();
    assert_eq!(ids[0], "libero_mem/t1");
    assert_eq!(ids[9], "libero_mem/t10");
    assert_eq!(ids[10], "libero_goal/open_the_middle_drawer_of_the_cabinet");
    assert_eq!(ids[19], "libero_goal/put_the_wine_bottle_on_the_rack");
    for t in &tasks {
        let class = if t.suite == Suite::LiberoMem {
            ProblemClass::KitchenTabletop
        } else {
            ProblemClass::Tabletop
        };
        assert_eq!(t.problem.problem_class, class, "{}", t.id);
        // The embedded text is what was parsed, and it round-trips through the printer.
        let again = sim::task::parse(&sim::task::print(&t.problem)).unwrap();
        assert_eq!(again, t.problem, "{}", t.id);
    }
}

#[test]
fn libero_mem_budgets_goal_lengths_and_instructions() {
    let want = [
        (200, 1, "pick up the bowl and place it back on the plate"),
        (290, 1, "lift the bottle and put it down on the plate"),
        (
            320,
            3,
            "lift the bowl and place it back on the plate 3 times",
        ),
        (
            370,
            3,
            "pick up the bottle and put it down the plate 3 times",
        ),
        (
            450,
            5,
            "lift the bowl and place it back on the plate 5 times",
        ),
        (655, 7, "pick up the bowl and place it on the plate 7 times"),
        (
            480,
            3,
            "swap the 2 bowls on their plates using the empty plate",
        ),
        (
            675,
            4,
            "rotate the 3 bowls on their plates from left to right using the empty plate",
        ),
        (
            390,
            2,
            "put the cream cheese in the nearest basket and place that basket in the center",
        ),
        (
            390,
            2,
            "put the cream cheese in the nearest basket and place the empty basket in the center",
        ),
    ];
    for (i, (steps, len, instr)) in want.iter().enumerate() {
        let n = i + 1;
        let t = registry::resolve(&format!("t{n}")).unwrap();
        assert_eq!(t.id, format!("libero_mem/t{n}"));
        assert_eq!(t.max_steps, *steps, "t{n}");
        assert_eq!(t.goal_len, *len, "t{n}");
        assert_eq!(t.instruction, *instr, "t{n}");
        assert_eq!(t.bddl_language, *instr, "t{n}");
        assert_eq!(t.task_language, format!("{n} {instr}"), "t{n}");
        assert_eq!(registry::resolve(&format!("libero_mem/t{n}")).unwrap(), t);
    }
}

#[test]
fn libero_goal_tasks_match_the_tsv() {
    let tsv = include_str!("fixtures/libero_goal_tasks.tsv");
    let mut rows = 0;
    for line in tsv
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("index"))
    {
        let f: Vec<&str> = line.split('\t').collect();
        let t = registry::resolve(&format!("libero_goal/{}", f[1])).unwrap();
        assert_eq!(t.instruction, f[2]);
        assert_eq!(t.task_language, f[2]);
        let goal = sim::task::parse(&t.bddl_text.replace(&goal_text(&t.bddl_text), f[3]))
            .unwrap()
            .goal;
        assert_eq!(t.problem.goal, goal, "{}", f[1]);
        assert_eq!(t.bddl_language, f[4].to_lowercase());
        assert_eq!(t.problem.language_raw, f[4]);
        assert_eq!(t.max_steps, 300);
        assert_eq!(t.goal_len, 1);
        rows += 1;
    }
    assert_eq!(rows, 10);
}

/// The `(And ...)` line of a shipped libero_goal file.
fn goal_text(bddl: &str) -> String {
    let i = bddl.find("(:goal").unwrap();
    bddl[i..].lines().nth(1).unwrap().trim().to_string()
}

#[test]
fn libero_goal_scene_is_the_shared_one() {
    let t = registry::resolve("libero_goal/open_the_top_drawer_and_put_the_bowl_inside").unwrap();
    let p = &t.problem;
    let fixtures: Vec<(&str, &str)> = p
        .fixtures
        .iter()
        .map(|i| (i.name.as_str(), i.category.as_str()))
        .collect();
    assert_eq!(
        fixtures,
        [
            ("main_table", "table"),
            ("wooden_cabinet_1", "wooden_cabinet"),
            ("flat_stove_1", "flat_stove"),
            ("wine_rack_1", "wine_rack")
        ]
    );
    let objects: Vec<&str> = p.objects.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(
        objects,
        [
            "akita_black_bowl_1",
            "cream_cheese_1",
            "wine_bottle_1",
            "plate_1"
        ]
    );
    assert_eq!(p.init.len(), 7);
    assert_eq!(
        p.obj_of_interest,
        ["akita_black_bowl_1", "wooden_cabinet_1_top_region"]
    );
    let front = p.region("main_table_stove_front_region").unwrap();
    assert!((front.ranges[0][0] + 0.09).abs() < 1e-12 && (front.ranges[0][3] - 0.25).abs() < 1e-12);
    assert_eq!(
        p.region("main_table_cabinet_region").unwrap().yaw_rotation,
        Some([std::f64::consts::PI; 2])
    );
    assert_eq!(
        p.region("main_table_plate_region").unwrap().yaw_rotation,
        None
    );
    assert!(p.region("bowl_drainer_1_right_region").is_some());
}

#[test]
fn libero_mem_scenes() {
    let t1 = registry::resolve("t1").unwrap().problem;
    let keys: Vec<String> = t1.regions.iter().map(|r| r.key()).collect();
    for k in [
        "kitchen_table_wooden_cabinet_1_region",
        "kitchen_table_plate_1_region",
        "kitchen_table_plate_2_region",
        "kitchen_table_plate_3_region",
        "wooden_cabinet_1_top_side",
    ] {
        assert!(keys.iter().any(|x| x == k), "{k} missing from {keys:?}");
    }
    assert_eq!(
        t1.region("kitchen_table_plate_2_region").unwrap().ranges,
        [[-0.25, 0.05, 0.12, 0.20]]
    );
    let objects: Vec<&str> = t1.objects.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(
        objects,
        [
            "akita_black_bowl_1",
            "wine_bottle_1",
            "plate_1",
            "plate_2",
            "plate_3"
        ]
    );
    let init: Vec<String> = t1.init.iter().map(|a| a.to_string()).collect();
    assert!(init.contains(&"(On akita_black_bowl_1 plate_1)".to_string()));
    assert!(init.contains(&"(On wine_bottle_1 plate_2)".to_string()));

    let t8 = registry::resolve("t8").unwrap().problem;
    assert_eq!(t8.objects.len(), 7);
    assert_eq!(
        t8.region("kitchen_table_plate_4_region").unwrap().ranges,
        [[-0.25, -0.15, 0.10, 0.25]]
    );

    let t9 = registry::resolve("t9").unwrap().problem;
    assert_eq!(t9.fixtures.len(), 1);
    assert_eq!(
        t9.region("kitchen_table_the_center").unwrap().ranges,
        [[-0.10, -0.17, 0.25, 0.20]]
    );
    assert_eq!(
        t9.region("basket_2_contain_region").unwrap().target,
        "basket_2"
    );
    let Goal::Or(branches) = &t9.goal else {
        panic!("T9 is an Or")
    };
    assert_eq!(branches.len(), 2);
}

#[test]
fn repetitions_scale_the_sequence() {
    let t = registry::resolve("t3@12").unwrap();
    assert_eq!(t.id, "libero_mem/t3@12");
    assert_eq!(t.goal_len, 12);
    assert_eq!(t.repeats, Some(12));
    assert_eq!(
        t.instruction,
        "lift the bowl and place it back on the plate 12 times"
    );
    assert_eq!(
        t.task_language,
        "3 lift the bowl and place it back on the plate 12 times"
    );
    let Goal::Sequence(s) = &t.problem.goal else {
        panic!()
    };
    assert_eq!(s.len(), 12);
    // The generated text is valid BDDL describing the same problem.
    assert_eq!(sim::task::parse(&t.bddl_text).unwrap(), t.problem);
    assert_eq!(t.tracker().goal_len(), 12);
    // Budgets: shipped points exactly, interpolated between, extrapolated beyond.
    assert_eq!(
        registry::resolve_with_repeats("t3", 3).unwrap(),
        registry::resolve("t3").unwrap()
    );
    assert_eq!(
        registry::resolve_with_repeats("t1", 7).unwrap().max_steps,
        655
    );
    assert_eq!(
        registry::resolve_with_repeats("t1", 2).unwrap().max_steps,
        260
    );
    assert_eq!(registry::resolve("t6@8").unwrap().max_steps, 758);
    assert_eq!(registry::resolve("t4@5").unwrap().max_steps, 450);
    assert_eq!(
        registry::resolve("t2@3").unwrap().instruction,
        "lift the bottle and put it down on the plate 3 times"
    );
    assert_eq!(
        registry::resolve("t5@1").unwrap().instruction,
        "lift the bowl and place it back on the plate"
    );
}

#[test]
fn bad_ids_and_counts() {
    let e = registry::resolve("t11").unwrap_err();
    assert!(matches!(e, TaskError::UnknownTask { .. }));
    let msg = e.to_string();
    for id in registry::known_ids() {
        assert!(msg.contains(&id), "{msg} lacks {id}");
    }
    assert!(msg.contains("libero_goal/turn_on_the_stove"));
    for bad in ["t3@0", "t7@3", "t3@x", "libero_goal/turn_on_the_stove@2"] {
        let e = registry::resolve(bad).unwrap_err();
        assert!(matches!(e, TaskError::BadRepeat { .. }), "{bad}: {e}");
    }
    assert!(
        registry::resolve("t3@0")
            .unwrap_err()
            .to_string()
            .contains("≥ 1")
    );
    assert!(
        registry::resolve("t7@3")
            .unwrap_err()
            .to_string()
            .contains("t1–t6")
    );
    assert!(matches!(
        registry::resolve_with_repeats("t9", 2),
        Err(TaskError::BadRepeat { .. })
    ));
}

#[test]
fn user_files() {
    let dir = std::env::temp_dir().join(format!("sim-task-registry-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("KITCHEN_SCENE3_turn_on_the_stove.bddl");
    std::fs::write(
        &path,
        registry::resolve("libero_goal/turn_on_the_stove")
            .unwrap()
            .bddl_text,
    )
    .unwrap();
    let t = registry::resolve(path.to_str().unwrap()).unwrap();
    assert_eq!(t.suite, Suite::User);
    assert_eq!(t.instruction, "turn on the stove");
    assert_eq!(t.goal_len, 1);

    let missing = dir.join("nope.bddl");
    let e = registry::resolve(missing.to_str().unwrap()).unwrap_err();
    assert!(matches!(e, TaskError::Io { .. }));
    assert!(e.to_string().contains("nope.bddl"), "{e}");

    let broken = dir.join("broken.bddl");
    std::fs::write(
        &broken,
        "(define (problem LIBERO_Tabletop_Manipulation)\n  (:goal (On a b))\n",
    )
    .unwrap();
    let e = registry::resolve(broken.to_str().unwrap()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!("{}:1:1: ", broken.display())),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn language_from_file_names() {
    use registry::{language_from_file_stem as lang, strip_leading_number as strip};
    assert_eq!(
        lang("KITCHEN_SCENE10_close_the_top_drawer_of_the_cabinet"),
        "close the top drawer of the cabinet"
    );
    assert_eq!(
        lang("LIVING_ROOM_SCENE2_pick_up_the_milk"),
        "pick up the milk"
    );
    assert_eq!(
        lang("put_the_bowl_on_the_plate"),
        "put the bowl on the plate"
    );
    let mem = lang("KITCHEN_SCENE1_10_put_the_cream_cheese_in_the_nearest_basket");
    assert_eq!(mem, "10 put the cream cheese in the nearest basket");
    assert_eq!(strip(&mem), "put the cream cheese in the nearest basket");
    assert_eq!(strip("swap the 2 bowls"), "swap the 2 bowls");
}
