//! Throughput figures for `sim bench`: physics, rendering, the Env, and a bare FFI loop doing the same work
//! as the Env (so the Env's overhead shows as a ratio measured in the same run).

use std::time::Instant;

use crate::engine::mujoco::{Data, Model, ffi, guard};
use crate::engine::render::{Channels, RenderQuality, Renderer};
use crate::world::env::{
    AGENTVIEW, EYE_IN_HAND, Env, EnvConfig, EnvError, SUBSTEPS, minimal_scene_xml,
};
use crate::world::robot::{INIT_FINGERS, INIT_QPOS, PandaIds};

/// One run of the benchmark.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchReport {
    /// Bare `mj_step` calls per second on the minimal scene (no rendering, no controller).
    pub physics_steps_per_s: f64,
    /// Frames per second, one camera, 128×128 RGB (render + read back + flip).
    pub render_fps_128: f64,
    /// `Env::step` calls per second with two 128×128 RGB cameras and state.
    pub env_steps_per_s: f64,
    /// Control steps per second of a bare FFI loop doing the same physics and rendering as the Env.
    pub raw_loop_steps_per_s: f64,
    /// `env_steps_per_s / raw_loop_steps_per_s`.
    pub env_over_raw: f64,
    /// `Env::step` calls per second without rendering (physics + OSC only).
    pub env_state_only_steps_per_s: f64,
    /// The OpenGL renderer string.
    pub gl_renderer: String,
    /// Control steps measured per figure.
    pub steps: usize,
    /// Alternated rounds for the Env and raw-loop figures (best of).
    pub rounds: usize,
}

fn action(t: usize) -> [f32; 7] {
    let s = (t as f32 * 0.1).sin();
    [
        0.3 * s,
        0.3 * (t as f32 * 0.07).cos(),
        0.1 * s,
        0.0,
        0.0,
        0.0,
        if t % 40 < 20 { -1.0 } else { 1.0 },
    ]
}

/// Runs every figure with `steps` control steps each (physics figures use `steps * 25` substeps); the
/// Env and raw-loop figures are the best of `rounds` alternated runs.
pub fn run(steps: usize, rounds: usize) -> Result<BenchReport, EnvError> {
    let steps = steps.max(10);
    let model = std::sync::Arc::new(Model::from_xml_str(&minimal_scene_xml())?);
    let ids = PandaIds::find(&model)?;

    // Physics only.
    let mut data = Data::new(model.clone())?;
    reset_raw(&mut data, &ids)?;
    let n_phys = steps * SUBSTEPS;
    let t0 = Instant::now();
    for _ in 0..n_phys {
        hold_arm(&mut data, &ids);
        data.step()?;
    }
    let physics_steps_per_s = n_phys as f64 / t0.elapsed().as_secs_f64();

    // Rendering only: one camera, 128² RGB.
    let mut renderer = Renderer::new(&model, 128, 128, RenderQuality::default())?;
    let gl_renderer = renderer.gl_info().renderer.clone();
    let cam = renderer.camera_id(AGENTVIEW)?;
    renderer.render(&mut data, cam, 128, 128, Channels::RGB)?; // warm-up
    let t0 = Instant::now();
    for _ in 0..steps {
        renderer.render(&mut data, cam, 128, 128, Channels::RGB)?;
    }
    let render_fps_128 = steps as f64 / t0.elapsed().as_secs_f64();

    drop(renderer);

    // The bare FFI loop and the Env, alternated over several rounds (best of each) so that load from
    // other processes does not land on one side only.
    let mut env = Env::new(EnvConfig::default())?;
    env.reset(0)?;
    env.step(&action(0))?; // warm-up
    let (mut raw_best, mut env_best) = (0.0f64, 0.0f64);
    for _ in 0..rounds.max(1) {
        raw_best = raw_best.max(raw_loop(&model, &ids, steps)?);
        let t0 = Instant::now();
        for t in 0..steps {
            env.step(&action(t))?;
        }
        env_best = env_best.max(steps as f64 / t0.elapsed().as_secs_f64());
    }
    let (raw_loop_steps_per_s, env_steps_per_s) = (raw_best, env_best);
    drop(env);

    let mut env = Env::new(EnvConfig {
        render: false,
        ..EnvConfig::default()
    })?;
    env.reset(0)?;
    let t0 = Instant::now();
    for t in 0..steps {
        env.step(&action(t))?;
    }
    let env_state_only_steps_per_s = steps as f64 / t0.elapsed().as_secs_f64();

    Ok(BenchReport {
        physics_steps_per_s,
        render_fps_128,
        env_steps_per_s,
        raw_loop_steps_per_s,
        env_over_raw: env_steps_per_s / raw_loop_steps_per_s,
        env_state_only_steps_per_s,
        gl_renderer,
        steps,
        rounds,
    })
}

