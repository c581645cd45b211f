//! The interface shared by every finite MDP in this module (the base MDP `M`, the augmented MDP
//! `M_Δ` and the abstract MDP `M̄_Δ`), so that value iteration, policy evaluation, the
//! homomorphism checks and Q-learning run on any of them.

/// A finite, discounted MDP with the same action set in every state (the paper's assumption
/// `A_s = A`, section 2.1). States are `0..num_states()`, actions `0..num_actions()`.
///
/// `reward` and `successors` index directly and panic on out-of-range arguments, like slices.
pub trait TabularModel {
    /// Number of states.
    fn num_states(&self) -> usize;

    /// Number of actions (identical in every state).
    fn num_actions(&self) -> usize;

    /// Discount factor `γ ∈ [0, 1)`.
    fn gamma(&self) -> f64;

    /// Expected immediate reward `R(state, action)`.
    fn reward(&self, state: usize, action: usize) -> f64;

    /// The next states with positive probability and their probabilities `P(next | state,
    /// action)`, in increasing order of next state.
    fn successors(&self, state: usize, action: usize) -> impl Iterator<Item = (usize, f64)> + '_;
}
