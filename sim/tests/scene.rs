//! Scene composition, seeded placement and predicates on hand-built task descriptions.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::mujoco::Data;
use sim::predicates::Predicates;
use sim::scene::{AtomSpec, InstanceSpec, RegionSpec, Scene, SceneSpec};

fn region(name: &str, target: &str, r: Option<[f64; 4]>, yaw: f64) -> RegionSpec {
    RegionSpec {
        name: name.into(),
        target: target.into(),
        ranges: r.into_iter().collect(),
        yaw: [yaw, yaw],
        rgba: [0.0, 0.0, 1.0, 0.0],
    }
}

fn inst(name: &str, category: &str) -> InstanceSpec {
    InstanceSpec {
        name: name.into(),
        category: category.into(),
    }
}

fn on(a: &str, b: &str) -> AtomSpec {
    AtomSpec {
        predicate: sim::task::Predicate::On,
        args: vec![a.into(), b.into()],
    }
}

/// The libero_goal scene (libero.md §1.3).
fn libero_goal() -> SceneSpec {
    let pi = std::f64::consts::PI;
    SceneSpec {
        problem_class: "libero_tabletop_manipulation".into(),
        regions: vec![
            region(
                "plate_region",
                "main_table",
                Some([0.04, -0.03, 0.06, -0.01]),
                0.0,
            ),
            region(
                "akita_black_bowl_region",
                "main_table",
                Some([-0.10, -0.01, -0.08, 0.01]),
                0.0,
            ),
            region(
                "wine_bottle_region",
                "main_table",
                Some([-0.21, -0.06, -0.19, -0.04]),
                0.0,
            ),
            region(
                "cream_cheese_region",
                "main_table",
                Some([-0.06, 0.12, -0.04, 0.14]),
                0.0,
            ),
            region(
                "stove_front_region",
                "main_table",
                Some([-0.09, 0.17, -0.01, 0.25]),
                0.0,
            ),
            region(
                "cabinet_region",
                "main_table",
                Some([0.02, -0.25, 0.04, -0.23]),
                pi,
            ),
            region(
                "stove_region",
                "main_table",
                Some([-0.42, 0.20, -0.40, 0.22]),
                0.0,
            ),
            region(
                "wine_rack_region",
                "main_table",
                Some([-0.27, -0.27, -0.25, -0.25]),
                pi,
            ),
            region("top_region", "wooden_cabinet_1", None, 0.0),
            region("middle_region", "wooden_cabinet_1", None, 0.0),
            region("bottom_region", "wooden_cabinet_1", None, 0.0),
            region("top_side", "wooden_cabinet_1", None, 0.0),
            region("cook_region", "flat_stove_1", None, 0.0),
            region("right_region", "bowl_drainer_1", None, 0.0),
            region("top_region", "wine_rack_1", None, 0.0),
        ],
        fixtures: vec![
            inst("main_table", "table"),
            inst("wooden_cabinet_1", "wooden_cabinet"),
            inst("flat_stove_1", "flat_stove"),
            inst("wine_rack_1", "wine_rack"),
        ],
        objects: vec![
            inst("akita_black_bowl_1", "akita_black_bowl"),
            inst("cream_cheese_1", "cream_cheese"),
            inst("wine_bottle_1", "wine_bottle"),
            inst("plate_1", "plate"),
        ],
        init: vec![
            on("akita_black_bowl_1", "main_table_akita_black_bowl_region"),
            on("plate_1", "main_table_plate_region"),
            on("wine_bottle_1", "main_table_wine_bottle_region"),
            on("cream_cheese_1", "main_table_cream_cheese_region"),
            on("wooden_cabinet_1", "main_table_cabinet_region"),
            on("flat_stove_1", "main_table_stove_region"),
            on("wine_rack_1", "main_table_wine_rack_region"),
        ],
    }
}

fn settle(data: &mut Data, steps: usize) {
    for _ in 0..steps {
        data.step().unwrap();
    }
}

#[test]
fn libero_goal_layout_matches_libero() {
    let scene = Scene::build(libero_goal()).unwrap();
    let m = &scene.model;
    // qpos: arm 7 + fingers 2 + 4 free joints + 3 drawers + knob = 41; nv = 37 (libero.md §4.2).
    assert_eq!((m.nq(), m.nv()), (41, 37));
    let names: Vec<_> = scene.instances.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "akita_black_bowl_1",
            "cream_cheese_1",
            "wine_bottle_1",
            "plate_1",
            "wooden_cabinet_1",
            "flat_stove_1",
            "wine_rack_1"
        ]
    );
    assert_eq!(scene.instances[0].qpos_adr, Some(9));
    assert_eq!(scene.instances[3].qpos_adr, Some(30));
    // Dangling region (bowl_drainer_1 is not in the scene) is kept but has no site.
    assert!(scene.regions["bowl_drainer_1_right_region"].site.is_none());
}

