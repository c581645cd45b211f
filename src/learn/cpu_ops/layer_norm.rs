//! The stacked layer norm, `y = (x − μ)/√(σ² + ε)·γ_s + β_s` over the last axis of each run
//! `s`'s rows (σ² the biased variance, as burn's and PyTorch's), and its backward pass written
//! out: with `x̂ = (x − μ)·r`, `r = 1/√(σ² + ε)`, `g` the incoming gradient and `w` the width,
//! `∂x = r·(gγ − mean(gγ) − x̂·mean(gγ·x̂))`, `∂γ_s = Σ_rows g·x̂`, `∂β_s = Σ_rows g`.
//! One pass serves every run; each run's rows and sums are its own, so a run computes the same
//! numbers alone and in a stack.
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::{Autodiff, Flex};
use burn::prelude::Tensor;
use burn::tensor::module::layer_norm as burn_layer_norm;

use super::{Route, flex, on_graph, plain, route, tracked, values};

/// Each run's slice of `x` `[S, …, width]` normalised over its last axis with the run's
/// `gamma` and `beta` `[S, width]`, differentiable in all three where they are.
pub fn layer_norm<const D: usize>(
    x: Tensor<D>,
    gamma: Tensor<2>,
    beta: Tensor<2>,
    epsilon: f64,
) -> Tensor<D> {
    let routes = [route(&x), route(&gamma), route(&beta)];
    match routes {
        [Route::Plain, Route::Plain, Route::Plain] => Tensor::from_primitive::<Flex>(forward(
            &[plain(x), plain(gamma), plain(beta)],
            epsilon as f32,
        )),
        [Route::Tracked, Route::Tracked, Route::Tracked] => {
            let epsilon = epsilon as f32;
            Tensor::from_primitive::<Autodiff<Flex>>(on_graph(
                LayerNorm { epsilon },
                [tracked(x), tracked(gamma), tracked(beta)],
                |inputs| forward(inputs, epsilon),
            ))
        }
        _ => per_run_in_burn(x, gamma, beta, epsilon),
    }
}

/// burn's layer norm, one call per run on the run's slice: a solo run takes the same slice and
/// concatenation, since burn's backward on a slice of a tensor rounds otherwise than on the
/// whole tensor.
fn per_run_in_burn<const D: usize>(
    x: Tensor<D>,
    gamma: Tensor<2>,
    beta: Tensor<2>,
    epsilon: f64,
) -> Tensor<D> {
    let [runs, width] = gamma.dims();
    let part = |p: &Tensor<2>, run: usize| p.clone().narrow(0, run, 1).reshape([width]);
    Tensor::cat(
        (0..runs)
            .map(|run| {
                burn_layer_norm(
                    x.clone().narrow(0, run, 1),
                    part(&gamma, run),
                    Some(part(&beta, run)),
                    epsilon,
                )
            })
            .collect(),
        0,
    )
}

/// Its state is the inputs `[x, γ, β]` (β unused).
#[derive(Debug)]
struct LayerNorm {
    epsilon: f32,
}

impl Backward<Flex, 3> for LayerNorm {
    type State = [FlexTensor; 3];

    fn backward(self, ops: Ops<[FlexTensor; 3], 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [x, gamma, _] = ops.state;
        let grad = grads.consume::<Flex>(&ops.node);
        let (x_shape, gamma_shape) = (x.layout().shape().clone(), gamma.layout().shape().clone());
        let width = x_shape[x_shape.num_dims() - 1];
        let mut dx = vec![0.0; x_shape.num_elements()];
        let mut dgamma = vec![0.0; gamma_shape.num_elements()];
        let mut dbeta = vec![0.0; gamma_shape.num_elements()];
        kernels::backward(
            (&values(&x), &values(&gamma), &values(&grad)),
            self.epsilon,
            width,
            (&mut dx, &mut dgamma, &mut dbeta),
        );
        let [to_x, to_gamma, to_beta] = ops.parents;
        for (parent, (gradient, shape)) in [to_x, to_gamma, to_beta].into_iter().zip([
            (dx, x_shape),
            (dgamma, gamma_shape.clone()),
            (dbeta, gamma_shape),
        ]) {
            if let Some(parent) = parent {
                grads.register::<Flex>(parent.id, flex(gradient, shape));
            }
        }
    }
}

