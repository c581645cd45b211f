//! The registry: one line per algorithm, and everything that lists algorithms (the names
//! `--algo` accepts, the messages that name them) generated from it.
use std::marker::PhantomData;

use super::agent::{Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, FieldDoc, Role, toml_table};
use super::{
    augmented_sac, bpql, d2hpg, d2hpg_principled, d2hpg_sac, delayed_sac, naive_sac, sac, vdpo,
};
use crate::learn::Devices;
use crate::protocol::{Protocol, merge_tables};

/// Every algorithm, one line each: the registry.
pub static ALGORITHMS: &[&dyn Algorithm] = &[
    &Registered::<sac::Config>::new(),
    &Registered::<naive_sac::Config>::new(),
    &Registered::<augmented_sac::Config>::new(),
    &Registered::<delayed_sac::Config>::new(),
    &Registered::<vdpo::Config>::new(),
    &Registered::<bpql::Config>::new(),
    &Registered::<d2hpg::NaiveConfig>::new(),
    &Registered::<d2hpg::Config>::new(),
    &Registered::<d2hpg_sac::Config>::new(),
    &Registered::<d2hpg_principled::Config>::new(),
];

/// The registered algorithm called `name`.
pub fn algorithm(name: &str) -> Result<&'static dyn Algorithm, AlgoError> {
    ALGORITHMS
        .iter()
        .copied()
        .find(|a| a.info().name == name)
        .ok_or_else(|| AlgoError::UnknownAlgorithm {
            name: name.to_string(),
            valid: names().join(", "),
        })
}

/// The names `--algo` accepts, in registry order.
pub fn names() -> Vec<&'static str> {
    ALGORITHMS.iter().map(|a| a.info().name).collect()
}

/// The names of the algorithms whose [`AlgoInfo`] passes `keep`, in registry order.
pub fn names_where(keep: impl Fn(&AlgoInfo) -> bool) -> Vec<&'static str> {
    ALGORITHMS
        .iter()
        .map(|a| a.info())
        .filter(|info| keep(info))
        .map(|info| info.name)
        .collect()
}

/// The delay-free reference (the one algorithm of [`Role::Reference`]): the default algorithm,
/// and the return every report score is a fraction of.
pub fn reference() -> &'static AlgoInfo {
    the_one(Role::Reference)
}

/// The paper's method (the one algorithm of [`Role::Proposed`]).
pub fn proposed() -> &'static AlgoInfo {
    the_one(Role::Proposed)
}

fn the_one(role: Role) -> &'static AlgoInfo {
    let mut found = ALGORITHMS
        .iter()
        .map(|a| a.info())
        .filter(|info| info.role == role);
    let one = found
        .next()
        .expect("the registry has an algorithm of each role");
    assert!(
        found.next().is_none(),
        "the registry has one {role:?} algorithm"
    );
    one
}

/// The paper's name of the algorithm called `name` (`name` itself for one not registered,
/// such as a run folder from a newer dhrl).
pub fn paper_name(name: &str) -> &str {
    ALGORITHMS
        .iter()
        .map(|a| a.info())
        .find(|info| info.name == name)
        .map_or(name, |info| info.paper_name)
}

/// A registered algorithm, whatever its configuration type.
pub trait Algorithm: Sync {
    fn info(&self) -> &'static AlgoInfo;
    fn field_docs(&self) -> Vec<FieldDoc>;
    /// The typed configuration: the defaults of `protocol` overridden by the fields of
    /// `given`, checked. The one place where an algorithm's TOML is read.
    fn parse(
        &self,
        protocol: Protocol,
        given: &toml::Table,
    ) -> Result<Box<dyn AnyConfig>, AlgoError>;
}

