//! The `eval` binary with sanity policies.

use std::process::Command;

fn eval(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn zero_policy_table_for_t1() {
    let dir = std::env::temp_dir().join(format!("eval-cli-{}", std::process::id()));
    let (code, out, err) = eval(&[
        "--tasks",
        "t1",
        "--episodes",
        "2",
        "--policy",
        "zero",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("| libero_mem/t1 | 2 | 0.0 ± 0.0 | 0.0"),
        "{out}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    let row = &json["tasks"][0];
    assert_eq!(row["task"], "libero_mem/t1");
    let c = row["completion"].as_f64().unwrap();
    assert!((0.0..=100.0).contains(&c));
    assert_eq!(json["episodes"].as_array().unwrap().len(), 2);
    // The zero policy never moves: it runs the whole 200-step budget.
    assert_eq!(json["episodes"][0]["steps"], 200);
    assert!(
        std::fs::read_to_string(dir.join("results.csv"))
            .unwrap()
            .starts_with("task,episodes,completion")
    );
}

#[test]
fn unknown_task_is_exit_2() {
    let (code, _, err) = eval(&["--tasks", "t99", "--episodes", "1"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("t99") && err.contains("libero_mem/t1"),
        "{err}"
    );
}
