//! A trained policy along recorded demonstrations: each episode's recorded actions are replayed
//! live from its seed, and at every step the policy (eval's input path, streaming state carried)
//! predicts an action from the same observation; prints predicted vs recorded actions and the
//! mean absolute error of the arm dims, per phase. Tells a policy that did not learn the
//! demonstrations apart from one that learned them and drifts in closed loop.
//!
//! With several episodes it also sums up the *carries* over all of them: the steps where the
//! recorded gripper command is closed and the recorded |x| + |y| exceeds 0.3 (an object held and
//! moved across the table), with the mean |pred − recorded| of x + y there against the mean
//! recorded |x| + |y| (a policy that ignores where to go scores about the latter).
//!
//! `cargo run --release -p eval --example teacher_forced -- RUN EPISODE.mcap [EPISODE.mcap …] [EVERY]`

use anyhow::{Context, bail};
use eval::Policy;

/// The command line.
const USAGE: &str = "usage: teacher_forced RUN EPISODE.mcap [EPISODE.mcap …] [EVERY]";

/// Recorded |x| + |y| above which a step with the gripper closed counts as a carry.
const CARRY_XY: f32 = 0.3;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, rest @ ..] = &args[..] else {
        bail!(USAGE);
    };
    let (episodes, every) = match rest {
        [eps @ .., last] if !last.ends_with(".mcap") => (
            eps,
            last.parse::<usize>()
                .with_context(|| format!("EVERY `{last}`: a number of steps"))?,
        ),
        eps => (eps, 16),
    };
    if episodes.is_empty() {
        bail!(USAGE);
    }
    let rd = eval::run::open(run)?;
    let device = eval::run::device(&rd, None)?;
    let mut policy = eval::run::policy(&rd, &device)?;
    // Carries over all episodes: steps, Σ |err x| + |err y|, Σ |x| + |y| recorded.
    let mut carry = (0usize, 0.0f64, 0.0f64);
    for episode in episodes {
        let reader = data::EpisodeReader::open(episode).with_context(|| episode.clone())?;
        let meta = reader.meta().clone();
        let task = sim::task::resolve(&meta.task_id)?;
        let mut env = eval::env_for(&task, &policy, &eval::EvalConfig::default())?;
        policy.reset(&task, meta.seed)?;
        let mut obs = env.reset(meta.seed)?;
        let n = reader.len();
        let (mut err, mut count) = (vec![0.0f64; 4], vec![0usize; 4]);
        if episodes.len() > 1 {
            println!("{episode}");
        }
        println!("step  recorded (x y z grip)          predicted");
        for t in 0..n {
            let rec = reader.read_step(t)?.action;
            let pred = policy.act(&env, &obs)?;
            let e: f64 = (0..3)
                .map(|d| f64::from((pred[d] - rec[d]).abs()))
                .sum::<f64>()
                / 3.0;
            let phase = match t {
                0..16 => 0,
                16..64 => 1,
                64..256 => 2,
                _ => 3,
            };
            err[phase] += e;
            count[phase] += 1;
            if rec[6] > 0.0 && rec[0].abs() + rec[1].abs() > CARRY_XY {
                carry.0 += 1;
                carry.1 += f64::from((pred[0] - rec[0]).abs() + (pred[1] - rec[1]).abs());
                carry.2 += f64::from(rec[0].abs() + rec[1].abs());
            }
            if t % every == 0 {
                println!(
                    "{t:4}  ({:5.2} {:5.2} {:5.2} {:4.1})  ({:5.2} {:5.2} {:5.2} {:4.1})  |err| {e:.3}",
                    rec[0], rec[1], rec[2], rec[6], pred[0], pred[1], pred[2], pred[6]
                );
            }
            obs = env.step(&rec)?;
        }
        for (i, name) in ["0-15", "16-63", "64-255", "256-"].iter().enumerate() {
            if count[i] > 0 {
                println!(
                    "steps {name}: mean |pred − recorded| over x, y, z = {:.3} ({} steps)",
                    err[i] / count[i] as f64,
                    count[i]
                );
            }
        }
    }
    if episodes.len() > 1 && carry.0 > 0 {
        let k = carry.0 as f64;
        println!(
            "carries ({} steps in {} episodes): mean |pred − recorded| of x + y = {:.3}, \
             recorded |x| + |y| = {:.3}",
            carry.0,
            episodes.len(),
            carry.1 / k,
            carry.2 / k
        );
    }
    Ok(())
}
