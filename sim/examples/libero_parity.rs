//! Side-by-side check of our LIBERO-pack world against Python LIBERO's own, on
//! `libero_goal/put_the_bowl_on_the_plate` at init state 0.
//!
//! The reference (`docs/parity/`) was recorded once with robosuite 1.4.0 + mujoco 2.3.7 + hf-libero
//! 0.1.4 by `docs/parity/libero_reference.py`; see `docs/libero_parity.md`. This program puts our
//! fixtures where that run drew them (init states do not hold fixture poses), renders the agentview at
//! 128² with the LIBERO look (`RenderQuality::high`: MuJoCo's defaults, as robosuite renders), writes
//! `ours | theirs | 4×|difference|` and prints the mean absolute pixel difference, then replays the
//! reference's end-effector runs (10 steps of one action from init state 0) and compares travel.
//!
//! `cargo run --release -p sim --example libero_parity -- docs/parity docs/libero_parity.png`

use std::path::PathBuf;

use anyhow::{Context, Result};
use sim::pack::{AssetPack, LiberoPack};

const TASK: &str = "libero_goal/put_the_bowl_on_the_plate";
const FIXTURES: [&str; 3] = ["wooden_cabinet_1", "flat_stove_1", "wine_rack_1"];

fn env_at_init0(
    pack: &LiberoPack,
    reference: &serde_json::Value,
    render: bool,
) -> Result<sim::Env> {
    let task = sim::task::resolve(TASK)?;
    let cfg = sim::EnvConfig {
        image_size: 128,
        render,
        quality: sim::render::RenderQuality::high(),
        ..Default::default()
    };
    let mut env = sim::Env::from_task_with_assets(&task, cfg, AssetPack::Libero)?;
    let states = pack.init_states(TASK)?;
    let st = states
        .state(0, env.model().nq(), env.model().nv())?
        .context("no init state 0")?;
    env.reset_to_init(0, st.qpos, st.qvel)?;
    for f in FIXTURES {
        let p = &reference["fixture_poses"][format!("{f}_main")];
        let v = |k: &str, n: usize| -> Result<Vec<f64>> {
            let a = p[k]
                .as_array()
                .with_context(|| format!("fixture_poses.{f}_main.{k}"))?;
            let out: Vec<f64> = a.iter().filter_map(|x| x.as_f64()).collect();
            anyhow::ensure!(
                out.len() == n,
                "fixture_poses.{f}_main.{k}: {n} numbers expected"
            );
            Ok(out)
        };
        let (pos, quat) = (v("model_body_pos", 3)?, v("model_body_quat_wxyz", 4)?);
        env.set_fixture_pose(
            f,
            [pos[0], pos[1], pos[2]],
            [quat[0], quat[1], quat[2], quat[3]],
        )?;
    }
    Ok(env)
}

/// Mean and largest absolute difference of two RGB buffers.
fn difference(a: &[u8], b: &[u8]) -> (f64, u8) {
    let d = a.iter().zip(b).map(|(&x, &y)| x.abs_diff(y));
    let (sum, max) = d.fold((0u64, 0u8), |(s, m), v| (s + v as u64, m.max(v)));
    (sum as f64 / a.len().max(1) as f64, max)
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().unwrap_or_else(|| "docs/parity".into()));
    let out = PathBuf::from(
        args.next()
            .unwrap_or_else(|| "docs/libero_parity.png".into()),
    );
    let read = |name: &str| -> Result<serde_json::Value> {
        let p = dir.join(name);
        let text =
            std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
        serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
    };
    let reference = read("init0_qpos.json")?;
    let travel = read("ee_travel.json")?;
    let pack = LiberoPack::locate_default()?;

    // Image parity.
    let mut env = env_at_init0(&pack, &reference, true)?;
    let obs = env.observe()?;
    let theirs = image::open(dir.join("theirs_agentview_128_upright.png"))?.to_rgb8();
    anyhow::ensure!(
        theirs.dimensions() == (128, 128),
        "the reference image is not 128²"
    );
    let ours = &obs.agentview_rgb;
    let (mad, max) = difference(ours, theirs.as_raw());
    let hand = image::open(dir.join("theirs_eye_in_hand_128_upright.png"))?.to_rgb8();
    let (hand_mad, hand_max) = difference(&obs.eye_in_hand_rgb, hand.as_raw());
    let mut strip = image::RgbImage::new(3 * 128, 128);
    for y in 0..128u32 {
        for x in 0..128u32 {
            let i = 3 * (y as usize * 128 + x as usize);
            let a = [ours[i], ours[i + 1], ours[i + 2]];
            let b = theirs.get_pixel(x, y).0;
            let d =
                [0, 1, 2].map(|c| ((a[c] as i32 - b[c] as i32).unsigned_abs() * 4).min(255) as u8);
            strip.put_pixel(x, y, image::Rgb(a));
            strip.put_pixel(128 + x, y, image::Rgb(b));
            strip.put_pixel(256 + x, y, image::Rgb(d));
        }
    }
    let big = image::imageops::resize(&strip, 3 * 256, 256, image::imageops::FilterType::Nearest);
    big.save(&out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "agentview 128², init state 0: mean |ours − theirs| = {mad:.3} grey levels, largest {max} (wrote {})",
        out.display()
    );
    println!(
        "eye_in_hand 128², init state 0: mean |ours − theirs| = {hand_mad:.3}, largest {hand_max}"
    );

    // End-effector travel.
    println!("\n| action | ours travel (m) | LIBERO travel (m) | ours / LIBERO |");
    println!("|---|---|---|---|");
    let runs = travel["runs"].as_object().context("ee_travel.json: runs")?;
    for (name, run) in runs {
        let action: Vec<f32> = run["action"]
            .as_array()
            .context("action")?
            .iter()
            .filter_map(|v| v.as_f64().map(|x| x as f32))
            .collect();
        let pos = run["eef_pos"].as_array().context("eef_pos")?;
        let p = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
                .unwrap_or_default()
        };
        let (t0, t1) = (p(&pos[0]), p(&pos[pos.len() - 1]));
        let theirs: f64 = (0..3).map(|k| (t1[k] - t0[k]).powi(2)).sum::<f64>().sqrt();
        let mut env = env_at_init0(&pack, &reference, false)?;
        let start = env.observe()?.eef_pos;
        let mut end = start;
        for _ in 0..pos.len() - 1 {
            end = env.step(&action)?.eef_pos;
        }
        let ours: f64 = (0..3)
            .map(|k| (end[k] - start[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        println!(
            "| {name} {action:?} | {ours:.4} ({:+.4}, {:+.4}, {:+.4}) | {theirs:.4} ({:+.4}, {:+.4}, {:+.4}) | {:.3} |",
            end[0] - start[0],
            end[1] - start[1],
            end[2] - start[2],
            t1[0] - t0[0],
            t1[1] - t0[1],
            t1[2] - t0[2],
            ours / theirs
        );
    }
    Ok(())
}
