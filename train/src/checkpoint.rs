//! Checkpoints in `RUN/checkpoints/step_<N>/`, written atomically: every file goes into a
//! temporary directory that is fsynced and then renamed to its final name, and the `latest`
//! pointer (a one-line file, itself replaced by rename) is written last. A run killed at any
//! moment leaves either no new checkpoint or a complete one; stray temporaries are removed at
//! the next start, and a pointer to a missing or broken checkpoint falls back to the newest
//! complete one.
//!
//! Each checkpoint holds `model.bpk` (weights, burnpack), `optim.bpk` (AdamW moments, burnpack),
//! `state.json` ([`TrainState`]: step, sampler, RNG seed, the resolved model config) and
//! `config.toml` (the resolved experiment config).

use std::fs;
use std::path::{Path, PathBuf};

use burn::optim::ModuleOptimizer;
use burn::prelude::*;
use model::{ModelConfig, PolicyModel};
use serde::{Deserialize, Serialize};

use crate::dataset::Sampler;
use crate::error::{Result, TrainError};

/// Format tag of `state.json`.
pub const STATE_FORMAT: &str = "libero-mem-rs/train-state/1";
/// Directory of the checkpoints inside a run directory.
pub const CHECKPOINTS: &str = "checkpoints";
/// The pointer file naming the newest checkpoint.
pub const LATEST: &str = "latest";

/// Everything besides weights and optimiser moments that a resumed run needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// [`STATE_FORMAT`].
    pub format: String,
    /// Optimiser steps done (the scheduler's state: the learning rate is a function of it).
    pub step: u64,
    /// Data sampler position.
    pub sampler: Sampler,
    /// Seed of Burn's RNG; the trainer re-seeds it with `rng_seed ^ step` right after writing
    /// a checkpoint and when resuming from one, so both runs see the same random stream.
    pub rng_seed: u64,
    /// Training seconds so far.
    pub elapsed_s: f64,
    /// The model this checkpoint belongs to (variant, sizes, vocabulary).
    pub model: ModelConfig,
}

/// Name of the checkpoint directory of `step`.
pub fn dir_name(step: u64) -> String {
    format!("step_{step:09}")
}

fn step_of(name: &str) -> Option<u64> {
    name.strip_prefix("step_")?.parse().ok()
}

fn sync_dir(dir: &Path) {
    // Best effort: directories cannot be fsynced on every platform.
    if let Ok(f) = fs::File::open(dir) {
        let _ = f.sync_all();
    }
}

fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut f = fs::File::create(path).map_err(|e| TrainError::io(path, e))?;
    f.write_all(bytes).map_err(|e| TrainError::io(path, e))?;
    f.sync_all().map_err(|e| TrainError::io(path, e))
}

fn sync_file(path: &Path) -> Result<()> {
    fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| TrainError::io(path, e))
}

/// Writes a checkpoint of `step` atomically, then points `latest` at it; returns its directory.
pub fn save(
    run_dir: &Path,
    model: &PolicyModel,
    optim: &ModuleOptimizer,
    state: &TrainState,
    config_toml: &str,
) -> Result<PathBuf> {
    let root = run_dir.join(CHECKPOINTS);
    fs::create_dir_all(&root).map_err(|e| TrainError::io(&root, e))?;
    let tmp = tempfile::Builder::new()
        .prefix(".tmp-")
        .tempdir_in(&root)
        .map_err(|e| TrainError::io(&root, e))?;
    let t = tmp.path();
    model.save(t.join("model.bpk"))?;
    sync_file(&t.join("model.bpk"))?;
    optim
        .save(t.join("optim.bpk"))
        .map_err(|e| TrainError::Other(format!("{}: {e}", t.join("optim.bpk").display())))?;
    sync_file(&t.join("optim.bpk"))?;
    let json = serde_json::to_string_pretty(state).expect("state serialises");
    write_synced(&t.join("state.json"), json.as_bytes())?;
    write_synced(&t.join("config.toml"), config_toml.as_bytes())?;
    sync_dir(t);
    let final_dir = root.join(dir_name(state.step));
    if final_dir.exists() {
        fs::remove_dir_all(&final_dir).map_err(|e| TrainError::io(&final_dir, e))?;
    }
    let t = tmp.keep();
    fs::rename(&t, &final_dir).map_err(|e| TrainError::io(&final_dir, e))?;
    sync_dir(&root);
    data::index::write_atomic(&root.join(LATEST), dir_name(state.step).as_bytes())?;
    sync_dir(&root);
    Ok(final_dir)
}

