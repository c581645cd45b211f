//! The data type of the whole learning side: time-aligned transitions, produced by the replay
//! and by both delay layers, consumed by every algorithm.
use super::layout::DelayLayout;

/// Time-aligned transitions `(x_τ, s_τ, a_τ, r_τ, x_{τ+1}, s_{τ+1}, terminated_{τ+1})`, one row
/// each, for every record of a step with `τ ≥ Δ` (where `x_τ` exists).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Transitions {
    pub copy: Vec<usize>,
    pub episode: Vec<u32>,
    pub tau: Vec<u32>,
    pub augmented: Vec<f32>,
    pub state: Vec<f32>,
    pub action: Vec<f32>,
    pub reward: Vec<f32>,
    pub next_augmented: Vec<f32>,
    pub next_state: Vec<f32>,
    /// 1 where the MDP ended (no bootstrapping); truncation is 0 (bootstrap).
    pub terminated: Vec<u32>,
    /// `[B, Δ, obs]`: the true states `s_{τ-Δ+1} … s_τ` between the observation inside `x_τ`
    /// and `s_τ`, when asked for ([`BatchExtras::intermediate_states`]); empty otherwise.
    pub intermediate_states: Vec<f32>,
}

/// Optional fields of sampled batches, rebuilt from the replay's step records on request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BatchExtras {
    /// [`Transitions::intermediate_states`].
    pub intermediate_states: bool,
}

impl Transitions {
    /// Empty, with room for `rows` transitions of `layout` (without optional fields).
    pub fn with_capacity(layout: &DelayLayout, rows: usize) -> Transitions {
        let (aug, obs, act) = (layout.augmented_dim(), layout.obs_dim, layout.act_dim);
        Transitions {
            copy: Vec::with_capacity(rows),
            episode: Vec::with_capacity(rows),
            tau: Vec::with_capacity(rows),
            augmented: Vec::with_capacity(rows * aug),
            state: Vec::with_capacity(rows * obs),
            action: Vec::with_capacity(rows * act),
            reward: Vec::with_capacity(rows),
            next_augmented: Vec::with_capacity(rows * aug),
            next_state: Vec::with_capacity(rows * obs),
            terminated: Vec::with_capacity(rows),
            intermediate_states: Vec::new(),
        }
    }
    pub fn len(&self) -> usize {
        self.copy.len()
    }
    pub fn is_empty(&self) -> bool {
        self.copy.is_empty()
    }
}
