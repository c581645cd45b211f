//! A loaded agent owns what it loaded: its saved folder replaced by the next checkpoint, or
//! removed, afterwards changes nothing (burn's own file loaders read tensors lazily from the
//! path, so both used to reach into the new files, or fail on the missing ones). The agent is
//! saved after updates that moved every optimiser state, input statistic and schedule it has,
//! so a load that skipped any of them would show in the updates after it.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use dhrl::algos::{
    ActMode, Agent, AgentSpec, AlgoSettings, RunStats, UpdateContext, names, random_batch,
};
use dhrl::learn::{Devices, LearnDevice};

/// Update `k` of a run, `k` thousand environment steps in: what an agent does on a schedule
/// (the actor every other update, VDPO's cloning stage every 1,000 steps) runs too.
fn advance(agent: &mut dyn Agent, spec: &AgentSpec, k: u64) -> RunStats {
    let batch = random_batch(spec, 32, 100 + k);
    agent
        .update(&mut UpdateContext::fixed(&batch, 1000 * k, k))
        .expect("a fixed batch is never empty")
        .values()
        .remove(0)
}

#[test]
fn a_loaded_agent_is_unaffected_by_its_folder_being_replaced_or_removed() {
    let devices = Devices::new(LearnDevice::Cpu).unwrap();
    for algo in names() {
        let mut settings = AlgoSettings::new(algo).unwrap();
        if settings.fields().contains_key("dropout") {
            // VDPO's dropout masks follow the seed an agent was built with, and the two agents
            // here are built with different seeds: compared without dropout.
            settings.set("dropout=0.0").unwrap();
        }
        if settings.fields().contains_key("bc_updates") {
            settings.set("bc_updates=5").unwrap();
        }
        let spec = AgentSpec {
            obs_dim: 4,
            act_dim: 2,
            delay: if settings.info().undelayed_only { 0 } else { 2 },
            action_low: vec![-1.0, -2.0],
            action_high: vec![1.0, 2.0],
        };
        let mut original = settings.build(&spec, &devices, 7);
        for k in 1..=3 {
            advance(original.as_mut(), &spec, k);
        }
        let folder = tempfile::tempdir().unwrap();
        let saved = folder.path().join("checkpoint");
        std::fs::create_dir(&saved).unwrap();
        original.save(&saved).unwrap();
        let mut loaded = settings.build(&spec, &devices, 8);
        loaded.load(&saved).unwrap();
        // The next checkpoint replaces every file (another agent's), then the folder goes.
        settings.build(&spec, &devices, 9).save(&saved).unwrap();
        std::fs::remove_dir_all(&saved).unwrap();
        for k in 4..=6 {
            assert_eq!(
                advance(original.as_mut(), &spec, k),
                advance(loaded.as_mut(), &spec, k),
                "{algo}: update {k} of the saved agent and of the one loaded from it"
            );
        }
        let probe = random_batch(&spec, 8, 5);
        for mode in [ActMode::Deterministic, ActMode::Explore] {
            assert_eq!(
                original.act(&probe.augmented, 8, mode),
                loaded.act(&probe.augmented, 8, mode),
                "{algo}: {mode:?} actions of the saved agent and of the one loaded from it"
            );
        }
    }
}
