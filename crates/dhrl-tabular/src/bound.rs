//! The value-loss bound of Lemma 3.7 for the lifted optimal policy of an (approximate) abstract
//! MDP:
//!
//! `‖V*_{M_Δ} − V^{(π̄*_ε)↑}_{M_Δ}‖_∞ ≤ 2/(1−γ) · (C1 + γ·ξ_ε/(2(1−γ)) · C2)`, with
//!
//! * `C1 = max_{(x,a)} |R_Δ(x, a) − R̄_ε(f(x), g(a))|`,
//! * `C2 = max_{(x,a)} Σ_{x̄'} |Σ_{y: f(y) = x̄'} P_Δ(y|x, a) − P̄_ε(x̄'|f(x), g(a))|`,
//! * `ξ_ε = max R̄_ε − min R̄_ε`, the range of the abstract reward.

use serde::Serialize;

use crate::error::TabularError;
use crate::model::TabularModel;
use crate::partition::check_partition_size;
use crate::quotient::{QuotientMdp, block_distribution};
use crate::sparse::{SparseAccumulator, l1_distance};

/// The terms and the value of the Lemma 3.7 bound.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ValueLossBound {
    /// Largest reward discrepancy `C1`.
    pub c1: f64,
    /// Largest block-transition discrepancy `C2` (an L1 distance, at most 2).
    pub c2: f64,
    /// Range `ξ` of the abstract reward.
    pub xi: f64,
    /// The discount factor used.
    pub gamma: f64,
    /// `2/(1−γ) · (C1 + γ ξ C2 / (2(1−γ)))`.
    pub bound: f64,
}

/// Computes the Lemma 3.7 bound for `model` (the augmented MDP `M_Δ`, or any model) and a quotient
/// of it built from a partition of its states.
///
/// # Errors
/// [`TabularError::ShapeMismatch`] when the quotient's partition does not cover the model's states
/// or the action counts differ.
pub fn value_loss_bound<M: TabularModel>(
    model: &M,
    quotient: &QuotientMdp,
) -> Result<ValueLossBound, TabularError> {
    let partition = quotient.partition();
    check_partition_size(model, partition)?;
    let abstract_mdp = quotient.abstract_mdp();
    if abstract_mdp.num_actions() != model.num_actions() {
        return Err(TabularError::ShapeMismatch {
            location: "quotient actions".to_string(),
            found: abstract_mdp.num_actions(),
            expected: model.num_actions(),
            unit: "actions (the model's action count)",
        });
    }
    let mut accumulator = SparseAccumulator::new(partition.num_blocks());
    let (mut c1, mut c2) = (0.0f64, 0.0f64);
    for x in 0..model.num_states() {
        let block = quotient.state_map(x);
        for action in 0..model.num_actions() {
            let abstract_action = quotient.action_map(action);
            let reward_gap =
                (model.reward(x, action) - abstract_mdp.reward(block, abstract_action)).abs();
            c1 = c1.max(reward_gap);
            let aggregated = block_distribution(model, partition, x, action, &mut accumulator);
            let abstract_row: Vec<(usize, f64)> =
                abstract_mdp.successors(block, abstract_action).collect();
            c2 = c2.max(l1_distance(&aggregated, &abstract_row));
        }
    }
    let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
    for block in 0..abstract_mdp.num_states() {
        for action in 0..abstract_mdp.num_actions() {
            let reward = abstract_mdp.reward(block, action);
            low = low.min(reward);
            high = high.max(reward);
        }
    }
    let xi = high - low;
    let gamma = model.gamma();
    let bound = 2.0 / (1.0 - gamma) * (c1 + gamma * xi * c2 / (2.0 * (1.0 - gamma)));
    Ok(ValueLossBound {
        c1,
        c2,
        xi,
        gamma,
        bound,
    })
}
