//! Stacked networks: the networks of S independent runs held in one set of tensors, every
//! parameter with a leading axis S (a linear layer's weight `[S, in, out]`), so that one
//! batched matrix product serves all of them — as jaxrl's `train_parallel` and BRO map SAC over
//! seeds, and CORL's ensembles keep one `[E, in, out]` weight per layer. A solo run is S = 1.
//!
//! Slice `i` is drawn exactly as run `i`'s solo network (built alone after seeding the device
//! with its seed, then [`stack`]ed), and its products read only slice `i`: on burn's CPU
//! backend a slice computes its solo run's values and gradients bit for bit
//! (`tests/stack.rs`). On disk a slice keeps the solo shapes (the leading axis dropped, see
//! [`slice_pack`]): a stacked run's checkpoint is a solo run's, and one written before stacking
//! loads as S = 1.
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::nn::{LayerNorm, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Bytes;
use burn_pack::{Reader, Writer};

use super::tensors::to_vec;
use crate::acting::{Dense, Norm};

/// `y = x·W + b` for each of S runs: `W` `[S, in, out]`, `b` `[S, out]`, on inputs `[S, B, in]`.
/// Its fields carry the names of burn's `Linear`, so that a slice's record reads as one.
#[derive(Module, Debug)]
pub struct StackedLinear {
    pub weight: Param<Tensor<3>>,
    pub bias: Param<Tensor<2>>,
}

impl StackedLinear {
    /// One run's layer (S = 1), drawn from the device's generator as burn's
    /// `LinearConfig::new(input, output)` draws it (weight, then bias; Kaiming-uniform by fan-in).
    pub fn new(input: usize, output: usize, device: &Device) -> StackedLinear {
        StackedLinear::from_burn(&LinearConfig::new(input, output).init(device))
    }

    /// burn's layer as a one-run stack (its weight drawn first, then its bias, if they are
    /// not yet drawn).
    pub fn from_burn(layer: &Linear) -> StackedLinear {
        let weight = layer.weight.val().unsqueeze_dim::<3>(0);
        let bias = layer
            .bias
            .as_ref()
            .expect("burn's linear layers have a bias by default")
            .val()
            .unsqueeze_dim::<2>(0);
        StackedLinear {
            weight: Param::from_tensor(weight.detach()),
            bias: Param::from_tensor(bias.detach()),
        }
    }

    /// `[S, B, in]` → `[S, B, out]` ([`cpu_ops::linear`](super::cpu_ops::linear)).
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        super::cpu_ops::linear(x, self.weight.val(), self.bias.val())
    }

    /// `relu(forward(x))`, a hidden layer ([`cpu_ops::linear_relu`](super::cpu_ops::linear_relu)).
    pub fn forward_relu(&self, x: Tensor<3>) -> Tensor<3> {
        super::cpu_ops::linear_relu(x, self.weight.val(), self.bias.val())
    }

    /// Slice `slice`'s weights as plain numbers (for export).
    pub fn dense(&self, slice: usize) -> Dense {
        let [_, input, output] = self.weight.val().dims();
        Dense {
            input,
            output,
            weight: to_vec(self.weight.val().slice(slice..slice + 1)),
            bias: to_vec(self.bias.val().slice(slice..slice + 1)),
        }
    }
}

/// burn's `LayerNorm` (ε = 1e-5) for each of S runs: scale `gamma` and shift `beta` `[S, width]`,
/// named as burn's fields so that a slice's record reads as one.
#[derive(Module, Debug)]
pub struct StackedLayerNorm {
    pub gamma: Param<Tensor<2>>,
    pub beta: Param<Tensor<2>>,
}

impl StackedLayerNorm {
    /// burn's `LayerNormConfig` default.
    const EPSILON: f64 = 1e-5;

    /// burn's layer as a one-run stack.
    pub fn from_burn(layer: &LayerNorm) -> StackedLayerNorm {
        let gamma = layer.gamma.val();
        let beta = match &layer.beta {
            Some(beta) => beta.val(),
            None => gamma.zeros_like(),
        };
        StackedLayerNorm {
            gamma: Param::from_tensor(gamma.unsqueeze_dim::<2>(0).detach()),
            beta: Param::from_tensor(beta.unsqueeze_dim::<2>(0).detach()),
        }
    }

