//! `sim render`: one camera of a task, the built-in scene, or an MJCF file to a PNG.

use std::path::PathBuf;

use anyhow::Context;
use sim::env::{Env, EnvConfig, EnvError};
use sim::mujoco::{Data, Model};
use sim::render::{Channels, RenderQuality, Renderer, save_png};

use super::{BadInput, Quality, check_out_dir, classify};

/// What `sim render` was asked for (its command-line arguments).
pub struct Options {
    /// Task id or `.bddl` path.
    pub task: Option<String>,
    /// Output PNG path.
    pub out: PathBuf,
    /// Camera name.
    pub camera: String,
    /// Image side in pixels.
    pub size: usize,
    /// Reset seed.
    pub seed: u64,
    /// An MJCF file to render instead.
    pub mjcf: Option<PathBuf>,
    /// Rendering quality.
    pub quality: Quality,
    /// LIBERO init state to start from.
    pub init: Option<usize>,
    /// Asset pack name.
    pub assets: String,
}

/// Renders what `o` asks for and writes the PNG.
pub fn run(o: Options) -> anyhow::Result<()> {
    let Options {
        task,
        out,
        camera,
        size,
        seed,
        mjcf,
        quality,
        init,
        assets,
    } = o;
    let assets: sim::pack::AssetPack = assets.parse().map_err(BadInput)?;
    if size == 0 || size > 4096 {
        return Err(BadInput(format!("--size must be between 1 and 4096, got {size}")).into());
    }
    let quality = match quality {
        Quality::Fast => RenderQuality::default(),
        Quality::High => RenderQuality::high(),
    };
    check_out_dir(&out)?;
    let frame = match (task, mjcf) {
        (Some(id), _) => {
            let spec = sim::task::resolve(&id).map_err(|e| BadInput(e.to_string()))?;
            let cfg = EnvConfig {
                image_size: size,
                quality,
                ..EnvConfig::default()
            };
            match init {
                None => render_start(
                    Env::from_task_with_assets(&spec, cfg, assets),
                    seed,
                    &camera,
                    size,
                )?,
                Some(k) => render_init(&spec, cfg, assets, seed, k, &camera, size)?,
            }
        }
        (None, Some(path)) => {
            let model = std::sync::Arc::new(
                Model::from_xml_file(&path).map_err(|e| BadInput(e.to_string()))?,
            );
            let mut data = Data::new(model.clone())?;
            data.forward()?;
            let mut r = Renderer::new(&model, size, size, quality)?;
            // A user's file may keep its visuals in group 0, which our LIBERO scenes hide.
            r.set_geom_group_visible(0, true);
            r.render_named(&mut data, &camera, size, Channels::RGB)
                .map_err(|e| classify(e.into()))?
        }
        (None, None) => {
            let cfg = EnvConfig {
                image_size: size,
                quality,
                ..EnvConfig::default()
            };
            render_start(Env::new(cfg), seed, &camera, size)?
        }
    };
    save_png(&frame, &out).with_context(|| format!("writing {}", out.display()))?;
    data::outln!("wrote {} ({size}x{size}, camera {camera})", out.display());
    Ok(())
}

/// Resets a freshly built environment from `seed` and renders `camera` at `size`².
pub fn render_start(
    env: Result<Env, EnvError>,
    seed: u64,
    camera: &str,
    size: usize,
) -> anyhow::Result<sim::render::Frame> {
    let mut env = env.map_err(classify)?;
    env.reset(seed).map_err(classify)?;
    render_now(&mut env, camera, size)
}

/// Renders `camera` at `size`² from the env's current state.
fn render_now(env: &mut Env, camera: &str, size: usize) -> anyhow::Result<sim::render::Frame> {
    let (r, data) = env.renderer_mut().context("rendering is off")?;
    r.render_named(data, camera, size, Channels::RGB)
        .map_err(|e| classify(e.into()))
}

/// Renders `task` from LIBERO's init state `k` (fixtures placed from `seed`).
fn render_init(
    task: &sim::task::TaskSpec,
    cfg: EnvConfig,
    assets: sim::pack::AssetPack,
    seed: u64,
    k: usize,
    camera: &str,
    size: usize,
) -> anyhow::Result<sim::render::Frame> {
    let pack = sim::pack::LiberoPack::locate_default().map_err(|e| BadInput(e.to_string()))?;
    let states = pack
        .init_states(&task.id)
        .map_err(|e| BadInput(e.to_string()))?;
    let mut env = Env::from_task_with_assets(task, cfg, assets).map_err(classify)?;
    let (nq, nv) = (env.model().nq(), env.model().nv());
    let state = states
        .require(k, nq, nv)
        .map_err(|e| BadInput(e.to_string()))?;
    env.reset_to_init(seed, state.qpos, state.qvel)
        .map_err(classify)?;
    render_now(&mut env, camera, size)
}
