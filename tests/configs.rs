//! Every config the repository ships fits the rest of the workspace: the training configs under
//! `configs/`, `configs/state/` and `configs/gpu/` name tasks the simulator knows, and every run an
//! experiment file under `configs/experiments/` plans (its config, its `set` overrides and each
//! variant) loads as `eval experiment` will hand it to `train`, in the observation mode the
//! experiment files it under.

use std::path::{Path, PathBuf};

/// Every entry directly in `dir`, sorted.
fn entries(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    out.sort();
    out
}

/// The `*.toml` files directly in `dir`, sorted.
fn tomls(dir: &Path) -> Vec<PathBuf> {
    entries(dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect()
}

/// Checks what the simulator must know of a loaded training config: its evaluation tasks and the
/// task its dataset is generated from.
fn check_tasks(path: &Path, cfg: &train::Config) {
    for t in &cfg.eval.tasks {
        if let Err(e) = eval::resolve_tasks(t, None) {
            panic!("{}: [eval].tasks `{t}`: {e}", path.display());
        }
    }
    if let Some(g) = &cfg.data.generate
        && let Err(e) = eval::resolve_tasks(&g.task, None)
    {
        panic!("{}: data.generate.task `{}`: {e}", path.display(), g.task);
    }
}

/// The training configs' tasks are the simulator's (`train`'s own test checks that they load and
/// are named as their files; it cannot ask the simulator).
#[test]
fn every_training_config_names_known_tasks() {
    let mut n = 0;
    for dir in ["configs", "configs/state", "configs/gpu"] {
        for path in tomls(&e2e::repo_root().join(dir)) {
            let cfg = train::Config::load(&path)
                .unwrap_or_else(|e| panic!("{} does not load: {e}", path.display()));
            check_tasks(&path, &cfg);
            n += 1;
        }
    }
    assert!(n >= 29, "only {n} training configs found");
}

#[test]
fn every_experiment_run_loads_as_train_will_see_it() {
    let files = tomls(&e2e::repo_root().join("configs/experiments"));
    assert!(files.len() >= 2, "experiment files: {files:?}");
    let mut planned = 0;
    for file in files {
        let x = eval::experiment::Experiment::load(&file)
            .unwrap_or_else(|e| panic!("{} does not load: {e}", file.display()));
        for p in x.plan() {
            let spec = p.spec;
            let config = e2e::repo_root().join(&spec.config);
            let sets = eval::experiment::train_overrides(&p);
            let cfg = train::Config::load_with(&config, &sets).unwrap_or_else(|e| {
                panic!(
                    "{}: run `{}` ({} with {:?}) does not load: {e}",
                    file.display(),
                    p.name,
                    spec.config.display(),
                    sets
                )
            });
            check_tasks(&config, &cfg);
            assert_eq!(
                cfg.model.obs.is_pixels(),
                spec.obs == "pixels",
                "{}: run `{}` is filed under obs = `{}` but its config is not",
                file.display(),
                p.name,
                spec.obs
            );
            if let Err(e) = eval::resolve_tasks(&spec.suite, None) {
                panic!(
                    "{}: run `{}`: suite `{}`: {e}",
                    file.display(),
                    p.name,
                    spec.suite
                );
            }
            planned += 1;
        }
    }
    assert!(planned >= 50, "only {planned} planned runs");
}

/// The probe scenes under `configs/probes/` (README, "Carries to a target that varies are learnt
/// late") load as tasks from their paths, with the subgoal counts their headers describe.
#[test]
fn probe_scenes_load_as_tasks() {
    let dir = e2e::repo_root().join("configs/probes");
    let want = [
        ("bowl_fixed_plate_wide.bddl", 1),
        ("bowl_to_plate_wide.bddl", 1),
        ("t7_first_move.bddl", 1),
        ("t7_two_moves.bddl", 2),
    ];
    let found: Vec<PathBuf> = entries(&dir);
    assert_eq!(found, want.map(|(f, _)| dir.join(f)));
    for (file, goal_len) in want {
        let path = dir.join(file);
        let task = sim::task::resolve(&path.to_string_lossy())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(task.goal_len, goal_len, "{file}");
        assert!(task.max_steps > 0, "{file}");
    }
}
