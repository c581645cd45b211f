//! What ties an algorithm file to the rest of dhrl: its [`AlgoInfo`], its configuration (the
//! `[algo]` table of `config.toml`, documented field by field) and its constructor, behind one
//! object-safe [`Algorithm`] that the registry in `mod.rs` lists, one line per algorithm.
use std::marker::PhantomData;

use serde::{Serialize, de::DeserializeOwned};

use super::{Agent, AgentSpec};
use crate::learn::Devices;

/// What is known of an algorithm before it is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlgoInfo {
    /// The name `--algo` takes and `config.toml` records.
    pub name: &'static str,
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
    /// Fields shown in plot labels, with the symbol they are shown as (e.g. `λ`).
    pub label_fields: &'static [(&'static str, &'static str)],
}

impl AlgoInfo {
    /// An algorithm of one learner that runs under any delay and learns no delay-free policy.
    pub const fn single_learner(
        name: &'static str,
        about: &'static str,
        acts_on_augmented_state: bool,
    ) -> AlgoInfo {
        AlgoInfo {
            name,
            about,
            acts_on_augmented_state,
            delay_free_policy: false,
            undelayed_only: false,
            delayed_only: false,
            learner_threads: 1,
            label_fields: &[],
        }
    }
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
        "{0} is a delay-free reference and runs with Δ = 0; use augmented-sac, naive-sac, bpql or a D2HPG variant under a delay"
    )]
    UndelayedOnly(&'static str),
    #[error(
        "{0} reads the Δ pending actions of the augmented state and needs a delay of at least 1; use sac for Δ = 0"
    )]
    DelayedOnly(&'static str),
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
pub trait AlgoConfig: ConfigFields + Serialize + DeserializeOwned + Default + 'static {
    const INFO: AlgoInfo;
    /// Checks every field, with errors that say what is accepted.
    fn validate(&self) -> Result<(), AlgoError>;
    /// The agent, for tasks of `spec`'s sizes, seeded with `seed`.
    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent>;
}

/// A registered algorithm, whatever its configuration type.
pub trait Algorithm: Sync {
    fn info(&self) -> &'static AlgoInfo;
    fn field_docs(&self) -> Vec<FieldDoc>;
    /// The whole configuration: defaults overridden by the fields of `given`, checked.
    fn resolve(&self, given: &toml::Table) -> Result<toml::Table, AlgoError>;
    /// The agent of a configuration that [`Algorithm::resolve`] returned.
    fn build(
        &self,
        resolved: &toml::Table,
        spec: &AgentSpec,
        devices: &Devices,
        seed: u64,
    ) -> Result<Box<dyn Agent>, AlgoError>;
}

/// The [`Algorithm`] of configuration type `C`: what a registry line holds.
pub struct Registered<C>(PhantomData<fn() -> C>);

impl<C> Registered<C> {
    pub const fn new() -> Registered<C> {
        Registered(PhantomData)
    }
}

impl<C: AlgoConfig> Registered<C> {
    fn parse(given: &toml::Table) -> Result<C, AlgoError> {
        let docs = C::field_docs();
        if let Some(field) = given.keys().find(|k| !docs.iter().any(|d| d.name == *k)) {
            return Err(AlgoError::UnknownField {
                algo: C::INFO.name,
                field: field.clone(),
                valid: docs.iter().map(|d| d.name).collect::<Vec<_>>().join(", "),
            });
        }
        let config: C = toml::Value::Table(given.clone()).try_into().map_err(|e| {
            // Name the field: the first that fails on its own.
            let field = given.iter().find(|(k, v)| {
                let alone = toml::Table::from_iter([((*k).clone(), (*v).clone())]);
                toml::Value::Table(alone).try_into::<C>().is_err()
            });
            AlgoError::BadValue {
                algo: C::INFO.name,
                message: match field {
                    Some((k, v)) => format!("{k} = {v}: {}", e.message()),
                    None => e.message().to_string(),
                },
            }
        })?;
        config.validate()?;
        Ok(config)
    }
}

impl<C: AlgoConfig> Algorithm for Registered<C> {
    fn info(&self) -> &'static AlgoInfo {
        &C::INFO
    }

    fn field_docs(&self) -> Vec<FieldDoc> {
        C::field_docs()
    }

    fn resolve(&self, given: &toml::Table) -> Result<toml::Table, AlgoError> {
        let config = Self::parse(given)?;
        match toml::Value::try_from(&config) {
            Ok(toml::Value::Table(table)) => Ok(table),
            other => unreachable!("an algorithm configuration serialises to a table: {other:?}"),
        }
    }

    fn build(
        &self,
        resolved: &toml::Table,
        spec: &AgentSpec,
        devices: &Devices,
        seed: u64,
    ) -> Result<Box<dyn Agent>, AlgoError> {
        Ok(Self::parse(resolved)?.build(spec, devices, seed))
    }
}

/// The TOML value of a field's default, for `--help-config`.
pub fn toml_value(value: &impl Serialize) -> toml::Value {
    toml::Value::try_from(value).expect("configuration fields are TOML values")
}

/// Declares an algorithm's configuration struct from its documented fields and defaults:
/// the struct (serde, every field defaulted), its `Default`, and its [`ConfigFields`]. A
/// leading `..name: Type;` embeds another configuration's fields flat (D2HPG's SAC fields).
#[macro_export]
macro_rules! algo_config {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( ..$base:ident : $base_ty:ty ; )?
            $( $(#[doc = $doc:literal])* pub $field:ident : $ty:ty = $default:expr, )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(default)]
        pub struct $name {
            $( #[serde(flatten)] pub $base: $base_ty, )?
            $( $(#[doc = $doc])* pub $field: $ty, )*
        }

        impl Default for $name {
            fn default() -> Self {
                Self {
                    $( $base: <$base_ty>::default(), )?
                    $( $field: $default, )*
                }
            }
        }

        impl $crate::algos::ConfigFields for $name {
            fn field_docs() -> Vec<$crate::algos::FieldDoc> {
                #[allow(unused_mut)]
                let mut docs: Vec<$crate::algos::FieldDoc> = Vec::new();
                $( docs.extend(<$base_ty as $crate::algos::ConfigFields>::field_docs()); )?
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
