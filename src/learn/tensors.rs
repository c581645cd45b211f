//! Host arrays in and out of tensors.
use burn::prelude::{Device, Tensor, TensorData};

use crate::delay::Transitions;

/// A `[rows, cols]` tensor from row-major values.
pub fn matrix(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, [rows, cols]), device)
}

/// A `[rows, 1]` tensor.
pub fn column(values: Vec<f32>, device: &Device) -> Tensor<2> {
    let rows = values.len();
    matrix(values, rows, 1, device)
}

/// `[rows, len / rows]` on `device`.
pub fn rows(values: Vec<f32>, rows: usize, device: &Device) -> Tensor<2> {
    let cols = values.len() / rows.max(1);
    matrix(values, rows, cols, device)
}

/// A batch of transitions as `[B, ·]` tensors; each algorithm chooses which of them its
/// networks condition on.
#[derive(Debug, Clone)]
pub struct TransitionTensors {
    /// `x_τ`
    pub augmented: Tensor<2>,
    /// `s_τ`
    pub state: Tensor<2>,
    pub action: Tensor<2>,
    /// `[B, 1]`
    pub reward: Tensor<2>,
    /// `x_{τ+1}`
    pub next_augmented: Tensor<2>,
    /// `s_{τ+1}`
    pub next_state: Tensor<2>,
    /// `[B, 1]`: 1 where the MDP terminated.
    pub done: Tensor<2>,
}

impl TransitionTensors {
    pub fn new(batch: &Transitions, device: &Device) -> TransitionTensors {
        let n = batch.len();
        TransitionTensors {
            augmented: rows(batch.augmented.clone(), n, device),
            state: rows(batch.state.clone(), n, device),
            action: rows(batch.action.clone(), n, device),
            reward: column(batch.reward.clone(), device),
            next_augmented: rows(batch.next_augmented.clone(), n, device),
            next_state: rows(batch.next_state.clone(), n, device),
            done: column(batch.terminated.iter().map(|&d| d as f32).collect(), device),
        }
    }
}

/// The values of a tensor, row-major.
pub fn to_vec<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("a float tensor converts to f32")
}

/// Asserts `found` equals `expected` entry by entry within 1e-5 (the unit tests' hand values).
#[cfg(test)]
pub(crate) fn assert_close(found: &[f32], expected: &[f32]) {
    assert_eq!(found.len(), expected.len(), "{found:?} vs {expected:?}");
    for (f, e) in found.iter().zip(expected) {
        assert!((f - e).abs() < 1e-5, "{found:?} vs {expected:?}");
    }
}
