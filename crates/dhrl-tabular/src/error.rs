//! The single error type of the finite-domain DHRL library.

use std::path::PathBuf;

/// Everything that can go wrong in this crate. Every message says what was wrong and what
/// is accepted instead.
#[derive(Debug, thiserror::Error)]
pub enum TabularError {
    /// The MDP lists no states.
    #[error("the MDP has no states; accepted: at least one state")]
    NoStates,

    /// The MDP lists no actions.
    #[error("the MDP has no actions; accepted: at least one action, the same set in every state")]
    NoActions,

    /// A nested list or vector does not have the length its context requires.
    #[error("shape mismatch: {location} has {found} {unit}, expected {expected}")]
    ShapeMismatch {
        /// Where the mismatch was found, e.g. `transitions[3][1]`.
        location: String,
        /// The length that was found.
        found: usize,
        /// The length that was expected.
        expected: usize,
        /// What the entries are, e.g. `next-state probabilities`.
        unit: &'static str,
    },

    /// The discount factor is outside `[0, 1)` (or not a number).
    #[error("discount factor gamma = {gamma} is invalid; accepted: a number with 0 <= gamma < 1")]
    InvalidGamma {
        /// The rejected discount factor.
        gamma: f64,
    },

    /// A transition probability is negative, above one or not finite.
    #[error(
        "transition probability P(next state {next_state} | state {state}, action {action}) = \
         {value} is invalid; accepted: a finite number in [0, 1]"
    )]
    InvalidProbability {
        /// Source state.
        state: usize,
        /// Action.
        action: usize,
        /// Next state.
        next_state: usize,
        /// The rejected probability.
        value: f64,
    },

    /// A sparse transition row names a next state that does not exist.
    #[error(
        "the transition row of state {state}, action {action} names next state {next_state}, but \
         the MDP has {num_states} states; accepted: next states 0..{num_states}"
    )]
    InvalidNextState {
        /// Source state.
        state: usize,
        /// Action.
        action: usize,
        /// The rejected next state.
        next_state: usize,
        /// Number of states of the MDP.
        num_states: usize,
    },

    /// A transition row does not sum to one.
    #[error(
        "the transition probabilities of state {state}, action {action} sum to {sum}; accepted: a \
         sum within 1e-9 of 1"
    )]
    RowSum {
        /// Source state.
        state: usize,
        /// Action.
        action: usize,
        /// The sum that was found.
        sum: f64,
    },

    /// A reward is NaN or infinite.
    #[error(
        "reward R(state {state}, action {action}) = {value} is not finite; accepted: any finite number"
    )]
    InvalidReward {
        /// State.
        state: usize,
        /// Action.
        action: usize,
        /// The rejected reward.
        value: f64,
    },

    /// The augmented state space `|S|·|A|^Δ` is above the configured limit.
    #[error(
        "the augmented state space |S|*|A|^delay = {states}*{actions}^{delay} = {augmented_states} \
         exceeds the limit of {limit} augmented states; accepted: at most {limit} (lower the delay \
         or the number of actions, or raise the limit)"
    )]
    TooLarge {
        /// `|S|`.
        states: usize,
        /// `|A|`.
        actions: usize,
        /// `Δ`.
        delay: usize,
        /// `|S|·|A|^Δ`, saturated at `u128::MAX`.
        augmented_states: u128,
        /// The configured limit.
        limit: usize,
    },

    /// A table whose entry count follows from the sizes (the `|S|·|A|` transition rows of a
    /// generated MDP, the `|X|·|A|` belief-expected rewards of an augmented MDP) overflows the
    /// address space or cannot be allocated.
    #[error(
        "the {table} of {states} states and {actions} actions needs {entries} entries, more than \
         this machine can address or allocate; accepted: fewer states or actions (or a lower delay)"
    )]
    TableTooLarge {
        /// Which table, e.g. `transition rows |S|*|A|`.
        table: &'static str,
        /// Number of states (`|S|`, or `|X|` for augmented tables).
        states: usize,
        /// `|A|`.
        actions: usize,
        /// The number of entries the table would need, saturated at `u128::MAX`.
        entries: u128,
    },

    /// A numeric parameter (epsilon, a weight, a learning setting, …) is out of range.
    #[error("{name} = {value} is invalid; accepted: {accepted}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// The rejected value, as text.
        value: String,
        /// What would have been accepted.
        accepted: String,
    },

    /// An index (state, action, augmented state) is out of range.
    #[error("{what} index {index} is out of range; accepted: 0..{bound}")]
    IndexOutOfRange {
        /// What kind of index.
        what: &'static str,
        /// The rejected index.
        index: usize,
        /// One past the largest valid index.
        bound: usize,
    },

    /// An iterative solver stopped before reaching its tolerance. Each sweep shrinks the error by
    /// the factor `γ`, so the sweeps needed grow like `1/(1−γ)`; the message names `γ` and the
    /// estimate.
    #[error(
        "{what} did not converge: stopped after {iterations} of at most {limit} sweeps (last \
         change {residual:e}); with gamma = {gamma} reaching the solver tolerance takes about \
         {needed} sweeps, and {reason}; accepted: a smaller gamma (the discount factor of the \
         MDP: each sweep only shrinks the error by the factor gamma), or, through the library, a \
         looser SolveOptions::tolerance or a larger SolveOptions::max_iterations"
    )]
    NotConverged {
        /// Which solver.
        what: &'static str,
        /// Sweeps performed.
        iterations: usize,
        /// The sweep limit in force (see [`crate::SolveOptions`]).
        limit: usize,
        /// Sweeps the `γ`-contraction bound needs from the first sweep's change to the tolerance.
        needed: usize,
        /// The discount factor `γ`.
        gamma: f64,
        /// The last sup-norm change between iterates.
        residual: f64,
        /// Why the solver stopped, in words.
        reason: &'static str,
    },

    /// The MDP JSON could not be parsed.
    #[error(
        "invalid MDP JSON: {source}; accepted: {{\"gamma\": g, \"transitions\": [[[p(s'|s,a) for s'] \
         for a] for s], \"rewards\": [[r(s,a) for a] for s]}}"
    )]
    Json {
        /// The parser error.
        source: serde_json::Error,
    },

    /// The MDP file could not be read.
    #[error("cannot read MDP file {}: {source}; accepted: a readable JSON file", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },

    /// The benchmark plot could not be written.
    #[error("cannot write plot {}: {message}; accepted: a writable .svg path", .path.display())]
    Plot {
        /// The output file.
        path: PathBuf,
        /// What the plotting backend reported.
        message: String,
    },
}
