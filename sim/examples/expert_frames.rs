//! One expert episode as a contact sheet: the agentview every N control steps and the last frame,
//! with the goal tracker's final status printed. For looking at what a plan does.
//!
//! `cargo run --release -p sim --example expert_frames -- TASK SEED OUT.png [EVERY]`

use anyhow::Context;
use sim::render::Frame;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(task), Some(seed), Some(out)) = (args.get(1), args.get(2), args.get(3)) else {
        anyhow::bail!("usage: expert_frames TASK SEED OUT.png [EVERY]");
    };
    let every: usize = args
        .get(4)
        .map(|s| s.parse())
        .transpose()
        .context("EVERY must be a number of steps")?
        .unwrap_or(20)
        .max(1);
    let seed: u64 = seed.parse().context("SEED must be an integer")?;
    let task = sim::task::resolve(task)?;
    let size = 256;
    let mut env = sim::Env::from_task(
        &task,
        sim::EnvConfig {
            image_size: size,
            ..Default::default()
        },
    )?;
    let mut obs = env.reset(seed)?;
    let mut expert = sim::expert::Expert::new(&task, seed);
    let tile = |label: String, obs: &sim::Observation| {
        (
            label,
            Frame {
                width: size,
                height: size,
                rgb: Some(obs.agentview_rgb.clone()),
                depth: None,
                segmentation: None,
            },
        )
    };
    let mut tiles = Vec::new();
    while obs.step < task.max_steps {
        if obs.step % every == 0 {
            tiles.push(tile(format!("{}", obs.step), &obs));
        }
        let Some(action) = expert.act(&env, &obs) else {
            break;
        };
        obs = env.step(&action)?;
    }
    tiles.push(tile(format!("end {}", obs.step), &obs));
    let sheet = sim::sheet::contact_sheet(&tiles, 6).context("no frames")?;
    sheet.save(out)?;
    match &obs.goal {
        Some(g) => println!(
            "{}: {} steps, {}/{} subgoals, done {}, failed {}; wrote {out}",
            task.id, obs.step, g.satisfied, g.goal_len, g.done, g.failed
        ),
        None => println!("{}: {} steps; wrote {out}", task.id, obs.step),
    }
    Ok(())
}
