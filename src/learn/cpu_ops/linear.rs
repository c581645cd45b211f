//! The stacked linear layer `y = x·W_s + b_s` as one op, and its backward pass
//! `∂x = g·W_sᵀ`, `∂W_s = x_sᵀ·g`, `∂b_s = Σ_rows g`. burn composes it from a product (whose
//! output buffer burn-flex zero-fills before gemm overwrites it), a broadcast add (a second
//! buffer) and the add's and the reshape's backward passes. Here gemm writes each product
//! straight into a fresh buffer and the bias is added in place. The products are burn-flex's
//! own gemm calls (the same strides and threading) and the bias's gradient is burn's own sum,
//! so the op's value and its three gradients keep burn's bits (tested). (A tensor that takes
//! three or more gradients may sum them in another order than before: the graph is one node
//! shallower.) A hidden layer's ReLU joins it (`linear_relu`): written over the output as the
//! bias is added, and in the backward pass the gradient masked in place where the output is 0,
//! as burn's ReLU and its backward pass compute them.
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::ops::FloatTensorOps;
use burn::backend::{Autodiff, Flex};
use burn::prelude::Tensor;
use burn::tensor::Shape;
use burn::tensor::activation;
use rayon::prelude::*;

use super::{Route, flex, on_graph_keeping, plain, route, tracked, values, zip_with};

/// `x` `[S, B, in]` times each run's `weight` `[S, in, out]` plus its `bias` `[S, out]`:
/// `[S, B, out]`, differentiable in all three where they are.
pub fn linear(x: Tensor<3>, weight: Tensor<3>, bias: Tensor<2>) -> Tensor<3> {
    layer(x, weight, bias, false)
}

/// `relu(linear(x, weight, bias))`: a hidden layer.
pub fn linear_relu(x: Tensor<3>, weight: Tensor<3>, bias: Tensor<2>) -> Tensor<3> {
    layer(x, weight, bias, true)
}

/// The layer, with its ReLU when `relu`.
fn layer(x: Tensor<3>, weight: Tensor<3>, bias: Tensor<2>, relu: bool) -> Tensor<3> {
    match [route(&x), route(&weight), route(&bias)] {
        [Route::Plain, Route::Plain, Route::Plain] if ours(&x, &weight, &bias) => {
            Tensor::from_primitive::<Flex>(forward(&[plain(x), plain(weight), plain(bias)], relu))
        }
        [Route::Tracked, Route::Tracked, Route::Tracked] if ours(&x, &weight, &bias) => {
            Tensor::from_primitive::<Autodiff<Flex>>(on_graph_keeping(
                Linear,
                [tracked(x), tracked(weight), tracked(bias)],
                |inputs| {
                    let output = forward(&inputs, relu);
                    // ReLU's backward pass reads where its output was above 0.
                    let relu_output = relu.then(|| output.clone());
                    (output, (inputs, relu_output))
                },
            ))
        }
        _ if relu => activation::relu(composed(x, weight, bias)),
        _ => composed(x, weight, bias),
    }
}

/// Whether the op takes these sizes: anything else (a broadcast run axis or bias, no rows,
/// mismatched sizes) is burn's to broadcast or to reject.
fn ours(x: &Tensor<3>, weight: &Tensor<3>, bias: &Tensor<2>) -> bool {
    let ([runs, rows, input], [weight_runs, weight_input, output]) = (x.dims(), weight.dims());
    runs == weight_runs && rows > 0 && input == weight_input && bias.dims() == [runs, output]
}

/// burn's own composition of the layer (its product, then a broadcast add).
fn composed(x: Tensor<3>, weight: Tensor<3>, bias: Tensor<2>) -> Tensor<3> {
    x.matmul(weight) + bias.unsqueeze_dim(1)
}

/// Its state is the inputs `[x, W, b]` (b for its shape) and, after a ReLU, the output.
#[derive(Debug)]
struct Linear;

impl Backward<Flex, 3> for Linear {
    type State = ([FlexTensor; 3], Option<FlexTensor>);

