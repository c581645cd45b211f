//! GELU, `x·Φ(x) = x·(1 + erf(x/√2))/2`, and its derivative. burn-flex evaluates both with
//! libm's scalar `erff`, which for |x| ≥ 0.84 takes a slow path through two `expf` calls: a
//! tenth of a VDPO update once its transformer's pre-activations have grown
//! (docs/results/performance-xeon.md). Here `erf` is PyTorch's own vectorised CPU form
//! (Abramowitz & Stegun 7.1.26, absolute error ≤ 1.5e-7 in exact arithmetic, one `exp`).
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, unary};
use burn::backend::flex::FlexTensor;
use burn::backend::{Autodiff, Flex};
use burn::prelude::Tensor;
use burn::tensor::activation;

use super::{Route, flex, on_graph, plain, route, tracked, values, writable};

/// `GELU(x)` elementwise, differentiable where `x` is.
pub fn gelu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    match route(&x) {
        Route::Plain => Tensor::from_primitive::<Flex>(forward(plain(x))),
        Route::Tracked => {
            let output = on_graph(Gelu, [tracked(x)], |[x]| forward(x.clone()));
            Tensor::from_primitive::<Autodiff<Flex>>(output)
        }
        Route::Burn => activation::gelu(x),
    }
}

/// The autodiff op: its state is the input, and the backward pass multiplies the incoming
/// gradient by `Φ(x) + x·φ(x)`.
#[derive(Debug)]
struct Gelu;

impl Backward<Flex, 1> for Gelu {
    type State = [FlexTensor; 1];

    fn backward(self, ops: Ops<[FlexTensor; 1], 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [x] = ops.state;
        unary::<Flex, _>(ops.parents, ops.node, grads, |grad| {
            let shape = grad.layout().shape().clone();
            let mut out = values(&grad).into_owned();
            kernels::scale_by_derivative(&values(&x), &mut out);
            flex(out, shape)
        });
    }
}

/// `GELU(x)` of a Flex tensor, in place when nothing else holds its buffer.
fn forward(x: FlexTensor) -> FlexTensor {
    match writable(x) {
        Ok(mut x) => {
            kernels::gelu_in_place(x.storage_mut());
            x
        }
        Err(x) => {
            let mut out = values(&x).into_owned();
            kernels::gelu_in_place(&mut out);
            flex(out, x.layout().shape().clone())
        }
    }
}

mod kernels {
    use std::f32::consts::{FRAC_1_SQRT_2, LOG2_E};

    /// `1/√(2π)`.
    const FRAC_1_SQRT_2PI: f32 = 0.398_942_3;

    /// `e^v` for `v ≤ 0` (clamped at −87, where it is ~1e-38, a normal float): `2^n·e^r`
    /// with `r = v − n·ln 2`, `|r| ≤ ln 2 / 2`, Cephes' `expf` polynomial for `e^r`, and `n`
    /// rounded by the 1.5·2²³ trick (no rounding instruction needed).
    #[inline(always)]
    fn exp_non_positive(v: f32) -> f32 {
        const ROUND: f32 = 12_582_912.0;
        const LN_2_HI: f32 = 0.693_359_4;
        const LN_2_LO: f32 = -2.121_944_4e-4;
        let v = v.max(-87.0);
        // `n` sits in the low bits of `shifted`'s mantissa: 2^n is built from those bits with
        // integer adds and a shift, which vectorise (a float-to-int cast does not, saturating).
        let shifted = v * LOG2_E + ROUND;
        let n = shifted - ROUND;
        let r = (v - n * LN_2_HI) - n * LN_2_LO;
        let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2)
            * r
            + 0.166_666_65)
            * r
            + 0.5;
        let e_r = p * r * r + r + 1.0;
        let biased_exponent = shifted
            .to_bits()
            .wrapping_sub(ROUND.to_bits())
            .wrapping_add(127);
        e_r * f32::from_bits(biased_exponent << 23)
    }

    /// `(erf(z), e^{−z²})` by Abramowitz & Stegun 7.1.26, as PyTorch's vectorised `erf`.
    #[inline(always)]
    fn erf_and_gaussian(z: f32) -> (f32, f32) {
        let a = z.abs();
        let t = 1.0 / (0.327_591_1 * a + 1.0);
        let poly = ((((1.061_405_4 * t - 1.453_152) * t + 1.421_413_8) * t - 0.284_496_74) * t
            + 0.254_829_6)
            * t;
        let gaussian = exp_non_positive(-(a * a));
        ((1.0 - poly * gaussian).copysign(z), gaussian)
    }

    #[inline(always)]
    fn gelu(x: f32) -> f32 {
        let (erf, _) = erf_and_gaussian(x * FRAC_1_SQRT_2);
        0.5 * x * (1.0 + erf)
    }

    /// `Φ(x) + x·φ(x)`; `e^{−(x/√2)²}` is the same `e^{−x²/2}` that `φ` needs.
    #[inline(always)]
    fn derivative(x: f32) -> f32 {
        let (erf, gaussian) = erf_and_gaussian(x * FRAC_1_SQRT_2);
        0.5 * (1.0 + erf) + x * FRAC_1_SQRT_2PI * gaussian
    }

    #[inline(always)]
    fn gelu_loop(values: &mut [f32]) {
        for v in values {
            *v = gelu(*v);
        }
    }

    #[inline(always)]
    fn derivative_loop(x: &[f32], grad: &mut [f32]) {
        assert_eq!(x.len(), grad.len());
        for (g, &x) in grad.iter_mut().zip(x) {
            *g *= derivative(x);
        }
    }

    best_isa!(gelu_in_place(values: &mut [f32]) { gelu_loop(values) });
    best_isa!(scale_by_derivative(x: &[f32], grad: &mut [f32]) { derivative_loop(x, grad) });

    /// Both loops as the baseline build compiles them.
    #[cfg(test)]
    pub(super) fn portable(x: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let mut values = x.to_vec();
        gelu_loop(&mut values);
        let mut grad = vec![1.0; x.len()];
        derivative_loop(x, &mut grad);
        (values, grad)
    }
}

