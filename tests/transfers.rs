//! What a learner moves between the host and its device. On a GPU every crossing is a transfer
//! and a synchronisation, so an update uploads only its sampled batches and the noise drawn on
//! the host and downloads nothing; the statistics of many updates come down in one download
//! when a log row is written; acting is one input upload (with its noise) and one download for
//! the whole stack. And a stack of runs moves what one run moves: its runs share each transfer.
//!
//! Counted at dhrl's boundary (`learn::upload`, `learn::to_vec`, through which every learner's
//! host data passes), the same count on every device, so this runs on the CPU. The counters are
//! the process's: this file holds one test, so that no other test counts alongside it.
use dhrl::algos::{ActMode, AgentSpec, AlgoSettings, Stats, UpdateContext, names, random_batch};
use dhrl::learn::{Devices, LearnDevice, Transfers, transfers};

/// The transfers of `updates` updates of a stack of `runs` runs, of downloading all their
/// statistics, and of acting once for every run (`Explore` and `Deterministic`).
fn count(
    settings: &AlgoSettings,
    spec: &AgentSpec,
    runs: usize,
    updates: u64,
) -> (Transfers, Transfers, Transfers, Transfers) {
    let devices = Devices::new(LearnDevice::Cpu).unwrap();
    let seeds: Vec<u64> = (0..runs as u64).collect();
    let mut agent = settings.build_stack(spec, &devices, &seeds);
    let batches: Vec<_> = (0..runs)
        .map(|run| random_batch(spec, 16, run as u64))
        .collect();
    let before = transfers();
    let stats: Vec<Stats> = (1..=updates)
        .map(|k| {
            // A thousand environment steps an update: every stage on a schedule runs.
            let mut contexts: Vec<UpdateContext> = batches
                .iter()
                .map(|batch| UpdateContext::fixed(batch, 1000 * k, k))
                .collect();
            agent.update_runs(&mut contexts).unwrap()
        })
        .collect();
    let updating = transfers() - before;

    let before = transfers();
    let values = Stats::download(&stats);
    let downloading = transfers() - before;
    assert_eq!(values.len(), updates as usize);
    assert!(values.iter().all(|update| update.len() == runs));

    let rows = 4;
    let augmented: Vec<f32> = (0..runs * rows * spec.augmented_dim())
        .map(|i| (i as f32 * 0.13).sin())
        .collect();
    let counts: Vec<usize> = (0..runs).map(|run| rows - run % 2).collect();
    let mut acting = [Transfers::default(); 2];
    for (moved, mode) in acting
        .iter_mut()
        .zip([ActMode::Explore, ActMode::Deterministic])
    {
        let before = transfers();
        let actions = agent.act_runs(&augmented, &counts, rows, mode);
        *moved = transfers() - before;
        assert_eq!(actions.len(), runs * rows * spec.act_dim);
    }
    (updating, downloading, acting[0], acting[1])
}

#[test]
fn updates_upload_their_batches_download_nothing_and_a_stack_moves_what_one_run_moves() {
    let updates = 3;
    for algo in names() {
        let mut settings = AlgoSettings::new(algo).unwrap();
        if algo == "vdpo" {
            // Small, with its cloning stage in every update.
            for assignment in ["belief_width=16", "bc_every=1000", "bc_updates=2"] {
                settings.set(assignment).unwrap();
            }
        }
        let spec = AgentSpec {
            obs_dim: 3,
            act_dim: 2,
            delay: if settings.info().undelayed_only { 0 } else { 2 },
            action_low: vec![-1.0, -2.0],
            action_high: vec![1.0, 2.0],
        };
        let one = count(&settings, &spec, 1, updates);
        let (updating, downloading, explore, deterministic) = one;
        println!(
            "{algo}: {} uploads an update, {} statistics download for {updates} updates; acting \
             {} up and {} down (explore), {} up and {} down (deterministic)",
            updating.uploads as f64 / updates as f64,
            downloading.downloads,
            explore.uploads,
            explore.downloads,
            deterministic.uploads,
            deterministic.downloads
        );
        assert_eq!(updating.downloads, 0, "{algo}: an update downloads nothing");
        assert!(updating.uploads > 0, "{algo}: an update uploads its batch");
        assert_eq!(
            downloading,
            Transfers {
                uploads: 0,
                downloads: 1
            },
            "{algo}: the statistics of {updates} updates in one download"
        );
        assert_eq!(
            explore.downloads, 1,
            "{algo}: acting downloads the actions once"
        );
        assert_eq!(deterministic.downloads, 1, "{algo}");
        assert!(
            explore.uploads > deterministic.uploads,
            "{algo}: exploring uploads its noise besides the states"
        );
        assert_eq!(
            count(&settings, &spec, 3, updates),
            one,
            "{algo}: a stack of three runs moves what one run moves"
        );
    }
}