    fn backward(
        self,
        ops: Ops<([FlexTensor; 3], Option<FlexTensor>), 3>,
        grads: &mut Gradients,
        _: &mut Checkpointer,
    ) {
        let ([x, weight, bias], relu_output) = ops.state;
        let grad = grads.consume::<Flex>(&ops.node);
        let grad = match &relu_output {
            Some(output) => relu_gradient(output, grad),
            None => grad,
        };
        let [to_x, to_weight, to_bias] = ops.parents;
        // burn's order: the add's backward (the bias), then the product's (x, then W).
        if let Some(parent) = to_bias {
            let rows = grad.layout().shape()[1];
            // burn sums over the broadcast axis only where it is broadcast (B > 1).
            let summed = if rows > 1 {
                Flex::float_sum_dim(grad.clone(), 1)
            } else {
                grad.clone()
            };
            let shape = bias.layout().shape().clone();
            grads.register::<Flex>(parent.id, Flex::float_reshape(summed, shape));
        }
        if let Some(parent) = to_x {
            let (dx, shape) = product(&grad, &weight.transpose(1, 2));
            grads.register::<Flex>(parent.id, flex(dx, shape));
        }
        if let Some(parent) = to_weight {
            let (dweight, shape) = product(&x.transpose(1, 2), &grad);
            grads.register::<Flex>(parent.id, flex(dweight, shape));
        }
    }
}

/// `grad` where ReLU's `output` passed it (above 0, or NaN), 0 elsewhere: burn-flex's
/// `relu_backward`, written over `grad` when nothing else holds it.
fn relu_gradient(output: &FlexTensor, grad: FlexTensor) -> FlexTensor {
    zip_with(grad, &values(output), |g, out| {
        if out.is_nan() || out > 0.0 { g } else { 0.0 }
    })
}

/// The layer's output, its ReLU applied as the bias is added when `relu` (burn-flex's: a NaN
/// passes, anything not above 0 becomes 0).
fn forward([x, weight, bias]: &[FlexTensor; 3], relu: bool) -> FlexTensor {
    let (mut out, shape) = product(x, weight);
    let (rows, output) = (shape[1], shape[2]);
    if rows * output > 0 {
        for (run, run_bias) in out
            .chunks_mut(rows * output)
            .zip(values(bias).chunks(output))
        {
            for row in run.chunks_exact_mut(output) {
                for (y, b) in row.iter_mut().zip(run_bias) {
                    *y += b;
                    if relu && !(y.is_nan() || *y > 0.0) {
                        *y = 0.0;
                    }
                }
            }
        }
    }
    flex(out, shape)
}

/// One operand of a batched product: its storage, where it starts, and its strides (batch,
/// row, column), the batch stride 0 for a batch of one, as burn-flex reads them.
struct Operand<'a> {
    values: &'a [f32],
    start: isize,
    batch: isize,
    row: isize,
    column: isize,
}

