//! A loaded agent owns what it loaded: its saved folder replaced by the next checkpoint, or
//! removed, afterwards changes nothing (burn's own file loaders read tensors lazily from the
//! path, so both used to reach into the new files, or fail on the missing ones).
mod common;

use dhrl::algos::{ActMode, AgentSpec, AlgoSettings, names, random_batch};
use dhrl::learn::{Devices, LearnDevice};

#[test]
fn a_loaded_agent_is_unaffected_by_its_folder_being_replaced_or_removed() {
    let devices = Devices::new(LearnDevice::Cpu).unwrap();
    for algo in names() {
        let mut settings = AlgoSettings::new(algo).unwrap();
        if settings.fields().contains_key("dropout") {
            // Dropout masks come from burn's process-wide generator, which the two agents
            // would draw from in turn: compared without dropout, the rest is deterministic.
            settings.set("dropout=0.0").unwrap();
        }
        let spec = AgentSpec {
            obs_dim: 4,
            act_dim: 2,
            delay: if settings.info().undelayed_only { 0 } else { 2 },
            action_low: vec![-1.0, -2.0],
            action_high: vec![1.0, 2.0],
        };
        let mut original = settings.build(&spec, &devices, 7).unwrap();
        let folder = tempfile::tempdir().unwrap();
        let saved = folder.path().join("checkpoint");
        std::fs::create_dir(&saved).unwrap();
        original.save(&saved).unwrap();
        let mut loaded = settings.build(&spec, &devices, 8).unwrap();
        loaded.load(&saved).unwrap();
        // The next checkpoint replaces every file (another agent's), then the folder goes.
        settings
            .build(&spec, &devices, 9)
            .unwrap()
            .save(&saved)
            .unwrap();
        std::fs::remove_dir_all(&saved).unwrap();
        for step in 0..3 {
            let batch = random_batch(&spec, 32, 100 + step);
            assert_eq!(
                common::update(original.as_mut(), &batch),
                common::update(loaded.as_mut(), &batch),
                "{algo}: update {step} of the saved agent and of the one loaded from it"
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
