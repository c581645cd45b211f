//! Integration tests of the finite-domain DHRL library (`dhrl::tabular`): the paper's section-3
//! guarantees (Prop. 3.3, Prop. 3.5, Cor. 3.4, Lemma 3.7), validation errors, JSON input, the
//! delayed environment, Q-learning, the benchmark and the CLI arguments.

use std::io::Write;
use std::path::Path;

use clap::Parser;
use dhrl_tabular::{
    AnalysisOptions, AugmentedMdp, BenchConfig, CHECK_TOLERANCE, DEFAULT_MAX_AUGMENTED_STATES,
    DelayedEnv, Environment, FiniteMdp, ModelEnv, Partition, QLearningConfig, QuotientMdp,
    RandomMdpSpec, SizeLimits, SolveOptions, TabularArgs, TabularBenchArgs, TabularError,
    TabularModel, analyze, approximate_belief_partition, belief_partition, check_homomorphism,
    evaluate_abstraction, evaluate_policy, q_learning, random_mdp, run_bench, run_tabular,
    run_tabular_bench, total_variation, value_iteration, value_loss_bound, write_bench_plot,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn deterministic(states: usize, actions: usize, seed: u64) -> FiniteMdp {
    random_mdp(&RandomMdpSpec {
        states,
        actions,
        gamma: 0.9,
        stochastic: 0.0,
        seed,
    })
    .expect("valid deterministic MDP")
}

fn stochastic(states: usize, actions: usize, mass: f64, seed: u64) -> FiniteMdp {
    random_mdp(&RandomMdpSpec {
        states,
        actions,
        gamma: 0.9,
        stochastic: mass,
        seed,
    })
    .expect("valid stochastic MDP")
}

fn augment(mdp: &FiniteMdp, delay: usize) -> AugmentedMdp {
    AugmentedMdp::new(mdp, delay, &SizeLimits::default()).expect("augmented MDP within limits")
}

fn precise() -> SolveOptions {
    SolveOptions {
        tolerance: 1e-12,
        ..SolveOptions::default()
    }
}

/// Two states, two actions, valid.
fn small_tables() -> (Vec<Vec<Vec<f64>>>, Vec<Vec<f64>>) {
    let transitions = vec![
        vec![vec![1.0, 0.0], vec![0.5, 0.5]],
        vec![vec![0.0, 1.0], vec![0.25, 0.75]],
    ];
    let rewards = vec![vec![1.0, 0.0], vec![0.5, 2.0]];
    (transitions, rewards)
}

/// Deterministic grids of (|S|, |A|, Δ) used by the proposition tests.
const GRID: [(usize, usize, usize); 7] = [
    (2, 2, 1),
    (5, 2, 3),
    (6, 3, 2),
    (7, 2, 4),
    (4, 1, 3),
    (3, 4, 0),
    (8, 2, 5),
];

// ---------------------------------------------------------------------------------------------
// JSON input and validation errors
// ---------------------------------------------------------------------------------------------

#[test]
fn parses_mdp_json_file_and_round_trips() {
    let text = r#"{"gamma": 0.9,
        "transitions": [[[1.0, 0.0], [0.5, 0.5]], [[0.0, 1.0], [0.25, 0.75]]],
        "rewards": [[1.0, 0.0], [0.5, 2.0]]}"#;
    let mut file = tempfile::NamedTempFile::new().expect("temporary file");
    file.write_all(text.as_bytes()).expect("write MDP file");
    let mdp = FiniteMdp::from_json_file(file.path()).expect("valid MDP file");
    assert_eq!(mdp.num_states(), 2);
    assert_eq!(mdp.num_actions(), 2);
    assert_eq!(mdp.gamma(), 0.9);
    assert_eq!(mdp.probability(1, 1, 1), 0.75);
    assert_eq!(mdp.probability(0, 0, 1), 0.0);
    assert_eq!(mdp.reward(1, 1), 2.0);
    assert!(!mdp.is_deterministic());
    let successors: Vec<(usize, f64)> = mdp.successors(0, 1).collect();
    assert_eq!(successors, vec![(0, 0.5), (1, 0.5)]);

    let json = serde_json::to_string(&mdp.to_file_format()).expect("serialisable");
    let again = FiniteMdp::from_json_str(&json).expect("round trip");
    assert_eq!(again.to_file_format(), mdp.to_file_format());
}

