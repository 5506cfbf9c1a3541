//! The `sim` binary: outputs, and bad input → one clear error line, exit code 2, no panic.

use std::process::{Command, Stdio};

fn sim(args: &[&str]) -> (i32, String, String) {
    sim_with_stdout(args, Stdio::piped())
}

/// `sim ARGS` with its stdout connected to `stdout`: exit code, stdout (when piped), stderr.
fn sim_with_stdout(args: &[&str], stdout: impl Into<Stdio>) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sim"))
        .args(args)
        .stdout(stdout)
        .output()
        .expect("run sim");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// LIBERO-Mem T1's task file, the base of the damaged ones below.
const T1_BDDL: &str = include_str!("../tasks/libero_mem/t1.bddl");

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("sim-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn info_reports_mujoco_222_and_a_renderer() {
    let (code, out, err) = sim(&["info"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("mujoco_version: 222"), "{out}");
    assert!(out.contains("gl_renderer: "), "{out}");
}

#[test]
fn render_writes_a_png_of_the_requested_size() {
    let path = tmp("agent.png");
    let (code, _, err) = sim(&["render", "--out", path.to_str().unwrap(), "--size", "96"]);
    assert_eq!(code, 0, "{err}");
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (96, 96));
    // Not blank: the table and the robot give many distinct colours.
    let mut colours: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    colours.sort();
    colours.dedup();
    assert!(colours.len() > 50, "{} colours", colours.len());
    assert!(!path.with_extension("png.tmp").exists());
}

