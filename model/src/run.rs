//! The run directory, a policy's contract (LeRobot's `from_pretrained` idea): what a trainer
//! leaves and what an evaluator (or any other user of the policy) needs, read and written here
//! only.
//!
//! ```text
//! runs/<name>/
//!   run.json            RunInfo: format, backend, tasks to evaluate by default
//!   model.json          ModelConfig (variant, sizes, vocabulary)
//!   processor.json      ProcessorConfig (frame size, text, action normalisation, subgoal input)
//!   action_stats.json   q01 / q99 / mask of the actions (the same numbers, for other tools)
//!   checkpoints/
//!     latest            one line: the name of the newest complete checkpoint
//!     step_<N>/         model.bpk (weights) and state.json ({ step, model, … }); trainers add
//!                       their own files (optimiser moments, sampler position, config);
//!                       manifest.json: the step and the size and sha256 of every other file
//! ```
//!
//! A checkpoint is trusted only once verified ([`verify_checkpoint`]): its manifest matches its
//! files byte for byte, and its directory, manifest and `state.json` name the same step. Readers
//! take the first verified one of [`candidates`] ([`newest_valid`]), the same rule in the trainer
//! (resume) and the evaluator, and report the ones they skipped.
//!
//! Checkpoints are written atomically: every file goes into a temporary directory that is synced
//! and renamed to its final name, and `latest` (itself replaced by rename) is written last. A run
//! killed at any moment leaves either no new checkpoint or a complete one; temporaries are removed
//! by [`clean_temporaries`], and a pointer to a missing checkpoint falls back to the newest one.

use std::fs;
use std::path::{Path, PathBuf};

use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use crate::backend::BackendKind;
use crate::config::ModelConfig;
use crate::error::{ModelError, Result};
use crate::io::{Processor, ProcessorConfig};
use crate::policy::PolicyModel;

/// `run.json`.
pub const RUN_JSON: &str = "run.json";
/// `model.json`.
pub const MODEL_JSON: &str = "model.json";
/// `processor.json`.
pub const PROCESSOR_JSON: &str = "processor.json";
/// `action_stats.json`.
pub const ACTION_STATS_JSON: &str = "action_stats.json";
/// Directory of the checkpoints inside a run directory.
pub const CHECKPOINTS: &str = "checkpoints";
/// The pointer file naming the newest checkpoint.
pub const LATEST: &str = "latest";
/// Weights of a checkpoint (burnpack).
pub const WEIGHTS: &str = "model.bpk";
/// The state file of a checkpoint; its presence marks a complete checkpoint.
pub const STATE_JSON: &str = "state.json";
/// Format tag of `run.json`.
pub const RUN_FORMAT: &str = "libero-mem-rs/run/1";
/// The manifest of a checkpoint: its step and the size and sha256 of every other file.
pub const MANIFEST: &str = "manifest.json";
/// Format tag of `manifest.json`.
pub const MANIFEST_FORMAT: &str = "libero-mem-rs/checkpoint-manifest/1";

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// The checkpoint's step.
    pub step: u64,
    /// Every other file of the checkpoint, by name: size and sha256.
    pub files: std::collections::BTreeMap<String, FileDigest>,
}

/// Size and sha256 (lowercase hex) of one file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileDigest {
    /// Bytes.
    pub bytes: u64,
    /// sha256, lowercase hex.
    pub sha256: String,
}

/// Size and sha256 of the file at `path` ([`data::fsio::sha256_file`]).
pub fn digest(path: &Path) -> Result<FileDigest> {
    let (bytes, sha256) = data::fsio::sha256_file(path).map_err(|e| match e {
        data::DataError::Io { source, .. } => io_error(path, source),
        other => ModelError::run(path, other.to_string()),
    })?;
    Ok(FileDigest { bytes, sha256 })
}

