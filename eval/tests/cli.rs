//! The `eval` binary with sanity policies.

use std::path::Path;
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
    let (code, _, err) = eval(&["--tasks", "t99", "--episodes", "1", "--policy", "zero"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("t99") && err.contains("libero_mem/t1"),
        "{err}"
    );
}

#[test]
fn no_policy_and_model_without_run_are_exit_2() {
    let (code, _, err) = eval(&["--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--run runs/NAME"), "{err}");
    let (code, _, err) = eval(&["--tasks", "t1", "--policy", "model"]);
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = eval(&["--tasks", "t1", "--policy", "zero", "--viz"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--viz needs the model policy"), "{err}");
}

#[test]
fn backend_override_is_checked() {
    let (code, _, err) = eval(&["--tasks", "t1", "--policy", "zero", "--backend", "flex"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--backend needs a model policy"), "{err}");
    let (code, _, err) = eval(&["--tasks", "t1", "--policy", "zero", "--backend", "tpu"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown backend `tpu`"), "{err}");
}

/// A run directory as `train` writes it (the run contract of `model::run`), without
/// checkpoints yet.
fn bare_run(dir: &Path) -> model::ModelConfig {
    let model = model::ModelConfig::tiny(model::Variant::ESlotSsm {
        oracle_subgoal: false,
    })
    .with_vocab_from(["put the bowl on the plate"]);
    let norm = data::ActionNorm {
        q01: [-1.0; 7],
        q99: [1.0; 7],
        mask: [true, true, true, true, true, true, false],
    };
    let info = model::run::RunInfo::new(Default::default(), vec!["t1".into()]);
    model::run::write_policy(dir, &info, &model, &model::Processor::new(&model, norm)).unwrap();
    model
}

#[test]
fn run_without_checkpoint_is_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    bare_run(&run);
    let (code, _, err) = eval(&["--run", run.to_str().unwrap(), "--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no complete checkpoint"), "{err}");
    let (code, _, err) = eval(&["--run", tmp.path().join("nope").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no such run directory"), "{err}");
}

/// A step-10 checkpoint in `run` whose state names `model` and whose weights are not weights.
fn unreadable_checkpoint(run: &Path, model: &model::ModelConfig) {
    let ck = run.join("checkpoints").join("step_000000010");
    std::fs::create_dir_all(&ck).unwrap();
    let state = serde_json::json!({ "step": 10, "model": model });
    std::fs::write(ck.join("state.json"), state.to_string()).unwrap();
    std::fs::write(ck.join("model.bpk"), b"not weights").unwrap();
}

/// A bare run (in a temporary folder, kept alive by the returned guard) whose only checkpoint,
/// step 10, names the run's own model and holds unreadable weights.
fn run_with_unreadable_checkpoint() -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let model = bare_run(&run);
    unreadable_checkpoint(&run, &model);
    (tmp, run)
}

#[test]
fn checkpoint_of_another_model_is_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let model = bare_run(&run);
    let other = model::ModelConfig {
        variant: model::Variant::SlotVla { history: 8 },
        ..model
    };
    unreadable_checkpoint(&run, &other);
    let (code, _, err) = eval(&["--run", run.to_str().unwrap(), "--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("step_000000010") && err.contains("slotvla"),
        "{err}"
    );
}

/// `--checkpoint N` takes that step's checkpoint or fails naming the steps the run holds; without
/// a run it is an argument error. Both exit 2.
#[test]
fn checkpoint_of_a_missing_step_is_exit_2_naming_the_steps() {
    let (_tmp, run) = run_with_unreadable_checkpoint();
    let r = run.to_str().unwrap();
    let (code, _, err) = eval(&["--run", r, "--checkpoint", "4", "--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("no complete checkpoint of step 4 (it holds steps 10)"),
        "{err}"
    );
    // The step it holds is the one opened: its (unreadable) weights are what fails.
    let (code, _, err) = eval(&["--run", r, "--checkpoint", "10", "--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("step_000000010") && err.contains("model.bpk"),
        "{err}"
    );
    assert!(!run.join("eval_step_10/results.json").exists());
    let (code, _, err) = eval(&["--policy", "zero", "--checkpoint", "10", "--tasks", "t1"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--checkpoint needs a model policy"), "{err}");
}

/// `eval serve --backend` picks the device the served policy runs on; one this binary lacks is
/// exit 2 naming it, before anything listens.
#[test]
fn serve_backend_override_is_checked() {
    let (_tmp, run) = run_with_unreadable_checkpoint();
    let run = run.to_str().unwrap();
    let (code, _, err) = eval(&["serve", "--run", run, "--port", "0", "--backend", "cuda"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cuda") && !err.contains("serving"), "{err}");
    let (code, _, err) = eval(&["serve", "--run", run, "--backend", "tpu"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown backend `tpu`"), "{err}");
    // On the CPU backend it gets as far as loading the (unreadable) weights.
    let (code, _, err) = eval(&["serve", "--run", run, "--port", "0", "--backend", "flex"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("model.bpk"), "{err}");
}

#[test]
fn compare_reads_results_and_rejects_garbage() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for (dir, policy) in [(&a, "zero"), (&b, "random")] {
        let (code, _, err) = eval(&[
            "--tasks",
            "t1",
            "--episodes",
            "1",
            "--policy",
            policy,
            "--quiet",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{err}");
    }
    let (code, out, err) = eval(&["compare", a.to_str().unwrap(), b.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("Subgoal completion %") && out.contains("| t1 | 0.0 | 0.0 |"),
        "{out}"
    );
    std::fs::write(tmp.path().join("bad.json"), "[1, 2]").unwrap();
    let (code, _, err) = eval(&["compare", tmp.path().join("bad.json").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bad.json: not an eval results file"), "{err}");
}

#[test]
fn expert_scaling_table_over_repetitions() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, out, err) = eval(&[
        "scaling",
        "--policy",
        "expert",
        "--tasks",
        "t1",
        "--repeats",
        "1,2",
        "--episodes",
        "1",
        "--quiet",
        "--out",
        tmp.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("| task | N = 1 | N = 2 |"), "{out}");
    assert!(out.contains("| t1 | 100.0 (100) | 100.0 (100) |"), "{out}");
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("scaling.json")).unwrap())
            .unwrap();
    assert_eq!(rows.as_array().unwrap().len(), 2);
}

#[test]
fn libero_init_without_the_pack_names_the_install_command() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--policy",
            "zero",
            "--tasks",
            "libero_goal/put_the_bowl_on_the_plate",
            "--libero-init",
            "--episodes",
            "1",
            "--out",
        ])
        .arg(tmp.path().join("out"))
        .env("LIBERO_MEM_CACHE", tmp.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("assets install libero"), "{err}");
    assert!(!tmp.path().join("out").join("results.json").exists());
}

/// With the LIBERO pack installed: LIBERO's protocol (init state k, 10 idle steps) and the expert
/// still solves the task from those starts.
#[test]
fn expert_from_libero_init_states() {
    if sim::pack::LiberoPack::for_tests().is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (code, out, err) = eval(&[
        "--policy",
        "expert",
        "--tasks",
        "libero_goal/put_the_bowl_on_the_plate",
        "--libero-init",
        "--episodes",
        "2",
        "--quiet",
        "--out",
        tmp.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("| libero_goal/put_the_bowl_on_the_plate | 2 | 100.0 ± 0.0 | 100.0"),
        "{out}"
    );
}

#[test]
fn a_closed_stdout_still_writes_the_results() {
    let dir = tempfile::tempdir().unwrap();
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--tasks",
            "t1",
            "--episodes",
            "1",
            "--policy",
            "zero",
            "--out",
        ])
        .arg(dir.path())
        .stdout(writer)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for f in ["results.md", "results.json", "results.csv"] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
}

/// On a clone without run directories, `eval experiment --tables-only` rebuilds the tables from
/// the ledger `OUT/runs.json` and writes the same ledger back; a run the ledger lacks is listed as
/// not trained; a ledger that is not one is exit 2 naming the file.
#[test]
fn experiment_tables_from_the_ledger_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("docs");
    std::fs::create_dir_all(&out).unwrap();
    let file = dir.path().join("x.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"x\"\nout = \"{}\"\nepisodes = 20\nseed = 1000\nruns_dir = \"{}\"\n\
             [[runs]]\nobs = \"state\"\nsuite = \"t3\"\nconfig = \"configs/state/t3.toml\"\n\
             variants = [\"e_slotssm\", \"slotvla_h1\"]\n",
            out.display(),
            dir.path().join("runs").display()
        ),
    )
    .unwrap();
    let run = dir.path().join("runs").join("x_state_t3_e_slotssm");
    let ledger = serde_json::json!({
        "episodes": 20, "seed": 1000, "full_budget": true,
        "runs": [{
            "obs": "state", "variant": "e_slotssm", "run": run.display().to_string(),
            "train_s": 1500.0, "steps": 16000,
            "tasks": [{
                "task": "libero_mem/t3", "episodes": 20, "completion": 66.67,
                "completion_ci95": 18.4, "success": 0.0, "success_ci95": [0.0, 16.1],
                "mean_steps": 320.0, "over_repetition": 11
            }]
        }]
    });
    let text = serde_json::to_string_pretty(&ledger).unwrap();
    std::fs::write(out.join("runs.json"), &text).unwrap();
    let f = file.to_str().unwrap();
    let (code, stdout, err) = eval(&["experiment", f, "--tables-only", "--quiet"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("1 evaluated runs read from"), "{err}");
    assert!(stdout.contains("| e_slotssm | 67 ± 18 |"), "{stdout}");
    assert!(
        stdout.contains("- state mode: slotvla_h1 on t3"),
        "{stdout}"
    );
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("| e_slotssm | 67 ± 18 |"), "{md}");
    let back: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("runs.json")).unwrap()).unwrap();
    assert_eq!(back, ledger);
    // --plan lists every run with its state and `train` command, and writes nothing.
    std::fs::remove_file(out.join("results.md")).unwrap();
    let (code, stdout, err) = eval(&["experiment", f, "--plan"]);
    assert_eq!(code, 0, "{err}");
    let runs = dir.path().join("runs");
    assert_eq!(
        stdout,
        format!(
            "x_state_t3_e_slotssm [e_slotssm] evaluated (66.7 % mean completion)\n  train \
             'configs/state/t3.toml' --run-dir '{0}/x_state_t3_e_slotssm' --set \
             'name=\"x_state_t3_e_slotssm\"' --set 'model.variant=\"e_slotssm\"'\n\
             x_state_t3_slotvla_h1 [slotvla_h1] to train and evaluate\n  train \
             'configs/state/t3.toml' --run-dir '{0}/x_state_t3_slotvla_h1' --set \
             'name=\"x_state_t3_slotvla_h1\"' --set 'model.variant=\"slotvla_h1\"'\n",
            runs.display()
        )
    );
    assert!(!out.join("results.md").exists());
    let (code, _, err) = eval(&["experiment", f, "--plan", "--tables-only"]);
    assert_eq!(code, 2, "{err}");
    // Another protocol's ledger is not used (and the tables say the run is missing).
    std::fs::write(
        out.join("runs.json"),
        text.replace("\"seed\": 1000", "\"seed\": 7"),
    )
    .unwrap();
    let (code, stdout, err) = eval(&["experiment", f, "--tables-only", "--quiet"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("- state mode: e_slotssm on t3"), "{stdout}");
    assert!(
        err.contains("runs.json: evaluated under another protocol"),
        "{err}"
    );
    // Garbage is one error naming the file.
    std::fs::write(out.join("runs.json"), "{\"runs\": 3}").unwrap();
    let (code, _, err) = eval(&["experiment", f, "--tables-only", "--quiet"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("runs.json") && err.contains("not a ledger of evaluated runs"),
        "{err}"
    );
}

#[test]
fn sharded_expert_evaluation_merges_into_the_unsharded_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let base = [
        "--policy",
        "expert",
        "--tasks",
        "t1,t3",
        "--episodes",
        "3",
        "--seed",
        "4",
    ];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = base.iter().copied().chain(extra.iter().copied()).collect();
        let (code, _, err) = eval(&args);
        assert_eq!(code, 0, "{err}");
    };
    run(&["--out", &out("whole")]);
    // Worker processes (each a shard, merged by the parent): the same files, their folder gone.
    run(&["--workers", "2", "--processes", "--out", &out("procs")]);
    assert!(!dir.path().join("procs/processes").exists());
    run(&["--shard", "0/2", "--out", &out("s0")]);
    run(&["--shard", "1/2", "--out", &out("s1")]);
    let (code, stdout, err) = eval(&["merge", &out("s1"), &out("s0"), "--out", &out("merged")]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("| libero_mem/t3 | 3 |"), "{stdout}");
    for f in ["results.md", "results.json", "results.csv"] {
        for other in ["merged", "procs"] {
            assert_eq!(
                std::fs::read_to_string(dir.path().join("whole").join(f)).unwrap(),
                std::fs::read_to_string(dir.path().join(other).join(f)).unwrap(),
                "{other}/{f}"
            );
        }
    }
    // A worker process that fails on bad input: exit 2 from the parent, naming the process and
    // the worker's own error, and no results.
    let (code, _, err) = eval(&[
        "--policy",
        "ws://127.0.0.1:1",
        "--tasks",
        "t1",
        "--episodes",
        "2",
        "--workers",
        "2",
        "--processes",
        "--out",
        &out("unreachable"),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("worker process") && err.contains("127.0.0.1:1"),
        "{err}"
    );
    assert!(!dir.path().join("unreachable/results.json").exists());
    let (code, _, err) = eval(&["merge", &out("s0"), "--out", &out("bad")]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("shard 1/2 is missing"), "{err}");
    assert!(
        !dir.path().join("bad").exists(),
        "no output on a refused merge"
    );
    let (code, _, err) = eval(&["--policy", "zero", "--shard", "2/2", "--out", &out("x")]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("expected I/N"), "{err}");
}

#[test]
fn bad_policy_urls_and_unreachable_servers_are_one_error() {
    for (policy, want) in [
        ("ws://localhost", "no port (ws://HOST:PORT)"),
        ("wss://h:1", "TLS (wss://) is not supported"),
        (
            "bogus",
            "expected model, expert, random, zero or ws://HOST:PORT",
        ),
    ] {
        let (code, _, err) = eval(&["--tasks", "t1", "--policy", policy]);
        assert_eq!(code, 2, "{policy}: {err}");
        assert!(err.contains(want), "{policy}: {err}");
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("ws://127.0.0.1:{port}");
    let dir = std::env::temp_dir().join(format!("eval-cli-ws-{}", std::process::id()));
    let (code, _, err) = eval(&[
        "--tasks",
        "t1",
        "--episodes",
        "1",
        "--policy",
        &url,
        "--remote-timeout",
        "2",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(&format!("policy server {url}: cannot connect")),
        "{err}"
    );
    assert!(!dir.join("results.json").exists(), "no results file");
    let (code, _, err) = eval(&["--tasks", "t1", "--policy", &url, "--run", "runs/x"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("either --run or a ws:// --policy"), "{err}");
}

#[test]
fn a_killed_evaluation_resumes_from_its_journal() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let args = |out: &Path| {
        vec![
            "--tasks".to_string(),
            "t1,t2".into(),
            "--episodes".into(),
            "3".into(),
            "--seed".into(),
            "4".into(),
            "--policy".into(),
            "random".into(),
            "--out".into(),
            out.display().to_string(),
        ]
    };
    let run = |out: &Path| {
        let a = args(out);
        eval(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    // The whole evaluation, once, for reference; its journal is gone once the tables are written.
    let whole = dir.path().join("whole");
    let (code, table, err) = run(&whole);
    assert_eq!(code, 0, "{err}");
    assert!(!whole.join("episodes.jsonl").exists());
    let journal = std::fs::read_to_string(
        // A journal as a killed run leaves it: the header, two episodes and a torn third line.
        {
            let (code, _, err) = run(&out);
            assert_eq!(code, 0, "{err}");
            out.join("results.json")
        },
    )
    .unwrap();
    let results: serde_json::Value = serde_json::from_str(&journal).unwrap();
    let eps = results["episodes"].as_array().unwrap();
    let header = serde_json::json!({
        "format": "libero-mem-rs/eval-journal/1",
        "evaluation": format!(
            "policy random | run None | checkpoint None | execute first | remote None | quality fast \
             | seed 4 | 3 episodes | full budget false | libero init false | assets Builtin | image 128 \
             | shard 0/1"
        ),
    });
    let mut text = format!("{header}\n");
    for e in &eps[..2] {
        text.push_str(&format!("{e}\n"));
    }
    // A marked copy of episode 0 shows that journaled episodes are not run again.
    text = text.replacen("\"steps\":200", "\"steps\":199", 1);
    text.push_str(&eps[2].to_string()[..20]);
    std::fs::remove_file(out.join("results.json")).unwrap();
    std::fs::write(out.join("episodes.jsonl"), &text).unwrap();
    let (code, resumed, err) = run(&out);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("resuming, 2 episodes already evaluated"),
        "{err}"
    );
    let back: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(back["episodes"][0]["steps"], 199, "taken from the journal");
    assert_eq!(
        back["episodes"].as_array().unwrap()[1..],
        results["episodes"].as_array().unwrap()[1..]
    );
    assert_ne!(resumed, table);
    assert!(!out.join("episodes.jsonl").exists());
    // A journal of another evaluation (here another seed) is not used.
    std::fs::write(out.join("episodes.jsonl"), text.replace("seed 4", "seed 5")).unwrap();
    let (code, again, err) = run(&out);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("a journal of another evaluation; starting afresh"),
        "{err}"
    );
    assert_eq!(again, table);
}

#[test]
fn videos_of_every_rollout_and_a_page_linking_them() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let videos = out.join("videos");
    let (code, _, err) = eval(&[
        "--tasks",
        "t1",
        "--episodes",
        "2",
        "--seed",
        "3",
        "--policy",
        "expert",
        "--image-size",
        "64",
        "--out",
        out.to_str().unwrap(),
        "--video",
        videos.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    // The results table as an HTML table.
    assert!(
        page.contains("<th>subgoal completion % (95 % CI)</th>")
            && page.contains("<td>libero_mem/t1</td>"),
        "{page}"
    );
    for e in results["episodes"].as_array().unwrap() {
        let k = e["episode"].as_u64().unwrap();
        let steps = e["steps"].as_u64().unwrap();
        let rel = format!("videos/libero_mem-t1/episode_{k:06}.mp4");
        assert!(page.contains(&format!("src=\"{rel}\"")), "{page}");
        // The first frame as the video's poster.
        let poster = rel.replace(".mp4", ".png");
        assert!(page.contains(&format!("poster=\"{poster}\"")), "{page}");
        let img = image::open(out.join(&poster)).unwrap();
        assert_eq!((img.width(), img.height()), (128, 88));
        let bytes = std::fs::read(out.join(&rel)).unwrap();
        let size = bytes.len() as u64;
        let r = mp4::Mp4Reader::read_header(std::io::Cursor::new(bytes), size).unwrap();
        // A frame per step the policy acted on, and the last observation; 128×(64 + 24).
        assert_eq!(r.sample_count(1).unwrap() as u64, steps + 1);
        let t = &r.tracks()[&1];
        assert_eq!((t.width(), t.height()), (128, 88));
        // Playable by Debian's ffmpeg, when it is installed.
        match Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-count_frames",
                "-show_entries",
                "stream=codec_name,width,height,nb_read_frames",
                "-of",
                "csv=p=0",
            ])
            .arg(out.join(&rel))
            .output()
        {
            Ok(o) => {
                assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
                let line = String::from_utf8_lossy(&o.stdout).trim().to_string();
                assert_eq!(line, format!("h264,128,88,{}", steps + 1));
            }
            Err(_) => eprintln!("ffprobe not installed: mp4 checked with the mp4 crate only"),
        }
    }
}

#[test]
fn dagger_bad_input_is_exit_2_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let run = tmp.path().join("run");
    bare_run(&run);
    let r = run.to_str().unwrap();
    let (code, _, err) = eval(&[
        "dagger", "--run", r, "--out", o, "--from", "0.9", "--to", "0.1",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--from 0.9 --to 0.1"), "{err}");
    let (code, _, err) = eval(&["dagger", "--run", r, "--out", o]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no complete checkpoint"), "{err}");
    let nope = tmp.path().join("nope");
    let (code, _, err) = eval(&["dagger", "--run", nope.to_str().unwrap(), "--out", o]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no such run directory"), "{err}");
    assert!(!out.exists(), "nothing written on bad input");
}
