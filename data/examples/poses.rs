//! Object poses, hand position and action of the first steps of episode files.
//!
//! `cargo run --release -p data --example poses -- EPISODE.mcap [STEPS]`

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        anyhow::bail!("usage: poses EPISODE.mcap [STEPS]");
    };
    let steps: usize = args.get(1).map_or(Ok(3), |s| s.parse())?;
    let r = data::EpisodeReader::open(path)?;
    for k in 0..steps.min(r.len()) {
        let s = r.read_step(k)?;
        let objs: Vec<String> = s
            .objects
            .iter()
            .filter_map(|o| {
                o.pose.map(|p| {
                    format!(
                        "{} [{:.3} {:.3} {:.3}] {:?}",
                        o.name, p[0], p[1], p[2], o.subgoal_label
                    )
                })
            })
            .collect();
        println!(
            "step {k} hand [{:.3} {:.3} {:.3}] action {:?}\n  {}",
            s.state[0],
            s.state[1],
            s.state[2],
            s.action,
            objs.join("\n  ")
        );
    }
    Ok(())
}
