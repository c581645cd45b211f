//! Adam (Kingma & Ba 2015, Algorithm 1, bias corrections arranged as burn's `AdaptiveMomentum`:
//! `θ ← θ − lr · (m·√(1−β₂ᵗ)/(1−β₁ᵗ)) / (√v + ε·√(1−β₂ᵗ))`) as one pass over each parameter.
//! burn runs it as thirteen elementwise ops, each a pass over the parameter and its moments,
//! most into a fresh buffer: 9% of a SAC update on the EPYC. The state is burn's own
//! `AdamState` (checkpoints are unchanged) and each value goes through the same f32 operations
//! in the same order, so the bits are burn's (tested); a tensor off the CPU backend (wgpu) or
//! not f32 takes burn's step.
use burn::backend::Flex;
use burn::backend::flex::FlexTensor;
use burn::optim::{
    Adam, AdamConfig, AdamState, AdaptiveMomentumState, LearningRate, ModuleOptimizer, Optimizer,
};
use burn::prelude::{Device, Tensor};

use super::{Route, flex, plain, route, values, writable};

/// burn's defaults, which every learner keeps.
const BETA_1: f32 = 0.9;
const BETA_2: f32 = 0.999;

/// Adam with ε = `epsilon`, β = (0.9, 0.999), no weight decay: the optimiser of every learner.
pub fn adam(epsilon: f64) -> ModuleOptimizer {
    let epsilon = epsilon as f32;
    let burn = AdamConfig::new()
        .with_beta_1(BETA_1)
        .with_beta_2(BETA_2)
        .with_epsilon(epsilon)
        .build();
    ModuleOptimizer::from(FusedAdam { burn, epsilon })
}

#[derive(Clone)]
struct FusedAdam {
    /// The same Adam as burn runs it, for the tensors the pass does not take.
    burn: Adam,
    epsilon: f32,
}

/// The step's scalars, each computed as burn computes it (in f32).
struct Coefficients {
    /// `1 − β₁`: the new gradient's weight in the first moment.
    gradient_weight_1: f32,
    /// `1 − β₂`: the squared gradient's weight in the second moment.
    gradient_weight_2: f32,
    /// `√(1−β₂ᵗ)/(1−β₁ᵗ)`: both bias corrections, on the first moment.
    step_scale: f32,
    /// `ε·√(1−β₂ᵗ)`.
    scaled_epsilon: f32,
    learning_rate: f32,
}

impl Optimizer for FusedAdam {
    type State<const D: usize> = AdamState<D>;

    fn step<const D: usize>(
        &self,
        lr: LearningRate,
        tensor: Tensor<D>,
        grad: Tensor<D>,
        state: Option<AdamState<D>>,
    ) -> (Tensor<D>, Option<AdamState<D>>) {
        let dims = tensor.dims();
        let ours = |x: &Tensor<D>| route(x) == Route::Plain && x.dims() == dims;
        let fused = ours(&tensor)
            && ours(&grad)
            && state.as_ref().is_none_or(|s| {
                let m = &s.momentum;
                m.max_moment_2.is_none() && ours(&m.moment_1) && ours(&m.moment_2)
            });
        if !fused {
            return self.burn.step(lr, tensor, grad, state);
        }
        let time = state.as_ref().map_or(1, |s| s.momentum.time + 1);
        let bias_correction_2 = (1.0 - BETA_2.powi(time as i32)).sqrt();
        let k = Coefficients {
            gradient_weight_1: 1.0 - BETA_1,
            gradient_weight_2: 1.0 - BETA_2,
            step_scale: bias_correction_2 / (1.0 - BETA_1.powi(time as i32)),
            scaled_epsilon: self.epsilon * bias_correction_2,
            learning_rate: lr as f32,
        };
        let grad = plain(grad);
        let grad = values(&grad);
        let (mut moment_1, mut moment_2) = match state {
            Some(s) => (
                writable(plain(s.momentum.moment_1)).unwrap_or_else(copied),
                writable(plain(s.momentum.moment_2)).unwrap_or_else(copied),
            ),
            None => {
                let shape = burn::tensor::Shape::from(dims);
                let zeros = || flex(vec![0.0; grad.len()], shape.clone());
                (zeros(), zeros())
            }
        };
        let n = grad.len();
        let (moment_1_values, moment_2_values) = (moment_1.storage_mut(), moment_2.storage_mut());
        let mut step = |target: kernels::Target<'_>| {
            kernels::adam_step(
                target,
                moment_1_values,
                moment_2_values,
                &grad,
                &k,
                time == 1,
            );
        };
        let param = match writable(plain(tensor)) {
            Ok(mut param) => {
                step(kernels::Target::InPlace(param.storage_mut()));
                param
            }
            // Shared (the learners step a clone of the module they hold): the new values go
            // into a buffer of their own, as burn's step writes every parameter.
            Err(shared) => {
                let mut updated = Vec::with_capacity(n);
                step(kernels::Target::Fresh {
                    from: &values(&shared),
                    into: &mut updated.spare_capacity_mut()[..n],
                });
                // SAFETY: the step sliced every input to `n` entries (panicking on a shorter
                // one) and wrote each of the `n` entries of `into`.
                unsafe { updated.set_len(n) };
                flex(updated, shared.layout().shape().clone())
            }
        };
        let state = AdamState::new(AdaptiveMomentumState::new(
            time,
            Tensor::from_primitive::<Flex>(moment_1),
            Tensor::from_primitive::<Flex>(moment_2),
        ));
        (Tensor::from_primitive::<Flex>(param), Some(state))
    }

    fn to_device<const D: usize>(state: AdamState<D>, device: &Device) -> AdamState<D> {
        Adam::to_device(state, device)
    }
}