fn reset_raw(data: &mut Data, ids: &PandaIds) -> Result<(), EnvError> {
    data.reset();
    let q = data.qpos_mut();
    for i in 0..7 {
        q[ids.arm_qpos[i]] = INIT_QPOS[i];
    }
    q[ids.finger_qpos[0]] = INIT_FINGERS[0];
    q[ids.finger_qpos[1]] = INIT_FINGERS[1];
    data.forward()?;
    Ok(())
}

/// Gravity compensation only: the cheapest control that keeps the scene comparable to the Env's.
fn hold_arm(data: &mut Data, ids: &PandaIds) {
    let tau: [f64; 7] = std::array::from_fn(|i| data.qfrc_bias()[ids.arm_dof[i]]);
    let ctrl = data.ctrl_mut();
    for i in 0..7 {
        ctrl[ids.arm_act[i]] = tau[i];
    }
}

/// The Env's work done straight on the C API: no controller maths, no buffers beyond MuJoCo's own read-back.
fn raw_loop(model: &std::sync::Arc<Model>, ids: &PandaIds, steps: usize) -> Result<f64, EnvError> {
    let mut data = Data::new(model.clone())?;
    reset_raw(&mut data, ids)?;
    // A renderer only for its GL context and MuJoCo scene/context; the loop below calls the FFI directly.
    let mut renderer = Renderer::new(model, 128, 128, RenderQuality::default())?;
    let cams = [
        renderer.camera_id(AGENTVIEW)?,
        renderer.camera_id(EYE_IN_HAND)?,
    ];
    let (scene, context, option, perturb) = renderer.raw_parts();
    let mut rgb = vec![0u8; 128 * 128 * 3];
    let viewport = ffi::mjrRect {
        left: 0,
        bottom: 0,
        width: 128,
        height: 128,
    };
    let m = model.ptr();
    let t0 = Instant::now();
    for _ in 0..steps {
        for _ in 0..SUBSTEPS {
            hold_arm(&mut data, ids);
            data.step2()?;
            data.step1()?;
        }
        for &cam in &cams {
            let d = data.ptr();
            // SAFETY: pointers owned by `renderer` and `data`, valid for the loop; the GL context is current.
            guard(|| unsafe {
                let mut c = std::mem::MaybeUninit::<ffi::mjvCamera>::uninit();
                ffi::mjv_defaultCamera(c.as_mut_ptr());
                let mut c = c.assume_init();
                c.type_ = ffi::mjCAMERA_FIXED as i32;
                c.fixedcamid = cam as i32;
                ffi::mjv_updateScene(m, d, option, perturb, &mut c, ffi::mjCAT_ALL as i32, scene);
                ffi::mjr_render(viewport, scene, context);
                ffi::mjr_readPixels(rgb.as_mut_ptr(), std::ptr::null_mut(), viewport, context);
            })?;
        }
    }
    Ok(steps as f64 / t0.elapsed().as_secs_f64())
}

/// Env throughput on a task scene, per asset pack.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TaskBench {
    /// Task id.
    pub task: String,
    /// Asset pack (`builtin` or `libero`).
    pub assets: String,
    /// `Env::step` calls per second with two 128×128 RGB cameras.
    pub env_steps_per_s: f64,
    /// `Env::step` calls per second without rendering.
    pub env_state_only_steps_per_s: f64,
    /// Control steps measured per figure.
    pub steps: usize,
}

/// Env steps/s on `task` built from `assets`, with two 128² cameras and without rendering.
pub fn run_task(
    task: &crate::task::TaskSpec,
    assets: crate::pack::AssetPack,
    steps: usize,
) -> Result<TaskBench, EnvError> {
    let steps = steps.max(10);
    let rate = |render: bool| -> Result<f64, EnvError> {
        let cfg = EnvConfig {
            render,
            image_size: 128,
            ..EnvConfig::default()
        };
        let mut env = Env::from_task_with_assets(task, cfg, assets)?;
        env.reset(0)?;
        let t0 = Instant::now();
        for t in 0..steps {
            env.step(&action(t))?;
        }
        Ok(steps as f64 / t0.elapsed().as_secs_f64())
    };
    Ok(TaskBench {
        task: task.id.clone(),
        assets: match assets {
            crate::pack::AssetPack::Builtin => "builtin".into(),
            crate::pack::AssetPack::Libero => "libero".into(),
        },
        env_steps_per_s: rate(true)?,
        env_state_only_steps_per_s: rate(false)?,
        steps,
    })
}