/// The manifest of the files now in checkpoint directory `dir` (all but the manifest itself).
fn manifest_of(dir: &Path, step: u64) -> Result<Manifest> {
    let mut files = std::collections::BTreeMap::new();
    for e in fs::read_dir(dir).map_err(|e| io_error(dir, e))? {
        let e = e.map_err(|e| io_error(dir, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name != MANIFEST && e.path().is_file() {
            files.insert(name, digest(&e.path())?);
        }
    }
    Ok(Manifest {
        format: MANIFEST_FORMAT.into(),
        step,
        files,
    })
}

/// How far a checkpoint could be verified.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verified {
    /// Its manifest matches every file.
    Manifest,
    /// Written before manifests existed: only its `state.json` and step could be checked.
    NoManifest,
}

/// Verifies checkpoint `dir` and returns the policy part of its `state.json`: the manifest
/// (when there is one) matches every file's size and sha256 and lists every file, and the
/// directory name, the manifest and `state.json` agree on the step. Any mismatch is an error
/// naming the file.
pub fn verify_checkpoint(dir: &Path) -> Result<(CheckpointInfo, Verified)> {
    let info = read_checkpoint(dir)?;
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned());
    if let Some(step) = name.as_deref().and_then(step_of)
        && step != info.step
    {
        return Err(ModelError::run(
            dir.join(STATE_JSON),
            format!("says step {}, its directory step {step}", info.step),
        ));
    }
    let path = dir.join(MANIFEST);
    if !path.exists() {
        return Ok((info, Verified::NoManifest));
    }
    let manifest: Manifest = read_json(&path, "checkpoint manifest")?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(ModelError::run(
            &path,
            format!("format `{}`, expected `{MANIFEST_FORMAT}`", manifest.format),
        ));
    }
    if manifest.step != info.step {
        return Err(ModelError::run(
            &path,
            format!("says step {}, state.json step {}", manifest.step, info.step),
        ));
    }
    let now = manifest_of(dir, info.step)?;
    for (name, want) in &manifest.files {
        match now.files.get(name) {
            None => {
                return Err(ModelError::run(
                    dir.join(name),
                    "missing (listed in manifest.json)",
                ));
            }
            Some(got) if got.bytes != want.bytes => {
                return Err(ModelError::run(
                    dir.join(name),
                    format!("{} bytes, manifest.json says {}", got.bytes, want.bytes),
                ));
            }
            Some(got) if got.sha256 != want.sha256 => {
                return Err(ModelError::run(
                    dir.join(name),
                    "content differs from manifest.json (sha256 mismatch): the file is corrupt",
                ));
            }
            Some(_) => {}
        }
    }
    if let Some(extra) = now.files.keys().find(|k| !manifest.files.contains_key(*k)) {
        return Err(ModelError::run(
            dir.join(extra),
            "not listed in manifest.json",
        ));
    }
    Ok((info, Verified::Manifest))
}

/// The checkpoint a reader uses, and the ones it skipped on the way.
#[derive(Clone, Debug)]
pub struct Chosen {
    /// Its directory.
    pub dir: PathBuf,
    /// The policy part of its `state.json`.
    pub info: CheckpointInfo,
    /// Whether a manifest vouched for it.
    pub verified: Verified,
    /// Newer checkpoints that failed verification, with the reason.
    pub skipped: Vec<(PathBuf, String)>,
}

/// The first checkpoint of [`candidates`] that verifies ([`verify_checkpoint`]). None when the
/// run has no complete checkpoint; an error (the newest one's) when none verifies.
pub fn newest_valid(run_dir: &Path) -> Result<Option<Chosen>> {
    let mut skipped = vec![];
    let mut first_err = None;
    for dir in candidates(run_dir)? {
        match verify_checkpoint(&dir) {
            Ok((info, verified)) => {
                return Ok(Some(Chosen {
                    dir,
                    info,
                    verified,
                    skipped,
                }));
            }
            Err(e) => {
                skipped.push((dir, e.to_string()));
                first_err.get_or_insert(e);
            }
        }
    }
    match first_err {
        Some(e) => Err(e),
        None => Ok(None),
    }
}

