//! The actions executed before the first observation arrives.
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::WarmupActions;

/// Draws warm-up actions for the copies that are not ready.
pub struct WarmupFiller {
    kind: WarmupActions,
    low: Vec<f32>,
    high: Vec<f32>,
    rng: ChaCha8Rng,
}

impl WarmupFiller {
    pub fn new(kind: WarmupActions, low: &[f64], high: &[f64], seed: u64) -> WarmupFiller {
        WarmupFiller {
            kind,
            low: low.iter().map(|&v| v as f32).collect(),
            high: high.iter().map(|&v| v as f32).collect(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    pub fn rng(&self) -> &ChaCha8Rng {
        &self.rng
    }

    pub fn rng_mut(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }

    /// Overwrites the rows of `actions` (`[N, act_dim]`) whose `ready` flag is 0.
    pub fn fill(&mut self, actions: &mut [f32], ready: impl Iterator<Item = bool>) {
        let act = self.low.len();
        for (row, ready) in actions.chunks_mut(act).zip(ready) {
            if !ready {
                for (j, a) in row.iter_mut().enumerate() {
                    *a = match self.kind {
                        WarmupActions::Random => self.rng.random_range(self.low[j]..=self.high[j]),
                        WarmupActions::Zeros => 0.0,
                    };
                }
            }
        }
    }
}
