//! Replay memory that stores step records, not augmented states: `x_τ` and `x_{τ+1}` are rebuilt
//! from the records of the Δ steps before (as Atari replays rebuild frame stacks), so a stored
//! step costs O(obs + act) floats instead of `2·(obs + Δ·act)`.
use rand::Rng;

use super::layout::{
    DelayLayout, RECORD_DIVERGED, RECORD_FINAL_STATE, RECORD_TERMINATED, RECORD_TRUNCATED,
};
use super::records::RecordBatch;
use super::transitions::{BatchExtras, Transitions};
use crate::snapshot::{SnapshotError, read_section, write_section};

/// The default capacity, in steps (docs/DESIGN.md §3.3).
pub const DEFAULT_CAPACITY: usize = 1_000_000;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ReplayError {
    #[error(
        "replay capacity {capacity} is too small for {copies} copies at delay {delay}: each copy needs at least {min} steps"
    )]
    TooSmall {
        capacity: usize,
        copies: usize,
        delay: usize,
        min: usize,
    },
    #[error("the replay store holds no complete transition yet")]
    Empty,
    #[error("records of layout {found:?} pushed into a store of layout {expected:?}")]
    LayoutMismatch {
        found: DelayLayout,
        expected: DelayLayout,
    },
}

/// One stored step of one copy.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct StepMeta {
    episode: u32,
    tau: u32,
    flags: u32,
}

/// Uniform replay over every complete transition, with per-copy segments so that each copy's
/// steps stay in order.
pub struct ReplayStore {
    layout: DelayLayout,
    segment: usize,
    /// Per copy: next physical slot to write, and how many slots hold steps.
    head: Vec<usize>,
    filled: Vec<usize>,
    meta: Vec<StepMeta>,
    /// `[copies · segment, obs + act + 1]`
    data: Vec<f32>,
}

impl ReplayStore {
    /// A store of `capacity` steps in all, shared equally by the copies.
    pub fn new(layout: DelayLayout, capacity: usize) -> Result<ReplayStore, ReplayError> {
        let segment = capacity / layout.copies.max(1);
        let min = 2 * layout.delay + 3;
        if segment < min {
            return Err(ReplayError::TooSmall {
                capacity,
                copies: layout.copies,
                delay: layout.delay,
                min,
            });
        }
        let slots = segment * layout.copies;
        Ok(ReplayStore {
            layout,
            segment,
            head: vec![0; layout.copies],
            filled: vec![0; layout.copies],
            meta: vec![StepMeta::default(); slots],
            data: vec![0.0; slots * layout.stride()],
        })
    }

    /// Bytes one stored step costs: its state, action and reward as f32, and its metadata.
    pub fn bytes_per_step(&self) -> usize {
        self.layout.stride() * size_of::<f32>() + size_of::<StepMeta>()
    }

    /// Bytes that `x_τ` and `x_{τ+1}` stored verbatim as f32 would cost per step, for comparison.
    pub fn verbatim_bytes_per_step(&self) -> usize {
        (2 * self.layout.augmented_dim() + 2 * self.layout.obs_dim + self.layout.act_dim + 2)
            * size_of::<f32>()
    }

    /// Writes the stored steps only (not the empty capacity), each copy's oldest first.
    pub fn save(&self, out: &mut impl std::io::Write) -> Result<(), SnapshotError> {
        let stride = self.layout.stride();
        let filled: Vec<u64> = self.filled.iter().map(|&f| f as u64).collect();
        write_section(out, &filled)?;
        for c in 0..self.layout.copies {
            let slots: Vec<usize> = (0..self.filled[c]).map(|i| self.slot(c, i)).collect();
            let meta: Vec<StepMeta> = slots.iter().map(|&s| self.meta[s]).collect();
            let data: Vec<f32> = slots
                .iter()
                .flat_map(|&s| &self.data[s * stride..(s + 1) * stride])
                .copied()
                .collect();
            write_section(out, &meta)?;
            write_section(out, &data)?;
        }
        Ok(())
    }

    /// Restores what [`ReplayStore::save`] wrote for a store of the same layout and capacity:
    /// the same steps in the same order, so sampling continues exactly.
    pub fn load(&mut self, input: &mut impl std::io::Read) -> Result<(), SnapshotError> {
        let stride = self.layout.stride();
        let mut filled = vec![0u64; self.filled.len()];
        read_section(input, "replay fill counts", &mut filled)?;
        for (c, &count) in filled.iter().enumerate() {
            let count = count as usize;
            if count > self.segment {
                return Err(SnapshotError::Mismatch {
                    what: "replay steps of one copy",
                    found: count,
                    expected: self.segment,
                });
            }
            let base = c * self.segment;
            read_section(input, "replay metadata", &mut self.meta[base..base + count])?;
            read_section(
                input,
                "replay steps",
                &mut self.data[base * stride..(base + count) * stride],
            )?;
            self.filled[c] = count;
            self.head[c] = count % self.segment;
        }
        Ok(())
    }