/// A copy of `x`'s values in a buffer of their own.
fn copied(x: FlexTensor) -> FlexTensor {
    flex(values(&x).into_owned(), x.layout().shape().clone())
}

mod kernels {
    use std::mem::MaybeUninit;

    use super::{BETA_1, BETA_2, Coefficients};

    /// Where the step writes the parameter.
    pub enum Target<'a> {
        /// Over its own values.
        InPlace(&'a mut [f32]),
        /// Into a fresh buffer, from values another tensor shares.
        Fresh {
            from: &'a [f32],
            into: &'a mut [MaybeUninit<f32>],
        },
    }

    /// One entry's step, each operation burn's in burn's order: `m ← m·β₁ + g·(1−β₁)`,
    /// `v ← v·β₂ + g²·(1−β₂)` (on the first step `m ← g·(1−β₁)`, `v ← g²·(1−β₂)`),
    /// `θ ← θ − ((m·c) / (√v + ε′))·lr`. Returns `(θ, m, v)`.
    #[inline(always)]
    fn entry(p: f32, m: f32, v: f32, g: f32, k: &Coefficients, first: bool) -> (f32, f32, f32) {
        let (m, v) = if first {
            (g * k.gradient_weight_1, g * g * k.gradient_weight_2)
        } else {
            (
                m * BETA_1 + g * k.gradient_weight_1,
                v * BETA_2 + g * g * k.gradient_weight_2,
            )
        };
        (
            p - m * k.step_scale / (v.sqrt() + k.scaled_epsilon) * k.learning_rate,
            m,
            v,
        )
    }

    #[inline(always)]
    fn adam_loop(
        target: Target<'_>,
        moment_1: &mut [f32],
        moment_2: &mut [f32],
        grad: &[f32],
        k: &Coefficients,
        first: bool,
    ) {
        let n = grad.len();
        let moments = moment_1[..n].iter_mut().zip(&mut moment_2[..n]).zip(grad);
        match target {
            Target::InPlace(param) => {
                for (p, ((m, v), &g)) in param[..n].iter_mut().zip(moments) {
                    (*p, *m, *v) = entry(*p, *m, *v, g, k, first);
                }
            }
            Target::Fresh { from, into } => {
                for ((out, &p), ((m, v), &g)) in into[..n].iter_mut().zip(&from[..n]).zip(moments) {
                    let updated;
                    (updated, *m, *v) = entry(p, *m, *v, g, k, first);
                    out.write(updated);
                }
            }
        }
    }

    best_isa!(adam_step(target: Target<'_>, moment_1: &mut [f32], moment_2: &mut [f32], grad: &[f32], k: &Coefficients, first: bool) {
        adam_loop(target, moment_1, moment_2, grad, k, first)
    });
}

#[cfg(test)]
mod tests {
    use burn::module::{Module, Param};
    use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
    use burn::prelude::{Device, Tensor};

    use crate::learn::to_vec;

    /// A parameter of every shape the learners step: a stack of weights, a bias, a scalar.
    #[derive(Module, Debug)]
    struct Params {
        weight: Param<Tensor<3>>,
        bias: Param<Tensor<2>>,
        log_alpha: Param<Tensor<1>>,
    }

    /// The same start every call, each tensor in a buffer of its own.
    fn params(device: &Device) -> Params {
        let values = |n: usize, phase: f32| -> Vec<f32> {
            (0..n).map(|i| (i as f32 * 0.7 + phase).sin()).collect()
        };
        Params {
            weight: Param::from_tensor(
                Tensor::<1>::from_floats(values(70, 0.0).as_slice(), device).reshape([2, 7, 5]),
            ),
            bias: Param::from_tensor(
                Tensor::<1>::from_floats(values(10, 1.0).as_slice(), device).reshape([2, 5]),
            ),
            log_alpha: Param::from_tensor(Tensor::zeros([1], device)),
        }
    }

