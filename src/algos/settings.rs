//! The `[algo]` table of `config.toml`: which algorithm, and every field of its
//! configuration, resolved against the algorithm's defaults and checked.
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::agent::{Agent, AgentSpec, AlgoError, AlgoInfo, FieldDoc};
use super::registry::{AnyConfig, algorithm};
use crate::learn::Devices;
use crate::protocol::Protocol;

/// An algorithm and its whole configuration, typed (defaults filled in, every field checked),
/// with the protocol whose defaults filled it in.
pub struct AlgoSettings {
    config: Box<dyn AnyConfig>,
    protocol: Protocol,
}

impl AlgoSettings {
    /// `name` with its defaults.
    pub fn new(name: &str) -> Result<AlgoSettings, AlgoError> {
        AlgoSettings::with_fields(name, &toml::Table::new())
    }

    /// `name` with the given fields over its defaults (dhrl's protocol).
    pub fn with_fields(name: &str, given: &toml::Table) -> Result<AlgoSettings, AlgoError> {
        AlgoSettings::under(Protocol::Dhrl, name, given)
    }

    /// `name` with the given fields over its defaults under `protocol`: the one place a
    /// configuration is read.
    pub fn under(
        protocol: Protocol,
        name: &str,
        given: &toml::Table,
    ) -> Result<AlgoSettings, AlgoError> {
        Ok(AlgoSettings {
            config: algorithm(name)?.parse(protocol, given)?,
            protocol,
        })
    }

    /// The protocol whose defaults these settings started from.
    pub fn protocol(&self) -> Protocol {
        self.protocol
    }

