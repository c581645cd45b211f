//! Ops that burn-flex runs slowly, written for the CPU learner as custom autodiff ops through
//! burn's `extension` API: VDPO's GELU (libm's scalar `erff`) and layer norm (on the autodiff
//! graph, burn composes it from eight elementwise ops and their backward passes, each a fresh
//! allocation), every algorithm's linear layer with its ReLU (burn zero-fills each product's
//! buffer, adds the bias into another, and ReLU takes a third), dropout's product with a
//! host-drawn mask (an upload and two fresh buffers in burn); beside them Adam's step as one
//! pass (burn takes thirteen). The GELU and layer-norm loops are compiled for AVX-512 and AVX2
//! and picked at run time, in plain multiplies and adds with sums over fixed lanes, so every
//! instruction set computes the same bits; the other ops keep burn's bits. Tensors elsewhere
//! (wgpu, gradient checkpointing) take burn's ops.
use burn::backend::autodiff::checkpoint::strategy::NoCheckpointing;
use burn::backend::autodiff::ops::{Backward, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, DispatchDevice, Flex, GradientCheckpointingStrategy};
use burn::prelude::{Tensor, TensorData};
use burn::tensor::DType;

/// Compiles `$body` (an `#[inline(always)]` function's call) for AVX-512F and AVX2 and runs the
/// best the CPU has, or the baseline build.
macro_rules! best_isa {
    ($name:ident($($arg:ident: $ty:ty),*) $body:block) => {
        pub fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f")]
                fn avx512($($arg: $ty),*) $body
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $body
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU has AVX-512F (checked just above).
                    return unsafe { avx512($($arg),*) };
                }
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2 (checked just above).
                    return unsafe { avx2($($arg),*) };
                }
            }
            $body
        }
    };
}

mod adam;
mod dropout;
mod gelu;
mod layer_norm;
mod linear;

pub use adam::adam;
pub use dropout::times_mask;
pub use gelu::gelu;
pub use layer_norm::layer_norm;
pub use linear::{linear, linear_relu};

/// How an op reaches a tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// A Flex tensor off the graph.
    Plain,
    /// A Flex tensor on burn's autodiff graph (no gradient checkpointing).
    Tracked,
    /// Anything else: burn's own op.
    Burn,
}

fn route<const D: usize>(x: &Tensor<D>) -> Route {
    let device = x.device();
    let on_flex = matches!(
        device.clone().inner().as_dispatch(),
        DispatchDevice::Flex(_)
    );
    if !on_flex || x.dtype() != DType::F32 {
        return Route::Burn;
    }
    match device.gradient_checkpointing_strategy() {
        None => Route::Plain,
        Some(GradientCheckpointingStrategy::Disabled) => Route::Tracked,
        Some(_) => Route::Burn,
    }
}

fn plain<const D: usize>(x: Tensor<D>) -> FlexTensor {
    x.try_into_primitive::<Flex>().expect("a Flex tensor")
}

fn tracked<const D: usize>(x: Tensor<D>) -> FloatTensor<Autodiff<Flex>> {
    x.try_into_primitive::<Autodiff<Flex>>()
        .expect("an autodiff Flex tensor")
}

/// Registers `op` on the graph over `inputs`, its output `forward(inner inputs)`, keeping the
/// inner inputs as the backward pass's state.
fn on_graph<Op, const N: usize>(
    op: Op,
    inputs: [FloatTensor<Autodiff<Flex>>; N],
    forward: impl FnOnce(&[FlexTensor; N]) -> FlexTensor,
) -> FloatTensor<Autodiff<Flex>>
where
    Op: Backward<Flex, N, State = [FlexTensor; N]>,
{
    on_graph_keeping(op, inputs, |inner| (forward(&inner), inner))
}

/// Registers `op` on the graph over `inputs`; `forward` maps the inner inputs to the output and
/// the backward pass's state.
fn on_graph_keeping<Op, const N: usize>(
    op: Op,
    inputs: [FloatTensor<Autodiff<Flex>>; N],
    forward: impl FnOnce([FlexTensor; N]) -> (FlexTensor, Op::State),
) -> FloatTensor<Autodiff<Flex>>
where
    Op: Backward<Flex, N>,
{
    use burn::backend::AutodiffBackend;
    let nodes = inputs.each_ref().map(|input| input.node());
    let (output, state) = forward(inputs.map(Autodiff::<Flex>::inner));
    match op
        .prepare::<NoCheckpointing>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => prep.finish(state, output),
        OpsKind::UnTracked(prep) => prep.finish(output),
    }
}

/// `x` when it alone owns a buffer holding exactly its values in order (so that an op can write
/// over them), else `Err(x)`.
fn writable(mut x: FlexTensor) -> Result<FlexTensor, FlexTensor> {
    let whole_buffer = x.is_contiguous()
        && x.layout().start_offset() == 0
        && x.bytes().len() == x.layout().shape().num_elements() * size_of::<f32>();
    if whole_buffer && x.try_storage_mut::<f32>().is_some() {
        Ok(x)
    } else {
        Err(x)
    }
}

/// `f(x, other)` entry by entry, `other` in `x`'s row-major order, written over `x` when nothing
/// else holds its buffer.
fn zip_with(x: FlexTensor, other: &[f32], f: impl Fn(f32, f32) -> f32) -> FlexTensor {
    match writable(x) {
        Ok(mut x) => {
            for (value, &o) in x.storage_mut::<f32>().iter_mut().zip(other) {
                *value = f(*value, o);
            }
            x
        }
        Err(x) => {
            let out = values(&x)
                .iter()
                .zip(other)
                .map(|(&v, &o)| f(v, o))
                .collect();
            flex(out, x.layout().shape().clone())
        }
    }
}

/// The tensor's values in row-major order (borrowed when its layout already is that).
fn values(x: &FlexTensor) -> std::borrow::Cow<'_, [f32]> {
    match x.as_slice::<f32>() {
        Some(values) => values.into(),
        None => x
            .to_contiguous()
            .as_slice::<f32>()
            .expect("contiguous")
            .to_vec()
            .into(),
    }
}

/// A Flex tensor of `values` in `shape`.
fn flex(values: Vec<f32>, shape: burn::tensor::Shape) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape))
}
