//! The algorithms, each readable top to bottom in its own file — its configuration first, then
//! its losses and its [`Agent`] — and the one registry line per algorithm that makes it known
//! to `dhrl train --algo`, `config.toml`, evaluation and the benches.
//!
//! Every transition carries both what the delayed agent saw (`x_τ`, `x_{τ+1}`) and the true
//! states (`s_τ`, `s_{τ+1}`), so learners on the true state (BPQL's critic, D2HPG's delay-free
//! SAC) and learners on `x` train from the same replay.

mod agent;
mod augmented_sac;
mod bpql;
mod context;
mod d2hpg;
mod d2hpg_principled;
mod d2hpg_sac;
mod delayed_sac;
mod independent;
mod lifting;
mod naive_sac;
mod registry;
mod sac;
mod settings;
mod stats;
mod vdpo;

pub use agent::{
    ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, ConfigFields, FieldDoc, Role,
    check, random_batch, toml_table, toml_value,
};
pub use bpql::Bpql;
pub use context::UpdateContext;
pub use d2hpg::{Config as D2hpgConfig, D2hpg, Regular};
pub use d2hpg_principled::{
    AbstractReward, ActionMap, Config as D2hpgPrincipledConfig, D2hpgPrincipled, Distance,
    Homomorphism, LaxMetric, MetricReduction, RegularCritic, TransitionLoss, TransitionStd,
    abstract_model_loss, gaussian_w2, lax_loss,
};
pub use lifting::{LiftingConfig, LiftingNoise, LiftingSchedule, Reduction};
pub use registry::{
    ALGORITHMS, Algorithm, AnyConfig, Registered, algorithm, names, names_where, paper_name,
    proposed, reference,
};
pub use sac::{
    Config as SacConfig, InputView, LearningRates, SAC_STATS, SacAgent, SacBatch, SacLearner,
};
pub use settings::{AlgoSettings, parse_assignment};
pub use stats::{RunStats, Stats};
