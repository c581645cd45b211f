//! Augmented SAC: the canonical state augmentation. Actor and critic take the augmented
//! state `x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1})`, which makes the delayed problem an MDP again
//! at the price of an input that grows with Δ; training uses `(x_t, a_t, r_t, x_{t+1})`.
//! Everything else is [`super::sac`]'s update.
use super::agent::{Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo};
use super::sac::Config as SacConfig;
use super::sac::{InputView, SacAgent};
use crate::learn::Devices;

crate::algo_config! {
    /// Augmented SAC's configuration: SAC's.
    pub struct Config {
        ..sac: SacConfig;
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo::single_learner(
        "augmented-sac",
        "Augmented SAC",
        "SAC with actor and critic on the augmented state x_t",
        true,
    );

    fn validate(&self) -> Result<(), AlgoError> {
        self.sac.check(Self::INFO.name)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(SacAgent::stacked(
            InputView::Augmented,
            spec,
            &self.sac,
            devices,
            seeds,
        ))
    }
}
