//! Episode results, per-task summaries and the tables: one run (Markdown, CSV, JSON), several runs
//! side by side (`eval compare`) and completion against the repetition count (`eval scaling`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::EvalError;

/// The outcome of one rollout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeResult {
    /// Task id.
    pub task: String,
    /// Episode index within the task.
    pub episode: usize,
    /// Seed used for the reset.
    pub seed: u64,
    /// Policy steps taken.
    pub steps: usize,
    /// Satisfied subgoals.
    pub satisfied: usize,
    /// Goal length.
    pub goal_len: usize,
    /// Success (see the crate docs for the two protocols).
    pub success: bool,
    /// Over-repetition after completion.
    pub over_repetition: bool,
}

impl EpisodeResult {
    /// Tiered credit in [0, 1].
    pub fn tiered(&self) -> f64 {
        self.satisfied as f64 / self.goal_len.max(1) as f64
    }
}

/// Per-task summary row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskSummary {
    /// Task id.
    pub task: String,
    /// Episodes run.
    pub episodes: usize,
    /// Mean subgoal completion (tiered credit), percent.
    pub completion: f64,
    /// Half-width of the 95 % confidence interval of `completion` (normal approximation), percent.
    pub completion_ci95: f64,
    /// Success rate, percent.
    pub success: f64,
    /// 95 % Wilson interval of the success rate, percent.
    pub success_ci95: [f64; 2],
    /// Mean steps per episode.
    pub mean_steps: f64,
    /// Episodes that failed by over-repetition.
    pub over_repetition: usize,
}

/// Everything one evaluation produced: what `results.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Results {
    /// Policy evaluated (`model`, `expert`, `random`, `zero`).
    pub policy: String,
    /// Run directory of a model policy.
    pub run: Option<String>,
    /// Training step of the evaluated checkpoint.
    pub checkpoint_step: Option<u64>,
    /// How a model's action chunks were executed (`eval --execute`), when not the first action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub execution: Option<String>,
    /// Base seed.
    pub seed: u64,
    /// Episodes per task.
    pub episodes_per_task: usize,
    /// Whether every episode ran its whole step budget.
    pub full_budget: bool,
    /// The shard these results cover (absent: the whole run).
    #[serde(default, skip_serializing_if = "data::shard::Shard::is_whole")]
    pub shard: data::shard::Shard,
    /// Per-task rows.
    pub tasks: Vec<TaskSummary>,
    /// Every episode.
    pub episodes: Vec<EpisodeResult>,
}

impl Results {
    /// Reads `results.json` from `path`, or from `path/results.json`, or `path/eval/results.json`
    /// (a run directory evaluated with the default output folder).
    pub fn load(path: &Path) -> Result<(PathBuf, Results), EvalError> {
        let candidates = [
            path.to_path_buf(),
            path.join("results.json"),
            path.join("eval").join("results.json"),
        ];
        let file = candidates
            .iter()
            .find(|p| p.is_file())
            .ok_or_else(|| EvalError::Results {
                path: path.to_path_buf(),
                message: "no results.json there (nor in its eval/ folder); run `eval` first".into(),
            })?;
        let text = std::fs::read_to_string(file).map_err(|e| EvalError::Results {
            path: file.clone(),
            message: e.to_string(),
        })?;
        let r = serde_json::from_str(&text).map_err(|e| EvalError::Results {
            path: file.clone(),
            message: format!("not an eval results file: {e}"),
        })?;
        Ok((file.clone(), r))
    }
}

/// The line above a results table: what was evaluated and how (`model runs/x (step 4000), seed
/// 1000, 20 episodes per task, full step budget`), then a blank line.
pub fn header(
    policy: &str,
    run: Option<(&str, u64)>,
    seed: u64,
    episodes: usize,
    full_budget: bool,
    shard: data::shard::Shard,
) -> String {
    let who = match run {
        Some((dir, step)) => format!("model {dir} (step {step})"),
        None => format!("{policy} policy"),
    };
    format!(
        "{who}, seed {seed}, {episodes} episodes per task{}{}\n\n",
        if full_budget {
            ", full step budget"
        } else {
            ""
        },
        if shard.is_whole() {
            String::new()
        } else {
            format!(
                ", shard {shard} (episodes k with k mod {} = {})",
                shard.count, shard.index
            )
        }
    )
}

