//! Where the delay layer's ring buffers live, and the layer made there.
use serde::{Deserialize, Serialize};

use super::cpu::CpuDelayLayer;
use super::gpu::GpuDelayLayer;
use super::layer::DelayLayer;
use super::{DelayConfig, DelayError};

/// Where the delay layer's ring buffers live.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum DelayDevice {
    /// Host memory, updated by the CPU reference.
    #[default]
    Cpu,
    /// `wgpu` storage buffers, updated by `shaders/delay.wgsl` (any Vulkan adapter, Mesa's
    /// software one included), read back after every step.
    Gpu,
}

/// A delay layer on `device` for `copies` copies with the given observation size and bounds.
pub fn delay_layer(
    device: DelayDevice,
    config: &DelayConfig,
    copies: usize,
    obs_dim: usize,
    action_low: &[f64],
    action_high: &[f64],
    seed: u64,
) -> Result<Box<dyn DelayLayer>, DelayError> {
    Ok(match device {
        DelayDevice::Cpu => Box::new(CpuDelayLayer::new(
            config,
            copies,
            obs_dim,
            action_low,
            action_high,
            seed,
        )?),
        DelayDevice::Gpu => Box::new(
            GpuDelayLayer::new(config, copies, obs_dim, action_low, action_high, seed)
                .map_err(|e| DelayError::Gpu(e.to_string()))?,
        ),
    })
}