/// The checkpoint of `step` (it must be complete and verify): for evaluating a run's earlier
/// checkpoints. An error naming the checkpoints folder and the steps it holds when there is none.
pub fn at_step(run_dir: &Path, step: u64) -> Result<Chosen> {
    let all = list(run_dir)?;
    let Some((_, dir)) = all.iter().find(|(s, _)| *s == step) else {
        let have: Vec<String> = all.iter().map(|(s, _)| s.to_string()).collect();
        return Err(ModelError::run(
            run_dir.join(CHECKPOINTS),
            format!(
                "no complete checkpoint of step {step} (it holds {})",
                if have.is_empty() {
                    "none".to_string()
                } else {
                    format!("steps {}", have.join(", "))
                }
            ),
        ));
    };
    let (info, verified) = verify_checkpoint(dir)?;
    Ok(Chosen {
        dir: dir.clone(),
        info,
        verified,
        skipped: vec![],
    })
}

/// `run.json`: what a run is besides its model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunInfo {
    /// [`RUN_FORMAT`].
    pub format: String,
    /// The backend it was trained on (the evaluator's default).
    pub backend: BackendKind,
    /// Task ids or aliases to evaluate by default (empty: the evaluator's default suite).
    pub eval_tasks: Vec<String>,
}

impl RunInfo {
    /// A run trained on `backend`, evaluated on `eval_tasks` by default.
    pub fn new(backend: BackendKind, eval_tasks: Vec<String>) -> Self {
        RunInfo {
            format: RUN_FORMAT.into(),
            backend,
            eval_tasks,
        }
    }
}

/// The part of a checkpoint's `state.json` that belongs to the policy (trainers write more
/// fields beside these; they are ignored here).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointInfo {
    /// Optimiser steps done.
    pub step: u64,
    /// The model whose weights the checkpoint holds.
    pub model: ModelConfig,
}

fn io_error(path: &Path, e: std::io::Error) -> ModelError {
    ModelError::run(path, e.to_string())
}

fn write(path: &Path, text: &str) -> Result<()> {
    data::index::write_atomic(path, text.as_bytes())
        .map_err(|e| ModelError::run(path, e.to_string()))
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = fs::read_to_string(path)
        .map_err(|e| ModelError::run(path, format!("cannot read it: {e}")))?;
    serde_json::from_str(&text)
        .map_err(|e| ModelError::run(path, format!("not a valid {what}: {e}")))
}

/// Writes the policy's description into `dir` (each file atomically): `run.json`, `model.json`,
/// `processor.json` and `action_stats.json`.
pub fn write_policy(
    dir: &Path,
    info: &RunInfo,
    model: &ModelConfig,
    processor: &Processor,
) -> Result<()> {
    processor.check_model(model)?;
    fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    write(&dir.join(RUN_JSON), &pretty(info))?;
    write(&dir.join(MODEL_JSON), &pretty(model))?;
    write(&dir.join(PROCESSOR_JSON), &pretty(processor.config()))?;
    let a = processor.action_norm();
    write(
        &dir.join(ACTION_STATS_JSON),
        &serde_json::json!({"q01": a.q01, "q99": a.q99, "mask": a.mask}).to_string(),
    )
}

fn pretty<T: Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).expect("run files serialise")
}

/// Name of the checkpoint directory of `step`.
pub fn checkpoint_name(step: u64) -> String {
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

/// Syncs a file to disk.
pub fn sync_file(path: &Path) -> Result<()> {
    fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| io_error(path, e))
}

/// Writes `bytes` to `path` and syncs it (inside a checkpoint's temporary directory).
pub fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut f = fs::File::create(path).map_err(|e| io_error(path, e))?;
    f.write_all(bytes).map_err(|e| io_error(path, e))?;
    f.sync_all().map_err(|e| io_error(path, e))
}