#[test]
fn libero_goal_site_positions_at_range_centres() {
    // Fixture poses at the range centres give LIBERO's site positions (libero.md §4.3 table).
    let scene = Scene::build(libero_goal()).unwrap();
    let mut data = Data::new(scene.model.clone()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    scene.sample_init(&mut data, &mut rng).unwrap();
    let pi = std::f64::consts::PI;
    for (name, x, y, yaw) in [
        ("wooden_cabinet_1", 0.03, -0.24, pi),
        ("flat_stove_1", -0.41, 0.21, 0.0),
        ("wine_rack_1", -0.26, -0.26, pi),
    ] {
        let i = scene.instance(name).unwrap();
        let mc = scene.instances[i].mocap.unwrap();
        let z = data.mocap_pos()[3 * mc + 2];
        data.mocap_pos_mut()[3 * mc..3 * mc + 3].copy_from_slice(&[x, y, z]);
        data.mocap_quat_mut()[4 * mc..4 * mc + 4].copy_from_slice(&sim::assets::yaw_quat(yaw));
    }
    data.forward().unwrap();
    let site = |k: &str| data.site_pos(scene.regions[k].site.unwrap());
    let close = |a: [f64; 3], b: [f64; 3], tol: f64| (0..3).all(|k| (a[k] - b[k]).abs() < tol);
    assert!(
        close(
            site("wooden_cabinet_1_top_side"),
            [0.0265, -0.2557, 1.1265],
            2e-3
        ),
        "{:?}",
        site("wooden_cabinet_1_top_side")
    );
    assert!(
        close(
            site("wooden_cabinet_1_top_region"),
            [0.0267, -0.2513, 1.0906],
            2e-3
        ),
        "{:?}",
        site("wooden_cabinet_1_top_region")
    );
    assert!((site("wooden_cabinet_1_middle_region")[2] - 1.0219).abs() < 2e-3);
    assert!((site("wooden_cabinet_1_bottom_region")[2] - 0.9520).abs() < 2e-3);
    assert!(
        close(site("flat_stove_1_cook_region"), [-0.26, 0.21, 0.905], 2e-3),
        "{:?}",
        site("flat_stove_1_cook_region")
    );
    assert!(
        close(
            site("wine_rack_1_top_region"),
            [-0.26, -0.1800, 1.1375],
            2e-3
        ),
        "{:?}",
        site("wine_rack_1_top_region")
    );
    assert!(close(
        site("main_table_stove_front_region"),
        [-0.05, 0.21, 0.895],
        1e-6
    ));
}

#[test]
fn placement_is_seeded_and_init_relations_hold_after_settling() {
    let scene = Scene::build(libero_goal()).unwrap();
    for seed in 0..5u64 {
        let mut a = Data::new(scene.model.clone()).unwrap();
        let mut b = Data::new(scene.model.clone()).unwrap();
        scene
            .sample_init(&mut a, &mut ChaCha8Rng::seed_from_u64(seed))
            .unwrap();
        scene
            .sample_init(&mut b, &mut ChaCha8Rng::seed_from_u64(seed))
            .unwrap();
        assert_eq!(a.qpos(), b.qpos());
        assert_eq!(a.mocap_pos(), b.mocap_pos());
        settle(&mut a, 400);
        let p = Predicates::new(&scene, &a);
        for atom in &scene.spec.init {
            assert!(
                p.eval(atom.predicate, &atom.args).unwrap(),
                "seed {seed}: ({atom}) false after settling"
            );
        }
        for c in a.contacts() {
            assert!(c.dist > -0.004, "seed {seed}: interpenetration {c:?}");
        }
    }
}

#[test]
fn unknown_category_names_it() {
    let mut spec = libero_goal();
    spec.objects.push(inst("teapot_1", "teapot"));
    let e = Scene::build(spec).unwrap_err().to_string();
    assert!(
        e.contains("teapot") && e.contains("akita_black_bowl"),
        "{e}"
    );
}

#[test]
fn task_env_resets_validly_and_renders() {
    let scene = Scene::build(libero_goal()).unwrap();
    let mut env = sim::Env::with_scene(
        scene,
        sim::EnvConfig {
            image_size: 128,
            ..Default::default()
        },
    )
    .unwrap();
    let obs = env.reset(0).unwrap();
    assert_eq!(obs.step, 0);
    assert_eq!(obs.agentview_rgb.len(), 128 * 128 * 3);
    let p = env.predicates().unwrap();
    assert!(
        p.eval(
            "on",
            &[
                "akita_black_bowl_1".into(),
                "main_table_akita_black_bowl_region".into()
            ]
        )
        .unwrap()
    );
    // Drawers start at q = 0: not open, and (LIBERO's strict q > 0 rule) not "closed" either.
    assert!(
        !p.eval("open", &["wooden_cabinet_1_top_region".into()])
            .unwrap()
    );
    assert!(
        !p.eval("close", &["wooden_cabinet_1_top_region".into()])
            .unwrap()
    );
    assert!(!p.eval("turnon", &["flat_stove_1".into()]).unwrap());
    assert!(
        !p.eval("on", &["akita_black_bowl_1".into(), "plate_1".into()])
            .unwrap()
    );
    if std::env::var("SAVE_PNG").is_ok() {
        let f = sim::render::Frame {
            width: 128,
            height: 128,
            rgb: Some(obs.agentview_rgb.clone()),
            ..Default::default()
        };
        sim::render::save_png(&f, std::path::Path::new("/tmp/libero_goal.png")).unwrap();
    }
}
