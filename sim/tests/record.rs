//! Recording an Env rollout as an mcap episode and reading it back.

use sim::record::Recorder;
use sim::task::registry;
use sim::{Env, EnvConfig};

/// Task `id` with 32² cameras and segmentation, as `sim generate` records it.
fn task_env(id: &str) -> (sim::task::TaskSpec, Env) {
    let task = registry::resolve(id).unwrap();
    let cfg = EnvConfig {
        image_size: 32,
        segmentation: true,
        ..EnvConfig::default()
    };
    let env = Env::from_task(&task, cfg).unwrap();
    (task, env)
}

/// T1, as [`task_env`].
fn t1_env() -> (sim::task::TaskSpec, Env) {
    task_env("t1")
}

/// The expert's demonstration of `task` at seed 0 recorded under `dir` (asserted to succeed:
/// `what` says what it does) and opened.
fn expert_episode(
    task: &sim::task::TaskSpec,
    env: &mut Env,
    dir: &std::path::Path,
    what: &str,
) -> data::EpisodeReader {
    let path = dir.join("ep.mcap");
    assert!(
        sim::generate::record_episode(
            env,
            task,
            0,
            &path,
            Default::default(),
            &Default::default(),
            false,
        )
        .unwrap(),
        "the expert {what} at seed 0"
    );
    data::EpisodeReader::open(&path).unwrap()
}

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
    // Schema 2: every instance's privileged pose at the step's observation, unit quaternion.
    for o in &step.objects {
        let p = o.pose.expect("pose recorded");
        let norm: f32 = p[3..].iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-4, "{}: {p:?}", o.name);
        assert!(p[2] > 0.5 && p[2] < 1.5, "{}: z {}", o.name, p[2]);
        assert_eq!(o.grasped, Some(false), "{}", o.name);
    }
}

/// The expert's T1 demonstration: the recorded poses follow the simulator's state at each
/// observation, and the bowl is flagged as grasped while it is carried, and only then.
#[test]
fn recorded_poses_track_the_objects_and_the_grasp() {
    let (task, mut env) = t1_env();
    let dir = tempfile::tempdir().unwrap();
    let reader = expert_episode(&task, &mut env, dir.path(), "solves T1");
    let steps: Vec<data::StepRecord> = (0..reader.len())
        .map(|k| reader.read_step(k).unwrap())
        .collect();
    // Replay the actions: each step's recorded poses are the state of its observation.
    let mut obs = env.reset(0).unwrap();
    for (k, st) in steps.iter().enumerate() {
        for (o, s) in st.objects.iter().zip(&obs.objects) {
            assert_eq!(o.pose, Some(s.pose()), "step {k} {}", o.name);
            assert_eq!(o.grasped, Some(s.grasped), "step {k} {}", o.name);
        }
        obs = env.step(&st.action).unwrap();
    }
    let bowl = |st: &data::StepRecord| st.objects[0].clone();
    let held: Vec<usize> = (0..steps.len())
        .filter(|&k| bowl(&steps[k]).grasped == Some(true))
        .collect();
    assert!(held.len() > 10, "the bowl is held for {} steps", held.len());
    let lifted = held
        .iter()
        .any(|&k| bowl(&steps[k]).pose.unwrap()[2] > bowl(&steps[0]).pose.unwrap()[2] + 0.03);
    assert!(lifted, "the bowl rises while it is held");
    assert_eq!(bowl(&steps[0]).grasped, Some(false));
    assert!(
        steps
            .iter()
            .flat_map(|s| &s.objects[1..])
            .all(|o| o.grasped == Some(false)),
        "only the bowl is grasped"
    );
}

