//! The contract between an algorithm file and the rest of dhrl: the [`Agent`] the training loop
//! drives, the sizes it is built for, and the [`AlgoConfig`] its configuration implements (its
//! [`AlgoInfo`], its documented fields, its constructor).
use std::ops::Range;
use std::path::Path;

use burn::prelude::{Device, Tensor};
use serde::{Serialize, de::DeserializeOwned};

use super::context::UpdateContext;
use super::sac::Config as SacConfig;
use super::stats::Stats;
use crate::acting::ActingNetwork;
use crate::delay::{BatchExtras, ReplayError, Transitions};
use crate::learn::{Devices, LearnError, to_vec, upload_rows};
use crate::protocol::Protocol;
use crate::sim::{SimError, TaskModel};
use crate::tasks::TaskName;

/// Sizes an agent is built for.
#[derive(Debug, Clone)]
pub struct AgentSpec {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Total delay Δ: augmented states have `obs_dim + Δ·act_dim` entries.
    pub delay: usize,
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
}

impl AgentSpec {
    /// The sizes of a task's model under a total delay Δ.
    pub fn for_model(model: &TaskModel, delay: usize) -> AgentSpec {
        AgentSpec {
            obs_dim: model.task.obs_dim,
            act_dim: model.task.act_dim,
            delay,
            action_low: model.action_low.clone(),
            action_high: model.action_high.clone(),
        }
    }

    /// The sizes of `task` under a total delay Δ (loads its model for the action bounds).
    pub fn for_task(task: TaskName, delay: usize) -> Result<AgentSpec, SimError> {
        Ok(AgentSpec::for_model(&*TaskModel::load(task)?, delay))
    }

    pub fn augmented_dim(&self) -> usize {
        self.obs_dim + self.delay * self.act_dim
    }
}

/// How actions are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActMode {
    /// Sampled from the policy (training).
    Explore,
    /// The policy's mode, `tanh` of the mean (evaluation).
    Deterministic,
}

/// What the training loop needs of an algorithm: a stack of S runs of one configuration, their
/// seeds apart, trained side by side, each with its own batches, random streams and folder (a
/// solo run is S = 1). The one-run methods (`act`, `update`, `save`, `load`) are run 0's, for
/// a solo agent.
pub trait Agent: Send {
    /// How many runs the agent trains side by side.
    fn runs(&self) -> usize;
    /// The sizes the agent was built for.
    fn spec(&self) -> &AgentSpec;
    /// The plain device the agent acts on.
    fn acting_device(&self) -> &Device;
    /// Actions `[s, rows, act_dim]` of the runs `runs` (the whole stack, or one run) for their
    /// augmented states `[s, rows, obs + Δ·act]` on [`Agent::acting_device`]: run
    /// `runs.start + i` acts on its first `counts[i]` rows, drawing exploration noise for
    /// those rows only, as a solo run given the same rows does; the rows after them are
    /// padding, whose actions mean nothing.
    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3>;
    /// One update of every run, run `i` drawing its batches from `contexts[i]` (as many as it
    /// needs); the statistics computed this time, on the device (an absent one is logged
    /// empty).
    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError>;
    /// Run `i`'s networks, optimiser states and random streams into `dirs[i]`, each as a solo
    /// run of its seed writes them.
    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError>;
    /// Restores run `i` from `dirs[i]` (what [`Agent::save_runs`] or a solo run wrote).
    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError>;
    /// The statistics an update may report, in `train.csv`'s column order.
    fn stat_names(&self) -> Vec<&'static str>;
    /// The optional batch fields the agent samples (none by default).
    fn batch_extras(&self) -> BatchExtras {
        BatchExtras::default()
    }
    /// What run 0 computes in [`ActMode::Deterministic`], as plain numbers (`dhrl export`).
    fn acting_network(&self) -> ActingNetwork;
    /// Deterministic actions of run 0's delay-free policy for `rows` true states `[rows, obs]`,
    /// evaluated undelayed; `None` unless [`AlgoInfo::delay_free_policy`] says there is one.
    fn act_delay_free(&mut self, _states: &[f32], _rows: usize) -> Option<Vec<f32>> {
        None
    }

