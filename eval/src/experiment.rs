//! The paper's experiment in one command (`eval experiment FILE`): train every listed variant on
//! every listed suite (by running the `train` binary next to this one, which resumes on its own),
//! evaluate each trained policy on held-out seeds, and write the tables of the paper — LIBERO-Goal
//! success (Table 2) and LIBERO-Mem subgoal completion (Table 3), per observation mode, with 95 %
//! intervals — as Markdown, JSON, CSV and an SVG plot.
//!
//! Every finished step is kept on disk (the run's checkpoints, its `eval/results.json`), so an
//! interrupted experiment continues where it stopped; every evaluated run is also recorded in
//! `OUT/runs.json` ([`Ledger`]), so a clone without the run directories rebuilds the same tables
//! and trains only what is missing.
//!
//! ```toml
//! name = "paper"
//! out = "docs"              # results.md, .json, .csv, .svg and the ledger runs.json
//! episodes = 20             # per task, seeds derived from `seed`
//! seed = 1000
//! full_budget = true
//!
//! [recipes]                 # optional: named override lists that run groups share
//! long = ["train.steps=40000", "train.ema=0.999"]
//!
//! [[runs]]
//! obs = "state"
//! suite = "libero_mem"      # the tasks evaluated (eval's --tasks syntax)
//! config = "configs/state/libero_mem.toml"
//! variants = ["e_slotssm_oracle", "e_slotssm", "slotvla_h1", "slotvla_h8", "dense"]
//! # tag = "hold"          # optional: the group's name, `+hold` in the tables
//! # recipe = "long"       # optional: a `[recipes]` entry, its overrides before `set`'s
//! # set = ["train.steps=8000"]   # optional: `train --set` overrides
//! # seeds = [1, 2]        # optional: the same runs again at these `train.seed`s (`+seed1`, …)
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::{Deserialize, Serialize};

use crate::error::EvalError;
use crate::report::{self, Results, TaskSummary};

/// An experiment file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// Name (prefix of every run directory, `runs/<name>_<obs>_<suite>_<variant>`).
    pub name: String,
    /// Folder of the tables (`results.md`, `.json`, `.csv`, `.svg`).
    pub out: PathBuf,
    /// Episodes per task.
    #[serde(default = "twenty")]
    pub episodes: usize,
    /// Base seed of the evaluation episodes (held out: training episodes use seeds 0…).
    #[serde(default)]
    pub seed: u64,
    /// Run every episode's whole step budget (upstream `mem_6`: over-repetition counts).
    #[serde(default = "yes")]
    pub full_budget: bool,
    /// Evaluation worker threads.
    #[serde(default = "one")]
    pub workers: usize,
    /// Folder of the run directories.
    #[serde(default = "runs_dir")]
    pub runs_dir: PathBuf,
    /// Named lists of `train --set` overrides that run groups share (a group's `recipe`).
    #[serde(default)]
    pub recipes: BTreeMap<String, Vec<String>>,
    /// What to train and evaluate.
    pub runs: Vec<RunSpec>,
}

fn twenty() -> usize {
    20
}
fn yes() -> bool {
    true
}
fn one() -> usize {
    1
}
fn runs_dir() -> PathBuf {
    PathBuf::from("runs")
}

/// One group of runs: a training config trained once per variant.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// Observation mode of the config (`state` or `pixels`): the table it goes to.
    pub obs: String,
    /// Tasks evaluated (`libero_mem`, `libero_goal`, `t1,t3`, …).
    pub suite: String,
    /// Training config (its `[model].variant` and `name` are replaced per run).
    pub config: PathBuf,
    /// Variants trained from it.
    pub variants: Vec<String>,
    /// Tag of the runs in the tables and their names (e.g. `windows` for an ablation).
    #[serde(default)]
    pub tag: Option<String>,
    /// A `[recipes]` entry: its overrides are given to `train` before the group's own `set`
    /// (once loaded, `set` holds both, the recipe's first).
    #[serde(default)]
    pub recipe: Option<String>,
    /// Further `KEY=VALUE` overrides given to `train --set`.
    #[serde(default)]
    pub set: Vec<String>,
    /// Further training seeds: besides the run at the config's own `train.seed`, one more run
    /// per variant and seed N (`train.seed=N`), named `…_seedN` and listed as `<label>+seedN`, so
    /// the tables show how far one recipe's result moves from one training run to the next.
    #[serde(default)]
    pub seeds: Vec<u64>,
}

/// Which of an experiment's runs to train and evaluate now (`eval experiment --obs/--suite/--tag`);
/// `None` admits every value.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Only {
    /// Observation mode (`state`, `pixels`).
    pub obs: Option<String>,
    /// Suite, as a run's `suite` names it.
    pub suite: Option<String>,
    /// Group tag, as a run's `tag` names it (`""` admits the groups without one).
    pub tag: Option<String>,
}

impl Only {
    /// Whether the runs of `spec` are to be trained and evaluated.
    pub fn admits(&self, spec: &RunSpec) -> bool {
        self.obs.as_ref().is_none_or(|o| *o == spec.obs)
            && self.suite.as_ref().is_none_or(|s| *s == spec.suite)
            && self
                .tag
                .as_ref()
                .is_none_or(|t| *t == spec.tag.as_deref().unwrap_or(""))
    }

    /// An error naming `file` when no run of `x` is admitted (a misspelt mode or suite), listing
    /// the file's modes and suites in file order.
    pub fn check(&self, x: &Experiment, file: &Path) -> Result<(), EvalError> {
        if self.obs.is_none() && self.suite.is_none() && self.tag.is_none()
            || x.runs.iter().any(|r| self.admits(r))
        {
            return Ok(());
        }
        let modes = report::first_seen(x.runs.iter().map(|r| r.obs.as_str()));
        let suites = report::first_seen(x.runs.iter().map(|r| r.suite.as_str()));
        let tags = report::first_seen(x.runs.iter().filter_map(|r| r.tag.as_deref()));
        Err(EvalError::Input {
            path: file.to_path_buf(),
            message: format!(
                "no run has{}{}{} (modes: {}; suites: {}; tags: {})",
                self.obs
                    .as_ref()
                    .map_or(String::new(), |o| format!(" obs = \"{o}\"")),
                self.suite
                    .as_ref()
                    .map_or(String::new(), |s| format!(" suite = \"{s}\"")),
                self.tag
                    .as_ref()
                    .map_or(String::new(), |t| format!(" tag = \"{t}\"")),
                modes.join(", "),
                suites.join(", "),
                tags.join(", ")
            ),
        })
    }
}

/// One run of an experiment's plan.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned<'a> {
    /// Its group.
    pub spec: &'a RunSpec,
    /// Its group's position in `runs` (what errors name as `runs[i]`).
    pub group: usize,
    /// Run name (its directory under `runs_dir`).
    pub name: String,
    /// Variant trained.
    pub variant: String,
    /// Variant with the group's tag (and `+seedN` for a further seed), as the tables show it.
    pub label: String,
    /// The further training seed of this run (None: the config's own).
    pub seed: Option<u64>,
}

impl Planned<'_> {
    /// How the tables list this run while it has no result: its observation mode, and the label
    /// with the tasks it is for (`e_slotssm+windows on t3`).
    pub fn not_trained(&self) -> (String, String) {
        (
            self.spec.obs.clone(),
            format!("{} on {}", self.label, self.spec.suite),
        )
    }
}

/// One trained and evaluated policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// Observation mode.
    pub obs: String,
    /// Variant name, with the tag (`e_slotssm+windows`).
    pub variant: String,
    /// Run directory.
    pub run: String,
    /// Wall time of training, seconds (from the run's metrics).
    pub train_s: Option<f64>,
    /// Training steps.
    pub steps: Option<u64>,
    /// Per-task rows.
    pub tasks: Vec<TaskSummary>,
}

impl RunResult {
    /// Mean subgoal completion over its tasks, percent (0 without tasks).
    pub fn mean_completion(&self) -> f64 {
        report::mean(self.tasks.iter().map(|t| t.completion))
    }
}

