//! `dhrl export`: a trained run's acting policy as files that leave dhrl — `policy.onnx`
//! (the whole computation from `x_t` to the action), `policy.safetensors` (its weights in
//! PyTorch's naming), `policy.json` (the manifest a runtime needs) and `check.safetensors` (a
//! recorded episode to check a runtime against). docs/deploy.md describes each.
mod check;
mod onnx;
mod state_dict;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

pub use check::{CheckRecord, record_check};
pub use onnx::{GraphSpec, INPUT, OPSET, OUTPUTS, onnx_model};
pub use state_dict::{Parameter, safetensors_bytes, state_dict};

use crate::acting::ActingNetwork;
use crate::deploy::{
    AugmentedStateLayout, DelayManifest, FORMAT, FORMAT_VERSION, FilesManifest, NetworkManifest,
    ParameterManifest, PolicyManifest, RunManifest, WarmupManifest,
};
use crate::learn::{LOG_STD_MAX, LOG_STD_MIN};
use crate::train::{SavedRun, TrainError, learner_pool, load_saved};

/// The files `dhrl export` writes.
pub const ONNX_FILE: &str = "policy.onnx";
pub const SAFETENSORS_FILE: &str = "policy.safetensors";
pub const MANIFEST_FILE: &str = "policy.json";
pub const CHECK_FILE: &str = "check.safetensors";

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("cannot write {path}: {message}")]
    Io { path: String, message: String },
    #[error("the safetensors writer: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    #[error("{0}")]
    Check(String),
}

/// What an export wrote.
#[derive(Debug)]
pub struct ExportSummary {
    pub manifest: PolicyManifest,
    pub files: Vec<PathBuf>,
    /// Decisions in the recorded check, and how many of them the policy took (after warm-up).
    pub check_steps: usize,
    pub check_policy_steps: usize,
}

/// Exports the policy of `run`'s latest checkpoint into `out` (created if missing; files in
/// it are replaced whole).
pub fn export_run(run: &Path, out: &Path) -> Result<ExportSummary, ExportError> {
    let SavedRun {
        config,
        trained_delay,
        env_steps,
        mut agent,
    } = load_saved(run, None)?;
    let info = config.algo.info();
    let network = agent.acting_network();
    let model = crate::sim::TaskModel::load(config.task).map_err(TrainError::from)?;
    let (obs, act) = (model.task.obs_dim, model.task.act_dim);
    let parameters = state_dict(&network);
    let manifest = PolicyManifest {
        format: FORMAT.into(),
        format_version: FORMAT_VERSION,
        algorithm: info.name.into(),
        paper_name: info.paper_name.into(),
        task: config.task.as_str().into(),
        gymnasium_id: config.task.gymnasium_id().into(),
        observation_dim: obs,
        action_dim: act,
        action_low: model.action_low.clone(),
        action_high: model.action_high.clone(),
        delay: DelayManifest {
            observation_delay: config.delay.observation_delay,
            action_delay: config.delay.action_delay,
            random: config.delay.random_delay,
            max_random_delay: config.delay.random_bound(),
            total: trained_delay,
            actuator_noise: config.delay.actuator_noise,
        },
        augmented_state: AugmentedStateLayout::new(obs, act, trained_delay),
        warmup: WarmupManifest {
            rule: config.delay.warmup,
            steps: trained_delay,
        },
        observation_normalisation: None,
        network: NetworkManifest {
            kind: network.kind().into(),
            log_std_bounds: [LOG_STD_MIN, LOG_STD_MAX],
            attention_heads: match &network {
                ActingNetwork::Belief { belief, .. } => Some(belief.heads),
                _ => None,
            },
            model_predicts_difference: match &network {
                ActingNetwork::ModelRollout { model, .. } => Some(model.predicts_difference),
                _ => None,
            },
            parameters: parameters
                .iter()
                .map(|p| ParameterManifest {
                    name: p.name.clone(),
                    shape: p.shape.clone(),
                })
                .collect(),
        },
        files: FilesManifest {
            onnx: ONNX_FILE.into(),
            onnx_opset: OPSET,
            onnx_input: INPUT.into(),
            onnx_outputs: OUTPUTS.iter().map(|s| s.to_string()).collect(),
            safetensors: SAFETENSORS_FILE.into(),
            check: CHECK_FILE.into(),
        },
        run: RunManifest {
            path: run.display().to_string(),
            seed: config.seed,
            steps: env_steps,
            dhrl_version: env!("CARGO_PKG_VERSION").into(),
        },
    };
    let metadata = vec![
        ("dhrl.algorithm".to_string(), manifest.algorithm.clone()),
        ("dhrl.task".to_string(), manifest.task.clone()),
        ("dhrl.delay".to_string(), trained_delay.to_string()),
        ("dhrl.manifest".to_string(), MANIFEST_FILE.to_string()),
    ];
    let onnx = onnx_model(
        &network,
        &GraphSpec {
            obs_dim: obs,
            act_dim: act,
            delay: trained_delay,
            action_low: &model.action_low,
            action_high: &model.action_high,
            log_std_bounds: (LOG_STD_MIN, LOG_STD_MAX),
            metadata: metadata.clone(),
        },
    );
    let mut header: HashMap<String, String> = metadata.into_iter().collect();
    header.insert("format".into(), "pt".into());
    let weights = safetensors_bytes(&parameters, header)?;
    let check = learner_pool(info.learner_threads)?
        .install(|| record_check(agent.as_mut(), &config, &manifest))?;
    let check_bytes = check.to_safetensors()?;

    std::fs::create_dir_all(out).map_err(io(out))?;
    let manifest_text =
        serde_json::to_string_pretty(&manifest).expect("the manifest serialises") + "\n";
    let mut files = Vec::new();
    for (name, bytes) in [
        (ONNX_FILE, onnx),
        (SAFETENSORS_FILE, weights),
        (CHECK_FILE, check_bytes),
        (MANIFEST_FILE, manifest_text.into_bytes()),
    ] {
        let path = out.join(name);
        crate::files::write_atomically(&path, bytes).map_err(io(&path))?;
        files.push(path);
    }
    Ok(ExportSummary {
        check_steps: check.steps(),
        check_policy_steps: check.policy_steps(),
        manifest,
        files,
    })
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> ExportError + '_ {
    move |e| ExportError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}
