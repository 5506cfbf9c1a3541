//! Chaos: the `train` binary killed with SIGKILL at random moments, `CHAOS_KILLS` times (default
//! 3; `scripts/chaos.sh` runs more), then resumed to the end, must leave the same final weights as
//! an uninterrupted run (by tensor content, bit for bit), every step logged once, and nothing left
//! behind.

mod common;
#[path = "../../tests/support/kill9.rs"]
mod kill9;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

fn train(config: &Path, run: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_train"));
    c.arg(config)
        .arg("--run-dir")
        .arg(run)
        .arg("--quiet")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

#[test]
fn killed_at_random_moments_then_resumed_equals_the_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    common::write_dataset(&data, 4, 40, 32);
    let mut cfg = common::tiny_config(&data);
    cfg.train.steps = 30;
    cfg.train.checkpoint_every = 3;
    cfg.train.warmup_steps = 3;
    cfg.train.val_every = 10;
    cfg.train.keep = 2;
    let config = dir.path().join("chaos.toml");
    std::fs::write(&config, cfg.to_toml()).unwrap();

    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let t_full = Instant::now();
    let out = train(&config, &a).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let full_ms = t_full.elapsed().as_millis() as u64;

    kill9::kill_at_random_moments(
        &b,
        full_ms,
        || train(&config, &b).spawn().unwrap(),
        |k, wait| {
            let at = model::run::newest_valid(&b)
                .ok()
                .flatten()
                .map_or(0, |c| c.info.step);
            eprintln!(
                "kill {k}/{} after {wait:?}, newest checkpoint step {at}",
                kill9::kills()
            );
        },
    );
    let out = train(&config, &b).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    assert_eq!(model::run::newest_valid(&b).unwrap().unwrap().info.step, 30);
    assert!(
        common::bits(&common::final_weights(&a)) == common::bits(&common::final_weights(&b)),
        "the weights differ after {} kills",
        kill9::kills()
    );
    let steps: Vec<u64> = train::metrics::read(&b.join("metrics.jsonl"))
        .unwrap()
        .iter()
        .map(|r| r.step)
        .collect();
    assert_eq!(steps, (1..=30).collect::<Vec<_>>());
    // Nothing left behind: no temporaries, no incomplete step directories, `keep` honoured.
    let ck = b.join("checkpoints");
    let names: Vec<String> = std::fs::read_dir(&ck)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.starts_with(".tmp")), "{names:?}");
    assert_eq!(model::run::list(&b).unwrap().len(), 2, "{names:?}");
    let in_run: Vec<String> = std::fs::read_dir(&b)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(in_run.iter().all(|n| !n.starts_with(".tmp")), "{in_run:?}");
}
