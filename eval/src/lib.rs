//! Closed-loop evaluation: rollouts of a policy in the simulator with the LIBERO-Mem goal tracker, and the
//! paper's tables — subgoal completion (tiered credit, Table 3) and success (Table 2) per task, with 95 %
//! confidence intervals, mean steps and over-repetition failures.
//!
//! Episode protocol (libero-mem-reference.md §4): reset from the episode seed (which includes LIBERO-Mem's
//! 20 settle steps with the gripper opening), then up to the task's step budget of policy steps; the goal
//! tracker is checked once per step. By default an episode ends as soon as it succeeds (every subgoal
//! satisfied), as `eval_slotssm_raw.py` does; with `full_budget` it runs the whole budget like upstream's
//! `mem_6`, where success also requires no over-repetition at the end.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sim::task::TaskSpec;
use sim::{Env, EnvConfig, Observation};

/// Errors from evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The simulator failed.
    #[error(transparent)]
    Env(#[from] sim::EnvError),
    /// A task id could not be resolved.
    #[error(transparent)]
    Task(#[from] sim::task::TaskError),
    /// Bad arguments.
    #[error("{0}")]
    Argument(String),
}

/// Something that maps observations to actions, step by step.
pub trait Policy {
    /// Called before each episode with its seed.
    fn reset(&mut self, task: &TaskSpec, seed: u64);
    /// The next 7-D action.
    fn act(&mut self, env: &Env, obs: &Observation) -> [f32; 7];
    /// Whether the policy needs camera images (off: faster state-only rollouts).
    fn needs_images(&self) -> bool;
}

/// Sends zeros with the gripper held: a floor for every table.
#[derive(Debug, Default, Clone, Copy)]
pub struct ZeroPolicy;

impl Policy for ZeroPolicy {
    fn reset(&mut self, _: &TaskSpec, _: u64) {}
    fn act(&mut self, _: &Env, _: &Observation) -> [f32; 7] {
        [0.0; 7]
    }
    fn needs_images(&self) -> bool {
        false
    }
}

/// Uniform random actions in [−1, 1] from the episode seed.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    rng: ChaCha8Rng,
}

impl Default for RandomPolicy {
    fn default() -> Self {
        RandomPolicy {
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }
}

impl Policy for RandomPolicy {
    fn reset(&mut self, _: &TaskSpec, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0005_eed0_fa11);
    }
    fn act(&mut self, _: &Env, _: &Observation) -> [f32; 7] {
        std::array::from_fn(|_| self.rng.random_range(-1.0f32..=1.0))
    }
    fn needs_images(&self) -> bool {
        false
    }
}

/// How to run episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalConfig {
    /// Episodes per task.
    pub episodes: usize,
    /// Base seed; episode k of a task uses [`episode_seed`]`(seed, k)`.
    pub seed: u64,
    /// Run the whole step budget instead of stopping at success.
    pub full_budget: bool,
    /// Camera image side when the policy needs images.
    pub image_size: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig {
            episodes: 20,
            seed: 0,
            full_budget: false,
            image_size: 128,
        }
    }
}

/// The seed of episode `k` under base seed `seed` (SplitMix64 of both, so neighbouring seeds differ).
pub fn episode_seed(seed: u64, k: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k)
        .wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The outcome of one rollout.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// Success (see the module docs for the two protocols).
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

/// Runs episode `k` of `task` with `policy` in `env` (which must be built for `task`).
pub fn run_episode(
    env: &mut Env,
    task: &TaskSpec,
    policy: &mut dyn Policy,
    cfg: &EvalConfig,
    k: usize,
) -> Result<EpisodeResult, EvalError> {
    let seed = episode_seed(cfg.seed, k as u64);
    policy.reset(task, seed);
    let mut obs = env.reset(seed)?;
    let mut steps = 0;
    let status = |o: &Observation| {
        o.goal
            .clone()
            .expect("task environments report goal progress")
    };
    let mut g = status(&obs);
    while steps < task.max_steps {
        if !cfg.full_budget && g.satisfied >= g.goal_len {
            break;
        }
        let a = policy.act(env, &obs);
        obs = env.step(&a)?;
        steps += 1;
        g = status(&obs);
    }
    let success = if cfg.full_budget {
        g.done && !g.failed
    } else {
        g.done || g.satisfied >= g.goal_len
    };
    Ok(EpisodeResult {
        task: task.id.clone(),
        episode: k,
        seed,
        steps,
        satisfied: g.satisfied,
        goal_len: g.goal_len,
        success,
        over_repetition: g.failed,
    })
}

