//! The reference implementation of the delay layer, and the CPU fallback.
use rayon::prelude::*;

use super::config::check_len;
use super::layer::{DelayLayer, LayerState, LayerStateMut, read_state, write_state};
use super::layout::{
    CopyCounters, DelayLayout, RECORD_FINAL_STATE, RECORD_TERMINATED, RECORD_TRUNCATED, RecordMeta,
};
use super::records::{RecordBatch, RecordRef, StepInput};
use super::transitions::Transitions;
use super::warmup::WarmupFiller;
use super::{DelayConfig, DelayError};
use crate::sim::CopyStep;
use crate::snapshot::SnapshotError;
use std::io::{Read, Write};

/// Copies one rayon task steps at least; a layer of no more copies steps them on the calling
/// thread (a copy's step is a few hundred nanoseconds of copying: less than a hand-off to the pool).
const COPIES_PER_WORKER: usize = 64;

/// The delay layer on the CPU: per copy, a ring of the last 2Δ + 3 steps `(s_τ, a_τ, r_τ)`.
pub struct CpuDelayLayer {
    layout: DelayLayout,
    warmup: WarmupFiller,
    counters: Vec<CopyCounters>,
    /// `[N, 2Δ + 3, obs + act + 1]`
    ring: Vec<f32>,
    /// `[N, obs + Δ·act]`
    augmented: Vec<f32>,
    /// `[N]`
    ready: Vec<u32>,
    records: RecordBatch,
}

/// The inputs of one copy for one step.
pub(super) struct CopyInput<'a> {
    pub action: &'a [f32],
    pub observation: &'a [f32],
    pub final_observation: &'a [f32],
    pub reward: f32,
    pub terminated: bool,
    pub truncated: bool,
    pub control: CopyStep,
}

impl<'a> CopyInput<'a> {
    /// Copy `i`'s rows of `input`.
    fn of(input: &StepInput<'a>, l: &DelayLayout, i: usize) -> CopyInput<'a> {
        let (obs, act) = (l.obs_dim, l.act_dim);
        CopyInput {
            action: &input.actions[i * act..(i + 1) * act],
            observation: &input.observations[i * obs..(i + 1) * obs],
            final_observation: &input.final_observations[i * obs..(i + 1) * obs],
            reward: input.rewards[i],
            terminated: input.terminated[i] != 0,
            truncated: input.truncated[i] != 0,
            control: input.control(i),
        }
    }
}

/// The outputs of one copy, as slices of the batch arrays.
pub(super) struct CopyState<'a> {
    pub counters: &'a mut CopyCounters,
    pub ring: &'a mut [f32],
    pub augmented: &'a mut [f32],
    pub meta: &'a mut [RecordMeta],
    pub data: &'a mut [f32],
}

impl CpuDelayLayer {
    /// A layer for `copies` copies of a task with the given observation size and action bounds.
    pub fn new(
        config: &DelayConfig,
        copies: usize,
        obs_dim: usize,
        action_low: &[f64],
        action_high: &[f64],
        seed: u64,
    ) -> Result<CpuDelayLayer, DelayError> {
        let layout = DelayLayout::for_config(config, copies, obs_dim, action_low.len())?;
        Ok(CpuDelayLayer {
            layout,
            warmup: WarmupFiller::new(config.warmup, action_low, action_high, seed),
            counters: vec![CopyCounters::default(); copies],
            ring: vec![0.0; copies * layout.ring_len() * layout.stride()],
            augmented: vec![0.0; copies * layout.augmented_dim()],
            ready: vec![0; copies],
            records: RecordBatch::new(layout),
        })
    }

    pub fn counters(&self) -> &[CopyCounters] {
        &self.counters
    }

    /// Copy `i`'s rows of the layer's arrays.
    fn copy_state(&mut self, i: usize) -> CopyState<'_> {
        let l = self.layout;
        let (ring, augmented) = (l.ring_len() * l.stride(), l.augmented_dim());
        let (slots, stride) = (l.record_slots(), l.stride());
        CopyState {
            counters: &mut self.counters[i],
            ring: &mut self.ring[i * ring..(i + 1) * ring],
            augmented: &mut self.augmented[i * augmented..(i + 1) * augmented],
            meta: &mut self.records.meta[i * slots..(i + 1) * slots],
            data: &mut self.records.data[i * slots * stride..(i + 1) * slots * stride],
        }
    }
}

impl DelayLayer for CpuDelayLayer {
    fn layout(&self) -> DelayLayout {
        self.layout
    }

