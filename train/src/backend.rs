//! The Burn device of a run, chosen at run time from `[backend]` (or `--backend`).

use burn::prelude::Device;

use crate::config::BackendKind;
use crate::error::Result;
#[cfg(not(all(feature = "ndarray", feature = "wgpu")))]
use crate::error::TrainError;

/// The plain (inference) device of `kind`; train on `device(kind)?.autodiff()`.
///
/// flex is always available; ndarray and wgpu need this crate's cargo features of the same
/// name, and asking for one that was not compiled in is an error naming the feature.
pub fn device(kind: BackendKind) -> Result<Device> {
    match kind {
        BackendKind::Flex => Ok(Device::flex()),
        BackendKind::Ndarray => ndarray(),
        BackendKind::Wgpu => wgpu(),
    }
}

#[cfg(feature = "ndarray")]
#[allow(deprecated)] // our users ask for it; Burn 0.22 deprecates it in favour of flex
fn ndarray() -> Result<Device> {
    Ok(Device::ndarray())
}

#[cfg(not(feature = "ndarray"))]
fn ndarray() -> Result<Device> {
    Err(TrainError::BackendUnavailable {
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
    Err(TrainError::BackendUnavailable {
        name: "wgpu".into(),
        feature: "wgpu".into(),
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
            assert_eq!(e.exit_code(), 2);
        }
    }
}
