//! Chaos: the `train` binary killed with SIGKILL at random moments, `CHAOS_KILLS` times (default
//! 3; `scripts/chaos.sh` runs more), then resumed to the end, must leave the same final weights as
//! an uninterrupted run (by tensor content, bit for bit), every step logged once, and nothing left
//! behind.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn kills() -> usize {
    std::env::var("CHAOS_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
}

/// A small xorshift generator: the kill schedule is reproducible from `CHAOS_SEED`.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n
    }
}

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
    let out = train(&config, &a).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let t_full = Instant::now();
    let out = train(&config, &dir.path().join("timing")).output().unwrap();
    assert!(out.status.success());
    let full_ms = t_full.elapsed().as_millis() as u64;

    let seed = std::env::var("CHAOS_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x5eed_u64);
    let mut rng = Rng(seed | 1);
    let mut killed = 0;
    while killed < kills() {
        let mut child = train(&config, &b).spawn().unwrap();
        // Anywhere in the run: start-up, a step, a checkpoint write, pruning.
        let wait = Duration::from_millis(rng.below(full_ms.max(50)));
        let t0 = Instant::now();
        let mut finished = false;
        while t0.elapsed() < wait {
            if child.try_wait().unwrap().is_some() {
                finished = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if finished {
            // It ran to the end before the kill: start over so that every kill lands mid-run.
            std::fs::remove_dir_all(&b).unwrap();
            continue;
        }
        child.kill().unwrap();
        child.wait().unwrap();
        killed += 1;
        let at = model::run::newest_valid(&b)
            .ok()
            .flatten()
            .map_or(0, |c| c.info.step);
        eprintln!(
            "kill {killed}/{} after {wait:?}, newest checkpoint step {at}",
            kills()
        );
    }
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
        kills()
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