/// An algorithm's configuration, typed, whatever the algorithm: what `AlgoSettings` holds and
/// builds the agent from.
pub trait AnyConfig: Send + Sync {
    fn info(&self) -> &'static AlgoInfo;
    /// Every field as TOML (`[algo]` of `config.toml`, without `name`).
    fn table(&self) -> toml::Table;
    /// The agent, for tasks of `spec`'s sizes, seeded with `seed`.
    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent>;
    /// The runs of `seeds` as one agent.
    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent>;
    fn boxed_clone(&self) -> Box<dyn AnyConfig>;
    /// [`AlgoConfig::schedule_within`].
    fn schedule_within(&self, updates: u64) -> Box<dyn AnyConfig>;
    /// [`AlgoConfig::for_budget`].
    fn for_budget(&self, steps: u64) -> Box<dyn AnyConfig>;
    /// [`AlgoConfig::budget`].
    fn budget(&self) -> Option<u64>;
}

impl<C: AlgoConfig> AnyConfig for C {
    fn info(&self) -> &'static AlgoInfo {
        &C::INFO
    }

    fn table(&self) -> toml::Table {
        toml_table(self)
    }

    fn for_budget(&self, steps: u64) -> Box<dyn AnyConfig> {
        Box::new(AlgoConfig::for_budget(self, steps))
    }

    fn budget(&self) -> Option<u64> {
        AlgoConfig::budget(self)
    }

    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        AlgoConfig::build(self, spec, devices, seed)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        AlgoConfig::build_stack(self, spec, devices, seeds)
    }

    fn boxed_clone(&self) -> Box<dyn AnyConfig> {
        Box::new(self.clone())
    }

    fn schedule_within(&self, updates: u64) -> Box<dyn AnyConfig> {
        Box::new(AlgoConfig::schedule_within(self, updates))
    }
}

/// The [`Algorithm`] of configuration type `C`: what a registry line holds.
pub struct Registered<C>(PhantomData<fn() -> C>);

impl<C> Registered<C> {
    pub const fn new() -> Registered<C> {
        Registered(PhantomData)
    }
}

