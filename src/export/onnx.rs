//! The acting network as an ONNX graph (opset [`OPSET`]), written with the `onnx-protobuf`
//! messages: input `augmented_state` `[batch, obs + Δ·act]` (the layout of `x_t`), outputs
//! `action` (the deterministic action `scale·tanh(mean) + bias`, within the bounds), `mean`
//! (before the squashing) and `log_std` (clamped), each `[batch, act]`.
use onnx_protobuf::tensor_proto::DataType;
use onnx_protobuf::{
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto,
    StringStringEntryProto, TensorProto, TensorShapeProto, TypeProto, ValueInfoProto,
    attribute_proto::AttributeType,
};
use protobuf::{EnumOrUnknown, MessageField};

use crate::acting::{
    ActingNetwork, BeliefTransformer, Dense, GaussianPolicyWeights, Norm, PolicyInput, RolloutModel,
};

/// The default ONNX operator set of the file (LayerNormalization needs 17).
pub const OPSET: i64 = 17;
/// The IR version that goes with opset 17.
const IR_VERSION: i64 = 8;
/// LayerNorm's ε, as burn's `LayerNormConfig` (and PyTorch) default.
const NORM_EPSILON: f32 = 1e-5;

/// The graph's input and outputs, by name.
pub const INPUT: &str = "augmented_state";
pub const OUTPUTS: [&str; 3] = ["action", "mean", "log_std"];

/// Sizes and constants the graph needs besides the weights.
pub struct GraphSpec<'a> {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub delay: usize,
    pub action_low: &'a [f64],
    pub action_high: &'a [f64],
    pub log_std_bounds: (f64, f64),
    /// `key = value` pairs stored in the model's metadata (task, algorithm, Δ, …).
    pub metadata: Vec<(String, String)>,
}

/// The serialised ONNX model of `network`.
pub fn onnx_model(network: &ActingNetwork, spec: &GraphSpec<'_>) -> Vec<u8> {
    let mut graph = Graph::default();
    let augmented = INPUT.to_string();
    let obs = spec.obs_dim;
    let policy_input = match network {
        ActingNetwork::Policy {
            input: PolicyInput::AugmentedState,
            ..
        } => augmented.clone(),
        ActingNetwork::Policy {
            input: PolicyInput::LastObservation,
            ..
        } => graph.columns(&augmented, 0, obs, "last_observation"),
        ActingNetwork::ModelRollout { model, .. } => {
            graph.model_rollout(&augmented, model, spec, "model")
        }
        ActingNetwork::Belief { belief, .. } => graph.belief(&augmented, belief, spec, "belief"),
    };
    graph.gaussian_policy(&policy_input, network.policy(), spec, "policy");

    let mut model = ModelProto::new();
    model.ir_version = IR_VERSION;
    model.producer_name = "dhrl".into();
    model.producer_version = env!("CARGO_PKG_VERSION").into();
    model.doc_string = format!(
        "dhrl acting network ({}): x_t = (s_(t-Δ), a_(t-Δ), ..., a_(t-1)) in, the deterministic action out",
        network.kind()
    );
    let mut opset = OperatorSetIdProto::new();
    opset.version = OPSET;
    model.opset_import.push(opset);
    for (key, value) in &spec.metadata {
        let mut entry = StringStringEntryProto::new();
        entry.key = key.clone();
        entry.value = value.clone();
        model.metadata_props.push(entry);
    }
    let width = obs + spec.delay * spec.act_dim;
    let mut proto = graph.proto;
    proto.name = "dhrl_policy".into();
    proto.input.push(value_info(INPUT, width));
    for output in OUTPUTS {
        proto.output.push(value_info(output, spec.act_dim));
    }
    model.graph = MessageField::some(proto);
    model
        .write_to_bytes()
        .expect("an in-memory ONNX model serialises")
}

/// A float tensor `[batch, width]` with a symbolic batch size.
fn value_info(name: &str, width: usize) -> ValueInfoProto {
    let mut shape = TensorShapeProto::new();
    let mut batch = onnx_protobuf::tensor_shape_proto::Dimension::new();
    batch.set_dim_param("batch".into());
    let mut columns = onnx_protobuf::tensor_shape_proto::Dimension::new();
    columns.set_dim_value(width as i64);
    shape.dim = vec![batch, columns];
    let mut tensor = onnx_protobuf::type_proto::Tensor::new();
    tensor.elem_type = DataType::FLOAT as i32;
    tensor.shape = MessageField::some(shape);
    let mut kind = TypeProto::new();
    kind.set_tensor_type(tensor);
    let mut info = ValueInfoProto::new();
    info.name = name.into();
    info.type_ = MessageField::some(kind);
    info
}

