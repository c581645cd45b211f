//! Host arrays in and out of tensors.
use burn::prelude::{Device, Tensor, TensorData};

/// A `[rows, cols]` tensor from row-major values.
pub fn matrix(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, [rows, cols]), device)
}

/// A `[rows, 1]` tensor.
pub fn column(values: Vec<f32>, device: &Device) -> Tensor<2> {
    let rows = values.len();
    matrix(values, rows, 1, device)
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
