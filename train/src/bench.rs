//! `train CONFIG --bench N`: the real trainer's speed on a config, and where its time goes.
//!
//! Two measurements on the config's dataset and model:
//! 1. **the trainer**: `warmup + N` steps of [`crate::train`] into a throw-away run directory
//!    (no checkpoints until the end, no validation on the way), timed from its own per-step
//!    metrics: median ms per step and its parts (waiting for data, forward with the losses,
//!    backward, clip + AdamW);
//! 2. **the loader alone**: batches drawn, read, augmented and batched as the loader thread
//!    makes them, with nothing else running: windows per second, against the windows per second
//!    the trainer consumes.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::dataset::ensure_dataset;
use crate::error::{Result, TrainError};
use crate::loader::{self, Draw};
use crate::trainer::{TrainOptions, open_data};

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Timed optimiser steps (after the warm-up).
    pub steps: u64,
    /// Untimed steps first.
    pub warmup: u64,
    /// Batches the loader makes alone.
    pub loader_batches: usize,
}

/// The figures of one benchmark run (milliseconds are medians over the timed steps).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    /// The config's run name.
    pub name: String,
    /// Model variant.
    pub variant: String,
    /// Windows (or lanes) per batch.
    pub batch_size: usize,
    /// Frames per window.
    pub window: usize,
    /// Model parameters.
    pub params: usize,
    /// Threads of the pool that runs the tensor kernels and the loader.
    pub threads: usize,
    /// Timed steps.
    pub steps: u64,
    /// Whole step (wall time between consecutive steps).
    pub step_ms: f64,
    /// Waiting for the batch.
    pub data_ms: f64,
    /// Forward and losses.
    pub forward_ms: f64,
    /// Backward.
    pub backward_ms: f64,
    /// Clip and optimiser step.
    pub optim_ms: f64,
    /// Optimiser steps per second (1000 / step_ms).
    pub steps_per_s: f64,
    /// Windows per second the trainer consumes (batch_size · steps_per_s).
    pub trainer_windows_per_s: f64,
    /// Windows per second the loader makes alone.
    pub loader_windows_per_s: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Measures `cfg` (see the module docs); `progress` shows the dataset generation's bar when the
/// dataset is missing and the config can generate it.
pub fn run(cfg: &Config, opts: &BenchOptions, progress: bool) -> Result<BenchReport> {
    if opts.steps == 0 {
        return Err(TrainError::Usage("--bench needs at least 1 step".into()));
    }
    ensure_dataset(cfg, progress)?;
    let mut cfg = cfg.clone();
    cfg.train.steps = opts.warmup + opts.steps;
    cfg.train.checkpoint_every = 0;
    cfg.train.val_every = 0;
    cfg.train.val_batches = 1;
    cfg.train.keep = 1;
    let window = cfg.window_len();
    let batch_size = cfg.train.batch_size;

    // The loader alone, on the trainer's device, before the trainer runs.
    let (mcfg, data) = open_data(&cfg)?;
    let device = model::backend::device(cfg.backend.kind)?.autodiff();
    let params = {
        use burn::module::Module;
        model::PolicyModel::new(&mcfg, &device)?.num_params()
    };
    let mut draw = Draw::new(&cfg.train, &data);
    let batches = opts.loader_batches.max(1);
    let started = Instant::now();
    for _ in 0..batches {
        let key = draw.next(&data, batch_size, window);
        loader::prepare(&data, key, true, 1, &device)?;
    }
    let loader_windows_per_s = (batches * batch_size) as f64 / started.elapsed().as_secs_f64();
    drop(data);

    let dir = tempfile::tempdir().map_err(|e| TrainError::io(std::env::temp_dir(), e))?;
    let train_opts = TrainOptions {
        run_dir: Some(dir.path().to_path_buf()),
        ..Default::default()
    };
    crate::train(&cfg, &train_opts)?;
    let records = crate::metrics::read(&dir.path().join("metrics.jsonl"))?;
    let timed: Vec<_> = records
        .windows(2)
        .filter(|w| w[1].step > opts.warmup)
        .collect();
    let ms = |f: &dyn Fn(&crate::metrics::Record) -> f64| {
        median(timed.iter().map(|w| f(&w[1]) * 1e3).collect())
    };
    let step_ms = median(
        timed
            .iter()
            .map(|w| (w[1].time_s - w[0].time_s) * 1e3)
            .collect(),
    );
    let steps_per_s = if step_ms > 0.0 { 1e3 / step_ms } else { 0.0 };
    Ok(BenchReport {
        name: cfg.run_name(),
        variant: cfg.model.variant.clone(),
        batch_size,
        window,
        params,
        threads: rayon::current_num_threads(),
        steps: timed.len() as u64,
        step_ms,
        data_ms: ms(&|r| r.data_s),
        forward_ms: ms(&|r| r.forward_s),
        backward_ms: ms(&|r| r.backward_s),
        optim_ms: ms(&|r| r.optim_s),
        steps_per_s,
        trainer_windows_per_s: batch_size as f64 * steps_per_s,
        loader_windows_per_s,
    })
}

impl BenchReport {
    /// The report as a small Markdown table.
    pub fn to_markdown(&self) -> String {
        format!(
            "| {} ({}, {} parameters, B={}, T={}, {} threads) | ms |\n|---|---:|\n\
             | step | {:.1} |\n| waiting for data | {:.1} |\n| forward + losses | {:.1} |\n\
             | backward | {:.1} |\n| clip + AdamW | {:.1} |\n\n\
             {:.3} steps/s; the trainer consumes {:.1} windows/s, the loader alone makes {:.1} \
             ({:.1}×)\n",
            self.name,
            self.variant,
            self.params,
            self.batch_size,
            self.window,
            self.threads,
            self.step_ms,
            self.data_ms,
            self.forward_ms,
            self.backward_ms,
            self.optim_ms,
            self.steps_per_s,
            self.trainer_windows_per_s,
            self.loader_windows_per_s,
            self.loader_windows_per_s / self.trainer_windows_per_s.max(f64::MIN_POSITIVE)
        )
    }
}
