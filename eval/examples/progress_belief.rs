//! What a policy trained with the progress loss (`train.loss_weights.progress`) believes it has
//! done, against what it has done: replays the episodes of the run's last evaluation (its
//! `eval/results.json`: task, seeds, full budget) in closed loop and, at every step, reads the
//! progress head's most probable count of subgoals done beside the environment's count. Prints
//! per episode the steps where either count changes and how often they agree, then the totals
//! (steps where the belief is ahead of the count, behind it, equal).
//!
//! `cargo run --release -p eval --example progress_belief -- RUN [EPISODES]`

use anyhow::{Context, bail};
use eval::Policy;

/// The command line.
const USAGE: &str = "usage: progress_belief RUN [EPISODES]";

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (run, episodes) = match &args[..] {
        [run] => (run, usize::MAX),
        [run, n] => (
            run,
            n.parse::<usize>()
                .with_context(|| format!("EPISODES `{n}`: a number"))?,
        ),
        _ => bail!(USAGE),
    };
    let results_path = std::path::Path::new(run).join("eval/results.json");
    let text = std::fs::read_to_string(&results_path)
        .with_context(|| format!("{}: evaluate the run first", results_path.display()))?;
    let results: eval::report::Results = serde_json::from_str(&text)
        .with_context(|| format!("{}: not an evaluation's results", results_path.display()))?;
    let rd = eval::run::open(run)?;
    let device = eval::run::device(&rd, None)?;
    let mut policy = eval::run::policy(&rd, &device)?;
    // Steps with the belief ahead of, behind and equal to the environment's count.
    let (mut ahead, mut behind, mut equal) = (0usize, 0usize, 0usize);
    for ep in results.episodes.iter().take(episodes) {
        let task = sim::task::resolve(&ep.task)?;
        let mut env = eval::env_for(&task, &policy, &eval::EvalConfig::default())?;
        policy.reset(&task, ep.seed)?;
        let mut obs = env.reset(ep.seed)?;
        let mut done_changes = Vec::new();
        let mut belief_changes = Vec::new();
        let (mut last_done, mut last_belief) = (0usize, None);
        let mut agree = 0usize;
        for t in 0..task.max_steps {
            let done = obs.goal.as_ref().map_or(0, |g| g.satisfied);
            let a = policy.act(&env, &obs)?;
            let Some((belief, p)) = policy.progress_belief()? else {
                bail!("{run}: the model has no progress head (trained without the progress loss)");
            };
            if done != last_done {
                done_changes.push(format!("{t}→{done}"));
                last_done = done;
            }
            if last_belief != Some(belief) {
                belief_changes.push(format!("{t}→{belief} ({p:.2})"));
                last_belief = Some(belief);
            }
            match belief.cmp(&done) {
                std::cmp::Ordering::Greater => ahead += 1,
                std::cmp::Ordering::Less => behind += 1,
                std::cmp::Ordering::Equal => {
                    equal += 1;
                    agree += 1;
                }
            }
            obs = env.step(&a)?;
        }
        let g = obs.goal.as_ref();
        println!(
            "episode {} ({} of {} done{}): belief = count at {:.0} % of {} steps\n  count  {}\n  belief {}",
            ep.episode,
            g.map_or(0, |g| g.satisfied),
            g.map_or(0, |g| g.goal_len),
            if g.is_some_and(|g| g.failed) {
                ", over-repeated"
            } else {
                ""
            },
            100.0 * agree as f64 / task.max_steps as f64,
            task.max_steps,
            done_changes.join("  "),
            belief_changes.join("  "),
        );
    }
    let all = (ahead + behind + equal).max(1) as f64;
    println!(
        "all steps: belief equal to the count {:.1} %, ahead {:.1} %, behind {:.1} %",
        100.0 * equal as f64 / all,
        100.0 * ahead as f64 / all,
        100.0 * behind as f64 / all
    );
    Ok(())
}
