//! Where the networks live.
use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use super::LearnError;

/// `cpu`: burn's pure-Rust Flex backend; `wgpu`: burn's wgpu backend (cargo feature
/// `wgpu-learner`, for a real GPU).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum LearnDevice {
    #[default]
    Cpu,
    Wgpu,
}

/// The plain device (data, targets, acting: no autodiff graph) and its autodiff twin (the
/// parameters being trained).
#[derive(Debug, Clone)]
pub struct Devices {
    pub plain: Device,
    pub train: Device,
}

impl Devices {
    pub fn new(kind: LearnDevice) -> Result<Devices, LearnError> {
        let plain = match kind {
            LearnDevice::Cpu => Device::flex(),
            #[cfg(feature = "wgpu-learner")]
            LearnDevice::Wgpu => Device::wgpu(burn::prelude::DeviceKind::DefaultDevice),
            #[cfg(not(feature = "wgpu-learner"))]
            LearnDevice::Wgpu => return Err(LearnError::WgpuNotBuilt),
        };
        Ok(Devices {
            train: plain.clone().autodiff(),
            plain,
        })
    }
}
