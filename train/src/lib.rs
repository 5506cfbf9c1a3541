//! Trainer of the LIBERO-Mem policies: an experiment config (TOML) → a training run in
//! `runs/<name>/`: the policy's files as `model::run` defines them (`run.json`, `model.json`,
//! `processor.json`, `action_stats.json`, atomic checkpoints — what eval reads), plus the
//! resolved `config.toml`, the optimiser and sampler state in each checkpoint (resumable),
//! per-step metrics (`metrics.jsonl`, `val.jsonl`) and loss-curve plots (`plots/loss_<term>.png`).
//!
//! The cargo feature `generate` (default) lets `[data].generate` record a missing dataset
//! through the simulator; without it the crate builds and trains with no simulator (no
//! libmujoco), on datasets recorded with `sim generate`.
//!
//! ```no_run
//! let cfg = train::Config::load("configs/tiny.toml")?;
//! let summary = train::train(&cfg, &train::TrainOptions { progress: true, ..Default::default() })?;
//! println!("{} steps, {:.2} steps/s", summary.step, summary.steps_per_s);
//! # Ok::<(), train::TrainError>(())
//! ```

#![warn(missing_docs)]

pub mod bench;
pub mod checkpoint;
pub mod clip;
pub mod config;
pub mod dataset;
pub mod ema;
pub mod error;
pub mod loader;
pub mod metrics;
pub mod parallel;
pub mod plot;
pub mod schedule;
pub mod stages;
pub mod trainer;

pub use config::{BackendKind, Config};
pub use error::{Result, TrainError};
pub use trainer::{TrainOptions, TrainSummary, open_data, plot_run, train};
