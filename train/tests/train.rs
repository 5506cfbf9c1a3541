//! End-to-end tests of the trainer on synthetic episodes (`data::synth`) with the CI config
//! `configs/tiny.toml`: the loss halves, a killed run resumes to the same weights as an
//! uninterrupted one, and bad input is a clear error with exit status 2.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard, OnceLock};

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::*;
use model::{ModelConfig, PolicyModel};
use train::{TrainOptions, metrics};

/// Burn's RNG is process-wide: runs of this test binary must not interleave.
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// One synthetic dataset shared by the tests (4 episodes × 40 steps of 32² frames).
fn dataset() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = tempfile::tempdir().unwrap();
        common::write_dataset(d.path(), 4, 40, 32);
        d
    })
    .path()
}

fn opts(run_dir: &Path) -> TrainOptions {
    TrainOptions {
        run_dir: Some(run_dir.to_path_buf()),
        ..Default::default()
    }
}

fn write_config(dir: &Path, cfg: &train::Config) -> PathBuf {
    let p = dir.join("exp.toml");
    std::fs::write(&p, cfg.to_toml()).unwrap();
    p
}

fn train_bin(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_train"))
        .args(args)
        .arg("--quiet")
        .output()
        .unwrap()
}

/// Runs the `train` binary with `args`, checks that it exits 2 (bad input), returns its stderr.
fn exit_2_stderr(args: &[&str]) -> String {
    let out = train_bin(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    stderr
}

#[test]
fn tiny_config_halves_the_training_loss() {
    let _g = serial();
    let run = tempfile::tempdir().unwrap();
    let cfg = common::tiny_config(dataset());
    let s = train::train(&cfg, &opts(run.path())).unwrap();
    assert_eq!(s.step, cfg.train.steps);
    let losses: Vec<f64> = metrics::read(&run.path().join("metrics.jsonl"))
        .unwrap()
        .iter()
        .map(|r| r.loss)
        .collect();
    assert_eq!(losses.len() as u64, cfg.train.steps);
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (initial, last) = (mean(&losses[..5]), mean(&losses[losses.len() - 20..]));
    eprintln!(
        "loss {initial:.4} → {last:.4} in {} steps ({:.2} steps/s)",
        s.step, s.steps_per_s
    );
    assert!(
        last < 0.5 * initial,
        "training loss {initial} → {last}: not below half"
    );
    // The run directory holds what eval and humans need.
    for f in [
        "config.toml",
        "model.json",
        "action_stats.json",
        "val.jsonl",
        "val_walk.jsonl",
        "plots/loss_loss.png",
        "plots/loss_action.png",
        "plots/loss_window.png",
        "checkpoints/latest",
    ] {
        assert!(run.path().join(f).is_file(), "{f} missing");
    }
    assert!(s.val_loss.is_some_and(f64::is_finite));
    assert!(s.val_walk_loss.is_some_and(f64::is_finite));
    // One walked validation beside each cold one, at the same steps.
    let steps = |f: &str| -> Vec<u64> {
        metrics::read(&run.path().join(f))
            .unwrap()
            .iter()
            .map(|r| r.step)
            .collect()
    };
    assert_eq!(steps("val_walk.jsonl"), steps("val.jsonl"));
    assert_eq!(steps("val.jsonl"), vec![100, 200, 300, 400]);
    // `train --validate` reads the newest checkpoint's weights back: the same losses as the
    // run's last validations, bit for bit, and the logs stay as they were.
    let config = write_config(run.path(), &cfg);
    let out = train_bin(&[
        config.to_str().unwrap(),
        "--run-dir",
        run.path().to_str().unwrap(),
        "--validate",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("(step 400): val loss"), "{stdout}");
    for (name, file) in [("windows", "val.jsonl"), ("walked", "val_walk.jsonl")] {
        let line = stdout
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no {name} line in {stdout}"));
        let printed: metrics::Record = serde_json::from_str(line).unwrap();
        let logged = metrics::read(&run.path().join(file)).unwrap();
        assert_eq!(
            printed.loss.to_bits(),
            logged.last().unwrap().loss.to_bits(),
            "{name}"
        );
    }
    assert_eq!(steps("val.jsonl").len(), 4);
    // keep = 2: older checkpoints were pruned.
    let kept = train::checkpoint::list(run.path()).unwrap();
    assert_eq!(
        kept.iter().map(|k| k.0).collect::<Vec<_>>(),
        vec![
            cfg.train.steps - cfg.train.checkpoint_every,
            cfg.train.steps
        ]
    );
    // The saved config is the resolved one and loads back.
    let saved = train::Config::load(run.path().join("config.toml")).unwrap();
    assert_eq!(saved.train, cfg.train);
}

/// The walked validation (whole validation episodes with the memory carried): its bookkeeping —
/// lanes taking the next episode, the memory of the lanes that go on, the batch shrinking when
/// the episodes run out — does not change its per-frame mean, whatever the number of lanes; and
/// walking each episode in chunks with the memory carried gives the action loss of reading each
/// episode in one chunk (nothing to carry), while cold-memory windows give another.
#[test]
fn walked_validation_is_the_same_for_any_lane_count_and_chunk_length() {
    let _g = serial();
    let data_dir = tempfile::tempdir().unwrap();
    common::write_dataset(data_dir.path(), 12, 40, 32);
    let run = tempfile::tempdir().unwrap();
    let mut cfg = common::tiny_config(data_dir.path());
    cfg.train.steps = 30;
    cfg.train.warmup_steps = 3;
    cfg.train.checkpoint_every = 30;
    cfg.train.val_every = 0;
    train::train(&cfg, &opts(run.path())).unwrap();
    let model = checkpoint_model(run.path(), 30);
    let device = Device::flex();
    let walked = |window: usize, lanes: usize, episodes: usize| {
        let mut c = cfg.clone();
        c.data.window = Some(window);
        let (_, data) = train::open_data(&c).unwrap();
        assert_eq!(data.val.as_ref().unwrap().num_episodes(), 3);
        train::trainer::validate_walked(&model, &data, lanes, episodes, 30, &device)
            .unwrap()
            .unwrap()
    };
    let base = walked(4, 8, 3);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * a.abs().max(1e-3);
    for lanes in [1, 2, 3] {
        let r = walked(4, lanes, 3);
        assert!(
            close(r.action, base.action),
            "{lanes} lanes: {r:?} vs {base:?}"
        );
        assert!(close(r.loss, base.loss), "{lanes} lanes: {r:?} vs {base:?}");
    }
    let whole = walked(40, 2, 3);
    assert!(close(whole.action, base.action), "{whole:?} vs {base:?}");
    // Fewer episodes: another mean; none: nothing.
    assert_ne!(walked(4, 8, 1).action.to_bits(), base.action.to_bits());
    let (_, data) = train::open_data(&cfg).unwrap();
    assert!(
        train::trainer::validate_walked(&model, &data, 8, 0, 30, &device)
            .unwrap()
            .is_none()
    );
    let cold = train::trainer::validate(&model, &data, 8, 0, 30, &device)
        .unwrap()
        .unwrap();
    eprintln!(
        "walked {} (whole {}), cold windows {}",
        base.action, whole.action, cold.action
    );
    assert!(!close(cold.action, base.action));
}

/// A short variant of the CI config for the resume tests.
fn short_config(steps: u64, every: u64) -> train::Config {
    let mut cfg = common::tiny_config(dataset());
    cfg.train.steps = steps;
    cfg.train.checkpoint_every = every;
    cfg.train.warmup_steps = 3;
    cfg.train.val_every = 5;
    cfg.train.keep = 0;
    cfg
}

#[test]
fn stopped_and_resumed_run_ends_with_identical_weights() {
    let _g = serial();
    for sampling in [
        train::config::Sampling::Episodes,
        train::config::Sampling::Windows,
    ] {
        stop_and_resume(sampling, 0);
    }
    // A lane pool three times the batch: the checkpoint keeps every pool lane's memory.
    stop_and_resume(train::config::Sampling::Episodes, 3);
}

/// The loader thread prepares the batches the loop would have made: a run with it and one
/// without end with the same weights, bit for bit, and the same per-step losses.
#[test]
fn prefetched_batches_train_like_batches_made_in_the_loop() {
    let _g = serial();
    for sampling in [
        train::config::Sampling::Episodes,
        train::config::Sampling::Windows,
    ] {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let mut cfg = short_config(7, 0);
        cfg.train.sampling = sampling;
        train::train(&cfg, &opts(a.path())).unwrap();
        let in_loop = TrainOptions {
            no_prefetch: true,
            ..opts(b.path())
        };
        train::train(&cfg, &in_loop).unwrap();
        let losses = |d: &Path| {
            metrics::read(&d.join("metrics.jsonl"))
                .unwrap()
                .iter()
                .map(|r| r.loss.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(losses(a.path()).len(), 7);
        assert_eq!(losses(a.path()), losses(b.path()), "{sampling:?}");
        assert_eq!(
            common::bits(&common::final_weights(a.path())),
            common::bits(&common::final_weights(b.path())),
            "{sampling:?}"
        );
    }
}

/// Episode sampling carries the memory across batches: the checkpoint keeps it (carry.json),
/// so the resumed run continues with the memory the uninterrupted run had.
/// `pool`: a lane pool of that many batches' lanes (0: none).
fn stop_and_resume(sampling: train::config::Sampling, pool: usize) {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mut cfg = short_config(12, 6);
    cfg.train.sampling = sampling;
    cfg.train.lane_pool = pool * cfg.train.batch_size;
    train::train(&cfg, &opts(a.path())).unwrap();
    let carry = a.path().join("checkpoints/step_000000006/carry.json");
    assert_eq!(
        carry.is_file(),
        sampling == train::config::Sampling::Episodes
    );
    if pool > 0 {
        // One slot row per pool lane.
        let rec: model::variants::CarryRecord =
            serde_json::from_str(&std::fs::read_to_string(&carry).unwrap()).unwrap();
        assert_eq!(
            rec.slots.unwrap().shape[0],
            pool * cfg.train.batch_size,
            "pool lanes in carry.json"
        );
        // The pool draws other batches than a run without one: other weights.
        let plain = tempfile::tempdir().unwrap();
        let mut no_pool = cfg.clone();
        no_pool.train.lane_pool = 0;
        train::train(&no_pool, &opts(plain.path())).unwrap();
        assert_ne!(
            common::bits(&common::final_weights(a.path())),
            common::bits(&common::final_weights(plain.path()))
        );
    }
    // Stopped at the mid-way checkpoint, as if killed right after it.
    let stop = TrainOptions {
        stop_at: Some(6),
        ..opts(b.path())
    };
    assert_eq!(train::train(&cfg, &stop).unwrap().step, 6);
    // What a kill -9 during the next checkpoint write can leave: a temporary directory, a
    // torn metrics line, a `latest` naming a checkpoint that never got its final name.
    let ck = b.path().join("checkpoints");
    std::fs::create_dir_all(ck.join(".tmp-killed")).unwrap();
    std::fs::write(ck.join(".tmp-killed/model.bpk"), b"partial").unwrap();
    std::fs::write(ck.join("latest"), "step_000000009").unwrap();
    let mut m = std::fs::OpenOptions::new()
        .append(true)
        .open(b.path().join("metrics.jsonl"))
        .unwrap();
    std::io::Write::write_all(&mut m, b"{\"step\":7,\"lo").unwrap();
    // Resuming is automatic when the run directory has checkpoints.
    let s = train::train(&cfg, &opts(b.path())).unwrap();
    assert_eq!((s.start_step, s.step), (6, 12));
    assert!(!ck.join(".tmp-killed").exists());
    assert_eq!(
        common::bits(&common::final_weights(a.path())),
        common::bits(&common::final_weights(b.path())),
        "{sampling:?}: resumed run differs from the uninterrupted one"
    );
    let steps: Vec<u64> = metrics::read(&b.path().join("metrics.jsonl"))
        .unwrap()
        .iter()
        .map(|r| r.step)
        .collect();
    assert_eq!(steps, (1..=12).collect::<Vec<_>>());
    // Same config and seed, a second time: the same weights.
    let c = tempfile::tempdir().unwrap();
    train::train(&cfg, &opts(c.path())).unwrap();
    assert_eq!(
        common::bits(&common::final_weights(a.path())),
        common::bits(&common::final_weights(c.path()))
    );
}

/// Two data-parallel replicas (half the lanes each, the mean of their gradients): from the same
/// initial weights, the loss curve follows the one-replica run's at the same global batch, and
/// the run is as reproducible as any: resumed from its mid-way checkpoint (the carried memory
/// joined from both halves), it ends with the uninterrupted run's bytes.
#[test]
fn two_replicas_follow_one_and_resume_bit_for_bit() {
    let _g = serial();
    let steps = 12;
    let mut one = short_config(steps, 6);
    one.train.sampling = train::config::Sampling::Episodes;
    let mut two = one.clone();
    two.train.replicas = 2;
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    train::train(&one, &opts(a.path())).unwrap();
    train::train(&two, &opts(b.path())).unwrap();
    let losses = |d: &Path| -> Vec<f64> {
        metrics::read(&d.join("metrics.jsonl"))
            .unwrap()
            .iter()
            .map(|r| r.loss)
            .collect()
    };
    let (l1, l2) = (losses(a.path()), losses(b.path()));
    assert_eq!((l1.len(), l2.len()), (steps as usize, steps as usize));
    // These lanes have equal frame counts, so the mean of the halves' mean losses is the
    // batch's mean loss: the curves agree to float rounding (the sums run in another order).
    for (k, (x, y)) in l1.iter().zip(&l2).enumerate() {
        assert!(
            (x - y).abs() <= 1e-4 * x.abs(),
            "step {}: one replica {x}, two {y}",
            k + 1
        );
    }
    // Stopped at the mid-way checkpoint and resumed: the uninterrupted two-replica run's bytes.
    let stop = TrainOptions {
        stop_at: Some(6),
        ..opts(c.path())
    };
    train::train(&two, &stop).unwrap();
    assert!(
        c.path()
            .join("checkpoints/step_000000006/carry.json")
            .is_file()
    );
    let s = train::train(&two, &opts(c.path())).unwrap();
    assert_eq!((s.start_step, s.step), (6, steps));
    assert_eq!(
        common::bits(&common::final_weights(b.path())),
        common::bits(&common::final_weights(c.path())),
        "resumed two-replica run differs from the uninterrupted one"
    );
    // A replica count that does not divide the batch is a config error.
    let d = tempfile::tempdir().unwrap();
    let mut three = one.clone();
    three.train.replicas = 3;
    let path = write_config(d.path(), &three);
    let err = exit_2_stderr(&[
        path.to_str().unwrap(),
        "--run-dir",
        d.path().join("r").to_str().unwrap(),
    ]);
    assert!(
        err.contains("train.replicas: must be ≥ 1 and divide train.batch_size 8 (got 3)"),
        "{err}"
    );
    assert!(err.contains("exp.toml"), "{err}");
}

/// A weight average (`train.ema`): each checkpoint's policy (`model.bpk`) is the average of the
/// trained weights after every step (recomputed here from each step's `train_model.bpk`), a
/// stopped run resumes to the same bytes of both, and a run or config with another decay is
/// refused with exit status 2.
#[test]
fn weight_average_follows_every_step_and_resumes_bit_for_bit() {
    let _g = serial();
    let steps = 8;
    let decay = 0.5;
    let mut cfg = short_config(steps, 1);
    cfg.train.ema = Some(decay);
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    train::train(&cfg, &opts(a.path())).unwrap();
    let name = |k: u64| format!("step_{k:09}");
    // ema₁ = w₁, emaₖ = d·emaₖ₋₁ + (1 − d)·wₖ, in f64 from the saved trained weights.
    let mut want: Vec<Vec<f64>> = vec![];
    for k in 1..=steps {
        let w = common::weights_of(a.path(), &name(k), "train_model.bpk");
        if k == 1 {
            want = w
                .iter()
                .map(|t| t.iter().map(|&x| x as f64).collect())
                .collect();
        } else {
            for (e, t) in want.iter_mut().zip(&w) {
                for (e, &x) in e.iter_mut().zip(t) {
                    *e = decay * *e + (1.0 - decay) * x as f64;
                }
            }
        }
        let got = common::weights_of(a.path(), &name(k), "model.bpk");
        assert_eq!(got.len(), want.len());
        let mut worst = 0f64;
        for (g, e) in got.iter().zip(&want) {
            for (&g, &e) in g.iter().zip(e) {
                worst = worst.max((g as f64 - e).abs() / e.abs().max(1e-3));
            }
        }
        assert!(worst < 1e-5, "step {k}: the average is off by {worst:e}");
        if k > 1 {
            // The average lags: it is not the trained weights.
            assert_ne!(
                common::bits(&got),
                common::bits(&common::weights_of(a.path(), &name(k), "train_model.bpk"))
            );
        }
    }
    // Stopped half-way and resumed: both files end as the uninterrupted run's.
    train::train(
        &cfg,
        &TrainOptions {
            stop_at: Some(4),
            ..opts(b.path())
        },
    )
    .unwrap();
    let s = train::train(&cfg, &opts(b.path())).unwrap();
    assert_eq!((s.start_step, s.step), (4, steps));
    for file in ["model.bpk", "train_model.bpk"] {
        assert_eq!(
            common::bits(&common::weights_of(a.path(), &name(steps), file)),
            common::bits(&common::weights_of(b.path(), &name(steps), file)),
            "{file}: resumed run differs"
        );
    }
    // Another decay on resume: refused, naming the key.
    let mut other = cfg.clone();
    other.train.ema = Some(0.9);
    other.train.steps = steps + 2;
    let err = train::train(&other, &opts(b.path())).unwrap_err();
    assert_eq!(err.exit_code(), 2);
    assert!(
        err.to_string()
            .contains("`train.ema` 0.5, the config asks 0.9"),
        "{err}"
    );
    // Without an average, no second weight file.
    let c = tempfile::tempdir().unwrap();
    train::train(&short_config(2, 1), &opts(c.path())).unwrap();
    assert!(
        !c.path()
            .join("checkpoints")
            .join(name(2))
            .join("train_model.bpk")
            .exists()
    );
    // A decay outside (0, 1) is a config error.
    let mut bad = cfg.clone();
    bad.train.ema = Some(1.0);
    let path = write_config(c.path(), &bad);
    let err = exit_2_stderr(&[
        path.to_str().unwrap(),
        "--run-dir",
        c.path().join("r").to_str().unwrap(),
    ]);
    assert!(
        err.contains("train.ema: the decay must be in (0, 1) (got 1)"),
        "{err}"
    );
}

#[test]
fn kill_9_mid_run_then_resume_matches_uninterrupted_binary_run() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let cfg = short_config(16, 1); // a checkpoint after every step: a kill lands in or near one
    let path = write_config(dir.path(), &cfg);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let out = train_bin(&[path.to_str().unwrap(), "--run-dir", a.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let mut child = Command::new(env!("CARGO_BIN_EXE_train"))
        .args([
            path.to_str().unwrap(),
            "--run-dir",
            b.to_str().unwrap(),
            "--quiet",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Wait for the first checkpoints, then kill -9 (SIGKILL) mid-run.
    let t0 = std::time::Instant::now();
    while train::checkpoint::list(&b).unwrap().len() < 3 && t0.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::thread::sleep(std::time::Duration::from_millis(37));
    child.kill().unwrap();
    child.wait().unwrap();
    let done = train::checkpoint::list(&b).unwrap().last().unwrap().0;
    eprintln!("killed after checkpoint {done}");
    let out = train_bin(&[
        path.to_str().unwrap(),
        "--run-dir",
        b.to_str().unwrap(),
        "--resume",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        common::bits(&common::final_weights(&a)),
        common::bits(&common::final_weights(&b))
    );
}

#[test]
fn bad_config_key_is_an_error_naming_key_and_file_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let good =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/tiny.toml"))
            .unwrap();
    for (typo, key) in [
        (good.replace("warmup_steps", "warmup_stpes"), "warmup_stpes"),
        (good.replace("feature_dim", "feature_dims"), "feature_dims"),
        (good.replace("[eval]", "[evall]"), "evall"),
    ] {
        let p = dir.path().join("typo.toml");
        std::fs::write(&p, typo).unwrap();
        let e = train::Config::load(&p).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains("typo.toml"), "{e}");
        let stderr = exit_2_stderr(&[p.to_str().unwrap()]);
        assert!(
            stderr.contains(key) && stderr.contains("typo.toml"),
            "{stderr}"
        );
    }
    let out = train_bin(&[dir.path().join("nope.toml").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    // `--steps 0` is refused like `steps = 0`, and a NaN in the file names its key.
    let p = dir.path().join("good.toml");
    std::fs::write(&p, &good).unwrap();
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--steps", "0"]);
    assert!(stderr.contains("--steps"), "{stderr}");
    let nan = good.replace("grad_clip = 1.0", "grad_clip = nan");
    assert_ne!(nan, good);
    std::fs::write(&p, nan).unwrap();
    let stderr = exit_2_stderr(&[p.to_str().unwrap()]);
    assert!(
        stderr.contains("good.toml") && stderr.contains("train.grad_clip: must be a finite number"),
        "{stderr}"
    );
}

#[test]
fn validate_without_a_checkpoint_exits_2_naming_the_directory() {
    let _g = serial();
    let run = tempfile::tempdir().unwrap();
    let config = write_config(run.path(), &common::tiny_config(dataset()));
    let stderr = exit_2_stderr(&[
        config.to_str().unwrap(),
        "--run-dir",
        run.path().to_str().unwrap(),
        "--validate",
    ]);
    assert!(stderr.contains("--validate: no checkpoint in"), "{stderr}");
    assert!(
        stderr.contains(&run.path().join("checkpoints").display().to_string()),
        "{stderr}"
    );
}

#[test]
fn missing_dataset_exits_2_naming_the_directory() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = common::tiny_config(&dir.path().join("no_such_dataset"));
    let p = write_config(dir.path(), &cfg);
    let run = dir.path().join("run");
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--run-dir", run.to_str().unwrap()]);
    assert!(
        stderr.contains("dataset missing") && stderr.contains("no_such_dataset"),
        "{stderr}"
    );
    // Generation of a task the simulator does not know is bad input too.
    cfg.data.generate = Some(generate_spec("t99"));
    let p = write_config(dir.path(), &cfg);
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--run-dir", run.to_str().unwrap()]);
    assert!(
        stderr.contains("data.generate") && stderr.contains("t99"),
        "{stderr}"
    );
}

/// Two 32² episodes of `task`, one of them held out, on one simulator thread.
fn generate_spec(task: &str) -> train::config::GenerateSpec {
    train::config::GenerateSpec {
        task: task.into(),
        episodes: 2,
        val: 1,
        seed: 0,
        image_size: 32,
        workers: None,
        plain_expert: false,
        hold_steps: None,
        branch_rule: Default::default(),
        exec_noise: 0.0,
    }
}

#[test]
fn missing_dataset_is_generated_through_the_simulator_then_trained_on() {
    let dir = tempfile::tempdir().unwrap();
    let data_dir = dir.path().join("t1");
    let mut cfg = common::tiny_config(&data_dir);
    cfg.data.generate = Some(generate_spec("t1"));
    let p = write_config(dir.path(), &cfg);
    let run = dir.path().join("run");
    let out = train_bin(&[
        p.to_str().unwrap(),
        "--run-dir",
        run.to_str().unwrap(),
        "--steps",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let index = data::DatasetIndex::load(&data_dir).unwrap();
    assert_eq!(index.episodes.len(), 2);
    assert_eq!(index.split(data::Split::Val).len(), 1);
    assert!(index.episodes.iter().all(|e| e.length > 20));
    assert!(index.vocab.len() > 2, "instruction words in the vocabulary");
    assert_eq!(metrics::read(&run.join("metrics.jsonl")).unwrap().len(), 3);
    // The same files as `sim generate` with the same arguments; a second call finds the index
    // and leaves them alone.
    let modified = |f: &str| {
        std::fs::metadata(data_dir.join(f))
            .unwrap()
            .modified()
            .unwrap()
    };
    let before = modified(&index.episodes[0].file);
    train::dataset::ensure_dataset(&cfg, false).unwrap();
    assert_eq!(modified(&index.episodes[0].file), before);
    // A generation killed half-way resumes: the index and one episode gone → only it is redone.
    std::fs::remove_file(data_dir.join(data::index::INDEX_FILE)).unwrap();
    std::fs::remove_file(data_dir.join(&index.episodes[1].file)).unwrap();
    train::dataset::ensure_dataset(&cfg, false).unwrap();
    assert_eq!(modified(&index.episodes[0].file), before);
    assert_eq!(data::DatasetIndex::load(&data_dir).unwrap(), index);
}

#[test]
fn corrupt_newest_checkpoint_is_skipped_by_resume_and_by_the_evaluator_alike() {
    let _g = serial();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let cfg = short_config(8, 4);
    train::train(&cfg, &opts(a.path())).unwrap();
    let stop = TrainOptions {
        stop_at: Some(8),
        ..opts(b.path())
    };
    train::train(&cfg, &stop).unwrap();
    let ck = b.path().join("checkpoints");
    for name in ["model.bpk", "optim.bpk", "state.json", "manifest.json"] {
        assert!(ck.join("step_000000008").join(name).is_file(), "{name}");
    }
    // 50 flipped bits in the newest weights.
    let w = ck.join("step_000000008/model.bpk");
    let mut bytes = std::fs::read(&w).unwrap();
    for k in 0..50 {
        let i = (k * 7919) % bytes.len();
        bytes[i] ^= 1 << (k % 8);
    }
    std::fs::write(&w, &bytes).unwrap();
    // The evaluator's reader and the trainer fall back to step 4, and say why.
    let run = model::RunDir::open(b.path()).unwrap();
    assert_eq!(run.step, 4);
    assert!(
        run.skipped[0].1.contains("sha256 mismatch"),
        "{:?}",
        run.skipped
    );
    // Asked for a step, the reader takes that checkpoint or fails: no silent fallback.
    let at4 = model::RunDir::open_at(b.path(), Some(4)).unwrap();
    assert_eq!(
        (at4.step, at4.checkpoint.clone()),
        (4, run.checkpoint.clone())
    );
    let e = model::RunDir::open_at(b.path(), Some(8)).unwrap_err();
    assert!(e.to_string().contains("sha256 mismatch"), "{e}");
    let e = model::RunDir::open_at(b.path(), Some(6)).unwrap_err();
    assert!(
        e.to_string()
            .contains("checkpoints: no complete checkpoint of step 6 (it holds steps 4, 8)"),
        "{e}"
    );
    let s = train::train(&cfg, &opts(b.path())).unwrap();
    assert_eq!((s.start_step, s.step), (4, 8));
    // Redoing steps 5..8 from step 4 gives the uninterrupted run's weights.
    assert_eq!(
        common::bits(&common::final_weights(a.path())),
        common::bits(&common::final_weights(b.path()))
    );
    // A step dir left empty by a kill is removed, not kept past pruning.
    std::fs::create_dir_all(ck.join("step_000000025")).unwrap();
    let s = train::train(&short_config(9, 4), &opts(b.path())).unwrap();
    assert_eq!((s.start_step, s.step), (8, 9));
    assert!(!ck.join("step_000000025").exists());
}

#[test]
fn incompatible_checkpoint_exits_2() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let cfg = short_config(2, 2);
    train::train(&cfg, &opts(&run)).unwrap();
    let mut other = cfg.clone();
    other.model.variant = "slotvla_h1".into();
    let e = train::train(&other, &opts(&run)).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(e.to_string().contains("slotvla_h1"), "{e}");
    let p = write_config(dir.path(), &other);
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--run-dir", run.to_str().unwrap()]);
    assert!(stderr.contains("incompatible checkpoint"), "{stderr}");
    // The episode sampler's options are the checkpoint's: changing any is refused, naming each
    // changed key.
    let mut pooled = cfg.clone();
    pooled.train.steps = 4;
    pooled.train.lane_pool = 3 * cfg.train.batch_size;
    let e = train::train(&pooled, &opts(&run)).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(
        e.to_string().contains(&format!(
            "its episode sampler was made with `train.lane_pool = 0` (the config: {})",
            3 * cfg.train.batch_size
        )),
        "{e}"
    );
    let mut changed = cfg.clone();
    changed.train.steps = 4;
    changed.train.stagger = true;
    changed.train.start_jitter = 5;
    changed.train.memory_reset = 0.25;
    let e = train::train(&changed, &opts(&run)).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(
        e.to_string().contains(
            "its episode sampler was made with `train.stagger = false` (the config: true), \
             `train.start_jitter = 0` (the config: 5), `train.memory_reset = 0` (the config: 0.25)"
        ),
        "{e}"
    );
    // The same options resume.
    let mut same = cfg.clone();
    same.train.steps = 3;
    assert_eq!(train::train(&same, &opts(&run)).unwrap().step, 3);
    // --resume with nothing to resume is bad input too.
    let empty = dir.path().join("empty");
    let out = train_bin(&[
        p.to_str().unwrap(),
        "--run-dir",
        empty.to_str().unwrap(),
        "--resume",
    ]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn state_mode_on_data_without_poses_and_oracle_without_goal_exit_2() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    // The synthetic plate has no pose: state mode names the first episode lacking one.
    let mut cfg = short_config(2, 2);
    cfg.model.obs = train::config::ObsMode::State;
    let p = write_config(dir.path(), &cfg);
    let run = dir.path().join("run");
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--run-dir", run.to_str().unwrap()]);
    assert!(
        stderr.contains("synth_000.mcap") && stderr.contains("object poses"),
        "{stderr}"
    );
    assert_eq!(
        stderr.lines().filter(|l| l.starts_with("error")).count(),
        1,
        "{stderr}"
    );
    // An oracle variant on episodes whose /goal records nothing (as data imported from RLDS).
    let stripped = dir.path().join("nogoal");
    let index = rewritten(&stripped, |step| {
        step.progress = data::GoalProgress::default()
    });
    let back = data::EpisodeReader::open(stripped.join(&index.episodes[0].file)).unwrap();
    assert_eq!(back.read_step(0).unwrap().progress.total, 0);
    let mut cfg = short_config(2, 2);
    cfg.data.dir = stripped.clone();
    cfg.model.variant = "e_slotssm_oracle".into();
    let e = train::train(&cfg, &opts(&dir.path().join("run2"))).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(
        e.to_string().contains("/goal") && e.to_string().contains("synth_000.mcap"),
        "{e}"
    );
    // The termination loss reads /goal too: the same error; on episodes with goals it trains
    // and logs L_done at every step.
    let mut done = short_config(2, 2);
    done.data.dir = stripped.clone();
    done.train.loss_weights.done = Some(0.5);
    let e = train::train(&done, &opts(&dir.path().join("run_done"))).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(e.to_string().contains("/goal"), "{e}");
    done.data.dir = dataset().to_path_buf();
    let run_done = dir.path().join("run_done2");
    train::train(&done, &opts(&run_done)).unwrap();
    let recs = metrics::read(&run_done.join("metrics.jsonl")).unwrap();
    assert_eq!(recs.len(), 2);
    assert!(
        recs.iter()
            .all(|r| r.done.is_some_and(|d| d.is_finite() && d > 0.0)),
        "{recs:?}"
    );
    // Articulated parts asked of episodes that record poses but no parts (schema 2, or scenes
    // without drawers and knobs): one error naming the dataset and the key.
    let posed = dir.path().join("posed");
    rewritten(&posed, |step| {
        for o in &mut step.objects {
            o.pose.get_or_insert([0.1, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0]);
        }
    });
    let mut cfg = short_config(2, 2);
    cfg.data.dir = posed.clone();
    cfg.model.obs = train::config::ObsMode::State;
    let mut parts = cfg.clone();
    parts.model.state_parts = true;
    let e = train::train(&parts, &opts(&dir.path().join("run3"))).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(
        e.to_string().contains("state_parts") && e.to_string().contains("posed"),
        "{e}"
    );
    assert!(!dir.path().join("run3").join("model.json").exists());
    // The same episodes train in state mode without parts.
    train::train(&cfg, &opts(&dir.path().join("run4"))).unwrap();
}

/// The test dataset copied to `to` with every step passed through `edit`, under a fresh index
/// (the files' sizes and CRCs change) with the same split; returns the original index.
fn rewritten(to: &std::path::Path, edit: impl Fn(&mut data::StepRecord)) -> data::DatasetIndex {
    std::fs::create_dir_all(to).unwrap();
    let index = data::DatasetIndex::load(dataset()).unwrap();
    for e in &index.episodes {
        let r = data::EpisodeReader::open(dataset().join(&e.file)).unwrap();
        let mut w = data::EpisodeWriter::create(
            to.join(&e.file),
            r.meta().clone(),
            data::WriterOptions::default(),
        )
        .unwrap();
        for t in 0..r.len() {
            let mut step = r.read_step(t).unwrap();
            edit(&mut step);
            w.write_step(&step).unwrap();
        }
        w.finish().unwrap();
    }
    let opts = data::IndexOptions {
        val_fraction: index.val_fraction,
        seed: index.split_seed,
    };
    data::build_index(to, &opts).unwrap();
    index
}

/// Bits of every float parameter inside the modules named `part` (anywhere in the model tree,
/// as a stage's `freeze` names them).
fn part_bits(model: &PolicyModel, part: &str) -> Vec<Vec<u32>> {
    struct Collect<'a> {
        part: &'a str,
        path: Vec<String>,
        bits: Vec<Vec<u32>>,
    }
    impl ModuleVisitor for Collect<'_> {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.into());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            if self
                .path
                .iter()
                .any(|n| train::stages::snake_case(n) == self.part)
            {
                let v = p.val().into_data().try_to_vec::<f32>().unwrap();
                self.bits.push(v.iter().map(|x| x.to_bits()).collect());
            }
        }
    }
    let mut c = Collect {
        part,
        path: vec![],
        bits: vec![],
    };
    model.visit(&mut c);
    assert!(!c.bits.is_empty(), "{part} has no parameters");
    c.bits
}

fn checkpoint_model(run_dir: &Path, step: u64) -> PolicyModel {
    let cfg: ModelConfig =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("model.json")).unwrap())
            .unwrap();
    let path = run_dir
        .join("checkpoints")
        .join(model::run::checkpoint_name(step))
        .join("model.bpk");
    PolicyModel::load(&cfg, path, &Device::flex()).unwrap()
}

#[test]
fn staged_training_trains_only_the_stage_parts_and_resumes_across_stages() {
    let _g = serial();
    let mut cfg = short_config(8, 1);
    let stages = r#"
[[stages]]
name = "slots"
steps = 4
losses = ["slot_recon", "contrastive", "window"]
freeze = ["encoder"]
[[stages]]
name = "all"
losses = ["action", "contrastive", "window", "slot_recon"]
"#;
    #[derive(serde::Deserialize)]
    struct S {
        stages: Vec<train::config::Stage>,
    }
    cfg.train.stages = toml::from_str::<S>(stages).unwrap().stages;
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    train::train(&cfg, &opts(a.path())).unwrap();

    // Checkpoints after steps 1 and 4 (both in stage 1; the initial weights are not at hand:
    // Burn initialises parameters lazily, in the order of first use), and after step 8.
    let (s1, s4, s8) = (
        checkpoint_model(a.path(), 1),
        checkpoint_model(a.path(), 4),
        checkpoint_model(a.path(), 8),
    );
    let same =
        |x: &PolicyModel, y: &PolicyModel, part: &str| part_bits(x, part) == part_bits(y, part);
    // Stage 1: the frozen encoder and the action decoder (no action loss) keep their weights
    // bit for bit (AdamW's weight decay alone would move them); the slot side learns.
    for part in ["encoder", "decoder"] {
        assert!(same(&s1, &s4, part), "{part} moved in stage 1");
    }
    for part in ["slot_attention", "slot_ssm", "slot_decoder"] {
        assert!(!same(&s1, &s4, part), "{part} did not learn in stage 1");
    }
    // Stage 2 trains everything.
    for part in ["encoder", "decoder", "slot_attention"] {
        assert!(!same(&s4, &s8, part), "{part} did not learn in stage 2");
    }
    let recs = metrics::read(&a.path().join("metrics.jsonl")).unwrap();
    let names: Vec<&str> = recs.iter().map(|r| r.stage.as_deref().unwrap()).collect();
    assert_eq!(
        names,
        ["slots"; 4]
            .into_iter()
            .chain(["all"; 4])
            .collect::<Vec<_>>()
    );

    // Stopped inside stage 1, resumed: the same weights as the uninterrupted run.
    let stop = TrainOptions {
        stop_at: Some(3),
        ..opts(b.path())
    };
    train::train(&cfg, &stop).unwrap();
    let s = train::train(&cfg, &opts(b.path())).unwrap();
    assert_eq!((s.start_step, s.step), (3, 8));
    assert_eq!(
        common::bits(&common::final_weights(a.path())),
        common::bits(&common::final_weights(b.path()))
    );
}

#[test]
fn backend_not_compiled_in_or_unknown_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_config(dir.path(), &common::tiny_config(dataset()));
    let run = dir.path().join("run");
    let mut missing = vec![];
    if cfg!(not(feature = "ndarray")) {
        missing.push("ndarray");
    }
    if cfg!(not(feature = "wgpu")) {
        missing.push("wgpu");
    }
    for b in missing {
        let stderr = exit_2_stderr(&[
            p.to_str().unwrap(),
            "--run-dir",
            run.to_str().unwrap(),
            "--backend",
            b,
        ]);
        assert!(
            stderr.contains(&format!("--features train/{b}")),
            "{stderr}"
        );
    }
    let stderr = exit_2_stderr(&[p.to_str().unwrap(), "--backend", "cuda"]);
    assert!(stderr.contains("cuda"), "{stderr}");
    assert!(!run.exists(), "nothing written before the backend check");
}