impl Results {
    /// [`header`] of these results.
    pub fn header(&self) -> String {
        header(
            &self.policy,
            self.run.as_deref().zip(self.checkpoint_step),
            self.seed,
            self.episodes_per_task,
            self.full_budget,
            self.shard,
        )
    }

    /// `results.md`: the header and the table.
    pub fn markdown(&self) -> String {
        let mut head = self.header();
        if let Some(e) = &self.execution {
            head = format!("{}, chunks executed: {e}\n\n", head.trim_end());
        }
        format!("{head}{}", markdown(&self.tasks))
    }
}

/// Joins the results of the shards `0/N … (N−1)/N` of one evaluation (each with the file it was
/// read from, for errors) into the results of the unsharded evaluation: the same episodes, rows
/// and order, as if it had run in one process. Refuses parts of different evaluations (policy,
/// run, checkpoint, seed, episode count, protocol, tasks), a shard missing or given twice, and
/// an episode missing, repeated or outside its shard.
pub fn merge(parts: &[(PathBuf, Results)]) -> Result<Results, EvalError> {
    let Some((first_path, first)) = parts.first() else {
        return Err(EvalError::Argument("no results to merge".into()));
    };
    let bad = |path: &Path, message: String| EvalError::Results {
        path: path.to_path_buf(),
        message,
    };
    let count = first.shard.count;
    let tasks: Vec<&str> = first.tasks.iter().map(|t| t.task.as_str()).collect();
    let mut owner: Vec<Option<&Path>> = vec![None; count];
    for (path, r) in parts {
        let differs = [
            ("policy", r.policy != first.policy),
            ("run", r.run != first.run),
            (
                "checkpoint step",
                r.checkpoint_step != first.checkpoint_step,
            ),
            ("seed", r.seed != first.seed),
            (
                "episodes per task",
                r.episodes_per_task != first.episodes_per_task,
            ),
            ("full-budget protocol", r.full_budget != first.full_budget),
            ("shard count", r.shard.count != count),
            (
                "tasks",
                r.tasks
                    .iter()
                    .map(|t| t.task.as_str())
                    .ne(tasks.iter().copied()),
            ),
        ];
        if let Some((what, _)) = differs.iter().find(|(_, d)| *d) {
            return Err(bad(
                path,
                format!(
                    "not a shard of the same evaluation as {}: its {what} differs",
                    first_path.display()
                ),
            ));
        }
        let i = r.shard.index;
        if let Some(other) = owner[i] {
            return Err(bad(
                path,
                format!(
                    "shard {} is given twice (also {})",
                    r.shard,
                    other.display()
                ),
            ));
        }
        owner[i] = Some(path);
        if let Some(e) = r.episodes.iter().find(|e| !r.shard.owns(e.episode)) {
            return Err(bad(
                path,
                format!(
                    "{} episode {} is not shard {}'s",
                    e.task, e.episode, r.shard
                ),
            ));
        }
    }
    if let Some(i) = owner.iter().position(Option::is_none) {
        return Err(EvalError::Argument(format!(
            "shard {i}/{count} is missing (give all {count} shards' results)"
        )));
    }
    let n = first.episodes_per_task;
    let mut rows = Vec::with_capacity(tasks.len());
    let mut episodes = Vec::with_capacity(tasks.len() * n);
    for task in &tasks {
        let mut eps: Vec<(&Path, &EpisodeResult)> = parts
            .iter()
            .flat_map(|(p, r)| {
                r.episodes
                    .iter()
                    .filter(|e| e.task == *task)
                    .map(move |e| (p.as_path(), e))
            })
            .collect();
        eps.sort_by_key(|(_, e)| e.episode);
        if let Some((path, e)) = eps.iter().find(|(_, e)| e.episode >= n) {
            return Err(bad(
                path,
                format!(
                    "{task} episode {} is past the {n} episodes per task",
                    e.episode
                ),
            ));
        }
        if let Some(w) = eps.windows(2).find(|w| w[0].1.episode == w[1].1.episode) {
            return Err(bad(
                w[1].0,
                format!(
                    "{task} episode {} appears twice (also in {})",
                    w[1].1.episode,
                    w[0].0.display()
                ),
            ));
        }
        if let Some(k) = (0..n).find(|&k| eps.get(k).is_none_or(|(_, e)| e.episode != k)) {
            return Err(EvalError::Argument(format!(
                "{task} episode {k} is in none of the shards' results"
            )));
        }
        let eps: Vec<EpisodeResult> = eps.into_iter().map(|(_, e)| e.clone()).collect();
        rows.push(summarize(task, &eps));
        episodes.extend(eps);
    }
    Ok(Results {
        shard: data::shard::Shard::WHOLE,
        tasks: rows,
        episodes,
        ..first.clone()
    })
}