impl Experiment {
    /// Reads an experiment file (errors name the file and the key).
    pub fn load(path: &Path) -> Result<Experiment, EvalError> {
        let bad = |message: String| EvalError::Input {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let mut x: Experiment = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        if x.episodes == 0 || x.workers == 0 {
            return Err(bad("episodes and workers must be ≥ 1".into()));
        }
        for (i, r) in x.runs.iter_mut().enumerate() {
            if let Some(name) = &r.recipe {
                let Some(recipe) = x.recipes.get(name) else {
                    let known: Vec<&str> = x.recipes.keys().map(String::as_str).collect();
                    return Err(bad(format!(
                        "runs[{i}].recipe: unknown recipe `{name}` (recipes: {})",
                        if known.is_empty() {
                            "none; define them under [recipes]".to_string()
                        } else {
                            known.join(", ")
                        }
                    )));
                };
                r.set = recipe.iter().chain(&r.set).cloned().collect();
            }
        }
        for (i, r) in x.runs.iter().enumerate() {
            if r.obs != "state" && r.obs != "pixels" {
                return Err(bad(format!(
                    "runs[{i}].obs: `{}`, expected `state` or `pixels`",
                    r.obs
                )));
            }
            if r.variants.is_empty() {
                return Err(bad(format!("runs[{i}].variants: name at least one")));
            }
            if let Some(v) = r
                .variants
                .iter()
                .find(|v| model::Variant::from_name(v).is_err())
            {
                return Err(bad(format!("runs[{i}].variants: unknown variant `{v}`")));
            }
        }
        // Two plans of one run would train one directory twice and count it twice in the tables.
        let mut first: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
        for p in x.plan() {
            let i = p.group;
            if let Some(&j) = first.get(&p.name) {
                return Err(bad(format!(
                    "runs[{i}]: run `{}` is planned twice (also by runs[{j}]: the same obs, suite, \
                     variant, tag and seed): give one another `tag`, or list further training \
                     seeds in `seeds`",
                    p.name
                )));
            }
            first.insert(p.name, i);
        }
        Ok(x)
    }

    /// Whether an evaluation run with `episodes` per task from `seed` (`full_budget` or not) is one
    /// of this experiment's: the protocol its tables compare.
    pub fn same_protocol(&self, episodes: usize, seed: u64, full_budget: bool) -> bool {
        episodes == self.episodes && seed == self.seed && full_budget == self.full_budget
    }

    /// Every (group, variant) pair, in file order.
    pub fn plan(&self) -> Vec<Planned<'_>> {
        let mut out = Vec::new();
        for (group, r) in self.runs.iter().enumerate() {
            for v in &r.variants {
                let mut name = format!("{}_{}_{}_{}", self.name, r.obs, slug(&r.suite), v);
                let mut label = v.clone();
                if let Some(t) = &r.tag {
                    name.push('_');
                    name.push_str(&slug(t));
                    label = format!("{v}+{t}");
                }
                out.push(Planned {
                    spec: r,
                    group,
                    name: name.clone(),
                    variant: v.clone(),
                    label: label.clone(),
                    seed: None,
                });
                for &seed in &r.seeds {
                    out.push(Planned {
                        spec: r,
                        group,
                        name: format!("{name}_seed{seed}"),
                        variant: v.clone(),
                        label: format!("{label}+seed{seed}"),
                        seed: Some(seed),
                    });
                }
            }
        }
        out
    }
}

/// A name fit for a directory (`t1,t3` → `t1-t3`, `libero_goal/x` → `libero_goal-x`).
fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The `train --set` overrides of one run, in the order [`train`] gives them (later ones win):
/// its name, its variant, the group's `set`, then its further seed.
pub fn train_overrides(p: &Planned) -> Vec<String> {
    let mut out = vec![
        format!("name=\"{}\"", p.name),
        format!("model.variant=\"{}\"", p.variant),
    ];
    out.extend(p.spec.set.iter().cloned());
    out.extend(p.seed.map(|s| format!("train.seed={s}")));
    out
}

/// The shell command that [`train`] runs for `p` (without `--threads`; recipes expanded), each
/// override single-quoted: what `eval experiment --plan` prints, to run a group's member by hand.
pub fn train_command(p: &Planned, runs_dir: &Path) -> String {
    let quote = |s: &str| format!("'{}'", s.replace('\'', r"'\''"));
    let mut out = format!(
        "train {} --run-dir {}",
        quote(&p.spec.config.display().to_string()),
        quote(&runs_dir.join(&p.name).display().to_string())
    );
    for s in train_overrides(p) {
        out.push_str(" --set ");
        out.push_str(&quote(&s));
    }
    out
}

/// Trains the run `p` with the `train` binary found next to this executable (resuming on its
/// own), on `threads` kernel threads (`None`: `train`'s default, one per core); its output goes
/// to `RUN/train.log`.
pub fn train(p: &Planned, runs_dir: &Path, threads: Option<usize>) -> Result<(), EvalError> {
    let (spec, name) = (p.spec, p.name.as_str());
    let exe = std::env::current_exe().map_err(|e| EvalError::Argument(e.to_string()))?;
    let bin = exe.with_file_name(format!("train{}", std::env::consts::EXE_SUFFIX));
    if !bin.is_file() {
        return Err(EvalError::Argument(format!(
            "{}: the `train` binary is missing; build it beside eval (`cargo build --release -p train`)",
            bin.display()
        )));
    }
    let run = runs_dir.join(name);
    std::fs::create_dir_all(&run).map_err(|e| EvalError::Output {
        path: run.clone(),
        message: e.to_string(),
    })?;
    let log_path = run.join("train.log");
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)
        .map_err(|e| EvalError::Output {
            path: log_path.clone(),
            message: e.to_string(),
        })?;
    let err_log = log.try_clone().map_err(|e| EvalError::Output {
        path: log_path.clone(),
        message: e.to_string(),
    })?;
    let mut cmd = Command::new(&bin);
    cmd.arg(&spec.config)
        .arg("--quiet")
        .arg("--run-dir")
        .arg(&run);
    if let Some(n) = threads {
        cmd.arg("--threads").arg(n.to_string());
    }
    for s in train_overrides(p) {
        cmd.arg("--set").arg(s);
    }
    let status = cmd
        .stdout(log)
        .stderr(err_log)
        .status()
        .map_err(|e| EvalError::Argument(format!("{}: {e}", bin.display())))?;
    if !status.success() {
        let tail = std::fs::read_to_string(&log_path).unwrap_or_default();
        let last: Vec<&str> = tail.lines().rev().take(3).collect();
        return Err(EvalError::Model(format!(
            "training {name} failed ({status}); see {}: {}",
            log_path.display(),
            last.into_iter().rev().collect::<Vec<_>>().join(" / ")
        )));
    }
    Ok(())
}

/// Kernel threads for each of `jobs` trainings run side by side on `cores` cores: the cores
/// shared out (at least one each), so that N trainings do not each start one thread per core.
pub fn threads_per_job(cores: usize, jobs: usize) -> usize {
    (cores / jobs.max(1)).max(1)
}

/// The `data.dir=VALUE` override among `spec`'s `set` (the last one wins), as given.
fn data_dir_override(spec: &RunSpec) -> Option<&str> {
    spec.set.iter().rev().find_map(|s| {
        let (k, v) = s.split_once('=')?;
        (k.trim() == "data.dir").then_some(v.trim())
    })
}

/// The dataset folder `spec`'s run trains on: a `data.dir` override (a TOML string, or bare as
/// `train --set` reads it) or the config's `[data].dir`; `None` when the config cannot be read.
pub fn dataset_dir(spec: &RunSpec) -> Option<PathBuf> {
    if let Some(v) = data_dir_override(spec) {
        let dir = match format!("v = {v}").parse::<toml::Table>() {
            Ok(t) => t.get("v")?.as_str()?.to_string(),
            Err(_) => v.to_string(),
        };
        return Some(PathBuf::from(dir));
    }
    let text = std::fs::read_to_string(&spec.config).ok()?;
    let value = text.parse::<toml::Table>().ok()?;
    let dir = value.get("data")?.get("dir")?.as_str()?;
    Some(PathBuf::from(dir))
}

/// Whether the dataset that `spec`'s run reads ([`dataset_dir`]) is already recorded (it holds an
/// `index.json`; relative to the working directory, as `train` reads it). False when the config
/// cannot be read (the caller then plays safe).
pub fn dataset_ready(spec: &RunSpec) -> bool {
    dataset_dir(spec).is_some_and(|d| d.join("index.json").is_file())
}

/// Orders the runs still to train for `--jobs`: first, one at a time, the first run of every
/// config (and `data.dir` override) whose dataset is not recorded yet (its `train` generates it; two at once would both
/// write into the same folder); then the rest, which may train side by side.
pub fn training_waves<'a, 'b>(
    todo: &[&'b Planned<'a>],
    ready: impl Fn(&RunSpec) -> bool,
) -> (Vec<&'b Planned<'a>>, Vec<&'b Planned<'a>>) {
    let (mut alone, mut side_by_side) = (Vec::new(), Vec::new());
    // One dataset per config and `data.dir` override.
    let mut generating: Vec<(&Path, Option<&str>)> = Vec::new();
    for &p in todo {
        let key = (p.spec.config.as_path(), data_dir_override(p.spec));
        if !ready(p.spec) && !generating.contains(&key) {
            generating.push(key);
            alone.push(p);
        } else {
            side_by_side.push(p);
        }
    }
    (alone, side_by_side)
}

/// The optimiser steps a run directory is configured to train: `[train] steps` of its
/// `config.toml` (None when it cannot be read).
pub fn planned_steps(run: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(run.join("config.toml")).ok()?;
    let value = text.parse::<toml::Table>().ok()?;
    let steps = value.get("train")?.get("steps")?.as_integer()?;
    u64::try_from(steps).ok()
}

/// Training wall time (seconds) and steps of a run, from its `metrics.jsonl`.
pub fn training_cost(run: &Path) -> (Option<f64>, Option<u64>) {
    let Ok(text) = std::fs::read_to_string(run.join("metrics.jsonl")) else {
        return (None, None);
    };
    let last = text
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok());
    match last {
        Some(v) => (
            v.get("time_s").and_then(serde_json::Value::as_f64),
            v.get("step").and_then(serde_json::Value::as_u64),
        ),
        None => (None, None),
    }
}

/// Task order of a table: LIBERO-Mem t1…t10 numerically, others by name.
fn task_key(t: &str) -> (String, u32, String) {
    let s = report::short(t);
    let n = s
        .strip_prefix('t')
        .and_then(|d| d.parse::<u32>().ok())
        .unwrap_or(u32::MAX);
    (report::suite(t).to_string(), n, s.to_string())
}

