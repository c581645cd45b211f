//! Sizes and buffer layout shared by the CPU and GPU implementations.
use bytemuck::{Pod, Zeroable};

use super::{DelayConfig, DelayError};

/// Flag: the step of this record ended the MDP (`terminated_{τ+1}`; no bootstrapping).
pub const RECORD_TERMINATED: u32 = 1;
/// Flag: the step of this record hit the time limit (bootstrap from `s_{τ+1}`).
pub const RECORD_TRUNCATED: u32 = 2;
/// Flag: this record only carries the last state `s_T` of a finished episode (no action).
pub const RECORD_FINAL_STATE: u32 = 4;
/// Set by the replay store (not the delay layers) on the last step of an episode that the
/// simulation's divergence ended: that step is no transition to learn from.
pub const RECORD_DIVERGED: u32 = 8;

/// Which step a record belongs to. Identical bytes on the CPU and in WGSL.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
pub struct RecordMeta {
    /// Step index within the episode.
    pub tau: u32,
    /// Episode counter of the copy.
    pub episode: u32,
    /// `RECORD_*` bits.
    pub flags: u32,
    /// Ring slot of the copy that held this step when the record was written.
    pub slot: u32,
}

/// Per-copy counters. Identical bytes on the CPU and in WGSL.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
pub struct CopyCounters {
    /// Index within the episode of the newest state.
    pub t: u32,
    pub episode: u32,
    /// Ring slot of the newest state (advances by one per step, across episodes).
    pub cursor: u32,
    /// 1 when `x_t` exists (`t ≥ Δ`), so the policy acts; 0 during warm-up.
    pub ready: u32,
    /// Records completed by the last step.
    pub record_count: u32,
    pub _pad: [u32; 3],
}

/// The shapes of one delay layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DelayLayout {
    pub copies: usize,
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Total delay Δ.
    pub delay: usize,
}

impl DelayLayout {
    /// The layout of `copies` copies under `config` (checked: see [`DelayConfig::total_delay`]).
    pub fn for_config(
        config: &DelayConfig,
        copies: usize,
        obs_dim: usize,
        act_dim: usize,
    ) -> Result<DelayLayout, DelayError> {
        Ok(DelayLayout {
            copies,
            obs_dim,
            act_dim,
            delay: config.total_delay()?,
        })
    }

    /// `obs_dim + Δ·act_dim`.
    pub fn augmented_dim(&self) -> usize {
        self.obs_dim + self.delay * self.act_dim
    }

    /// Writes `x = (s_{τ-Δ}, a_{τ-Δ}, …, a_{τ-1})` into `out` (`augmented_dim` long) from the
    /// stored steps `row(0..Δ)`, oldest first (ring slots or replay steps of one copy, each
    /// `[state, action, reward]`): the state of row 0, then the action of every row.
    pub fn assemble_augmented<'r>(&self, row: impl Fn(usize) -> &'r [f32], out: &mut [f32]) {
        let (obs, act) = (self.obs_dim, self.act_dim);
        out[..obs].copy_from_slice(&row(0)[..obs]);
        for k in 0..self.delay {
            out[obs + k * act..obs + (k + 1) * act].copy_from_slice(&row(k)[obs..obs + act]);
        }
    }

    /// [`DelayLayout::assemble_augmented`], appended to `out`.
    pub fn push_augmented<'r>(&self, row: impl Fn(usize) -> &'r [f32], out: &mut Vec<f32>) {
        let (obs, act) = (self.obs_dim, self.act_dim);
        out.reserve(self.augmented_dim());
        out.extend_from_slice(&row(0)[..obs]);
        for k in 0..self.delay {
            out.extend_from_slice(&row(k)[obs..obs + act]);
        }
    }
    /// Appends `x_{τ+1}` to `out` given `x_τ` (`augmented`) and the stored steps `row(0..=Δ)`
    /// of `x_τ` (as [`DelayLayout::assemble_augmented`]'s, row Δ being step τ itself): the two
    /// share Δ − 1 actions, so `x_{τ+1} = (s_{τ+1−Δ}, a_{τ+1−Δ} … a_{τ−1}, a_τ)` is three copies
    /// instead of Δ + 1 (a transition's gather costs one short `memcpy` call per copy).
    pub fn push_next_augmented<'r>(
        &self,
        augmented: &[f32],
        row: impl Fn(usize) -> &'r [f32],
        out: &mut Vec<f32>,
    ) {
        let (obs, act) = (self.obs_dim, self.act_dim);
        out.reserve(self.augmented_dim());
        out.extend_from_slice(&row(1)[..obs]);
        if self.delay > 0 {
            out.extend_from_slice(&augmented[obs + act..]);
            out.extend_from_slice(&row(self.delay)[obs..obs + act]);
        }
    }
    /// Steps kept per copy: transition τ completes at τ + 1 + Δ and needs `s_{τ-Δ}`; an episode
    /// end flushes τ down to T − Δ − 1, so `s_{T-2Δ-1} … s_T` (2Δ + 2 states) must survive the
    /// step that also writes the next episode's `s_0`: 2Δ + 3 slots.
    pub fn ring_len(&self) -> usize {
        2 * self.delay + 3
    }
    /// Floats per ring slot and per record: state, action, reward.
    pub fn stride(&self) -> usize {
        self.obs_dim + self.act_dim + 1
    }
    /// At most Δ + 1 step records plus the final-state record complete in one step (at an
    /// episode end); one otherwise.
    pub fn record_slots(&self) -> usize {
        self.delay + 2
    }
}
