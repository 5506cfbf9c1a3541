//! A training run directory as `train` leaves it (`config.toml`, `model.json`,
//! `action_stats.json`, `checkpoints/`), opened for evaluation.

use std::path::{Path, PathBuf};

use burn::prelude::Device;
use model::{ActionStats, ModelConfig, PolicyModel};

use crate::EvalError;
use crate::policy::ModelPolicy;

/// A run directory with its newest complete checkpoint.
#[derive(Clone, Debug)]
pub struct RunDir {
    /// The run directory.
    pub dir: PathBuf,
    /// Its resolved experiment config.
    pub config: train::Config,
    /// The model it trains (`model.json`).
    pub model: ModelConfig,
    /// Action statistics of its training data (`action_stats.json`).
    pub stats: ActionStats,
    /// The checkpoint evaluated (the one `latest` names, else the newest complete one).
    pub checkpoint: PathBuf,
    /// Optimiser steps of that checkpoint.
    pub step: u64,
}

fn run_error(path: &Path, message: impl Into<String>) -> EvalError {
    EvalError::Run {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn read(path: &Path) -> Result<String, EvalError> {
    std::fs::read_to_string(path).map_err(|e| run_error(path, format!("cannot read it: {e}")))
}

#[derive(serde::Deserialize)]
struct StatsFile {
    q01: Vec<f32>,
    q99: Vec<f32>,
}

/// Parses `action_stats.json` (7 first and 99th percentiles).
pub fn parse_stats(path: &Path, text: &str) -> Result<ActionStats, EvalError> {
    let s: StatsFile =
        serde_json::from_str(text).map_err(|e| run_error(path, format!("not valid: {e}")))?;
    let arr = |v: Vec<f32>, name: &str| -> Result<[f32; 7], EvalError> {
        <[f32; 7]>::try_from(v.as_slice())
            .map_err(|_| run_error(path, format!("`{name}` has {} values, expected 7", v.len())))
    };
    Ok(ActionStats {
        q01: arr(s.q01, "q01")?,
        q99: arr(s.q99, "q99")?,
    })
}

impl RunDir {
    /// Opens `dir`: its config, model, statistics and newest checkpoint, checking that the
    /// checkpoint holds the model `model.json` describes.
    pub fn open(dir: impl AsRef<Path>) -> Result<RunDir, EvalError> {
        let dir = dir.as_ref();
        if !dir.is_dir() {
            return Err(run_error(
                dir,
                "no such run directory (train one with `cargo run -p train -- CONFIG`)",
            ));
        }
        let config = train::Config::load(dir.join("config.toml"))
            .map_err(|e| run_error(&dir.join("config.toml"), e.to_string()))?;
        let model_path = dir.join("model.json");
        let model: ModelConfig = serde_json::from_str(&read(&model_path)?)
            .map_err(|e| run_error(&model_path, format!("not a model config: {e}")))?;
        let stats_path = dir.join("action_stats.json");
        let stats = parse_stats(&stats_path, &read(&stats_path)?)?;
        let checkpoint = train::checkpoint::candidates(dir)
            .map_err(|e| run_error(dir, e.to_string()))?
            .into_iter()
            .next()
            .ok_or_else(|| {
                run_error(
                    &dir.join(train::checkpoint::CHECKPOINTS),
                    "no complete checkpoint (has the run trained past its first checkpoint?)",
                )
            })?;
        let state = train::checkpoint::read_state(&checkpoint)
            .map_err(|e| run_error(&checkpoint, e.to_string()))?;
        if let Some(diff) = train::checkpoint::model_difference(&state.model, &model) {
            return Err(run_error(
                &checkpoint,
                format!("does not match {}: {diff}", model_path.display()),
            ));
        }
        Ok(RunDir {
            dir: dir.to_path_buf(),
            config,
            model,
            stats,
            step: state.step,
            checkpoint,
        })
    }

    /// Loads the checkpoint's weights on `device`.
    pub fn load_model(&self, device: &Device) -> Result<PolicyModel, EvalError> {
        PolicyModel::load(&self.model, self.checkpoint.join("model.bpk"), device)
            .map_err(|e| run_error(&self.checkpoint, e.to_string()))
    }

    /// A fresh streaming policy of this run on `device`.
    pub fn policy(&self, device: &Device) -> Result<ModelPolicy, EvalError> {
        ModelPolicy::new(self.load_model(device)?, self.stats.clone(), device)
    }

    /// The run's name (its directory's last component).
    pub fn name(&self) -> String {
        self.dir.file_name().map_or_else(
            || self.dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_need_seven_values() {
        let p = Path::new("runs/x/action_stats.json");
        let ok = parse_stats(
            p,
            r#"{"q01":[0,0,0,0,0,0,-1],"q99":[1,1,1,1,1,1,1],"mask":[]}"#,
        );
        assert_eq!(ok.unwrap().q99, [1.0; 7]);
        let e = parse_stats(p, r#"{"q01":[0,0],"q99":[1,1,1,1,1,1,1]}"#).unwrap_err();
        assert!(e.to_string().contains("`q01` has 2 values"), "{e}");
        assert!(e.to_string().contains("action_stats.json"), "{e}");
    }

    #[test]
    fn missing_run_and_missing_checkpoint_are_clear_errors() {
        let e = RunDir::open("/nonexistent/run").unwrap_err();
        assert!(e.to_string().contains("no such run directory"), "{e}");
        assert_eq!(e.exit_code(), 2);
    }
}