/// Nodes and initialisers, with the names of the values between them.
#[derive(Default)]
struct Graph {
    proto: GraphProto,
}

enum Attribute {
    Int(i64),
    Ints(Vec<i64>),
    Float(f32),
}

impl Graph {
    /// Adds a node with one output named `output`, returns the name.
    fn node(
        &mut self,
        op: &str,
        inputs: &[&str],
        output: &str,
        attributes: &[(&str, Attribute)],
    ) -> String {
        let mut node = NodeProto::new();
        node.op_type = op.into();
        node.name = output.into();
        node.input = inputs.iter().map(|name| name.to_string()).collect();
        node.output = vec![output.to_string()];
        for (name, value) in attributes {
            let mut attribute = AttributeProto::new();
            attribute.name = (*name).into();
            match value {
                Attribute::Int(i) => {
                    attribute.type_ = EnumOrUnknown::new(AttributeType::INT);
                    attribute.i = *i;
                }
                Attribute::Ints(ints) => {
                    attribute.type_ = EnumOrUnknown::new(AttributeType::INTS);
                    attribute.ints = ints.clone();
                }
                Attribute::Float(f) => {
                    attribute.type_ = EnumOrUnknown::new(AttributeType::FLOAT);
                    attribute.f = *f;
                }
            }
            node.attribute.push(attribute);
        }
        self.proto.node.push(node);
        output.to_string()
    }

    /// A float constant of shape `dims`.
    fn floats(&mut self, name: &str, dims: &[usize], values: &[f32]) -> String {
        assert_eq!(dims.iter().product::<usize>(), values.len(), "{name}");
        let mut tensor = TensorProto::new();
        tensor.name = name.into();
        tensor.data_type = DataType::FLOAT as i32;
        tensor.dims = dims.iter().map(|&d| d as i64).collect();
        tensor.float_data = values.to_vec();
        self.proto.initializer.push(tensor);
        name.to_string()
    }

    /// An int64 constant of shape `[values.len()]` (or a scalar with `scalar`).
    fn ints(&mut self, name: &str, values: &[i64], scalar: bool) -> String {
        let mut tensor = TensorProto::new();
        tensor.name = name.into();
        tensor.data_type = DataType::INT64 as i32;
        if !scalar {
            tensor.dims = vec![values.len() as i64];
        }
        tensor.int64_data = values.to_vec();
        self.proto.initializer.push(tensor);
        name.to_string()
    }

    /// A bool constant of shape `dims`.
    fn bools(&mut self, name: &str, dims: &[usize], values: &[bool]) -> String {
        let mut tensor = TensorProto::new();
        tensor.name = name.into();
        tensor.data_type = DataType::BOOL as i32;
        tensor.dims = dims.iter().map(|&d| d as i64).collect();
        tensor.int32_data = values.iter().map(|&b| i32::from(b)).collect();
        self.proto.initializer.push(tensor);
        name.to_string()
    }

    /// Columns `start..end` of a `[batch, width]` value.
    fn columns(&mut self, x: &str, start: usize, end: usize, name: &str) -> String {
        let starts = self.ints(&format!("{name}.starts"), &[start as i64], false);
        let ends = self.ints(&format!("{name}.ends"), &[end as i64], false);
        let axes = self.ints(&format!("{name}.axes"), &[1], false);
        self.node("Slice", &[x, &starts, &ends, &axes], name, &[])
    }

    /// `x·W + b` over the last axis.
    fn dense(&mut self, x: &str, layer: &Dense, name: &str) -> String {
        let weight = self.floats(
            &format!("{name}.weight_t"),
            &[layer.input, layer.output],
            &layer.weight,
        );
        let bias = self.floats(&format!("{name}.bias"), &[layer.output], &layer.bias);
        let product = self.node("MatMul", &[x, &weight], &format!("{name}.matmul"), &[]);
        self.node("Add", &[&product, &bias], name, &[])
    }

