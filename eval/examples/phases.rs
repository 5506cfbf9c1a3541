//! Where recorded rollouts (`eval --record DIR`) or demonstrations stop making progress: per
//! episode, the subgoals satisfied, the first step the gripper closes and how far the hand then
//! is from the nearest movable object (horizontal and vertical, cm), whether any object was held,
//! and the highest lift of a held object (cm above its start); then a summary line.
//!
//! With `--every N` (first argument), every N-th step of each episode is printed too: the hand's
//! position (cm) and the action.
//!
//! `cargo run --release -p eval --example phases -- [--every N] DIR_OR_EPISODE...`

use anyhow::Context;

/// The episode file `arg`, or the episodes of a dataset or `--record` directory (its files and
/// those of its task subfolders).
fn episodes(arg: &str) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let p = std::path::Path::new(arg);
    if p.is_file() {
        return Ok(vec![p.to_path_buf()]);
    }
    Ok(data::index::episode_files(p)?)
}

fn main() -> anyhow::Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let every = if args.first().is_some_and(|a| a == "--every") {
        let n = args
            .get(1)
            .and_then(|v| v.parse::<u64>().ok())
            .filter(|&n| n > 0)
            .context("--every takes a step count ≥ 1")?;
        args.drain(..2);
        Some(n)
    } else {
        None
    };
    println!("episode  satisfied  close@step  dxy_cm  dz_cm  held  lift_cm  steps  dx_cm  dy_cm");
    let (mut n, mut n_held, mut n_closed, mut n_done) = (0, 0, 0, 0);
    for arg in &args {
        for path in episodes(arg)? {
            let reader =
                data::EpisodeReader::open(&path).with_context(|| path.display().to_string())?;
            let steps = reader.read_all()?;
            let Some(first) = steps.first() else { continue };
            let start: Vec<[f32; 3]> = first
                .objects
                .iter()
                .map(|o| o.pose.map_or([0.0; 3], |p| [p[0], p[1], p[2]]))
                .collect();
            let mut close = None;
            let mut held = false;
            let mut lift = 0.0f32;
            for s in &steps {
                if every.is_some_and(|n| s.step % n == 0) {
                    println!(
                        "  step {:>4}  hand {:>6.1} {:>6.1} {:>6.1}  action {:>5.2?}",
                        s.step,
                        s.state[0] * 100.0,
                        s.state[1] * 100.0,
                        s.state[2] * 100.0,
                        s.action
                    );
                }
                if close.is_none() && s.action[6] > 0.0 {
                    let hand = [s.state[0], s.state[1], s.state[2]];
                    let nearest = s
                        .objects
                        .iter()
                        .filter_map(|o| o.pose)
                        .map(|p| {
                            let dxy = ((p[0] - hand[0]).powi(2) + (p[1] - hand[1]).powi(2)).sqrt();
                            (dxy, p[2] - hand[2], hand[0] - p[0], hand[1] - p[1])
                        })
                        .min_by(|a, b| a.0.total_cmp(&b.0));
                    close = Some((s.step, nearest));
                }
                for (o, s0) in s.objects.iter().zip(&start) {
                    if o.grasped == Some(true) {
                        held = true;
                        if let Some(p) = o.pose {
                            lift = lift.max(p[2] - s0[2]);
                        }
                    }
                }
            }
            let last = steps.last().expect("non-empty");
            n += 1;
            n_held += usize::from(held);
            n_closed += usize::from(close.is_some());
            n_done += usize::from(last.progress.satisfied == last.progress.total);
            let (at, dxy, dz, dx, dy) = match close {
                Some((t, Some((dxy, dz, dx, dy)))) => (
                    t.to_string(),
                    dxy * 100.0,
                    dz * 100.0,
                    dx * 100.0,
                    dy * 100.0,
                ),
                _ => (
                    close.map_or("-".into(), |c| c.0.to_string()),
                    f32::NAN,
                    f32::NAN,
                    f32::NAN,
                    f32::NAN,
                ),
            };
            println!(
                "{:<8} {:>4}/{:<4}  {:>10}  {:>6.1}  {:>5.1}  {:>4}  {:>7.1}  {:>5}  {:>5.1}  {:>5.1}",
                path.file_stem().and_then(|s| s.to_str()).unwrap_or("?"),
                last.progress.satisfied,
                last.progress.total,
                at,
                dxy,
                dz,
                if held { "yes" } else { "no" },
                lift * 100.0,
                steps.len(),
                dx,
                dy
            );
        }
    }
    println!(
        "{n} episodes: every subgoal satisfied in {n_done}, gripper closed in {n_closed}, an \
         object held in {n_held}"
    );
    Ok(())
}
