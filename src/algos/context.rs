//! What an update sees: where its batches come from, and where training stands.
use rand_chacha::ChaCha8Rng;

use crate::delay::{BatchExtras, ReplayError, ReplayStore, Transitions};

enum Source<'a> {
    /// Uniform draws from the replay (training).
    Replay {
        replay: &'a ReplayStore,
        rng: &'a mut ChaCha8Rng,
        extras: BatchExtras,
    },
    /// The same batch on every draw (tests and update benchmarks).
    Fixed(&'a Transitions),
}

/// Handed to [`super::agent::Agent::update`]: an agent draws as many batches as it needs (with the
/// optional fields it declared in [`super::agent::Agent::batch_extras`]) and may schedule work by the
/// counters.
pub struct UpdateContext<'a> {
    source: Source<'a>,
    /// The configured batch size.
    pub batch_size: usize,
    /// Environment steps taken so far (all copies together).
    pub env_steps: u64,
    /// Updates completed before this one.
    pub updates: u64,
}

impl<'a> UpdateContext<'a> {
    /// Draws from `replay` with `rng`, with the optional fields `extras`.
    pub fn replay(
        replay: &'a ReplayStore,
        rng: &'a mut ChaCha8Rng,
        extras: BatchExtras,
        batch_size: usize,
        env_steps: u64,
        updates: u64,
    ) -> UpdateContext<'a> {
        UpdateContext {
            source: Source::Replay {
                replay,
                rng,
                extras,
            },
            batch_size,
            env_steps,
            updates,
        }
    }

    /// Every draw returns `batch` itself, whatever the size asked (it must carry the optional
    /// fields the agent uses).
    pub fn fixed(batch: &'a Transitions, env_steps: u64, updates: u64) -> UpdateContext<'a> {
        UpdateContext {
            source: Source::Fixed(batch),
            batch_size: batch.len(),
            env_steps,
            updates,
        }
    }

    /// A batch of the configured size.
    pub fn batch(&mut self) -> Result<Transitions, ReplayError> {
        self.sample(self.batch_size)
    }

    /// A batch of each run of a stack, run `i`'s from `contexts[i]`.
    pub fn batches(contexts: &mut [UpdateContext<'_>]) -> Result<Vec<Transitions>, ReplayError> {
        contexts.iter_mut().map(UpdateContext::batch).collect()
    }

    /// `n` transitions drawn uniformly from the complete ones (with replacement).
    pub fn sample(&mut self, n: usize) -> Result<Transitions, ReplayError> {
        match &mut self.source {
            Source::Replay {
                replay,
                rng,
                extras,
            } => replay.sample_with(n, *rng, *extras),
            Source::Fixed(batch) => Ok((*batch).clone()),
        }
    }
}
