//! Key frames of a recorded episode as one labelled contact sheet: the first step, every step where the
//! goal tracker appends a subgoal, the step half-way between two appends (the object away), and the
//! last step.
//!
//! `cargo run --release -p sim --example key_frames -- EPISODE.mcap OUT.png`

use anyhow::Context;
use data::EpisodeReader;
use sim::render::Frame;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(input), Some(out)) = (args.get(1), args.get(2)) else {
        anyhow::bail!("usage: key_frames EPISODE.mcap OUT.png");
    };
    let ep = EpisodeReader::open(input)?;
    let steps = ep.read_all()?;
    let mut appends = vec![0usize];
    for k in 1..steps.len() {
        if steps[k].progress.satisfied != steps[k - 1].progress.satisfied {
            appends.push(k);
        }
    }
    let mut picks: Vec<(usize, String)> = vec![(0, "start".into())];
    for w in appends.windows(2) {
        picks.push(((w[0] + w[1]) / 2, "away".into()));
        picks.push((w[1], format!("append {}", steps[w[1]].progress.satisfied)));
    }
    picks.push((steps.len() - 1, "end".into()));
    let mut tiles = Vec::new();
    for (k, label) in picks {
        let img = &steps[k].agentview;
        println!("step {k:>3}: {label}");
        tiles.push((
            format!("{k} {label}"),
            Frame {
                width: img.width as usize,
                height: img.height as usize,
                rgb: Some(img.data.clone()),
                depth: None,
                segmentation: None,
            },
        ));
    }
    let sheet = sim::sheet::contact_sheet(&tiles, 4).context("no frames")?;
    sheet.save(out)?;
    println!("wrote {out} ({} steps in the episode)", steps.len());
    Ok(())
}
