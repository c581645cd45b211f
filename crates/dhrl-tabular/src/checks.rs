//! The two conditions under which a partition induces an MDP homomorphism (the definitions that
//! open appendix A, after Ravindran and Barto): the partition is reward-respecting and has the
//! stochastic substitution property (SSP). Prop. 3.3 states both for the belief-equivalence
//! partition under deterministic dynamics.
//!
//! (The paper's appendix numbering: A.1–A.3 prove Prop. 3.3, Prop. 3.5 and Cor. 3.6, A.4 proves
//! Prop. 4.2 and A.5 constructs the approximate abstract MDP.)

use serde::Serialize;

use crate::error::TabularError;
use crate::model::TabularModel;
use crate::partition::{Partition, check_partition_size};
use crate::quotient::block_distribution;
use crate::sparse::{SparseAccumulator, max_abs_difference};

/// Default tolerance of the checks. Reward differences up to `tolerance·max(1, max |R|)` count as
/// equal (relative to the reward scale); block-transition probabilities, which lie in `[0, 1]`,
/// are compared with the absolute `tolerance`.
pub const CHECK_TOLERANCE: f64 = 1e-9;

/// The outcome of [`check_homomorphism`] (with the identity action map, so the state-action
/// blocks are `block × {a}`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct HomomorphismCheck {
    /// `x ≡ x'` implies `R(x, a) = R(x', a)` for every action (appendix A, reward-respecting
    /// partition), up to `tolerance·max(1, max |R|)`.
    pub reward_respecting: bool,
    /// `x ≡ x'` implies `P(G|x, a) = P(G|x', a)` for every block `G` and action (appendix A,
    /// stochastic substitution property), up to the absolute `tolerance`.
    pub ssp: bool,
    /// Largest `|R(x, a) − R(x₀, a)|` over the members `x` of a block and its first member `x₀`.
    pub max_reward_difference: f64,
    /// Largest `|P(G|x, a) − P(G|x₀, a)|` over members `x`, first members `x₀`, blocks `G`.
    pub max_transition_difference: f64,
}

/// Checks whether `partition` of `model`'s states is reward-respecting and has the SSP, treating
/// reward differences up to `tolerance·max(1, max |R|)` and block-transition differences up to
/// `tolerance` as equal (see [`CHECK_TOLERANCE`]).
///
/// # Errors
/// [`TabularError::ShapeMismatch`] when the partition does not cover the model's states,
/// [`TabularError::InvalidParameter`] for a negative or non-finite tolerance.
pub fn check_homomorphism<M: TabularModel>(
    model: &M,
    partition: &Partition,
    tolerance: f64,
) -> Result<HomomorphismCheck, TabularError> {
    check_partition_size(model, partition)?;
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(TabularError::InvalidParameter {
            name: "check tolerance",
            value: tolerance.to_string(),
            accepted: "a finite number >= 0".to_string(),
        });
    }
    let mut accumulator = SparseAccumulator::new(partition.num_blocks());
    let mut max_reward_difference = 0.0f64;
    let mut max_transition_difference = 0.0f64;
    for block in 0..partition.num_blocks() {
        let members = partition.members(block);
        let Some((&first, rest)) = members.split_first() else {
            continue;
        };
        for action in 0..model.num_actions() {
            let reference_reward = model.reward(first, action);
            let reference = block_distribution(model, partition, first, action, &mut accumulator);
            for &x in rest {
                let reward_gap = (model.reward(x, action) - reference_reward).abs();
                max_reward_difference = max_reward_difference.max(reward_gap);
                let distribution =
                    block_distribution(model, partition, x, action, &mut accumulator);
                max_transition_difference =
                    max_transition_difference.max(max_abs_difference(&distribution, &reference));
            }
        }
    }
    let mut max_abs_reward = 0.0f64;
    for state in 0..model.num_states() {
        for action in 0..model.num_actions() {
            max_abs_reward = max_abs_reward.max(model.reward(state, action).abs());
        }
    }
    let reward_tolerance = tolerance * max_abs_reward.max(1.0);
    Ok(HomomorphismCheck {
        reward_respecting: max_reward_difference <= reward_tolerance,
        ssp: max_transition_difference <= tolerance,
        max_reward_difference,
        max_transition_difference,
    })
}