/// Summarises the episodes of one task.
pub fn summarize(task: &str, eps: &[EpisodeResult]) -> TaskSummary {
    let n = eps.len().max(1) as f64;
    let tiered: Vec<f64> = eps.iter().map(EpisodeResult::tiered).collect();
    let mean = tiered.iter().sum::<f64>() / n;
    let var = if eps.len() > 1 {
        tiered.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    let succ = eps.iter().filter(|e| e.success).count() as f64;
    TaskSummary {
        task: task.to_string(),
        episodes: eps.len(),
        completion: 100.0 * mean,
        completion_ci95: 100.0 * 1.96 * (var / n).sqrt(),
        success: 100.0 * succ / n,
        success_ci95: wilson(succ, n).map(|v| 100.0 * v),
        mean_steps: eps.iter().map(|e| e.steps as f64).sum::<f64>() / n,
        over_repetition: eps.iter().filter(|e| e.over_repetition).count(),
    }
}

/// 95 % Wilson score interval for `k` successes out of `n`.
pub fn wilson(k: f64, n: f64) -> [f64; 2] {
    if n <= 0.0 {
        return [0.0, 1.0];
    }
    let z = 1.96f64;
    let p = k / n;
    let den = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / den;
    let half = z * ((p * (1.0 - p) / n) + z * z / (4.0 * n * n)).sqrt() / den;
    [(centre - half).max(0.0), (centre + half).min(1.0)]
}

/// The suite of a task id (`libero_mem/t3` → `libero_mem`).
pub fn suite(task: &str) -> &str {
    task.split_once('/').map_or("", |(s, _)| s)
}

/// Short display name of a task (`libero_mem/t3@5` → `t3@5`).
pub fn short(task: &str) -> &str {
    task.split_once('/').map_or(task, |(_, t)| t)
}

/// Items grouped by the suite of their task id (`task` reads it), groups and items in first-seen order.
fn by_suite<'a, T>(
    items: impl IntoIterator<Item = &'a T>,
    task: impl Fn(&T) -> &str,
) -> Vec<(String, Vec<&'a T>)> {
    let mut out: Vec<(String, Vec<&'a T>)> = Vec::new();
    for item in items {
        let s = suite(task(item)).to_string();
        match out.iter_mut().find(|(name, _)| *name == s) {
            Some((_, v)) => v.push(item),
            None => out.push((s, vec![item])),
        }
    }
    out
}

/// Distinct strings in first-seen order.
pub(crate) fn first_seen<'a>(items: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for s in items {
        if !out.contains(&s) {
            out.push(s);
        }
    }
    out
}

/// The mean of `v` (0 when it is empty).
pub(crate) fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { 0.0 } else { s / n as f64 }
}

