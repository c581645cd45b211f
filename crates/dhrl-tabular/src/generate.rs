//! Seeded random finite MDPs for `dhrl tabular --random` and the sample-complexity benchmark.

use std::collections::TryReserveError;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::augmented::table_entries;
use crate::error::TabularError;
use crate::mdp::FiniteMdp;

/// The table that [`random_mdp`] allocates, as named in its errors.
const TABLE: &str = "transition rows |S|*|A|";

/// What [`random_mdp`] generates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RandomMdpSpec {
    /// `|S| ≥ 1`.
    pub states: usize,
    /// `|A| ≥ 1`.
    pub actions: usize,
    /// `γ ∈ [0, 1)`.
    pub gamma: f64,
    /// Probability mass moved from the main next state to one other, uniformly chosen next state
    /// (0 gives deterministic dynamics).
    pub stochastic: f64,
    /// Seed of the ChaCha8 generator.
    pub seed: u64,
}

/// A random MDP: for every `(s, a)` the reward is uniform in `[0, 1)` and the main next state is
/// uniform over `S`; with `stochastic = p > 0`, mass `p` moves to another uniformly chosen state.
///
/// The generator does not know the delay: callers that go on to build an augmented MDP should
/// check its size first (as `dhrl tabular --random` does), so that an oversized request fails
/// before any table is generated.
///
/// # Errors
/// [`TabularError::NoStates`], [`TabularError::NoActions`], [`TabularError::InvalidGamma`],
/// [`TabularError::InvalidParameter`] for `p ∉ [0, 1]` or `p > 0` with a single state, and
/// [`TabularError::TableTooLarge`] when the `|S|·|A|` rows overflow or cannot be allocated.
pub fn random_mdp(spec: &RandomMdpSpec) -> Result<FiniteMdp, TabularError> {
    if spec.states == 0 {
        return Err(TabularError::NoStates);
    }
    if spec.actions == 0 {
        return Err(TabularError::NoActions);
    }
    if !(0.0..=1.0).contains(&spec.stochastic) {
        return Err(TabularError::InvalidParameter {
            name: "stochastic",
            value: spec.stochastic.to_string(),
            accepted: "a probability mass in [0, 1]".to_string(),
        });
    }
    if spec.stochastic > 0.0 && spec.states < 2 {
        return Err(TabularError::InvalidParameter {
            name: "stochastic",
            value: spec.stochastic.to_string(),
            accepted: "0 for a single-state MDP (there is no other next state to move mass to)"
                .to_string(),
        });
    }
    let pairs = table_entries(TABLE, spec.states, spec.actions)?;
    let too_large = |_: TryReserveError| TabularError::TableTooLarge {
        table: TABLE,
        states: spec.states,
        actions: spec.actions,
        entries: pairs as u128,
    };
    let mut rows: Vec<Vec<(usize, f64)>> = Vec::new();
    rows.try_reserve_exact(pairs).map_err(too_large)?;
    let mut rewards: Vec<f64> = Vec::new();
    rewards.try_reserve_exact(pairs).map_err(too_large)?;
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    for _ in 0..pairs {
        rewards.push(rng.random::<f64>());
        let main = rng.random_range(0..spec.states);
        if spec.stochastic > 0.0 {
            let mut other = rng.random_range(0..spec.states - 1);
            if other >= main {
                other += 1;
            }
            rows.push(vec![
                (main, 1.0 - spec.stochastic),
                (other, spec.stochastic),
            ]);
        } else {
            rows.push(vec![(main, 1.0)]);
        }
    }
    FiniteMdp::from_sparse(spec.states, spec.actions, spec.gamma, rows, rewards)
}
