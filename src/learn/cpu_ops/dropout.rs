//! Dropout's product `x · mask`, the mask drawn on the host (VDPO's `DropoutMasks`). burn takes
//! the mask as an upload (a copy into a buffer of its own), multiplies into a fresh buffer and
//! keeps both for a backward multiply into another; here the mask's own buffer is the op's
//! state, the product is written over `x` when nothing else holds it, and the gradient is
//! scaled in place. The same products, so the same bits (tested).
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, unary};
use burn::backend::flex::FlexTensor;
use burn::backend::{Autodiff, Flex};
use burn::prelude::{Tensor, TensorData};

use super::{Route, flex, on_graph_keeping, plain, route, tracked, values, zip_with};
use crate::learn::upload;

/// `x · mask` elementwise, `mask` one entry per entry of `x` in row-major order;
/// differentiable where `x` is.
pub fn times_mask<const D: usize>(x: Tensor<D>, mask: Vec<f32>) -> Tensor<D> {
    let route = match route(&x) {
        _ if mask.len() != x.shape().num_elements() => Route::Burn,
        route => route,
    };
    match route {
        Route::Plain => Tensor::from_primitive::<Flex>(product(plain(x), &mask)),
        Route::Tracked => Tensor::from_primitive::<Autodiff<Flex>>(on_graph_keeping(
            TimesMask,
            [tracked(x)],
            |[x]| {
                let mask = flex(mask, x.layout().shape().clone());
                (product(x, values(&mask).as_ref()), mask)
            },
        )),
        // burn's own: it uploads the mask, and rejects a mask of another size.
        Route::Burn => {
            let shape = x.shape();
            let mask = upload(TensorData::new(mask, shape), &x.device());
            x * mask
        }
    }
}

/// The autodiff op: its state is the mask, by which the backward pass scales the gradient.
#[derive(Debug)]
struct TimesMask;

impl Backward<Flex, 1> for TimesMask {
    type State = FlexTensor;

    fn backward(self, ops: Ops<FlexTensor, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let mask = ops.state;
        unary::<Flex, _>(ops.parents, ops.node, grads, |grad| {
            product(grad, values(&mask).as_ref())
        });
    }
}

/// `x · mask` of a Flex tensor, written over `x` when nothing else holds its buffer.
fn product(x: FlexTensor, mask: &[f32]) -> FlexTensor {
    zip_with(x, mask, |value, m| value * m)
}

#[cfg(test)]
mod tests {
    use burn::prelude::{Device, Tensor};
    use burn::tensor::{Distribution, TensorData};

    use super::times_mask;
    use crate::learn::to_vec;

    fn bits(x: Vec<f32>) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// Value and gradient bit for bit as burn's `x * mask` (the mask as an untracked tensor),
    /// for a tracked `x` written over, one another op still holds, and a transposed view off
    /// the graph; the mask holds zeros and a scale, so signed zeros come out too.
    #[test]
    fn keeps_burns_bits_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        let shape = [2, 3, 5];
        let x = Tensor::<3>::random(shape, Distribution::Normal(0.0, 2.0), &device);
        let mask: Vec<f32> = (0..30)
            .map(|i| if i % 3 == 0 { 0.0 } else { 1.0 / 0.9 })
            .collect();
        let upstream = Tensor::<3>::random(shape, Distribution::Normal(0.0, 1.0), &device);
        let burns = |x: Tensor<3>| {
            let mask = Tensor::<3>::from_data(TensorData::new(mask.clone(), shape), &device);
            x * mask
        };
        for held in [false, true] {
            let ours_x = x.clone().detach().require_grad();
            let theirs_x = x.clone().detach().require_grad();
            // A fresh buffer (the op may write over it) or one that a second use shares.
            let (ours_in, theirs_in) = (
                ours_x.clone().mul_scalar(1.5),
                theirs_x.clone().mul_scalar(1.5),
            );
            let keep = held.then(|| ours_in.clone());
            let ours = times_mask(ours_in, mask.clone());
            let theirs = burns(theirs_in);
            assert_eq!(
                bits(to_vec(ours.clone())),
                bits(to_vec(theirs.clone())),
                "held: {held}"
            );
            let ours_grad = (ours * upstream.clone()).sum().backward();
            let theirs_grad = (theirs * upstream.clone()).sum().backward();
            assert_eq!(
                bits(to_vec(ours_x.grad(&ours_grad).unwrap())),
                bits(to_vec(theirs_x.grad(&theirs_grad).unwrap())),
                "held: {held}"
            );
            if let Some(keep) = keep {
                assert_eq!(
                    to_vec(keep),
                    to_vec(x.clone().mul_scalar(1.5)),
                    "the sharer kept its values"
                );
            }
        }
        let plain = Device::flex();
        let view = Tensor::<3>::random([2, 5, 3], Distribution::Default, &plain).swap_dims(1, 2);
        let mask_plain = Tensor::<3>::from_data(TensorData::new(mask.clone(), shape), &plain);
        assert_eq!(
            bits(to_vec(times_mask(view.clone(), mask.clone()))),
            bits(to_vec(view * mask_plain))
        );
    }
}
