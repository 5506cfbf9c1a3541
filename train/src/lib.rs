//! Trainer of the LIBERO-Mem policies: an experiment config (TOML) → a training run in
//! `runs/<name>/` with the resolved `config.toml`, `model.json` and `action_stats.json` (what
//! eval needs), atomic resumable checkpoints, per-step metrics (`metrics.jsonl`, `val.jsonl`)
//! and loss-curve plots (`plots/loss_<term>.png`).
//!
//! ```no_run
//! let cfg = train::Config::load("configs/tiny.toml")?;
//! let summary = train::train(&cfg, &train::TrainOptions { progress: true, ..Default::default() })?;
//! println!("{} steps, {:.2} steps/s", summary.step, summary.steps_per_s);
//! # Ok::<(), train::TrainError>(())
//! ```

#![warn(missing_docs)]

pub mod backend;
pub mod checkpoint;
pub mod clip;
pub mod config;
pub mod dataset;
pub mod error;
pub mod metrics;
pub mod plot;
pub mod schedule;
pub mod stages;
pub mod trainer;

pub use config::{BackendKind, Config};
pub use error::{Result, TrainError};
pub use trainer::{TrainOptions, TrainSummary, plot_run, train};