    pub fn name(&self) -> &'static str {
        self.info().name
    }

    pub fn info(&self) -> &'static AlgoInfo {
        self.config.info()
    }

    /// Every field as TOML (without `name`).
    pub fn fields(&self) -> toml::Table {
        self.config.table()
    }

    /// The fields of this algorithm with their defaults and docs.
    pub fn field_docs(&self) -> Vec<FieldDoc> {
        algorithm(self.name())
            .expect("a configuration's algorithm is registered")
            .field_docs()
    }

    /// `values` over these settings, read once: under `algorithm` when given (keeping the
    /// fields it shares with this one, the rest at its defaults), else under this one.
    pub fn with(
        &self,
        algorithm_name: Option<&str>,
        values: &toml::Table,
    ) -> Result<AlgoSettings, AlgoError> {
        let target = algorithm(algorithm_name.unwrap_or(self.name()))?;
        let docs = target.field_docs();
        let mut given: toml::Table = self
            .fields()
            .into_iter()
            .filter(|(k, _)| docs.iter().any(|d| d.name == k.as_str()))
            .collect();
        given.extend(values.iter().map(|(k, v)| (k.clone(), v.clone())));
        AlgoSettings::under(self.protocol, target.info().name, &given)
    }

    /// These settings, their fields all given, as read under `protocol` (a `config.toml`'s
    /// `[algo]`, complete, beside its `protocol`).
    pub fn tagged(self, protocol: Protocol) -> AlgoSettings {
        AlgoSettings { protocol, ..self }
    }

    /// [`crate::algos::AlgoConfig::budget`].
    pub fn budget(&self) -> Option<u64> {
        self.config.budget()
    }

    /// [`crate::algos::AlgoConfig::for_budget`].
    pub fn for_budget(&self, steps: u64) -> AlgoSettings {
        AlgoSettings {
            config: self.config.for_budget(steps),
            protocol: self.protocol,
        }
    }

    /// Overrides one field from `FIELD=VALUE` (VALUE in TOML syntax; a bare word is a string).
    pub fn set(&mut self, assignment: &str) -> Result<(), AlgoError> {
        let (field, value) = parse_assignment(assignment)?;
        *self = self.with(None, &toml::Table::from_iter([(field, value)]))?;
        Ok(())
    }

    /// These settings with their environment-step schedule within `updates` updates
    /// ([`crate::algos::AlgoConfig::schedule_within`]).
    pub fn schedule_within(&self, updates: u64) -> AlgoSettings {
        AlgoSettings {
            config: self.config.schedule_within(updates),
            protocol: self.protocol,
        }
    }

    /// The agent, for tasks of `spec`'s sizes, seeded with `seed`.
    pub fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        self.config.build(spec, devices, seed)
    }

    /// The runs of `seeds` as one agent (a stack).
    pub fn build_stack(
        &self,
        spec: &AgentSpec,
        devices: &Devices,
        seeds: &[u64],
    ) -> Box<dyn Agent> {
        self.config.build_stack(spec, devices, seeds)
    }

    /// The runs of `seeds` as one agent whose learners serve `per_pass` runs at a time: stacks
    /// of that many, updated one after the other.
    pub fn build_in_passes(
        &self,
        spec: &AgentSpec,
        devices: &Devices,
        seeds: &[u64],
        per_pass: usize,
    ) -> Box<dyn Agent> {
        if per_pass >= seeds.len() {
            return self.build_stack(spec, devices, seeds);
        }
        Box::new(super::independent::Independent::new(
            seeds
                .chunks(per_pass.max(1))
                .map(|part| self.build_stack(spec, devices, part))
                .collect(),
        ))
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

/// `FIELD=VALUE` (`--set`) as a field name and its TOML value (a bare word is a string).
pub fn parse_assignment(assignment: &str) -> Result<(String, toml::Value), AlgoError> {
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
    Ok((field.to_string(), value))
}

impl Clone for AlgoSettings {
    fn clone(&self) -> AlgoSettings {
        AlgoSettings {
            config: self.config.boxed_clone(),
            protocol: self.protocol,
        }
    }
}

impl PartialEq for AlgoSettings {
    fn eq(&self, other: &AlgoSettings) -> bool {
        // The fields decide; the protocol only chose the defaults they started from.
        self.name() == other.name() && self.fields() == other.fields()
    }
}

impl std::fmt::Debug for AlgoSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlgoSettings")
            .field("name", &self.name())
            .field("protocol", &self.protocol)
            .field("fields", &self.fields())
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
        table.extend(self.fields());
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

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> toml::Table {
        text.parse().unwrap()
    }

    /// Switching algorithms keeps the fields both have and defaults the rest; values given
    /// with the switch go over both; a field the target lacks is refused by name.
    #[test]
    fn settings_switch_algorithms_keeping_the_shared_fields() {
        let d2hpg = AlgoSettings::with_fields("d2hpg", &table("lifting_weight = 3.0\ngamma = 0.9"))
            .unwrap();
        let naive = d2hpg
            .with(Some("d2hpg-naive"), &table("tau = 0.01"))
            .unwrap();
        assert_eq!(naive.name(), "d2hpg-naive");
        let fields = naive.fields();
        assert_eq!(fields["lifting_weight"].as_float(), Some(3.0));
        assert_eq!(fields["gamma"].as_float(), Some(0.9));
        assert_eq!(fields["tau"].as_float(), Some(0.01));
        let bpql = d2hpg.with(Some("bpql"), &toml::Table::new()).unwrap();
        assert_eq!(bpql.fields()["gamma"].as_float(), Some(0.9));
        assert!(!bpql.fields().contains_key("lifting_weight"));
        let refused = d2hpg.with(Some("bpql"), &table("lifting_samples = 4"));
        assert!(
            matches!(&refused, Err(AlgoError::UnknownField { field, .. }) if field == "lifting_samples"),
            "{:?}",
            refused.err()
        );
        // Unchanged by the failed switch, and equal to its own round trip through TOML.
        assert_eq!(
            d2hpg,
            AlgoSettings::with_fields("d2hpg", &d2hpg.fields()).unwrap()
        );
    }

    #[test]
    fn assignments_parse_to_typed_values() {
        let parsed = |text| parse_assignment(text).unwrap();
        assert_eq!(parsed("tau=0.01"), ("tau".into(), toml::Value::Float(0.01)));
        assert_eq!(
            parsed(" lifting_samples = 4 "),
            ("lifting_samples".into(), toml::Value::Integer(4))
        );
        assert_eq!(
            parsed("model_output=difference").1,
            toml::Value::String("difference".into())
        );
        assert!(matches!(
            parse_assignment("tau"),
            Err(AlgoError::BadAssignment(_))
        ));
        assert!(matches!(
            parse_assignment("=3"),
            Err(AlgoError::BadAssignment(_))
        ));
    }
}
