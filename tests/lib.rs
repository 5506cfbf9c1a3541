//! Helpers of the end-to-end tests (generate → train → eval), which live in `e2e.rs`.

use std::path::{Path, PathBuf};

/// The repository root (the workspace this crate sits in).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Where the end-to-end test leaves its evaluation table for CI to print
/// (`$CARGO_TARGET_DIR/e2e/results.md`, else `target/e2e/results.md` in the workspace).
pub fn report_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(t) => PathBuf::from(t).join("e2e"),
        None => repo_root().join("target/e2e"),
    }
}

/// `configs/tiny.toml` with its dataset directory set to `data_dir`, generation off, and `steps`
/// optimiser steps (checkpointing and validation every `steps`).
pub fn tiny_config(data_dir: &Path, steps: u64) -> train::Config {
    let path = repo_root().join("configs/tiny.toml");
    let mut cfg = train::Config::load(&path).expect("configs/tiny.toml loads");
    cfg.data.dir = data_dir.to_path_buf();
    cfg.data.generate = None;
    cfg.train.steps = steps;
    cfg.train.warmup_steps = cfg.train.warmup_steps.min(steps / 4);
    cfg.train.checkpoint_every = steps;
    cfg.train.val_every = steps;
    cfg
}
