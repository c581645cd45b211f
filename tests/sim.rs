//! The batched simulator: layout, seeding, automatic resets, time limit and actuator noise.
use dhrl::sim::{BatchConfig, BatchedEnv, MAX_EPISODE_STEPS};
use dhrl::tasks::TaskName;

fn batch(
    task: TaskName,
    envs: usize,
    threads: usize,
    seed: u64,
    actuator_noise: f64,
) -> BatchedEnv {
    BatchedEnv::new(&BatchConfig {
        task,
        envs,
        threads,
        seed,
        actuator_noise,
    })
    .unwrap()
}

fn constant_actions(env: &BatchedEnv, value: f32) -> Vec<f32> {
    vec![value; env.len() * env.act_dim()]
}

#[test]
fn arrays_are_contiguous_rows_per_copy() {
    for task in TaskName::ALL {
        let env = batch(task, 3, 1, 0, 0.0);
        assert_eq!(env.observations().len(), 3 * task.def().obs_dim, "{task}");
        assert_eq!(
            env.final_observations().len(),
            3 * task.def().obs_dim,
            "{task}"
        );
        assert_eq!(env.rewards().len(), 3);
        assert_eq!(env.terminated().len(), 3);
        assert_eq!(env.truncated().len(), 3);
    }
}

#[test]
fn observation_dimensions_match_the_paper() {
    let dims: Vec<usize> = TaskName::ALL.iter().map(|t| t.def().obs_dim).collect();
    assert_eq!(dims, vec![27, 17, 11, 17, 376, 4]);
}

#[test]
fn seeds_make_runs_reproducible_whatever_the_thread_count() {
    let mut one = batch(TaskName::Hopper, 16, 1, 42, 0.1);
    let mut two = batch(TaskName::Hopper, 16, 2, 42, 0.1);
    let mut other = batch(TaskName::Hopper, 16, 2, 43, 0.1);
    assert_eq!(one.observations(), two.observations());
    assert_ne!(one.observations(), other.observations());
    let actions = constant_actions(&one, 0.3);
    for _ in 0..60 {
        one.step(&actions).unwrap();
        two.step(&actions).unwrap();
        other.step(&actions).unwrap();
        assert_eq!(one.observations(), two.observations());
        assert_eq!(one.rewards(), two.rewards());
        assert_eq!(one.terminated(), two.terminated());
    }
    // Copies draw from separate streams: their reset states differ.
    let d = TaskName::Hopper.def().obs_dim;
    assert_ne!(&one.observations()[..d], &one.observations()[d..2 * d]);
}

#[test]
fn finished_copies_reset_and_keep_their_final_observation() {
    // Pushing the cart hard makes the pole fall within a few dozen steps.
    let mut env = batch(TaskName::InvertedPendulum, 8, 2, 1, 0.0);
    let actions = constant_actions(&env, 3.0);
    let mut steps = vec![0u32; 8];
    let mut finished = 0;
    for _ in 0..200 {
        env.step(&actions).unwrap();
        for i in 0..8 {
            steps[i] += 1;
            if env.terminated()[i] == 1 {
                let final_obs = &env.final_observations()[i * 4..i * 4 + 4];
                let new_obs = &env.observations()[i * 4..i * 4 + 4];
                assert!(
                    final_obs[1].abs() > 0.2,
                    "terminal pole angle {}",
                    final_obs[1]
                );
                assert!(
                    new_obs.iter().all(|v| v.abs() <= 0.01),
                    "reset state {new_obs:?}"
                );
                assert_eq!(env.episode_lengths()[i], steps[i]);
                assert_eq!(
                    env.episode_returns()[i],
                    steps[i] as f32,
                    "reward 1 per step"
                );
                steps[i] = 0;
                finished += 1;
            }
        }
    }
    assert!(finished >= 8, "only {finished} episodes ended");
}

