//! `sim bench`: physics, rendering and Env throughput, or a task scene's Env steps per second.

use super::{BadInput, classify};

/// Measures and prints (a table, or JSON with `json`).
pub fn run(
    json: bool,
    steps: usize,
    rounds: usize,
    gl_threads: usize,
    task: Option<String>,
    assets: String,
) -> anyhow::Result<()> {
    // SAFETY: set before any thread or GL context exists; llvmpipe reads it when the context is made.
    unsafe { std::env::set_var("LP_NUM_THREADS", gl_threads.to_string()) };
    if let Some(id) = task {
        let spec = sim::task::resolve(&id).map_err(|e| BadInput(e.to_string()))?;
        let packs = match assets.as_str() {
            "both" => vec![sim::pack::AssetPack::Builtin, sim::pack::AssetPack::Libero],
            other => vec![other.parse().map_err(BadInput)?],
        };
        let mut rows = Vec::new();
        for p in packs {
            rows.push(sim::bench::run_task(&spec, p, steps).map_err(classify)?);
        }
        if json {
            data::outln!("{}", serde_json::to_string(&rows)?);
        } else {
            for r in &rows {
                data::outln!(
                    "{} [{}]: env steps/s {:.1} (2×128² RGB), {:.1} without rendering",
                    r.task,
                    r.assets,
                    r.env_steps_per_s,
                    r.env_state_only_steps_per_s
                );
            }
        }
        return Ok(());
    }
    let r = sim::bench::run(steps, rounds).map_err(classify)?;
    if json {
        data::outln!("{}", serde_json::to_string(&r)?);
    } else {
        data::outln!("renderer               {}", r.gl_renderer);
        data::outln!("physics steps/s        {:>10.0}", r.physics_steps_per_s);
        data::outln!("render fps (128², RGB) {:>10.1}", r.render_fps_128);
        data::outln!(
            "raw loop steps/s       {:>10.1}  (25 substeps + 2×128² RGB, bare FFI)",
            r.raw_loop_steps_per_s
        );
        data::outln!(
            "env steps/s            {:>10.1}  (same work through Env)",
            r.env_steps_per_s
        );
        data::outln!("env / raw              {:>10.3}", r.env_over_raw);
        data::outln!(
            "env steps/s, no render {:>10.1}",
            r.env_state_only_steps_per_s
        );
    }
    Ok(())
}
