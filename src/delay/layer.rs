//! The delay layer as one interface over its two implementations, the CPU reference and the
//! WGSL kernels (chosen by `DelayDevice`, in device.rs); both save the same checkpoint format,
//! so a run's delay state moves between them.
use std::io::{Read, Write};

use rand_chacha::ChaCha8Rng;

use super::DelayError;
use super::layout::{CopyCounters, DelayLayout};
use super::records::{RecordBatch, StepInput};
use super::transitions::Transitions;
use crate::snapshot::{SnapshotError, read_section, write_section};

/// What every implementation of the delay layer offers (docs/DESIGN.md §1).
pub trait DelayLayer: Send {
    fn layout(&self) -> DelayLayout;
    /// Starts every copy's first episode from `observations` (`[N, obs_dim]`, the `s_0`s).
    fn reset(&mut self, observations: &[f32]) -> Result<(), DelayError>;
    /// Records one step of the undelayed batch and updates augmented states and records.
    fn step(&mut self, input: &StepInput<'_>) -> Result<(), DelayError>;
    /// Overwrites the rows of `actions` of copies still in warm-up with warm-up actions.
    fn fill_warmup(&mut self, actions: &mut [f32]) -> Result<(), DelayError>;
    /// `[N, obs + Δ·act]`: `x_t` of every copy (zeros where not ready).
    fn augmented(&self) -> &[f32];
    /// `[N]`: 1 where `x_t` exists and the policy acts, 0 during warm-up.
    fn ready(&self) -> &[u32];
    /// The step records completed by the last step.
    fn records(&self) -> &RecordBatch;
    /// The transitions of those records, written out in full (`x_τ` and `x_{τ+1}` verbatim).
    fn transitions(&self) -> Result<Transitions, DelayError>;
    /// Writes the layer's state (counters, rings, outputs, warm-up random stream).
    fn save(&self, out: &mut dyn Write) -> Result<(), SnapshotError>;
    /// Restores what [`DelayLayer::save`] wrote, from either implementation.
    fn load(&mut self, input: &mut dyn Read) -> Result<(), SnapshotError>;
}

/// A layer's whole state as host arrays: what a checkpoint holds, in this order.
pub(super) struct LayerState<'a> {
    pub counters: &'a [CopyCounters],
    pub ring: &'a [f32],
    pub augmented: &'a [f32],
    pub ready: &'a [u32],
    pub records: &'a RecordBatch,
    pub rng: &'a ChaCha8Rng,
}

/// The mutable twin of [`LayerState`], restored in place.
pub(super) struct LayerStateMut<'a> {
    pub counters: &'a mut [CopyCounters],
    pub ring: &'a mut [f32],
    pub augmented: &'a mut [f32],
    pub ready: &'a mut [u32],
    pub records: &'a mut RecordBatch,
    pub rng: &'a mut ChaCha8Rng,
}

pub(super) fn write_state(
    mut out: &mut dyn Write,
    state: LayerState<'_>,
) -> Result<(), SnapshotError> {
    write_section(&mut out, state.counters)?;
    write_section(&mut out, state.ring)?;
    write_section(&mut out, state.augmented)?;
    write_section(&mut out, state.ready)?;
    write_section(&mut out, &state.records.counts)?;
    write_section(&mut out, &state.records.meta)?;
    write_section(&mut out, &state.records.data)?;
    let rng = serde_json::to_vec(state.rng).map_err(std::io::Error::other)?;
    write_section(&mut out, &rng)
}

pub(super) fn read_state(
    mut input: &mut dyn Read,
    state: LayerStateMut<'_>,
) -> Result<(), SnapshotError> {
    read_section(&mut input, "delay counters", state.counters)?;
    read_section(&mut input, "delay ring", state.ring)?;
    read_section(&mut input, "augmented states", state.augmented)?;
    read_section(&mut input, "ready flags", state.ready)?;
    read_section(&mut input, "record counts", &mut state.records.counts)?;
    read_section(&mut input, "record metadata", &mut state.records.meta)?;
    read_section(&mut input, "record data", &mut state.records.data)?;
    let mut len = [0u8; 8];
    input.read_exact(&mut len)?;
    let mut rng = vec![0u8; u64::from_le_bytes(len) as usize];
    input.read_exact(&mut rng)?;
    *state.rng = serde_json::from_slice(&rng).map_err(std::io::Error::other)?;
    Ok(())
}