    /// Steps held (context and final states included).
    pub fn len(&self) -> usize {
        self.filled.iter().sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stores what the last step of `batch` completed, flagging the copies whose episode the
    /// simulation's divergence ended (training's one way in); returns how many there were.
    pub fn push_step(&mut self, batch: &super::DelayedBatch) -> Result<u64, ReplayError> {
        let diverged = batch.env().diverged();
        self.push(batch.layer().records(), diverged)?;
        Ok(diverged.iter().filter(|&&d| d != 0).count() as u64)
    }

    /// Appends the records of one step of the delay layer. `diverged` (`[N]`) flags the copies whose
    /// episode that step ended by the simulation's divergence: their last step is kept as the
    /// context of the steps before it but never sampled as a transition.
    pub fn push(&mut self, records: &RecordBatch, diverged: &[u32]) -> Result<(), ReplayError> {
        if records.layout != self.layout {
            return Err(ReplayError::LayoutMismatch {
                found: records.layout,
                expected: self.layout,
            });
        }
        let stride = self.layout.stride();
        for record in records.iter() {
            let c = record.copy;
            let slot = c * self.segment + self.head[c];
            let last_step = record.meta.flags & RECORD_TRUNCATED != 0 && !record.is_final_state();
            let ended_by_divergence = last_step && diverged.get(c).is_some_and(|&d| d != 0);
            self.meta[slot] = StepMeta {
                episode: record.meta.episode,
                tau: record.meta.tau,
                flags: record.meta.flags
                    | if ended_by_divergence {
                        RECORD_DIVERGED
                    } else {
                        0
                    },
            };
            let row = &mut self.data[slot * stride..(slot + 1) * stride];
            row[..self.layout.obs_dim].copy_from_slice(record.state);
            row[self.layout.obs_dim..stride - 1].copy_from_slice(record.action);
            row[stride - 1] = record.reward;
            self.head[c] = (self.head[c] + 1) % self.segment;
            self.filled[c] = (self.filled[c] + 1).min(self.segment);
        }
        Ok(())
    }

    /// Physical slot of the `i`-th oldest step of copy `c`.
    fn slot(&self, c: usize, i: usize) -> usize {
        c * self.segment + (self.head[c] + self.segment - self.filled[c] + i) % self.segment
    }

    /// Whether the `i`-th oldest step of copy `c` is a transition whose context is stored: the
    /// Δ steps before it and the step after it, of the same episode.
    fn is_complete(&self, c: usize, i: usize) -> bool {
        let d = self.layout.delay;
        let m = self.meta[self.slot(c, i)];
        if m.flags & (RECORD_FINAL_STATE | RECORD_DIVERGED) != 0
            || (m.tau as usize) < d
            || i < d
            || i + 1 >= self.filled[c]
        {
            return false;
        }
        let before = self.meta[self.slot(c, i - d)];
        let after = self.meta[self.slot(c, i + 1)];
        before.episode == m.episode
            && before.tau + d as u32 == m.tau
            && after.episode == m.episode
            && after.tau == m.tau + 1
    }

    /// Rebuilds the transition at the `i`-th oldest step of copy `c` into `out`, with the
    /// optional fields in `extras`.
    fn rebuild(&self, c: usize, i: usize, extras: BatchExtras, out: &mut Transitions) {
        let l = self.layout;
        let (stride, obs, act) = (l.stride(), l.obs_dim, l.act_dim);
        let row = |k: usize| &self.data[self.slot(c, k) * stride..(self.slot(c, k) + 1) * stride];
        let m = self.meta[self.slot(c, i)];
        out.copy.push(c);
        out.episode.push(m.episode);
        out.tau.push(m.tau);
        let at = out.augmented.len();
        l.push_augmented(|k| row(i - l.delay + k), &mut out.augmented);
        out.state.extend_from_slice(&row(i)[..obs]);
        out.action.extend_from_slice(&row(i)[obs..obs + act]);
        out.reward.push(row(i)[stride - 1]);
        l.push_next_augmented(
            &out.augmented[at..],
            |k| row(i - l.delay + k),
            &mut out.next_augmented,
        );
        out.next_state.extend_from_slice(&row(i + 1)[..obs]);
        out.terminated
            .push(u32::from(m.flags & RECORD_TERMINATED != 0));
        if extras.intermediate_states {
            for k in i + 1 - l.delay..=i {
                out.intermediate_states.extend_from_slice(&row(k)[..obs]);
            }
        }
    }

    /// `batch` transitions drawn uniformly (with replacement) from the complete ones.
    pub fn sample(&self, batch: usize, rng: &mut impl Rng) -> Result<Transitions, ReplayError> {
        self.sample_with(batch, rng, BatchExtras::default())
    }

    /// [`ReplayStore::sample`] with the optional fields in `extras` (the same draws).
    pub fn sample_with(
        &self,
        batch: usize,
        rng: &mut impl Rng,
        extras: BatchExtras,
    ) -> Result<Transitions, ReplayError> {
        let total = self.len();
        if total == 0 {
            return Err(ReplayError::Empty);
        }
        let mut out = Transitions::with_capacity(&self.layout, batch);
        let mut misses = 0usize;
        while out.len() < batch {
            // Uniform over stored steps, then rejection of the few that are not transitions
            // (warm-up context, final states, steps whose context was overwritten).
            let mut g = rng.random_range(0..total);
            let c = self
                .filled
                .iter()
                .position(|&f| {
                    if g < f {
                        true
                    } else {
                        g -= f;
                        false
                    }
                })
                .expect("g < total");
            if self.is_complete(c, g) {
                self.rebuild(c, g, extras, &mut out);
            } else {
                misses += 1;
                if misses > 1000 * batch.max(1) {
                    return Err(ReplayError::Empty);
                }
            }
        }
        Ok(out)
    }

    /// Every complete transition held, copy by copy, oldest first.
    pub fn all(&self) -> Transitions {
        let mut out = Transitions::default();
        for c in 0..self.layout.copies {
            for i in 0..self.filled[c] {
                if self.is_complete(c, i) {
                    self.rebuild(c, i, BatchExtras::default(), &mut out);
                }
            }
        }
        out
    }
}
