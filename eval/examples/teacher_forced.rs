//! A trained policy along a recorded demonstration: the episode's recorded actions are replayed
//! live from its seed, and at every step the policy (eval's input path, streaming state carried)
//! predicts an action from the same observation; prints predicted vs recorded actions and the
//! mean absolute error of the arm dims, per phase. Tells a policy that did not learn the
//! demonstrations apart from one that learned them and drifts in closed loop.
//!
//! `cargo run --release -p eval --example teacher_forced -- RUN EPISODE.mcap [EVERY]`

use anyhow::{Context, bail};
use eval::Policy;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, episode, rest @ ..] = &args[..] else {
        bail!("usage: teacher_forced RUN EPISODE.mcap [EVERY]");
    };
    let every: usize = rest.first().map_or(Ok(16), |s| s.parse())?;
    let rd = eval::run::open(run)?;
    let device = eval::run::device(&rd, None)?;
    let mut policy = eval::run::policy(&rd, &device)?;
    let reader = data::EpisodeReader::open(episode).with_context(|| episode.clone())?;
    let meta = reader.meta().clone();
    let task = sim::task::resolve(&meta.task_id)?;
    let mut env = eval::env_for(&task, &policy, &eval::EvalConfig::default())?;
    policy.reset(&task, meta.seed)?;
    let mut obs = env.reset(meta.seed)?;
    let n = reader.len();
    let (mut err, mut count) = (vec![0.0f64; 4], vec![0usize; 4]);
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
    Ok(())
}