#[cfg(test)]
mod tests {
    use burn::prelude::{Device, Tensor};
    use burn::tensor::Distribution;
    use burn::tensor::activation;

    use super::{gelu, kernels};
    use crate::learn::to_vec;

    /// Every float from −10 to 10 in steps of 1/1024, the tails and zero.
    fn grid() -> Vec<f32> {
        let mut x: Vec<f32> = (-10_240..=10_240).map(|i| i as f32 / 1024.0).collect();
        x.extend([-40.0, -12.5, 1e-30, -1e-6, 3e-7, 12.5, 40.0]);
        x
    }

    /// GELU and GELU′ of `x` through the loops this CPU runs (its best instruction set).
    fn on_this_cpu(x: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let mut values = x.to_vec();
        kernels::gelu_in_place(&mut values);
        let mut slopes = vec![1.0; x.len()];
        kernels::scale_by_derivative(x, &mut slopes);
        (values, slopes)
    }

    #[test]
    fn gelu_and_its_derivative_are_within_two_ulps_of_the_exact_functions() {
        let x = grid();
        let (values, slopes) = on_this_cpu(&x);
        let (mut worst_value, mut worst_slope) = (0.0f64, 0.0f64);
        for ((&x, &y), &dy) in x.iter().zip(&values).zip(&slopes) {
            let xd = f64::from(x);
            let cdf = 0.5 * (1.0 + libm::erf(xd / std::f64::consts::SQRT_2));
            let pdf = (-0.5 * xd * xd).exp() / (2.0 * std::f64::consts::PI).sqrt();
            let scale = xd.abs().max(1.0);
            worst_value = worst_value.max((f64::from(y) - xd * cdf).abs() / scale);
            worst_slope = worst_slope.max((f64::from(dy) - (cdf + xd * pdf)).abs() / scale);
        }
        // A&S 7.1.26's 1.5e-7 on erf, halved by Φ, plus the rounding of `1 + erf` near 2
        // (its ulp is 2.4e-7): about two ulps of the result.
        assert!(
            worst_value <= 2.5e-7,
            "GELU off by {worst_value:e}·max(1, |x|)"
        );
        assert!(
            worst_slope <= 3e-7,
            "GELU′ off by {worst_slope:e}·max(1, |x|)"
        );
    }

    #[test]
    fn every_instruction_set_computes_the_same_bits() {
        let x = grid();
        let (values, slopes) = on_this_cpu(&x);
        let (portable_values, portable_slopes) = kernels::portable(&x);
        assert!(
            values
                .iter()
                .zip(&portable_values)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        assert!(
            slopes
                .iter()
                .zip(&portable_slopes)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    /// Against burn's GELU (libm's `erff`): values, and gradients through a loss that weighs
    /// every entry differently, on a non-contiguous view as well.
    #[test]
    fn matches_burns_gelu_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        let input = Tensor::<3>::random([2, 64, 48], Distribution::Normal(0.0, 2.0), &device);
        let weights = Tensor::<3>::random([2, 48, 64], Distribution::Uniform(-1.0, 1.0), &device);
        let run = |ours: bool| {
            let x = input.clone().detach().require_grad();
            let viewed = x.clone().swap_dims(1, 2);
            let y = if ours {
                gelu(viewed)
            } else {
                activation::gelu(viewed)
            };
            let loss = (y.clone() * weights.clone()).sum();
            let grads = loss.backward();
            (to_vec(y), to_vec(x.grad(&grads).expect("a gradient")))
        };
        let ((ours, our_grad), (burns, burns_grad)) = (run(true), run(false));
        let close = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .all(|(p, q)| (p - q).abs() <= 1e-6 * q.abs().max(1.0))
        };
        assert!(close(&ours, &burns));
        assert!(close(&our_grad, &burns_grad));

        // Off the graph (the cloning stage's transformer) and on the plain device.
        let plain = input.clone().inner();
        assert!(close(
            &to_vec(gelu(plain.clone())),
            &to_vec(activation::gelu(plain))
        ));
    }
}
