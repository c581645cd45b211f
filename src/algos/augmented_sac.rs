//! Augmented SAC: the canonical state augmentation. Actor and critic take the augmented
//! state `x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1})`, which makes the delayed problem an MDP again
//! at the price of an input that grows with Δ; training uses `(x_t, a_t, r_t, x_{t+1})`.
//! Everything else is [`super::sac`]'s update.
use super::sac::{InputView, SacAgent};
use super::{AgentSpec, Hyper};
use crate::learn::Devices;

pub fn augmented_sac(spec: &AgentSpec, hyper: &Hyper, devices: &Devices, seed: u64) -> SacAgent {
    SacAgent::new(InputView::Augmented, spec, hyper, devices, seed)
}