impl<'a> Operand<'a> {
    fn of(tensor: &'a FlexTensor) -> Operand<'a> {
        let layout = tensor.layout();
        let strides = layout.strides();
        Operand {
            values: tensor.storage::<f32>(),
            start: layout.start_offset() as isize,
            batch: if layout.shape()[0] > 1 { strides[0] } else { 0 },
            row: strides[1],
            column: strides[2],
        }
    }

    /// Where matrix `b` of the batch starts.
    fn matrix(&self, b: usize) -> *const f32 {
        self.values
            .as_ptr()
            .wrapping_offset(self.start + b as isize * self.batch)
    }
}

/// gemm's sizes (products of `m × n × k`) above which burn-flex spreads one matrix over the
/// threads, and a batch of them over the threads, one matrix each.
const PARALLEL_MATRIX: usize = 192 * 192 * 192;
const PARALLEL_BATCH: usize = 128 * 128 * 128;

/// `lhs·rhs` per run, `[S, m, k]`·`[S, k, n]` → `[S, m, n]` (row-major), through the gemm calls
/// burn-flex's batched product makes, into a buffer that is not filled first.
fn product(lhs: &FlexTensor, rhs: &FlexTensor) -> (Vec<f32>, Shape) {
    let lhs_shape = lhs.layout().shape();
    let (runs, m, k, n) = (
        lhs_shape[0],
        lhs_shape[1],
        lhs_shape[2],
        rhs.layout().shape()[2],
    );
    let (lhs, rhs) = (Operand::of(lhs), Operand::of(rhs));
    let matrix = m.checked_mul(n).expect("a product's size fits in memory");
    let len = runs
        .checked_mul(matrix)
        .expect("a product's size fits in memory");
    let mut out = Vec::<f32>::with_capacity(len);
    // The tests fill the buffer with NaN first: a read before gemm's write would show.
    #[cfg(test)]
    out.spare_capacity_mut()[..len].fill(std::mem::MaybeUninit::new(f32::NAN));
    let one = |b: usize, dst: *mut f32, parallelism: gemm::Parallelism| {
        // SAFETY: `dst` has room for the `m × n` matrix at row stride `n`, the operands'
        // pointers and strides are their tensors' own, and with `read_dst` false gemm writes
        // every entry of `dst` (zeros when `k` is 0) without reading it.
        unsafe {
            gemm::gemm(
                m,
                n,
                k,
                dst,
                1,
                n as isize,
                false,
                lhs.matrix(b),
                lhs.column,
                lhs.row,
                rhs.matrix(b),
                rhs.column,
                rhs.row,
                0.0,
                1.0,
                false,
                false,
                false,
                parallelism,
            )
        }
    };
    if matrix > 0 {
        let per_matrix = matrix.saturating_mul(k);
        let total = runs.saturating_mul(per_matrix);
        let batch_parallel = runs >= 4 && total >= PARALLEL_BATCH;
        let slots = &mut out.spare_capacity_mut()[..len];
        if per_matrix >= PARALLEL_MATRIX && !batch_parallel {
            for (b, dst) in slots.chunks_mut(matrix).enumerate() {
                one(b, dst.as_mut_ptr().cast(), gemm::Parallelism::Rayon(0));
            }
        } else if total >= PARALLEL_BATCH && runs > 1 {
            slots
                .par_chunks_mut(matrix)
                .enumerate()
                .for_each(|(b, dst)| one(b, dst.as_mut_ptr().cast(), gemm::Parallelism::None));
        } else {
            for (b, dst) in slots.chunks_mut(matrix).enumerate() {
                one(b, dst.as_mut_ptr().cast(), gemm::Parallelism::None);
            }
        }
    }
    // SAFETY: the loops above wrote all `len` entries (none when `m × n` is 0).
    unsafe { out.set_len(len) };
    (out, Shape::new([runs, m, n]))
}

#[cfg(test)]
mod tests {
    use burn::prelude::{Device, Tensor};
    use burn::tensor::Distribution;

    use burn::tensor::activation::relu;

    use super::{composed, linear, linear_relu};
    use crate::learn::to_vec;

    /// The layer (with ReLU after it when `hidden`) by our op or by burn's composition.
    fn layer(
        ours: bool,
        hidden: bool,
        x: Tensor<3>,
        weight: Tensor<3>,
        bias: Tensor<2>,
    ) -> Tensor<3> {
        match (ours, hidden) {
            (true, false) => linear(x, weight, bias),
            (true, true) => linear_relu(x, weight, bias),
            (false, false) => composed(x, weight, bias),
            (false, true) => relu(composed(x, weight, bias)),
        }
    }

    /// The output and the gradients of x (where it has one), W and b, by our op or by burn's
    /// composition, under a loss weighting every entry of the output differently.
    fn run(
        (ours, hidden): (bool, bool),
        x: &Tensor<3>,
        params: &[Tensor<3>; 2],
        bias: &Tensor<2>,
    ) -> Vec<Vec<f32>> {
        let [weight, loss_weights] = params;
        let x_tracked = x.is_require_grad();
        let (weight, bias) = (
            weight.clone().detach().require_grad(),
            bias.clone().detach().require_grad(),
        );
        let y = layer(ours, hidden, x.clone(), weight.clone(), bias.clone());
        let grads = (y.clone() * loss_weights.clone()).sum().backward();
        let mut out = vec![to_vec(y)];
        if x_tracked {
            out.push(to_vec(x.grad(&grads).expect("x's gradient")));
        }
        out.push(to_vec(weight.grad(&grads).expect("W's gradient")));
        out.push(to_vec(bias.grad(&grads).expect("b's gradient")));
        out
    }

    fn bits(values: &[Vec<f32>]) -> Vec<Vec<u32>> {
        values
            .iter()
            .map(|v| v.iter().map(|f| f.to_bits()).collect())
            .collect()
    }