/// Writes the checkpoint of `step` atomically: the weights, `state.json` (`state` must
/// serialise to an object holding at least [`CheckpointInfo`]'s fields) and whatever `extra`
/// writes into the temporary directory; then points `latest` at it. Returns its directory.
pub fn save_checkpoint(
    run_dir: &Path,
    step: u64,
    model: &PolicyModel,
    state: &impl Serialize,
    extra: impl FnOnce(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let root = run_dir.join(CHECKPOINTS);
    fs::create_dir_all(&root).map_err(|e| io_error(&root, e))?;
    let tmp = tempfile::Builder::new()
        .prefix(".tmp-")
        .tempdir_in(&root)
        .map_err(|e| io_error(&root, e))?;
    let t = tmp.path();
    model.save(t.join(WEIGHTS))?;
    sync_file(&t.join(WEIGHTS))?;
    extra(t)?;
    let json = serde_json::to_string_pretty(state).expect("checkpoint state serialises");
    let info: CheckpointInfo = serde_json::from_str(&json)
        .map_err(|e| ModelError::Config(format!("checkpoint state lacks step/model: {e}")))?;
    if info.step != step || info.model != model.config {
        return Err(ModelError::Config(
            "checkpoint state names another step or model than it is saved with".into(),
        ));
    }
    write_synced(&t.join(STATE_JSON), json.as_bytes())?;
    let manifest = manifest_of(t, step)?;
    write_synced(&t.join(MANIFEST), pretty(&manifest).as_bytes())?;
    sync_dir(t);
    let final_dir = root.join(checkpoint_name(step));
    if final_dir.exists() {
        fs::remove_dir_all(&final_dir).map_err(|e| io_error(&final_dir, e))?;
    }
    let t = tmp.keep();
    fs::rename(&t, &final_dir).map_err(|e| io_error(&final_dir, e))?;
    sync_dir(&root);
    write(&root.join(LATEST), &checkpoint_name(step))?;
    sync_dir(&root);
    Ok(final_dir)
}

/// Complete checkpoints of a run (those with a `state.json`), oldest first.
pub fn list(run_dir: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let root = run_dir.join(CHECKPOINTS);
    if !root.is_dir() {
        return Ok(vec![]);
    }
    let mut v = vec![];
    for e in fs::read_dir(&root).map_err(|e| io_error(&root, e))? {
        let e = e.map_err(|e| io_error(&root, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(step) = step_of(&name)
            && e.path().join(STATE_JSON).is_file()
        {
            v.push((step, e.path()));
        }
    }
    v.sort();
    Ok(v)
}

/// Removes what a killed run left behind: temporary directories (`.tmp-*`) and step
/// directories without a `state.json` (a checkpoint being replaced when the run died).
pub fn clean_temporaries(run_dir: &Path) -> Result<()> {
    let root = run_dir.join(CHECKPOINTS);
    if !root.is_dir() {
        return Ok(());
    }
    for e in fs::read_dir(&root).map_err(|e| io_error(&root, e))? {
        let e = e.map_err(|e| io_error(&root, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        let incomplete = step_of(&name).is_some() && !e.path().join(STATE_JSON).is_file();
        if name.starts_with(".tmp-") || incomplete {
            let p = e.path();
            let r = if p.is_dir() {
                fs::remove_dir_all(&p)
            } else {
                fs::remove_file(&p)
            };
            r.map_err(|e| io_error(&p, e))?;
        }
    }
    Ok(())
}

/// Complete checkpoints, best first: the one `latest` names, then the others, newest first.
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
            fs::remove_dir_all(p).map_err(|e| io_error(p, e))?;
            removed.push(p.clone());
        }
    }
    Ok(removed)
}

/// The policy part of a checkpoint's `state.json`.
pub fn read_checkpoint(dir: &Path) -> Result<CheckpointInfo> {
    read_json(&dir.join(STATE_JSON), "checkpoint state")
}

/// What differs between the model of a checkpoint and the one asked for (None: the same).
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

/// A run directory opened for use: its description and newest complete checkpoint.
#[derive(Clone, Debug)]
pub struct RunDir {
    /// The run directory.
    pub dir: PathBuf,
    /// `run.json`.
    pub info: RunInfo,
    /// `model.json`.
    pub model: ModelConfig,
    /// `processor.json`, built.
    pub processor: Processor,
    /// The checkpoint used: the first of [`candidates`] that verifies ([`newest_valid`]).
    pub checkpoint: PathBuf,
    /// Optimiser steps of that checkpoint.
    pub step: u64,
    /// Whether a manifest vouched for the checkpoint's files.
    pub verified: Verified,
    /// Newer checkpoints that failed verification, with the reason.
    pub skipped: Vec<(PathBuf, String)>,
}

impl RunDir {
    /// Opens `dir`, checking that its files agree with each other and with the checkpoint.
    pub fn open(dir: impl AsRef<Path>) -> Result<RunDir> {
        RunDir::open_at(dir, None)
    }

    /// Opens `dir` as [`RunDir::open`] does, at the checkpoint of `step` when given ([`at_step`])
    /// instead of the newest one that verifies.
    pub fn open_at(dir: impl AsRef<Path>, step: Option<u64>) -> Result<RunDir> {
        let dir = dir.as_ref();
        if !dir.is_dir() {
            return Err(ModelError::run(
                dir,
                "no such run directory (train one with `cargo run -p train -- CONFIG`)",
            ));
        }
        let info: RunInfo = read_json(&dir.join(RUN_JSON), "run description")?;
        if info.format != RUN_FORMAT {
            return Err(ModelError::run(
                dir.join(RUN_JSON),
                format!("format `{}`, expected `{RUN_FORMAT}`", info.format),
            ));
        }
        let model_path = dir.join(MODEL_JSON);
        let model: ModelConfig = read_json(&model_path, "model config")?;
        let proc_path = dir.join(PROCESSOR_JSON);
        let processor =
            Processor::from_config(read_json::<ProcessorConfig>(&proc_path, "processor")?)
                .and_then(|p| p.check_model(&model).map(|_| p))
                .map_err(|e| ModelError::run(&proc_path, e.to_string()))?;
        let chosen = match step {
            Some(step) => at_step(dir, step)?,
            None => newest_valid(dir)?.ok_or_else(|| {
                ModelError::run(
                    dir.join(CHECKPOINTS),
                    "no complete checkpoint (has the run trained past its first checkpoint?)",
                )
            })?,
        };
        let (checkpoint, state) = (chosen.dir, chosen.info);
        if let Some(diff) = model_difference(&state.model, &model) {
            return Err(ModelError::run(
                &checkpoint,
                format!("does not match {}: {diff}", model_path.display()),
            ));
        }
        Ok(RunDir {
            dir: dir.to_path_buf(),
            info,
            model,
            processor,
            step: state.step,
            checkpoint,
            verified: chosen.verified,
            skipped: chosen.skipped,
        })
    }

    /// Loads the checkpoint's weights on `device`.
    pub fn load_model(&self, device: &Device) -> Result<PolicyModel> {
        PolicyModel::load(&self.model, self.checkpoint.join(WEIGHTS), device)
            .map_err(|e| ModelError::run(&self.checkpoint, e.to_string()))
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

    fn fake(run: &Path, step: u64) {
        let d = run.join(CHECKPOINTS).join(checkpoint_name(step));
        fs::create_dir_all(&d).unwrap();
        fs::write(d.join(STATE_JSON), "{}").unwrap();
    }

    #[test]
    fn latest_first_then_newest_and_prune_keeps_the_newest() {
        let run = tempfile::tempdir().unwrap();
        let run = run.path();
        assert!(candidates(run).unwrap().is_empty());
        for s in [10, 20, 30] {
            fake(run, s);
        }
        // Incomplete: no state.json (left when a run dies while replacing a checkpoint).
        fs::create_dir_all(run.join(CHECKPOINTS).join(checkpoint_name(40))).unwrap();
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
        assert!(!run.join(CHECKPOINTS).join(checkpoint_name(40)).exists());
        // keep 1: the newest stays, and so does the one `latest` names.
        prune(run, 1).unwrap();
        let left: Vec<u64> = list(run).unwrap().iter().map(|x| x.0).collect();
        assert_eq!(left, vec![20, 30]);
        assert!(read_checkpoint(&run.join(CHECKPOINTS).join(checkpoint_name(30))).is_err());
    }

    /// A checkpoint of `step` with a real state.json, fake weights and its manifest.
    fn fake_with_manifest(run: &Path, step: u64) -> PathBuf {
        let d = run.join(CHECKPOINTS).join(checkpoint_name(step));
        fs::create_dir_all(&d).unwrap();
        let info = CheckpointInfo {
            step,
            model: ModelConfig::tiny(crate::config::Variant::Dense { history: 1 }),
        };
        fs::write(d.join(STATE_JSON), pretty(&info)).unwrap();
        fs::write(d.join(WEIGHTS), vec![7u8; 5000]).unwrap();
        let m = manifest_of(&d, step).unwrap();
        fs::write(d.join(MANIFEST), pretty(&m)).unwrap();
        d
    }

    #[test]
    fn manifests_catch_corrupt_files_and_readers_fall_back_to_the_newest_valid() {
        let tmp = tempfile::tempdir().unwrap();
        let run = tmp.path();
        let old = fake_with_manifest(run, 10);
        let new = fake_with_manifest(run, 20);
        let (info, v) = verify_checkpoint(&new).unwrap();
        assert_eq!((info.step, v), (20, Verified::Manifest));
        let m: Manifest = read_json(&new.join(MANIFEST), "m").unwrap();
        assert_eq!(m.files[WEIGHTS].bytes, 5000);
        assert_eq!(m.files[WEIGHTS].sha256.len(), 64);
        let err = |d: &Path| verify_checkpoint(d).unwrap_err().to_string();

        // One flipped bit in the weights.
        let mut w = fs::read(new.join(WEIGHTS)).unwrap();
        w[1234] ^= 0x10;
        fs::write(new.join(WEIGHTS), &w).unwrap();
        assert!(
            err(&new).contains("model.bpk: content differs from manifest.json (sha256 mismatch)")
        );
        // Truncated weights.
        fs::write(new.join(WEIGHTS), &w[..100]).unwrap();
        assert!(err(&new).contains("model.bpk: 100 bytes, manifest.json says 5000"));
        // The newest is skipped with its reason, the older one is used.
        let chosen = newest_valid(run).unwrap().unwrap();
        assert_eq!((chosen.dir.clone(), chosen.info.step), (old.clone(), 10));
        assert_eq!(chosen.skipped.len(), 1);
        assert!(
            chosen.skipped[0].1.contains("model.bpk: 100 bytes"),
            "{:?}",
            chosen.skipped
        );

        // state.json claiming another step: caught by its directory name and by the manifest.
        let state = fs::read_to_string(old.join(STATE_JSON)).unwrap();
        fs::write(
            old.join(STATE_JSON),
            state.replace("\"step\": 10", "\"step\": 999999"),
        )
        .unwrap();
        assert!(
            err(&old).contains("says step 999999, its directory step 10"),
            "{}",
            err(&old)
        );
        // Every candidate bad: the newest one's error.
        let e = newest_valid(run).unwrap_err().to_string();
        assert!(
            e.contains("step_000000020") && e.contains("model.bpk"),
            "{e}"
        );

        // A file the manifest does not list, and a listed file gone.
        let d = fake_with_manifest(run, 30);
        fs::write(d.join("extra.bin"), b"x").unwrap();
        assert!(err(&d).contains("extra.bin: not listed in manifest.json"));
        fs::remove_file(d.join("extra.bin")).unwrap();
        fs::remove_file(d.join(WEIGHTS)).unwrap();
        assert!(err(&d).contains("model.bpk: missing (listed in manifest.json)"));
        // Written before manifests: accepted as such, flagged.
        let d = fake_with_manifest(run, 40);
        fs::remove_file(d.join(MANIFEST)).unwrap();
        assert_eq!(verify_checkpoint(&d).unwrap().1, Verified::NoManifest);
    }

    #[test]
    fn missing_run_and_missing_files_are_clear_errors() {
        let e = RunDir::open("/nonexistent/run").unwrap_err();
        assert!(e.to_string().contains("no such run directory"), "{e}");
        let run = tempfile::tempdir().unwrap();
        let e = RunDir::open(run.path()).unwrap_err();
        assert!(e.to_string().contains("run.json: cannot read it"), "{e}");
        fs::write(run.path().join(RUN_JSON), "{").unwrap();
        let e = RunDir::open(run.path()).unwrap_err();
        assert!(
            e.to_string()
                .contains("run.json: not a valid run description"),
            "{e}"
        );
    }
}
