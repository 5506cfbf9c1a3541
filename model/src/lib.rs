//! Embodied-SlotSSM and its baselines (SlotVLA(h), dense patches) in Burn, with a parallel
//! training forward over windows and a constant-memory streaming policy.
//!
//! Layout follows `../shared/spec/model.md`: [`encoder`] (§1), [`slot_attention`] (§2),
//! [`losses`] (§3, §5, §8), [`mamba`] and [`slot_ssm`] (§4), [`heads`] (§5 windowed head,
//! §6 slot fusion, the L_sa decoder), [`relation`] (§7), [`text`] and [`decoder`] (§8),
//! [`variants`] and [`policy`] (§9, the variants as types and the shared window forward) and
//! [`streaming`] (§10).
//! Model code has no backend parameter: the backend is chosen at run time by the
//! [`burn::prelude::Device`] (flex or ndarray on CPU; wgpu with this crate's `wgpu` feature).
//!
//! Training (one window batch):
//! ```text
//! let cfg = ModelConfig::tiny(Variant::from_name("e_slotssm")?).with_vocab_from(instructions);
//! let device = Device::flex().autodiff();
//! let model = PolicyModel::new(&cfg, &device)?;
//! let (out, losses) = model.forward(&WindowBatch { images, actions, frame_mask, .. })?;
//! let grads = losses.total.backward();           // λ-weighted sum of the terms
//! ```
//! Inputs are prepared by one [`io::Processor`] for training (`Processor::batch` over `data`'s
//! window samples) and evaluation (`Processor::step` per observation); [`run`] reads and writes
//! the run directory (model, processor, checkpoints) that both share.
//!
//! Evaluation (per environment step):
//! ```text
//! let run = RunDir::open("runs/t3")?;
//! let mut policy = StreamingPolicy::new(run.load_model(&device)?, &device)?;
//! policy.reset();
//! let input = run.processor.step(&StepObservation { agentview, state, instruction, goal }, &device)?;
//! let chunk = policy.act_input(input)?;                  // [H_a][7], normalised
//! let action = run.processor.unnormalize(chunk[0]);
//! ```

#![warn(missing_docs)]

pub mod backend;
pub mod blocks;
pub mod config;
pub mod decoder;
pub mod encoder;
pub mod error;
pub mod heads;
pub mod io;
pub mod losses;
pub mod mamba;
pub mod matching;
pub mod policy;
pub mod relation;
pub mod run;
pub mod slot_attention;
pub mod slot_ssm;
pub mod streaming;
pub mod text;
pub mod variants;

pub use config::{ModelConfig, Observation, Variant};
pub use encoder::Frames;
pub use error::{ModelError, Result};
pub use io::{Processor, StepInput, StepObservation, Tokenizer};
pub use policy::{Carry, Losses, PolicyModel, WindowBatch, WindowOutput};
pub use run::RunDir;
pub use streaming::StreamingPolicy;
pub use variants::Subgoal;

/// The CPU device of the unit tests (flex, pure Rust), seeded with 0.
///
/// Burn's RNG may be global, and the test harness runs tests on several threads: the returned
/// guard holds a process-wide lock until the test ends, so that a seed really fixes every
/// random draw of that test (same seed → same result).
#[cfg(test)]
pub(crate) fn test_device() -> (std::sync::MutexGuard<'static, ()>, burn::prelude::Device) {
    seeded(burn::prelude::Device::flex())
}

/// [`test_device`] with autodiff.
#[cfg(test)]
pub(crate) fn test_autodiff_device() -> (std::sync::MutexGuard<'static, ()>, burn::prelude::Device)
{
    seeded(burn::prelude::Device::flex().autodiff())
}

#[cfg(test)]
fn seeded(
    device: burn::prelude::Device,
) -> (std::sync::MutexGuard<'static, ()>, burn::prelude::Device) {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    device.seed(0);
    (guard, device)
}
