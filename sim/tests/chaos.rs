//! Chaos: `sim generate` killed with SIGKILL at random moments, `CHAOS_KILLS` times (default 3;
//! `scripts/chaos.sh` runs more), then rerun to the end, must leave the files of an uninterrupted
//! run, byte for byte (episodes, index, generation record), and no temporary file.

#[path = "../../tests/support/kill9.rs"]
mod kill9;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

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

    kill9::kill_at_random_moments(
        &b,
        full_ms,
        || generate(&b).spawn().unwrap(),
        |k, wait| eprintln!("kill {k}/{} after {wait:?}", kill9::kills()),
    );
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
        assert!(x == y, "{name} differs after {} kills", kill9::kills());
    }
    assert!(names(&fa).contains(&"generation.json".to_string()));
}
