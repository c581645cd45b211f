//! Partitions of a state space, and the two belief-based partitions of the augmented state space:
//! the exact belief-equivalence partition (Definition 3.2) and the ε-abstract partition under
//! total variation (section 3.2, appendix A.5).
//!
//! # Exact partition tolerance
//! Beliefs are compared after rounding every probability to the nearest multiple of
//! `2^-40 ≈ 9.1e-13` (entries that round to zero are dropped): two augmented states share a block
//! exactly when their rounded beliefs are identical. Merged beliefs therefore differ by at most
//! `2^-40` in every coordinate, and beliefs that differ only by floating-point noise (around
//! `1e-16`) are merged unless the noise happens to straddle a rounding boundary, which can only
//! split a block, never merge distinct beliefs. Under deterministic dynamics beliefs are exact
//! Dirac vectors and the partition is exact.

use std::collections::HashMap;

use crate::augmented::AugmentedMdp;
use crate::error::TabularError;
use crate::model::TabularModel;
use crate::sparse::{SparseDistribution, merge_union};

/// `2^40`: beliefs are rounded to multiples of `1 / BELIEF_SCALE` before comparison.
const BELIEF_SCALE: f64 = 1_099_511_627_776.0;

/// A partition of the states `0..num_elements()` into blocks `0..num_blocks()`, numbered in order
/// of their first element. For a partition of `X` this is the state map `f: X → X̄`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Partition {
    block_of: Vec<usize>,
    offsets: Vec<usize>,
    members: Vec<usize>,
}

impl Partition {
    /// The partition whose blocks are the sets of elements sharing a label. Labels may be any
    /// numbers; blocks are renumbered in order of first appearance.
    pub fn from_labels(labels: &[usize]) -> Self {
        let mut renumber: HashMap<usize, usize> = HashMap::new();
        let block_of: Vec<usize> = labels
            .iter()
            .map(|&label| {
                let next = renumber.len();
                *renumber.entry(label).or_insert(next)
            })
            .collect();
        Self::from_block_map(block_of, renumber.len())
    }

    /// The partition into singletons (no abstraction): `f` is the identity.
    pub fn discrete(num_elements: usize) -> Self {
        Self::from_block_map((0..num_elements).collect(), num_elements)
    }

    /// Builds the member lists of a block map whose blocks are `0..num_blocks`.
    fn from_block_map(block_of: Vec<usize>, num_blocks: usize) -> Self {
        let mut counts = vec![0usize; num_blocks];
        for &block in &block_of {
            counts[block] += 1;
        }
        let mut offsets = Vec::with_capacity(num_blocks + 1);
        offsets.push(0);
        let mut total = 0;
        for count in &counts {
            total += count;
            offsets.push(total);
        }
        let mut cursor = offsets[..num_blocks].to_vec();
        let mut members = vec![0; block_of.len()];
        for (element, &block) in block_of.iter().enumerate() {
            members[cursor[block]] = element;
            cursor[block] += 1;
        }
        Self {
            block_of,
            offsets,
            members,
        }
    }

    /// Number of partitioned elements (`|X|` for a partition of `X`).
    pub fn num_elements(&self) -> usize {
        self.block_of.len()
    }

