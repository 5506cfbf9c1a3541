//! `eval --policy ws://` against a policy server written in Python with openpi's wire format
//! (`replay_server.py`: `websockets` + `msgpack` from PyPI, the interpreter named by
//! `EVAL_WS_PYTHON`, which `scripts/test.sh` sets up): the server replays the expert's recorded
//! actions, and the remote evaluation scores exactly what the expert scored.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use eval::remote::{RemoteConfig, RemotePolicy};
use eval::{EvalConfig, EvalError, Policy};

/// Kills the server when the test ends, however it ends.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn python() -> Option<PathBuf> {
    match std::env::var_os("EVAL_WS_PYTHON") {
        Some(p) => Some(PathBuf::from(p)),
        None => {
            assert!(
                std::env::var_os("EVAL_WS_REQUIRED").is_none(),
                "EVAL_WS_REQUIRED is set but EVAL_WS_PYTHON is not"
            );
            eprintln!(
                "skipped: EVAL_WS_PYTHON (a Python with websockets and msgpack) is not set; \
                 scripts/test.sh sets it"
            );
            None
        }
    }
}

/// Starts replay_server.py on `actions`; the server and its port.
fn start(python: &Path, actions: &Path, horizon: usize) -> (Server, u16) {
    let actions = actions.to_string_lossy();
    start_with(python, &[&actions, "--horizon", &horizon.to_string()])
}

/// Starts replay_server.py with `args`; the server and the port it printed.
fn start_with(python: &Path, args: &[&str]) -> (Server, u16) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/replay_server.py");
    let mut child = Command::new(python)
        .arg(script)
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .expect("the Python server starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let port = line
        .trim()
        .strip_prefix("port ")
        .unwrap_or_else(|| panic!("server said {line:?}"))
        .parse()
        .unwrap();
    (Server(child), port)
}

#[test]
fn a_python_server_replaying_the_expert_scores_what_the_expert_scores() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // T1, T3 (three placements), T7 (swap two bowls) and a LIBERO-Goal task, one episode each.
    let tasks = eval::resolve_tasks(
        "t1,t3,t7,libero_goal/open_the_middle_drawer_of_the_cabinet",
        None,
    )
    .unwrap();
    let rec = tmp.path().join("rec");
    let base = EvalConfig {
        episodes: 1,
        seed: 41,
        image_size: 64,
        ..EvalConfig::default()
    };
    let expert =
        || -> Result<Box<dyn Policy>, EvalError> { Ok(Box::new(eval::ExpertPolicy::default())) };
    let cfg = EvalConfig {
        record: Some(rec.clone()),
        ..base.clone()
    };
    let want = eval::evaluate(&tasks, &expert, &cfg, &|_| {}).unwrap();
    assert!(
        want.episodes.iter().all(|e| e.success),
        "{:?}",
        want.episodes
    );

    // The recorded actions, by episode id ("<task>@<seed>", what the client sends).
    let mut episodes = serde_json::Map::new();
    for e in &want.episodes {
        let path = rec
            .join(eval::task_slug(&e.task))
            .join(format!("episode_{:06}.mcap", e.episode));
        let reader = data::EpisodeReader::open(&path).unwrap();
        let actions: Vec<Vec<f32>> = reader
            .read_all()
            .unwrap()
            .iter()
            .map(|s| s.action.to_vec())
            .collect();
        assert_eq!(actions.len(), e.steps);
        episodes.insert(format!("{}@{}", e.task, e.seed), actions.into());
    }
    let file = tmp.path().join("actions.json");
    std::fs::write(&file, serde_json::Value::Object(episodes).to_string()).unwrap();

    let (_server, port) = start(&python, &file, 8);
    for replan in [5, 1] {
        let remote = RemoteConfig {
            url: format!("ws://127.0.0.1:{port}"),
            replan_steps: replan,
            // The oracle subgoal's text rides along in one of the two passes.
            send_subgoal: replan == 1,
            ..RemoteConfig::default()
        };
        let make = || -> Result<Box<dyn Policy>, EvalError> {
            Ok(Box::new(RemotePolicy::connect(remote.clone())?))
        };
        let got = eval::evaluate(&tasks, &make, &base, &|_| {}).unwrap();
        assert_eq!(got.episodes, want.episodes, "replan {replan}");
        assert_eq!(got.tasks, want.tasks, "the same table rows");
    }

    // An episode the server does not know: its error text, naming the episode and step.
    let other = EvalConfig {
        seed: 42,
        ..base.clone()
    };
    let remote = RemoteConfig {
        url: format!("ws://127.0.0.1:{port}"),
        ..RemoteConfig::default()
    };
    let make = || -> Result<Box<dyn Policy>, EvalError> {
        Ok(Box::new(RemotePolicy::connect(remote.clone())?))
    };
    let e = eval::evaluate(&tasks[..1], &make, &other, &|_| {}).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!(
            "policy server ws://127.0.0.1:{port}: episode libero_mem/t1@"
        )) && msg.contains(", step 0: the server failed:\nno recorded episode"),
        "{msg}"
    );
}

/// A server that fails mid-evaluation — closes the connection, replies `[H, 5]` actions, or a NaN
/// in the chunk — stops `eval --policy ws://` with one error naming the server, the episode and
/// the step (exit 2), no results file, and the episode finished before it kept in the journal.
#[test]
fn a_server_failing_mid_evaluation_is_one_error_and_keeps_finished_episodes() {
    let Some(python) = python() else { return };
    let budget = sim::task::resolve("t1").unwrap().max_steps;
    // Episode 0 takes ceil(budget / 5) requests at 5 replan steps; episode 1 fails at its 4th.
    let fail_after = budget.div_ceil(5) + 3;
    for (mode, want) in [
        ("close", "the server closed the connection"),
        ("shape", "`actions` has shape [8, 5]"),
        ("nan", "`actions`[1, 3] is NaN, not a finite number"),
    ] {
        let fail_after = fail_after.to_string();
        let (_server, port) = start_with(
            &python,
            &["--zeros", "--fail", mode, "--fail-after", &fail_after],
        );
        let url = format!("ws://127.0.0.1:{port}");
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let run = Command::new(env!("CARGO_BIN_EXE_eval"))
            .args(["--tasks", "t1", "--episodes", "2", "--seed", "7"])
            .args([
                "--policy",
                &url,
                "--image-size",
                "64",
                "--remote-timeout",
                "20",
            ])
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{mode}: {err}");
        let msg: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
        assert_eq!(msg.len(), 1, "{mode}: one error line: {err}");
        assert!(
            msg[0].contains(&format!("policy server {url}: episode libero_mem/t1@"))
                && msg[0].contains("step 15")
                && msg[0].contains(want),
            "{mode}: {err}"
        );
        assert!(
            !out.join("results.json").exists(),
            "{mode}: no results file"
        );
        let journal = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
        assert_eq!(
            journal.lines().count(),
            2,
            "{mode}: the header and the finished episode: {journal}"
        );
    }
}