/// `docs/results.json`: `{obs: {variant: {task: {completion, success, episodes}}}}`.
pub fn results_json(runs: &[RunResult]) -> serde_json::Value {
    let mut root: BTreeMap<String, BTreeMap<String, BTreeMap<String, serde_json::Value>>> =
        BTreeMap::new();
    for r in runs {
        let v = root
            .entry(r.obs.clone())
            .or_default()
            .entry(r.variant.clone())
            .or_default();
        for t in &r.tasks {
            v.insert(
                t.task.clone(),
                serde_json::json!({
                    "completion": round1(t.completion),
                    "completion_ci95": round1(t.completion_ci95),
                    "success": round1(t.success),
                    "success_ci95": [round1(t.success_ci95[0]), round1(t.success_ci95[1])],
                    "episodes": t.episodes,
                }),
            );
        }
    }
    serde_json::to_value(root).unwrap_or_default()
}

fn round1(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// Mean over a suite's tasks of a run, with the 95 % half-width of the pooled episodes
/// (normal approximation over per-task means: the tasks have equal episode counts).
fn suite_mean(rows: &[&TaskSummary], f: impl Fn(&TaskSummary) -> (f64, f64)) -> (f64, f64) {
    let n = rows.len().max(1) as f64;
    let m = rows.iter().map(|r| f(r).0).sum::<f64>() / n;
    let h = (rows.iter().map(|r| f(r).1.powi(2)).sum::<f64>()).sqrt() / n;
    (m, h)
}

/// A table's number of a row, with its 95 % half-width.
type Metric = fn(&TaskSummary) -> (f64, f64);

/// The success half-width of a row (Wilson interval, halved).
fn success_half(t: &TaskSummary) -> f64 {
    (t.success_ci95[1] - t.success_ci95[0]) / 2.0
}

/// Per variant (in order of first appearance), its rows of `suite` from every run of `runs`; a
/// task already seen for the variant keeps its first row.
fn merged_rows<'a>(runs: &[&'a RunResult], suite: &str) -> Vec<(&'a str, Vec<&'a TaskSummary>)> {
    let mut out: Vec<(&str, Vec<&TaskSummary>)> = Vec::new();
    for r in runs {
        for t in r.tasks.iter().filter(|t| report::suite(&t.task) == suite) {
            let i = match out.iter().position(|(v, _)| *v == r.variant) {
                Some(i) => i,
                None => {
                    out.push((&r.variant, Vec::new()));
                    out.len() - 1
                }
            };
            if !out[i].1.iter().any(|x| x.task == t.task) {
                out[i].1.push(t);
            }
        }
    }
    out
}

/// Appends the header of a task table to `s`: a `first` column, one right-aligned column per task
/// of `tasks` (short ids) and a mean column.
fn table_header(s: &mut String, first: &str, tasks: &[impl AsRef<str>]) {
    s.push_str(&format!("| {first} |"));
    for t in tasks {
        s.push_str(&format!(" {} |", report::short(t.as_ref())));
    }
    s.push_str(" mean |\n|---|");
    for _ in tasks {
        s.push_str("---:|");
    }
    s.push_str("---:|\n");
}

/// Appends a Markdown table to `s`: a column per task of `tasks` and a mean column, a row per
/// variant of `by_variant` (`cell` of its row for each task, `–` where it has none; `mean` of its rows).
fn variant_table(
    s: &mut String,
    tasks: &[String],
    by_variant: &[(&str, Vec<&TaskSummary>)],
    cell: impl Fn(&TaskSummary) -> String,
    mean: impl Fn(&[&TaskSummary]) -> String,
) {
    table_header(s, "variant", tasks);
    for (variant, rows) in by_variant {
        s.push_str(&format!("| {variant} |"));
        for t in tasks {
            match rows.iter().find(|x| &x.task == t) {
                Some(row) => s.push_str(&format!(" {} |", cell(row))),
                None => s.push_str(" – |"),
            }
        }
        s.push_str(&format!(" {} |\n", mean(rows)));
    }
    s.push('\n');
}

/// The tables: per observation mode, Table 3 (LIBERO-Mem completion) and Table 2 (LIBERO-Goal
/// success), then other suites' completion and success, and the training cost of each run.
pub fn markdown(x: &Experiment, runs: &[RunResult], missing: &[(String, String)]) -> String {
    let mut s = format!(
        "# Results: `{}`\n\n{} held-out episodes per task (seeds from {}), {}; mean ± 95 % \
         interval half-width (completion: normal approximation; success: Wilson). Every run below is \
         also recorded in `runs.json` beside this file, from which `eval experiment` reads the runs \
         whose directories are not on the machine (remove an entry to train and evaluate it again).\n\n",
        x.name,
        x.episodes,
        x.seed,
        if x.full_budget {
            "full step budget (over-repetition counts, as upstream `mem_6`)"
        } else {
            "stopping at success"
        }
    );
    for m in report::first_seen(runs.iter().map(|r| r.obs.as_str())) {
        let of_mode: Vec<&RunResult> = runs.iter().filter(|r| r.obs == m).collect();
        let mut suites: Vec<String> = of_mode
            .iter()
            .flat_map(|r| r.tasks.iter().map(|t| report::suite(&t.task).to_string()))
            .collect();
        suites.sort();
        suites.dedup();
        // LIBERO-Mem first (Table 3), then LIBERO-Goal (Table 2), then the rest.
        suites.sort_by_key(|s| match s.as_str() {
            "libero_mem" => 0,
            "libero_goal" => 1,
            _ => 2,
        });
        for suite in suites {
            let (metric, title): (Metric, &str) = match suite.as_str() {
                "libero_goal" => (|t| (t.success, success_half(t)), "success (%) — Table 2"),
                "libero_mem" => (
                    |t| (t.completion, t.completion_ci95),
                    "subgoal completion (%) — Table 3",
                ),
                _ => (
                    |t| (t.completion, t.completion_ci95),
                    "subgoal completion (%)",
                ),
            };
            let mut tasks: Vec<String> = of_mode
                .iter()
                .flat_map(|r| r.tasks.iter())
                .filter(|t| report::suite(&t.task) == suite)
                .map(|t| t.task.clone())
                .collect();
            tasks.sort_by_key(|t| task_key(t));
            tasks.dedup();
            s.push_str(&format!("## {m} mode: {suite} {title}\n\n"));
            // One row per variant: runs of the same variant on different tasks (one config per
            // task) share it; a task evaluated twice for a variant shows the first run's result.
            let by_variant = merged_rows(&of_mode, &suite);
            variant_table(
                &mut s,
                &tasks,
                &by_variant,
                |row| {
                    let (v, h) = metric(row);
                    format!("{v:.0} ± {h:.0}")
                },
                |rows| {
                    let (mv, mh) = suite_mean(rows, metric);
                    format!("**{mv:.1}** ± {mh:.1}")
                },
            );
            if suite == "libero_mem" && x.full_budget {
                // Completion counts subgoals ever reached; success also needs the policy to stop.
                s.push_str(&format!(
                    "### {m} mode: {suite} success (%) and over-repetitions\n\nSuccess: every subgoal \
                     done and nothing repeated; in parentheses, episodes that did the task and then \
                     went on (upstream `mem_6`).\n\n"
                ));
                variant_table(
                    &mut s,
                    &tasks,
                    &by_variant,
                    |row| format!("{:.0} ({})", row.success, row.over_repetition),
                    |rows| {
                        let (mv, _) = suite_mean(rows, |t| (t.success, success_half(t)));
                        format!("**{mv:.1}**")
                    },
                );
            }
            if suite == "libero_mem" {
                for recipe in recipes(&by_variant) {
                    s.push_str(&memory_claim(m, &by_variant, &recipe));
                }
            }
        }
        // Success / completion means of every run of this mode.
        s.push_str(&format!(
            "### {m} mode: means and training cost\n\n| variant | tasks | completion | success | train steps | train time |\n|---|---|---:|---:|---:|---:|\n"
        ));
        for r in &of_mode {
            for suite in report::first_seen(r.tasks.iter().map(|t| report::suite(&t.task))) {
                let rows: Vec<&TaskSummary> = r
                    .tasks
                    .iter()
                    .filter(|t| report::suite(&t.task) == suite)
                    .collect();
                let (c, ch) = suite_mean(&rows, |t| (t.completion, t.completion_ci95));
                let (sc, sh) = suite_mean(&rows, |t| (t.success, success_half(t)));
                // A few tasks are named; a whole suite by its name.
                let which = if rows.len() <= 3 {
                    let mut sorted = rows.clone();
                    sorted.sort_by_key(|t| task_key(&t.task));
                    let short: Vec<&str> = sorted.iter().map(|t| report::short(&t.task)).collect();
                    format!("{suite}: {}", short.join(", "))
                } else {
                    format!("{suite} ({} tasks)", rows.len())
                };
                s.push_str(&format!(
                    "| {} | {which} | {c:.1} ± {ch:.1} | {sc:.1} ± {sh:.1} | {} | {} |\n",
                    r.variant,
                    r.steps.map_or("–".into(), |v| v.to_string()),
                    r.train_s.map_or("–".into(), |v| if v < 120.0 {
                        format!("{v:.0} s")
                    } else {
                        format!("{:.1} min", v / 60.0)
                    }),
                ));
            }
        }
        s.push('\n');
    }
    if !missing.is_empty() {
        s.push_str("## Not trained\n\n");
        for (obs, v) in missing {
            s.push_str(&format!("- {obs} mode: {v}\n"));
        }
        s.push('\n');
    }
    s
}

