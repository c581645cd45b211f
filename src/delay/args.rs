//! The delay options shared by every command that runs a delayed environment.
use super::{DelayConfig, WarmupActions};

/// `--delay`, `--action-delay`, `--random-delay --max-delay`, `--actuator-noise`, `--warmup`.
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct DelayArgs {
    /// Observation delay Δ_o in steps (reward and done flags travel with the observation).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "STEPS", allow_negative_numbers = true)
    )]
    pub delay: Option<i64>,
    /// Action delay Δ_a in steps; the agent sees the total Δ = Δ_o + Δ_a.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "STEPS", allow_negative_numbers = true)
    )]
    pub action_delay: Option<i64>,
    /// Random observation delays in 1..=--max-delay, out of order; the conservative agent
    /// acts on observations exactly --max-delay old.
    #[cfg_attr(feature = "cli", arg(long))]
    pub random_delay: bool,
    /// The bound Δ_max of --random-delay.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "STEPS", allow_negative_numbers = true)
    )]
    pub max_delay: Option<i64>,
    /// σ of Gaussian actuator noise: the executed action is clip(a + N(0, σ²)).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "SIGMA", allow_negative_numbers = true)
    )]
    pub actuator_noise: Option<f64>,
    /// Actions executed before the first observation arrives: zeros (a new run's default) or
    /// random (the paper's Algorithm 1 as written, which caps InvertedPendulum far below its
    /// published returns).
    #[cfg_attr(feature = "cli", arg(long, value_enum))]
    pub warmup: Option<WarmupActions>,
}

#[derive(Debug, thiserror::Error, PartialEq)]
#[error("--{flag} must be a whole number of steps ≥ 0, got {value}")]
pub struct NegativeDelay {
    pub flag: &'static str,
    pub value: i64,
}

fn steps(flag: &'static str, value: Option<i64>) -> Result<Option<usize>, NegativeDelay> {
    value
        .map(|v| usize::try_from(v).map_err(|_| NegativeDelay { flag, value: v }))
        .transpose()
}

impl DelayArgs {
    /// Whether any delay option was given.
    pub fn any(&self) -> bool {
        self.sets_a_delay() || self.actuator_noise.is_some() || self.warmup.is_some()
    }

    /// Whether an option that sets the delay itself was given (not the noise or the warm-up).
    pub fn sets_a_delay(&self) -> bool {
        self.delay.is_some()
            || self.action_delay.is_some()
            || self.random_delay
            || self.max_delay.is_some()
    }

    /// The options laid over `base` (a config file's, or the default). Combinations are
    /// checked by [`DelayConfig::total_delay`].
    pub fn apply(&self, base: DelayConfig) -> Result<DelayConfig, NegativeDelay> {
        Ok(DelayConfig {
            observation_delay: steps("delay", self.delay)?.unwrap_or(base.observation_delay),
            action_delay: steps("action-delay", self.action_delay)?.unwrap_or(base.action_delay),
            random_delay: self.random_delay || base.random_delay,
            max_random_delay: steps("max-delay", self.max_delay)?.or(base.max_random_delay),
            actuator_noise: self.actuator_noise.unwrap_or(base.actuator_noise),
            warmup: self.warmup.unwrap_or(base.warmup),
        })
    }
}
