//! The pieces every learner is built from, in burn 0.22: devices, networks, the SAC losses
//! (each a small function tested against hand-computed values), Polyak averaging and
//! host-side noise so that runs are reproducible and resumable. The SAC family's networks are
//! stacked ([`stack`]): one set of tensors serves S runs.

mod clip;
mod cpu_ops;
mod device;
mod init;
mod io;
mod losses;
mod nets;
mod noise;
mod stack;
mod tensors;

pub use clip::clip_norm_per_run;
pub use cpu_ops::{adam, gelu, times_mask};
#[cfg(feature = "wgpu-learner")]
pub use device::real_gpu_adapters;
pub use device::{Devices, LearnDevice, SOFTWARE_WGPU};
pub use init::{NetworkInit, initialise};
pub use io::{CheckpointDir, load_json_stack, load_optimizer_stack, load_stack};
pub use losses::{
    actor_loss, batch_mean, critic_loss, critic_target, lifting_loss, polyak,
    squashed_gaussian_log_prob, temperature_loss,
};
pub use nets::{
    ActionScale, GaussianPolicy, HIDDEN, LOG_STD_MAX, LOG_STD_MIN, Mlp, MlpConfig, PolicySample,
    QNetwork, Temperature, TwinQ, squashed_sample, squashed_samples_k,
};
pub use noise::Noise;
pub use stack::{
    StackedLayerNorm, StackedLinear, select_runs, slice, slice_pack, stack, stack_packs,
};
#[cfg(test)]
pub(crate) use tensors::assert_close;
pub use tensors::{
    Transfers, TransitionTensors, matrix, stacked_rows, to_vec, transfers, upload, upload_rows,
};

/// What can go wrong while learning, saving or loading.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    #[error(
        "--device wgpu needs the `wgpu-learner` cargo feature: build with `cargo build --release --features wgpu-learner`"
    )]
    WgpuNotBuilt,
    #[error(
        "--device wgpu needs a real GPU adapter, and wgpu found none (adapters seen: {found}); \
         use --device cpu, or for testing only set DHRL_WGPU_SOFTWARE=vulkan to run burn's \
         kernels on a software adapter such as Mesa's lavapipe (far slower than the CPU)"
    )]
    NoRealGpu { found: String },
    #[error("{0}")]
    SoftwareWgpu(String),
    #[error("cannot save {what}: {message}")]
    Save { what: String, message: String },
    #[error("cannot load {what}: {message}")]
    Load { what: String, message: String },
}
