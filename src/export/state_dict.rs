//! The acting network in PyTorch's `state_dict` naming and layout (`nn.Linear.weight` is
//! `[out, in]`, `nn.LayerNorm`'s `weight`/`bias`, `nn.Embedding.weight`), written as
//! safetensors. The module these names belong to is described in docs/deploy.md and built by
//! python/tests/test_export.py.
use std::collections::HashMap;

use safetensors::tensor::{Dtype, TensorView};

use crate::acting::{ActingNetwork, Dense, GaussianPolicyWeights, Norm};

/// One named tensor: its shape and values, row-major.
pub struct Parameter {
    pub name: String,
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

impl Parameter {
    pub fn new(name: impl Into<String>, shape: Vec<usize>, values: &[f32]) -> Parameter {
        Parameter {
            name: name.into(),
            shape,
            values: values.to_vec(),
        }
    }
}

/// Every tensor of `network`, in a fixed order.
pub fn state_dict(network: &ActingNetwork) -> Vec<Parameter> {
    let mut out = Vec::new();
    match network {
        ActingNetwork::Policy { .. } => {}
        ActingNetwork::ModelRollout { model, .. } => {
            for (i, layer) in model.layers.iter().enumerate() {
                linear(&mut out, &format!("model.layers.{i}"), layer);
            }
            if let Some((mean, std)) = &model.input_moments {
                vector(&mut out, "model.input_mean", mean);
                vector(&mut out, "model.input_std", std);
            }
        }
        ActingNetwork::Belief { belief, .. } => {
            linear(&mut out, "belief.state_embedding", &belief.state_embedding);
            linear(
                &mut out,
                "belief.action_embedding",
                &belief.action_embedding,
            );
            linear(&mut out, "belief.token", &belief.token);
            let width = belief.width();
            out.push(Parameter::new(
                "belief.position.weight",
                vec![belief.position.len() / width, width],
                &belief.position,
            ));
            layer_norm(&mut out, "belief.input_norm", &belief.input_norm);
            for (j, block) in belief.blocks.iter().enumerate() {
                let b = format!("belief.blocks.{j}");
                layer_norm(
                    &mut out,
                    &format!("{b}.attention_norm"),
                    &block.attention_norm,
                );
                linear(&mut out, &format!("{b}.query"), &block.query);
                linear(&mut out, &format!("{b}.key"), &block.key);
                linear(&mut out, &format!("{b}.value"), &block.value);
                linear(
                    &mut out,
                    &format!("{b}.attention_output"),
                    &block.attention_output,
                );
                layer_norm(
                    &mut out,
                    &format!("{b}.feed_forward_norm"),
                    &block.feed_forward_norm,
                );
                linear(
                    &mut out,
                    &format!("{b}.feed_forward_inner"),
                    &block.feed_forward_inner,
                );
                linear(
                    &mut out,
                    &format!("{b}.feed_forward_outer"),
                    &block.feed_forward_outer,
                );
            }
            layer_norm(&mut out, "belief.output_norm", &belief.output_norm);
        }
    }
    policy(&mut out, network.policy());
    out
}

fn policy(out: &mut Vec<Parameter>, policy: &GaussianPolicyWeights) {
    for (i, layer) in policy.hidden.iter().enumerate() {
        linear(out, &format!("policy.hidden.{i}"), layer);
    }
    linear(out, "policy.mean", &policy.mean);
    linear(out, "policy.log_std", &policy.log_std);
}

fn linear(out: &mut Vec<Parameter>, name: &str, layer: &Dense) {
    out.push(Parameter::new(
        format!("{name}.weight"),
        vec![layer.output, layer.input],
        &layer.weight_output_major(),
    ));
    vector(out, &format!("{name}.bias"), &layer.bias);
}

fn layer_norm(out: &mut Vec<Parameter>, name: &str, norm: &Norm) {
    vector(out, &format!("{name}.weight"), &norm.scale);
    vector(out, &format!("{name}.bias"), &norm.shift);
}

fn vector(out: &mut Vec<Parameter>, name: &str, values: &[f32]) {
    out.push(Parameter::new(name, vec![values.len()], values));
}

/// `tensors` as a safetensors file's bytes, with `metadata` in its header.
pub fn safetensors_bytes(
    tensors: &[Parameter],
    metadata: HashMap<String, String>,
) -> Result<Vec<u8>, safetensors::SafeTensorError> {
    let bytes: Vec<Vec<u8>> = tensors
        .iter()
        .map(|t| t.values.iter().flat_map(|v| v.to_le_bytes()).collect())
        .collect();
    let views = tensors
        .iter()
        .zip(&bytes)
        .map(|(t, data)| {
            Ok((
                t.name.clone(),
                TensorView::new(Dtype::F32, t.shape.clone(), data)?,
            ))
        })
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()?;
    safetensors::tensor::serialize(views, Some(metadata))
}