#[test]
fn unknown_camera_is_exit_2_with_the_camera_list() {
    let path = tmp("nope.png");
    let (code, _, err) = sim(&[
        "render",
        "--out",
        path.to_str().unwrap(),
        "--camera",
        "nope",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("unknown camera 'nope'") && err.contains("agentview"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!path.exists());
}

#[test]
fn bad_size_is_exit_2() {
    for size in ["0", "5000"] {
        let (code, _, err) = sim(&[
            "render",
            "--out",
            tmp("s.png").to_str().unwrap(),
            "--size",
            size,
        ]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("--size"), "{err}");
    }
    let (code, _, err) = sim(&[
        "render",
        "--out",
        tmp("s.png").to_str().unwrap(),
        "--size",
        "abc",
    ]);
    assert_eq!(code, 2, "{err}");
}

#[test]
fn unreadable_or_malformed_mjcf_is_exit_2_with_the_file_name() {
    let (code, _, err) = sim(&[
        "render",
        "--out",
        tmp("m.png").to_str().unwrap(),
        "--mjcf",
        "/nonexistent/scene.xml",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("/nonexistent/scene.xml"), "{err}");
    let bad = tmp("bad.xml");
    std::fs::write(&bad, "<mujoco><worldbody><body></mujoco>").unwrap();
    let (code, _, err) = sim(&[
        "render",
        "--out",
        tmp("m.png").to_str().unwrap(),
        "--mjcf",
        bad.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bad.xml") && err.contains("MuJoCo"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn render_of_a_user_mjcf_file() {
    let xml = tmp("user.xml");
    std::fs::write(
        &xml,
        r#"<mujoco><worldbody><light pos="0 0 3"/><geom type="sphere" size="0.3" rgba="0 1 0 1"/>
<camera name="cam" pos="0 0 2"/></worldbody></mujoco>"#,
    )
    .unwrap();
    let out = tmp("user.png");
    let (code, _, err) = sim(&[
        "render",
        "--out",
        out.to_str().unwrap(),
        "--mjcf",
        xml.to_str().unwrap(),
        "--camera",
        "cam",
        "--size",
        "32",
    ]);
    assert_eq!(code, 0, "{err}");
    let img = image::open(&out).unwrap().to_rgb8();
    let centre = img.get_pixel(16, 16).0;
    assert!(centre[1] > 100 && centre[0] < 80, "{centre:?}");
}

#[test]
fn missing_output_folder_is_exit_2() {
    let (code, _, err) = sim(&["render", "--out", "/nonexistent-dir/x.png"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("/nonexistent-dir"), "{err}");
}

#[test]
fn bench_json_has_every_figure() {
    let (code, out, err) = sim(&["bench", "--json", "--steps", "10", "--rounds", "1"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    for key in [
        "physics_steps_per_s",
        "render_fps_128",
        "env_steps_per_s",
        "raw_loop_steps_per_s",
        "env_over_raw",
    ] {
        let x = v[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing in {out}"));
        assert!(x > 0.0 && x.is_finite(), "{key} = {x}");
    }
}

#[test]
fn tasks_lists_twenty() {
    let (code, out, err) = sim(&["tasks"]);
    assert_eq!(code, 0, "{err}");
    let rows: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(rows.len(), 20, "{out}");
    assert!(
        rows[6].starts_with("libero_mem/t7") && rows[6].contains("swap the 2 bowls"),
        "{}",
        rows[6]
    );
}

#[test]
fn render_a_task() {
    let path = tmp("t7.png");
    let (code, _, err) = sim(&[
        "render",
        "--task",
        "t7",
        "--seed",
        "3",
        "--out",
        path.to_str().unwrap(),
        "--size",
        "64",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(image::open(&path).unwrap().to_rgb8().dimensions(), (64, 64));
}

#[test]
fn unknown_task_lists_the_known_ids() {
    let (code, _, err) = sim(&[
        "render",
        "--task",
        "t42",
        "--out",
        tmp("x.png").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("t42")
            && err.contains("libero_mem/t10")
            && err.contains("libero_goal/put_the_bowl_on_the_plate"),
        "{err}"
    );
}

/// A task of the pack-only suites without the pack: exit 2 and the one command that installs it.
#[test]
fn pack_task_without_the_pack_names_the_install_command() {
    let empty = tmp("no-pack-cache");
    std::fs::create_dir_all(&empty).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sim"))
        .args([
            "render",
            "--task",
            "libero_10/LIVING_ROOM_SCENE2_put_both_the_alphabet_soup_and_the_tomato_sauce_in_the_basket",
            "--out",
            tmp("y.png").to_str().unwrap(),
        ])
        .env("LIBERO_MEM_CACHE", &empty)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("not installed") && err.contains("sim -- assets install libero"),
        "{err}"
    );
}

#[test]
fn bddl_syntax_error_names_file_line_and_column() {
    let bad = tmp("broken.bddl");
    std::fs::write(&bad, "(define (problem LIBERO_Tabletop_Manipulation)\n  (:domain robosuite)\n  (:objects plate_1 - plate\n").unwrap();
    let (code, _, err) = sim(&[
        "render",
        "--task",
        bad.to_str().unwrap(),
        "--out",
        tmp("y.png").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("broken.bddl:"), "{err}");
    assert!(err.contains(":1:1") || err.contains(":3:"), "{err}");
}

#[test]
fn a_closed_stdout_ends_quietly() {
    for args in [&["tasks"][..], &["info"]] {
        // `sim … | true`: a pipe whose reader is already gone.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let (code, _, err) = sim_with_stdout(args, writer);
        assert_eq!((code, err.as_str()), (0, ""), "sim {args:?}");
    }
}

#[test]
fn a_goal_nested_10000_deep_is_exit_2_not_a_stack_overflow() {
    let path = tmp("deep.bddl");
    let text = T1_BDDL;
    let start = text.find("(:goal").unwrap();
    let deep = format!(
        "{}(:goal {}(On akita_black_bowl_1 plate_1){}))\n",
        &text[..start],
        "(And ".repeat(10_000),
        ")".repeat(10_000)
    );
    std::fs::write(&path, deep).unwrap();
    let (code, _, err) = sim(&[
        "render",
        "--task",
        path.to_str().unwrap(),
        "--out",
        tmp("deep.png").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("deep.bddl:"),
        "{err}"
    );
    assert!(err.contains("nested deeper than 64 levels"), "{err}");
    assert!(!tmp("deep.png").exists());
}

#[test]
fn task_file_faults_are_exit_2_naming_the_file_in_render_and_generate() {
    let t1 = T1_BDDL;
    let unknown = tmp("saucer.bddl");
    std::fs::write(
        &unknown,
        t1.replace(
            "akita_black_bowl_1 - akita_black_bowl",
            "akita_black_bowl_1 - flying_saucer",
        ),
    )
    .unwrap();
    let inverted = tmp("inverted.bddl");
    std::fs::write(
        &inverted,
        t1.replace("(-0.25 -0.15 0.12 -0.01)", "(0.12 -0.15 -0.25 -0.01)"),
    )
    .unwrap();
    for (file, want) in [
        (&unknown, "unknown object category 'flying_saucer'"),
        (&inverted, "inverted rectangle"),
    ] {
        let f = file.to_str().unwrap();
        let png = tmp("x.png");
        let out = tmp("gen");
        for args in [
            vec!["render", "--task", f, "--out", png.to_str().unwrap()],
            vec![
                "generate",
                "--task",
                f,
                "--out",
                out.to_str().unwrap(),
                "--episodes",
                "2",
                "--val",
                "1",
                "--size",
                "16",
            ],
        ] {
            let (code, _, err) = sim(&args);
            assert_eq!(code, 2, "{args:?}: {err}");
            assert!(err.contains(f) && err.contains(want), "{args:?}: {err}");
            assert_eq!(err.lines().count(), 1, "{err}");
        }
    }
}

#[test]
fn bad_exec_noise_is_exit_2_and_writes_nothing() {
    for noise in ["-0.1", "nan", "x"] {
        let out = tmp(&format!("noise-{noise}"));
        let arg = format!("--exec-noise={noise}");
        let (code, _, err) = sim(&[
            "generate",
            "--task",
            "t1",
            "--episodes",
            "1",
            "--out",
            out.to_str().unwrap(),
            &arg,
        ]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("--exec-noise") && err.contains("≥ 0"), "{err}");
        assert!(!out.exists(), "{noise}: nothing written");
    }
}

/// `--workers N` records with N processes of `sim` (`--shard i/N` each): the same bytes as one
/// process, every file; a directory of other parameters is refused by the parent before any
/// process starts (exit 2, nothing recorded), and `--force` there empties it once.
#[test]
fn worker_processes_record_the_bytes_one_process_records() {
    let record = |out: &std::path::Path, workers: &str, extra: &[&str]| {
        let mut args = vec![
            "generate",
            "--task",
            "t1",
            "--episodes",
            "3",
            "--val",
            "1",
            "--seed",
            "5",
            "--size",
            "32",
            "--workers",
            workers,
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        sim(&args)
    };
    let (one, two) = (tmp("workers-1"), tmp("workers-2"));
    let (code, _, err) = record(&one, "1", &[]);
    assert_eq!(code, 0, "{err}");
    let (code, stdout, err) = record(&two, "2", &[]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("3 episodes") && stdout.contains("by 2 processes"),
        "{stdout}"
    );
    let names = |d: &std::path::Path| {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&one), names(&two));
    assert_eq!(names(&two).len(), 5, "{:?}", names(&two)); // 3 episodes, index, generation.json
    for name in names(&one) {
        assert_eq!(
            std::fs::read(one.join(&name)).unwrap(),
            std::fs::read(two.join(&name)).unwrap(),
            "{name}"
        );
    }
    // Another seed into the same folder: refused by the parent, nothing touched.
    let before = std::fs::read(two.join("episode_00000.mcap")).unwrap();
    let (code, _, err) = record(&two, "2", &["--seed", "6"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("other parameters") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(two.join("episode_00000.mcap")).unwrap(),
        before
    );
    // With --force: emptied once, recorded again by the processes.
    let (code, _, err) = record(&two, "2", &["--seed", "6", "--force"]);
    assert_eq!(code, 0, "{err}");
    assert_ne!(
        std::fs::read(two.join("episode_00000.mcap")).unwrap(),
        before
    );
    assert_eq!(names(&two).len(), 5);
}