    /// The policy's three outputs from its input.
    fn gaussian_policy(
        &mut self,
        x: &str,
        policy: &GaussianPolicyWeights,
        spec: &GraphSpec<'_>,
        name: &str,
    ) {
        let mut hidden = x.to_string();
        for (i, layer) in policy.hidden.iter().enumerate() {
            let pre = self.dense(&hidden, layer, &format!("{name}.hidden.{i}"));
            hidden = self.node("Relu", &[&pre], &format!("{name}.hidden.{i}.relu"), &[]);
        }
        let mean_pre = self.dense(&hidden, &policy.mean, &format!("{name}.mean"));
        self.node("Identity", &[&mean_pre], OUTPUTS[1], &[]);
        let log_std = self.dense(&hidden, &policy.log_std, &format!("{name}.log_std"));
        let (low, high) = spec.log_std_bounds;
        let low = self.floats(&format!("{name}.log_std_min"), &[], &[low as f32]);
        let high = self.floats(&format!("{name}.log_std_max"), &[], &[high as f32]);
        self.node("Clip", &[&log_std, &low, &high], OUTPUTS[2], &[]);
        let squashed = self.node("Tanh", &[&mean_pre], &format!("{name}.tanh"), &[]);
        let (scale, bias): (Vec<f32>, Vec<f32>) = spec
            .action_low
            .iter()
            .zip(spec.action_high)
            .map(|(l, h)| (((h - l) / 2.0) as f32, ((h + l) / 2.0) as f32))
            .unzip();
        let scale = self.floats(&format!("{name}.action_scale"), &[spec.act_dim], &scale);
        let bias = self.floats(&format!("{name}.action_bias"), &[spec.act_dim], &bias);
        let scaled = self.node("Mul", &[&squashed, &scale], &format!("{name}.scaled"), &[]);
        self.node("Add", &[&scaled, &bias], OUTPUTS[0], &[]);
    }

    /// Delayed SAC's estimate of `s_t`: the model rolled over the pending actions from
    /// `s_{t−Δ}`, oldest first.
    fn model_rollout(
        &mut self,
        x: &str,
        model: &RolloutModel,
        spec: &GraphSpec<'_>,
        name: &str,
    ) -> String {
        let (obs, act) = (spec.obs_dim, spec.act_dim);
        if spec.delay == 0 {
            return x.to_string();
        }
        let mut state = self.columns(x, 0, obs, &format!("{name}.state.0"));
        let moments = model.input_moments.as_ref().map(|(mean, std)| {
            (
                self.floats(&format!("{name}.input_mean"), &[mean.len()], mean),
                self.floats(&format!("{name}.input_std"), &[std.len()], std),
            )
        });
        for k in 0..spec.delay {
            let action = self.columns(
                x,
                obs + k * act,
                obs + (k + 1) * act,
                &format!("{name}.action.{k}"),
            );
            let mut input = self.node(
                "Concat",
                &[&state, &action],
                &format!("{name}.input.{k}"),
                &[("axis", Attribute::Int(1))],
            );
            if let Some((mean, std)) = &moments {
                let centred =
                    self.node("Sub", &[&input, mean], &format!("{name}.centred.{k}"), &[]);
                input = self.node(
                    "Div",
                    &[&centred, std],
                    &format!("{name}.standardised.{k}"),
                    &[],
                );
            }
            let out = self.mlp_shared(&input, &model.layers, &format!("{name}.layers"), k);
            state = if model.predicts_difference {
                self.node(
                    "Add",
                    &[&state, &out],
                    &format!("{name}.state.{}", k + 1),
                    &[],
                )
            } else {
                out
            };
        }
        state
    }

    /// An MLP whose weights are stored once (under `name`) and applied again at `step`.
    fn mlp_shared(&mut self, x: &str, layers: &[Dense], name: &str, step: usize) -> String {
        let mut value = x.to_string();
        for (i, layer) in layers.iter().enumerate() {
            let (weight, bias) = (format!("{name}.{i}.weight_t"), format!("{name}.{i}.bias"));
            if step == 0 {
                self.floats(&weight, &[layer.input, layer.output], &layer.weight);
                self.floats(&bias, &[layer.output], &layer.bias);
            }
            let product = self.node(
                "MatMul",
                &[&value, &weight],
                &format!("{name}.{i}.matmul.{step}"),
                &[],
            );
            value = self.node(
                "Add",
                &[&product, &bias],
                &format!("{name}.{i}.out.{step}"),
                &[],
            );
            if i + 1 < layers.len() {
                value = self.node("Relu", &[&value], &format!("{name}.{i}.relu.{step}"), &[]);
            }
        }
        value
    }

