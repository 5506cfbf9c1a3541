//! The trainer's side of a checkpoint. Layout, atomic writing, the `latest` pointer, listing,
//! pruning and the policy's part of `state.json` belong to the run contract in [`model::run`];
//! here each checkpoint gains `optim.bpk` (AdamW moments, burnpack), the trainer's fields of
//! `state.json` ([`TrainState`]: sampler position, RNG seed, time) and `config.toml` (the
//! resolved experiment config).

use std::path::{Path, PathBuf};

use burn::optim::ModuleOptimizer;
use burn::prelude::*;
use model::run;
use model::{ModelConfig, PolicyModel};
use serde::{Deserialize, Serialize};

use crate::dataset::{EpisodeSampler, Sampler};
use crate::error::{Result, TrainError};

pub use model::run::{
    CHECKPOINTS, LATEST, candidates, clean_temporaries, list, model_difference, prune,
};

/// Format tag of `state.json`.
pub const STATE_FORMAT: &str = "libero-mem-rs/train-state/1";
/// The optimiser moments of a checkpoint.
pub const OPTIM: &str = "optim.bpk";
/// The memory carried into the next batch (episode sampling).
pub const CARRY: &str = "carry.json";
/// The trained weights of a run with a weight average (`[train] ema`), whose `model.bpk` is
/// the average.
pub const TRAIN_WEIGHTS: &str = "train_model.bpk";

/// Everything besides weights and optimiser moments that a resumed run needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// [`STATE_FORMAT`].
    pub format: String,
    /// Optimiser steps done (the scheduler's state: the learning rate is a function of it).
    pub step: u64,
    /// Data sampler position (`sampling = "windows"`).
    pub sampler: Sampler,
    /// Episode lanes (`sampling = "episodes"`); the carried memory is in `carry.json`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub episodes: Option<EpisodeSampler>,
    /// Seed of Burn's RNG; the trainer re-seeds it with `rng_seed ^ step` right after writing
    /// a checkpoint and when resuming from one, so both runs see the same random stream.
    pub rng_seed: u64,
    /// Training seconds so far.
    pub elapsed_s: f64,
    /// The model this checkpoint belongs to (variant, sizes, vocabulary).
    pub model: ModelConfig,
    /// The weight average's decay (`[train] ema`); with one, `model.bpk` is the average and the
    /// trained weights are [`TRAIN_WEIGHTS`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ema: Option<f64>,
}

/// Writes a checkpoint of `step` atomically (see [`model::run::save_checkpoint`]), then points
/// `latest` at it; returns its directory. With a weight average `ema`, the average is the
/// checkpoint's policy (`model.bpk`) and `model` goes beside it as [`TRAIN_WEIGHTS`].
#[allow(clippy::too_many_arguments)]
pub fn save(
    run_dir: &Path,
    model: &PolicyModel,
    ema: Option<&PolicyModel>,
    optim: &ModuleOptimizer,
    state: &TrainState,
    carry: &model::Carry,
    config_toml: &str,
) -> Result<PathBuf> {
    Ok(run::save_checkpoint(
        run_dir,
        state.step,
        ema.unwrap_or(model),
        state,
        |t| {
            if ema.is_some() {
                model.save(t.join(TRAIN_WEIGHTS))?;
                run::sync_file(&t.join(TRAIN_WEIGHTS))?;
            }
            if !carry.is_empty() {
                let json = serde_json::to_string(&carry.to_record()).expect("carry serialises");
                run::write_synced(&t.join(CARRY), json.as_bytes())?;
            }
            optim
                .save(t.join(OPTIM))
                .map_err(|e| model::ModelError::run(t.join(OPTIM), e.to_string()))?;
            run::sync_file(&t.join(OPTIM))?;
            run::write_synced(&t.join("config.toml"), config_toml.as_bytes())
        },
    )?)
}

/// Reads `state.json` of a checkpoint.
pub fn read_state(dir: &Path) -> Result<TrainState> {
    let p = dir.join(run::STATE_JSON);
    let text = std::fs::read_to_string(&p).map_err(|e| TrainError::io(&p, e))?;
    let state: TrainState =
        serde_json::from_str(&text).map_err(|e| TrainError::IncompatibleCheckpoint {
            path: dir.to_path_buf(),
            message: format!("state.json: {e}"),
        })?;
    if state.format != STATE_FORMAT {
        return Err(TrainError::IncompatibleCheckpoint {
            path: dir.to_path_buf(),
            message: format!("format `{}`, expected `{STATE_FORMAT}`", state.format),
        });
    }
    Ok(state)
}

/// The carried memory saved with a checkpoint (empty when it has none).
pub fn read_carry(dir: &Path, device: &Device) -> Result<model::Carry> {
    let p = dir.join(CARRY);
    if !p.is_file() {
        return Ok(model::Carry::default());
    }
    let incompatible = |message: String| TrainError::IncompatibleCheckpoint {
        path: dir.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(&p).map_err(|e| TrainError::io(&p, e))?;
    let rec: model::variants::CarryRecord =
        serde_json::from_str(&text).map_err(|e| incompatible(format!("{CARRY}: {e}")))?;
    model::Carry::from_record(&rec, device).map_err(|e| incompatible(format!("{CARRY}: {e}")))
}

/// A loaded checkpoint.
pub struct Loaded {
    /// Its directory.
    pub dir: PathBuf,
    /// Its state.
    pub state: TrainState,
    /// The trained weights.
    pub model: PolicyModel,
    /// The weight average, where the checkpoint has one (without autodiff).
    pub ema: Option<PolicyModel>,
    /// The optimiser with its moments.
    pub optim: ModuleOptimizer,
}

/// Loads one checkpoint for a model of `want` on `device`; a checkpoint of another model is
/// [`TrainError::IncompatibleCheckpoint`].
pub fn load(
    dir: &Path,
    want: &ModelConfig,
    optim: ModuleOptimizer,
    device: &Device,
) -> Result<Loaded> {
    let state = read_state(dir)?;
    if let Some(diff) = model_difference(&state.model, want) {
        return Err(TrainError::IncompatibleCheckpoint {
            path: dir.to_path_buf(),
            message: diff,
        });
    }
    let incompatible = |message: String| TrainError::IncompatibleCheckpoint {
        path: dir.to_path_buf(),
        message,
    };
    let weights = |file: &str| {
        PolicyModel::load(want, dir.join(file), device).map_err(|e| incompatible(e.to_string()))
    };
    // With a weight average, `model.bpk` is the average and the trained weights lie beside it.
    let (model, ema) = match state.ema {
        Some(_) => (
            weights(TRAIN_WEIGHTS)?,
            Some(crate::ema::start(&weights(run::WEIGHTS)?)),
        ),
        None => (weights(run::WEIGHTS)?, None),
    };
    let optim = optim
        .load(dir.join(OPTIM))
        .map_err(|e| incompatible(format!("optim.bpk: {e}")))?;
    Ok(Loaded {
        dir: dir.to_path_buf(),
        state,
        model,
        ema,
        optim,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_of_another_format_is_incompatible() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(run::STATE_JSON), "{}").unwrap();
        let e = read_state(dir.path()).unwrap_err();
        assert!(
            matches!(e, TrainError::IncompatibleCheckpoint { .. }),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2);
    }
}
