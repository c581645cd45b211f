//! The actions executed before the first observation arrives.
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::check_len;
use super::{DelayError, WarmupActions};

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

    /// Draws by `kind` from now on (the stream goes on where it is).
    pub fn set_kind(&mut self, kind: WarmupActions) {
        self.kind = kind;
    }

    pub fn rng(&self) -> &ChaCha8Rng {
        &self.rng
    }

    pub fn rng_mut(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }

    /// Overwrites the rows of `actions` (`[N, act_dim]`, one per `ready` flag) whose flag is 0.
    pub fn fill(&mut self, actions: &mut [f32], ready: &[u32]) -> Result<(), DelayError> {
        let act = self.low.len();
        check_len("actions", actions.len(), ready.len() * act)?;
        for (row, &ready) in actions.chunks_mut(act).zip(ready) {
            if ready == 0 {
                for (j, a) in row.iter_mut().enumerate() {
                    *a = match self.kind {
                        WarmupActions::Random => self.rng.random_range(self.low[j]..=self.high[j]),
                        WarmupActions::Zeros => 0.0,
                    };
                }
            }
        }
        Ok(())
    }
}