/// An environment configured for `policy`.
pub fn env_for(task: &TaskSpec, policy: &dyn Policy, cfg: &EvalConfig) -> Result<Env, EvalError> {
    Ok(Env::from_task(
        task,
        EnvConfig {
            render: policy.needs_images(),
            image_size: cfg.image_size,
            ..EnvConfig::default()
        },
    )?)
}

/// Per-task summary row.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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

/// A Markdown table of task rows plus the average row.
pub fn markdown(rows: &[TaskSummary]) -> String {
    let mut s = String::from(
        "| task | episodes | subgoal completion % | success % (95 % CI) | mean steps | over-repetition |\n|---|---:|---:|---:|---:|---:|\n",
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
    if rows.len() > 1 {
        let n = rows.len() as f64;
        s.push_str(&format!(
            "| **average** | {} | {:.1} | {:.1} | {:.1} | {} |\n",
            rows.iter().map(|r| r.episodes).sum::<usize>(),
            rows.iter().map(|r| r.completion).sum::<f64>() / n,
            rows.iter().map(|r| r.success).sum::<f64>() / n,
            rows.iter().map(|r| r.mean_steps).sum::<f64>() / n,
            rows.iter().map(|r| r.over_repetition).sum::<usize>()
        ));
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

/// Resolves `--tasks` (comma-separated ids, or the suites `libero_mem`, `libero_goal`, `all`).
pub fn resolve_tasks(spec: &str, repeat: Option<usize>) -> Result<Vec<TaskSpec>, EvalError> {
    let mut out = Vec::new();
    for part in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match part {
            "all" => out.extend(sim::task::list()),
            "libero_mem" | "libero_goal" => out.extend(
                sim::task::list()
                    .into_iter()
                    .filter(|t| t.id.starts_with(&format!("{part}/"))),
            ),
            id => out.push(match repeat {
                Some(n) => sim::task::resolve_with_repeats(id, n)?,
                None => sim::task::resolve(id)?,
            }),
        }
    }
    if out.is_empty() {
        return Err(EvalError::Argument("no tasks given".into()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_interval_brackets_the_rate() {
        let [lo, hi] = wilson(19.0, 20.0);
        assert!(lo > 0.74 && lo < 0.77 && hi > 0.99, "{lo} {hi}");
        assert_eq!(wilson(0.0, 0.0), [0.0, 1.0]);
        let [lo, hi] = wilson(0.0, 10.0);
        assert!(lo == 0.0 && (hi - 0.2775).abs() < 1e-3, "{hi}");
    }

    #[test]
    fn summary_numbers() {
        let ep = |satisfied, success, failed| EpisodeResult {
            task: "t".into(),
            episode: 0,
            seed: 0,
            steps: 10,
            satisfied,
            goal_len: 4,
            success,
            over_repetition: failed,
        };
        let s = summarize(
            "t",
            &[
                ep(4, true, false),
                ep(2, false, false),
                ep(0, false, false),
                ep(4, false, true),
            ],
        );
        assert_eq!(s.completion, 62.5);
        assert_eq!(s.success, 25.0);
        assert_eq!(s.over_repetition, 1);
        assert!(s.completion_ci95 > 0.0);
        let md = markdown(&[s.clone(), s]);
        assert!(
            md.contains("| t | 4 | 62.5 ±") && md.contains("**average**"),
            "{md}"
        );
    }

    #[test]
    fn episode_seeds_differ_and_repeat() {
        assert_eq!(episode_seed(0, 3), episode_seed(0, 3));
        assert_ne!(episode_seed(0, 3), episode_seed(0, 4));
        assert_ne!(episode_seed(0, 3), episode_seed(1, 3));
    }
}