    /// Number of blocks (`|X̄|`).
    pub fn num_blocks(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The block of `element`: the state map `f(x)`.
    ///
    /// # Panics
    /// If `element >= num_elements()`.
    pub fn block_of(&self, element: usize) -> usize {
        self.block_of[element]
    }

    /// The whole state map, `block_map()[x] = f(x)`.
    pub fn block_map(&self) -> &[usize] {
        &self.block_of
    }

    /// The elements of `block`, in increasing order.
    ///
    /// # Panics
    /// If `block >= num_blocks()`.
    pub fn members(&self, block: usize) -> &[usize] {
        &self.members[self.offsets[block]..self.offsets[block + 1]]
    }

    /// The compression ratio `ζ = |X̄| / |X|` of Prop. 3.5.
    pub fn compression_ratio(&self) -> f64 {
        if self.block_of.is_empty() {
            1.0
        } else {
            self.num_blocks() as f64 / self.num_elements() as f64
        }
    }
}

/// Checks that `partition` partitions exactly the states of `model`.
pub(crate) fn check_partition_size<M: TabularModel>(
    model: &M,
    partition: &Partition,
) -> Result<(), TabularError> {
    if partition.num_elements() == model.num_states() {
        Ok(())
    } else {
        Err(TabularError::ShapeMismatch {
            location: "partition".to_string(),
            found: partition.num_elements(),
            expected: model.num_states(),
            unit: "elements (one per state of the model)",
        })
    }
}

/// Rejects an ε outside the paper's range `[0, 1)`.
pub(crate) fn validate_epsilon(epsilon: f64) -> Result<(), TabularError> {
    if (0.0..1.0).contains(&epsilon) {
        Ok(())
    } else {
        Err(TabularError::InvalidParameter {
            name: "epsilon",
            value: epsilon.to_string(),
            accepted: "a total-variation radius with 0 <= epsilon < 1".to_string(),
        })
    }
}

/// The rounded form of a belief used as a hash key (see the module documentation).
fn belief_key(belief: &[(usize, f64)]) -> Vec<(usize, i64)> {
    belief
        .iter()
        .filter_map(|&(state, p)| {
            let units = (p * BELIEF_SCALE).round() as i64;
            (units != 0).then_some((state, units))
        })
        .collect()
}

/// Augmented states grouped by identical (rounded) belief.
struct BeliefClasses {
    /// `class_of[x]`, classes numbered in order of first appearance.
    class_of: Vec<usize>,
    /// The belief of the first member of every class.
    representatives: Vec<SparseDistribution>,
}

fn group_identical_beliefs(model: &AugmentedMdp) -> BeliefClasses {
    let mut index: HashMap<Vec<(usize, i64)>, usize> = HashMap::new();
    let mut representatives: Vec<SparseDistribution> = Vec::new();
    let mut class_of = vec![0; model.num_states()];
    model.for_each_belief(|x, belief| {
        let next = representatives.len();
        let class = *index.entry(belief_key(belief)).or_insert_with(|| {
            representatives.push(belief.to_vec());
            next
        });
        class_of[x] = class;
    });
    BeliefClasses {
        class_of,
        representatives,
    }
}

/// The belief-equivalence partition `B_Δ|X` of Definition 3.2: `x ~ x'` iff
/// `b_Δ(·|x) = b_Δ(·|x')`. Under deterministic dynamics it is reward-respecting and has the SSP
/// (Prop. 3.3) and has at most `|S|` blocks (Prop. 3.5).
///
/// Tolerance: every probability is rounded to the nearest multiple of `2^-40 ≈ 9.1e-13` (entries
/// that round to zero are dropped) and beliefs are equal when the rounded vectors are identical.
/// Merged beliefs thus differ by at most `2^-40` per state; beliefs equal up to floating-point
/// noise are merged unless the noise straddles a rounding boundary, which can only split a block.
/// Deterministic dynamics give exact Dirac beliefs, so there the partition is exact.
pub fn belief_partition(model: &AugmentedMdp) -> Partition {
    Partition::from_labels(&group_identical_beliefs(model).class_of)
}

/// The componentwise range `[lo_s, hi_s]` of the beliefs in one block, stored sparsely; states
/// outside the list have `lo = hi = 0`.
struct BeliefBox {
    entries: Vec<(usize, (f64, f64))>,
}

impl BeliefBox {
    fn new(belief: &[(usize, f64)]) -> Self {
        Self {
            entries: belief.iter().map(|&(s, p)| (s, (p, p))).collect(),
        }
    }

    /// An upper bound on `max_m ‖b − m‖_TV` over every belief `m` in the box:
    /// `½ Σ_s max(|b_s − lo_s|, |b_s − hi_s|)`.
    fn max_distance_bound(&self, belief: &[(usize, f64)]) -> f64 {
        let mut total = 0.0;
        merge_union(&self.entries, belief, |_, range, p| {
            let (lo, hi) = range.unwrap_or((0.0, 0.0));
            let p = p.unwrap_or(0.0);
            total += (p - lo).abs().max((p - hi).abs());
        });
        0.5 * total
    }

    /// Widens the box to contain `belief`.
    fn include(&mut self, belief: &[(usize, f64)]) {
        let mut widened = Vec::with_capacity(self.entries.len().max(belief.len()));
        merge_union(&self.entries, belief, |state, range, p| {
            let (lo, hi) = range.unwrap_or((0.0, 0.0));
            let p = p.unwrap_or(0.0);
            widened.push((state, (lo.min(p), hi.max(p))));
        });
        self.entries = widened;
    }
}

/// An ε-abstract partition of `X` (section 3.2, appendix A.5): any two augmented states in the same
/// block satisfy `‖b_Δ(·|x) − b_Δ(·|x')‖_TV ≤ ε` (up to the exact-partition rounding, see the
/// module documentation).
///
/// Construction: augmented states with identical beliefs are grouped first; the distinct beliefs
/// are then visited in order of first appearance and each joins the first existing block whose
/// componentwise belief range stays within TV distance ε of it (a sufficient test for the
/// pairwise condition), or opens a new block. The cost is `O(distinct beliefs × blocks ×
/// support)`. With `ε = 0` this is the exact partition of [`belief_partition`].
///
/// # Errors
/// [`TabularError::InvalidParameter`] unless `0 ≤ ε < 1`.
pub fn approximate_belief_partition(
    model: &AugmentedMdp,
    epsilon: f64,
) -> Result<Partition, TabularError> {
    validate_epsilon(epsilon)?;
    let classes = group_identical_beliefs(model);
    let mut boxes: Vec<BeliefBox> = Vec::new();
    let mut block_of_class = Vec::with_capacity(classes.representatives.len());
    for belief in &classes.representatives {
        let found = boxes
            .iter()
            .position(|candidate| candidate.max_distance_bound(belief) <= epsilon);
        let block = match found {
            Some(block) => {
                boxes[block].include(belief);
                block
            }
            None => {
                boxes.push(BeliefBox::new(belief));
                boxes.len() - 1
            }
        };
        block_of_class.push(block);
    }
    let labels: Vec<usize> = classes
        .class_of
        .iter()
        .map(|&class| block_of_class[class])
        .collect();
    Ok(Partition::from_labels(&labels))
}