    fn reset(&mut self, observations: &[f32]) -> Result<(), DelayError> {
        let l = self.layout;
        check_len(
            "initial observations",
            observations.len(),
            l.copies * l.obs_dim,
        )?;
        self.ring.fill(0.0);
        self.records = RecordBatch::new(l);
        for (i, s0) in observations.chunks(l.obs_dim).enumerate() {
            let mut copy = self.copy_state(i);
            *copy.counters = CopyCounters::default();
            start_episode(&l, &mut copy, s0, false);
            let ready = copy.counters.ready;
            self.ready[i] = ready;
        }
        Ok(())
    }

    fn step(&mut self, input: &StepInput<'_>) -> Result<(), DelayError> {
        let l = self.layout;
        input.check(&l)?;
        let step_one = |copy: usize, mut state: CopyState<'_>| {
            step_copy(&l, &mut state, &CopyInput::of(input, &l, copy));
        };
        if l.copies <= COPIES_PER_WORKER {
            for copy in 0..l.copies {
                step_one(copy, self.copy_state(copy));
            }
        } else {
            (
                self.counters.par_iter_mut(),
                self.ring.par_chunks_mut(l.ring_len() * l.stride()),
                self.augmented.par_chunks_mut(l.augmented_dim()),
                self.records.meta.par_chunks_mut(l.record_slots()),
                self.records
                    .data
                    .par_chunks_mut(l.record_slots() * l.stride()),
                (0..l.copies).into_par_iter(),
            )
                .into_par_iter()
                .with_min_len(COPIES_PER_WORKER)
                .for_each(|(counters, ring, augmented, meta, data, copy)| {
                    let state = CopyState {
                        counters,
                        ring,
                        augmented,
                        meta,
                        data,
                    };
                    step_one(copy, state);
                });
        }
        for (ready, c) in self.ready.iter_mut().zip(&self.counters) {
            *ready = c.ready;
        }
        self.records.set_counts(&self.counters);
        Ok(())
    }

    fn fill_warmup(&mut self, actions: &mut [f32]) -> Result<(), DelayError> {
        self.warmup.fill(actions, &self.ready)
    }

    fn augmented(&self) -> &[f32] {
        &self.augmented
    }

    fn ready(&self) -> &[u32] {
        &self.ready
    }

    fn records(&self) -> &RecordBatch {
        &self.records
    }

    fn transitions(&self) -> Result<Transitions, DelayError> {
        Ok(transitions_from(&self.layout, &self.ring, &self.records))
    }

    fn save(&self, out: &mut dyn Write) -> Result<(), SnapshotError> {
        write_state(
            out,
            LayerState {
                counters: &self.counters,
                ring: &self.ring,
                augmented: &self.augmented,
                ready: &self.ready,
                records: &self.records,
                rng: self.warmup.rng(),
            },
        )
    }
    fn load(&mut self, input: &mut dyn Read) -> Result<(), SnapshotError> {
        read_state(
            input,
            LayerStateMut {
                counters: &mut self.counters,
                ring: &mut self.ring,
                augmented: &mut self.augmented,
                ready: &mut self.ready,
                records: &mut self.records,
                rng: self.warmup.rng_mut(),
            },
        )
    }
}

/// The transitions of the step records in `records`, written out in full (`x` verbatim) from
/// the layer's rings (`[N, 2Δ + 3, obs + act + 1]`): what [`DelayLayer::transitions`] returns.
pub(super) fn transitions_from(
    l: &DelayLayout,
    ring: &[f32],
    records: &RecordBatch,
) -> Transitions {
    let (ring_len, stride) = (l.ring_len(), l.stride());
    let delivered =
        |record: &RecordRef<'_>| !record.is_final_state() && (record.meta.tau as usize) >= l.delay;
    let mut out = Transitions::with_capacity(l, records.iter().filter(delivered).count());
    for record in records.iter().filter(delivered) {
        let ring = &ring[record.copy * ring_len * stride..(record.copy + 1) * ring_len * stride];
        let slot = record.meta.slot as usize;
        let next = (slot + 1) % ring_len;
        out.copy.push(record.copy);
        out.episode.push(record.meta.episode);
        out.tau.push(record.meta.tau);
        let at = out.augmented.len();
        l.push_augmented(|k| ring_row(l, ring, slot, k), &mut out.augmented);
        out.state.extend_from_slice(record.state);
        out.action.extend_from_slice(record.action);
        out.reward.push(record.reward);
        l.push_next_augmented(
            &out.augmented[at..],
            |k| ring_row(l, ring, slot, k),
            &mut out.next_augmented,
        );
        out.next_state
            .extend_from_slice(&ring[next * stride..next * stride + l.obs_dim]);
        out.terminated
            .push(u32::from(record.meta.flags & RECORD_TERMINATED != 0));
    }
    out
}

