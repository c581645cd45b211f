//! What goes into the delay layer each step, and the step records that come out.
use super::DelayError;
use super::layout::{CopyCounters, DelayLayout, RECORD_FINAL_STATE, RecordMeta};
use crate::sim::{BatchedEnv, CopyStep};

/// One step of the undelayed batch, as [`BatchedEnv`] exposes it: the actions that were
/// executed (as chosen), and what the step returned, with finished copies already reset.
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    /// `[N, act_dim]`
    pub actions: &'a [f32],
    /// `[N, obs_dim]`: the new state, or the first state of the next episode where done.
    pub observations: &'a [f32],
    /// `[N, obs_dim]`: the last state of an episode that ended (rows where done).
    pub final_observations: &'a [f32],
    pub rewards: &'a [f32],
    pub terminated: &'a [u32],
    pub truncated: &'a [u32],
    /// `[N]`: what each copy did ([`BatchedEnv::step_each`]); `None`: every copy stepped. A
    /// held copy stays as it is and completes no record; a restarted one starts a new episode
    /// from its `observations` row, the steps of the one it leaves never completing.
    pub controls: Option<&'a [CopyStep]>,
}

impl<'a> StepInput<'a> {
    pub fn from_env(env: &'a BatchedEnv, actions: &'a [f32]) -> StepInput<'a> {
        StepInput {
            actions,
            observations: env.observations(),
            final_observations: env.final_observations(),
            rewards: env.rewards(),
            terminated: env.terminated(),
            truncated: env.truncated(),
            controls: Some(env.controls()),
        }
    }

    /// What copy `i` did.
    pub fn control(&self, i: usize) -> CopyStep {
        self.controls.map_or(CopyStep::Step, |c| c[i])
    }

    pub(super) fn check(&self, layout: &DelayLayout) -> Result<(), DelayError> {
        let n = layout.copies;
        for (what, found, expected) in [
            ("actions", self.actions.len(), n * layout.act_dim),
            ("observations", self.observations.len(), n * layout.obs_dim),
            (
                "final observations",
                self.final_observations.len(),
                n * layout.obs_dim,
            ),
            ("rewards", self.rewards.len(), n),
            ("terminated flags", self.terminated.len(), n),
            ("truncated flags", self.truncated.len(), n),
            (
                "per-copy step controls",
                self.controls.map_or(n, <[CopyStep]>::len),
                n,
            ),
        ] {
            if found != expected {
                return Err(DelayError::WrongLength {
                    what,
                    found,
                    expected,
                });
            }
        }
        Ok(())
    }
}

/// Time-aligned step records completed by one step: for copy `i`, slots
/// `0..counts[i]` of row `i`. A record holds `(s_τ, a_τ, r_τ)` of one true step τ — every τ of
/// the episode in order, `τ < Δ` included (they are the context of the first augmented states) —
/// with `terminated`/`truncated` set on the last step, and, after it, a final-state record
/// carrying `s_T`. Record τ completes when `s_{τ+1}` reaches the agent (at τ + 1 + Δ), or at once
/// when the episode ends (the last Δ observations are delivered then).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordBatch {
    pub layout: DelayLayout,
    /// `[N]`
    pub counts: Vec<u32>,
    /// `[N, Δ + 2]`
    pub meta: Vec<RecordMeta>,
    /// `[N, Δ + 2, obs_dim + act_dim + 1]`: state, action, reward.
    pub data: Vec<f32>,
}

/// One record, borrowed from a [`RecordBatch`].
#[derive(Debug, Clone, Copy)]
pub struct RecordRef<'a> {
    pub copy: usize,
    pub meta: RecordMeta,
    pub state: &'a [f32],
    pub action: &'a [f32],
    pub reward: f32,
}

impl RecordRef<'_> {
    pub fn is_final_state(&self) -> bool {
        self.meta.flags & RECORD_FINAL_STATE != 0
    }
}

impl RecordBatch {
    pub fn new(layout: DelayLayout) -> RecordBatch {
        let slots = layout.copies * layout.record_slots();
        RecordBatch {
            layout,
            counts: vec![0; layout.copies],
            meta: vec![RecordMeta::default(); slots],
            data: vec![0.0; slots * layout.stride()],
        }
    }

    pub(super) fn set_counts(&mut self, counters: &[CopyCounters]) {
        for (count, c) in self.counts.iter_mut().zip(counters) {
            *count = c.record_count;
        }
    }

    /// Total records in the batch.
    pub fn len(&self) -> usize {
        self.counts.iter().map(|&c| c as usize).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The reward that reached the agent with copy `copy`'s observations in the last step:
    /// the sum over the step records it completed (one per step once `t > Δ`, none before, and
    /// at an episode end all that remained), so an episode's delivered rewards add up to its
    /// return.
    pub fn delivered_reward(&self, copy: usize) -> f32 {
        let (slots, stride) = (self.layout.record_slots(), self.layout.stride());
        (0..self.counts[copy] as usize)
            .map(|k| copy * slots + k)
            .filter(|&row| self.meta[row].flags & RECORD_FINAL_STATE == 0)
            .map(|row| self.data[(row + 1) * stride - 1])
            .sum()
    }

    /// `x_T` of copy `copy` when its episode ended in the last step, from the records the end
    /// delivered: `(s_{T-Δ}, a_{T-Δ}, …, a_{T-1})`, appended to `out`. `false` (nothing
    /// appended) where no episode ended, or it ended before `x_T` existed (`T < Δ`).
    pub fn push_final_augmented(&self, copy: usize, out: &mut Vec<f32>) -> bool {
        let (slots, stride, delay) = (
            self.layout.record_slots(),
            self.layout.stride(),
            self.layout.delay,
        );
        let rows = &self.meta[copy * slots..copy * slots + self.counts[copy] as usize];
        let Some(last) = rows.last().filter(|m| m.flags & RECORD_FINAL_STATE != 0) else {
            return false;
        };
        let Some(first_tau) = (last.tau as usize).checked_sub(delay) else {
            return false;
        };
        // Records are in step order: the one of τ = T − Δ starts the window.
        let Some(start) = rows.iter().position(|m| m.tau as usize == first_tau) else {
            return false;
        };
        let row = |k: usize| {
            let at = (copy * slots + start + k) * stride;
            &self.data[at..at + stride]
        };
        self.layout.push_augmented(row, out);
        true
    }

    /// Every record, copy by copy, in step order.
    pub fn iter(&self) -> impl Iterator<Item = RecordRef<'_>> {
        let (slots, stride, obs) = (
            self.layout.record_slots(),
            self.layout.stride(),
            self.layout.obs_dim,
        );
        self.counts
            .iter()
            .enumerate()
            .flat_map(move |(copy, &count)| {
                (0..count as usize).map(move |k| {
                    let row = copy * slots + k;
                    let data = &self.data[row * stride..(row + 1) * stride];
                    RecordRef {
                        copy,
                        meta: self.meta[row],
                        state: &data[..obs],
                        action: &data[obs..stride - 1],
                        reward: data[stride - 1],
                    }
                })
            })
    }
}
