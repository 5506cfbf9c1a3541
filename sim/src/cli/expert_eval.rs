//! `sim expert-eval`: the scripted expert's success rate and episode lengths per task.

use std::path::PathBuf;

use anyhow::Context;

use sim::env::{Env, EnvConfig};

use super::{BadInput, check_out_dir, classify};

/// Runs `episodes` expert episodes per selected task and prints (and optionally writes) the table.
pub fn run(
    task: &str,
    episodes: usize,
    seed: u64,
    repeat: Option<usize>,
    markdown: Option<PathBuf>,
    verbose: bool,
    workers: usize,
) -> anyhow::Result<()> {
    if workers == 0 {
        return Err(BadInput("--workers must be at least 1".into()).into());
    }
    if episodes == 0 {
        return Err(BadInput("--episodes must be at least 1".into()).into());
    }
    if let Some(md) = &markdown {
        check_out_dir(md)?;
    }
    // eval's suite names (`libero_mem`, `libero_goal`, `all`, the pack's suites, task ids);
    // `mem` and `goal` stay as the old short forms.
    let spec: Vec<&str> = task
        .split(',')
        .map(|t| match t.trim() {
            "mem" => "libero_mem",
            "goal" => "libero_goal",
            other => other,
        })
        .collect();
    let tasks =
        sim::pack::resolve_suites(&spec.join(","), repeat).map_err(|e| BadInput(e.to_string()))?;
    if tasks.is_empty() {
        return Err(BadInput("no tasks given".into()).into());
    }
    let cfg = sim::expert::ExpertConfig::default();
    let header = format!(
        "| {:<54} | {:>4} | {:>8} | {:>6} | {:>9} | {:>8} | {:>6} | {:>6} |",
        "task", "goal", "episodes", "success", "tiered", "mean len", "max len", "budget"
    );
    let rule = format!(
        "|{}|{}|{}|{}|{}|{}|{}|{}|",
        "-".repeat(56),
        "-".repeat(6),
        "-".repeat(10),
        "-".repeat(9),
        "-".repeat(11),
        "-".repeat(10),
        "-".repeat(9),
        "-".repeat(8)
    );
    data::outln!("{header}\n{rule}");
    let t0 = std::time::Instant::now();
    let results: std::sync::Mutex<Vec<Option<Vec<sim::expert::EpisodeResult>>>> =
        std::sync::Mutex::new(vec![None; tasks.len()]);
    let run_task = |spec: &sim::task::TaskSpec| -> anyhow::Result<Vec<sim::expert::EpisodeResult>> {
        let mut env = Env::from_task(
            spec,
            EnvConfig {
                render: false,
                ..EnvConfig::default()
            },
        )
        .map_err(classify)?;
        let mut out = Vec::with_capacity(episodes);
        for k in 0..episodes {
            let s = seed + k as u64;
            let r = sim::expert::run_episode_in(&mut env, spec, s, &cfg)
                .with_context(|| format!("{} seed {s}", spec.id))?;
            if verbose {
                eprintln!(
                    "{} seed {s}: success {} steps {} tiered {:.2} ({})",
                    spec.id, r.success, r.steps, r.tiered, r.end
                );
            }
            out.push(r);
        }
        Ok(out)
    };
    data::pool::for_each(
        tasks.len(),
        workers,
        || Ok(()),
        |_, i| {
            let r = run_task(&tasks[i])?;
            results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
            Ok(())
        },
        || anyhow::anyhow!("an expert-eval worker panicked"),
    )?;
    let results = results.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut rows = Vec::new();
    let (mut total_eps, mut total_steps) = (0usize, 0usize);
    for (spec, res) in tasks.iter().zip(results) {
        let res = res.context("a task was not run")?;
        let ok = res.iter().filter(|r| r.success).count();
        let tiered: f64 = res.iter().map(|r| r.tiered).sum();
        let lens: Vec<usize> = res.iter().map(|r| r.steps).collect();
        total_steps += lens.iter().sum::<usize>();
        total_eps += episodes;
        let mean = lens.iter().sum::<usize>() as f64 / lens.len() as f64;
        let max = lens.iter().copied().max().unwrap_or(0);
        let row = format!(
            "| {:<54} | {:>4} | {:>8} | {:>6.1}% | {:>9.3} | {:>8.1} | {:>7} | {:>6} |",
            spec.id,
            spec.goal_len,
            episodes,
            100.0 * ok as f64 / episodes as f64,
            tiered / episodes as f64,
            mean,
            max,
            spec.max_steps
        );
        data::outln!("{row}");
        rows.push(row);
    }
    let secs = t0.elapsed().as_secs_f64();
    let thr = format!(
        "{total_eps} episodes, {total_steps} steps in {secs:.1} s: {:.1} episodes/min, {:.0} steps/s ({workers} worker thread{}, rendering off)",
        total_eps as f64 * 60.0 / secs,
        total_steps as f64 / secs,
        if workers == 1 { "" } else { "s" }
    );
    data::outln!("\n{thr}");
    if let Some(md) = markdown {
        let mut s = String::new();
        s.push_str("# Scripted expert: success and episode lengths\n\n");
        s.push_str(&format!(
            "Regenerate with `cargo run --release -p sim -- expert-eval --task {task} --episodes {episodes} --seed {seed}{} --markdown {}` (add `--workers 2` to run two tasks at a time; the table does not depend on it).\n\n",
            repeat.map(|n| format!(" --repeat {n}")).unwrap_or_default(),
            md.display()
        ));
        s.push_str(&format!(
            "Seeds {seed}..{}; success = the goal tracker reports done (and no over-repetition) when the expert finishes; tiered = mean satisfied/goal length; lengths in control steps (20 Hz) including the final hold; budget = the task's step limit.\n\n",
            seed + episodes as u64 - 1
        ));
        s.push_str(&header);
        s.push('\n');
        s.push_str(&rule);
        s.push('\n');
        for r in &rows {
            s.push_str(r);
            s.push('\n');
        }
        s.push_str(&format!("\nThroughput: {thr}.\n\n"));
        s.push_str(sim::expert::NOTES);
        data::fsio::write_atomic(&md, s.as_bytes())
            .with_context(|| format!("writing {}", md.display()))?;
    }
    Ok(())
}