/// The ring slot `k` steps after the one Δ steps before `slot`: row `k` of `x` at `slot`.
fn ring_row<'r>(l: &DelayLayout, ring: &'r [f32], slot: usize, k: usize) -> &'r [f32] {
    let (ring_len, stride) = (l.ring_len(), l.stride());
    let s = (slot + ring_len - l.delay + k) % ring_len;
    &ring[s * stride..(s + 1) * stride]
}

/// Puts `s_0` of a new episode at the cursor (advanced past the last episode's `s_T` when
/// `advance`) and rebuilds `x_0`.
fn start_episode(l: &DelayLayout, copy: &mut CopyState<'_>, s0: &[f32], advance: bool) {
    let c = &mut *copy.counters;
    let stride = l.stride();
    if advance {
        c.cursor = (c.cursor + 1) % l.ring_len() as u32;
    }
    c.t = 0;
    let at = c.cursor as usize * stride;
    copy.ring[at..at + l.obs_dim].copy_from_slice(s0);
    copy.ring[at + l.obs_dim..at + stride].fill(0.0);
    update_augmented(l, copy);
}

/// One step of one copy: store `a_t, r_t` beside `s_t`, store `s_{t+1}`, emit the records that
/// completed, start the next episode where this one ended, and rebuild `x`.
pub(super) fn step_copy(l: &DelayLayout, copy: &mut CopyState<'_>, input: &CopyInput<'_>) {
    match input.control {
        CopyStep::Step => {}
        CopyStep::Hold => {
            copy.counters.record_count = 0;
            return;
        }
        CopyStep::Restart => {
            copy.counters.record_count = 0;
            copy.counters.episode += 1;
            start_episode(l, copy, input.observation, true);
            return;
        }
    }
    let (ring_len, stride, obs) = (l.ring_len() as u32, l.stride(), l.obs_dim);
    let done = input.terminated || input.truncated;
    let c = &mut *copy.counters;
    let at = c.cursor as usize * stride;
    copy.ring[at + obs..at + obs + l.act_dim].copy_from_slice(input.action);
    copy.ring[at + stride - 1] = input.reward;
    c.cursor = (c.cursor + 1) % ring_len;
    c.t += 1;
    let at = c.cursor as usize * stride;
    let next_state = if done {
        input.final_observation
    } else {
        input.observation
    };
    copy.ring[at..at + obs].copy_from_slice(next_state);
    copy.ring[at + obs..at + stride].fill(0.0);
    c.record_count = 0;

    // Record τ completes when s_{τ+1} arrives: τ = t − Δ − 1; an episode end delivers the rest.
    let t = c.t as i64;
    let first = t - l.delay as i64 - 1;
    let taus = if done {
        first.max(0)..t
    } else {
        first.max(0)..(first + 1).max(0)
    };
    for tau in taus {
        let last = tau == t - 1;
        let flags = if last && input.terminated {
            RECORD_TERMINATED
        } else {
            0
        } | if last && input.truncated {
            RECORD_TRUNCATED
        } else {
            0
        };
        emit_record(l, copy, tau as u32, flags);
    }
    if done {
        let flags = RECORD_FINAL_STATE
            | if input.terminated {
                RECORD_TERMINATED
            } else {
                0
            }
            | if input.truncated { RECORD_TRUNCATED } else { 0 };
        let t = copy.counters.t;
        emit_record(l, copy, t, flags);
        copy.counters.episode += 1;
        start_episode(l, copy, input.observation, true);
    } else {
        update_augmented(l, copy);
    }
}

/// Copies step `tau` of the current episode out of the ring into the next record slot.
fn emit_record(l: &DelayLayout, copy: &mut CopyState<'_>, tau: u32, flags: u32) {
    let (ring_len, stride) = (l.ring_len() as u32, l.stride());
    let c = &mut *copy.counters;
    let slot = (c.cursor + ring_len - (c.t - tau)) % ring_len;
    let k = c.record_count as usize;
    copy.meta[k] = RecordMeta {
        tau,
        episode: c.episode,
        flags,
        slot,
    };
    let from = slot as usize * stride;
    copy.data[k * stride..(k + 1) * stride].copy_from_slice(&copy.ring[from..from + stride]);
    c.record_count += 1;
}

/// `x_t` from the ring, or zeros while `t < Δ`.
fn update_augmented(l: &DelayLayout, copy: &mut CopyState<'_>) {
    let c = &mut *copy.counters;
    c.ready = u32::from(c.t as usize >= l.delay);
    if c.ready == 0 {
        copy.augmented.fill(0.0);
        return;
    }
    let (ring, cursor) = (&*copy.ring, c.cursor as usize);
    l.assemble_augmented(|k| ring_row(l, ring, cursor, k), copy.augmented);
}
