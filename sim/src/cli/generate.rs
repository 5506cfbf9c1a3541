//! `sim generate`: scripted-expert demonstrations recorded as mcap episodes plus the dataset index.

use std::path::PathBuf;

use super::BadInput;

/// Generates `cfg.episodes` episodes (of which `cfg.val` validation) of `task` into `out`; for a suite
/// (`libero_mem`, `libero_goal`, `all` or a comma list) that many of every task, one subfolder
/// each, and the suite's index over all of them (one multi-task dataset).
pub fn run(task: String, out: PathBuf, cfg: sim::generate::GenerateConfig) -> anyhow::Result<()> {
    let episodes = cfg.episodes;
    let tasks = sim::pack::resolve_suites(&task, None).map_err(|e| BadInput(e.to_string()))?;
    if tasks.is_empty() {
        return Err(BadInput(format!("--task `{task}` names no task")).into());
    }

    for t in &tasks {
        let dir = if tasks.len() > 1 {
            out.join(sim::generate::suite_folder(t))
        } else {
            out.clone()
        };
        let bar = indicatif::ProgressBar::new(episodes as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{prefix} {bar:30} {pos}/{len} episodes  {msg}  ETA {eta}",
            )
            .expect("valid template"),
        );
        bar.set_prefix(t.id.clone());
        let start = std::time::Instant::now();
        let on_progress = |p: sim::generate::GenerateProgress| {
            bar.set_position(p.done as u64);
            bar.set_message(format!(
                "{} ok, {} failed attempts",
                p.successes, p.failures
            ));
        };
        let classify = |e| match e {
            sim::generate::GenerateError::Argument(m) => anyhow::Error::new(BadInput(m)),
            e if e.is_bad_input() => anyhow::Error::new(BadInput(e.to_string())),
            other => other.into(),
        };
        if !cfg.shard.is_whole() {
            bar.set_length(cfg.shard.items(episodes).len() as u64);
            let n =
                sim::generate::generate_episodes(t, &dir, &cfg, &on_progress).map_err(classify)?;
            bar.finish_and_clear();
            data::outln!(
                "{}: shard {}: {n} episodes in {} in {:.1} s (no index: once every shard is done, \
                 the same command without --shard writes it)",
                t.id,
                cfg.shard,
                dir.display(),
                start.elapsed().as_secs_f64()
            );
            continue;
        }
        let index = sim::generate::generate(t, &dir, &cfg, &on_progress).map_err(classify)?;
        bar.finish_and_clear();
        let steps: usize = index.episodes.iter().map(|e| e.length).sum();
        data::outln!(
            "{}: {} episodes ({} steps) in {} in {:.1} s",
            t.id,
            index.episodes.len(),
            steps,
            dir.display(),
            start.elapsed().as_secs_f64()
        );
    }
    if tasks.len() > 1 && cfg.shard.is_whole() {
        // Every task is recorded above: only the suite's index is left.
        let index = sim::generate::write_index(&out, &cfg)?;
        data::outln!(
            "suite index: {} episodes of {} tasks in {}",
            index.episodes.len(),
            tasks.len(),
            out.display()
        );
    }
    Ok(())
}
