//! The delay layer (docs/DESIGN.md §1): turns a batch of undelayed simulations into what a delayed agent
//! sees — augmented states `x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1})` — and what the learners train
//! on — time-aligned step records, from which every transition
//! `(x_τ, s_τ, a_τ, r_τ, x_{τ+1}, s_{τ+1}, terminated_{τ+1})` is rebuilt.
//!
//! [`CpuDelayLayer`] is the reference and the fallback; [`GpuDelayLayer`] keeps the same ring
//! buffers on a `wgpu` device and updates them with `shaders/delay.wgsl`, producing identical
//! outputs; both are a [`DelayLayer`], chosen by [`DelayDevice`]. [`ReplayStore`] keeps records at O(obs + act) floats per step.

mod args;
mod batch;
mod config;
mod cpu;
mod device;
mod gpu;
mod layer;
mod layout;
mod records;
mod replay;
mod transitions;
mod warmup;

pub use args::{DelayArgs, NegativeDelay};
pub use batch::{BatchError, DelayedBatch};
pub use config::{DelayConfig, DelayError, MAX_DELAY, WarmupActions, arrival_delay};
pub use cpu::CpuDelayLayer;
pub use device::{DelayDevice, delay_layer};
pub use gpu::{GpuDelayLayer, GpuError};
pub use layer::DelayLayer;
pub use layout::{
    CopyCounters, DelayLayout, RECORD_FINAL_STATE, RECORD_TERMINATED, RECORD_TRUNCATED, RecordMeta,
};
pub use records::{RecordBatch, RecordRef, StepInput};
pub use replay::{DEFAULT_CAPACITY, ReplayError, ReplayStore};
pub use transitions::{BatchExtras, Transitions};
pub use warmup::WarmupFiller;
