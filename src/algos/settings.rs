//! The `[algo]` table of `config.toml`: which algorithm, and every field of its
//! configuration, resolved against the algorithm's defaults and checked.
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::agent::{Agent, AgentSpec, AlgoError, AlgoInfo, FieldDoc};
use super::registry::{Algorithm, algorithm};
use crate::learn::Devices;

/// An algorithm and its whole configuration (`name` plus every field, defaults filled in).
#[derive(Clone)]
pub struct AlgoSettings {
    algorithm: &'static dyn Algorithm,
    fields: toml::Table,
}

impl AlgoSettings {
    /// `name` with its defaults.
    pub fn new(name: &str) -> Result<AlgoSettings, AlgoError> {
        AlgoSettings::with_fields(name, &toml::Table::new())
    }

    /// `name` with the given fields over its defaults.
    pub fn with_fields(name: &str, given: &toml::Table) -> Result<AlgoSettings, AlgoError> {
        let algorithm = algorithm(name)?;
        Ok(AlgoSettings {
            fields: algorithm.resolve(given)?,
            algorithm,
        })
    }

    pub fn name(&self) -> &'static str {
        self.info().name
    }

    pub fn info(&self) -> &'static AlgoInfo {
        self.algorithm.info()
    }

    /// The resolved fields (without `name`).
    pub fn fields(&self) -> &toml::Table {
        &self.fields
    }

    /// The fields of this algorithm with their defaults and docs.
    pub fn field_docs(&self) -> Vec<FieldDoc> {
        self.algorithm.field_docs()
    }

    /// Overrides one field from `FIELD=VALUE` (VALUE in TOML syntax; a bare word is a string).
    pub fn set(&mut self, assignment: &str) -> Result<(), AlgoError> {
        let (field, value) = assignment
            .split_once('=')
            .map(|(f, v)| (f.trim(), v.trim()))
            .filter(|(f, v)| !f.is_empty() && !v.is_empty())
            .ok_or_else(|| AlgoError::BadAssignment(assignment.to_string()))?;
        let value = format!("value = {value}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("value"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut given = self.fields.clone();
        given.insert(field.to_string(), value);
        self.fields = self.algorithm.resolve(&given)?;
        Ok(())
    }

    /// The same fields under another algorithm: those it shares are kept, the rest default.
    pub fn switch_to(&self, name: &str) -> Result<AlgoSettings, AlgoError> {
        let target = algorithm(name)?;
        let names: Vec<&str> = target.field_docs().iter().map(|d| d.name).collect();
        let shared = self
            .fields
            .iter()
            .filter(|(k, _)| names.iter().any(|name| *name == k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        AlgoSettings::with_fields(name, &shared)
    }

    /// The agent, for tasks of `spec`'s sizes, seeded with `seed`.
    pub fn build(
        &self,
        spec: &AgentSpec,
        devices: &Devices,
        seed: u64,
    ) -> Result<Box<dyn Agent>, AlgoError> {
        self.algorithm.build(&self.fields, spec, devices, seed)
    }

    /// `--help-config`: every field with its default and its doc.
    pub fn describe(&self) -> String {
        let info = self.info();
        let mut text = format!(
            "{}: {}\n\nfields of [algo] (set with --set FIELD=VALUE, or in a --config file):\n",
            info.name, info.about
        );
        for doc in self.field_docs() {
            text.push_str(&format!(
                "  {} = {}\n      {}\n",
                doc.name, doc.default, doc.doc
            ));
        }
        text
    }
}

impl Default for AlgoSettings {
    /// The delay-free reference with its defaults.
    fn default() -> AlgoSettings {
        AlgoSettings::new(super::registry::reference().name).expect("the reference is registered")
    }
}

impl PartialEq for AlgoSettings {
    fn eq(&self, other: &AlgoSettings) -> bool {
        self.name() == other.name() && self.fields == other.fields
    }
}

impl std::fmt::Debug for AlgoSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlgoSettings")
            .field("name", &self.name())
            .field("fields", &self.fields)
            .finish()
    }
}

impl std::fmt::Display for AlgoSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for AlgoSettings {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut table = toml::Table::new();
        table.insert("name".into(), toml::Value::String(self.name().into()));
        table.extend(self.fields.clone());
        table.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for AlgoSettings {
    /// `[algo]` with `name` and any fields; a plain name (`algo = "bpql"`) takes the defaults.
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<AlgoSettings, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Given {
            Name(String),
            Table(toml::Table),
        }
        let result = match Given::deserialize(deserializer)? {
            Given::Name(name) => AlgoSettings::new(&name),
            Given::Table(mut table) => match table.remove("name") {
                Some(toml::Value::String(name)) => AlgoSettings::with_fields(&name, &table),
                _ => {
                    return Err(serde::de::Error::custom(format!(
                        "[algo] needs name = one of {}",
                        super::registry::names().join(", ")
                    )));
                }
            },
        };
        result.map_err(serde::de::Error::custom)
    }
}
