//! Standard normal noise drawn on the host from a seeded stream, so that a run's randomness
//! is reproducible, independent of the backend, and saved in checkpoints.
use burn::prelude::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::tensors::upload;

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

    /// A uniform draw from `0..n` (`n` ≥ 1).
    pub fn below(&mut self, n: usize) -> usize {
        self.rng.random_range(0..n)
    }

    /// `n` independent N(0, 1) draws.
    pub fn normal_values(&mut self, n: usize) -> Vec<f32> {
        (0..n)
            .map(|_| StandardNormal.sample(&mut self.rng))
            .collect()
    }

    /// A `[S, rows, cols]` tensor: slice `i` is `[rows, cols]` draws from `streams[i]` (each run
    /// of a stack draws from its own stream what it would draw alone).
    pub fn stacked_normal(
        streams: &mut [Noise],
        rows: usize,
        cols: usize,
        device: &Device,
    ) -> Tensor<3> {
        let counts = vec![rows; streams.len()];
        Noise::stacked_normal_rows(streams.iter_mut(), &counts, rows, cols, device)
    }

    /// [`Noise::stacked_normal`] where run `i` draws its first `counts[i]` rows only (the rows
    /// it acts for) from the i-th of `streams` and the rest of its slice is zeros.
    pub fn stacked_normal_rows<'a>(
        streams: impl IntoIterator<Item = &'a mut Noise>,
        counts: &[usize],
        rows: usize,
        cols: usize,
        device: &Device,
    ) -> Tensor<3> {
        let block = rows * cols;
        let mut values = vec![0.0f32; counts.len() * block];
        for (i, (stream, &count)) in streams.into_iter().zip(counts).enumerate() {
            let start = i * block;
            values[start..start + count * cols]
                .copy_from_slice(&stream.normal_values(count * cols));
        }
        upload(TensorData::new(values, [counts.len(), rows, cols]), device)
    }

    /// A `[k, S, rows, cols]` tensor: run `i`'s K samples of `[rows, cols]` draws from
    /// `streams[i]`, drawn sample after sample as that run draws them alone (S = 1), the samples
    /// leading.
    pub fn stacked_normal_k(
        streams: &mut [Noise],
        k: usize,
        rows: usize,
        cols: usize,
        device: &Device,
    ) -> Tensor<4> {
        let block = rows * cols;
        let per_run: Vec<Vec<f32>> = streams
            .iter_mut()
            .map(|stream| stream.normal_values(k * block))
            .collect();
        let values: Vec<f32> = (0..k)
            .flat_map(|sample| {
                per_run
                    .iter()
                    .flat_map(move |run| &run[sample * block..(sample + 1) * block])
            })
            .copied()
            .collect();
        upload(
            TensorData::new(values, [k, streams.len(), rows, cols]),
            device,
        )
    }
}