    /// Actions `[rows, act_dim]` of run `run` for `rows` augmented states
    /// `[rows, obs + Δ·act]`: one upload, one download.
    fn act_run(&mut self, run: usize, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        let width = self.spec().augmented_dim();
        let input = upload_rows(augmented, 1, rows, width, self.acting_device());
        to_vec(self.act_tensor(run..run + 1, input, &[rows], mode))
    }
    /// Actions of every run in one pass (one upload, one download): `augmented` is
    /// `[S, rows, obs + Δ·act]`, run `i`'s `counts[i]` states first in slice `i`
    /// ([`Agent::act_tensor`]); returns `[S, rows, act_dim]`.
    fn act_runs(
        &mut self,
        augmented: &[f32],
        counts: &[usize],
        rows: usize,
        mode: ActMode,
    ) -> Vec<f32> {
        let (runs, width) = (self.runs(), self.spec().augmented_dim());
        let input = upload_rows(augmented, runs, rows, width, self.acting_device());
        to_vec(self.act_tensor(0..runs, input, counts, mode))
    }
    /// [`Agent::act_run`] of run 0.
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.act_run(0, augmented, rows, mode)
    }
    /// [`Agent::update_runs`] of a solo agent.
    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError> {
        self.update_runs(std::slice::from_mut(ctx))
    }
    /// [`Agent::save_runs`] of a solo agent.
    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.save_runs(&[dir])
    }
    /// [`Agent::load_runs`] of a solo agent.
    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.load_runs(&[dir])
    }
}

/// `n` random transitions at `spec`'s sizes, with their intermediate states (values uniform
/// in [−1, 1), every fifth one terminal): what update benchmarks and tests feed the learners, whose cost does not depend on
/// the values.
pub fn random_batch(spec: &AgentSpec, n: usize, seed: u64) -> Transitions {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut random = |len: usize| {
        (0..len)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect::<Vec<f32>>()
    };
    let (aug, obs, act) = (spec.augmented_dim(), spec.obs_dim, spec.act_dim);
    Transitions {
        copy: vec![0; n],
        episode: vec![0; n],
        tau: vec![0; n],
        augmented: random(n * aug),
        state: random(n * obs),
        action: random(n * act),
        reward: random(n),
        next_augmented: random(n * aug),
        next_state: random(n * obs),
        terminated: (0..n).map(|i| u32::from(i % 5 == 0)).collect(),
        intermediate_states: random(n * spec.delay * obs),
    }
}

/// What is known of an algorithm before it is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlgoInfo {
    /// The name `--algo` takes and `config.toml` records.
    pub name: &'static str,
    /// Its name in the paper's Table 1: report tables and figure legends.
    pub paper_name: &'static str,
    /// Its part in the paper's comparison.
    pub role: Role,
    /// Whether it is one of the lifting ablation's bars (the report's ablation figure).
    pub in_lifting_ablation: bool,
    /// One line for `--help` and `--help-config`.
    pub about: &'static str,
    /// Whether the acting policy's input is the augmented state `x_t` (its size grows with Δ,
    /// so the policy runs only at the delay it was trained with).
    pub acts_on_augmented_state: bool,
    /// Whether the agent also learns a policy on the true state that `dhrl eval
    /// --delay-free-policy` evaluates undelayed ([`Agent::act_delay_free`]).
    pub delay_free_policy: bool,
    /// Whether the algorithm is a delay-free reference that runs with Δ = 0 only.
    pub undelayed_only: bool,
    /// Whether the algorithm needs a delay Δ ≥ 1 (its policy reads the Δ pending actions).
    pub delayed_only: bool,
    /// Learners updated side by side (rayon threads an update can use to advantage).
    pub learner_threads: usize,
    /// The runs one learner pass serves on the CPU unless `--runs-per-pass` says otherwise: 2
    /// where a pass of two costs what two runs cost, 1 where it costs more (VDPO, whose
    /// activations alone fill the cache: docs/results/stacking.md).
    pub cpu_runs_per_pass: usize,
    /// Fields shown in plot labels: `(symbol, field)`, e.g. `("λ", "lifting_weight")`.
    pub label_fields: &'static [(&'static str, &'static str)],
}

