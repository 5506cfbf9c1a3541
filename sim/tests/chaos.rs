//! Chaos: `sim generate` killed with SIGKILL at random moments, `CHAOS_KILLS` times (default 3;
//! `scripts/chaos.sh` runs more), then rerun to the end, must leave the files of an uninterrupted
//! run, byte for byte (episodes, index, generation record), and no temporary file.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn kills() -> usize {
    std::env::var("CHAOS_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
}

fn generate(out: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sim"));
    c.args([
        "generate",
        "--task",
        "t1",
        "--episodes",
        "6",
        "--val",
        "1",
        "--size",
        "16",
        "--seed",
        "3",
        "--out",
    ])
    .arg(out)
    .stdout(Stdio::null())
    .stderr(Stdio::piped());
    c
}

/// Every file of a directory by name, with its bytes.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn killed_at_random_moments_then_rerun_equals_the_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let t0 = Instant::now();
    let out = generate(&a).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let full_ms = t0.elapsed().as_millis() as u64;

    let mut rng = 0x5eed_u64
        ^ std::env::var("CHAOS_SEED")
            .ok()
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0);
    let mut next = |n: u64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng % n.max(1)
    };
    let mut killed = 0;
    while killed < kills() {
        let mut child = generate(&b).spawn().unwrap();
        let wait = Duration::from_millis(next(full_ms));
        let t = Instant::now();
        let mut finished = false;
        while t.elapsed() < wait {
            if child.try_wait().unwrap().is_some() {
                finished = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if finished {
            // Done before the kill: start over so that every kill lands mid-run.
            std::fs::remove_dir_all(&b).unwrap();
            continue;
        }
        child.kill().unwrap();
        child.wait().unwrap();
        killed += 1;
        eprintln!("kill {killed}/{} after {wait:?}", kills());
    }
    let out = generate(&b).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (fa, fb) = (files(&a), files(&b));
    let names = |f: &[(String, Vec<u8>)]| f.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&fa), names(&fb), "no temporary file stays");
    for ((name, x), (_, y)) in fa.iter().zip(&fb) {
        assert!(x == y, "{name} differs after {} kills", kills());
    }
    assert!(names(&fa).contains(&"generation.json".to_string()));
}