    /// Every shape the learners use: a critic's scalar head, one row (a solo run acting, and in
    /// a stack), small stacks, a stack of four spread over the threads one matrix each, one
    /// large matrix spread over the threads; x contiguous and tracked, or a transposed view off
    /// the graph (an input); W contiguous, or a transposed view.
    #[test]
    fn keeps_burns_bits_in_value_and_every_gradient() {
        let device = Device::flex().autodiff();
        let shapes = [
            (1, 7, 5, 1),
            (1, 1, 6, 4),
            (2, 1, 9, 3),
            (3, 33, 17, 8),
            (4, 256, 256, 256),
            (1, 256, 256, 256),
        ];
        for (runs, rows, input, output) in shapes {
            let normal = Distribution::Normal(0.0, 1.0);
            let weight = Tensor::<3>::random([runs, input, output], normal, &device);
            let weight_view =
                Tensor::<3>::random([runs, output, input], normal, &device).swap_dims(1, 2);
            let bias = Tensor::<2>::random([runs, output], normal, &device);
            let loss_weights = Tensor::<3>::random([runs, rows, output], normal, &device);
            let contiguous = Tensor::<3>::random([runs, rows, input], normal, &device);
            let transposed =
                Tensor::<3>::random([runs, input, rows], normal, &device).swap_dims(1, 2);
            let cases = [
                (contiguous.require_grad(), weight.clone()),
                (transposed, weight_view),
            ];
            for (x, weight) in cases {
                let params = [weight, loss_weights.clone()];
                for hidden in [false, true] {
                    let ours = run((true, hidden), &x, &params, &bias);
                    let burns = run((false, hidden), &x, &params, &bias);
                    assert_eq!(ours.len(), burns.len());
                    assert!(
                        bits(&ours) == bits(&burns),
                        "{runs}×{rows}×{input}→{output}, x tracked: {}, ReLU: {hidden}",
                        x.is_require_grad()
                    );
                }
            }
            // Off the graph (target networks, acting), on the plain device.
            let (weight, bias) = (weight.inner(), bias.inner());
            let x = Tensor::<3>::random([runs, rows, input], normal, &weight.device());
            for hidden in [false, true] {
                let ours = layer(true, hidden, x.clone(), weight.clone(), bias.clone());
                let burns = layer(false, hidden, x.clone(), weight.clone(), bias.clone());
                assert!(bits(&[to_vec(ours)]) == bits(&[to_vec(burns)]));
            }
        }
    }

    /// ReLU keeps a NaN (as burn's does) and zeroes what is not above 0, in value and gradient.
    #[test]
    fn relu_passes_nan_and_stops_at_zero_as_burns() {
        let device = Device::flex().autodiff();
        // x·W is [NaN, 0, −1, 2] across the four outputs of the one row.
        let x = Tensor::<3>::from_floats([[[1.0, 0.0]]], &device).require_grad();
        let weight = Tensor::<3>::from_floats(
            [[[f32::NAN, 0.0, -1.0, 2.0], [5.0, 5.0, 5.0, 5.0]]],
            &device,
        );
        let bias = Tensor::<2>::zeros([1, 4], &device);
        let loss_weights = Tensor::<3>::from_floats([[[1.0, 2.0, 3.0, 4.0]]], &device);
        let params = [weight, loss_weights];
        let ours = run((true, true), &x, &params, &bias);
        let burns = run((false, true), &x, &params, &bias);
        assert!(bits(&ours) == bits(&burns));
        assert!(ours[0][0].is_nan() && ours[0][1..] == [0.0, 0.0, 2.0]);
    }

    /// A bias shared by every run of the stack is not the op's: burn broadcasts it.
    #[test]
    fn leaves_a_broadcast_bias_to_burn() {
        let device = Device::flex();
        let normal = Distribution::Normal(0.0, 1.0);
        let x = Tensor::<3>::random([2, 5, 3], normal, &device);
        let weight = Tensor::<3>::random([2, 3, 4], normal, &device);
        let shared = Tensor::<2>::random([1, 4], normal, &device);
        let ours = linear(x.clone(), weight.clone(), shared.clone());
        let burns = composed(x, weight, shared);
        assert!(bits(&[to_vec(ours)]) == bits(&[to_vec(burns)]));
    }
}