impl AlgoInfo {
    /// An algorithm of one learner that runs under any delay and learns no delay-free policy.
    pub const fn single_learner(
        name: &'static str,
        paper_name: &'static str,
        about: &'static str,
        acts_on_augmented_state: bool,
    ) -> AlgoInfo {
        AlgoInfo {
            name,
            paper_name,
            role: Role::Baseline,
            in_lifting_ablation: false,
            about,
            acts_on_augmented_state,
            delay_free_policy: false,
            undelayed_only: false,
            delayed_only: false,
            learner_threads: 1,
            cpu_runs_per_pass: 2,
            label_fields: &[],
        }
    }
}

/// An algorithm's part in the paper's comparison (what the report does with its runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The delay-free reference whose Table 1 return normalises every score.
    Reference,
    /// A delayed baseline.
    Baseline,
    /// The paper's method: the report's probability of improvement is its, over each baseline.
    Proposed,
    /// Run for the lifting ablation only.
    Ablation,
}

/// One documented field of an algorithm's configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldDoc {
    pub name: &'static str,
    pub default: toml::Value,
    pub doc: String,
}

/// What an algorithm's configuration is wrong about.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AlgoError {
    #[error("unknown algorithm `{name}`; the algorithms are: {valid}")]
    UnknownAlgorithm { name: String, valid: String },
    #[error(
        "{algo} has no field `{field}`; its fields are: {valid} (`dhrl train --algo {algo} --help-config` describes them)"
    )]
    UnknownField {
        algo: &'static str,
        field: String,
        valid: String,
    },
    #[error("[algo] of {algo}: {message}")]
    BadValue { algo: &'static str, message: String },
    #[error("{algo}: {what} must be {accepted}, got {value}")]
    Invalid {
        algo: &'static str,
        what: &'static str,
        accepted: &'static str,
        value: String,
    },
    #[error("--set takes FIELD=VALUE (e.g. --set lifting_weight=10), got `{0}`")]
    BadAssignment(String),
    #[error(
        "{algo} is a delay-free reference and runs with Δ = 0; under a delay use one of: {delayed}"
    )]
    UndelayedOnly { algo: &'static str, delayed: String },
    #[error(
        "{algo} reads the Δ pending actions of the augmented state and needs a delay of at least 1; for Δ = 0 use one of: {undelayed}"
    )]
    DelayedOnly {
        algo: &'static str,
        undelayed: String,
    },
}

/// Checks one field: `Ok` when `ok`, else [`AlgoError::Invalid`].
pub fn check(
    ok: bool,
    algo: &'static str,
    what: &'static str,
    accepted: &'static str,
    value: impl ToString,
) -> Result<(), AlgoError> {
    if ok {
        Ok(())
    } else {
        Err(AlgoError::Invalid {
            algo,
            what,
            accepted,
            value: value.to_string(),
        })
    }
}

/// Field names and docs of a configuration struct (written by [`algo_config!`]).
pub trait ConfigFields {
    fn field_docs() -> Vec<FieldDoc>;
}

