//! Where the networks live.
use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use super::LearnError;

/// `cpu`: burn's pure-Rust Flex backend; `wgpu`: burn's wgpu backend (cargo feature
/// `wgpu-learner`, for a real GPU).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
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
    /// A software wgpu adapter: [`Devices::settle`] waits for it.
    software: bool,
}

impl Devices {
    pub fn new(kind: LearnDevice) -> Result<Devices, LearnError> {
        // The device, and whether it is a software adapter.
        let (plain, software) = match kind {
            LearnDevice::Cpu => (Device::flex(), false),
            #[cfg(feature = "wgpu-learner")]
            LearnDevice::Wgpu => {
                // One command stream for every thread. A learner is used from several
                // threads (D2HPG's two learners side by side under rayon::join, acting on the
                // simulation pool, updates on the learner pool), and with CubeCL's default
                // stream per thread a kernel could read a parameter another thread's stream
                // had not finished writing: on an H200 D2HPG's delay-free α read back as 1.0
                // instead of 0.2 on every run (and on lavapipe about one run in ten). One
                // stream runs the kernels in the order they were submitted.
                cubecl_environment::stream::set_policy(
                    cubecl_environment::stream::StreamPolicy::Single,
                );
                let (real, all) = real_gpu_adapters();
                if !real.is_empty() {
                    (
                        Device::wgpu(burn::prelude::DeviceKind::DefaultDevice),
                        false,
                    )
                } else if let Some(api) = software_opt_in()? {
                    (software_device(api)?, true)
                } else {
                    return Err(LearnError::NoRealGpu {
                        found: if all.is_empty() {
                            "none".into()
                        } else {
                            all.join(", ")
                        },
                    });
                }
            }
            #[cfg(not(feature = "wgpu-learner"))]
            LearnDevice::Wgpu => return Err(LearnError::WgpuNotBuilt),
        };
        Ok(Devices {
            train: plain.clone().autodiff(),
            plain,
            software,
        })
    }

    /// On a software wgpu adapter, waits until the device has run everything queued so far;
    /// elsewhere does nothing. A learner calls it between the steps of an update and at its
    /// end. CubeCL's client spins while its queue of 32 tasks is full, and a software adapter
    /// runs the kernels on the same cores: an update queued whole spent the adapter's time
    /// spinning (SAC, InvertedPendulum sizes, batch 64, lavapipe on 2 Xeon cores: 94 ms per
    /// update without, 76–80 ms with both waits). Never measured on a real GPU, so not done there.
    pub fn settle(&self) {
        if self.software {
            if let Err(error) = self.plain.sync() {
                panic!("the wgpu device failed to run the learner's kernels: {error:?}");
            }
        }
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

/// The variable that lets `--device wgpu` run burn's kernels on a software adapter (Mesa's
/// CPU rasterisers): for testing that the wgpu learner computes what the CPU learner does,
/// never for speed. Its value names the graphics API: `gl` or `vulkan`.
pub const SOFTWARE_WGPU: &str = "DHRL_WGPU_SOFTWARE";

/// The software graphics API asked for through [`SOFTWARE_WGPU`], if any.
#[cfg(feature = "wgpu-learner")]
fn software_opt_in() -> Result<Option<burn::tensor::wgpu::WgpuBackend>, LearnError> {
    use burn::tensor::wgpu::WgpuBackend;
    match std::env::var(SOFTWARE_WGPU).as_deref() {
        Err(_) | Ok("") => Ok(None),
        Ok("gl") => Ok(Some(WgpuBackend::Gl)),
        Ok("vulkan") => Ok(Some(WgpuBackend::Vulkan)),
        Ok(other) => Err(LearnError::SoftwareWgpu(format!(
            "{SOFTWARE_WGPU}={other} is not a graphics API; accepted: gl, vulkan"
        ))),
    }
}

/// burn's wgpu device on the software adapter of `api`, made once per process (burn's
/// runtime cannot be set up twice) and cloned after that.
#[cfg(feature = "wgpu-learner")]
fn software_device(api: burn::tensor::wgpu::WgpuBackend) -> Result<Device, LearnError> {
    use std::sync::OnceLock;
    static DEVICE: OnceLock<Result<Device, String>> = OnceLock::new();
    let device = DEVICE.get_or_init(|| {
        eprintln!(
            "warning: {SOFTWARE_WGPU} is set: burn's wgpu learner runs on a software {api:?} \
             adapter, for testing only (it is far slower than --device cpu)"
        );
        Device::wgpu_options()
            .device_kind(burn::prelude::DeviceKind::Cpu)
            .graphics_api(api)
            .init()
            .map_err(|e| format!("burn could not start wgpu on a software {api:?} adapter: {e}"))
    });
    device.clone().map_err(LearnError::SoftwareWgpu)
}
