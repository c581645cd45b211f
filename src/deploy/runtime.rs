//! `DelayedPolicy`: acting under delay outside dhrl's training loop. Fed each delayed
//! observation `s_τ` as it arrives, it keeps the actions it chose, builds
//! `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})` exactly as training did, executes the warm-up rule for
//! the first Δ decisions of an episode, and asks its policy for `a_t` after that. Random
//! delays are the conservative agent's: an observation that arrives early waits until it is
//! exactly Δ old. python/dhrl/deploy.py is the same runtime over onnxruntime.
use std::collections::{BTreeMap, VecDeque};

use super::manifest::PolicyManifest;
use crate::delay::{WarmupActions, WarmupFiller};

/// What chooses `a_t` from `x_t` (one row).
pub trait ActionSource {
    fn action(&mut self, augmented_state: &[f32]) -> Vec<f32>;
}

impl<F: FnMut(&[f32]) -> Vec<f32>> ActionSource for F {
    fn action(&mut self, augmented_state: &[f32]) -> Vec<f32> {
        self(augmented_state)
    }
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RuntimeError {
    #[error(
        "the observation has {found} values; the policy takes {expected} (the task's observation size)"
    )]
    ObservationSize { found: usize, expected: usize },
    #[error(
        "the observation of step {emitted_at} holds a non-finite value at index {index}; only finite numbers are accepted"
    )]
    NonFinite { emitted_at: usize, index: usize },
    #[error(
        "the observation of step {emitted_at} arrived at decision {t}, after it was needed (at decision {needed}): its delay is above the policy's Δ = {delay}"
    )]
    TooLate {
        emitted_at: usize,
        t: usize,
        needed: usize,
        delay: usize,
    },
    #[error(
        "the observation of step {emitted_at} cannot have arrived before decision {t} (observations of steps 0..={t} can)"
    )]
    FromTheFuture { emitted_at: usize, t: usize },
    #[error("the observation of step {0} arrived twice")]
    Duplicate(usize),
    #[error(
        "decision {t} needs the observation of step {needed} (Δ = {delay}), which has not arrived: observe it first (its delay may be at most Δ)"
    )]
    MissingObservation {
        t: usize,
        needed: usize,
        delay: usize,
    },
    #[error("the policy returned {found} values, expected {expected} (the action size)")]
    ActionSize { found: usize, expected: usize },
}

/// The delay-aware runtime around an [`ActionSource`].
pub struct DelayedPolicy<P> {
    policy: P,
    obs_dim: usize,
    act_dim: usize,
    delay: usize,
    warmup: WarmupFiller,
    /// Decisions taken in this episode: the index `t` of the next one.
    t: usize,
    /// `a_{t−Δ}, …, a_{t−1}` (fewer during the warm-up), oldest first.
    recent_actions: VecDeque<Vec<f32>>,
    /// Observations that arrived and are not yet Δ old, by the step they show.
    waiting: BTreeMap<usize, Vec<f32>>,
}

impl<P: ActionSource> DelayedPolicy<P> {
    /// The runtime for the policy `manifest` describes, with the manifest's warm-up rule (a
    /// random warm-up draws as training's delay layer does, from a ChaCha8 stream seeded with
    /// `seed`).
    pub fn new(manifest: &PolicyManifest, policy: P, seed: u64) -> DelayedPolicy<P> {
        DelayedPolicy {
            policy,
            obs_dim: manifest.observation_dim,
            act_dim: manifest.action_dim,
            delay: manifest.delay.total,
            warmup: WarmupFiller::new(
                manifest.warmup.rule,
                &manifest.action_low,
                &manifest.action_high,
                seed,
            ),
            t: 0,
            recent_actions: VecDeque::new(),
            waiting: BTreeMap::new(),
        }
    }

    /// The same runtime with another warm-up rule (e.g. zeros where the run drew random ones).
    pub fn with_warmup(mut self, warmup: WarmupActions) -> DelayedPolicy<P> {
        self.warmup.set_kind(warmup);
        self
    }

    /// Starts a new episode: forgets the actions and the observations not yet used.
    pub fn reset(&mut self) {
        self.t = 0;
        self.recent_actions.clear();
        self.waiting.clear();
    }

    /// The policy the runtime asks.
    pub fn policy_mut(&mut self) -> &mut P {
        &mut self.policy
    }

    /// The index `t` of the next decision in this episode.
    pub fn decision(&self) -> usize {
        self.t
    }

