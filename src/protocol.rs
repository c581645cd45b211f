//! Whose settings fill in what the paper leaves open. The paper states the method and most of
//! SAC's hyperparameters but not λ, K, their schedule, the warm-up or the initialisation; its
//! authors' released code (GitHub `JongsooLee/DHRL`) chose some, dhrl's own two-seed grid chose
//! others (docs/DESIGN.md §3.4). A protocol is one name for one consistent set of those
//! choices: `config.toml` records it, and every setting it fills in stays a typed field that a
//! flag, `--set` or a config file overrides.
use serde::{Deserialize, Serialize};

#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Protocol {
    /// dhrl's own settings: 1,000 random steps then one update per step, burn's initialisation,
    /// D2HPG with λ = 1 constant, K = 2 with common noise, the lifting loss summed over action
    /// dimensions and one temperature per learner.
    #[default]
    Dhrl,
    /// The authors' released code: 10,000 random steps with updates from step 100 in blocks of
    /// 50 once the replay holds a batch, orthogonal initialisation (gain 1, zero biases),
    /// D2HPG with λ = 10 held to 25% of the run's steps and decayed to 0 at 75%, K = 100 with
    /// independent noise, the lifting loss averaged over action dimensions, and one α shared
    /// by the regular and the delay-free learner.
    Authors,
}

impl Protocol {
    /// The name `--protocol` takes and `config.toml` records.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Dhrl => "dhrl",
            Protocol::Authors => "authors",
        }
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `over`'s entries written into `base`, tables merged key by key (a config file's `[delay]`
/// over a protocol's keeps the fields the file leaves out).
pub fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(inner)), toml::Value::Table(value)) => {
                merge_tables(inner, value)
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merging_keeps_what_the_overlay_leaves_out() {
        let mut base: toml::Table = "a = 1\n[t]\nx = 1\ny = 2\n".parse().unwrap();
        merge_tables(&mut base, "b = 3\n[t]\ny = 5\n".parse().unwrap());
        let expected: toml::Table = "a = 1\nb = 3\n[t]\nx = 1\ny = 5\n".parse().unwrap();
        assert_eq!(base, expected);
    }
}
