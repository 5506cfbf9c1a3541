//! A training run opened for evaluation: the run contract of [`model::run`] (no dependency on
//! the trainer), with its errors as [`EvalError`]s.

use std::path::Path;

use burn::prelude::Device;
pub use model::run::RunDir;

use crate::error::EvalError;
use crate::policy::ModelPolicy;

impl From<model::ModelError> for EvalError {
    fn from(e: model::ModelError) -> Self {
        match e {
            model::ModelError::Run { path, message } => EvalError::Run { path, message },
            model::ModelError::BackendUnavailable { .. } => EvalError::Argument(e.to_string()),
            other => EvalError::Model(other.to_string()),
        }
    }
}

/// Opens `dir` as [`RunDir::open`] does (the newest checkpoint that verifies, the trainer's rule)
/// and says on stderr which checkpoint it uses and which newer ones it skipped, and why.
pub fn open(dir: impl AsRef<Path>) -> Result<RunDir, EvalError> {
    open_at(dir, None)
}

/// [`open`] at the checkpoint of `step` when given (`eval --checkpoint STEP`; an error naming
/// the steps the run holds when it has no such checkpoint).
pub fn open_at(dir: impl AsRef<Path>, step: Option<u64>) -> Result<RunDir, EvalError> {
    let t = std::time::Instant::now();
    let run = RunDir::open_at(dir, step)?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    for (skipped, why) in &run.skipped {
        eprintln!(
            "warning: skipping corrupt checkpoint {}: {why}",
            skipped.display()
        );
    }
    let note = match run.verified {
        model::run::Verified::Manifest => "verified against its manifest",
        model::run::Verified::NoManifest => "no manifest (written before manifests): not verified",
    };
    eprintln!(
        "checkpoint {} (step {}): {note} (run opened in {ms:.1} ms)",
        run.checkpoint.display(),
        run.step
    );
    Ok(run)
}

/// The device a run evaluates on: `backend` when given (`--backend`), else the backend it was
/// trained on; an error when this binary lacks it.
pub fn device(
    run: &RunDir,
    backend: Option<model::backend::BackendKind>,
) -> Result<Device, EvalError> {
    Ok(model::backend::device(backend.unwrap_or(run.info.backend))?)
}

/// A fresh streaming policy of `run` on `device`.
pub fn policy(run: &RunDir, device: &Device) -> Result<ModelPolicy, EvalError> {
    ModelPolicy::new(run.load_model(device)?, run.processor.clone(), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_run_is_a_clear_error_with_exit_code_2() {
        let e = open("/nonexistent/run").unwrap_err();
        assert!(e.to_string().contains("no such run directory"), "{e}");
        assert_eq!(e.exit_code(), 2);
    }
}
