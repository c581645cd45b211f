//! Naive SAC: the memoryless baseline. The policy acts on the last received observation
//! `s_{t-Δ}` alone, ignoring the actions still in flight, and learns from
//! `(s_{t-Δ}, a_t, r_t, s_{t-Δ+1})` as if that were an MDP — it is not, which is why it fails
//! at long delays. Everything else is [`super::sac`]'s update.
use super::agent::{Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo};
use super::sac::Config as SacConfig;
use super::sac::{InputView, SacAgent};
use crate::learn::Devices;

crate::algo_config! {
    /// Naive SAC's configuration: SAC's.
    pub struct Config {
        ..sac: SacConfig;
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo::single_learner(
        "naive-sac",
        "Naive SAC",
        "SAC on the last received observation s_{t-Δ} only (memoryless)",
        false,
    );

    fn validate(&self) -> Result<(), AlgoError> {
        self.sac.check(Self::INFO.name)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(SacAgent::stacked(
            InputView::LastObservation,
            spec,
            &self.sac,
            devices,
            seeds,
        ))
    }
}
