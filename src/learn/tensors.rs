//! Host arrays in and out of tensors. Every crossing a learner makes between the host and its
//! device goes through [`upload`] or [`to_vec`], which count them ([`transfers`]): on a GPU
//! each is a transfer and a synchronisation, so what an update moves is tested, not assumed.
use std::sync::atomic::{AtomicU64, Ordering};

use burn::prelude::{Device, Tensor, TensorData};

use crate::delay::Transitions;

static UPLOADS: AtomicU64 = AtomicU64::new(0);
static DOWNLOADS: AtomicU64 = AtomicU64::new(0);

/// Uploads and downloads made through this module since the process started, by every thread.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Transfers {
    pub uploads: u64,
    pub downloads: u64,
}

impl std::ops::Sub for Transfers {
    type Output = Transfers;
    fn sub(self, before: Transfers) -> Transfers {
        Transfers {
            uploads: self.uploads - before.uploads,
            downloads: self.downloads - before.downloads,
        }
    }
}

/// The count so far.
pub fn transfers() -> Transfers {
    Transfers {
        uploads: UPLOADS.load(Ordering::Relaxed),
        downloads: DOWNLOADS.load(Ordering::Relaxed),
    }
}

/// `data` as a tensor on `device`: one upload.
pub fn upload<const D: usize>(data: TensorData, device: &Device) -> Tensor<D> {
    UPLOADS.fetch_add(1, Ordering::Relaxed);
    Tensor::from_data(data, device)
}

/// `[runs, rows, width]` from the first `runs · rows · width` of `values` (row-major): one upload.
pub fn upload_rows(
    values: &[f32],
    runs: usize,
    rows: usize,
    width: usize,
    device: &Device,
) -> Tensor<3> {
    let len = runs * rows * width;
    upload(
        TensorData::new(values[..len].to_vec(), [runs, rows, width]),
        device,
    )
}

/// A `[rows, cols]` tensor from row-major values.
pub fn matrix(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    upload(TensorData::new(values, [rows, cols]), device)
}

/// The batches of a stack's runs as `[S, B, ·]` tensors (a solo run's `[1, B, ·]`), one upload
/// per field; each algorithm chooses which of them its networks condition on.
#[derive(Debug, Clone)]
pub struct TransitionTensors {
    /// `x_τ`
    pub augmented: Tensor<3>,
    /// `s_τ`
    pub state: Tensor<3>,
    pub action: Tensor<3>,
    /// `[S, B, 1]`
    pub reward: Tensor<3>,
    /// `x_{τ+1}`
    pub next_augmented: Tensor<3>,
    /// `s_{τ+1}`
    pub next_state: Tensor<3>,
    /// `[S, B, 1]`: 1 where the MDP terminated.
    pub done: Tensor<3>,
}

impl TransitionTensors {
    /// One run's batch.
    pub fn new(batch: &Transitions, device: &Device) -> TransitionTensors {
        TransitionTensors::stacked(std::slice::from_ref(batch), device)
    }

    /// Run `i`'s batch `batches[i]` in slice `i` (all of one size).
    pub fn stacked(batches: &[Transitions], device: &Device) -> TransitionTensors {
        let field = |values: fn(&Transitions) -> &[f32]| {
            stacked_rows(batches.iter().map(values), batches, device)
        };
        let done: Vec<Vec<f32>> = batches
            .iter()
            .map(|b| b.terminated.iter().map(|&d| d as f32).collect())
            .collect();
        TransitionTensors {
            augmented: field(|b| &b.augmented),
            state: field(|b| &b.state),
            action: field(|b| &b.action),
            reward: field(|b| &b.reward),
            next_augmented: field(|b| &b.next_augmented),
            next_state: field(|b| &b.next_state),
            done: stacked_rows(done.iter().map(Vec::as_slice), batches, device),
        }
    }
}

/// One field of each run's batch (`runs`, row-major `[B, width]` each) as `[S, B, width]`.
pub fn stacked_rows<'a>(
    runs: impl Iterator<Item = &'a [f32]>,
    batches: &[Transitions],
    device: &Device,
) -> Tensor<3> {
    let values: Vec<f32> = runs.flat_map(|run| run.iter().copied()).collect();
    let (stack, rows) = (batches.len(), batches[0].len());
    let width = values.len() / (stack * rows).max(1);
    upload(TensorData::new(values, [stack, rows, width]), device)
}

/// The values of a tensor, row-major: one download.
pub fn to_vec<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    DOWNLOADS.fetch_add(1, Ordering::Relaxed);
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