/// The counting tasks of the memory claim (LIBERO-Mem "… N times").
pub const COUNTING_TASKS: [&str; 4] = [
    "libero_mem/t3",
    "libero_mem/t4",
    "libero_mem/t5",
    "libero_mem/t6",
];

/// Subgoal-completion margin (points) that e_slotssm must have over slotvla_h1 on every counting
/// task for the memory claim to hold.
pub const CLAIM_MARGIN: f64 = 30.0;

/// A variant's result on one task, averaged over its training seeds.
struct Seeded {
    /// Mean subgoal completion, percent.
    completion: f64,
    /// Mean success, percent.
    success: f64,
    /// Training seeds averaged.
    seeds: usize,
}

/// A run tag without its trailing `+seedN` (a replicate at another `train.seed`).
fn strip_seed(tag: &str) -> &str {
    match tag.rsplit_once("+seed") {
        Some((base, n)) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => base,
        _ => tag,
    }
}

/// The run-tag suffixes under which a memory claim can be compared: `""` (untagged runs) and every
/// tag other than the `windows` ablation that some e_slotssm or slotvla_h1 run carries (`"+plain"`
/// for `e_slotssm+plain`), in first-seen order.
fn recipes(by_variant: &[(&str, Vec<&TaskSummary>)]) -> Vec<String> {
    let mut out = vec![String::new()];
    for (label, _) in by_variant {
        // `+seedN` runs are replicates of their recipe, not a recipe of their own.
        let Some((base, tag)) = strip_seed(label).split_once('+') else {
            continue;
        };
        if matches!(base, "e_slotssm" | "slotvla_h1")
            && !tag.starts_with("windows")
            && !out.iter().any(|r| r.strip_prefix('+') == Some(tag))
        {
            out.push(format!("+{tag}"));
        }
    }
    out
}

/// The memory claim section of one mode (empty when no counting task has both sides): on each
/// counting task, subgoal completion (success in parentheses) of e_slotssm minus slotvla_h1 (equal
/// inputs, no oracle label), of e_slotssm minus e_slotssm trained on independent windows, and of
/// e_slotssm_oracle minus e_slotssm; and whether the claim (≥ [`CLAIM_MARGIN`] points on every
/// counting task measured) holds.
///
/// `recipe` is a run tag suffix (`""` or e.g. `"+plain"`): the comparison is then between the runs
/// of that tag (the same data and training recipe on both sides).
fn memory_claim(mode: &str, by_variant: &[(&str, Vec<&TaskSummary>)], recipe: &str) -> String {
    // A variant's completion and success on a task, the mean over its training seeds (the run
    // of the label and its `+seedN` replicates), with their number.
    let find = |variant: &str, task: &str| -> Option<Seeded> {
        let label = format!("{variant}{recipe}");
        let rows: Vec<&TaskSummary> = by_variant
            .iter()
            .filter(|(v, _)| strip_seed(v) == label)
            .filter_map(|(_, rows)| rows.iter().find(|t| t.task == task).copied())
            .collect();
        let n = rows.len();
        (n > 0).then(|| Seeded {
            completion: rows.iter().map(|t| t.completion).sum::<f64>() / n as f64,
            success: rows.iter().map(|t| t.success).sum::<f64>() / n as f64,
            seeds: n,
        })
    };
    let measured: Vec<&str> = COUNTING_TASKS
        .into_iter()
        .filter(|t| find("e_slotssm", t).is_some() && find("slotvla_h1", t).is_some())
        .collect();
    if measured.is_empty() {
        return String::new();
    }
    let r = recipe;
    // The windows ablations of this recipe (`e_slotssm+windows{r}`, `e_slotssm+windows16{r}`, …),
    // in first-seen order: each one row.
    let mut ablations: Vec<String> = vec![];
    for (label, _) in by_variant {
        let label = strip_seed(label);
        if let Some(w) = label
            .strip_prefix("e_slotssm+windows")
            .and_then(|x| x.strip_suffix(r))
            .filter(|w| w.chars().all(|c| c.is_ascii_digit()))
        {
            let v = format!("e_slotssm+windows{w}");
            if !ablations.contains(&v) {
                ablations.push(v);
            }
        }
    }
    let mut comparisons: Vec<(String, String, String)> = vec![(
        format!("e_slotssm{r} − slotvla_h1{r} (the claim)"),
        "e_slotssm".into(),
        "slotvla_h1".into(),
    )];
    for v in ablations {
        let frames = match v.strip_prefix("e_slotssm+windows") {
            Some("") | None => String::new(),
            Some(n) => format!(" of {n} frames"),
        };
        comparisons.push((
            format!("e_slotssm{r} − {v}{r} (carried memory vs independent windows{frames})"),
            "e_slotssm".into(),
            v,
        ));
    }
    comparisons.push((
        format!("e_slotssm_oracle{r} − e_slotssm{r} (what the oracle label adds)"),
        "e_slotssm_oracle".into(),
        "e_slotssm".into(),
    ));
    let title = if recipe.is_empty() {
        String::new()
    } else {
        format!(" ({recipe} runs)")
    };
    let mut s = format!(
        "### {mode} mode: the memory claim on the counting tasks{title}\n\nPoints of subgoal \
         completion (success in parentheses) between two variants on each counting task; the \
         claim: e_slotssm ≥ {CLAIM_MARGIN:.0} points above the memoryless slotvla_h1 with equal \
         inputs (no oracle label) on every counting task.\n\n"
    );
    // Every variant the comparisons read, once each, in order.
    let mut variants: Vec<&str> = vec![];
    for (_, a, b) in &comparisons {
        for v in [a.as_str(), b.as_str()] {
            if !variants.contains(&v) {
                variants.push(v);
            }
        }
    }
    table_header(&mut s, "comparison", &measured);
    // The claim's own margins (every measured task has both sides), per task.
    let mut margins: Vec<f64> = vec![];
    for (i, (label, a, b)) in comparisons.iter().enumerate() {
        let cells: Vec<Option<(f64, f64)>> = measured
            .iter()
            .map(|t| {
                let (x, y) = (find(a, t)?, find(b, t)?);
                Some((x.completion - y.completion, x.success - y.success))
            })
            .collect();
        if i == 0 {
            margins = cells.iter().flatten().map(|(dc, _)| *dc).collect();
        }
        if cells.iter().all(Option::is_none) {
            continue;
        }
        s.push_str(&format!("| {label} |"));
        for c in &cells {
            match c {
                Some((dc, ds)) => s.push_str(&format!(" {dc:+.0} ({ds:+.0}) |")),
                None => s.push_str(" – |"),
            }
        }
        let have: Vec<(f64, f64)> = cells.iter().flatten().copied().collect();
        let n = have.len() as f64;
        let (mc, ms) = have
            .iter()
            .fold((0.0, 0.0), |(c, s), (dc, ds)| (c + dc / n, s + ds / n));
        s.push_str(&format!(" **{mc:+.1}** ({ms:+.1}) |\n"));
    }
    let replicated: Vec<String> = variants
        .into_iter()
        .flat_map(|v| {
            measured.iter().filter_map(move |t| {
                find(v, t)
                    .filter(|x| x.seeds > 1)
                    .map(|x| format!("{v}{r} on {} ({} seeds)", report::short(t), x.seeds))
            })
        })
        .collect();
    if !replicated.is_empty() {
        s.push_str(&format!(
            "\nA variant trained at several `train.seed`s (`+seedN` rows) enters with its mean over \
             them: {}.\n",
            replicated.join(", ")
        ));
    }
    let missing: Vec<&str> = COUNTING_TASKS
        .into_iter()
        .filter(|t| !measured.contains(t))
        .map(report::short)
        .collect();
    let tasks = |pass: bool| -> Vec<String> {
        measured
            .iter()
            .zip(&margins)
            .filter(|(_, m)| (**m >= CLAIM_MARGIN) == pass)
            .map(|(t, m)| {
                if pass {
                    report::short(t).to_string()
                } else {
                    format!("{} ({m:+.0})", report::short(t))
                }
            })
            .collect()
    };
    let (pass, fail) = (tasks(true), tasks(false));
    if fail.is_empty() {
        s.push_str(&format!(
            "\nThe claim holds on {} (every margin ≥ {CLAIM_MARGIN:.0} points).",
            pass.join(", ")
        ));
    } else {
        s.push_str(&format!(
            "\nThe claim does not hold: the margin is below {CLAIM_MARGIN:.0} points on {}{}.",
            fail.join(", "),
            if pass.is_empty() {
                String::new()
            } else {
                format!(" (it holds on {})", pass.join(", "))
            }
        ));
    }
    if !missing.is_empty() {
        s.push_str(&format!(" Not measured on {}.", missing.join(", ")));
    }
    s.push_str("\n\n");
    s
}