    /// A loss whose gradients span many magnitudes (from ~1e-12 to ~1e3), signed zeros among
    /// them, so that the moments reach tiny values and the corrections matter.
    fn loss(p: &Params, step: usize) -> Tensor<1> {
        let scale = 10f32.powi((step as i32 % 16) - 12);
        let w = p.weight.val();
        let bent = w.clone().mul(w.clone()).mul_scalar(scale).sum()
            + w.slice([0..1, 0..1, 0..5]).sin().sum().mul_scalar(1e3);
        bent + p.bias.val().exp().sum() + p.log_alpha.val().mul_scalar(-0.5 * step as f32).sum()
    }

    fn flat(p: &Params) -> Vec<u32> {
        [
            to_vec(p.weight.val()),
            to_vec(p.bias.val()),
            to_vec(p.log_alpha.val()),
        ]
        .concat()
        .iter()
        .map(|v| v.to_bits())
        .collect()
    }

    /// `optimizer`'s steps `steps` from `p`: the parameters' bits after each. With `shared`,
    /// a clone of the module is held through every step (as the learners hold theirs).
    fn steps(
        optimizer: &mut ModuleOptimizer,
        mut p: Params,
        steps: std::ops::Range<usize>,
        shared: bool,
    ) -> Vec<Vec<u32>> {
        let mut after = Vec::new();
        for step in steps {
            let grads = GradientsParams::from_grads(loss(&p, step).backward(), &p);
            let held = shared.then(|| p.clone());
            p = optimizer.step(3e-3, p, grads);
            drop(held);
            after.push(flat(&p));
        }
        after
    }

    /// Each of thirty steps from the same start leaves the same bits as burn's Adam, stepped in
    /// place or into a new buffer (every step reads the moments and the step count, so they
    /// are equal too).
    #[test]
    fn the_pass_keeps_burns_bits() {
        let device = Device::flex().autodiff();
        for (epsilon, shared) in [(1e-8f32, false), (1e-8, true), (1e-5, false)] {
            let ours = steps(
                &mut super::adam(f64::from(epsilon)),
                params(&device),
                0..30,
                shared,
            );
            let burns = steps(
                &mut AdamConfig::new().with_epsilon(epsilon).init(),
                params(&device),
                0..30,
                shared,
            );
            for (step, (ours, burns)) in ours.iter().zip(&burns).enumerate() {
                assert_eq!(
                    ours, burns,
                    "parameters after step {step}, ε = {epsilon}, shared: {shared}"
                );
            }
        }
    }

    /// Moments saved by burn's Adam resume in the pass with the same next steps as in burn's
    /// (the record is burn's own type).
    #[test]
    fn a_checkpoint_of_burns_adam_resumes_in_the_pass() {
        let device = Device::flex().autodiff();
        let mut p = params(&device);
        let mut burns = AdamConfig::new().with_epsilon(1e-8).init();
        for step in 0..5 {
            let grads = GradientsParams::from_grads(loss(&p, step).backward(), &p);
            p = burns.step(3e-3, p, grads);
        }
        let bytes = burns.into_bytes().unwrap();
        let resume = |optimizer: ModuleOptimizer| {
            let mut optimizer = optimizer.from_bytes(bytes.clone()).unwrap();
            steps(&mut optimizer, p.clone(), 5..12, false)
        };
        assert_eq!(
            resume(super::adam(1e-8)),
            resume(AdamConfig::new().with_epsilon(1e-8).init())
        );
    }

    /// Where the weights' values live: a parameter nothing else holds is stepped in its own
    /// buffer; one that a clone shares (a target network) is stepped into a new buffer, and
    /// the clone keeps its values.
    #[test]
    fn steps_in_place_only_what_nothing_else_holds() {
        let buffer = |p: &Params| super::plain(p.weight.val().inner()).bytes().as_ptr();
        let device = Device::flex().autodiff();
        let mut optimizer = super::adam(1e-8);
        let mut p = params(&device);
        for step in 0..2 {
            let before = buffer(&p);
            let grads = GradientsParams::from_grads(loss(&p, step).backward(), &p);
            p = optimizer.step(3e-3, p, grads);
            assert_eq!(buffer(&p), before, "step {step} in place");
        }
        let target = p.clone().no_grad();
        let values = flat(&target);
        let grads = GradientsParams::from_grads(loss(&p, 2).backward(), &p);
        let stepped = optimizer.step(3e-3, p, grads);
        assert_ne!(buffer(&stepped), buffer(&target));
        assert_eq!(flat(&target), values);
        assert_ne!(flat(&stepped), values);
    }
}
