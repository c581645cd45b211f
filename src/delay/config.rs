//! What the agent's delay is, checked once.
use serde::{Deserialize, Serialize};

/// The largest total delay the layer supports (ring buffers hold 2Δ + 3 slots per copy).
pub const MAX_DELAY: usize = 64;

/// What is executed for `t < Δ`, before any observation has arrived (docs/DESIGN.md §1.3).
///
/// Zeros by default: on InvertedPendulum a random warm-up ends 56% of the episodes at Δ = 5
/// (88% at Δ = 10) before any policy acts, which caps every policy's mean return far below the
/// paper's published ones; the paper group's BPQL code executes zeros
/// (docs/results/warmup-evidence.md, `scripts/warmup_evidence.py`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum WarmupActions {
    /// Uniform random in the action bounds (the paper's Algorithm 1 as written).
    Random,
    /// All zeros (what the paper's published numbers need; the BPQL reference code).
    #[default]
    Zeros,
}

/// The delay the agent lives with.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DelayConfig {
    /// Steps between a state and its observation reaching the agent (with its reward and flags).
    pub observation_delay: usize,
    /// Steps between choosing an action and its execution.
    pub action_delay: usize,
    /// Random observation delays: each observation's delay is drawn from `{1..=max}` and
    /// observations may arrive out of order; the conservative agent holds each one until it is
    /// exactly `max` old. Replaces `observation_delay`.
    pub random_delay: bool,
    /// The bound `Δ_max` of random delays.
    pub max_random_delay: Option<usize>,
    /// σ of Gaussian actuator noise on the executed action (`clip(a + N(0, σ²))`).
    pub actuator_noise: f64,
    /// What is executed before the first observation arrives.
    pub warmup: WarmupActions,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DelayError {
    #[error(
        "a random observation delay needs its bound: set max_random_delay (--max-delay) to an integer in 1..={MAX_DELAY}"
    )]
    RandomDelayWithoutBound,
    #[error(
        "max_random_delay (--max-delay) is {0}, but only random delays have a bound; add random_delay (--random-delay) or drop it"
    )]
    BoundWithoutRandomDelay(usize),
    #[error("choose a fixed observation delay ({0}) or a random one, not both")]
    FixedAndRandomObservationDelay(usize),
    #[error("the random delay bound must be at least 1, got 0")]
    ZeroRandomBound,
    #[error("total delay {total} is above the supported maximum {MAX_DELAY}")]
    TooLong { total: usize },
    #[error("actuator noise σ must be a finite number ≥ 0, got {0}")]
    BadNoise(f64),
    #[error("the GPU delay layer: {0}")]
    Gpu(String),
    #[error("{what} has length {found}, expected {expected}")]
    WrongLength {
        what: &'static str,
        found: usize,
        expected: usize,
    },
}

impl DelayConfig {
    /// A fixed observation delay of `delay` steps and nothing else.
    pub fn fixed(delay: usize) -> DelayConfig {
        DelayConfig {
            observation_delay: delay,
            ..DelayConfig::default()
        }
    }

    /// Checks the combination and returns the total delay Δ the agent sees: observation plus
    /// action delay (only the sum matters to the agent, and `x_t` has the same form), with a
    /// random observation delay counting as its bound (the conservative agent).
    pub fn total_delay(&self) -> Result<usize, DelayError> {
        if !(self.actuator_noise.is_finite() && self.actuator_noise >= 0.0) {
            return Err(DelayError::BadNoise(self.actuator_noise));
        }
        let observation = match (self.random_delay, self.max_random_delay) {
            (false, None) => self.observation_delay,
            (false, Some(bound)) => return Err(DelayError::BoundWithoutRandomDelay(bound)),
            (true, None) => return Err(DelayError::RandomDelayWithoutBound),
            (true, Some(_)) if self.observation_delay > 0 => {
                return Err(DelayError::FixedAndRandomObservationDelay(
                    self.observation_delay,
                ));
            }
            (true, Some(0)) => return Err(DelayError::ZeroRandomBound),
            (true, Some(bound)) => bound,
        };
        let total = observation + self.action_delay;
        if total > MAX_DELAY {
            return Err(DelayError::TooLong { total });
        }
        Ok(total)
    }

    /// `Δ_max` when observation delays are random.
    pub fn random_bound(&self) -> Option<usize> {
        self.max_random_delay.filter(|_| self.random_delay)
    }
}

/// The delay, in `{1..=bound}`, with which the observation of state `tau` of `episode` in copy
/// `copy` reaches the agent under random delays: a counter-based hash (PCG-style), so the draw is
/// the same whichever implementation or thread asks.
pub fn arrival_delay(seed: u64, copy: u32, episode: u32, tau: u32, bound: usize) -> usize {
    let mut x = seed ^ (u64::from(copy) << 40) ^ (u64::from(episode) << 20) ^ u64::from(tau);
    // splitmix64 finaliser
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    1 + (x % bound as u64) as usize
}

/// `Ok` when a buffer holds the `expected` number of values, else [`DelayError::WrongLength`].
pub(super) fn check_len(
    what: &'static str,
    found: usize,
    expected: usize,
) -> Result<(), DelayError> {
    if found == expected {
        Ok(())
    } else {
        Err(DelayError::WrongLength {
            what,
            found,
            expected,
        })
    }
}