    /// Normalises each run's `[…, width]` slice of `x` `[S, …, width]` over its last axis with
    /// the run's scale and shift ([`cpu_ops::layer_norm`](super::cpu_ops::layer_norm)).
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        super::cpu_ops::layer_norm(x, self.gamma.val(), self.beta.val(), Self::EPSILON)
    }

    /// Slice `slice`'s scale and shift as plain numbers (for export).
    pub fn norm(&self, slice: usize) -> Norm {
        Norm {
            scale: to_vec(self.gamma.val().narrow(0, slice, 1)),
            shift: to_vec(self.beta.val().narrow(0, slice, 1)),
        }
    }
}

/// The modules of several stacks (each of any size, usually solo ones) as one stack, in order:
/// every parameter is the concatenation of theirs along the leading axis. The parameter ids
/// are the first part's; the parts must share one structure.
pub fn stack<M: Module>(parts: Vec<M>) -> M {
    struct Collect(Vec<(Vec<usize>, Tensor<1>)>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let value = param.val();
            self.0.push((value.dims().to_vec(), value.reshape([-1])));
        }
    }
    struct Concatenate {
        /// Per part, its parameters in visiting order.
        parts: Vec<std::vec::IntoIter<(Vec<usize>, Tensor<1>)>>,
    }
    impl ModuleMapper for Concatenate {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let slices: Vec<Tensor<D>> = self
                .parts
                .iter_mut()
                .map(|part| {
                    let (dims, flat) = part.next().expect("stacked parts share one structure");
                    flat.reshape::<D, _>(<[usize; D]>::try_from(dims).expect("same rank"))
                })
                .collect();
            param.map(|first| {
                let require_grad = first.is_require_grad();
                Tensor::cat(slices, 0)
                    .detach()
                    .set_require_grad(require_grad)
            })
        }
    }
    let mut parts = parts.into_iter();
    let first = parts.next().expect("a stack of at least one module");
    let collected: Vec<_> = std::iter::once(&first)
        .chain(parts.as_slice())
        .map(|part| {
            let mut collect = Collect(Vec::new());
            part.visit(&mut collect);
            collect.0.into_iter()
        })
        .collect();
    first.map(&mut Concatenate { parts: collected })
}

/// Run `run` of a stacked module as a one-run stack; its parameters are views of the stack's.
pub fn slice<M: Module>(module: &M, run: usize) -> M {
    struct Cut(usize);
    impl ModuleMapper for Cut {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let run = self.0;
            param.map(|value| value.slice(run..run + 1))
        }
    }
    module.clone().map(&mut Cut(run))
}

/// `module` for the runs `runs` of its stack of `stack`: the whole of it, or the one run
/// `runs.start` ([`slice`]).
pub fn select_runs<M: Module>(module: M, runs: std::ops::Range<usize>, stack: usize) -> M {
    match runs.len() == stack {
        true => module,
        false => {
            debug_assert_eq!(runs.len(), 1, "the whole stack or one run");
            slice(&module, runs.start)
        }
    }
}

/// Something wrong in a stacked record.
fn record_error(message: impl std::fmt::Display) -> String {
    message.to_string()
}

/// The record (a burnpack of a module or an optimiser) of slice `slice` of a stacked one, in
/// the solo shapes: every tensor `[S, rest…]` becomes slice `slice`'s `[rest…]`; names,
/// parameter ids, scalars (Adam's step counts, shared by the stack) and metadata unchanged.
pub fn slice_pack(bytes: Bytes, slice: usize) -> Result<Bytes, String> {
    let reader = Reader::from_bytes(bytes).map_err(record_error)?;
    let scalars = with_ranks_moved(reader.scalars(), -1)?;
    let metadata = reader.metadata().clone();
    let tensors = reader
        .into_tensors()
        .map_err(record_error)?
        .into_iter()
        .map(|tensor| {
            let (name, dtype, shape, id, data) = tensor.into_parts().map_err(record_error)?;
            let dims = shape.to_vec();
            let stacked = *dims
                .first()
                .ok_or_else(|| format!("{name} has no stack axis"))?;
            if slice >= stacked {
                return Err(format!("{name}: slice {slice} of a stack of {stacked}"));
            }
            let len = data.len() / stacked;
            let part = Bytes::from_bytes_vec(data[slice * len..(slice + 1) * len].to_vec());
            Ok(burn_pack::Tensor::new(
                name,
                dtype,
                dims[1..].to_vec(),
                id,
                part,
            ))
        })
        .collect::<Result<Vec<_>, String>>()?;
    pack(tensors, &scalars, &metadata)
}