/// A Markdown table of task rows plus one average row per suite with more than one task (and an
/// overall row when several suites are present).
pub fn markdown(rows: &[TaskSummary]) -> String {
    let mut s = String::from(
        "| task | episodes | subgoal completion % (95 % CI) | success % (95 % CI) | mean steps | over-repetition |\n|---|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.1} ± {:.1} | {:.1} ({:.1}–{:.1}) | {:.1} | {} |\n",
            r.task,
            r.episodes,
            r.completion,
            r.completion_ci95,
            r.success,
            r.success_ci95[0],
            r.success_ci95[1],
            r.mean_steps,
            r.over_repetition
        ));
    }
    let average = |name: &str, v: &[&TaskSummary]| {
        format!(
            "| **{name}** | {} | {:.1} | {:.1} | {:.1} | {} |\n",
            v.iter().map(|r| r.episodes).sum::<usize>(),
            mean(v.iter().map(|r| r.completion)),
            mean(v.iter().map(|r| r.success)),
            mean(v.iter().map(|r| r.mean_steps)),
            v.iter().map(|r| r.over_repetition).sum::<usize>()
        )
    };
    let groups = by_suite(rows, |r| &r.task);
    for (name, v) in &groups {
        if v.len() > 1 {
            let label = if name.is_empty() {
                "average".to_string()
            } else {
                format!("{name} average")
            };
            s.push_str(&average(&label, v));
        }
    }
    if groups.len() > 1 {
        s.push_str(&average("average", &rows.iter().collect::<Vec<_>>()));
    }
    s
}

/// CSV of task rows.
pub fn csv(rows: &[TaskSummary]) -> String {
    let mut s = String::from(
        "task,episodes,completion,completion_ci95,success,success_ci95_lo,success_ci95_hi,mean_steps,over_repetition\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}\n",
            r.task,
            r.episodes,
            r.completion,
            r.completion_ci95,
            r.success,
            r.success_ci95[0],
            r.success_ci95[1],
            r.mean_steps,
            r.over_repetition
        ));
    }
    s
}

/// Several runs side by side, paper style: one table of subgoal completion (Table 3) and one of
/// success (Table 2), a column per run, a row per task, suite averages over the tasks every run has.
pub fn compare(runs: &[(String, Results)]) -> String {
    let tasks = first_seen(
        runs.iter()
            .flat_map(|(_, r)| r.tasks.iter().map(|t| t.task.as_str())),
    );
    // Suites with more than one task get an average over the tasks every run has.
    let averaged: Vec<(String, Vec<&str>)> = by_suite(&tasks, |t| t)
        .into_iter()
        .filter(|(_, v)| v.len() > 1)
        .map(|(name, v)| (name, v.into_iter().copied().collect()))
        .collect();
    let lookup: Vec<BTreeMap<&str, &TaskSummary>> = runs
        .iter()
        .map(|(_, r)| r.tasks.iter().map(|t| (t.task.as_str(), t)).collect())
        .collect();
    let mut out = String::new();
    for (title, field) in [
        (
            "Subgoal completion % (tiered credit)",
            (|t: &TaskSummary| t.completion) as fn(&TaskSummary) -> f64,
        ),
        ("Success %", |t: &TaskSummary| t.success),
    ] {
        out.push_str(&format!("{title}\n\n| task |"));
        for (name, _) in runs {
            out.push_str(&format!(" {name} |"));
        }
        out.push_str("\n|---|");
        out.push_str(&"---:|".repeat(runs.len()));
        out.push('\n');
        for t in &tasks {
            out.push_str(&format!("| {} |", short(t)));
            for l in &lookup {
                match l.get(t) {
                    Some(s) => out.push_str(&format!(" {:.1} |", field(s))),
                    None => out.push_str(" – |"),
                }
            }
            out.push('\n');
        }
        for (name, ts) in &averaged {
            let common: Vec<&str> = ts
                .iter()
                .copied()
                .filter(|t| lookup.iter().all(|l| l.contains_key(t)))
                .collect();
            if common.is_empty() {
                continue;
            }
            out.push_str(&format!("| **{name} average** |"));
            for l in &lookup {
                out.push_str(&format!(
                    " {:.1} |",
                    mean(common.iter().map(|t| field(l[t])))
                ));
            }
            out.push('\n');
        }
        out.push('\n');
    }
    out
}

/// One cell of the temporal-scaling table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScalingRow {
    /// Base task id (without `@N`).
    pub task: String,
    /// Repetitions.
    pub repeats: usize,
    /// The summary at that count.
    pub summary: TaskSummary,
}