/// An algorithm's configuration, the whole of what its file exports to the registry.
pub trait AlgoConfig:
    ConfigFields + Serialize + DeserializeOwned + Default + Clone + Send + Sync + 'static
{
    const INFO: AlgoInfo;
    /// Checks every field, with errors that say what is accepted.
    fn validate(&self) -> Result<(), AlgoError>;
    /// The runs of `seeds` as one agent ([`Agent::runs`] = `seeds.len()`), for tasks of
    /// `spec`'s sizes: its learners stacked ([`crate::learn::stack`]), one pass serving every
    /// run, run `i` computing what a solo run of `seeds[i]` computes.
    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent>;
    /// One run's agent, seeded with `seed`: a stack of one.
    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        self.build_stack(spec, devices, &[seed])
    }
    /// This algorithm's defaults under `protocol` ([`Protocol`]). By default, its own defaults
    /// with the SAC settings the protocol sets ([`SacConfig::protocol_defaults`]) in the fields
    /// it shares with SAC.
    fn for_protocol(protocol: Protocol) -> Self {
        let mut table = toml_table(&Self::default());
        let docs = Self::field_docs();
        table.extend(
            toml_table(&SacConfig::protocol_defaults(protocol))
                .into_iter()
                .filter(|(field, _)| docs.iter().any(|doc| doc.name == field.as_str())),
        );
        toml::Value::Table(table)
            .try_into()
            .expect("SAC's fields read back into the configurations that embed them")
    }
    /// This configuration with what it schedules over the run's step budget (D2HPG's lifting
    /// weight under the `authors` protocol) fixed to `steps`, where it is not fixed yet: what
    /// a fresh run records in its `config.toml`, so that a run extended on resume keeps the
    /// schedule of its original budget. An algorithm that schedules nothing so is itself.
    fn for_budget(&self, _steps: u64) -> Self {
        self.clone()
    }
    /// The step budget this configuration schedules over, once fixed ([`AlgoConfig::for_budget`]);
    /// `None` for one that schedules nothing so.
    fn budget(&self) -> Option<u64> {
        None
    }
    /// This configuration with the work it schedules by environment steps (VDPO's cloning
    /// stages) brought within `updates` updates at one update per step, in the same amount per
    /// update, so that timing that many updates counts it (`dhrl bench update`, the cost
    /// estimate of `dhrl sweep plan`). An algorithm that schedules nothing is itself.
    fn schedule_within(&self, _updates: u64) -> Self {
        self.clone()
    }
}

/// A configuration's fields as a TOML table.
pub fn toml_table(config: &impl Serialize) -> toml::Table {
    match toml::Value::try_from(config) {
        Ok(toml::Value::Table(table)) => table,
        other => unreachable!("an algorithm configuration serialises to a table: {other:?}"),
    }
}

/// The TOML value of a field's default, for `--help-config`.
pub fn toml_value(value: &impl Serialize) -> toml::Value {
    toml::Value::try_from(value).expect("configuration fields are TOML values")
}

/// Declares an algorithm's configuration struct from its documented fields and defaults:
/// the struct (serde, every field defaulted), its `Default`, and its [`ConfigFields`]. A
/// leading `..name: Type;` embeds another configuration's fields flat (D2HPG's SAC and lifting
/// fields).
#[macro_export]
macro_rules! algo_config {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( ..$base:ident : $base_ty:ty ; )*
            $( $(#[doc = $doc:literal])* pub $field:ident : $ty:ty = $default:expr, )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(default)]
        pub struct $name {
            $( #[serde(flatten)] pub $base: $base_ty, )*
            $( $(#[doc = $doc])* pub $field: $ty, )*
        }

        impl Default for $name {
            fn default() -> Self {
                Self {
                    $( $base: <$base_ty>::default(), )*
                    $( $field: $default, )*
                }
            }
        }

        impl $crate::algos::ConfigFields for $name {
            fn field_docs() -> Vec<$crate::algos::FieldDoc> {
                #[allow(unused_mut)]
                let mut docs: Vec<$crate::algos::FieldDoc> = Vec::new();
                $( docs.extend(<$base_ty as $crate::algos::ConfigFields>::field_docs()); )*
                #[allow(unused_variables)]
                let defaults = <Self as Default>::default();
                $(
                    docs.push($crate::algos::FieldDoc {
                        name: stringify!($field),
                        default: $crate::algos::toml_value(&defaults.$field),
                        doc: [$($doc),*].iter().map(|line| line.trim()).collect::<Vec<_>>().join(" "),
                    });
                )*
                docs
            }
        }
    };
}
