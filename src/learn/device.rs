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
            LearnDevice::Wgpu => {
                let (real, all) = real_gpu_adapters();
                if real.is_empty() {
                    return Err(LearnError::NoRealGpu {
                        found: if all.is_empty() {
                            "none".into()
                        } else {
                            all.join(", ")
                        },
                    });
                }
                Device::wgpu(burn::prelude::DeviceKind::DefaultDevice)
            }
            #[cfg(not(feature = "wgpu-learner"))]
            LearnDevice::Wgpu => return Err(LearnError::WgpuNotBuilt),
        };
        Ok(Devices {
            train: plain.clone().autodiff(),
            plain,
        })
    }
}

/// The adapters wgpu sees, as `(real GPUs, all)`, each "name (type, backend)". A real GPU is
/// any adapter that is not a CPU rasteriser; burn's wgpu learner needs one.
#[cfg(feature = "wgpu-learner")]
pub fn real_gpu_adapters() -> (Vec<String>, Vec<String>) {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let mut real = Vec::new();
    let mut all = Vec::new();
    for adapter in adapters {
        let info = adapter.get_info();
        let name = format!("{} ({:?}, {:?})", info.name, info.device_type, info.backend);
        if info.device_type != wgpu::DeviceType::Cpu {
            real.push(name.clone());
        }
        all.push(name);
    }
    (real, all)
}
