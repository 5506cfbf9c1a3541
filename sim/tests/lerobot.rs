//! LeRobot v3 datasets of recorded expert episodes (`data::lerobot`): the export opens in LeRobot's
//! own `LeRobotDataset` from PyPI (frame and episode counts, the first and last action bit for bit,
//! a decoded frame against ours, timestamps; run when `LEROBOT_PYTHON` names a Python with
//! `lerobot`, as scripts/test.sh sets up, and required where `LEROBOT_REQUIRED=1`), and importing
//! the export gives the episodes back: numbers and annotations equal, frames within the video
//! codec's loss.

use std::path::{Path, PathBuf};
use std::process::Command;

use data::lerobot::{ExportOptions, ImportOptions};
use data::{DatasetIndex, Flip, Split};

/// Three T1 expert episodes (one of them validation) at 64².
fn record(dir: &Path) {
    let task = sim::task::resolve("t1").unwrap();
    let cfg = sim::generate::GenerateConfig {
        episodes: 3,
        val: 1,
        seed: 11,
        workers: 1,
        image_size: 64,
        ..Default::default()
    };
    sim::generate::generate(&task, dir, &cfg, &|_| {}).unwrap();
}

/// The episodes in export order (train, then validation) with their steps.
fn episodes(dir: &Path) -> Vec<(data::EpisodeMeta, Vec<data::StepRecord>)> {
    let index = DatasetIndex::load(dir).unwrap();
    let mut order: Vec<usize> = index.split(Split::Train).iter().map(|(i, _)| *i).collect();
    order.extend(index.split(Split::Val).iter().map(|(i, _)| *i));
    order
        .into_iter()
        .map(|i| {
            let r = index.episodes[i].open(dir).unwrap();
            (r.meta().clone(), r.read_all().unwrap())
        })
        .collect()
}

fn required(var: &str) -> bool {
    std::env::var(var).is_ok_and(|v| v == "1")
}

/// An ffmpeg program: `LEROBOT_FFMPEG`, the one `imageio-ffmpeg` ships in LeRobot's venv, or
/// `ffmpeg` on the PATH.
fn ffmpeg() -> Option<PathBuf> {
    if let Ok(p) = std::env::var("LEROBOT_FFMPEG") {
        return Some(p.into());
    }
    if let Ok(py) = std::env::var("LEROBOT_PYTHON") {
        let out = Command::new(py)
            .args([
                "-c",
                "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())",
            ])
            .output()
            .ok()?;
        if out.status.success() {
            return Some(String::from_utf8_lossy(&out.stdout).trim().into());
        }
    }
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|_| PathBuf::from("ffmpeg"))
}

fn mean_abs(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.len() as f64
}