#[test]
fn malformed_json_and_missing_file_are_errors() {
    let missing_field = FiniteMdp::from_json_str(r#"{"gamma": 0.9, "rewards": [[0.0]]}"#);
    assert!(
        matches!(missing_field, Err(TabularError::Json { .. })),
        "{missing_field:?}"
    );
    let not_json = FiniteMdp::from_json_str("gamma = 0.9");
    let message = not_json.expect_err("not JSON").to_string();
    assert!(
        message.contains("transitions"),
        "message should show the accepted format: {message}"
    );
    let dir = tempfile::tempdir().expect("temporary directory");
    let absent = FiniteMdp::from_json_file(dir.path().join("absent.json"));
    assert!(matches!(absent, Err(TabularError::Io { .. })), "{absent:?}");
}

#[test]
fn row_sum_error_names_state_and_action() {
    let (mut transitions, rewards) = small_tables();
    transitions[1][0] = vec![0.5, 0.4];
    let error = FiniteMdp::new(0.9, &transitions, &rewards).expect_err("row sums to 0.9");
    match &error {
        TabularError::RowSum { state, action, sum } => {
            assert_eq!((*state, *action), (1, 0));
            assert!((sum - 0.9).abs() < 1e-12);
        }
        other => panic!("expected RowSum, got {other:?}"),
    }
    let message = error.to_string();
    assert!(
        message.contains("state 1") && message.contains("action 0"),
        "{message}"
    );
    assert!(
        message.contains("1e-9"),
        "message should say what is accepted: {message}"
    );
}

#[test]
fn negative_probability_is_rejected() {
    let (mut transitions, rewards) = small_tables();
    transitions[0][1] = vec![-0.25, 1.25];
    let error = FiniteMdp::new(0.9, &transitions, &rewards).expect_err("negative probability");
    match error {
        TabularError::InvalidProbability {
            state,
            action,
            next_state,
            value,
        } => {
            assert_eq!((state, action, next_state), (0, 1, 0));
            assert_eq!(value, -0.25);
        }
        other => panic!("expected InvalidProbability, got {other:?}"),
    }
}

#[test]
fn non_finite_reward_is_rejected() {
    for bad in [f64::NAN, f64::INFINITY] {
        let (transitions, mut rewards) = small_tables();
        rewards[1][1] = bad;
        let error = FiniteMdp::new(0.9, &transitions, &rewards).expect_err("bad reward");
        assert!(
            matches!(
                error,
                TabularError::InvalidReward {
                    state: 1,
                    action: 1,
                    ..
                }
            ),
            "{error:?}"
        );
        assert!(error.to_string().contains("finite"));
    }
}

#[test]
fn discount_outside_unit_interval_is_rejected() {
    let (transitions, rewards) = small_tables();
    for gamma in [1.0, 1.5, -0.1, f64::NAN] {
        let error = FiniteMdp::new(gamma, &transitions, &rewards).expect_err("bad gamma");
        assert!(
            matches!(error, TabularError::InvalidGamma { .. }),
            "{error:?}"
        );
        assert!(error.to_string().contains("0 <= gamma < 1"));
    }
    assert!(FiniteMdp::new(0.0, &transitions, &rewards).is_ok());
}

#[test]
fn shape_mismatches_are_rejected() {
    let location_of = |result: Result<FiniteMdp, TabularError>| match result {
        Err(TabularError::ShapeMismatch { location, .. }) => location,
        other => panic!("expected ShapeMismatch, got {other:?}"),
    };
    let (transitions, mut rewards) = small_tables();
    rewards.push(vec![0.0, 0.0]);
    assert_eq!(
        location_of(FiniteMdp::new(0.9, &transitions, &rewards)),
        "rewards"
    );

    let (mut transitions, rewards) = small_tables();
    transitions[1] = vec![vec![1.0, 0.0]];
    assert_eq!(
        location_of(FiniteMdp::new(0.9, &transitions, &rewards)),
        "transitions[1]"
    );

    let (mut transitions, rewards) = small_tables();
    transitions[0][0] = vec![1.0, 0.0, 0.0];
    assert_eq!(
        location_of(FiniteMdp::new(0.9, &transitions, &rewards)),
        "transitions[0][0]"
    );

    let (transitions, mut rewards) = small_tables();
    rewards[0] = vec![1.0];
    assert_eq!(
        location_of(FiniteMdp::new(0.9, &transitions, &rewards)),
        "rewards[0]"
    );

    assert!(matches!(
        FiniteMdp::new(0.9, &[], &[]),
        Err(TabularError::NoStates)
    ));
    let sparse = FiniteMdp::from_sparse(
        2,
        1,
        0.9,
        vec![vec![(0, 1.0)], vec![(5, 1.0)]],
        vec![0.0; 2],
    );
    assert!(matches!(
        sparse,
        Err(TabularError::InvalidNextState {
            state: 1,
            next_state: 5,
            ..
        })
    ));
}

#[test]
fn size_limit_is_refused_with_a_clear_error() {
    let mdp = deterministic(10, 4, 0);
    let error = AugmentedMdp::new(&mdp, 12, &SizeLimits::default()).expect_err("too large");
    match &error {
        TabularError::TooLarge {
            augmented_states,
            limit,
            delay,
            ..
        } => {
            assert_eq!(*augmented_states, 10 * 4u128.pow(12));
            assert_eq!(*limit, DEFAULT_MAX_AUGMENTED_STATES);
            assert_eq!(*delay, 12);
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    assert!(error.to_string().contains("exceeds the limit"));

    let small = SizeLimits {
        max_augmented_states: 100,
    };
    assert!(matches!(
        AugmentedMdp::new(&mdp, 2, &small),
        Err(TabularError::TooLarge { .. })
    ));
    assert_eq!(
        AugmentedMdp::new(&mdp, 1, &small)
            .expect("40 states fit")
            .num_states(),
        40
    );
    // An absurd delay saturates instead of overflowing.
    assert!(matches!(
        AugmentedMdp::new(&mdp, 10_000, &SizeLimits::default()),
        Err(TabularError::TooLarge { .. })
    ));
    let options = AnalysisOptions {
        limits: small,
        ..AnalysisOptions::default()
    };
    assert!(matches!(
        analyze(&mdp, 3, &options),
        Err(TabularError::TooLarge { .. })
    ));
}

#[test]
fn invalid_epsilon_and_generator_settings_are_rejected() {
    let model = augment(&stochastic(3, 2, 0.2, 1), 1);
    for epsilon in [1.0, -0.1, f64::NAN] {
        let result = approximate_belief_partition(&model, epsilon);
        assert!(
            matches!(
                result,
                Err(TabularError::InvalidParameter {
                    name: "epsilon",
                    ..
                })
            ),
            "{result:?}"
        );
    }
    let single = random_mdp(&RandomMdpSpec {
        states: 1,
        actions: 2,
        gamma: 0.9,
        stochastic: 0.1,
        seed: 0,
    });
    assert!(matches!(
        single,
        Err(TabularError::InvalidParameter {
            name: "stochastic",
            ..
        })
    ));
    let too_much = random_mdp(&RandomMdpSpec {
        states: 3,
        actions: 2,
        gamma: 0.9,
        stochastic: 1.5,
        seed: 0,
    });
    assert!(matches!(
        too_much,
        Err(TabularError::InvalidParameter {
            name: "stochastic",
            ..
        })
    ));
}

// ---------------------------------------------------------------------------------------------
// Augmented MDP
// ---------------------------------------------------------------------------------------------

#[test]
fn augmented_mdp_matches_definitions() {
    let mdp = stochastic(4, 3, 0.3, 7);
    let model = augment(&mdp, 2);
    assert_eq!(model.num_states(), 4 * 9);
    for x in 0..model.num_states() {
        let (state, actions) = model.decode(x).expect("in range");
        assert_eq!(model.encode(state, &actions).expect("valid history"), x);

        // Belief by rolling P forward densely.
        let mut belief = vec![0.0; 4];
        belief[state] = 1.0;
        for &action in &actions {
            let mut next = vec![0.0; 4];
            for (from, mass) in belief.iter().enumerate() {
                for (to, slot) in next.iter_mut().enumerate() {
                    *slot += mass * mdp.probability(from, action, to);
                }
            }
            belief = next;
        }
        let mut sparse_as_dense = vec![0.0; 4];
        for &(s, p) in &model.belief(x).expect("in range") {
            sparse_as_dense[s] = p;
        }
        for (a, b) in sparse_as_dense.iter().zip(&belief) {
            assert!((a - b).abs() < 1e-12);
        }

        for action in 0..3 {
            let expected: f64 = belief
                .iter()
                .enumerate()
                .map(|(s, p)| p * mdp.reward(s, action))
                .sum();
            assert!((model.reward(x, action) - expected).abs() < 1e-12);
            let total: f64 = model.successors(x, action).map(|(_, p)| p).sum();
            assert!((total - 1.0).abs() < 1e-9);
            for (y, p) in model.successors(x, action) {
                let (next_state, next_actions) = model.decode(y).expect("in range");
                assert_eq!(next_actions, vec![actions[1], action]);
                assert_eq!(p, mdp.probability(state, actions[0], next_state));
            }
        }
    }

    let mut visited = Vec::new();
    model.for_each_belief(|x, belief| visited.push((x, belief.to_vec())));
    assert_eq!(visited.len(), model.num_states());
    for (index, (x, belief)) in visited.iter().enumerate() {
        assert_eq!(*x, index);
        assert!(total_variation(belief, &model.belief(*x).expect("in range")) < 1e-12);
    }

    assert!(matches!(
        model.encode(0, &[0]),
        Err(TabularError::ShapeMismatch { .. })
    ));
    assert!(matches!(
        model.encode(0, &[0, 3]),
        Err(TabularError::IndexOutOfRange { .. })
    ));
    assert!(matches!(
        model.decode(36),
        Err(TabularError::IndexOutOfRange { .. })
    ));
}

#[test]
fn zero_delay_is_the_base_mdp() {
    let mdp = stochastic(5, 2, 0.4, 3);
    let model = augment(&mdp, 0);
    assert_eq!(model.num_states(), 5);
    for x in 0..5 {
        assert_eq!(model.belief(x).expect("in range"), vec![(x, 1.0)]);
        for action in 0..2 {
            assert_eq!(model.reward(x, action), mdp.reward(x, action));
            let ours: Vec<(usize, f64)> = model.successors(x, action).collect();
            let base: Vec<(usize, f64)> = mdp.successors(x, action).collect();
            assert_eq!(ours, base);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Prop. 3.3: deterministic ⇒ reward-respecting and SSP; a stochastic counter-example
// ---------------------------------------------------------------------------------------------

#[test]
fn prop_3_3_deterministic_belief_partition_is_reward_respecting_and_ssp() {
    for seed in 0..12 {
        for (states, actions, delay) in GRID {
            let model = augment(&deterministic(states, actions, seed), delay);
            let partition = belief_partition(&model);
            let check =
                check_homomorphism(&model, &partition, CHECK_TOLERANCE).expect("sizes match");
            assert!(
                check.reward_respecting && check.ssp,
                "seed {seed}, {states}/{actions}/{delay}: {check:?}"
            );
            assert_eq!(check.max_reward_difference, 0.0);
            assert_eq!(check.max_transition_difference, 0.0);
        }
    }
}

/// Seven states, two actions, delay 2. `x1 = (0, a0, a0)` and `x2 = (1, a0, a0)` share the belief
/// `½δ5 + ½δ6`, but from `x1` the next belief is `δ5` or `δ6` while from `x2` it stays
/// `½δ5 + ½δ6`, so the belief partition violates the SSP.
fn ssp_counter_example() -> FiniteMdp {
    let rows = vec![
        vec![(2, 0.5), (3, 0.5)],
        vec![(0, 1.0)],
        vec![(4, 1.0)],
        vec![(1, 1.0)],
        vec![(5, 1.0)],
        vec![(2, 1.0)],
        vec![(6, 1.0)],
        vec![(3, 1.0)],
        vec![(5, 0.5), (6, 0.5)],
        vec![(4, 1.0)],
        vec![(5, 1.0)],
        vec![(5, 1.0)],
        vec![(6, 1.0)],
        vec![(6, 1.0)],
    ];
    let rewards = (0..14)
        .map(|i| (i / 2) as f64 * 0.1 + (i % 2) as f64)
        .collect();
    FiniteMdp::from_sparse(7, 2, 0.9, rows, rewards).expect("valid counter-example")
}

#[test]
fn prop_3_3_fails_under_stochastic_dynamics() {
    let mdp = ssp_counter_example();
    let model = augment(&mdp, 2);
    let partition = belief_partition(&model);
    let x1 = model.encode(0, &[0, 0]).expect("valid");
    let x2 = model.encode(1, &[0, 0]).expect("valid");
    assert_eq!(model.belief(x1).expect("valid"), vec![(5, 0.5), (6, 0.5)]);
    assert_eq!(partition.block_of(x1), partition.block_of(x2));

    let check = check_homomorphism(&model, &partition, CHECK_TOLERANCE).expect("sizes match");
    assert!(
        check.reward_respecting,
        "equal beliefs always give equal expected rewards"
    );
    assert!(!check.ssp);
    assert!(
        (check.max_transition_difference - 1.0).abs() < 1e-12,
        "{check:?}"
    );

    let report = analyze(&mdp, 2, &AnalysisOptions::default()).expect("small problem");
    assert!(!report.deterministic);
    assert!(report.reward_respecting);
    assert!(!report.ssp);
}

// ---------------------------------------------------------------------------------------------
// Prop. 3.5 and Cor. 3.4
// ---------------------------------------------------------------------------------------------

#[test]
fn prop_3_5_compression_under_deterministic_dynamics() {
    for seed in 0..12 {
        for (states, actions, delay) in GRID {
            let model = augment(&deterministic(states, actions, seed), delay);
            let partition = belief_partition(&model);
            assert!(partition.num_blocks() <= states);
            let bound = 1.0 / (actions as f64).powi(delay as i32);
            assert!(partition.compression_ratio() <= bound + 1e-15);
            assert_eq!(
                partition.compression_ratio(),
                partition.num_blocks() as f64 / model.num_states() as f64
            );
        }
    }
}

#[test]
fn cor_3_4_abstract_values_match_and_lifted_policy_is_optimal() {
    let options = AnalysisOptions {
        solve: precise(),
        ..AnalysisOptions::default()
    };
    for seed in 0..10 {
        for (states, actions, delay) in GRID {
            let mdp = deterministic(states, actions, seed);
            let report = analyze(&mdp, delay, &options).expect("small problem");
            assert!(report.deterministic && report.reward_respecting && report.ssp);
            assert!(report.max_value_gap < 1e-8, "{report:?}");
            assert!(report.lifted_policy_value_loss < 1e-8, "{report:?}");
            assert!(report.abstract_states <= states);
        }
    }
}

#[test]
fn deterministic_abstract_mdp_is_the_delay_free_mdp() {
    let mdp = deterministic(6, 3, 2);
    let model = augment(&mdp, 3);
    let base = value_iteration(&mdp, &precise()).expect("converges");
    let augmented = value_iteration(&model, &precise()).expect("converges");
    for x in 0..model.num_states() {
        let belief = model.belief(x).expect("in range");
        assert_eq!(belief.len(), 1, "deterministic beliefs are Dirac");
        assert!((augmented.values[x] - base.values[belief[0].0]).abs() < 1e-8);
    }
}

// ---------------------------------------------------------------------------------------------
// Lemma 3.7 on stochastic MDPs
// ---------------------------------------------------------------------------------------------

#[test]
fn epsilon_zero_is_the_exact_partition() {
    let model = augment(&stochastic(5, 2, 0.3, 9), 3);
    let exact = belief_partition(&model);
    assert_eq!(
        approximate_belief_partition(&model, 0.0).expect("valid"),
        exact
    );
    let coarse = approximate_belief_partition(&model, 0.5).expect("valid");
    assert!(coarse.num_blocks() <= exact.num_blocks());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn lemma_3_7_measured_loss_is_within_the_bound(
        seed in 0u64..1_000_000,
        states in 2usize..7,
        actions in 1usize..4,
        delay in 0usize..4,
        mass in 0.05f64..0.5,
        epsilon in 0.0f64..0.6,
        gamma in 0.5f64..0.95,
    ) {
        let mdp = random_mdp(&RandomMdpSpec { states, actions, gamma, stochastic: mass, seed })
            .expect("valid MDP");
        let model = augment(&mdp, delay);
        let partition = approximate_belief_partition(&model, epsilon).expect("valid epsilon");

        // The ε-abstract partition: pairwise TV distance within every block.
        for block in 0..partition.num_blocks() {
            let beliefs: Vec<_> = partition
                .members(block)
                .iter()
                .map(|&x| model.belief(x).expect("in range"))
                .collect();
            for (i, a) in beliefs.iter().enumerate() {
                for b in &beliefs[i + 1..] {
                    prop_assert!(total_variation(a, b) <= epsilon + 1e-9);
                }
            }
        }

        let optimal = value_iteration(&model, &precise()).expect("converges");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let weights: Vec<f64> = (0..model.num_states()).map(|_| 0.1 + rng.random::<f64>()).collect();
        let uniform = QuotientMdp::new(&model, &partition).expect("consistent");
        let weighted = QuotientMdp::with_weights(&model, &partition, &weights).expect("valid weights");
        for quotient in [&uniform, &weighted] {
            let bound = value_loss_bound(&model, quotient).expect("consistent");
            let quality = evaluate_abstraction(&model, &optimal.values, quotient, &precise())
                .expect("converges");
            prop_assert!(bound.c2 <= 2.0 + 1e-12);
            prop_assert!(
                quality.lifted_policy_value_loss <= bound.bound + 1e-7,
                "loss {} > bound {} ({:?})",
                quality.lifted_policy_value_loss,
                bound.bound,
                bound
            );
        }
    }
}

#[test]
fn quotient_rejects_bad_weights_and_policies() {
    let model = augment(&stochastic(3, 2, 0.2, 4), 1);
    let partition = belief_partition(&model);
    let n = model.num_states();
    assert!(matches!(
        QuotientMdp::with_weights(&model, &partition, &vec![1.0; n - 1]),
        Err(TabularError::ShapeMismatch { .. })
    ));
    let mut negative = vec![1.0; n];
    negative[2] = -1.0;
    assert!(matches!(
        QuotientMdp::with_weights(&model, &partition, &negative),
        Err(TabularError::InvalidParameter { .. })
    ));
    let quotient = QuotientMdp::new(&model, &partition).expect("consistent");
    assert!(matches!(
        quotient.lift_policy(&[0]),
        Err(TabularError::ShapeMismatch { .. })
    ));
    let too_big = vec![2; partition.num_blocks()];
    assert!(matches!(
        quotient.lift_policy(&too_big),
        Err(TabularError::IndexOutOfRange { .. })
    ));
    let lifted = quotient
        .lift_policy(&vec![1; partition.num_blocks()])
        .expect("valid policy");
    assert_eq!(lifted, vec![1; n]);
    assert_eq!(quotient.action_map(1), 1);
    let other = Partition::discrete(n + 1);
    assert!(matches!(
        QuotientMdp::new(&model, &other),
        Err(TabularError::ShapeMismatch { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Delayed environment, Q-learning and the benchmark
// ---------------------------------------------------------------------------------------------

#[test]
fn delayed_env_shows_the_delayed_state_and_action_history() {
    let mdp = deterministic(5, 3, 4);
    let model = augment(&mdp, 3);
    let mut env = DelayedEnv::new(&model);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let first = env.reset(&mut rng);
    let true_state = env.true_state().expect("reset");
    assert_eq!(
        model.belief(first).expect("in range"),
        vec![(true_state, 1.0)]
    );
    let (mut observed, mut history) = model.decode(first).expect("in range");
    for step in 0..30 {
        let action = step % 3;
        let current = env.true_state().expect("reset");
        let (reward, observation) = env.step(action, &mut rng);
        assert_eq!(reward, mdp.reward(current, action));
        let (next_observed, next_history) = model.decode(observation).expect("in range");
        let mut expected_history = history[1..].to_vec();
        expected_history.push(action);
        assert_eq!(next_history, expected_history);
        let expected_state = mdp
            .successors(observed, history[0])
            .next()
            .expect("one successor")
            .0;
        assert_eq!(next_observed, expected_state);
        let now = env.true_state().expect("reset");
        assert_eq!(
            model.belief(observation).expect("in range"),
            vec![(now, 1.0)]
        );
        observed = next_observed;
        history = next_history;
    }
}

#[test]
fn q_learning_finds_a_near_optimal_policy_of_a_small_mdp() {
    let mdp = deterministic(4, 2, 3);
    let options = SolveOptions::default();
    let optimal = value_iteration(&mdp, &options).expect("converges");
    let mut env = ModelEnv::new(&mdp);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let config = QLearningConfig {
        exploration: 0.5,
        episode_length: 20,
        max_samples: 200_000,
        check_every: 1_000,
    };
    let partition = Partition::discrete(mdp.num_states());
    let run = q_learning(&mut env, &partition, &config, &mut rng, |q| {
        let values = evaluate_policy(&mdp, &q.greedy_policy(), None, &options)?;
        Ok(optimal
            .values
            .iter()
            .zip(&values)
            .all(|(best, value)| best - value <= 0.05))
    })
    .expect("valid settings");
    let reached = run
        .reached_at
        .expect("Q-learning reaches a 0.05-optimal greedy policy");
    assert_eq!(reached % config.check_every, 0);
    assert_eq!(run.samples, reached);
    assert_eq!(run.q.num_states(), 4);

    let bad = QLearningConfig {
        exploration: 1.5,
        ..config
    };
    let result = q_learning(&mut env, &partition, &bad, &mut rng, |_| Ok(false));
    assert!(matches!(
        result,
        Err(TabularError::InvalidParameter {
            name: "exploration",
            ..
        })
    ));
}

#[test]
fn bench_compares_both_learners_and_writes_an_svg() {
    let config = BenchConfig {
        states: 4,
        actions: 2,
        gamma: 0.9,
        min_delay: 0,
        max_delay: 2,
        seeds: 2,
        tolerance: 0.5,
        learning: QLearningConfig {
            exploration: 0.3,
            episode_length: 20,
            max_samples: 30_000,
            check_every: 250,
        },
        limits: SizeLimits::default(),
    };
    let report = run_bench(&config).expect("valid settings");
    assert_eq!(report.rows.len(), 3);
    for row in &report.rows {
        assert_eq!(row.augmented_states, 4 * 2usize.pow(row.delay as u32));
        assert!(row.abstract_states_mean <= 4.0);
        for stats in [&row.augmented, &row.abstraction] {
            assert_eq!(stats.runs, 2);
            assert_eq!(stats.samples.len(), 2);
            assert_eq!(stats.reached, stats.samples.iter().flatten().count());
            assert_eq!(stats.mean.is_some(), stats.reached > 0);
            for samples in stats.samples.iter().flatten() {
                assert!(*samples <= 30_000 && samples % 250 == 0);
            }
        }
    }
    // With Δ = 0 the belief partition is the identity, so both learners make the same run.
    assert_eq!(
        report.rows[0].augmented.samples,
        report.rows[0].abstraction.samples
    );

    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("bench.svg");
    write_bench_plot(&report, &path).expect("writable");
    let svg = std::fs::read_to_string(&path).expect("written");
    assert!(svg.contains("<svg"));
    let json = serde_json::to_value(&report).expect("serialisable");
    assert!(json["rows"][0]["abstract"]["samples"].is_array());
    assert!(report.to_table().contains("abstract Q: samples"));

    let reversed = BenchConfig {
        min_delay: 3,
        max_delay: 1,
        ..config
    };
    assert!(matches!(
        run_bench(&reversed),
        Err(TabularError::InvalidParameter {
            name: "min_delay",
            ..
        })
    ));
}

// ---------------------------------------------------------------------------------------------
// Report and CLI
// ---------------------------------------------------------------------------------------------

#[test]
fn report_json_has_the_documented_keys() {
    let mdp = stochastic(4, 2, 0.2, 1);
    let plain = analyze(&mdp, 2, &AnalysisOptions::default()).expect("small problem");
    let value = serde_json::to_value(&plain).expect("serialisable");
    for key in [
        "augmented_states",
        "abstract_states",
        "compression_ratio",
        "reward_respecting",
        "ssp",
        "max_value_gap",
        "lifted_policy_value_loss",
    ] {
        assert!(value.get(key).is_some(), "missing {key}");
    }
    assert!(value.get("value_loss_bound").is_none());
    assert_eq!(value["augmented_states"], 16);
    // Prop. 3.5 holds under deterministic dynamics only: the key is there, but null.
    assert!(!plain.deterministic);
    assert_eq!(plain.compression_bound, None);
    assert!(value["compression_bound"].is_null(), "{value}");
    assert!(plain.to_table().contains("n/a (stochastic dynamics"));
    let exact =
        analyze(&deterministic(4, 2, 1), 2, &AnalysisOptions::default()).expect("small problem");
    assert_eq!(exact.compression_bound, Some(0.25));
    let value = serde_json::to_value(&exact).expect("serialisable");
    assert_eq!(value["compression_bound"].as_f64(), Some(0.25));

    let options = AnalysisOptions {
        epsilon: Some(0.2),
        ..AnalysisOptions::default()
    };
    let with_epsilon = analyze(&mdp, 2, &options).expect("small problem");
    let value = serde_json::to_value(&with_epsilon).expect("serialisable");
    let bound = value["value_loss_bound"].as_f64().expect("bound present");
    let loss = value["approx_lifted_policy_value_loss"]
        .as_f64()
        .expect("loss present");
    assert!(loss <= bound + 1e-7);
    assert!(with_epsilon.to_table().contains("Lemma 3.7"));
}

#[derive(Parser, Debug)]
struct TabularCli {
    #[command(flatten)]
    args: TabularArgs,
}

#[test]
fn tabular_cli_needs_exactly_one_source() {
    assert!(TabularCli::try_parse_from(["tabular", "--delay", "2"]).is_err());
    assert!(
        TabularCli::try_parse_from([
            "tabular",
            "--mdp",
            "m.json",
            "--random",
            "--states",
            "3",
            "--actions",
            "2",
            "--delay",
            "1",
        ])
        .is_err()
    );
    assert!(
        TabularCli::try_parse_from([
            "tabular", "--mdp", "m.json", "--states", "3", "--delay", "1"
        ])
        .is_err()
    );
    let random = TabularCli::try_parse_from([
        "tabular",
        "--random",
        "--states",
        "3",
        "--actions",
        "2",
        "--delay",
        "1",
        "--seed",
        "4",
        "--stochastic",
        "0.2",
        "--epsilon",
        "0.1",
        "--json",
    ])
    .expect("valid arguments");
    assert!(random.args.random && random.args.json);
    assert_eq!(random.args.states, Some(3));
    assert_eq!(random.args.stochastic, Some(0.2));
    assert_eq!(
        random.args.max_augmented_states,
        DEFAULT_MAX_AUGMENTED_STATES
    );
    let file = TabularCli::try_parse_from(["tabular", "--mdp", "m.json", "--delay", "0"])
        .expect("valid arguments");
    assert_eq!(file.args.mdp.as_deref(), Some(Path::new("m.json")));
}

#[test]
fn run_tabular_handles_file_and_random_sources() {
    let mdp = deterministic(4, 2, 8);
    let mut file = tempfile::NamedTempFile::new().expect("temporary file");
    let json = serde_json::to_string(&mdp.to_file_format()).expect("serialisable");
    file.write_all(json.as_bytes()).expect("write MDP file");
    let path = file.path().to_str().expect("UTF-8 path").to_string();

    let from_file = TabularCli::try_parse_from([
        "tabular",
        "--mdp",
        path.as_str(),
        "--delay",
        "2",
        "--epsilon",
        "0.1",
        "--json",
    ])
    .expect("valid arguments");
    run_tabular(&from_file.args).expect("analysis of a valid file");

    let random = TabularCli::try_parse_from([
        "tabular",
        "--random",
        "--states",
        "4",
        "--actions",
        "2",
        "--delay",
        "2",
    ])
    .expect("valid arguments");
    run_tabular(&random.args).expect("analysis of a random MDP");

    let missing =
        TabularCli::try_parse_from(["tabular", "--random", "--states", "4", "--delay", "1"])
            .expect("parses; the missing --actions is reported when running");
    let error = run_tabular(&missing.args).expect_err("--actions missing");
    assert!(error.to_string().contains("--actions"));
}

// ---------------------------------------------------------------------------------------------
// Hand-computed examples: Lemma 3.7, the ε-partition, the homomorphism checks
// ---------------------------------------------------------------------------------------------

/// Three states, two actions, `γ = ½`:
///
/// | (s, a)  | P(·|s, a)        | R(s, a) |
/// |---------|------------------|---------|
/// | (0, a0) | 0 w.p. 1         | 1       |
/// | (0, a1) | 0, 2 w.p. ½ each | 0       |
/// | (1, a0) | 1, 2 w.p. ½ each | 0       |
/// | (1, a1) | 1 w.p. 1         | 3       |
/// | (2, ·)  | 2 w.p. 1         | ¼       |
fn lemma_3_7_example() -> FiniteMdp {
    let rows = vec![
        vec![(0, 1.0)],
        vec![(0, 0.5), (2, 0.5)],
        vec![(1, 0.5), (2, 0.5)],
        vec![(1, 1.0)],
        vec![(2, 1.0)],
        vec![(2, 1.0)],
    ];
    let rewards = vec![1.0, 0.0, 0.0, 3.0, 0.25, 0.25];
    FiniteMdp::from_sparse(3, 2, 0.5, rows, rewards).expect("valid example")
}

/// Lemma 3.7 on `lemma_3_7_example` with the partition `A = {0, 1}`, `B = {2}` and uniform
/// weights, every number by hand:
///
/// * Quotient: `R̄(A, a0) = (1 + 0)/2 = ½`, `R̄(A, a1) = (0 + 3)/2 = 3/2`, `R̄(B, ·) = ¼`.
///   Block transitions: `(0, a0) → A:1`, `(1, a0) → A:½ B:½`, so `P̄(·|A, a0) = (¾, ¼)`;
///   `(0, a1) → A:½ B:½`, `(1, a1) → A:1`, so `P̄(·|A, a1) = (¾, ¼)`; `P̄(B|B, ·) = 1`.
/// * `C1 = max |R − R̄|`: `(0,a0) ½, (0,a1) 3/2, (1,a0) ½, (1,a1) 3/2, (2,·) 0`, so `C1 = 3/2`.
/// * `C2 = max L1`: `(0,a0) |1−¾| + |0−¼| = ½`, likewise `½` for the other three pairs of `A`
///   and `0` for state 2, so `C2 = ½`.
/// * `ξ = max R̄ − min R̄ = 3/2 − ¼ = 5/4`.
/// * Bound `= 2/(1−γ)·(C1 + γ ξ C2 / (2(1−γ))) = 4·(3/2 + ½·5/4·½/1) = 4·(3/2 + 5/16) = 29/4`.
/// * `V*`: state 2: `¼/(1−½) = ½`; state 1: `a1` forever, `3/(1−½) = 6` (`a0` gives
///   `½(½·6 + ½·½) = 13/8`); state 0: `a0` forever, `1/(1−½) = 2` (`a1` gives `½(½·2 + ½·½) = 5/8`).
/// * Abstract: `V̄(B) = ½`; the rows of `a0` and `a1` agree, so `a1` (reward 3/2) wins:
///   `V̄(A) = 3/2 + ½(¾ V̄(A) + ¼·½)`, `V̄(A) = 5/2`.
/// * Lifted policy `a1` in states 0 and 1: `V(0) = ½(½ V(0) + ½·½)`, `V(0) = 1/6`; `V(1) = 6`;
///   `V(2) = ½`. Value loss `2 − 1/6 = 11/6` (at state 0), value gap
///   `max(|2 − 5/2|, |6 − 5/2|, |½ − ½|) = 7/2` (at state 1).
#[test]
fn lemma_3_7_terms_match_a_hand_computed_example() {
    let mdp = lemma_3_7_example();
    let partition = Partition::from_labels(&[0, 0, 1]);
    assert_eq!(partition.num_blocks(), 2);
    let quotient = QuotientMdp::new(&mdp, &partition).expect("consistent");
    let abstract_mdp = quotient.abstract_mdp();
    assert_eq!(abstract_mdp.reward(0, 0), 0.5);
    assert_eq!(abstract_mdp.reward(0, 1), 1.5);
    assert_eq!(abstract_mdp.reward(1, 0), 0.25);
    assert_eq!(abstract_mdp.reward(1, 1), 0.25);
    for action in 0..2 {
        let row: Vec<(usize, f64)> = abstract_mdp.successors(0, action).collect();
        assert_eq!(row, vec![(0, 0.75), (1, 0.25)]);
        let row: Vec<(usize, f64)> = abstract_mdp.successors(1, action).collect();
        assert_eq!(row, vec![(1, 1.0)]);
    }

    let bound = value_loss_bound(&mdp, &quotient).expect("consistent");
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    assert!(close(bound.c1, 1.5), "{bound:?}");
    assert!(close(bound.c2, 0.5), "{bound:?}");
    assert!(close(bound.xi, 1.25), "{bound:?}");
    assert_eq!(bound.gamma, 0.5);
    assert!(close(bound.bound, 7.25), "{bound:?}");

    let optimal = value_iteration(&mdp, &precise()).expect("converges");
    for (value, expected) in optimal.values.iter().zip([2.0, 6.0, 0.5]) {
        assert!((value - expected).abs() < 1e-9, "{:?}", optimal.values);
    }
    assert_eq!(&optimal.policy[..2], &[0, 1]);
    let abstract_solution = value_iteration(abstract_mdp, &precise()).expect("converges");
    assert!((abstract_solution.values[0] - 2.5).abs() < 1e-9);
    assert!((abstract_solution.values[1] - 0.5).abs() < 1e-9);
    assert_eq!(abstract_solution.policy[0], 1);
    let lifted = quotient
        .lift_policy(&abstract_solution.policy)
        .expect("valid policy");
    assert_eq!(&lifted[..2], &[1, 1]);

    let quality =
        evaluate_abstraction(&mdp, &optimal.values, &quotient, &precise()).expect("converges");
    assert!(
        (quality.lifted_policy_value_loss - 11.0 / 6.0).abs() < 1e-9,
        "{quality:?}"
    );
    assert!((quality.max_value_gap - 3.5).abs() < 1e-9, "{quality:?}");
    assert!(quality.lifted_policy_value_loss > 1.0 && quality.max_value_gap > 1.0);
    assert!(quality.lifted_policy_value_loss <= bound.bound);
}

/// Two states, one action, `γ = ½`: `P(·|0) = (0.6, 0.4)`, `P(·|1) = (½, ½)`, `R = (1, 0)`.
/// With delay 1, `x0 = (0, a0)` and `x1 = (1, a0)` have beliefs `(0.6, 0.4)` and `(½, ½)`, at
/// total-variation distance `½(0.1 + 0.1) = 0.1`.
fn near_beliefs_mdp() -> FiniteMdp {
    FiniteMdp::new(
        0.5,
        &[vec![vec![0.6, 0.4]], vec![vec![0.5, 0.5]]],
        &[vec![1.0], vec![0.0]],
    )
    .expect("valid MDP")
}

#[test]
fn epsilon_partition_merges_beliefs_closer_than_epsilon() {
    let model = augment(&near_beliefs_mdp(), 1);
    assert_eq!(model.num_states(), 2);
    let (x0, x1) = (
        model.encode(0, &[0]).expect("valid"),
        model.encode(1, &[0]).expect("valid"),
    );
    let (b0, b1) = (
        model.belief(x0).expect("valid"),
        model.belief(x1).expect("valid"),
    );
    assert_ne!(b0, b1);
    let distance = total_variation(&b0, &b1);
    assert!((distance - 0.1).abs() < 1e-12, "{distance}");

    let exact = belief_partition(&model);
    assert_ne!(exact.block_of(x0), exact.block_of(x1));
    assert_eq!(exact.num_blocks(), 2);
    let merged = approximate_belief_partition(&model, 0.2).expect("valid epsilon");
    assert_eq!(merged.block_of(x0), merged.block_of(x1), "TV 0.1 <= 0.2");
    assert_eq!(merged.num_blocks(), 1);
    let apart = approximate_belief_partition(&model, 0.05).expect("valid epsilon");
    assert_ne!(apart.block_of(x0), apart.block_of(x1), "TV 0.1 > 0.05");
}

/// Lemma 3.7 through `analyze` on `near_beliefs_mdp` at delay 1 with ε = 0.2 (one block), by
/// hand:
///
/// * `R_Δ(x0) = 0.6·1 + 0.4·0 = 0.6`, `R_Δ(x1) = ½`; `P_Δ(·|x0) = (0.6, 0.4)`,
///   `P_Δ(·|x1) = (½, ½)` (the next augmented state is `(s', a0)`).
/// * Quotient (one block, uniform weights): `R̄ = 0.55`, `P̄ = 1`, so `V̄ = 0.55/(1−½) = 1.1`.
/// * `C1 = max(|0.6 − 0.55|, |0.5 − 0.55|) = 0.05`, `C2 = 0` (one block), `ξ = 0` (one abstract
///   reward), bound `= 2/(1−½)·0.05 = 0.2`.
/// * `V*`: `V0 = 0.6 + ½(0.6 V0 + 0.4 V1)`, `V1 = ½ + ½(½ V0 + ½ V1)` give `V0 = 22/19`,
///   `V1 = 20/19`; the value gap is `max(22/19 − 11/10, 11/10 − 20/19) = 11/190`.
/// * One action, so the lifted policy is optimal: loss 0.
#[test]
fn lemma_3_7_epsilon_abstraction_of_a_delayed_mdp_by_hand() {
    let options = AnalysisOptions {
        epsilon: Some(0.2),
        solve: precise(),
        ..AnalysisOptions::default()
    };
    let report = analyze(&near_beliefs_mdp(), 1, &options).expect("small problem");
    assert_eq!(report.augmented_states, 2);
    assert_eq!(report.abstract_states, 2);
    assert!(report.max_value_gap < 1e-9 && report.lifted_policy_value_loss < 1e-9);
    let approximate = report.approximate.expect("epsilon requested");
    assert_eq!(approximate.approx_abstract_states, 1);
    assert_eq!(approximate.approx_compression_ratio, 0.5);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    assert!(close(approximate.c1, 0.05), "{approximate:?}");
    assert!(close(approximate.c2, 0.0), "{approximate:?}");
    assert!(close(approximate.xi, 0.0), "{approximate:?}");
    assert!(close(approximate.value_loss_bound, 0.2), "{approximate:?}");
    assert!(
        close(approximate.approx_max_value_gap, 11.0 / 190.0),
        "{approximate:?}"
    );
    assert!(approximate.approx_lifted_policy_value_loss < 1e-9);
}

/// Three states, one action: `0 → 2`, `1 → 0`, `2 → 2`, rewards `(1, 0, 0)`.
fn mixed_reward_mdp() -> FiniteMdp {
    let rows = vec![vec![(2, 1.0)], vec![(0, 1.0)], vec![(2, 1.0)]];
    FiniteMdp::from_sparse(3, 1, 0.9, rows, vec![1.0, 0.0, 0.0]).expect("valid MDP")
}

#[test]
fn partitions_mixing_rewards_are_not_reward_respecting() {
    let mdp = mixed_reward_mdp();
    let check = |labels: &[usize]| {
        check_homomorphism(&mdp, &Partition::from_labels(labels), CHECK_TOLERANCE)
            .expect("sizes match")
    };

    // {0, 2} | {1}: rewards 1 and 0 share a block; both members move into their own block.
    let mixed = check(&[0, 1, 0]);
    assert!(!mixed.reward_respecting, "{mixed:?}");
    assert!(mixed.ssp, "{mixed:?}");
    assert_eq!(mixed.max_reward_difference, 1.0);
    assert_eq!(mixed.max_transition_difference, 0.0);
    let quotient = QuotientMdp::new(&mdp, &Partition::from_labels(&[0, 1, 0])).expect("consistent");
    assert_eq!(quotient.abstract_mdp().reward(0, 0), 0.5);

    // {0} | {1, 2}: equal rewards, but 1 moves to {0} and 2 stays in {1, 2}.
    let split = check(&[0, 1, 1]);
    assert!(split.reward_respecting, "{split:?}");
    assert!(!split.ssp, "{split:?}");
    assert_eq!(split.max_reward_difference, 0.0);
    assert_eq!(split.max_transition_difference, 1.0);

    // {0, 1} | {2}: different rewards and different block transitions.
    let neither = check(&[0, 0, 1]);
    assert!(!neither.reward_respecting && !neither.ssp, "{neither:?}");

    let discrete = check(&[0, 1, 2]);
    assert!(discrete.reward_respecting && discrete.ssp, "{discrete:?}");
}

#[test]
fn reward_check_tolerance_is_relative_to_the_reward_scale() {
    // Two absorbing states in one block: the SSP holds, only the rewards differ.
    let respecting = |r0: f64, r1: f64| {
        let mdp = FiniteMdp::from_sparse(
            2,
            1,
            0.9,
            vec![vec![(0, 1.0)], vec![(1, 1.0)]],
            vec![r0, r1],
        )
        .expect("valid MDP");
        let check = check_homomorphism(&mdp, &Partition::from_labels(&[0, 0]), CHECK_TOLERANCE)
            .expect("sizes match");
        assert!(check.ssp);
        check.reward_respecting
    };
    // 1e-4 apart at scale 1e6: within 1e-9·1e6 = 1e-3.
    assert!(respecting(1e6, 1e6 + 1e-4));
    // 1e-4 apart at scale 1: not within 1e-9.
    assert!(!respecting(1.0, 1.0 + 1e-4));
    // Small rewards keep the absolute floor 1e-9·max(1, ·) = 1e-9.
    assert!(respecting(1e-3, 1e-3 + 5e-10));
    assert!(!respecting(1e-3, 1e-3 + 1e-8));
}

// ---------------------------------------------------------------------------------------------
// Sizes, solver limits and input shapes
// ---------------------------------------------------------------------------------------------

#[test]
fn random_source_is_refused_before_it_is_generated() {
    let run = |extra: &[&str]| {
        let mut argv = vec!["tabular", "--random"];
        argv.extend_from_slice(extra);
        let cli = TabularCli::try_parse_from(argv).expect("valid arguments");
        // Generating first would need |S|·|A| = 10^10 transition rows, far beyond this
        // machine's memory: an error here means the size was refused before generation.
        // (How fast the refusal is: benches/tabular.rs.)
        run_tabular(&cli.args).expect_err("too large")
    };
    let error = run(&["--states", "100000000", "--actions", "100", "--delay", "0"]);
    match error.downcast_ref::<TabularError>() {
        Some(TabularError::TooLarge {
            states,
            actions,
            delay,
            augmented_states,
            limit,
        }) => {
            assert_eq!((*states, *actions, *delay), (100_000_000, 100, 0));
            assert_eq!(*augmented_states, 100_000_000);
            assert_eq!(*limit, DEFAULT_MAX_AUGMENTED_STATES);
        }
        other => panic!("expected TooLarge, got {other:?} ({error})"),
    }
    let error = run(&["--states", "1000", "--actions", "100", "--delay", "3"]);
    assert!(
        matches!(
            error.downcast_ref::<TabularError>(),
            Some(TabularError::TooLarge {
                augmented_states: 1_000_000_000,
                ..
            })
        ),
        "{error}"
    );
    // Within a huge limit the table sizes overflow: checked, not wrapped.
    let max = usize::MAX.to_string();
    let error = run(&[
        "--states",
        max.as_str(),
        "--actions",
        "2",
        "--delay",
        "0",
        "--max-augmented-states",
        max.as_str(),
    ]);
    assert!(
        matches!(
            error.downcast_ref::<TabularError>(),
            Some(TabularError::TableTooLarge { .. })
        ),
        "{error}"
    );

    // The generator itself checks |S|·|A| and its allocation.
    for (states, actions) in [(usize::MAX, 2), (1 << 40, 1 << 20)] {
        let result = random_mdp(&RandomMdpSpec {
            states,
            actions,
            gamma: 0.9,
            stochastic: 0.0,
            seed: 0,
        });
        assert!(
            matches!(result, Err(TabularError::TableTooLarge { .. })),
            "{result:?}"
        );
    }
}

#[test]
fn solver_names_gamma_when_it_needs_too_many_sweeps() {
    let single =
        |gamma: f64| FiniteMdp::new(gamma, &[vec![vec![1.0]]], &[vec![1.0]]).expect("valid MDP");
    // γ = 0.999999 from a first change of 1 to the default tolerance 1e-10 needs
    // ln(1e-10·1e-6)/ln(0.999999) ≈ 3.7e7 sweeps, above the default limit of 1e6: stop at once.
    let slow = single(0.999_999);
    let errors = [
        value_iteration(&slow, &SolveOptions::default()).expect_err("too slow"),
        evaluate_policy(&slow, &[0], None, &SolveOptions::default()).expect_err("too slow"),
    ];
    for error in errors {
        match &error {
            TabularError::NotConverged {
                iterations,
                limit,
                needed,
                gamma,
                ..
            } => {
                assert_eq!(*iterations, 1);
                assert_eq!(*limit, 1_000_000);
                assert!((36_000_000..38_000_000).contains(needed), "{error}");
                assert_eq!(*gamma, 0.999_999);
            }
            other => panic!("expected NotConverged, got {other:?}"),
        }
        let message = error.to_string();
        assert!(message.contains("gamma = 0.999999"), "{message}");
        assert!(message.contains("smaller gamma"), "{message}");
    }

    // γ = 0.999 needs about ln(1e-13)/ln(0.999) ≈ 3e4 sweeps: allowed, and V = 1/(1−γ) = 1000.
    let fine = single(0.999);
    let solution = value_iteration(&fine, &SolveOptions::default()).expect("converges");
    assert!(
        (solution.values[0] - 1000.0).abs() < 1e-5,
        "{:?}",
        solution.values
    );
    assert!(solution.iterations < 60_000);

    // A limit below the estimate is refused after the first sweep too.
    let tight = SolveOptions {
        max_iterations: 100,
        ..SolveOptions::default()
    };
    let error = value_iteration(&single(0.9), &tight).expect_err("needs about 240 sweeps");
    assert!(
        matches!(
            error,
            TabularError::NotConverged {
                iterations: 1,
                limit: 100,
                ..
            }
        ),
        "{error:?}"
    );
}

#[test]
fn missing_actions_of_state_zero_is_a_shape_mismatch() {
    let transitions = vec![vec![], vec![vec![0.0, 1.0]]];
    let rewards = vec![vec![], vec![0.0]];
    match FiniteMdp::new(0.9, &transitions, &rewards) {
        Err(TabularError::ShapeMismatch {
            location,
            found,
            expected,
            ..
        }) => {
            assert_eq!(location, "transitions[0]");
            assert_eq!((found, expected), (0, 1));
        }
        other => panic!("expected ShapeMismatch, got {other:?}"),
    }
    let none: Vec<Vec<Vec<f64>>> = vec![vec![], vec![]];
    let no_rewards: Vec<Vec<f64>> = vec![vec![], vec![]];
    assert!(matches!(
        FiniteMdp::new(0.9, &none, &no_rewards),
        Err(TabularError::NoActions)
    ));
}

#[test]
fn bench_checks_the_largest_delay_before_any_run() {
    // With room for 4·2^7 = 512 augmented states, a bench that ran the delays in order would
    // stop at Δ = 8 (1,024 states); refusing Δ = 30 means the largest was checked first.
    let config = BenchConfig {
        states: 4,
        actions: 2,
        min_delay: 0,
        max_delay: 30,
        limits: SizeLimits {
            max_augmented_states: 1000,
        },
        ..BenchConfig::default()
    };
    let result = run_bench(&config);
    assert!(
        matches!(result, Err(TabularError::TooLarge { delay: 30, .. })),
        "{result:?}"
    );
}

#[derive(Parser, Debug)]
struct TabularBenchCli {
    #[command(flatten)]
    args: TabularBenchArgs,
}

#[test]
fn bench_cli_reports_an_unwritable_plot_path() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let blocker = dir.path().join("not-a-directory");
    std::fs::write(&blocker, "x").expect("write file");
    let out = blocker.join("plot.svg");
    let out = out.to_str().expect("UTF-8 path").to_string();
    let cli = TabularBenchCli::try_parse_from([
        "tabular-bench",
        "--states",
        "3",
        "--min-delay",
        "0",
        "--max-delay",
        "1",
        "--seeds",
        "1",
        "--max-samples",
        "2000",
        "--check-every",
        "500",
        "--tolerance",
        "0.5",
        "--json",
        "--out",
        out.as_str(),
    ])
    .expect("valid arguments");
    let error = run_tabular_bench(&cli.args).expect_err("unwritable plot path");
    assert!(
        matches!(
            error.downcast_ref::<TabularError>(),
            Some(TabularError::Plot { .. })
        ),
        "{error}"
    );
}
