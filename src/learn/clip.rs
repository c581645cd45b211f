//! Gradient-norm clipping of a stacked module, run by run: PyTorch's `clip_grad_norm_` (one
//! norm over all of a network's parameters, the gradients scaled by `max / (norm + 1e-6)`
//! where that is below 1) applied to each run's slice on its own, as if each run had its
//! own network. burn's optimiser clipping works per parameter tensor, so it cannot say this.
use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;

/// PyTorch's `clip_grad_norm_` guard against a zero norm.
const NORM_GUARD: f64 = 1e-6;

/// Scales each run's gradients in `grads` (the leading axis of every parameter of `module`
/// indexes the runs) so that its L2 norm over all of `module`'s parameters is at most
/// `max_norm`. Returns each run's norm before clipping, `[S]`.
pub fn clip_norm_per_run<M: Module>(
    grads: &mut GradientsParams,
    module: &M,
    max_norm: f64,
) -> Tensor<1> {
    let mut squared = SquaredNorms { grads, total: None };
    module.visit(&mut squared);
    let norm = squared
        .total
        .expect("a module with parameters has gradients")
        .sqrt();
    let factor = norm
        .clone()
        .add_scalar(NORM_GUARD)
        .recip()
        .mul_scalar(max_norm)
        .clamp_max(1.0);
    module.visit(&mut Scale { grads, factor });
    norm
}

/// Sums each run's squared gradient entries over every parameter.
struct SquaredNorms<'a> {
    grads: &'a GradientsParams,
    total: Option<Tensor<1>>,
}

impl ModuleVisitor for SquaredNorms<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let Some(grad) = self.grads.get::<D>(param.id) else {
            return;
        };
        let runs = grad.dims()[0];
        let per_run: Tensor<1> = grad
            .square()
            .reshape([runs as i32, -1])
            .sum_dim(1)
            .reshape([runs]);
        self.total = Some(match self.total.take() {
            Some(total) => total + per_run,
            None => per_run,
        });
    }
}

/// Multiplies each run's slice of every gradient by that run's factor.
struct Scale<'a> {
    grads: &'a mut GradientsParams,
    factor: Tensor<1>,
}

impl ModuleVisitor for Scale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let Some(grad) = self.grads.remove::<D>(param.id) else {
            return;
        };
        let mut shape = [1usize; D];
        shape[0] = grad.dims()[0];
        let factor = self.factor.clone().reshape(shape);
        self.grads.register(param.id, grad * factor);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::{Mlp, MlpConfig, stack, to_vec};

    /// Collects every parameter's id and shape.
    struct Ids(Vec<(burn::module::ParamId, Vec<usize>)>);
    impl ModuleVisitor for Ids {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push((param.id, param.val().dims().to_vec()));
        }
    }

    #[test]
    fn each_run_is_clipped_to_the_norm_over_all_its_parameters() {
        let device = Device::default();
        let module: Mlp = stack(
            (0..2)
                .map(|_| MlpConfig::new(3, &[4], 2).init(&device))
                .collect(),
        );
        let mut ids = Ids(Vec::new());
        module.visit(&mut ids);
        // Run 0's entries are all 1, run 1's all 0.01: run 0's norm is √n, run 1's 0.01·√n.
        let mut grads = GradientsParams::new();
        let mut per_run_entries = 0;
        for (id, shape) in &ids.0 {
            let entries: usize = shape[1..].iter().product();
            per_run_entries += entries;
            let values: Vec<f32> = (0..shape[0])
                .flat_map(|run| vec![if run == 0 { 1.0 } else { 0.01 }; entries])
                .collect();
            match shape.len() {
                2 => grads.register(
                    *id,
                    Tensor::<2>::from_data(TensorData::new(values, shape.clone()), &device),
                ),
                3 => grads.register(
                    *id,
                    Tensor::<3>::from_data(TensorData::new(values, shape.clone()), &device),
                ),
                other => panic!("a stacked MLP has rank-2 and rank-3 parameters, not rank {other}"),
            }
        }
        let n = per_run_entries as f64;
        let norms = to_vec(clip_norm_per_run(&mut grads, &module, 1.0));
        assert!(
            (norms[0] as f64 - n.sqrt()).abs() < 1e-3 * n.sqrt(),
            "{norms:?}"
        );
        assert!(
            (norms[1] as f64 - 0.01 * n.sqrt()).abs() < 1e-5 * n.sqrt(),
            "{norms:?}"
        );
        // After: run 0 at norm 1 (every entry 1/(√n + 1e-6)), run 1 untouched.
        let after = to_vec(clip_norm_per_run(&mut grads, &module, 1.0));
        assert!((after[0] - 1.0).abs() < 1e-4, "{after:?}");
        assert!(
            (after[1] as f64 - 0.01 * n.sqrt()).abs() < 1e-5 * n.sqrt(),
            "{after:?}"
        );
    }
}