/// Schema 3: the cabinet's drawers and the stove's knob are recorded as parts, and the expert's
/// pull shows in the middle handle's place and joint (and nowhere else).
#[test]
fn drawer_parts_follow_the_pull() {
    let (task, mut env) = task_env("libero_goal/open_the_middle_drawer_of_the_cabinet");
    let dir = tempfile::tempdir().unwrap();
    let reader = expert_episode(&task, &mut env, dir.path(), "opens the drawer");
    let (first, last) = (
        reader.read_step(0).unwrap(),
        reader.read_step(reader.len() - 1).unwrap(),
    );
    let parts = |st: &data::StepRecord, name: &str| -> Vec<data::PartState> {
        st.objects
            .iter()
            .find(|o| o.name == name)
            .unwrap_or_else(|| panic!("{name} in the scene"))
            .parts
            .clone()
    };
    let names = |p: &[data::PartState]| p.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    let (c0, c1) = (
        parts(&first, "wooden_cabinet_1"),
        parts(&last, "wooden_cabinet_1"),
    );
    assert_eq!(names(&c0), ["top_handle", "middle_handle", "bottom_handle"]);
    assert_eq!(names(&parts(&first, "flat_stove_1")), ["knob"]);
    assert!(
        parts(&first, "akita_black_bowl_1").is_empty(),
        "a bowl has no parts"
    );
    // Closed at the start, the handles stacked 7 cm apart in front of the cabinet.
    assert!(c0.iter().all(|p| p.joint.abs() < 1e-3), "{c0:?}");
    assert!(
        (c0[0].pose[2] - c0[1].pose[2] - 0.0687).abs() < 2e-3,
        "{c0:?}"
    );
    // The middle drawer comes out by more than the 14 cm `Open` needs; its handle moves as much.
    assert!(c1[1].joint < -0.14, "{:?}", c1[1]);
    let moved = |a: &data::PartState, b: &data::PartState| {
        (0..3)
            .map(|d| (a.pose[d] - b.pose[d]).powi(2))
            .sum::<f32>()
            .sqrt()
    };
    assert!((moved(&c0[1], &c1[1]) - c1[1].joint.abs()).abs() < 0.01);
    assert!(
        c1[0].joint.abs() < 0.01 && c1[2].joint.abs() < 0.01,
        "{c1:?}"
    );
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

/// DART (`exec_noise`): the arm is pushed off the nominal path while the expert moves with the
/// gripper open, and the recorded actions are its clean corrections. Stepping the recorded actions therefore leaves
/// the recorded states, while stepping the expert's perturbed actions (same seed, same noise
/// stream) reproduces every recorded state and label; the expert still solves the task, and
/// the same seed gives the same bytes.
#[test]
fn execution_noise_records_clean_corrections_of_perturbed_moves() {
    let (task, mut env) = t1_env();
    let dir = tempfile::tempdir().unwrap();
    let expert = sim::expert::ExpertConfig {
        exec_noise: 0.1,
        ..sim::generate::plain_expert()
    };
    let record = |env: &mut Env, name: &str| {
        let path = dir.path().join(name);
        let ok =
            sim::generate::record_episode(env, &task, 0, &path, Default::default(), &expert, false)
                .unwrap();
        assert!(ok, "the perturbed expert solves T1 seed 0");
        path
    };
    let (a, b) = (record(&mut env, "a.mcap"), record(&mut env, "b.mcap"));
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let steps = data::EpisodeReader::open(&a).unwrap().read_all().unwrap();

    // The expert's own loop: clean labels, perturbed execution.
    let mut obs = env.reset(0).unwrap();
    let mut ex = sim::expert::Expert::with_config(&task, 0, expert.clone());
    let mut pushed = 0;
    for (k, st) in steps.iter().enumerate() {
        for (o, s) in st.objects.iter().zip(&obs.objects) {
            assert_eq!(o.pose, Some(s.pose()), "step {k} {}", o.name);
        }
        let clean = ex
            .act(&env, &obs)
            .expect("the expert acts at every recorded step");
        assert_eq!(st.action, clean, "step {k}: the label is the clean action");
        let run = ex.executed(clean);
        pushed += usize::from(run != clean);
        if clean[6] > 0.0 {
            assert_eq!(run, clean, "step {k}: no push while the gripper is closed");
        }
        assert!(
            run.iter().all(|v| (-1.0..=1.0).contains(v)),
            "step {k}: {run:?}"
        );
        assert_eq!(
            run[3..],
            clean[3..],
            "step {k}: only the translation is pushed"
        );
        obs = env.step(&run).unwrap();
    }
    assert!(
        pushed > steps.len() / 3,
        "{pushed} of {} steps pushed",
        steps.len()
    );

    // Replaying the labels alone drifts from the recorded states.
    let mut obs = env.reset(0).unwrap();
    let mut drift = 0f32;
    for st in &steps {
        let hand = [
            obs.eef_pos[0] as f32,
            obs.eef_pos[1] as f32,
            obs.eef_pos[2] as f32,
        ];
        drift = drift.max(
            (0..3)
                .map(|i| (hand[i] - st.state[i]).abs())
                .fold(0.0, f32::max),
        );
        obs = env.step(&st.action).unwrap();
    }
    assert!(
        drift > 1e-3,
        "labels replayed follow the perturbed path (drift {drift})"
    );
}
