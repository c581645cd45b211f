//! Standard normal noise drawn on the host from a seeded stream, so that a run's randomness
//! is reproducible, independent of the backend, and saved in checkpoints.
use burn::prelude::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::tensors::matrix;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Noise {
    rng: ChaCha8Rng,
}

impl Noise {
    pub fn new(seed: u64) -> Noise {
        Noise {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// A `[k, rows, cols]` tensor of independent N(0, 1) draws: `k` samples of `[rows, cols]`.
    pub fn normal3(&mut self, k: usize, rows: usize, cols: usize, device: &Device) -> Tensor<3> {
        let values: Vec<f32> = (0..k * rows * cols)
            .map(|_| StandardNormal.sample(&mut self.rng))
            .collect();
        Tensor::from_data(
            burn::prelude::TensorData::new(values, [k, rows, cols]),
            device,
        )
    }

    /// A uniform draw from `0..n` (`n` ≥ 1).
    pub fn below(&mut self, n: usize) -> usize {
        self.rng.random_range(0..n)
    }

    /// A `[rows, cols]` tensor of independent N(0, 1) draws.
    pub fn normal(&mut self, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
        let values = (0..rows * cols)
            .map(|_| StandardNormal.sample(&mut self.rng))
            .collect();
        matrix(values, rows, cols, device)
    }
}