impl<C: AlgoConfig> Algorithm for Registered<C> {
    fn info(&self) -> &'static AlgoInfo {
        &C::INFO
    }

    fn field_docs(&self) -> Vec<FieldDoc> {
        C::field_docs()
    }

    fn parse(
        &self,
        protocol: Protocol,
        given: &toml::Table,
    ) -> Result<Box<dyn AnyConfig>, AlgoError> {
        let docs = C::field_docs();
        if let Some(field) = given.keys().find(|k| !docs.iter().any(|d| d.name == *k)) {
            return Err(AlgoError::UnknownField {
                algo: C::INFO.name,
                field: field.clone(),
                valid: docs.iter().map(|d| d.name).collect::<Vec<_>>().join(", "),
            });
        }
        let mut fields = toml_table(&C::for_protocol(protocol));
        merge_tables(&mut fields, given.clone());
        let config: C = toml::Value::Table(fields).try_into().map_err(|e| {
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
        Ok(Box::new(config))
    }
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::*;

    /// The string literals of Rust source `code`, comments skipped (raw strings too).
    fn string_literals(code: &str) -> Vec<(usize, String)> {
        let chars: Vec<char> = code.chars().collect();
        let (mut out, mut i, mut line) = (Vec::new(), 0, 1);
        while i < chars.len() {
            match chars[i] {
                '\n' => line += 1,
                '/' if chars.get(i + 1) == Some(&'/') => {
                    while i < chars.len() && chars[i] != '\n' {
                        i += 1;
                    }
                    continue;
                }
                '\'' if chars.get(i + 2) == Some(&'\'') || chars.get(i + 1) == Some(&'\\') => {
                    // A char literal ('"' among them), or a lifetime: skip its quote.
                    i += if chars.get(i + 1) == Some(&'\\') {
                        4
                    } else {
                        3
                    };
                    continue;
                }
                'r' if matches!(chars.get(i + 1), Some('"' | '#'))
                    && !chars
                        .get(i.wrapping_sub(1))
                        .is_some_and(|c| c.is_alphanumeric()) =>
                {
                    let hashes = chars[i + 1..].iter().take_while(|&&c| c == '#').count();
                    let start = i + 2 + hashes;
                    let closing: Vec<char> = std::iter::once('"')
                        .chain(std::iter::repeat_n('#', hashes))
                        .collect();
                    let mut end = start;
                    while end < chars.len() && !chars[end..].starts_with(&closing) {
                        end += 1;
                    }
                    let text: String = chars[start..end.min(chars.len())].iter().collect();
                    out.push((line, text.clone()));
                    line += text.matches('\n').count();
                    i = end + closing.len();
                    continue;
                }
                '"' => {
                    let mut text = String::new();
                    i += 1;
                    while i < chars.len() && chars[i] != '"' {
                        if chars[i] == '\\' {
                            i += 1;
                        }
                        if chars.get(i) == Some(&'\n') {
                            line += 1;
                        }
                        text.extend(chars.get(i));
                        i += 1;
                    }
                    out.push((line, text));
                }
                _ => {}
            }
            i += 1;
        }
        out
    }

    fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                rust_files(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }

    /// Whether `name` occurs in `text` as a whole word: letters, digits, '-' and '_' continue a
    /// word ("sac" is not in "naive-sac"), anything else ends one ("vdpo" is in "vdpo/belief").
    fn mentions(text: &str, name: &str) -> bool {
        let word = |c: char| c.is_alphanumeric() || c == '-' || c == '_';
        text.match_indices(name).any(|(at, _)| {
            !text[..at].chars().next_back().is_some_and(word)
                && !text[at + name.len()..].chars().next().is_some_and(word)
        })
    }

    /// Every list or message of algorithms is generated from the registry: no source file but
    /// the algorithms' own writes an algorithm's name or paper name in a string (unit tests
    /// aside).
    #[test]
    fn no_algorithm_name_is_written_outside_the_algorithm_files() {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        let own_files: Vec<&PathBuf> = files
            .iter()
            .filter(|p| {
                p.starts_with(src.join("algos"))
                    && std::fs::read_to_string(p)
                        .unwrap()
                        .contains("const INFO: AlgoInfo")
            })
            .collect();
        assert!(
            own_files.len() >= 6,
            "found the algorithm files: {own_files:?}"
        );
        let words: Vec<&str> = ALGORITHMS
            .iter()
            .flat_map(|a| [a.info().name, a.info().paper_name])
            .collect();
        let mut found = Vec::new();
        for path in files.iter().filter(|p| !own_files.contains(p)) {
            let code = std::fs::read_to_string(path).unwrap();
            // A file's unit tests (its `#[cfg(test)]` module, last) may name algorithms.
            let code = code.split("#[cfg(test)]").next().unwrap_or_default();
            for (line, literal) in string_literals(&code) {
                for word in words.iter().filter(|w| mentions(&literal, w)) {
                    found.push(format!(
                        "{}:{line}: {word:?} in {literal:?}",
                        path.display()
                    ));
                }
            }
        }
        assert!(
            found.is_empty(),
            "algorithm names written by hand:\n{}",
            found.join("\n")
        );
    }

    /// The scanner itself: it finds a name in a plain, a multi-line and a raw string, and
    /// neither in comments nor inside a longer name.
    #[test]
    fn the_scanner_finds_names_in_strings_only() {
        let code = "// \"bpql\" in a comment\nlet a = \"use bpql here\";\nlet c = '\"';\n\
                    let b = r#\"raw \"d2hpg\"\"#;\nlet d = \"naive-sac\";\n";
        let literals = string_literals(code);
        let texts: Vec<&str> = literals.iter().map(|(_, t)| t.as_str()).collect();
        assert_eq!(texts, ["use bpql here", "raw \"d2hpg\"", "naive-sac"]);
        assert_eq!(literals[1].0, 4, "line numbers count from 1");
        assert!(mentions("use bpql here", "bpql"));
        assert!(mentions("raw \"d2hpg\"", "d2hpg"));
        assert!(
            !mentions("naive-sac", "sac"),
            "a longer name is not the shorter one"
        );
        assert!(!mentions("d2hpg-naive", "d2hpg"));
    }
}