#[test]
fn export_opens_in_lerobot_and_imports_back() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    record(&src);
    let eps = episodes(&src);
    let frames: usize = eps.iter().map(|(_, s)| s.len()).sum();
    let out = tmp.path().join("lerobot");
    let rep = data::lerobot::export(&src, &out, &ExportOptions::default()).unwrap();
    assert_eq!(
        (rep.episodes, rep.frames as usize, rep.tasks),
        (3, frames, 1)
    );
    assert_eq!((rep.data_files, rep.video_files), (1, 1));

    // The layout and info.json as LeRobot's v3.0 writes them.
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("meta/info.json")).unwrap())
            .unwrap();
    assert_eq!(info["codebase_version"], "v3.0");
    assert_eq!(info["total_frames"], frames);
    assert_eq!(info["fps"], 20);
    assert_eq!(info["splits"]["train"], "0:2");
    assert_eq!(info["splits"]["val"], "2:3");
    assert_eq!(
        info["features"]["observation.state"]["shape"],
        serde_json::json!([8])
    );
    assert_eq!(info["features"]["action"]["shape"], serde_json::json!([7]));
    // The scene's cabinet: its three drawer handles as part rows of their own.
    let parts = eps[0].1[0]
        .objects
        .iter()
        .map(|o| o.parts.len())
        .sum::<usize>();
    assert_eq!(parts, 3, "the scene's cabinet has three drawer handles");
    assert_eq!(info["libero_mem"]["max_parts"], 3);
    assert_eq!(
        info["features"]["observation.parts.pose"]["shape"],
        serde_json::json!([3, 7])
    );
    assert_eq!(
        info["features"]["observation.parts.object"]["shape"],
        serde_json::json!([3])
    );
    assert_eq!(
        info["features"]["observation.images.wrist_image"]["shape"],
        serde_json::json!([64, 64, 3])
    );
    for f in [
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "data/chunk-000/file-000.parquet",
        "videos/observation.images.image/chunk-000/file-000.mp4",
        "videos/observation.images.wrist_image/chunk-000/file-000.mp4",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // A second export onto it is refused, the first left as it was.
    let again = data::lerobot::export(&src, &out, &ExportOptions::default()).unwrap_err();
    assert!(again.to_string().contains("already exists"), "{again}");

    // LeRobot's own loader.
    match std::env::var("LEROBOT_PYTHON") {
        Ok(python) => {
            let k = frames / 2;
            let (mut e, mut off) = (0, k);
            while off >= eps[e].1.len() {
                off -= eps[e].1.len();
                e += 1;
            }
            let img = &eps[e].1[off].agentview;
            let mut want = img.data.clone();
            data::imageio::apply_flip(&mut want, 64, 64, 3, Flip::Horizontal);
            let rgb = tmp.path().join("frame.rgb");
            std::fs::write(&rgb, &want).unwrap();
            let last = eps.last().unwrap().1.last().unwrap().action;
            let expect = serde_json::json!({
                "frames": frames,
                "episodes": 3,
                "episode_lengths": eps.iter().map(|(_, s)| s.len()).collect::<Vec<_>>(),
                "tasks": [eps[0].0.instruction],
                "first_action": eps[0].1[0].action,
                "last_action": last,
                "frame": {"index": k, "rgb": rgb, "max_mean_abs": 5.0},
                "backends": ["pyav"],
            });
            let expect_path = tmp.path().join("expect.json");
            std::fs::write(&expect_path, expect.to_string()).unwrap();
            let script =
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/tests/lerobot_check.py");
            let run = Command::new(&python)
                .arg(&script)
                .arg(&out)
                .arg(&expect_path)
                .env("HF_HUB_OFFLINE", "1")
                .env("HF_HOME", tmp.path().join("hf"))
                .output()
                .unwrap();
            let stdout = String::from_utf8_lossy(&run.stdout);
            eprintln!("LeRobotDataset: {}", stdout.trim());
            assert!(
                run.status.success(),
                "lerobot check failed: {stdout}\n{}",
                String::from_utf8_lossy(&run.stderr)
            );
        }
        Err(_) => {
            assert!(
                !required("LEROBOT_REQUIRED"),
                "CI must set LEROBOT_PYTHON (scripts/test.sh does)"
            );
            eprintln!("LEROBOT_PYTHON not set: LeRobotDataset check not run here");
        }
    }

    // Import gives the episodes back.
    let Some(ffmpeg) = ffmpeg() else {
        assert!(
            !required("LEROBOT_REQUIRED"),
            "no ffmpeg for the import check (LeRobot's venv ships one)"
        );
        eprintln!("no ffmpeg: import check not run here");
        return;
    };
    let back = tmp.path().join("back");
    let opts = ImportOptions {
        ffmpeg,
        val_fraction: 0.0,
        ..Default::default()
    };
    let rep = data::lerobot::import(&out, &back, &opts).unwrap();
    assert_eq!((rep.episodes, rep.frames as usize), (3, frames));
    let index = DatasetIndex::load(&back).unwrap();
    let mut worst = 0.0f64;
    for (k, (meta, steps)) in eps.iter().enumerate() {
        let entry = &index.episodes[k];
        let r = entry.open(&back).unwrap();
        assert_eq!(r.meta().instruction, meta.instruction);
        assert_eq!(r.meta().task_id, meta.task_id);
        assert_eq!(r.meta().seed, meta.seed);
        let got = r.read_all().unwrap();
        assert_eq!(got.len(), steps.len());
        for (a, b) in got.iter().zip(steps) {
            assert_eq!(a.state.map(f32::to_bits), b.state.map(f32::to_bits));
            assert_eq!(a.action.map(f32::to_bits), b.action.map(f32::to_bits));
            assert_eq!(
                a.joint_state.map(f32::to_bits),
                b.joint_state.map(f32::to_bits)
            );
            assert_eq!(a.objects, b.objects, "step {}", a.step);
            assert_eq!(a.progress, b.progress, "step {}", a.step);
            worst = worst
                .max(mean_abs(&a.agentview.data, &b.agentview.data))
                .max(mean_abs(&a.eye_in_hand.data, &b.eye_in_hand.data));
        }
    }
    eprintln!("import: worst frame mean absolute difference {worst:.2} grey levels");
    // H.264 stores 4:2:0 YUV: on 64² frames the colour conversion alone costs 3–4 grey levels.
    assert!(
        worst < 5.0,
        "frames differ by {worst:.2} grey levels on average"
    );
}
