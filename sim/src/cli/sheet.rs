//! `sim sheet`: the agentview of every shipped task at one seed in a labelled contact sheet.

use std::path::PathBuf;

use anyhow::Context;
use sim::env::{Env, EnvConfig};

use super::render::render_start;
use super::{BadInput, check_out_dir};

/// Renders every shipped task at `seed` into one PNG at `out`, `size`² tiles from `camera`.
pub fn run(out: PathBuf, seed: u64, size: usize, camera: String) -> anyhow::Result<()> {
    if size == 0 || size > 1024 {
        return Err(BadInput(format!("--size must be between 1 and 1024, got {size}")).into());
    }
    check_out_dir(&out)?;
    let mut tiles = Vec::new();
    for t in sim::task::list() {
        let cfg = EnvConfig {
            image_size: size,
            ..EnvConfig::default()
        };
        let frame = render_start(Env::from_task(&t, cfg), seed, &camera, size)
            .with_context(|| format!("rendering {}", t.id))?;
        tiles.push((
            t.id.replace("libero_goal/", "goal/")
                .replace("libero_mem/", "mem/"),
            frame,
        ));
    }
    let img = sim::sheet::contact_sheet(&tiles, 5).context("no tiles")?;
    data::fsio::write_png(&out, &img)?;
    data::outln!(
        "wrote {} ({} tasks, seed {seed}, camera {camera})",
        out.display(),
        tiles.len()
    );
    Ok(())
}