/// `docs/results.csv`: one row per (mode, variant, task).
pub fn csv(runs: &[RunResult]) -> String {
    let mut s = String::from(
        "obs,variant,task,episodes,completion,completion_ci95,success,success_lo,success_hi,over_repetition\n",
    );
    for r in runs {
        for t in &r.tasks {
            s.push_str(&format!(
                "{},{},{},{},{:.2},{:.2},{:.2},{:.2},{:.2},{}\n",
                r.obs,
                r.variant,
                t.task,
                t.episodes,
                t.completion,
                t.completion_ci95,
                t.success,
                t.success_ci95[0],
                t.success_ci95[1],
                t.over_repetition
            ));
        }
    }
    s
}

/// `docs/results.svg`: subgoal completion per task (grouped bars, one colour per variant, error
/// bars at the 95 % interval), one panel per observation mode. Written by hand: a few rectangles
/// and labels (a plotting crate would need system fonts).
pub fn svg(runs: &[RunResult]) -> String {
    const COLORS: [&str; 8] = [
        "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
    ];
    let mut modes: Vec<&str> = runs.iter().map(|r| r.obs.as_str()).collect();
    modes.sort();
    modes.dedup();
    let variants = report::first_seen(runs.iter().map(|r| r.variant.as_str()));
    let panel_h = 260.0;
    let (left, top) = (50.0, 30.0);
    let mut body = String::new();
    let mut width: f64 = 600.0;
    for (pi, m) in modes.iter().enumerate() {
        let of_mode: Vec<&RunResult> = runs.iter().filter(|r| &r.obs == m).collect();
        let mut tasks: Vec<String> = of_mode
            .iter()
            .flat_map(|r| r.tasks.iter().map(|t| t.task.clone()))
            .collect();
        tasks.sort_by_key(|t| task_key(t));
        tasks.dedup();
        let group = (variants.len() as f64 * 8.0 + 10.0).max(30.0);
        width = width.max(left + tasks.len() as f64 * group + 180.0);
        let y0 = top + pi as f64 * (panel_h + 60.0);
        let scale = |v: f64| y0 + panel_h - v / 100.0 * panel_h;
        body.push_str(&format!(
            "<text x=\"{left}\" y=\"{}\" font-size=\"14\">{m} mode: subgoal completion (%)</text>\n",
            y0 - 10.0
        ));
        for g in [0.0, 25.0, 50.0, 75.0, 100.0] {
            body.push_str(&format!(
                "<line x1=\"{left}\" x2=\"{}\" y1=\"{y}\" y2=\"{y}\" stroke=\"#ddd\"/><text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">{g:.0}</text>\n",
                left + tasks.len() as f64 * group,
                left - 4.0,
                scale(g) + 3.0,
                y = scale(g)
            ));
        }
        for (ti, t) in tasks.iter().enumerate() {
            let gx = left + ti as f64 * group + 5.0;
            for (vi, v) in variants.iter().enumerate() {
                let Some(row) = of_mode
                    .iter()
                    .filter(|r| r.variant == *v)
                    .flat_map(|r| r.tasks.iter())
                    .find(|x| &x.task == t)
                else {
                    continue;
                };
                let x = gx + vi as f64 * 8.0;
                let y = scale(row.completion);
                let c = COLORS[vi % COLORS.len()];
                body.push_str(&format!(
                    "<rect x=\"{x:.1}\" y=\"{y:.1}\" width=\"7\" height=\"{:.1}\" fill=\"{c}\"/>\n",
                    y0 + panel_h - y
                ));
                let (lo, hi) = (
                    (row.completion - row.completion_ci95).max(0.0),
                    (row.completion + row.completion_ci95).min(100.0),
                );
                body.push_str(&format!(
                    "<line x1=\"{:.1}\" x2=\"{:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"#333\"/>\n",
                    x + 3.5,
                    x + 3.5,
                    scale(lo),
                    scale(hi)
                ));
            }
            body.push_str(&format!(
                "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"middle\">{}</text>\n",
                gx + variants.len() as f64 * 4.0,
                y0 + panel_h + 14.0,
                report::short(t)
            ));
        }
    }
    let lx = width - 170.0;
    for (vi, v) in variants.iter().enumerate() {
        body.push_str(&format!(
            "<rect x=\"{lx}\" y=\"{}\" width=\"10\" height=\"10\" fill=\"{}\"/><text x=\"{}\" y=\"{}\" font-size=\"11\">{v}</text>\n",
            top + vi as f64 * 16.0,
            COLORS[vi % COLORS.len()],
            lx + 14.0,
            top + vi as f64 * 16.0 + 9.0
        ));
    }
    let height = top + modes.len().max(1) as f64 * (panel_h + 60.0);
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" font-family=\"sans-serif\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n{body}</svg>\n"
    )
}

/// Loads a finished run's evaluation (None when it has not been evaluated with the
/// experiment's protocol, which executes the first action of each chunk: an `eval --execute`
/// other than `first` written to the run's `eval/` is not one of its results).
pub fn load_result(x: &Experiment, run: &Path, obs: &str, label: &str) -> Option<RunResult> {
    let (_, r) = Results::load(&run.join("eval")).ok()?;
    if !x.same_protocol(r.episodes_per_task, r.seed, r.full_budget) || r.execution.is_some() {
        return None;
    }
    // An evaluation of a checkpoint before the run's last step (an `eval --run` while it was
    // still training) is not the run's result: the run is trained to the end and evaluated again.
    if let (Some(at), Some(total)) = (r.checkpoint_step, planned_steps(run))
        && at != total
    {
        return None;
    }
    let (train_s, steps) = training_cost(run);
    Some(RunResult {
        obs: obs.to_string(),
        variant: label.to_string(),
        run: run.display().to_string(),
        train_s,
        steps,
        tasks: r.tasks,
    })
}

/// The record of every evaluated run of an experiment, written beside its tables (`OUT/runs.json`)
/// and kept under version control with them: the tables can be rebuilt, and grown by new runs, on
/// a machine that does not hold the run directories (a fresh clone). A run directory that holds an
/// evaluation with the experiment's protocol always wins over its entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ledger {
    /// Episodes per task of every entry.
    pub episodes: usize,
    /// Base evaluation seed of every entry.
    pub seed: u64,
    /// Whether every entry ran the full step budget.
    pub full_budget: bool,
    /// One entry per evaluated run (`run` is its directory, as the plan names it).
    pub runs: Vec<RunResult>,
}

impl Ledger {
    /// Where an experiment keeps its ledger: `OUT/runs.json`.
    pub fn path(x: &Experiment) -> PathBuf {
        x.out.join("runs.json")
    }

    /// The ledger of `runs` under the experiment's protocol.
    pub fn of(x: &Experiment, runs: &[RunResult]) -> Ledger {
        Ledger {
            episodes: x.episodes,
            seed: x.seed,
            full_budget: x.full_budget,
            runs: runs.to_vec(),
        }
    }