fn forward([x, gamma, beta]: &[FlexTensor; 3], epsilon: f32) -> FlexTensor {
    let shape = x.layout().shape().clone();
    let width = shape[shape.num_dims() - 1];
    let mut out = vec![0.0; shape.num_elements()];
    kernels::forward(
        (&values(x), &values(gamma), &values(beta)),
        epsilon,
        width,
        &mut out,
    );
    flex(out, shape)
}

mod kernels {

    /// Sums run over this many lanes, added pairwise at the end: the same order (and bits)
    /// whatever the vector width.
    const LANES: usize = 16;

    /// `Σ_k term(slices[0][k], …, slices[N−1][k])` over the lanes (the slices of one length).
    #[inline(always)]
    fn lane_sum<const N: usize>(slices: [&[f32]; N], term: impl Fn([f32; N]) -> f32) -> f32 {
        let mut lanes = [0.0f32; LANES];
        let len = slices[0].len();
        let full = len - len % LANES;
        for base in (0..full).step_by(LANES) {
            let blocks: [&[f32; LANES]; N] =
                slices.map(|s| s[base..base + LANES].try_into().expect("a full block"));
            for (k, lane) in lanes.iter_mut().enumerate() {
                *lane += term(blocks.map(|block| block[k]));
            }
        }
        for (k, lane) in (full..len).zip(&mut lanes) {
            *lane += term(slices.map(|s| s[k]));
        }
        let mut width = LANES;
        while width > 1 {
            width /= 2;
            for k in 0..width {
                lanes[k] += lanes[k + width];
            }
        }
        lanes[0]
    }

    /// `(μ, 1/√(σ² + ε))` of one row.
    #[inline(always)]
    fn moments(row: &[f32], epsilon: f32) -> (f32, f32) {
        let width = row.len() as f32;
        let mean = lane_sum([row], |[v]| v) / width;
        let variance = lane_sum([row], |[v]| (v - mean) * (v - mean)) / width;
        (mean, 1.0 / (variance + epsilon).sqrt())
    }

    /// Which run each `[width]` row of `x` belongs to (the stack's `runs` own equal shares of
    /// the rows, in order), and the row.
    #[inline(always)]
    fn rows(x: &[f32], width: usize, runs: usize) -> impl Iterator<Item = (usize, &[f32])> {
        let rows_per_run = x.len() / width / runs;
        x.chunks_exact(width)
            .enumerate()
            .map(move |(row, values)| (row / rows_per_run, values))
    }

    #[inline(always)]
    fn forward_loop(
        (x, gamma, beta): (&[f32], &[f32], &[f32]),
        epsilon: f32,
        width: usize,
        out: &mut [f32],
    ) {
        let rows = rows(x, width, gamma.len() / width).zip(out.chunks_exact_mut(width));
        for ((run, row), out) in rows {
            let (mean, rstd) = moments(row, epsilon);
            let (gamma, beta) = (
                &gamma[run * width..][..width],
                &beta[run * width..][..width],
            );
            for (((out, &v), &scale), &shift) in out.iter_mut().zip(row).zip(gamma).zip(beta) {
                *out = (v - mean) * rstd * scale + shift;
            }
        }
    }