    /// Takes the observation of the state at step `emitted_at` of this episode (`s_τ`), as it
    /// arrives, in any order.
    pub fn observe(&mut self, emitted_at: usize, observation: &[f32]) -> Result<(), RuntimeError> {
        if observation.len() != self.obs_dim {
            return Err(RuntimeError::ObservationSize {
                found: observation.len(),
                expected: self.obs_dim,
            });
        }
        if let Some(index) = observation.iter().position(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFinite { emitted_at, index });
        }
        if emitted_at > self.t {
            return Err(RuntimeError::FromTheFuture {
                emitted_at,
                t: self.t,
            });
        }
        let needed = emitted_at + self.delay;
        if needed < self.t {
            return Err(RuntimeError::TooLate {
                emitted_at,
                t: self.t,
                needed,
                delay: self.delay,
            });
        }
        if self.waiting.contains_key(&emitted_at) {
            return Err(RuntimeError::Duplicate(emitted_at));
        }
        self.waiting.insert(emitted_at, observation.to_vec());
        Ok(())
    }

    /// `x_t` for the next decision, once `s_{t−Δ}` has arrived (`None` during the warm-up or
    /// while it is missing).
    pub fn augmented_state(&self) -> Option<Vec<f32>> {
        let observation = self.waiting.get(&self.t.checked_sub(self.delay)?)?;
        let mut x = observation.clone();
        for action in &self.recent_actions {
            x.extend_from_slice(action);
        }
        Some(x)
    }

    /// Decides `a_t`: the warm-up action for `t < Δ`, else the policy's action on `x_t`.
    /// The action is remembered for the `x` of the next Δ decisions.
    pub fn act(&mut self) -> Result<Vec<f32>, RuntimeError> {
        let action = if self.t < self.delay {
            self.warmup_action()
        } else {
            let needed = self.t - self.delay;
            let x = self
                .augmented_state()
                .ok_or(RuntimeError::MissingObservation {
                    t: self.t,
                    needed,
                    delay: self.delay,
                })?;
            let action = self.policy.action(&x);
            if action.len() != self.act_dim {
                return Err(RuntimeError::ActionSize {
                    found: action.len(),
                    expected: self.act_dim,
                });
            }
            self.waiting.remove(&needed);
            action
        };
        if self.delay > 0 {
            if self.recent_actions.len() == self.delay {
                self.recent_actions.pop_front();
            }
            self.recent_actions.push_back(action.clone());
        }
        self.t += 1;
        Ok(action)
    }

    fn warmup_action(&mut self) -> Vec<f32> {
        let mut action = vec![0.0; self.act_dim];
        self.warmup
            .fill(&mut action, &[0])
            .expect("one row of the action size");
        action
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deploy::manifest::{
        AugmentedStateLayout, DelayManifest, FilesManifest, NetworkManifest, RunManifest,
        WarmupManifest,
    };

    /// Observations of 2 entries, actions of 1 in [−2, 2], Δ = `delay`.
    fn manifest(delay: usize, warmup: WarmupActions) -> PolicyManifest {
        PolicyManifest {
            format: super::super::FORMAT.into(),
            format_version: super::super::FORMAT_VERSION,
            algorithm: String::new(),
            paper_name: String::new(),
            task: String::new(),
            gymnasium_id: String::new(),
            observation_dim: 2,
            action_dim: 1,
            action_low: vec![-2.0],
            action_high: vec![2.0],
            delay: DelayManifest {
                observation_delay: delay,
                action_delay: 0,
                random: false,
                max_random_delay: None,
                total: delay,
                actuator_noise: 0.0,
            },
            augmented_state: AugmentedStateLayout::new(2, 1, delay),
            warmup: WarmupManifest {
                rule: warmup,
                steps: delay,
            },
            observation_normalisation: None,
            network: NetworkManifest {
                kind: String::new(),
                log_std_bounds: [-20.0, 2.0],
                attention_heads: None,
                model_predicts_difference: None,
                parameters: Vec::new(),
            },
            files: FilesManifest {
                onnx: String::new(),
                onnx_opset: 17,
                onnx_input: String::new(),
                onnx_outputs: Vec::new(),
                safetensors: String::new(),
                check: String::new(),
            },
            run: RunManifest {
                path: String::new(),
                seed: 0,
                steps: 0,
                dhrl_version: String::new(),
            },
        }
    }

    /// A policy that returns the sum of its input.
    fn summing() -> impl FnMut(&[f32]) -> Vec<f32> {
        |x: &[f32]| vec![x.iter().sum()]
    }

    #[test]
    fn builds_x_t_from_the_observation_delta_old_and_the_actions_since() {
        let mut policy = DelayedPolicy::new(&manifest(2, WarmupActions::Zeros), summing(), 0);
        // Warm-up: decisions 0 and 1 are zeros, and need no observation.
        assert_eq!(policy.act().unwrap(), vec![0.0]);
        policy.observe(0, &[1.0, 2.0]).unwrap();
        assert_eq!(policy.augmented_state(), None, "t = 1 < Δ");
        assert_eq!(policy.act().unwrap(), vec![0.0]);
        // t = 2: x = (s_0, a_0, a_1) = (1, 2, 0, 0).
        assert_eq!(policy.augmented_state(), Some(vec![1.0, 2.0, 0.0, 0.0]));
        assert_eq!(policy.act().unwrap(), vec![3.0]);
        // t = 3: x = (s_1, a_1, a_2) = (10, 20, 0, 3).
        policy.observe(1, &[10.0, 20.0]).unwrap();
        assert_eq!(policy.augmented_state(), Some(vec![10.0, 20.0, 0.0, 3.0]));
        assert_eq!(policy.act().unwrap(), vec![33.0]);
        assert_eq!(policy.decision(), 4);
    }

    #[test]
    fn random_delays_out_of_order_wait_until_delta_old() {
        let mut policy = DelayedPolicy::new(&manifest(3, WarmupActions::Zeros), summing(), 0);
        policy.act().unwrap();
        policy.observe(1, &[5.0, 5.0]).unwrap(); // s_1 arrives before s_0
        policy.act().unwrap();
        policy.observe(0, &[1.0, 1.0]).unwrap();
        policy.observe(2, &[7.0, 7.0]).unwrap();
        policy.act().unwrap();
        // t = 3 uses s_0 although s_1 and s_2 are newer.
        assert_eq!(policy.augmented_state().unwrap()[..2], [1.0, 1.0]);
        policy.act().unwrap();
        assert_eq!(policy.augmented_state().unwrap()[..2], [5.0, 5.0]);
    }

    #[test]
    fn reset_starts_a_new_warm_up_and_forgets_what_waited() {
        let mut policy = DelayedPolicy::new(&manifest(1, WarmupActions::Zeros), summing(), 0);
        policy.act().unwrap();
        policy.observe(0, &[1.0, 1.0]).unwrap();
        assert_eq!(policy.act().unwrap(), vec![2.0]);
        policy.observe(1, &[4.0, 4.0]).unwrap();
        policy.reset();
        assert_eq!(policy.decision(), 0);
        assert_eq!(policy.augmented_state(), None);
        assert_eq!(policy.act().unwrap(), vec![0.0], "a warm-up again");
        assert_eq!(
            policy.act(),
            Err(RuntimeError::MissingObservation {
                t: 1,
                needed: 0,
                delay: 1
            }),
            "the old episode's s_1 is gone"
        );
    }

    #[test]
    fn random_warm_up_lies_within_the_bounds_and_repeats_per_seed() {
        let draws = |seed| {
            let mut policy =
                DelayedPolicy::new(&manifest(20, WarmupActions::Random), summing(), seed);
            (0..20)
                .map(|_| policy.act().unwrap()[0])
                .collect::<Vec<f32>>()
        };
        let first = draws(3);
        assert!(first.iter().all(|a| (-2.0..=2.0).contains(a)));
        assert!(first.iter().any(|a| a.abs() > 0.5), "{first:?}");
        assert_eq!(first, draws(3));
        assert_ne!(first, draws(4));
    }

    #[test]
    fn refuses_what_the_delay_model_rules_out() {
        let mut policy = DelayedPolicy::new(&manifest(2, WarmupActions::Zeros), summing(), 0);
        assert_eq!(
            policy.observe(0, &[1.0]),
            Err(RuntimeError::ObservationSize {
                found: 1,
                expected: 2
            })
        );
        assert_eq!(
            policy.observe(0, &[1.0, f32::NAN]),
            Err(RuntimeError::NonFinite {
                emitted_at: 0,
                index: 1
            })
        );
        assert_eq!(
            policy.observe(1, &[1.0, 1.0]),
            Err(RuntimeError::FromTheFuture {
                emitted_at: 1,
                t: 0
            })
        );
        policy.observe(0, &[1.0, 1.0]).unwrap();
        assert_eq!(
            policy.observe(0, &[9.0, 9.0]),
            Err(RuntimeError::Duplicate(0))
        );
        policy.act().unwrap();
        policy.act().unwrap();
        assert_eq!(
            policy.augmented_state().unwrap()[..2],
            [1.0, 1.0],
            "the first copy stays"
        );
        policy.act().unwrap();
        assert_eq!(
            policy.act(),
            Err(RuntimeError::MissingObservation {
                t: 3,
                needed: 1,
                delay: 2
            })
        );
        assert_eq!(
            policy.observe(0, &[1.0, 1.0]),
            Err(RuntimeError::TooLate {
                emitted_at: 0,
                t: 3,
                needed: 2,
                delay: 2
            })
        );
        let mut wrong = DelayedPolicy::new(
            &manifest(0, WarmupActions::Zeros),
            |_: &[f32]| vec![1.0, 2.0],
            0,
        );
        wrong.observe(0, &[1.0, 1.0]).unwrap();
        assert_eq!(
            wrong.act(),
            Err(RuntimeError::ActionSize {
                found: 2,
                expected: 1
            })
        );
        assert_eq!(
            wrong.augmented_state(),
            Some(vec![1.0, 1.0]),
            "a failed decision keeps its observation for a retry"
        );
    }

    #[test]
    fn without_delay_x_t_is_the_current_observation() {
        let mut policy = DelayedPolicy::new(&manifest(0, WarmupActions::Zeros), summing(), 0);
        policy.observe(0, &[1.0, 2.0]).unwrap();
        assert_eq!(policy.act().unwrap(), vec![3.0]);
        policy.observe(1, &[2.0, 2.0]).unwrap();
        assert_eq!(policy.act().unwrap(), vec![4.0]);
    }
}