    /// Reads the experiment's ledger (`None` when there is none); a file that is not a ledger is
    /// an error naming it.
    pub fn load(x: &Experiment) -> Result<Option<Ledger>, EvalError> {
        let path = Ledger::path(x);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(EvalError::Input {
                    path,
                    message: e.to_string(),
                });
            }
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| EvalError::Input {
                path,
                message: format!("not a ledger of evaluated runs: {e}"),
            })
    }

    /// Whether the entries were evaluated under the experiment's protocol (episodes, seed,
    /// budget): those of another protocol cannot go into its tables.
    pub fn usable(&self, x: &Experiment) -> bool {
        x.same_protocol(self.episodes, self.seed, self.full_budget)
    }

    /// The entry of a planned run: same run directory, observation mode and label.
    pub fn find(&self, run: &str, obs: &str, label: &str) -> Option<&RunResult> {
        self.runs
            .iter()
            .find(|r| r.run == run && r.obs == obs && r.variant == label)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(task: &str, completion: f64, success: f64) -> TaskSummary {
        TaskSummary {
            task: task.into(),
            episodes: 20,
            completion,
            completion_ci95: 5.0,
            success,
            success_ci95: [success - 10.0, success + 10.0],
            mean_steps: 100.0,
            over_repetition: 0,
        }
    }

    /// An experiment with no runs of its own (20 episodes from seed 1000, full budget).
    fn experiment() -> Experiment {
        Experiment {
            name: "p".into(),
            out: "d".into(),
            episodes: 20,
            seed: 1000,
            full_budget: true,
            workers: 1,
            runs_dir: "runs".into(),
            recipes: BTreeMap::new(),
            runs: vec![],
        }
    }

    /// A run's evaluation is the experiment's only with its protocol: episodes, seed, budget,
    /// and the first action of each chunk executed.
    #[test]
    fn load_result_takes_only_the_experiments_protocol() {
        let x = experiment();
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("r");
        std::fs::create_dir_all(run.join("eval")).unwrap();
        let write = |r: &Results| {
            std::fs::write(
                run.join("eval/results.json"),
                serde_json::to_string(r).unwrap(),
            )
            .unwrap();
        };
        let mut r = Results {
            policy: "model".into(),
            run: None,
            checkpoint_step: None,
            execution: None,
            seed: 1000,
            episodes_per_task: 20,
            full_budget: true,
            shard: data::shard::Shard::WHOLE,
            tasks: vec![row("libero_mem/t1", 50.0, 40.0)],
            episodes: vec![],
        };
        write(&r);
        let got = load_result(&x, &run, "state", "e_slotssm").unwrap();
        assert_eq!((got.variant.as_str(), got.tasks.len()), ("e_slotssm", 1));
        r.execution = Some("ensemble".into());
        write(&r);
        assert!(load_result(&x, &run, "state", "e_slotssm").is_none());
        r.execution = None;
        r.full_budget = false;
        write(&r);
        assert!(load_result(&x, &run, "state", "e_slotssm").is_none());
        // Only the evaluation of the run's last step counts.
        r.full_budget = true;
        std::fs::write(
            run.join("config.toml"),
            "name = \"r\"\n[train]\nsteps = 8000\n",
        )
        .unwrap();
        assert_eq!(planned_steps(&run), Some(8000));
        r.checkpoint_step = Some(4000);
        write(&r);
        assert!(load_result(&x, &run, "state", "e_slotssm").is_none());
        r.checkpoint_step = Some(8000);
        write(&r);
        assert!(load_result(&x, &run, "state", "e_slotssm").is_some());
    }

    fn state_run(variant: &str, tasks: Vec<TaskSummary>) -> RunResult {
        RunResult {
            obs: "state".into(),
            variant: variant.into(),
            run: format!("runs/{variant}"),
            train_s: None,
            steps: None,
            tasks,
        }
    }

    /// The memory-claim section: margins per counting task and their mean, the verdict, the
    /// counting tasks not measured; no section without both sides of the claim.
    #[test]
    fn memory_claim_gives_margins_and_a_verdict() {
        let x = experiment();
        let t3 = "libero_mem/t3";
        let t5 = "libero_mem/t5";
        let mut runs = vec![
            state_run("e_slotssm_oracle", vec![row(t3, 60.0, 55.0)]),
            state_run("e_slotssm", vec![row(t3, 40.0, 5.0), row(t5, 50.0, 10.0)]),
            state_run("slotvla_h1", vec![row(t3, 5.0, 0.0), row(t5, 10.0, 0.0)]),
            state_run("e_slotssm+windows", vec![row(t5, 20.0, 0.0)]),
            state_run("e_slotssm", vec![row("libero_mem/t1", 90.0, 30.0)]),
        ];
        let md = markdown(&x, &runs, &[]);
        let sec = md
            .split("### state mode: the memory claim on the counting tasks")
            .nth(1)
            .expect("a memory-claim section");
        assert!(sec.contains("| comparison | t3 | t5 | mean |"), "{sec}");
        assert!(
            sec.contains(
                "| e_slotssm − slotvla_h1 (the claim) | +35 (+5) | +40 (+10) | **+37.5** (+7.5) |"
            ),
            "{sec}"
        );
        assert!(
            sec.contains(
                "(carried memory vs independent windows) | – | +30 (+10) | **+30.0** (+10.0) |"
            ),
            "{sec}"
        );
        assert!(
            sec.contains("(what the oracle label adds) | +20 (+50) | – | **+20.0** (+50.0) |"),
            "{sec}"
        );
        assert!(
            sec.contains(
                "The claim holds on t3, t5 (every margin ≥ 30 points). Not measured on t4, t6."
            ),
            "{sec}"
        );
        // A second windows ablation (16-frame windows) is a row of its own, after the first.
        let mut more = runs.clone();
        more.push(state_run("e_slotssm+windows16", vec![row(t3, 10.0, 0.0)]));
        let md = markdown(&x, &more, &[]);
        let at = |needle: &str| md.find(needle).unwrap_or_else(|| panic!("{needle}: {md}"));
        assert!(
            at("(carried memory vs independent windows) | – | +30 (+10) |")
                < at(
                    "| e_slotssm − e_slotssm+windows16 (carried memory vs independent windows of 16 frames) | +30 (+5) | – | **+30.0** (+5.0) |"
                )
        );
        // A margin under 30 points on one task: the claim does not hold.
        runs[2].tasks[1].completion = 25.0;
        let md = markdown(&x, &runs, &[]);
        assert!(
            md.contains(
                "The claim does not hold: the margin is below 30 points on t5 (+25) (it holds on t3)."
            ),
            "{md}"
        );
        // Without slotvla_h1 there is no claim to measure.
        runs.remove(2);
        assert!(!markdown(&x, &runs, &[]).contains("memory claim"));
    }

    /// Replicates at other training seeds (`+seedN`) enter the claim with their recipe's run,
    /// averaged; they are not a recipe of their own.
    #[test]
    fn memory_claim_averages_the_training_seeds() {
        let x = experiment();
        let t3 = "libero_mem/t3";
        let runs = vec![
            state_run("e_slotssm+hold", vec![row(t3, 70.0, 40.0)]),
            state_run("e_slotssm+hold+seed1", vec![row(t3, 10.0, 0.0)]),
            state_run("e_slotssm+hold+seed2", vec![row(t3, 10.0, 20.0)]),
            state_run("slotvla_h1+hold", vec![row(t3, 0.0, 0.0)]),
        ];
        let md = markdown(&x, &runs, &[]);
        assert_eq!(
            md.matches("the memory claim on the counting tasks").count(),
            1,
            "{md}"
        );
        let hold = md
            .split("the memory claim on the counting tasks (+hold runs)")
            .nth(1)
            .expect("a section of the +hold runs");
        assert!(
            hold.contains("| e_slotssm+hold − slotvla_h1+hold (the claim) | +30 (+20) |"),
            "{hold}"
        );
        assert!(hold.contains("e_slotssm+hold on t3 (3 seeds)"), "{hold}");
        assert_eq!(strip_seed("hold+seed12"), "hold");
        assert_eq!(strip_seed("hold+seedling"), "hold+seedling");
    }

    /// Tagged runs (another data recipe on both sides) get their own claim section, compared
    /// only with runs of the same tag; the `windows` ablation is not a recipe of its own.
    #[test]
    fn memory_claim_compares_runs_of_the_same_tag() {
        let x = experiment();
        let t3 = "libero_mem/t3";
        let runs = vec![
            state_run("e_slotssm", vec![row(t3, 40.0, 5.0)]),
            state_run("slotvla_h1", vec![row(t3, 5.0, 0.0)]),
            state_run("e_slotssm+windows", vec![row(t3, 20.0, 0.0)]),
            state_run("e_slotssm+plain", vec![row(t3, 90.0, 60.0)]),
            state_run("slotvla_h1+plain", vec![row(t3, 70.0, 10.0)]),
            state_run("e_slotssm_oracle+plain", vec![row(t3, 100.0, 95.0)]),
        ];
        let md = markdown(&x, &runs, &[]);
        assert_eq!(
            md.matches("the memory claim on the counting tasks").count(),
            2
        );
        let plain = md
            .split("the memory claim on the counting tasks (+plain runs)")
            .nth(1)
            .expect("a section of the +plain runs");
        assert!(
            plain.contains(
                "| e_slotssm+plain − slotvla_h1+plain (the claim) | +20 (+50) | **+20.0** (+50.0) |"
            ),
            "{plain}"
        );
        assert!(
            plain.contains("what the oracle label adds) | +10 (+35) |"),
            "{plain}"
        );
        assert!(!plain.contains("independent windows"), "{plain}");
        assert!(
            plain.contains("the margin is below 30 points on t3 (+20)"),
            "{plain}"
        );
        let untagged = md.split("(+plain runs)").next().unwrap();
        assert!(
            untagged.contains("| e_slotssm − slotvla_h1 (the claim) | +35 (+5) |"),
            "{untagged}"
        );
        assert!(
            untagged.contains("independent windows) | +20 (+5) |"),
            "{untagged}"
        );
    }

    /// An experiment file `x.toml` with `text` in a fresh folder (kept alive by the returned guard).
    fn experiment_file(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.toml");
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn side_by_side_trainings_share_the_cores() {
        assert_eq!(threads_per_job(2, 2), 1);
        assert_eq!(threads_per_job(16, 2), 8);
        assert_eq!(threads_per_job(16, 3), 5);
        assert_eq!(threads_per_job(2, 4), 1, "at least one thread each");
        assert_eq!(threads_per_job(2, 1), 2);
        assert_eq!(threads_per_job(4, 0), 4, "no jobs reads as one");
    }

    #[test]
    fn only_admits_its_mode_and_suite_and_names_what_exists() {
        let (_dir, p) = experiment_file(
            "name = \"paper\"\nout = \"docs\"\n[[runs]]\nobs = \"state\"\nsuite = \"libero_mem\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\"]\n[[runs]]\nobs = \"pixels\"\nsuite = \"t1\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\"]\n",
        );
        let x = Experiment::load(&p).unwrap();
        let only = |obs: Option<&str>, suite: Option<&str>| Only {
            obs: obs.map(String::from),
            suite: suite.map(String::from),
            tag: None,
        };
        let admitted = |o: &Only| -> Vec<bool> { x.runs.iter().map(|r| o.admits(r)).collect() };
        assert_eq!(admitted(&Only::default()), [true, true]);
        assert_eq!(admitted(&only(Some("state"), None)), [true, false]);
        assert_eq!(admitted(&only(None, Some("t1"))), [false, true]);
        assert_eq!(admitted(&only(Some("state"), Some("t1"))), [false, false]);
        assert!(only(Some("pixels"), None).check(&x, &p).is_ok());
        let err = only(Some("state"), Some("t1"))
            .check(&x, &p)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with(&p.display().to_string()), "{err}");
        assert!(
            err.ends_with(
                "no run has obs = \"state\" suite = \"t1\" (modes: state, pixels; suites: libero_mem, t1; tags: )"
            ),
            "{err}"
        );
    }

    #[test]
    fn only_admits_a_tag_and_the_empty_tag_admits_untagged_groups() {
        let (_dir, p) = experiment_file(
            "name = \"paper\"\nout = \"docs\"\n[[runs]]\nobs = \"state\"\nsuite = \"libero_mem\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\"]\n[[runs]]\nobs = \"state\"\nsuite = \"libero_mem\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\"]\ntag = \"40k\"\n",
        );
        let x = Experiment::load(&p).unwrap();
        let tag = |t: &str| Only {
            tag: Some(t.into()),
            ..Only::default()
        };
        let admitted = |o: &Only| -> Vec<bool> { x.runs.iter().map(|r| o.admits(r)).collect() };
        assert_eq!(admitted(&tag("40k")), [false, true]);
        assert_eq!(admitted(&tag("")), [true, false]);
        let err = tag("4k").check(&x, &p).unwrap_err().to_string();
        assert!(
            err.ends_with("no run has tag = \"4k\" (modes: state; suites: libero_mem; tags: 40k)"),
            "{err}"
        );
    }

    /// A group's recipe comes before its own `set` (later overrides win in `train`), groups
    /// without one keep their own; an unknown recipe is an error naming the file and the group.
    #[test]
    fn recipes_expand_before_the_groups_own_overrides() {
        let group = |tag: &str, recipe: &str, set: &str| {
            format!(
                "[[runs]]\nobs = \"state\"\nsuite = \"t1\"\nconfig = \"c\"\nvariants = [\"e_slotssm\"]\ntag = \"{tag}\"\n{}set = [{set}]\n",
                if recipe.is_empty() {
                    String::new()
                } else {
                    format!("recipe = \"{recipe}\"\n")
                }
            )
        };
        let (_dir, p) = experiment_file(&format!(
            "name = \"x\"\nout = \"d\"\n[recipes]\nlong = [\"train.steps=40000\", \"train.ema=0.999\"]\nempty = []\n{}{}{}",
            group("a", "long", "\"train.steps=10\""),
            group("b", "empty", "\"a=1\""),
            group("c", "", "\"b=2\"")
        ));
        let x = Experiment::load(&p).unwrap();
        let sets: Vec<&[String]> = x.runs.iter().map(|r| r.set.as_slice()).collect();
        assert_eq!(
            sets,
            [
                &["train.steps=40000", "train.ema=0.999", "train.steps=10"][..],
                &["a=1"][..],
                &["b=2"][..]
            ]
        );
        let plan = x.plan();
        assert_eq!(
            train_overrides(&plan[0])[2..],
            ["train.steps=40000", "train.ema=0.999", "train.steps=10"]
        );
        assert_eq!(x.runs[0].recipe.as_deref(), Some("long"));
        assert_eq!(
            train_command(&plan[0], Path::new("runs")),
            "train 'c' --run-dir 'runs/x_state_t1_e_slotssm_a' --set 'name=\"x_state_t1_e_slotssm_a\"' \
             --set 'model.variant=\"e_slotssm\"' --set 'train.steps=40000' --set 'train.ema=0.999' \
             --set 'train.steps=10'"
        );
        std::fs::write(
            &p,
            format!(
                "name = \"x\"\nout = \"d\"\n[recipes]\nlong = []\n{}{}",
                group("a", "", "\"b=2\""),
                group("b", "lnog", "")
            ),
        )
        .unwrap();
        let e = Experiment::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("x.toml")
                && e.contains("runs[1].recipe: unknown recipe `lnog` (recipes: long)"),
            "{e}"
        );
        std::fs::write(
            &p,
            format!("name = \"x\"\nout = \"d\"\n{}", group("a", "long", "")),
        )
        .unwrap();
        let e = Experiment::load(&p).unwrap_err().to_string();
        assert!(
            e.contains(
                "runs[0].recipe: unknown recipe `long` (recipes: none; define them under [recipes])"
            ),
            "{e}"
        );
        // A quote inside an override survives the shell quoting.
        let mut spec = x.runs[2].clone();
        spec.set = vec!["name=\"it's\"".into()];
        let planned = Planned {
            spec: &spec,
            group: 2,
            name: "n".into(),
            variant: "dense".into(),
            label: "dense".into(),
            seed: None,
        };
        assert!(
            train_command(&planned, Path::new("r")).ends_with(r#"--set 'name="it'\''s"'"#),
            "{}",
            train_command(&planned, Path::new("r"))
        );
    }

    #[test]
    fn experiment_files_parse_plan_and_name_bad_keys() {
        let (_dir, p) = experiment_file(
            "name = \"paper\"\nout = \"docs\"\n[[runs]]\nobs = \"state\"\nsuite = \"t1,t3\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\", \"slotvla_h1\"]\n[[runs]]\nobs = \"state\"\nsuite = \"libero_mem\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\"]\ntag = \"windows\"\nset = [\"train.sampling=windows\"]\n",
        );
        let x = Experiment::load(&p).unwrap();
        assert_eq!((x.episodes, x.full_budget, x.workers), (20, true, 1));
        let plan: Vec<(String, String)> = x.plan().into_iter().map(|p| (p.name, p.label)).collect();
        assert_eq!(
            plan,
            [
                ("paper_state_t1-t3_e_slotssm".into(), "e_slotssm".into()),
                ("paper_state_t1-t3_slotvla_h1".into(), "slotvla_h1".into()),
                (
                    "paper_state_libero_mem_e_slotssm_windows".into(),
                    "e_slotssm+windows".into()
                ),
            ]
        );
        // Further seeds: one more run per variant and seed, its seed given last to `train`.
        std::fs::write(
            &p,
            "name = \"x\"\nout = \"d\"\n[[runs]]\nobs = \"state\"\nsuite = \"t1\"\nconfig = \"c.toml\"\nvariants = [\"e_slotssm\", \"dense\"]\ntag = \"hold\"\nset = [\"train.seed=7\", \"data.dir=\\\"d\\\"\"]\nseeds = [1, 2]\n",
        )
        .unwrap();
        let x = Experiment::load(&p).unwrap();
        let plan = x.plan();
        let named: Vec<(&str, &str, Option<u64>)> = plan
            .iter()
            .map(|p| (p.name.as_str(), p.label.as_str(), p.seed))
            .collect();
        assert_eq!(
            named,
            [
                ("x_state_t1_e_slotssm_hold", "e_slotssm+hold", None),
                (
                    "x_state_t1_e_slotssm_hold_seed1",
                    "e_slotssm+hold+seed1",
                    Some(1)
                ),
                (
                    "x_state_t1_e_slotssm_hold_seed2",
                    "e_slotssm+hold+seed2",
                    Some(2)
                ),
                ("x_state_t1_dense_hold", "dense+hold", None),
                ("x_state_t1_dense_hold_seed1", "dense+hold+seed1", Some(1)),
                ("x_state_t1_dense_hold_seed2", "dense+hold+seed2", Some(2)),
            ]
        );
        assert_eq!(
            train_overrides(&plan[2]),
            [
                "name=\"x_state_t1_e_slotssm_hold_seed2\"",
                "model.variant=\"e_slotssm\"",
                "train.seed=7",
                "data.dir=\"d\"",
                "train.seed=2",
            ]
        );
        assert_eq!(train_overrides(&plan[0]).last().unwrap(), "data.dir=\"d\"");
        std::fs::write(&p, "name = \"x\"\nout = \"d\"\nrunz = []\n").unwrap();
        let e = Experiment::load(&p).unwrap_err().to_string();
        assert!(e.contains("runz") && e.contains("x.toml"), "{e}");
        std::fs::write(
            &p,
            "name = \"x\"\nout = \"d\"\n[[runs]]\nobs = \"state\"\nsuite = \"t1\"\nconfig = \"c\"\nvariants = [\"slotssm\"]\n",
        )
        .unwrap();
        let e = Experiment::load(&p).unwrap_err().to_string();
        assert!(e.contains("unknown variant `slotssm`"), "{e}");
        // One run planned twice: by a second entry, or by a seed of one entry the other runs.
        let entry = |tag: &str, seeds: &str| {
            format!(
                "[[runs]]\nobs = \"state\"\nsuite = \"t1\"\nconfig = \"c\"\nvariants = [\"e_slotssm\"]\ntag = \"{tag}\"\nseeds = {seeds}\n"
            )
        };
        for (second, which) in [
            (entry("a", "[]"), "`x_state_t1_e_slotssm_a`"),
            (entry("a_seed1", "[]"), "`x_state_t1_e_slotssm_a_seed1`"),
        ] {
            let text = format!("name = \"x\"\nout = \"d\"\n{}{second}", entry("a", "[1]"));
            std::fs::write(&p, text).unwrap();
            let e = Experiment::load(&p).unwrap_err().to_string();
            assert!(
                e.contains(&format!(
                    "runs[1]: run {which} is planned twice (also by runs[0]"
                )) && e.contains("x.toml"),
                "{e}"
            );
        }
        std::fs::write(
            &p,
            format!(
                "name = \"x\"\nout = \"d\"\n{}{}",
                entry("a", "[1]"),
                entry("b", "[1]")
            ),
        )
        .unwrap();
        assert_eq!(Experiment::load(&p).unwrap().plan().len(), 4);
    }

    /// With `--jobs`, the first run of a config whose dataset is missing trains alone, first.
    #[test]
    fn runs_that_generate_their_dataset_train_alone_first() {
        let (dir, p) = experiment_file(
            "name = \"x\"\nout = \"d\"\n[[runs]]\nobs = \"state\"\nsuite = \"t1\"\nconfig = \"a.toml\"\nvariants = [\"e_slotssm\", \"slotvla_h1\", \"dense\"]\n[[runs]]\nobs = \"state\"\nsuite = \"t3\"\nconfig = \"b.toml\"\nvariants = [\"e_slotssm\", \"dense\"]\n",
        );
        let x = Experiment::load(&p).unwrap();
        let plan = x.plan();
        let todo: Vec<&Planned> = plan.iter().collect();
        let names = |v: Vec<&Planned>| v.into_iter().map(|p| p.name.clone()).collect::<Vec<_>>();
        // a.toml's dataset is missing, b.toml's is there.
        let (alone, rest) = training_waves(&todo, |s| s.config.ends_with("b.toml"));
        assert_eq!(names(alone), ["x_state_t1_e_slotssm"]);
        assert_eq!(
            names(rest),
            [
                "x_state_t1_slotvla_h1",
                "x_state_t1_dense",
                "x_state_t3_e_slotssm",
                "x_state_t3_dense"
            ]
        );
        let (alone, rest) = training_waves(&todo, |_| false);
        assert_eq!(
            names(alone),
            ["x_state_t1_e_slotssm", "x_state_t3_e_slotssm"]
        );
        assert_eq!(rest.len(), 3);
        // Every dataset there: everything may train side by side.
        let (alone, rest) = training_waves(&todo, |_| true);
        assert!(alone.is_empty() && rest.len() == 5);
        // dataset_ready reads [data].dir of the config (relative to the working directory).
        let cfg = dir.path().join("c.toml");
        let data = dir.path().join("ds");
        std::fs::create_dir_all(&data).unwrap();
        std::fs::write(
            &cfg,
            format!("[data]\ndir = {:?}\n", data.display().to_string()),
        )
        .unwrap();
        let mut spec = x.runs[0].clone();
        spec.config = cfg.clone();
        assert!(!dataset_ready(&spec));
        std::fs::write(data.join("index.json"), "{}").unwrap();
        assert!(dataset_ready(&spec));
        // A `data.dir` override is read instead of the config's, quoted or bare; other `data.`
        // overrides do not matter once the folder holds an index.
        spec.set = vec!["data.dir=\"elsewhere\"".into()];
        assert!(!dataset_ready(&spec));
        assert_eq!(dataset_dir(&spec), Some(PathBuf::from("elsewhere")));
        let other = dir.path().join("other");
        std::fs::create_dir_all(&other).unwrap();
        std::fs::write(other.join("index.json"), "{}").unwrap();
        spec.set = vec![
            format!("data.dir={:?}", other.display().to_string()),
            "data.generate.hold_steps=5".into(),
        ];
        assert!(dataset_ready(&spec));
        spec.set = vec![format!("data.dir={}", other.display())];
        assert!(dataset_ready(&spec));
        spec.set = vec!["data.generate.hold_steps=5".into()];
        assert!(dataset_ready(&spec), "the config's folder has an index");
        spec.set.clear();
        spec.config = dir.path().join("missing.toml");
        assert!(!dataset_ready(&spec));
    }

    /// Two groups of one config on different `data.dir` overrides record two datasets: the first run
    /// of each trains alone.
    #[test]
    fn each_data_dir_override_generates_its_own_dataset() {
        let (_dir, p) = experiment_file(
            "name = \"x\"\nout = \"d\"\n[[runs]]\nobs = \"state\"\nsuite = \"t3\"\nconfig = \"a.toml\"\nvariants = [\"e_slotssm\", \"dense\"]\nset = [\"data.dir=\\\"p\\\"\"]\n[[runs]]\nobs = \"state\"\nsuite = \"t3\"\nconfig = \"a.toml\"\nvariants = [\"e_slotssm\", \"dense\"]\ntag = \"q\"\nset = [\"data.dir=\\\"q\\\"\"]\n",
        );
        let x = Experiment::load(&p).unwrap();
        let plan = x.plan();
        let todo: Vec<&Planned> = plan.iter().collect();
        let (alone, rest) = training_waves(&todo, |_| false);
        let names = |v: Vec<&Planned>| v.into_iter().map(|p| p.name.clone()).collect::<Vec<_>>();
        assert_eq!(
            names(alone),
            ["x_state_t3_e_slotssm", "x_state_t3_e_slotssm_q"]
        );
        assert_eq!(names(rest), ["x_state_t3_dense", "x_state_t3_dense_q"]);
    }

    /// Every shipped experiment file loads, and the training configs it names exist.
    #[test]
    fn shipped_experiment_files_load() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut names = vec![];
        for e in std::fs::read_dir(root.join("configs/experiments")).unwrap() {
            let p = e.unwrap().path();
            let x = Experiment::load(&p).unwrap_or_else(|e| panic!("{e}"));
            for r in &x.runs {
                assert!(
                    root.join(&r.config).is_file(),
                    "{}: {}",
                    p.display(),
                    r.config.display()
                );
            }
            names.push(x.name);
        }
        names.sort();
        assert_eq!(names, ["mem", "paper"]);
    }

    #[test]
    fn tables_json_and_plot_hold_every_run() {
        let x = experiment();
        let runs = vec![
            RunResult {
                obs: "state".into(),
                variant: "e_slotssm".into(),
                run: "runs/a".into(),
                train_s: Some(600.0),
                steps: Some(3000),
                tasks: vec![
                    row("libero_mem/t10", 50.0, 40.0),
                    row("libero_mem/t2", 100.0, 100.0),
                    row(
                        "libero_goal/open_the_middle_drawer_of_the_cabinet",
                        90.0,
                        95.0,
                    ),
                ],
            },
            RunResult {
                obs: "state".into(),
                variant: "slotvla_h1".into(),
                run: "runs/b".into(),
                train_s: None,
                steps: None,
                tasks: vec![row("libero_mem/t2", 20.0, 10.0)],
            },
            // The same variant trained for another task (one config per task) joins its row.
            RunResult {
                obs: "state".into(),
                variant: "e_slotssm".into(),
                run: "runs/c".into(),
                train_s: Some(60.0),
                steps: Some(100),
                tasks: vec![
                    TaskSummary {
                        over_repetition: 7,
                        ..row("libero_mem/t3", 90.0, 55.0)
                    },
                    row("libero_mem/t2", 0.0, 0.0),
                ],
            },
        ];
        let md = markdown(&x, &runs, &[("pixels".into(), "dense".into())]);
        // Table 3 lists t2 before t10, with the mean of the run's LIBERO-Mem tasks.
        let t3 = md.find("libero_mem subgoal completion").unwrap();
        let line = md[t3..]
            .lines()
            .find(|l| l.starts_with("| e_slotssm |"))
            .unwrap();
        assert_eq!(
            line,
            "| e_slotssm | 100 ± 5 | 90 ± 5 | 50 ± 5 | **80.0** ± 2.9 |"
        );
        let table3 = &md[t3..t3 + md[t3..].find("\n#").unwrap()];
        assert_eq!(
            table3.matches("| e_slotssm |").count(),
            1,
            "one row per variant"
        );
        let line = md[t3..]
            .lines()
            .find(|l| l.starts_with("| slotvla_h1 |"))
            .unwrap();
        assert_eq!(line, "| slotvla_h1 | 20 ± 5 | – | – | **20.0** ± 5.0 |");
        // Success with the over-repetitions beside it.
        let sr = md
            .find("libero_mem success (%) and over-repetitions")
            .unwrap();
        let line = md[sr..]
            .lines()
            .find(|l| l.starts_with("| e_slotssm |"))
            .unwrap();
        assert_eq!(line, "| e_slotssm | 100 (0) | 55 (7) | 40 (0) | **65.0** |");
        // Table 2 reports success.
        let t2 = md.find("libero_goal success").unwrap();
        let line = md[t2..]
            .lines()
            .find(|l| l.starts_with("| e_slotssm |"))
            .unwrap();
        assert_eq!(line, "| e_slotssm | 95 ± 10 | **95.0** ± 10.0 |");
        assert!(
            md.contains(
                "| e_slotssm | libero_mem: t2, t10 | 75.0 ± 3.5 | 70.0 ± 7.1 | 3000 | 10.0 min |"
            ) && md.contains(
                "| e_slotssm | libero_mem: t2, t3 | 45.0 ± 3.5 | 27.5 ± 7.1 | 100 | 60 s |"
            ),
            "{md}"
        );
        assert!(md.contains("- pixels mode: dense"));
        let j = results_json(&runs);
        assert_eq!(
            j["state"]["e_slotssm"]["libero_mem/t10"]["completion"],
            50.0
        );
        assert_eq!(j["state"]["slotvla_h1"]["libero_mem/t2"]["episodes"], 20);
        assert_eq!(csv(&runs).lines().count(), 7);
        let svg = svg(&runs);
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(
            svg.matches("<rect x=").count(),
            5 + 2,
            "5 bars (the t2 of the first e_slotssm run) + 2 legend boxes"
        );
    }
}
