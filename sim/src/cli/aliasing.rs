//! `sim aliasing`: perceptual aliasing of expert episodes.

use super::{BadInput, classify};

/// Collects `episodes` expert episodes of `task` and prints the aliasing fractions.
pub fn run(
    task: &str,
    episodes: usize,
    seed: u64,
    k: usize,
    side: usize,
    render_size: usize,
) -> anyhow::Result<()> {
    use sim::aliasing::{Features, analyse, collect};
    if episodes == 0 {
        return Err(BadInput("--episodes must be at least 1".into()).into());
    }
    let spec = sim::task::resolve(task).map_err(|e| BadInput(e.to_string()))?;
    let t0 = std::time::Instant::now();
    let frames = collect(&spec, episodes, seed, render_size, side).map_err(|e| match e {
        sim::aliasing::AliasingError::Argument(m) => anyhow::Error::new(BadInput(m)),
        sim::aliasing::AliasingError::Env(e) => classify(e),
    })?;
    data::outln!(
        "{}: {} frames from {episodes} expert episodes (seeds {seed}..{}) in {:.1} s; image {side}x{side} grey; neighbours exclude the same episode within ±{k} steps",
        spec.id,
        frames.len(),
        seed + episodes as u64 - 1,
        t0.elapsed().as_secs_f64()
    );
    data::outln!(
        "\n| features    | frames | NN needs other next subgoal (index) | (text) | NN from another episode |"
    );
    data::outln!("|-------------|--------|------|------|------|");
    let both = analyse(&frames, Features::Both, k);
    for (name, which) in [
        ("image+state", Features::Both),
        ("image only", Features::Image),
        ("state only", Features::State),
    ] {
        let r = if which == Features::Both {
            both.clone()
        } else {
            analyse(&frames, which, k)
        };
        data::outln!(
            "| {name:<11} | {:>6} | {:>5.1}% | {:>5.1}% | {:>5.1}% |",
            r.frames,
            100.0 * r.index_fraction,
            100.0 * r.text_fraction,
            100.0 * r.cross_episode
        );
    }
    data::outln!(
        "\nPer next subgoal (image+state):\n\n| # | next subgoal | frames | aliased |\n|---|---|---|---|"
    );
    for (l, text, n, f) in &both.per_label {
        data::outln!("| {l} | {text} | {n} | {:.1}% |", 100.0 * f);
    }
    Ok(())
}
