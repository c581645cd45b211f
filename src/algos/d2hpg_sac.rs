//! D2HPG-SAC: D2HPG with augmented SAC as its regular learner, the actor **and** the critic on
//! the augmented state `x_t` (`Q(x, a)`, the paper's `L_regular-critic`), instead of BPQL's
//! critic on the true state. It is the default agent of the authors' released code
//! (`--agent-type sac`, `agents/d2hpg_sac.py`); the paper's D2HPG is the BPQL form (`d2hpg.rs`).
//! Everything else — the delay-free SAC on the time-aligned `(s, a, r, s')`, the lifting loss
//! (Eq. 4), its schedule, K, noise and the shared temperature — is `d2hpg`'s, one update as
//! [`D2hpg`] runs it.
use serde::{Deserialize, Serialize};

use super::agent::{
    Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, ConfigFields, FieldDoc, Role,
};
use super::d2hpg::{Config as D2hpgConfig, D2HPG_INFO, D2hpg, Regular};
use crate::learn::Devices;
use crate::protocol::Protocol;

/// `d2hpg-sac`'s configuration: D2HPG's, field for field.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Config(pub D2hpgConfig);

impl ConfigFields for Config {
    fn field_docs() -> Vec<FieldDoc> {
        D2hpgConfig::field_docs()
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo {
        name: "d2hpg-sac",
        paper_name: "D2HPG-SAC",
        role: Role::Ablation,
        in_lifting_ablation: false,
        about: "D2HPG with augmented SAC (critic on x_t) as the regular learner: the authors' code's default agent",
        ..D2HPG_INFO
    };

    fn validate(&self) -> Result<(), AlgoError> {
        <D2hpgConfig as AlgoConfig>::validate(&self.0)
    }

    fn for_protocol(protocol: Protocol) -> Config {
        Config(D2hpgConfig::protocol_defaults(protocol))
    }

    fn for_budget(&self, steps: u64) -> Config {
        Config(self.0.for_budget(steps))
    }

    fn budget(&self) -> Option<u64> {
        self.0.budget()
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(D2hpg::new(
            Regular::AugmentedSac,
            &self.0,
            spec,
            devices,
            seeds,
        ))
    }
}
