//! Per-step metrics as JSON lines (`RUN/metrics.jsonl`, validation in `RUN/val.jsonl`).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, TrainError};

/// One line of `metrics.jsonl` (training) or `val.jsonl` (validation; lr/grad_norm are 0).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Optimiser steps done when measured (1-based for training lines).
    pub step: u64,
    /// Learning rate of this step.
    #[serde(default)]
    pub lr: f64,
    /// λ-weighted total loss.
    pub loss: f64,
    /// L_act.
    pub action: f64,
    /// L_tc (slot variants).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrastive: Option<f64>,
    /// L_win (e_slotssm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<f64>,
    /// L_sa (slot variants with λ_sa > 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slot_recon: Option<f64>,
    /// L_ptr (with the pointer head and λ_ptr > 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pointer: Option<f64>,
    /// L_prog (with λ_prog > 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub progress: Option<f64>,
    /// L_done (with λ_done > 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub done: Option<f64>,
    /// Global gradient norm before clipping.
    #[serde(default)]
    pub grad_norm: f64,
    /// Seconds since the run started (cumulative over resumes).
    #[serde(default)]
    pub time_s: f64,
    /// Seconds this step waited for its batch (read, augmented and batched on the loader
    /// thread ahead of the step; in the loop with `--no-prefetch`).
    #[serde(default)]
    pub data_s: f64,
    /// Seconds of the forward pass and the losses.
    #[serde(default)]
    pub forward_s: f64,
    /// Seconds of the backward pass.
    #[serde(default)]
    pub backward_s: f64,
    /// Seconds of the gradient clip and the optimiser step.
    #[serde(default)]
    pub optim_s: f64,
    /// Name of the training stage (staged training only; `loss` is then that stage's total).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage: Option<String>,
}

impl Record {
    /// The loss terms present, by name (`loss` first).
    pub fn terms(&self) -> Vec<(&'static str, f64)> {
        let mut v = vec![("loss", self.loss), ("action", self.action)];
        for (n, x) in [
            ("contrastive", self.contrastive),
            ("window", self.window),
            ("slot_recon", self.slot_recon),
            ("pointer", self.pointer),
            ("progress", self.progress),
            ("done", self.done),
        ] {
            if let Some(x) = x {
                v.push((n, x));
            }
        }
        v
    }
}

/// Appends records to a JSONL file.
pub struct JsonlWriter {
    path: PathBuf,
    file: fs::File,
}

impl JsonlWriter {
    /// Opens `path` for appending, first dropping lines with `step > keep_up_to` (what a run
    /// wrote after its last checkpoint before it was killed).
    pub fn open(path: &Path, keep_up_to: u64) -> Result<Self> {
        let kept: Vec<Record> = read(path)?
            .into_iter()
            .filter(|r| r.step <= keep_up_to)
            .collect();
        let mut text = String::new();
        for r in &kept {
            text.push_str(&serde_json::to_string(r).expect("serialises"));
            text.push('\n');
        }
        data::index::write_atomic(path, text.as_bytes())?;
        let file = fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| TrainError::io(path, e))?;
        Ok(JsonlWriter {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one record.
    pub fn write(&mut self, r: &Record) -> Result<()> {
        let mut line = serde_json::to_string(r).expect("serialises");
        line.push('\n');
        self.file
            .write_all(line.as_bytes())
            .map_err(|e| TrainError::io(&self.path, e))
    }
}

/// Reads a JSONL metrics file (missing file = empty; a torn last line is skipped).
pub fn read(path: &Path) -> Result<Vec<Record>> {
    let text = match fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(vec![]),
        Err(e) => return Err(TrainError::io(path, e)),
    };
    Ok(text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect())
}