/// Complete checkpoints of a run, oldest first.
pub fn list(run_dir: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let root = run_dir.join(CHECKPOINTS);
    if !root.is_dir() {
        return Ok(vec![]);
    }
    let mut v = vec![];
    for e in fs::read_dir(&root).map_err(|e| TrainError::io(&root, e))? {
        let e = e.map_err(|e| TrainError::io(&root, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(step) = step_of(&name)
            && e.path().join("state.json").is_file()
        {
            v.push((step, e.path()));
        }
    }
    v.sort();
    Ok(v)
}

/// Removes temporaries that a killed run left behind.
pub fn clean_temporaries(run_dir: &Path) -> Result<()> {
    let root = run_dir.join(CHECKPOINTS);
    if !root.is_dir() {
        return Ok(());
    }
    for e in fs::read_dir(&root).map_err(|e| TrainError::io(&root, e))? {
        let e = e.map_err(|e| TrainError::io(&root, e))?;
        if e.file_name().to_string_lossy().starts_with(".tmp-") {
            let p = e.path();
            let r = if p.is_dir() {
                fs::remove_dir_all(&p)
            } else {
                fs::remove_file(&p)
            };
            r.map_err(|e| TrainError::io(&p, e))?;
        }
    }
    Ok(())
}

/// Candidate checkpoints to resume from, best first: the one `latest` names, then the others,
/// newest first.
pub fn candidates(run_dir: &Path) -> Result<Vec<PathBuf>> {
    let mut all: Vec<PathBuf> = list(run_dir)?.into_iter().rev().map(|x| x.1).collect();
    let root = run_dir.join(CHECKPOINTS);
    if let Ok(name) = fs::read_to_string(root.join(LATEST)) {
        let p = root.join(name.trim());
        if let Some(i) = all.iter().position(|x| *x == p) {
            let p = all.remove(i);
            all.insert(0, p);
        }
    }
    Ok(all)
}

/// Reads `state.json` of a checkpoint.
pub fn read_state(dir: &Path) -> Result<TrainState> {
    let p = dir.join("state.json");
    let text = fs::read_to_string(&p).map_err(|e| TrainError::io(&p, e))?;
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

/// What differs between the model of a checkpoint and the one being trained.
pub fn model_difference(saved: &ModelConfig, want: &ModelConfig) -> Option<String> {
    if saved == want {
        return None;
    }
    if saved.variant != want.variant {
        return Some(format!(
            "it holds a `{}` model, the config asks for `{}`",
            saved.variant.name(),
            want.variant.name()
        ));
    }
    let (a, b) = (
        serde_json::to_value(saved).expect("serialises"),
        serde_json::to_value(want).expect("serialises"),
    );
    let mut keys = vec![];
    if let (Some(a), Some(b)) = (a.as_object(), b.as_object()) {
        for (k, v) in a {
            if b.get(k) != Some(v) {
                keys.push(k.clone());
            }
        }
    }
    Some(format!(
        "its model config differs in: {} (other sizes, loss weights or dataset vocabulary)",
        keys.join(", ")
    ))
}

/// A loaded checkpoint.
pub struct Loaded {
    /// Its directory.
    pub dir: PathBuf,
    /// Its state.
    pub state: TrainState,
    /// The weights.
    pub model: PolicyModel,
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
    let model = PolicyModel::load(want, dir.join("model.bpk"), device)
        .map_err(|e| incompatible(e.to_string()))?;
    let optim = optim
        .load(dir.join("optim.bpk"))
        .map_err(|e| incompatible(format!("optim.bpk: {e}")))?;
    Ok(Loaded {
        dir: dir.to_path_buf(),
        state,
        model,
        optim,
    })
}

/// Deletes all but the newest `keep` checkpoints (0 = keep all); never the one `latest` names.
pub fn prune(run_dir: &Path, keep: usize) -> Result<Vec<PathBuf>> {
    if keep == 0 {
        return Ok(vec![]);
    }
    let all = list(run_dir)?;
    let latest = candidates(run_dir)?.into_iter().next();
    let mut removed = vec![];
    if all.len() > keep {
        for (_, p) in &all[..all.len() - keep] {
            if Some(p) == latest.as_ref() {
                continue;
            }
            fs::remove_dir_all(p).map_err(|e| TrainError::io(p, e))?;
            removed.push(p.clone());
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fake(run: &Path, step: u64) {
        let d = run.join(CHECKPOINTS).join(dir_name(step));
        fs::create_dir_all(&d).unwrap();
        fs::write(d.join("state.json"), "{}").unwrap();
    }

    #[test]
    fn latest_first_then_newest_and_prune_keeps_the_newest() {
        let run = tempfile::tempdir().unwrap();
        let run = run.path();
        assert!(candidates(run).unwrap().is_empty());
        for s in [10, 20, 30] {
            fake(run, s);
        }
        // Incomplete: no state.json (never renamed into place by `save`, but be safe).
        fs::create_dir_all(run.join(CHECKPOINTS).join(dir_name(40))).unwrap();
        fs::create_dir_all(run.join(CHECKPOINTS).join(".tmp-x")).unwrap();
        let names = |v: Vec<PathBuf>| -> Vec<String> {
            v.iter()
                .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(
            names(candidates(run).unwrap()),
            ["step_000000030", "step_000000020", "step_000000010"]
        );
        fs::write(run.join(CHECKPOINTS).join(LATEST), "step_000000020\n").unwrap();
        assert_eq!(names(candidates(run).unwrap())[0], "step_000000020");
        clean_temporaries(run).unwrap();
        assert!(!run.join(CHECKPOINTS).join(".tmp-x").exists());
        // keep 1: the newest stays, and so does the one `latest` names.
        prune(run, 1).unwrap();
        let left: Vec<u64> = list(run).unwrap().iter().map(|x| x.0).collect();
        assert_eq!(left, vec![20, 30]);
        assert!(read_state(&run.join(CHECKPOINTS).join(dir_name(30))).is_err());
    }
}