/// The stacked record of the solo records `slices` (as [`slice_pack`] writes them): each
/// tensor `[rest…]` becomes `[S, rest…]`, slice `i` from `slices[i]`. Names, ids, scalars and
/// metadata are the first's; every slice must hold the same tensors in the same shapes.
pub fn stack_packs(slices: Vec<Bytes>) -> Result<Bytes, String> {
    let count = slices.len();
    if count == 0 {
        return Err("a stack of no records".into());
    }
    let mut readers = slices
        .into_iter()
        .map(|bytes| Reader::from_bytes(bytes).map_err(record_error))
        .collect::<Result<Vec<_>, String>>()?;
    let first = readers.remove(0);
    let scalars = with_ranks_moved(first.scalars(), 1)?;
    let metadata = first.metadata().clone();
    let mut tensors = first.into_tensors().map_err(record_error)?;
    let others = readers
        .into_iter()
        .map(|reader| reader.into_tensors().map_err(record_error))
        .collect::<Result<Vec<_>, String>>()?;
    let mut stacked = Vec::with_capacity(tensors.len());
    for (k, tensor) in tensors.drain(..).enumerate() {
        let (name, dtype, shape, id, data) = tensor.into_parts().map_err(record_error)?;
        let mut all = data.to_vec();
        for (i, other) in others.iter().enumerate() {
            let other = other
                .get(k)
                .filter(|t| t.name == name && t.shape == shape)
                .ok_or_else(|| {
                    format!("slice {} does not hold {name} of shape {shape:?}", i + 1)
                })?;
            all.extend_from_slice(&other.to_bytes().map_err(record_error)?);
        }
        let dims: Vec<usize> = std::iter::once(count)
            .chain(shape.iter().copied())
            .collect();
        stacked.push(burn_pack::Tensor::new(
            name,
            dtype,
            dims,
            id,
            Bytes::from_bytes_vec(all),
        ));
    }
    if let Some((i, extra)) = others
        .iter()
        .enumerate()
        .find(|(_, o)| o.len() != stacked.len())
    {
        return Err(format!(
            "slice {} holds {} tensors, the first {}",
            i + 1,
            extra.len(),
            stacked.len()
        ));
    }
    pack(stacked, &scalars, &metadata)
}

/// burn's optimiser records keep each parameter's rank as a scalar `"{id}.__rank"`, which
/// decides the rank its state is rebuilt with: it follows the stack axis, `by` ±1.
fn with_ranks_moved(
    scalars: &std::collections::BTreeMap<String, burn_pack::Scalar>,
    by: isize,
) -> Result<std::collections::BTreeMap<String, burn_pack::Scalar>, String> {
    scalars
        .iter()
        .map(|(key, value)| {
            if !key.ends_with(".__rank") {
                return Ok((key.clone(), *value));
            }
            let rank = usize::try_from(*value)
                .ok()
                .and_then(|rank| rank.checked_add_signed(by))
                .ok_or_else(|| format!("{key}: a rank that cannot move by {by}"))?;
            Ok((key.clone(), burn_pack::Scalar::from(rank)))
        })
        .collect()
}

fn pack(
    tensors: Vec<burn_pack::Tensor>,
    scalars: &std::collections::BTreeMap<String, burn_pack::Scalar>,
    metadata: &std::collections::BTreeMap<String, String>,
) -> Result<Bytes, String> {
    let mut writer = Writer::new(tensors);
    for (key, value) in scalars {
        writer = writer.with_scalar(key, *value);
    }
    for (key, value) in metadata {
        writer = writer.with_metadata(key, value);
    }
    writer.into_bytes().map_err(record_error)
}