#[test]
fn time_limit_truncates_at_1000_steps() {
    let mut env = batch(TaskName::HalfCheetah, 2, 2, 5, 0.0);
    let actions = constant_actions(&env, 0.0);
    for step in 1..=MAX_EPISODE_STEPS {
        env.step(&actions).unwrap();
        let expected = u32::from(step == MAX_EPISODE_STEPS);
        assert_eq!(env.truncated(), &[expected, expected], "step {step}");
        assert_eq!(env.terminated(), &[0, 0]);
    }
    assert_eq!(
        env.episode_lengths(),
        &[MAX_EPISODE_STEPS, MAX_EPISODE_STEPS]
    );
}

#[test]
fn actuator_noise_changes_the_executed_action_only() {
    let mut clean = batch(TaskName::HalfCheetah, 4, 1, 9, 0.0);
    let mut noisy = batch(TaskName::HalfCheetah, 4, 1, 9, 0.5);
    assert_eq!(
        clean.observations(),
        noisy.observations(),
        "same reset states"
    );
    let actions = constant_actions(&clean, 0.2);
    clean.step(&actions).unwrap();
    noisy.step(&actions).unwrap();
    assert_ne!(clean.observations(), noisy.observations());
    // Huge noise is clipped to the action bounds, so the physics stays finite and the
    // control cost within 0.1·6·1².
    let mut wild = batch(TaskName::HalfCheetah, 4, 1, 9, 1e6);
    let zero = constant_actions(&wild, 0.0);
    for _ in 0..3 {
        wild.step(&zero).unwrap();
        for &r in wild.rewards() {
            assert!(r.is_finite() && r.abs() < 50.0, "reward {r}");
        }
    }
}

#[test]
fn bad_configurations_are_clear_errors() {
    let err = |c: BatchConfig| BatchedEnv::new(&c).err().expect("an error").to_string();
    let base = BatchConfig {
        task: TaskName::Hopper,
        envs: 2,
        threads: 1,
        seed: 0,
        actuator_noise: 0.0,
    };
    assert!(
        err(BatchConfig {
            envs: 0,
            ..base.clone()
        })
        .contains("environment copies")
    );
    assert!(
        err(BatchConfig {
            threads: 0,
            ..base.clone()
        })
        .contains("threads")
    );
    assert!(
        err(BatchConfig {
            actuator_noise: -1.0,
            ..base.clone()
        })
        .contains("actuator noise")
    );
    let mut env = BatchedEnv::new(&base).unwrap();
    let msg = env.step(&[0.0; 5]).unwrap_err().to_string();
    assert!(msg.contains("length 5, expected 6"), "{msg}");
}

#[test]
fn unknown_task_names_list_the_valid_ones() {
    let msg = "halfcheetah".parse::<TaskName>().unwrap_err().to_string();
    assert!(msg.contains("unknown task 'halfcheetah'"), "{msg}");
    for task in TaskName::ALL {
        assert!(msg.contains(task.as_str()), "{msg}");
        assert_eq!(task.as_str().parse::<TaskName>().unwrap(), task);
    }
}

/// The float mode (src/float_mode.rs): on in every simulation and learner pool thread, set on a
/// caller's thread only for as long as a guard lives, and the caller's own mode back after it.
#[test]
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
fn pool_threads_flush_subnormals_and_a_caller_thread_gets_its_mode_back() {
    use dhrl::float_mode::{FlushGuard, enabled, flushing, subnormal_product_is_zero};
    let on = enabled();
    let env = batch(TaskName::HalfCheetah, 4, 2, 0, 0.0);
    assert_eq!(env.workers_flush_subnormals(), vec![on; 2]);
    let learners = dhrl::train::learner_pool(2).unwrap();
    assert_eq!(
        learners.broadcast(|_| (flushing(), subnormal_product_is_zero())),
        vec![(on, on); 2]
    );
    // The test harness's thread is not dhrl's: it starts in the default mode.
    assert!(!flushing() && !subnormal_product_is_zero());
    {
        let _mode = FlushGuard::new();
        assert_eq!(subnormal_product_is_zero(), on);
        // One copy steps on this thread, and leaves its mode as it found it.
        let mut one = batch(TaskName::HalfCheetah, 1, 1, 0, 0.0);
        one.step(&constant_actions(&one, 0.1)).unwrap();
        assert_eq!(subnormal_product_is_zero(), on);
    }
    assert!(!flushing() && !subnormal_product_is_zero());
}