    #[inline(always)]
    fn backward_loop(
        (x, gamma, grad): (&[f32], &[f32], &[f32]),
        epsilon: f32,
        width: usize,
        (dx, dgamma, dbeta): (&mut [f32], &mut [f32], &mut [f32]),
    ) {
        let rows = rows(x, width, gamma.len() / width)
            .zip(grad.chunks_exact(width))
            .zip(dx.chunks_exact_mut(width));
        for (((run, row), grad), dx) in rows {
            let (mean, rstd) = moments(row, epsilon);
            let gamma = &gamma[run * width..][..width];
            let (dgamma, dbeta) = (
                &mut dgamma[run * width..][..width],
                &mut dbeta[run * width..][..width],
            );
            let count = width as f32;
            let mean_scaled = lane_sum([grad, gamma], |[g, c]| g * c) / count;
            let mean_projected =
                lane_sum([grad, gamma, row], |[g, c, v]| g * c * ((v - mean) * rstd)) / count;
            let per_entry = dx
                .iter_mut()
                .zip(dgamma.iter_mut())
                .zip(dbeta.iter_mut())
                .zip(row.iter().zip(grad).zip(gamma));
            for (((dx, dgamma), dbeta), ((&v, &g), &c)) in per_entry {
                let normalised = (v - mean) * rstd;
                *dx = rstd * (g * c - mean_scaled - normalised * mean_projected);
                *dgamma += g * normalised;
                *dbeta += g;
            }
        }
    }

    best_isa!(forward(
        inputs: (&[f32], &[f32], &[f32]),
        epsilon: f32,
        width: usize,
        out: &mut [f32]
    ) {
        forward_loop(inputs, epsilon, width, out)
    });

    best_isa!(backward(
        inputs: (&[f32], &[f32], &[f32]),
        epsilon: f32,
        width: usize,
        gradients: (&mut [f32], &mut [f32], &mut [f32])
    ) {
        backward_loop(inputs, epsilon, width, gradients)
    });

    /// Both loops as the baseline build compiles them.
    #[cfg(test)]
    pub(super) fn portable(
        inputs: (&[f32], &[f32], &[f32]),
        grad: &[f32],
        epsilon: f32,
        width: usize,
    ) -> [Vec<f32>; 4] {
        let (x, gamma, beta) = inputs;
        let mut out = vec![0.0; x.len()];
        forward_loop(inputs, epsilon, width, &mut out);
        let (mut dx, mut dgamma, mut dbeta) = (
            vec![0.0; x.len()],
            vec![0.0; gamma.len()],
            vec![0.0; beta.len()],
        );
        backward_loop(
            (x, gamma, grad),
            epsilon,
            width,
            (&mut dx, &mut dgamma, &mut dbeta),
        );
        [out, dx, dgamma, dbeta]
    }
}

#[cfg(test)]
mod tests {
    use burn::prelude::{Device, Tensor};
    use burn::tensor::Distribution;

    use super::{kernels, layer_norm, per_run_in_burn};
    use crate::learn::to_vec;

    const EPSILON: f64 = 1e-5;

    /// `[x, γ, β]` of a stack of `runs` runs, width 24 (a remainder after the lanes) and 256,
    /// on the autodiff device, and a gradient weighting every entry of the output differently.
    fn inputs(runs: usize, width: usize, device: &Device) -> [Tensor<4>; 2] {
        let x = Tensor::<4>::random([runs, 40, 3, width], Distribution::Normal(0.5, 2.0), device);
        let weights = Tensor::<4>::random(x.dims(), Distribution::Uniform(-1.0, 1.0), device);
        [x, weights]
    }

    fn params(runs: usize, width: usize, device: &Device) -> [Tensor<2>; 2] {
        [
            Tensor::random([runs, width], Distribution::Uniform(0.5, 1.5), device),
            Tensor::random([runs, width], Distribution::Uniform(-0.5, 0.5), device),
        ]
    }

