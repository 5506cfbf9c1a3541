//! The Burn device of a run, chosen at run time (`[backend]` of a training config, `run.json` of
//! a run directory, or `--backend`).

use std::str::FromStr;

use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};

/// Which Burn device trains or evaluates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// Burn's pure-Rust CPU backend (always compiled in; the default).
    #[default]
    Flex,
    /// burn-ndarray (cargo feature `ndarray`; deprecated upstream).
    Ndarray,
    /// wgpu (cargo feature `wgpu`).
    Wgpu,
    /// CUDA, the first GPU (cargo feature `cuda`).
    Cuda,
}

impl FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "flex" => Ok(BackendKind::Flex),
            "ndarray" => Ok(BackendKind::Ndarray),
            "wgpu" => Ok(BackendKind::Wgpu),
            "cuda" => Ok(BackendKind::Cuda),
            _ => Err(format!(
                "unknown backend `{s}` (expected flex, ndarray, wgpu or cuda)"
            )),
        }
    }
}

/// The plain (inference) device of `kind`; train on `device(kind)?.autodiff()`.
///
/// flex is always available; ndarray and wgpu need the cargo features of the same name, and
/// asking for one that was not compiled in is an error naming the feature.
pub fn device(kind: BackendKind) -> Result<Device> {
    match kind {
        BackendKind::Flex => Ok(Device::flex()),
        BackendKind::Ndarray => ndarray(),
        BackendKind::Wgpu => wgpu(),
        BackendKind::Cuda => cuda(),
    }
}

#[cfg(feature = "ndarray")]
#[allow(deprecated)] // our users ask for it; Burn 0.22 deprecates it in favour of flex
fn ndarray() -> Result<Device> {
    Ok(Device::ndarray())
}

#[cfg(not(feature = "ndarray"))]
fn ndarray() -> Result<Device> {
    Err(ModelError::BackendUnavailable {
        name: "ndarray".into(),
        feature: "ndarray".into(),
    })
}

#[cfg(feature = "wgpu")]
fn wgpu() -> Result<Device> {
    Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice))
}

#[cfg(not(feature = "wgpu"))]
fn wgpu() -> Result<Device> {
    Err(ModelError::BackendUnavailable {
        name: "wgpu".into(),
        feature: "wgpu".into(),
    })
}

#[cfg(feature = "cuda")]
fn cuda() -> Result<Device> {
    Ok(Device::cuda(0))
}

#[cfg(not(feature = "cuda"))]
fn cuda() -> Result<Device> {
    Err(ModelError::BackendUnavailable {
        name: "cuda".into(),
        feature: "cuda".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flex_is_always_there_and_missing_backends_name_their_feature() {
        assert!(device(BackendKind::Flex).is_ok());
        #[cfg(not(feature = "ndarray"))]
        {
            let e = device(BackendKind::Ndarray).unwrap_err();
            assert!(e.to_string().contains("--features train/ndarray"), "{e}");
        }
        assert_eq!("wgpu".parse::<BackendKind>(), Ok(BackendKind::Wgpu));
        assert_eq!("cuda".parse::<BackendKind>(), Ok(BackendKind::Cuda));
        #[cfg(not(feature = "cuda"))]
        {
            let e = device(BackendKind::Cuda).unwrap_err();
            assert!(e.to_string().contains("--features train/cuda"), "{e}");
        }
        assert!(
            "metal"
                .parse::<BackendKind>()
                .unwrap_err()
                .contains("flex, ndarray, wgpu or cuda")
        );
    }
}
