//! `sim generate`: scripted-expert demonstrations recorded as mcap episodes plus the dataset index.

use std::path::PathBuf;

use super::BadInput;

/// Generates `episodes` episodes (of which `val` validation) of `task` (or of every shipped task,
/// one subfolder each, for `all`) into `out`.
pub fn run(
    task: String,
    episodes: usize,
    val: usize,
    seed: u64,
    out: PathBuf,
    workers: usize,
    size: usize,
) -> anyhow::Result<()> {
    let tasks = if task == "all" {
        sim::task::list()
    } else {
        vec![sim::task::resolve(&task).map_err(|e| BadInput(e.to_string()))?]
    };
    let cfg = sim::generate::GenerateConfig {
        episodes,
        val,
        seed,
        workers,
        image_size: size,
        ..Default::default()
    };
    for t in &tasks {
        let dir = if tasks.len() > 1 {
            out.join(t.id.replace('/', "_"))
        } else {
            out.clone()
        };
        let bar = indicatif::ProgressBar::new(episodes as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{prefix} {bar:30} {pos}/{len} episodes  {msg}  ETA {eta}",
            )
            .expect("valid template"),
        );
        bar.set_prefix(t.id.clone());
        let start = std::time::Instant::now();
        let index = sim::generate::generate(t, &dir, &cfg, &|p| {
            bar.set_position(p.done as u64);
            bar.set_message(format!(
                "{} ok, {} failed attempts",
                p.successes, p.failures
            ));
        })
        .map_err(|e| match e {
            sim::generate::GenerateError::Argument(m) => anyhow::Error::new(BadInput(m)),
            other => other.into(),
        })?;
        bar.finish_and_clear();
        let steps: usize = index.episodes.iter().map(|e| e.length).sum();
        println!(
            "{}: {} episodes ({} steps) in {} in {:.1} s",
            t.id,
            index.episodes.len(),
            steps,
            dir.display(),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
