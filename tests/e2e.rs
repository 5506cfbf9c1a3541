//! The whole loop on the CI config: generate T1 expert episodes in the simulator, train the tiny
//! model briefly (the loss must halve), and evaluate two closed-loop rollouts of its checkpoint (recording them and
//! writing slot overlays); the results table has the T1 row with numbers in [0, 100] and the
//! JSON parses back.

use std::path::Path;

#[test]
fn generate_train_eval_t1() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let task = sim::task::resolve("t1").unwrap();

    // 1. Generate: 4 expert episodes (one held out) at 128², as `sim generate` records them.
    let gen_cfg = sim::generate::GenerateConfig {
        episodes: 4,
        val: 1,
        seed: 0,
        workers: 2,
        ..Default::default()
    };
    let index = sim::generate::generate(&task, &data_dir, &gen_cfg, &|_| {}).unwrap();
    assert_eq!(index.episodes.len(), 4);

    // 2. Train the tiny model briefly.
    let run_dir = tmp.path().join("run");
    let cfg = e2e::tiny_config(&data_dir, 120);
    let summary = train::train(
        &cfg,
        &train::TrainOptions {
            run_dir: Some(run_dir.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.step, 120);
    let (first, last) = (summary.first_loss.unwrap(), summary.final_loss.unwrap());
    assert!(
        last.is_finite() && last < 0.5 * first,
        "the training loss must end below half its initial value: {first} → {last}"
    );

    // 3. Evaluate 2 rollouts of the checkpoint, recorded, with slot overlays of the first.
    let run = eval::RunDir::open(&run_dir).unwrap();
    assert_eq!(run.step, 120);
    let device = eval::run::device(&run, None).unwrap();
    let out = tmp.path().join("eval");
    let eval_cfg = eval::EvalConfig {
        episodes: 2,
        seed: 0,
        workers: 2,
        record: Some(out.join("rollouts")),
        viz: Some(out.join("viz")),
        viz_every: 50,
        ..Default::default()
    };
    let make = || -> Result<Box<dyn eval::Policy>, eval::EvalError> {
        Ok(Box::new(eval::run::policy(&run, &device)?))
    };
    let tasks = eval::resolve_tasks("t1", None).unwrap();
    let mut results = eval::evaluate(&tasks, &make, &eval_cfg, &|_| {}).unwrap();
    results.policy = "model".into();
    results.run = Some(run_dir.display().to_string());
    results.checkpoint_step = Some(run.step);

    let md = eval::report::markdown(&results.tasks);
    let json = serde_json::to_string_pretty(&results).unwrap();
    let report = e2e::report_dir();
    std::fs::create_dir_all(&report).unwrap();
    std::fs::write(
        report.join("results.md"),
        format!(
            "tiny model, {} steps on {} generated T1 episodes (loss {first:.3} → {last:.3}), 2 rollouts:\n\n{md}",
            summary.step,
            index.episodes.len()
        ),
    )
    .unwrap();

    // The table has the T1 row with numbers in [0, 100], and the JSON parses back.
    let row = md
        .lines()
        .find(|l| l.starts_with("| libero_mem/t1 | 2 |"))
        .unwrap_or_else(|| panic!("no T1 row in\n{md}"));
    let back: serde_json::Value = serde_json::from_str(&json).unwrap();
    let t1 = &back["tasks"][0];
    assert_eq!(t1["task"], "libero_mem/t1");
    for key in ["completion", "success"] {
        let v = t1[key].as_f64().unwrap();
        assert!((0.0..=100.0).contains(&v), "{key} = {v} in {row}");
    }
    let eps = back["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 2);
    for e in eps {
        let steps = e["steps"].as_u64().unwrap();
        assert!(steps >= 1 && steps <= task.max_steps as u64);
    }

    // Both rollouts were recorded as episodes the data crate reads back, step for step.
    let rec = out.join("rollouts").join("libero_mem-t1");
    for (k, e) in eps.iter().enumerate() {
        let path = rec.join(format!("episode_{k:06}.mcap"));
        let reader = data::EpisodeReader::open(&path).unwrap();
        assert_eq!(reader.meta().task_id, "libero_mem/t1");
        assert_eq!(reader.len() as u64, e["steps"].as_u64().unwrap());
    }
    // Slot overlays of the first rollout: one strip every 50 steps.
    let strips = count_png(&out.join("viz"));
    let first_steps = eps[0]["steps"].as_u64().unwrap() as usize;
    assert_eq!(strips, first_steps.div_ceil(50));
}

fn count_png(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "png")
        })
        .count()
}
