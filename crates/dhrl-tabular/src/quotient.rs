//! The quotient (abstract) MDP `M̄ = M/B` of a state partition, with the state map `f`, the
//! action map `g` (the identity, appendix A.5) and policy lifting (section 2.2, Lemma 3.7).
//!
//! The abstract reward and transition are the weighted averages of appendix A.5:
//! `R̄(x̄, ā) = Σ_{x ∈ x̄} w(x) R(x, ā)` and
//! `P̄(x̄'|x̄, ā) = Σ_{x ∈ x̄} w(x) Σ_{y: f(y) = x̄'} P(y|x, ā)`, with `w` uniform over each block
//! unless weights are given. For a reward-respecting SSP partition (Prop. 3.3) every member of a
//! block has the same reward and block-transition probabilities, so any weights give the exact
//! homomorphic image of Definition 3.1.

use crate::error::TabularError;
use crate::mdp::{FiniteMdp, TransitionRows};
use crate::model::TabularModel;
use crate::partition::{Partition, check_partition_size};
use crate::sparse::{SparseAccumulator, SparseDistribution};

/// `P(G|x, a) = Σ_{y ∈ G} P(y|x, a)` for every block `G` reached from `(x, a)`, sorted by block.
pub(crate) fn block_distribution<M: TabularModel>(
    model: &M,
    partition: &Partition,
    state: usize,
    action: usize,
    accumulator: &mut SparseAccumulator,
) -> SparseDistribution {
    for (next, p) in model.successors(state, action) {
        accumulator.add(partition.block_of(next), p);
    }
    accumulator.drain_sorted()
}

/// The abstract MDP `M̄` induced by a partition of a model's states, together with the partition
/// (the state map `f`).
#[derive(Clone, Debug)]
pub struct QuotientMdp {
    mdp: FiniteMdp,
    partition: Partition,
}

impl QuotientMdp {
    /// The quotient with uniform weights `w` over each block (this crate's default for the
    /// weights of appendix A.5).
    ///
    /// # Errors
    /// [`TabularError::ShapeMismatch`] when the partition does not cover the model's states.
    pub fn new<M: TabularModel>(model: &M, partition: &Partition) -> Result<Self, TabularError> {
        Self::build(model, partition, None)
    }

    /// The quotient with the weights `w(x)` of appendix A.5, normalised within each block
    /// (`weights[x]` for every state `x` of the model; the same weights for every action).
    ///
    /// # Errors
    /// [`TabularError::ShapeMismatch`] for a wrong number of weights or a partition that does not
    /// cover the model, [`TabularError::InvalidParameter`] for a negative or non-finite weight or a
    /// block whose weights sum to zero.
    pub fn with_weights<M: TabularModel>(
        model: &M,
        partition: &Partition,
        weights: &[f64],
    ) -> Result<Self, TabularError> {
        Self::build(model, partition, Some(weights))
    }

    fn build<M: TabularModel>(
        model: &M,
        partition: &Partition,
        weights: Option<&[f64]>,
    ) -> Result<Self, TabularError> {
        check_partition_size(model, partition)?;
        if let Some(weights) = weights {
            validate_weights(partition, weights)?;
        }
        let (num_blocks, num_actions) = (partition.num_blocks(), model.num_actions());
        let mut accumulator = SparseAccumulator::new(num_blocks);
        let mut rows = TransitionRows::with_capacity(num_blocks * num_actions);
        let mut rewards = Vec::with_capacity(num_blocks * num_actions);
        for block in 0..num_blocks {
            let members = partition.members(block);
            let total: f64 = match weights {
                Some(weights) => members.iter().map(|&x| weights[x]).sum(),
                None => members.len() as f64,
            };
            for action in 0..num_actions {
                let mut reward = 0.0;
                for &x in members {
                    let weight = weights.map_or(1.0, |weights| weights[x]) / total;
                    if weight == 0.0 {
                        continue;
                    }
                    reward += weight * model.reward(x, action);
                    for (next, p) in model.successors(x, action) {
                        accumulator.add(partition.block_of(next), weight * p);
                    }
                }
                rewards.push(reward);
                rows.push_row(&accumulator.drain_sorted());
            }
        }
        let mdp = FiniteMdp::from_parts(num_blocks, num_actions, model.gamma(), rewards, rows);
        Ok(Self {
            mdp,
            partition: partition.clone(),
        })
    }

    /// The abstract MDP `M̄` over the blocks `X̄`.
    pub fn abstract_mdp(&self) -> &FiniteMdp {
        &self.mdp
    }

    /// The partition, i.e. the state map `f`.
    pub fn partition(&self) -> &Partition {
        &self.partition
    }

    /// The state map `f(x)`.
    ///
    /// # Panics
    /// If `state` is not a state of the partitioned model.
    pub fn state_map(&self, state: usize) -> usize {
        self.partition.block_of(state)
    }

    /// The action map `g(a)`: the identity, `Ā = A` (appendix A.5).
    pub fn action_map(&self, action: usize) -> usize {
        action
    }

    /// Lifts a deterministic abstract policy `π̄` to the partitioned model:
    /// `π↑(a|x) = π̄(ā|f(x)) / |g⁻¹(ā)|` for `a ∈ g⁻¹(ā)` (section 2.2, Lemma 3.7). With `g` the
    /// identity, `g⁻¹(ā) = {ā}`, so `π↑(x) = π̄(f(x))`.
    ///
    /// # Errors
    /// [`TabularError::ShapeMismatch`] unless the policy has one action per block,
    /// [`TabularError::IndexOutOfRange`] for an action `≥ |A|`.
    pub fn lift_policy(&self, abstract_policy: &[usize]) -> Result<Vec<usize>, TabularError> {
        let (num_blocks, num_actions) = (self.partition.num_blocks(), self.mdp.num_actions());
        if abstract_policy.len() != num_blocks {
            return Err(TabularError::ShapeMismatch {
                location: "abstract policy".to_string(),
                found: abstract_policy.len(),
                expected: num_blocks,
                unit: "actions (one per abstract state)",
            });
        }
        if let Some(&action) = abstract_policy
            .iter()
            .find(|&&action| action >= num_actions)
        {
            return Err(TabularError::IndexOutOfRange {
                what: "abstract action",
                index: action,
                bound: num_actions,
            });
        }
        Ok(self
            .partition
            .block_map()
            .iter()
            .map(|&block| abstract_policy[block])
            .collect())
    }
}

fn validate_weights(partition: &Partition, weights: &[f64]) -> Result<(), TabularError> {
    if weights.len() != partition.num_elements() {
        return Err(TabularError::ShapeMismatch {
            location: "quotient weights".to_string(),
            found: weights.len(),
            expected: partition.num_elements(),
            unit: "weights (one per state)",
        });
    }
    if let Some((state, &weight)) = weights
        .iter()
        .enumerate()
        .find(|&(_, &w)| !(w.is_finite() && w >= 0.0))
    {
        return Err(TabularError::InvalidParameter {
            name: "weight",
            value: format!("w[{state}] = {weight}"),
            accepted: "finite, non-negative weights".to_string(),
        });
    }
    for block in 0..partition.num_blocks() {
        let total: f64 = partition.members(block).iter().map(|&x| weights[x]).sum();
        if total <= 0.0 {
            return Err(TabularError::InvalidParameter {
                name: "weights",
                value: format!("total weight 0 in block {block}"),
                accepted: "a positive total weight in every block".to_string(),
            });
        }
    }
    Ok(())
}