/// Completion (and success) against the repetition count: a row per task, a column per N.
pub fn scaling_table(rows: &[ScalingRow]) -> String {
    let mut ns: Vec<usize> = rows.iter().map(|r| r.repeats).collect();
    ns.sort_unstable();
    ns.dedup();
    let tasks = first_seen(rows.iter().map(|r| r.task.as_str()));
    let mut s = String::from("Subgoal completion % (success %) against repetitions N\n\n| task |");
    for n in &ns {
        s.push_str(&format!(" N = {n} |"));
    }
    s.push_str("\n|---|");
    s.push_str(&"---:|".repeat(ns.len()));
    s.push('\n');
    for t in tasks {
        s.push_str(&format!("| {} |", short(t)));
        for n in &ns {
            match rows.iter().find(|r| r.task == t && r.repeats == *n) {
                Some(r) => s.push_str(&format!(
                    " {:.1} ({:.0}) |",
                    r.summary.completion, r.summary.success
                )),
                None => s.push_str(" – |"),
            }
        }
        s.push('\n');
    }
    s
}

/// Escapes `&`, `<`, `>` and `"` for HTML.
fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A markdown table (as [`markdown`] writes it) as an HTML table; `**bold**` cells as `<b>`.
fn html_table(md: &str) -> String {
    let mut h = String::from("<table>\n");
    for (i, line) in md.lines().filter(|l| l.starts_with('|')).enumerate() {
        if i == 1 {
            continue; // the alignment row
        }
        let tag = if i == 0 { "th" } else { "td" };
        h.push_str("<tr>");
        for cell in line.trim().trim_matches('|').split('|') {
            let cell = cell.trim();
            let text = match cell.strip_prefix("**").and_then(|c| c.strip_suffix("**")) {
                Some(b) => format!("<b>{}</b>", html_escape(b)),
                None => html_escape(cell),
            };
            h.push_str(&format!("<{tag}>{text}</{tag}>"));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
    h
}

/// `OUT/index.html` of an evaluation with videos: the results table, then one row per episode
/// (task, episode, seed, steps, subgoals, success, over-repetition) with its video, whose link
/// `video` gives (relative to OUT where possible).
pub fn index_html(results: &Results, video: &dyn Fn(&EpisodeResult) -> String) -> String {
    let mut h = String::from(
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>rollouts</title>\n<style>\
         body{font-family:sans-serif}table{border-collapse:collapse;margin-bottom:1em}td,th{border:1px solid #ccc;\
         padding:2px 6px}video{width:384px}</style></head><body>\n",
    );
    h.push_str(&format!(
        "<h1>{} — {} episodes per task, seed {}{}</h1>\n{}<h2>episodes</h2>\n<table>\n<tr><th>task</th>\
         <th>episode</th><th>seed</th><th>steps</th><th>subgoals</th><th>success</th>\
         <th>over-repetition</th><th>video</th></tr>\n",
        html_escape(&results.policy),
        results.episodes_per_task,
        results.seed,
        if results.full_budget {
            ", full budget"
        } else {
            ""
        },
        html_table(&markdown(&results.tasks)),
    ));
    let poster = |src: &str| match src.strip_suffix(".mp4") {
        Some(stem) => format!("{stem}.png"),
        None => format!("{src}.png"),
    };
    for e in &results.episodes {
        let src = video(e);
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}/{}</td><td>{}</td><td>{}</td>\
             <td><video controls preload=\"none\" poster=\"{}\" src=\"{}\"></video></td></tr>\n",
            html_escape(&e.task),
            e.episode,
            e.seed,
            e.steps,
            e.satisfied,
            e.goal_len,
            if e.success { "yes" } else { "no" },
            if e.over_repetition { "yes" } else { "no" },
            html_escape(&poster(&src)),
            html_escape(&src),
        ));
    }
    h.push_str("</table>\n</body></html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ep(task: &str, satisfied: usize, success: bool, failed: bool) -> EpisodeResult {
        EpisodeResult {
            task: task.into(),
            episode: 0,
            seed: 0,
            steps: 10,
            satisfied,
            goal_len: 4,
            success,
            over_repetition: failed,
        }
    }

    #[test]
    fn wilson_interval_brackets_the_rate() {
        let [lo, hi] = wilson(19.0, 20.0);
        assert!(lo > 0.74 && lo < 0.77 && hi > 0.99, "{lo} {hi}");
        assert_eq!(wilson(0.0, 0.0), [0.0, 1.0]);
        let [lo, hi] = wilson(0.0, 10.0);
        assert!(lo == 0.0 && (hi - 0.2775).abs() < 1e-3, "{hi}");
    }

    #[test]
    fn summary_numbers_and_suite_averages() {
        let t = "libero_mem/t3";
        let s = summarize(
            t,
            &[
                ep(t, 4, true, false),
                ep(t, 2, false, false),
                ep(t, 0, false, false),
                ep(t, 4, false, true),
            ],
        );
        assert_eq!(s.completion, 62.5);
        assert_eq!(s.success, 25.0);
        assert_eq!(s.over_repetition, 1);
        assert!(s.completion_ci95 > 0.0);
        let mut g = s.clone();
        g.task = "libero_goal/x".into();
        g.completion = 100.0;
        let md = markdown(&[s.clone(), s.clone(), g]);
        assert!(md.contains("| libero_mem/t3 | 4 | 62.5 ±"), "{md}");
        assert!(
            md.contains("| **libero_mem average** | 8 | 62.5 | 25.0 |"),
            "{md}"
        );
        assert!(!md.contains("libero_goal average"), "{md}");
        assert!(md.contains("| **average** | 12 | 75.0 |"), "{md}");
        let c = csv(&[s]);
        assert_eq!(c.lines().count(), 2);
        assert!(
            c.lines()
                .nth(1)
                .unwrap()
                .starts_with("libero_mem/t3,4,62.5000,")
        );
    }

    #[test]
    fn compare_puts_runs_side_by_side() {
        let row = |task: &str, c: f64, sr: f64| TaskSummary {
            completion: c,
            success: sr,
            ..summarize(task, &[ep(task, 1, false, false)])
        };
        let res = |rows: Vec<TaskSummary>| Results {
            policy: "model".into(),
            run: None,
            checkpoint_step: None,
            execution: None,
            seed: 0,
            episodes_per_task: 1,
            full_budget: false,
            shard: data::shard::Shard::WHOLE,
            tasks: rows,
            episodes: vec![],
        };
        let a = res(vec![
            row("libero_mem/t1", 50.0, 10.0),
            row("libero_mem/t3", 30.0, 0.0),
        ]);
        let b = res(vec![row("libero_mem/t1", 70.0, 40.0)]);
        let t = compare(&[("a".into(), a), ("b".into(), b)]);
        assert!(t.contains("| task | a | b |"), "{t}");
        assert!(t.contains("| t1 | 50.0 | 70.0 |"), "{t}");
        assert!(t.contains("| t3 | 30.0 | – |"), "{t}");
        assert!(
            t.contains("| **libero_mem average** | 50.0 | 70.0 |"),
            "{t}"
        );
        assert!(t.contains("| t1 | 10.0 | 40.0 |"), "{t}");
    }

    #[test]
    fn scaling_table_has_a_column_per_n() {
        let s = |c| TaskSummary {
            completion: c,
            ..summarize("x", &[ep("x", 4, true, false)])
        };
        let rows = vec![
            ScalingRow {
                task: "libero_mem/t3".into(),
                repeats: 5,
                summary: s(80.0),
            },
            ScalingRow {
                task: "libero_mem/t3".into(),
                repeats: 3,
                summary: s(100.0),
            },
        ];
        let t = scaling_table(&rows);
        assert!(t.contains("| task | N = 3 | N = 5 |"), "{t}");
        assert!(t.contains("| t3 | 100.0 (100) | 80.0 (100) |"), "{t}");
    }

    #[test]
    fn loading_results_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = Results::load(dir.path()).unwrap_err();
        assert!(e.to_string().contains("no results.json"), "{e}");
        std::fs::write(dir.path().join("results.json"), "{").unwrap();
        let e = Results::load(dir.path()).unwrap_err();
        assert!(
            e.to_string()
                .contains("results.json: not an eval results file"),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2);
    }
}