    fn layer_norm(&mut self, x: &str, norm: &Norm, name: &str) -> String {
        let scale = self.floats(&format!("{name}.weight"), &[norm.scale.len()], &norm.scale);
        let shift = self.floats(&format!("{name}.bias"), &[norm.shift.len()], &norm.shift);
        self.node(
            "LayerNormalization",
            &[x, &scale, &shift],
            name,
            &[
                ("axis", Attribute::Int(-1)),
                ("epsilon", Attribute::Float(NORM_EPSILON)),
            ],
        )
    }

    /// VDPO's belief: the last token's features `[batch, width]`.
    fn belief(
        &mut self,
        x: &str,
        belief: &BeliefTransformer,
        spec: &GraphSpec<'_>,
        name: &str,
    ) -> String {
        let (obs, act, delay) = (spec.obs_dim, spec.act_dim, spec.delay);
        let width = belief.width();
        let state = self.columns(x, 0, obs, &format!("{name}.state"));
        let flat_actions = self.columns(x, obs, obs + delay * act, &format!("{name}.actions.flat"));
        let action_shape = self.ints(
            &format!("{name}.actions.shape"),
            &[-1, delay as i64, act as i64],
            false,
        );
        let actions = self.node(
            "Reshape",
            &[&flat_actions, &action_shape],
            &format!("{name}.actions"),
            &[],
        );
        // token([embed(s); embed(a_i)]) = embed(s)·W_top + embed(a_i)·W_bottom + b.
        let state_embedded = self.dense(
            &state,
            &belief.state_embedding,
            &format!("{name}.state_embedding"),
        );
        let actions_embedded = self.dense(
            &actions,
            &belief.action_embedding,
            &format!("{name}.action_embedding"),
        );
        let token = &belief.token;
        let top = self.floats(
            &format!("{name}.token.weight_t.state"),
            &[width, width],
            &token.weight[..width * width],
        );
        let bottom = self.floats(
            &format!("{name}.token.weight_t.action"),
            &[width, width],
            &token.weight[width * width..],
        );
        let from_state = self.node(
            "MatMul",
            &[&state_embedded, &top],
            &format!("{name}.token.from_state"),
            &[],
        );
        let axis = self.ints(&format!("{name}.token.axis"), &[1], false);
        let from_state = self.node(
            "Unsqueeze",
            &[&from_state, &axis],
            &format!("{name}.token.from_state.per_position"),
            &[],
        );
        let from_actions = self.node(
            "MatMul",
            &[&actions_embedded, &bottom],
            &format!("{name}.token.from_actions"),
            &[],
        );
        let position = self.floats(
            &format!("{name}.position.weight"),
            &[delay, width],
            &belief.position,
        );
        let token_bias = self.floats(&format!("{name}.token.bias"), &[width], &token.bias);
        let sum = self.node(
            "Add",
            &[&from_actions, &from_state],
            &format!("{name}.token.sum"),
            &[],
        );
        let sum = self.node(
            "Add",
            &[&sum, &position],
            &format!("{name}.token.positioned"),
            &[],
        );
        let tokens = self.node("Add", &[&sum, &token_bias], &format!("{name}.tokens"), &[]);
        let mut z = self.layer_norm(&tokens, &belief.input_norm, &format!("{name}.input_norm"));

        let heads = belief.heads;
        let head_width = width / heads;
        let split_shape = self.ints(
            &format!("{name}.split_shape"),
            &[-1, delay as i64, heads as i64, head_width as i64],
            false,
        );
        let merge_shape = self.ints(
            &format!("{name}.merge_shape"),
            &[-1, delay as i64, width as i64],
            false,
        );
        // True above the diagonal: token i attends to 0..=i only.
        let later: Vec<bool> = (0..delay * delay)
            .map(|ij| ij % delay > ij / delay)
            .collect();
        let causal = self.bools(&format!("{name}.causal"), &[delay, delay], &later);
        let fill = self.floats(&format!("{name}.mask_fill"), &[], &[belief.mask_fill]);
        let temperature = self.floats(
            &format!("{name}.score_scale"),
            &[],
            &[(head_width as f32).sqrt()],
        );
        let root_two = self.floats(&format!("{name}.sqrt2"), &[], &[std::f32::consts::SQRT_2]);
        let one = self.floats(&format!("{name}.one"), &[], &[1.0]);
        let half = self.floats(&format!("{name}.half"), &[], &[0.5]);
        for (j, block) in belief.blocks.iter().enumerate() {
            let b = format!("{name}.blocks.{j}");
            let normed = self.layer_norm(&z, &block.attention_norm, &format!("{b}.attention_norm"));
            let split = |graph: &mut Graph, layer: &Dense, what: &str| {
                let projected = graph.dense(&normed, layer, &format!("{b}.{what}"));
                let heads = graph.node(
                    "Reshape",
                    &[&projected, &split_shape],
                    &format!("{b}.{what}.heads"),
                    &[],
                );
                graph.node(
                    "Transpose",
                    &[&heads],
                    &format!("{b}.{what}.by_head"),
                    &[("perm", Attribute::Ints(vec![0, 2, 1, 3]))],
                )
            };
            let query = split(self, &block.query, "query");
            let key = split(self, &block.key, "key");
            let value = split(self, &block.value, "value");
            let key_t = self.node(
                "Transpose",
                &[&key],
                &format!("{b}.key.transposed"),
                &[("perm", Attribute::Ints(vec![0, 1, 3, 2]))],
            );
            let scores = self.node("MatMul", &[&query, &key_t], &format!("{b}.scores.raw"), &[]);
            let scores = self.node(
                "Div",
                &[&scores, &temperature],
                &format!("{b}.scores.scaled"),
                &[],
            );
            let scores = self.node(
                "Where",
                &[&causal, &fill, &scores],
                &format!("{b}.scores"),
                &[],
            );
            let weights = self.node(
                "Softmax",
                &[&scores],
                &format!("{b}.weights"),
                &[("axis", Attribute::Int(-1))],
            );
            let context = self.node(
                "MatMul",
                &[&weights, &value],
                &format!("{b}.context.by_head"),
                &[],
            );
            let context = self.node(
                "Transpose",
                &[&context],
                &format!("{b}.context.by_token"),
                &[("perm", Attribute::Ints(vec![0, 2, 1, 3]))],
            );
            let context = self.node(
                "Reshape",
                &[&context, &merge_shape],
                &format!("{b}.context"),
                &[],
            );
            let attended = self.dense(
                &context,
                &block.attention_output,
                &format!("{b}.attention_output"),
            );
            z = self.node(
                "Add",
                &[&z, &attended],
                &format!("{b}.after_attention"),
                &[],
            );
            let normed = self.layer_norm(
                &z,
                &block.feed_forward_norm,
                &format!("{b}.feed_forward_norm"),
            );
            let inner = self.dense(
                &normed,
                &block.feed_forward_inner,
                &format!("{b}.feed_forward_inner"),
            );
            // GELU(x) = x·(1 + erf(x/√2))/2, exactly (opset 17 has no Gelu node).
            let scaled = self.node(
                "Div",
                &[&inner, &root_two],
                &format!("{b}.gelu.scaled"),
                &[],
            );
            let erf = self.node("Erf", &[&scaled], &format!("{b}.gelu.erf"), &[]);
            let shifted = self.node("Add", &[&erf, &one], &format!("{b}.gelu.shifted"), &[]);
            let product = self.node(
                "Mul",
                &[&inner, &shifted],
                &format!("{b}.gelu.product"),
                &[],
            );
            let activated = self.node("Mul", &[&product, &half], &format!("{b}.gelu"), &[]);
            let outer = self.dense(
                &activated,
                &block.feed_forward_outer,
                &format!("{b}.feed_forward_outer"),
            );
            z = self.node("Add", &[&z, &outer], &format!("{b}.out"), &[]);
        }
        let z = self.layer_norm(&z, &belief.output_norm, &format!("{name}.output_norm"));
        let last = self.ints(&format!("{name}.last_position"), &[delay as i64 - 1], true);
        self.node(
            "Gather",
            &[&z, &last],
            &format!("{name}.last"),
            &[("axis", Attribute::Int(1))],
        )
    }
}