    /// The output and the gradients of x, γ and β, by our op or burn's per-run one.
    fn run(
        ours: bool,
        x: &Tensor<4>,
        weights: &Tensor<4>,
        [gamma, beta]: &[Tensor<2>; 2],
    ) -> [Vec<f32>; 4] {
        let (x, gamma, beta) = (
            x.clone().detach().require_grad(),
            gamma.clone().detach().require_grad(),
            beta.clone().detach().require_grad(),
        );
        let y = if ours {
            layer_norm(x.clone(), gamma.clone(), beta.clone(), EPSILON)
        } else {
            per_run_in_burn(x.clone(), gamma.clone(), beta.clone(), EPSILON)
        };
        let grads = (y.clone() * weights.clone()).sum().backward();
        [
            to_vec(y),
            to_vec(x.grad(&grads).expect("x's gradient")),
            to_vec(gamma.grad(&grads).expect("γ's gradient")),
            to_vec(beta.grad(&grads).expect("β's gradient")),
        ]
    }

    #[test]
    fn matches_burns_layer_norm_in_value_and_every_gradient() {
        let device = Device::flex().autodiff();
        for width in [24, 256] {
            let [x, weights] = inputs(2, width, &device);
            let params = params(2, width, &device);
            let ours = run(true, &x, &weights, &params);
            let burns = run(false, &x, &weights, &params);
            for (what, (a, b)) in ["y", "∂x", "∂γ", "∂β"].iter().zip(ours.iter().zip(&burns))
            {
                let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
                let worst = a
                    .iter()
                    .zip(b)
                    .fold(0.0f32, |m, (p, q)| m.max((p - q).abs()));
                // ∂γ and ∂β sum 120 rows: float rounding in a different order.
                assert!(
                    worst <= 2e-5 * scale,
                    "{what} at width {width}: off by {worst} (scale {scale})"
                );
            }
            // Off the graph (the cloning stage) and on the plain device.
            let plain = |t: &Tensor<2>| t.clone().inner();
            let y = layer_norm(
                x.clone().inner(),
                plain(&params[0]),
                plain(&params[1]),
                EPSILON,
            );
            let expected = &burns[0];
            assert!(
                to_vec(y)
                    .iter()
                    .zip(expected)
                    .all(|(p, q)| (p - q).abs() <= 1e-5)
            );
        }
    }

    /// Run 1 of a stack of two, and run 1 alone: the same bits, value and gradients.
    #[test]
    fn a_run_computes_the_same_bits_alone_and_in_a_stack() {
        let device = Device::flex().autodiff();
        let [x, weights] = inputs(2, 256, &device);
        let params = params(2, 256, &device);
        let stacked = run(true, &x, &weights, &params);
        let second = |t: Tensor<4>| t.narrow(0, 1, 1);
        let alone = run(
            true,
            &second(x.clone()),
            &second(weights.clone()),
            &params.clone().map(|p| p.narrow(0, 1, 1)),
        );
        for (stacked, alone) in stacked.iter().zip(&alone) {
            let half = stacked.len() / 2;
            assert!(
                stacked[half..]
                    .iter()
                    .zip(alone)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
    }

    #[test]
    fn every_instruction_set_computes_the_same_bits() {
        let device = Device::flex();
        let [x, grad] = inputs(2, 24, &device).map(to_vec);
        let [gamma, beta] = params(2, 24, &device).map(to_vec);
        let (epsilon, width) = (EPSILON as f32, 24);
        let [out, dx, dgamma, dbeta] =
            kernels::portable((&x, &gamma, &beta), &grad, epsilon, width);
        let mut best = vec![0.0; x.len()];
        kernels::forward((&x, &gamma, &beta), epsilon, width, &mut best);
        let (mut best_dx, mut best_dgamma, mut best_dbeta) =
            (vec![0.0; x.len()], vec![0.0; 48], vec![0.0; 48]);
        kernels::backward(
            (&x, &gamma, &grad),
            epsilon,
            width,
            (&mut best_dx, &mut best_dgamma, &mut best_dbeta),
        );
        for (a, b) in [
            (out, best),
            (dx, best_dx),
            (dgamma, best_dgamma),
            (dbeta, best_dbeta),
        ] {
            assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
        }
    }
}
