//! Embodied-SlotSSM and its baselines (SlotVLA(h), dense patches) in Burn, with a parallel
//! training forward over windows and a constant-memory streaming policy.
//!
//! Layout follows `../shared/spec/model.md`: [`encoder`] (§1), [`slot_attention`] (§2),
//! [`losses`] (§3, §5, §8), [`mamba`] and [`slot_ssm`] (§4), [`heads`] (§5 windowed head,
//! §6 slot fusion, L_sa decoder), [`relation`] (§7), [`text`] and [`decoder`] (§8),
//! [`policy`] (§9, the variants and the window forward) and [`streaming`] (§10).
//! The backend is chosen at run time by the [`burn::prelude::Device`].

pub mod blocks;
pub mod config;
pub mod decoder;
pub mod encoder;
pub mod error;
pub mod heads;
pub mod losses;
pub mod mamba;
pub mod policy;
pub mod relation;
pub mod slot_attention;
pub mod slot_ssm;
pub mod text;

pub use config::{ModelConfig, Variant};
pub use error::{ModelError, Result};

/// The CPU device used by the unit tests (flex, pure Rust), seeded.
#[cfg(test)]
pub(crate) fn test_device() -> burn::prelude::Device {
    let device = burn::prelude::Device::flex();
    device.seed(0);
    device
}
