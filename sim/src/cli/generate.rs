//! `sim generate`: scripted-expert demonstrations recorded as mcap episodes plus the dataset index.

use std::path::{Path, PathBuf};

use super::BadInput;

fn task_dir(tasks: &[sim::task::TaskSpec], out: &Path, t: &sim::task::TaskSpec) -> PathBuf {
    if tasks.len() > 1 {
        out.join(sim::generate::suite_folder(t))
    } else {
        out.to_path_buf()
    }
}

/// The progress bar of `total` episodes, `prefix` before it.
fn episodes_bar(total: u64, prefix: String) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{prefix} {bar:30} {pos}/{len} episodes  {msg}  ETA {eta}",
        )
        .expect("valid template"),
    );
    bar.set_prefix(prefix);
    bar
}

/// Records every episode of `tasks` with `cfg.workers` processes of this program, process i the
/// same command with `--shard i/N --workers 1` (one simulator and one GL context each: llvmpipe
/// renders one frame at a time per process, so threads would queue for it). The directories are
/// claimed here first (and emptied with `--force`); the progress bar counts finished episodes.
fn record_in_processes(
    tasks: &[sim::task::TaskSpec],
    out: &Path,
    cfg: &sim::generate::GenerateConfig,
) -> anyhow::Result<()> {
    let n = cfg.workers;
    let dirs: Vec<PathBuf> = tasks.iter().map(|t| task_dir(tasks, out, t)).collect();
    for (t, dir) in tasks.iter().zip(&dirs) {
        sim::generate::prepare_dir(t, dir, cfg).map_err(|e| match e {
            sim::generate::GenerateError::Argument(m) => anyhow::Error::new(BadInput(m)),
            e if e.is_bad_input() => anyhow::Error::new(BadInput(e.to_string())),
            other => other.into(),
        })?;
    }
    // This command's arguments without --force (done above), then the shard's overrides.
    let args = data::procs::own_args(&["--force"]);
    let logs = tempfile::tempdir()?;
    let total = (tasks.len() * cfg.episodes) as u64;
    let bar = episodes_bar(total, format!("{n} processes"));
    let shard_args = |i: usize| {
        let mut a = args.clone();
        a.extend(["--workers", "1", "--shard", &format!("{i}/{n}")].map(Into::into));
        a
    };
    let count_done = || {
        let done: usize = dirs
            .iter()
            .map(|d| {
                (0..cfg.episodes)
                    .filter(|&k| sim::generate::episode_path(d, k).exists())
                    .count()
            })
            .sum();
        bar.set_position(done as u64);
    };
    let ran = data::procs::run_all(n, logs.path(), shard_args, count_done);
    bar.finish_and_clear();
    // One failed shard stops the others: their finished episodes stay for a rerun.
    ran.map_err(|f| {
        if f.is_bad_input() {
            anyhow::Error::new(BadInput(f.to_string()))
        } else {
            anyhow::Error::new(f)
        }
    })
}

/// Generates `cfg.episodes` episodes (of which `cfg.val` validation) of `task` into `out`; for a suite
/// (`libero_mem`, `libero_goal`, `all` or a comma list) that many of every task, one subfolder
/// each, and the suite's index over all of them (one multi-task dataset).
pub fn run(task: String, out: PathBuf, cfg: sim::generate::GenerateConfig) -> anyhow::Result<()> {
    let episodes = cfg.episodes;
    let tasks = sim::pack::resolve_suites(&task, None).map_err(|e| BadInput(e.to_string()))?;
    if tasks.is_empty() {
        return Err(BadInput(format!("--task `{task}` names no task")).into());
    }
    let mut cfg = cfg;
    let started = std::time::Instant::now();
    let mut by_processes = None;
    if cfg.workers > 1 && cfg.shard.is_whole() {
        record_in_processes(&tasks, &out, &cfg)?;
        by_processes = Some((cfg.workers, started.elapsed().as_secs_f64()));
        // What is left: the indices, from the episodes the processes recorded.
        cfg.workers = 1;
        cfg.force = false;
    }

    for t in &tasks {
        let dir = task_dir(&tasks, &out, t);
        let bar = episodes_bar(episodes as u64, t.id.clone());
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
        let took = match by_processes {
            Some((n, secs)) if tasks.len() == 1 => format!("in {secs:.1} s by {n} processes"),
            Some((n, _)) => format!("by {n} processes"),
            None => format!("in {:.1} s", start.elapsed().as_secs_f64()),
        };
        data::outln!(
            "{}: {} episodes ({} steps) in {} {took}",
            t.id,
            index.episodes.len(),
            steps,
            dir.display(),
        );
    }
    if tasks.len() > 1 && cfg.shard.is_whole() {
        // Every task is recorded above: only the suite's index is left.
        let index = sim::generate::write_index(&out, &cfg)?;
        data::outln!(
            "suite index: {} episodes of {} tasks in {} ({:.1} s)",
            index.episodes.len(),
            tasks.len(),
            out.display(),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
