//! The `data` binary: subcommands, messages and exit codes.

use std::process::Command;

fn data() -> Command {
    Command::new(env!("CARGO_BIN_EXE_data"))
}

#[test]
fn synth_stats_inspect_and_bad_input_exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let out = data()
        .args(["synth", "--out"])
        .arg(dir.path())
        .args(["--episodes", "2", "--steps", "8", "--size", "16"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = data()
        .arg("stats")
        .arg(dir.path())
        .args(["--val-fraction", "0"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        text.contains("2 episodes (2 train, 0 val), 16 train steps"),
        "{text}"
    );
    // verify: every episode checked against the index; a damaged one is exit 2 naming it
    let out = data().arg("verify").arg(dir.path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("2 episodes"),
        "{text}"
    );
    let ep = dir.path().join("synth_000.mcap");
    let good = std::fs::read(&ep).unwrap();
    let mut bad = good.clone();
    bad[100] ^= 1;
    std::fs::write(&ep, &bad).unwrap();
    let out = data().arg("verify").arg(dir.path()).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("synth_000.mcap") && err.contains("CRC-32"),
        "{err}"
    );
    std::fs::write(&ep, &good).unwrap();
    let out = data()
        .arg("inspect")
        .arg(&ep)
        .arg("--verify")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    for want in [
        "steps       8 (0.40 s at 20 Hz)",
        "/agentview/image",
        "foxglove.CompressedImage",
        "/agentview/depth",
        "libero_mem/t1",
        "verified",
    ] {
        assert!(text.contains(want), "missing {want:?} in\n{text}");
    }
    // truncated copy: one error line naming the file and an offset, exit code 2
    let bytes = std::fs::read(&ep).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = data().arg("inspect").arg(&cut).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("cut.mcap") && err.contains("byte offset"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    // stdout closed (`data inspect … | true`): quiet, exit 0
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = data()
        .arg("inspect")
        .arg(&ep)
        .stdout(writer)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!((out.status.code(), err.as_ref()), (Some(0), ""));
    // missing file: exit 2 too
    let out = data()
        .arg("inspect")
        .arg(dir.path().join("nope.mcap"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    // empty source directory for convert-rlds
    let empty = tempfile::tempdir().unwrap();
    let out = data()
        .args(["convert-rlds", "--src"])
        .arg(empty.path())
        .arg("--out")
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no TFRecord shards"));
}

/// `export-lerobot` / `import-lerobot`: the export's layout, then bad input — an existing output,
/// a LeRobot directory missing a parquet file, no info.json — each one error naming the file,
/// exit 2, nothing written.
#[test]
fn lerobot_export_and_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    for args in [
        vec![
            "synth",
            "--out",
            src.to_str().unwrap(),
            "--episodes",
            "3",
            "--steps",
            "6",
            "--size",
            "16",
        ],
        vec!["stats", src.to_str().unwrap(), "--val-fraction", "0"],
    ] {
        let out = data().args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let lr = tmp.path().join("lr");
    let out = data()
        .arg("export-lerobot")
        .arg(&src)
        .arg("--out")
        .arg(&lr)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("3 episodes, 18 frames, 1 tasks"), "{text}");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(lr.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["total_episodes"], 3);
    assert_eq!(info["total_frames"], 18);
    assert_eq!(info["libero_mem"]["image_flip"], "hflip");
    // No temporary directory is left beside the output.
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".lerobot-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");

    // An existing output is refused.
    let out = data()
        .arg("export-lerobot")
        .arg(&src)
        .arg("--out")
        .arg(&lr)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("already exists"), "{err}");

    // A missing data file: one error naming it, exit 2, no output directory.
    let missing = lr.join("data/chunk-000/file-000.parquet");
    std::fs::rename(&missing, tmp.path().join("moved.parquet")).unwrap();
    let back = tmp.path().join("back");
    let out = data()
        .arg("import-lerobot")
        .arg(&lr)
        .arg("--out")
        .arg(&back)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("data/chunk-000/file-000.parquet") && err.contains("missing"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!back.exists());

    // No info.json.
    let out = data()
        .arg("import-lerobot")
        .arg(tmp.path().join("nowhere"))
        .arg("--out")
        .arg(&back)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("nowhere/meta/info.json"), "{err}");
    assert!(!back.exists());
}
