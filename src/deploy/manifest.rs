//! `policy.json`: what a deployed policy needs to know besides its weights — the task's sizes
//! and bounds, the delay it was trained under, the layout of `x_t`, the warm-up rule, the
//! network and the run it came from. The Rust and Python runtimes read it; people read it too.
use serde::{Deserialize, Serialize};

use crate::delay::WarmupActions;

/// The `format` field of every manifest.
pub const FORMAT: &str = "dhrl-policy";
/// The version of the layout below; a runtime refuses other versions.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyManifest {
    pub format: String,
    pub format_version: u32,
    /// `--algo` name and the paper's name of the algorithm.
    pub algorithm: String,
    pub paper_name: String,
    /// dhrl's task name and the Gymnasium environment id it reproduces.
    pub task: String,
    pub gymnasium_id: String,
    pub observation_dim: usize,
    pub action_dim: usize,
    /// The actuators' control range; the policy's actions lie within it.
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
    pub delay: DelayManifest,
    pub augmented_state: AugmentedStateLayout,
    pub warmup: WarmupManifest,
    /// Always `null`: dhrl's policies take raw observations.
    pub observation_normalisation: Option<String>,
    pub network: NetworkManifest,
    pub files: FilesManifest,
    pub run: RunManifest,
}

/// The delay the policy was trained under.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DelayManifest {
    /// Steps between a state and its observation reaching the agent (fixed delays).
    pub observation_delay: usize,
    /// Steps between choosing an action and its execution.
    pub action_delay: usize,
    /// Whether observation delays were random in `1..=max_random_delay` (the conservative agent
    /// uses every observation exactly `max_random_delay` steps old).
    pub random: bool,
    pub max_random_delay: Option<usize>,
    /// Δ: the policy at decision `t` acts on `s_{t−Δ}` and the actions `a_{t−Δ}..a_{t−1}`.
    pub total: usize,
    /// σ of the Gaussian actuator noise of training (0: none).
    pub actuator_noise: f64,
}

/// Where the parts of `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})` lie, as half-open column ranges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AugmentedStateLayout {
    pub width: usize,
    /// `s_{t−Δ}`.
    pub observation_columns: [usize; 2],
    /// `a_{t−Δ}`, …, `a_{t−1}`: oldest first, the actions the policy chose (before any
    /// actuator noise), warm-up actions included.
    pub action_columns: Vec<[usize; 2]>,
}

impl AugmentedStateLayout {
    pub fn new(observation_dim: usize, action_dim: usize, delay: usize) -> AugmentedStateLayout {
        let start = |k: usize| observation_dim + k * action_dim;
        AugmentedStateLayout {
            width: start(delay),
            observation_columns: [0, observation_dim],
            action_columns: (0..delay).map(|k| [start(k), start(k + 1)]).collect(),
        }
    }
}

/// What is executed at decisions `t < Δ`, before the first observation arrives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WarmupManifest {
    /// `zeros` (every component 0) or `random` (uniform within the bounds).
    pub rule: WarmupActions,
    pub steps: usize,
}

/// The acting network and its files' contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkManifest {
    /// What the network computes (see docs/deploy.md).
    pub kind: String,
    /// The policy's log-std clamp `[min, max]`.
    pub log_std_bounds: [f64; 2],
    /// The belief transformer's attention heads (VDPO), `null` for the others.
    pub attention_heads: Option<usize>,
    /// Whether delayed SAC's forward model predicts the change of the state (added to it) or
    /// the next state itself; `null` for the others.
    pub model_predicts_difference: Option<bool>,
    /// Every tensor of `policy.safetensors`, in PyTorch's `state_dict` naming and layout.
    pub parameters: Vec<ParameterManifest>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterManifest {
    pub name: String,
    pub shape: Vec<usize>,
}

/// The files beside the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilesManifest {
    pub onnx: String,
    pub onnx_opset: i64,
    /// The ONNX input's name (`[batch, width]`) and its outputs' (`[batch, action_dim]`).
    pub onnx_input: String,
    pub onnx_outputs: Vec<String>,
    pub safetensors: String,
    /// A recorded episode to check a runtime against (see docs/deploy.md).
    pub check: String,
}

/// Where the policy came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunManifest {
    /// The run folder, as given to `dhrl export`.
    pub path: String,
    pub seed: u64,
    /// Environment steps the policy was trained for.
    pub steps: u64,
    pub dhrl_version: String,
}

#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("cannot read {path}: {message}")]
    Io { path: String, message: String },
    #[error("{path} is not a dhrl policy manifest: {message}")]
    Parse { path: String, message: String },
    #[error(
        "{path} is format {format} version {version}; this dhrl reads {FORMAT} version {FORMAT_VERSION}"
    )]
    Version {
        path: String,
        format: String,
        version: u32,
    },
}

impl PolicyManifest {
    /// Reads and checks `policy.json`.
    pub fn read(path: &std::path::Path) -> Result<PolicyManifest, ManifestError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ManifestError::Io {
            path: shown.clone(),
            message: e.to_string(),
        })?;
        let manifest: PolicyManifest =
            serde_json::from_str(&text).map_err(|e| ManifestError::Parse {
                path: shown.clone(),
                message: e.to_string(),
            })?;
        if manifest.format != FORMAT || manifest.format_version != FORMAT_VERSION {
            return Err(ManifestError::Version {
                path: shown,
                format: manifest.format,
                version: manifest.format_version,
            });
        }
        Ok(manifest)
    }
}
