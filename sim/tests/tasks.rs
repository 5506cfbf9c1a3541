//! Every shipped task: composes, resets validly for 20 seeds, tracks its goal.

use sim::env::MAX_PENETRATION;
use sim::task::registry;
use sim::{Env, EnvConfig};

fn state_only() -> EnvConfig {
    EnvConfig {
        render: false,
        ..EnvConfig::default()
    }
}

#[test]
fn twenty_tasks_are_shipped() {
    let tasks = registry::list();
    assert_eq!(tasks.len(), 20);
    assert_eq!(
        tasks
            .iter()
            .filter(|t| t.id.starts_with("libero_mem/"))
            .count(),
        10
    );
}

#[test]
fn every_task_resets_validly_for_20_seeds() {
    for task in registry::list() {
        let mut env =
            Env::from_task(&task, state_only()).unwrap_or_else(|e| panic!("{}: {e}", task.id));
        for seed in 0..20u64 {
            let obs = env
                .reset(seed)
                .unwrap_or_else(|e| panic!("{} seed {seed}: {e}", task.id));
            let scene = env.scene().unwrap();
            let p = env.predicates().unwrap();
            for atom in &scene.spec.init {
                assert!(
                    p.eval(atom.predicate, &atom.args).unwrap(),
                    "{} seed {seed}: ({atom}) false",
                    task.id
                );
            }
            for c in env.data().contacts() {
                assert!(
                    c.dist > -MAX_PENETRATION,
                    "{} seed {seed}: interpenetration {c:?}",
                    task.id
                );
            }
            let goal = obs.goal.expect("task envs report goal progress");
            assert_eq!(goal.goal_len, task.goal_len);
            assert_eq!(goal.satisfied, 0, "{} seed {seed}", task.id);
            assert!(!goal.failed);
        }
    }
}

#[test]
fn resets_are_deterministic() {
    let task = registry::resolve("t8").unwrap();
    let mut a = Env::from_task(
        &task,
        EnvConfig {
            image_size: 64,
            ..EnvConfig::default()
        },
    )
    .unwrap();
    let mut b = Env::from_task(
        &task,
        EnvConfig {
            image_size: 64,
            ..EnvConfig::default()
        },
    )
    .unwrap();
    let (oa, ob) = (a.reset(11).unwrap(), b.reset(11).unwrap());
    assert_eq!(oa, ob);
    assert_eq!(a.data().qpos(), b.data().qpos());
    let oc = b.reset(12).unwrap();
    assert_ne!(oa.agentview_rgb, oc.agentview_rgb);
}

#[test]
fn goal_progress_is_reported_with_pending_text() {
    let task = registry::resolve("t7").unwrap();
    let mut env = Env::from_task(&task, state_only()).unwrap();
    let obs = env.reset(0).unwrap();
    let g = obs.goal.unwrap();
    assert_eq!((g.satisfied, g.goal_len, g.done), (0, 3, false));
    assert_eq!(g.pending.as_deref(), Some("bowl 1 on plate 3"));
    let obs = env.step(&[0.0; 7]).unwrap();
    assert_eq!(obs.goal.unwrap().satisfied, 0);
}

#[test]
fn repeats_and_user_files_and_bad_ids() {
    let t = registry::resolve("t3@12").unwrap();
    assert_eq!(t.goal_len, 12);
    let env = Env::from_task(&t, state_only()).unwrap();
    assert_eq!(env.goal().unwrap().goal_len, 12);
    let e = registry::resolve("t11").unwrap_err().to_string();
    assert!(
        e.contains("libero_mem/t1") && e.contains("libero_goal/turn_on_the_stove"),
        "{e}"
    );
    // A user file naming an object the asset library lacks.
    let dir = std::env::temp_dir().join(format!("sim-tasks-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("teapot.bddl");
    let text = registry::resolve("libero_goal/turn_on_the_stove")
        .unwrap()
        .bddl_text
        .replace("cream_cheese_1 - cream_cheese", "cream_cheese_1 - teapot");
    std::fs::write(&path, text).unwrap();
    let t = registry::resolve(path.to_str().unwrap()).unwrap();
    let e = Env::from_task(&t, state_only()).err().unwrap().to_string();
    assert!(e.contains("teapot") && e.contains("cream_cheese_1"), "{e}");
}
