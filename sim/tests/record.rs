//! Recording an Env rollout as an mcap episode and reading it back.

use sim::record::Recorder;
use sim::task::registry;
use sim::{Env, EnvConfig};

#[test]
fn a_rollout_round_trips_through_mcap() {
    let task = registry::resolve("t1").unwrap();
    let cfg = EnvConfig {
        image_size: 64,
        segmentation: true,
        depth: true,
        ..EnvConfig::default()
    };
    let mut env = Env::from_task(&task, cfg).unwrap();
    let mut obs = env.reset(5).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ep.mcap");
    let mut rec = Recorder::create(&path, &env, &task, 5, Default::default()).unwrap();
    let mut actions = Vec::new();
    for t in 0..12 {
        let a = [
            0.3 * ((t as f32) * 0.5).sin(),
            0.0,
            -0.2,
            0.0,
            0.0,
            0.0,
            -1.0,
        ];
        let next = env.step(&a).unwrap();
        rec.record(&env, &obs, a, &next).unwrap();
        actions.push(a);
        obs = next;
    }
    assert!(!path.exists(), "the final name appears only at finish");
    let written = rec.finish().unwrap();
    assert_eq!(written, path);

    let reader = data::EpisodeReader::open(&path).unwrap();
    assert_eq!(reader.len(), 12);
    assert_eq!(reader.meta().task_id, "libero_mem/t1");
    assert_eq!(reader.meta().seed, 5);
    let step = reader.read_step(7).unwrap();
    assert_eq!(step.step, 7);
    assert_eq!(step.action, actions[7]);
    assert_eq!((step.agentview.width, step.agentview.height), (64, 64));
    assert!(step.depth.is_some() && step.segmentation.is_some());
    let names: Vec<_> = step.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "akita_black_bowl_1",
            "wine_bottle_1",
            "plate_1",
            "plate_2",
            "plate_3",
            "wooden_cabinet_1"
        ]
    );
    let bowl = &step.objects[0];
    assert!(
        bowl.visible && bowl.bbox[2] > 0.0 && bowl.bbox[3] > 0.0,
        "{bowl:?}"
    );
    assert_eq!(bowl.subgoal_label, "0");
    assert_eq!(step.progress.total, 1);
    assert_eq!(step.progress.current_subgoal, "bowl 1 on plate 1");
}

#[test]
fn recording_needs_segmentation() {
    let task = registry::resolve("t1").unwrap();
    let env = Env::from_task(
        &task,
        EnvConfig {
            image_size: 32,
            ..EnvConfig::default()
        },
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let e = Recorder::create(
        &dir.path().join("x.mcap"),
        &env,
        &task,
        0,
        Default::default(),
    )
    .err()
    .unwrap();
    assert!(e.to_string().contains("segmentation"), "{e}");
}
