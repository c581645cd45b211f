//! How the SAC family's linear layers are drawn: burn's default, or orthogonal weights with zero
//! biases as the authors' released code draws every `nn.Linear` (`torch.nn.init.orthogonal_`
//! with gain 1, Saxe et al. 2014).
use burn::module::{Module, ModuleMapper, Param};
use burn::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NetworkInit {
    /// burn's `LinearConfig` default: Kaiming-uniform weights and biases by fan-in (about
    /// PyTorch's default).
    #[default]
    Burn,
    /// Orthogonal weights (gain 1) and zero biases.
    Orthogonal,
}

/// `module` (a network made of [`super::StackedLinear`] layers only: every rank-3 parameter a
/// weight `[S, in, out]`, every rank-2 one a bias `[S, out]`) drawn again as `init` says, from
/// the stream seeded with `seed`; [`NetworkInit::Burn`] leaves it as it is.
pub fn initialise<M: Module>(module: M, init: NetworkInit, seed: u64) -> M {
    match init {
        NetworkInit::Burn => module,
        NetworkInit::Orthogonal => module.map(&mut Orthogonal {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }),
    }
}

struct Orthogonal {
    rng: ChaCha8Rng,
}

impl ModuleMapper for Orthogonal {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let rng = &mut self.rng;
        param.map(|value| {
            let (shape, device, tracked) = (value.dims(), value.device(), value.is_require_grad());
            let drawn = match D {
                3 => {
                    let (slices, input, output) = (shape[0], shape[1], shape[2]);
                    let values: Vec<f32> = (0..slices)
                        .flat_map(|_| orthogonal_weight(input, output, rng))
                        .collect();
                    Tensor::from_data(TensorData::new(values, shape), &device)
                }
                2 => Tensor::zeros(shape, &device),
                _ => return value,
            };
            // A fresh tensor is off the graph: a trained parameter must stay on it.
            drawn.set_require_grad(tracked)
        })
    }
}

/// A linear layer's weight `[input, output]` (row-major, `y = x·W`) whose transpose, PyTorch's
/// `[output, input]` weight, is what `orthogonal_` draws: a standard normal matrix of the
/// taller orientation made orthonormal column by column (Gram–Schmidt keeps the diagonal of R
/// positive, which is PyTorch's `Q·sign(diag R)`), so that `WᵀW = I` when `input ≥ output` and
/// `WWᵀ = I` otherwise.
pub fn orthogonal_weight(input: usize, output: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    // PyTorch draws the [output, input] matrix and transposes it to tall before the QR.
    let (rows, cols) = (output.max(input), output.min(input));
    let drawn: Vec<f64> = (0..output * input)
        .map(|_| StandardNormal.sample(rng))
        .collect();
    // `tall[r][c]`, rows × cols, from the drawn [output, input] matrix.
    let at = |r: usize, c: usize| match output >= input {
        true => drawn[r * input + c],
        false => drawn[c * input + r],
    };
    let mut columns: Vec<Vec<f64>> = (0..cols)
        .map(|c| (0..rows).map(|r| at(r, c)).collect())
        .collect();
    for c in 0..cols {
        // Modified Gram–Schmidt, twice: orthogonal to round-off at these sizes.
        for _ in 0..2 {
            for previous in 0..c {
                let (done, rest) = columns.split_at_mut(c);
                let projection: f64 = done[previous]
                    .iter()
                    .zip(&rest[0])
                    .map(|(q, v)| q * v)
                    .sum();
                for (v, q) in rest[0].iter_mut().zip(&done[previous]) {
                    *v -= projection * q;
                }
            }
        }
        let norm = columns[c].iter().map(|v| v * v).sum::<f64>().sqrt();
        columns[c].iter_mut().for_each(|v| *v /= norm);
    }
    // PyTorch's weight W_pt [output, input] is `tall` (output ≥ input) or its transpose; dhrl's
    // weight is W_pt's transpose.
    let mut weight = vec![0.0f32; input * output];
    for i in 0..input {
        for o in 0..output {
            let value = match output >= input {
                true => columns[i][o],
                false => columns[o][i],
            };
            weight[i * output + o] = value as f32;
        }
    }
    weight
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `MᵀM` of a row-major `[rows, cols]` matrix.
    fn gram(m: &[f32], rows: usize, cols: usize) -> Vec<f64> {
        let mut g = vec![0.0; cols * cols];
        for a in 0..cols {
            for b in 0..cols {
                g[a * cols + b] = (0..rows)
                    .map(|r| f64::from(m[r * cols + a]) * f64::from(m[r * cols + b]))
                    .sum();
            }
        }
        g
    }

    fn assert_identity(g: &[f64], n: usize) {
        for a in 0..n {
            for b in 0..n {
                let expected = if a == b { 1.0 } else { 0.0 };
                assert!(
                    (g[a * n + b] - expected).abs() < 1e-5,
                    "entry ({a}, {b}) of the Gram matrix is {}",
                    g[a * n + b]
                );
            }
        }
    }

    /// A layer with more inputs than outputs has orthonormal columns (`WᵀW = I`), one with more
    /// outputs orthonormal rows (`WWᵀ = I`), a square one both; and the values are not all of
    /// one size (a scaled identity would pass the Gram test of a square layer).
    #[test]
    fn orthogonal_weights_are_orthonormal_in_their_short_direction() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let wide_in = orthogonal_weight(256, 6, &mut rng);
        assert_identity(&gram(&wide_in, 256, 6), 6);
        let wide_out = orthogonal_weight(11, 256, &mut rng);
        let transposed: Vec<f32> = (0..256)
            .flat_map(|o| (0..11).map(move |i| (i, o)))
            .map(|(i, o)| wide_out[i * 256 + o])
            .collect();
        assert_identity(&gram(&transposed, 256, 11), 11);
        let square = orthogonal_weight(64, 64, &mut rng);
        assert_identity(&gram(&square, 64, 64), 64);
        let distinct = square
            .iter()
            .map(|v| (v.abs() * 1e4) as i64)
            .collect::<std::collections::BTreeSet<_>>();
        assert!(
            distinct.len() > 1000,
            "{} distinct magnitudes",
            distinct.len()
        );
    }
}
