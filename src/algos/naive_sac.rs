//! Naive SAC: the memoryless baseline. The policy acts on the last received observation
//! `s_{t-Δ}` alone, ignoring the actions still in flight, and learns from
//! `(s_{t-Δ}, a_t, r_t, s_{t-Δ+1})` as if that were an MDP — it is not, which is why it fails
//! at long delays. Everything else is [`super::sac`]'s update.
use super::sac::{InputView, SacAgent};
use super::{AgentSpec, Hyper};
use crate::learn::Devices;

pub fn naive_sac(spec: &AgentSpec, hyper: &Hyper, devices: &Devices, seed: u64) -> SacAgent {
    SacAgent::new(InputView::LastObservation, spec, hyper, devices, seed)
}
