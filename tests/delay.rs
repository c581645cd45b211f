//! The delay layer against its contract (docs/DESIGN.md §1), on the CPU reference and on the GPU.
use std::collections::BTreeMap;

use dhrl::delay::{
    BatchExtras, CpuDelayLayer, DelayConfig, DelayDevice, DelayError, DelayLayer, DelayedBatch,
    GpuDelayLayer, MAX_DELAY, RecordBatch, ReplayStore, StepInput, Transitions, WarmupActions,
};
use dhrl::sim::{BatchConfig, BatchedEnv, CopyStep};
use dhrl::tasks::TaskName;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A synthetic undelayed batch: states are `[copy, episode, step, k]`-coded numbers so any
/// mix-up shows; episode lengths and ends (terminated or truncated) come from a seeded RNG.
struct FakeBatch {
    obs_dim: usize,
    act_dim: usize,
    episode_len: Vec<u32>,
    episode: Vec<u32>,
    t: Vec<u32>,
    rng: ChaCha8Rng,
    max_len: u32,
}

/// What a fake batch step produced, in the arrays [`StepInput`] borrows.
struct FakeStep {
    observations: Vec<f32>,
    final_observations: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<u32>,
    truncated: Vec<u32>,
}

impl FakeStep {
    fn input<'a>(&'a self, actions: &'a [f32]) -> StepInput<'a> {
        StepInput {
            actions,
            observations: &self.observations,
            final_observations: &self.final_observations,
            rewards: &self.rewards,
            terminated: &self.terminated,
            truncated: &self.truncated,
            controls: None,
        }
    }
}

/// The true process of one copy, logged undelayed: per episode, the states, actions, rewards
/// and how it ended.
#[derive(Default, Clone, Debug)]
struct Episode {
    states: Vec<Vec<f32>>,
    actions: Vec<Vec<f32>>,
    rewards: Vec<f32>,
    terminated: bool,
    truncated: bool,
}

impl FakeBatch {
    fn new(copies: usize, obs_dim: usize, act_dim: usize, max_len: u32, seed: u64) -> FakeBatch {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let episode_len = (0..copies).map(|_| rng.random_range(1..=max_len)).collect();
        FakeBatch {
            obs_dim,
            act_dim,
            episode_len,
            episode: vec![0; copies],
            t: vec![0; copies],
            rng,
            max_len,
        }
    }

    fn state(&self, copy: usize, episode: u32, t: u32) -> Vec<f32> {
        (0..self.obs_dim)
            .map(|k| (copy * 1_000_000 + episode as usize * 10_000 + t as usize * 10 + k) as f32)
            .collect()
    }

    fn initial(&self) -> Vec<f32> {
        (0..self.episode.len())
            .flat_map(|c| self.state(c, 0, 0))
            .collect()
    }

    /// The undelayed log, one list of episodes per copy, each starting with its `s_0`.
    fn new_log(&self) -> Vec<Vec<Episode>> {
        (0..self.episode.len())
            .map(|c| {
                vec![Episode {
                    states: vec![self.state(c, 0, 0)],
                    ..Episode::default()
                }]
            })
            .collect()
    }

    /// Steps every copy with `actions`; returns the StepInput arrays and logs into `log`.
    fn step(&mut self, actions: &[f32], log: &mut [Vec<Episode>]) -> FakeStep {
        let n = self.episode.len();
        let (mut obs, mut fin, mut rew, mut term, mut trunc) =
            (vec![], vec![], vec![], vec![0; n], vec![0; n]);
        for c in 0..n {
            let (e, t) = (self.episode[c], self.t[c]);
            let ep = &mut log[c][e as usize];
            ep.actions
                .push(actions[c * self.act_dim..(c + 1) * self.act_dim].to_vec());
            let r = (c * 100 + e as usize * 10) as f32 + t as f32 * 0.5;
            ep.rewards.push(r);
            rew.push(r);
            let next = self.state(c, e, t + 1);
            ep.states.push(next.clone());
            if t + 1 == self.episode_len[c] {
                let terminated = self.rng.random_bool(0.5);
                (ep.terminated, ep.truncated) = (terminated, !terminated);
                term[c] = u32::from(terminated);
                trunc[c] = u32::from(!terminated);
                fin.extend_from_slice(&next);
                self.episode[c] += 1;
                self.t[c] = 0;
                self.episode_len[c] = self.rng.random_range(1..=self.max_len);
                log[c].push(Episode {
                    states: vec![self.state(c, e + 1, 0)],
                    ..Episode::default()
                });
                obs.extend(self.state(c, e + 1, 0));
            } else {
                self.t[c] = t + 1;
                fin.extend(std::iter::repeat_n(-1.0, self.obs_dim));
                obs.extend(next);
            }
        }
        FakeStep {
            observations: obs,
            final_observations: fin,
            rewards: rew,
            terminated: term,
            truncated: trunc,
        }
    }
}

const LOW: [f64; 2] = [-1.0, -2.0];
const HIGH: [f64; 2] = [1.0, 2.0];

/// A fixed delay with random warm-up actions (not the default zeros), so that the actions
/// executed before the first observation differ from step to step and copy to copy.
fn fixed(delay: usize) -> DelayConfig {
    DelayConfig {
        warmup: WarmupActions::Random,
        ..DelayConfig::fixed(delay)
    }
}

fn cpu_layer(delay: usize, copies: usize, obs_dim: usize) -> CpuDelayLayer {
    CpuDelayLayer::new(&fixed(delay), copies, obs_dim, &LOW, &HIGH, 7).unwrap()
}

/// `x_t` as the contract defines it, from the undelayed log.
fn expected_augmented(ep: &Episode, t: usize, delay: usize) -> Vec<f32> {
    let mut x = ep.states[t - delay].clone();
    for a in &ep.actions[t - delay..t] {
        x.extend_from_slice(a);
    }
    x
}

/// Every transition `(x_τ, s_τ, a_τ, r_τ, x_{τ+1}, s_{τ+1}, terminated)` of a finished episode,
/// τ from Δ (the first with an augmented state) to T − 1, from the undelayed log.
fn expected_transitions(
    ep: &Episode,
    delay: usize,
) -> Vec<(
    u32,
    Vec<f32>,
    Vec<f32>,
    Vec<f32>,
    f32,
    Vec<f32>,
    Vec<f32>,
    u32,
)> {
    let len = ep.actions.len();
    (delay..len)
        .map(|tau| {
            let last = tau + 1 == len;
            (
                tau as u32,
                expected_augmented(ep, tau, delay),
                ep.states[tau].clone(),
                ep.actions[tau].clone(),
                ep.rewards[tau],
                expected_augmented(ep, tau + 1, delay),
                ep.states[tau + 1].clone(),
                u32::from(last && ep.terminated),
            )
        })
        .collect()
}

type Keyed =
    BTreeMap<(usize, u32, u32), (Vec<f32>, Vec<f32>, Vec<f32>, f32, Vec<f32>, Vec<f32>, u32)>;

fn key_transitions(tr: &Transitions, layout_aug: usize, obs: usize, act: usize, into: &mut Keyed) {
    for i in 0..tr.len() {
        let previous = into.insert(
            (tr.copy[i], tr.episode[i], tr.tau[i]),
            (
                tr.augmented[i * layout_aug..(i + 1) * layout_aug].to_vec(),
                tr.state[i * obs..(i + 1) * obs].to_vec(),
                tr.action[i * act..(i + 1) * act].to_vec(),
                tr.reward[i],
                tr.next_augmented[i * layout_aug..(i + 1) * layout_aug].to_vec(),
                tr.next_state[i * obs..(i + 1) * obs].to_vec(),
                tr.terminated[i],
            ),
        );
        assert!(
            previous.is_none(),
            "transition {:?} emitted twice",
            (tr.copy[i], tr.episode[i], tr.tau[i])
        );
    }
}

/// Room for every record of [`run_cpu`]: at most one step and one final state per copy and step.
fn replay_capacity(copies: usize, steps: usize, delay: usize) -> usize {
    copies * (2 * steps + 2 * delay + 8)
}

/// Runs the CPU layer over a fake batch, checking `x_t` every step; returns the emitted
/// transitions keyed by (copy, episode, τ), the undelayed log and the replay store.
fn run_cpu(
    delay: usize,
    copies: usize,
    max_len: u32,
    steps: usize,
    seed: u64,
) -> (Keyed, Vec<Vec<Episode>>, ReplayStore, usize) {
    let (obs_dim, act_dim) = (3, 2);
    let mut fake = FakeBatch::new(copies, obs_dim, act_dim, max_len, seed);
    let mut layer = cpu_layer(delay, copies, obs_dim);
    let layout = layer.layout();
    let mut replay = ReplayStore::new(layout, replay_capacity(copies, steps, delay)).unwrap();
    layer.reset(&fake.initial()).unwrap();
    let mut log = fake.new_log();
    let mut emitted = Keyed::new();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 99);
    let aug = layout.augmented_dim();
    for _ in 0..steps {
        let mut actions: Vec<f32> = (0..copies * act_dim)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        layer.fill_warmup(&mut actions).unwrap();
        let produced = fake.step(&actions, &mut log);
        let input = produced.input(&actions);
        layer.step(&input).unwrap();
        replay.push(layer.records(), &[]).unwrap();
        key_transitions(
            &layer.transitions().unwrap(),
            aug,
            obs_dim,
            act_dim,
            &mut emitted,
        );
        for c in 0..copies {
            let ep = log[c].last().unwrap();
            let t = fake.t[c] as usize;
            let ready = layer.ready()[c] == 1;
            assert_eq!(ready, t >= delay, "copy {c} t {t}");
            let x = &layer.augmented()[c * aug..(c + 1) * aug];
            if ready {
                assert_eq!(
                    x,
                    expected_augmented(ep, t, delay).as_slice(),
                    "x_t of copy {c} at t {t}"
                );
            } else {
                assert!(x.iter().all(|&v| v == 0.0));
            }
        }
    }
    (emitted, log, replay, aug)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// (a) x_t = (s_{t-Δ}, a_{t-Δ..t-1}); every transition of every finished episode appears
    /// exactly once with the right flags; nothing of an unfinished episode appears early.
    /// Layers of more than 64 copies step them in parallel, smaller ones on the calling thread.
    #[test]
    fn augmented_states_and_transitions_follow_the_undelayed_log(
        delay in 0usize..7, copies in prop_oneof![1usize..5, 65usize..70], max_len in 1u32..20,
        seed in 0u64..1000,
    ) {
        let (emitted, log, _, _) = run_cpu(delay, copies, max_len, 60, seed);
        let mut expected = 0;
        for (c, episodes) in log.iter().enumerate() {
            for (e, ep) in episodes.iter().enumerate() {
                if !(ep.terminated || ep.truncated) {
                    continue; // unfinished: only transitions whose s_{τ+1} arrived may be out
                }
                for tr in expected_transitions(ep, delay) {
                    expected += 1;
                    let got = emitted.get(&(c, e as u32, tr.0)).unwrap_or_else(|| panic!("missing transition {:?}", (c, e, tr.0)));
                    prop_assert_eq!(got, &(tr.1, tr.2, tr.3, tr.4, tr.5, tr.6, tr.7));
                }
            }
        }
        // The rest come from unfinished episodes, only once s_{τ+1} arrived: τ ≤ t − Δ − 1.
        for (&(c, e, tau), _) in &emitted {
            let ep = &log[c][e as usize];
            if !(ep.terminated || ep.truncated) {
                prop_assert!((tau as usize) + 1 + delay <= ep.actions.len(), "early transition {:?}", (c, e, tau));
            }
        }
        prop_assert!(emitted.len() >= expected);
    }

    /// (d) The replay store rebuilds exactly the transitions the layer wrote out verbatim.
    /// A transition of a running episode becomes sampleable one step after it completed (its
    /// `s_{τ+1}` is stored with record τ + 1), so only each running episode's newest
    /// transition may be missing.
    #[test]
    fn replay_reconstruction_equals_the_verbatim_transitions(
        delay in 0usize..7, copies in 1usize..4, max_len in 1u32..20, seed in 0u64..1000,
    ) {
        let (emitted, log, replay, aug) = run_cpu(delay, copies, max_len, 50, seed);
        let mut rebuilt = Keyed::new();
        key_transitions(&replay.all(), aug, 3, 2, &mut rebuilt);
        for (key, value) in &rebuilt {
            prop_assert_eq!(emitted.get(key), Some(value));
        }
        for (&(c, e, tau), _) in emitted.iter().filter(|(k, _)| !rebuilt.contains_key(k)) {
            let running = e as usize + 1 == log[c].len();
            let newest = emitted.range((c, e, tau + 1)..(c, e + 1, 0)).next().is_none();
            prop_assert!(running && newest, "transition {:?} missing from the replay", (c, e, tau));
        }
        if !emitted.is_empty() {
            let extras = BatchExtras { intermediate_states: true };
            let batch = replay.sample_with(64, &mut ChaCha8Rng::seed_from_u64(seed), extras).unwrap();
            let plain = replay.sample(64, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
            prop_assert!(plain.intermediate_states.is_empty(), "only on request");
            prop_assert_eq!(&plain.tau, &batch.tau, "the same draws");
            // s_{τ-Δ+1} … s_τ of each sample, from the undelayed log.
            let expected: Vec<f32> = (0..batch.len())
                .flat_map(|i| {
                    let ep = &log[batch.copy[i]][batch.episode[i] as usize];
                    let tau = batch.tau[i] as usize;
                    ep.states[tau + 1 - delay..=tau].concat()
                })
                .collect();
            prop_assert_eq!(&batch.intermediate_states, &expected);
            let mut sampled = Keyed::new();
            for i in 0..batch.len() {
                let one = Transitions {
                    copy: vec![batch.copy[i]], episode: vec![batch.episode[i]], tau: vec![batch.tau[i]],
                    augmented: batch.augmented[i * aug..(i + 1) * aug].to_vec(), state: batch.state[i * 3..(i + 1) * 3].to_vec(),
                    action: batch.action[i * 2..(i + 1) * 2].to_vec(), reward: vec![batch.reward[i]],
                    next_augmented: batch.next_augmented[i * aug..(i + 1) * aug].to_vec(),
                    next_state: batch.next_state[i * 3..(i + 1) * 3].to_vec(), terminated: vec![batch.terminated[i]],
                    intermediate_states: Vec::new(),
                };
                sampled.clear();
                key_transitions(&one, aug, 3, 2, &mut sampled);
                let (k, v) = sampled.iter().next().unwrap();
                prop_assert_eq!(emitted.get(k), Some(v));
            }
        }
    }
}

#[test]
fn zero_delay_is_the_undelayed_task() {
    let (emitted, log, _, _) = run_cpu(0, 2, 6, 30, 3);
    for (c, episodes) in log.iter().enumerate() {
        for (e, ep) in episodes
            .iter()
            .enumerate()
            .filter(|(_, ep)| ep.terminated || ep.truncated)
        {
            for (tau, a) in ep.actions.iter().enumerate() {
                let got = &emitted[&(c, e as u32, tau as u32)];
                assert_eq!(got.0, ep.states[tau], "x_t = s_t");
                assert_eq!(&got.2, a);
                assert_eq!(got.5, ep.states[tau + 1]);
            }
        }
    }
}

#[test]
fn replay_reports_its_memory_per_step() {
    let layout = cpu_layer(20, 1, 376).layout();
    let layout = dhrl::delay::DelayLayout {
        act_dim: 17,
        ..layout
    };
    let replay = ReplayStore::new(layout, 1000).unwrap();
    assert_eq!(replay.bytes_per_step(), (376 + 17 + 1) * 4 + 12);
    assert_eq!(
        replay.verbatim_bytes_per_step(),
        (2 * (376 + 20 * 17) + 2 * 376 + 17 + 2) * 4
    );
    assert!(matches!(
        ReplayStore::new(layout, 10),
        Err(dhrl::delay::ReplayError::TooSmall { .. })
    ));
}

#[test]
fn warmup_actions_are_random_in_bounds_or_zeros() {
    let mut layer = cpu_layer(3, 4, 2);
    layer.reset(&[0.0; 8]).unwrap();
    let mut actions = vec![9.0; 8];
    layer.fill_warmup(&mut actions).unwrap();
    for row in actions.chunks(2) {
        assert!(
            (-1.0..=1.0).contains(&row[0]) && (-2.0..=2.0).contains(&row[1]),
            "{row:?}"
        );
    }
    assert!(actions.iter().any(|&a| a != 0.0));
    let config = DelayConfig {
        warmup: WarmupActions::Zeros,
        ..fixed(3)
    };
    let mut zeros = CpuDelayLayer::new(&config, 4, 2, &LOW, &HIGH, 1).unwrap();
    zeros.reset(&[0.0; 8]).unwrap();
    zeros.fill_warmup(&mut actions).unwrap();
    assert!(actions.iter().all(|&a| a == 0.0));
}

#[test]
fn invalid_delay_configurations_are_clear_errors() {
    let random = DelayConfig {
        random_delay: true,
        ..DelayConfig::default()
    };
    assert_eq!(
        random.total_delay(),
        Err(DelayError::RandomDelayWithoutBound)
    );
    assert!(
        random
            .total_delay()
            .unwrap_err()
            .to_string()
            .contains("--max-delay")
    );
    let bound_only = DelayConfig {
        max_random_delay: Some(3),
        ..DelayConfig::default()
    };
    assert_eq!(
        bound_only.total_delay(),
        Err(DelayError::BoundWithoutRandomDelay(3))
    );
    let both = DelayConfig {
        observation_delay: 2,
        random_delay: true,
        max_random_delay: Some(3),
        ..DelayConfig::default()
    };
    assert_eq!(
        both.total_delay(),
        Err(DelayError::FixedAndRandomObservationDelay(2))
    );
    let too_long = DelayConfig {
        observation_delay: MAX_DELAY,
        action_delay: 1,
        ..DelayConfig::default()
    };
    assert_eq!(
        too_long.total_delay(),
        Err(DelayError::TooLong {
            total: MAX_DELAY + 1
        })
    );
    let noise = DelayConfig {
        actuator_noise: -0.1,
        ..DelayConfig::default()
    };
    assert_eq!(noise.total_delay(), Err(DelayError::BadNoise(-0.1)));
    let split = DelayConfig {
        observation_delay: 3,
        action_delay: 2,
        ..DelayConfig::default()
    };
    assert_eq!(
        split.total_delay(),
        Ok(5),
        "only the total delay matters to the agent"
    );
    let conservative = DelayConfig {
        random_delay: true,
        max_random_delay: Some(4),
        action_delay: 1,
        ..DelayConfig::default()
    };
    assert_eq!(conservative.total_delay(), Ok(5));
}

/// (c) Under random delays the conservative agent acts on exactly Δ_max-old observations: its
/// augmented states and readiness are those of a fixed delay of Δ_max.
#[test]
fn conservative_agent_sees_exactly_max_delay_old_observations() {
    let bound = 5;
    let config = DelayConfig {
        random_delay: true,
        max_random_delay: Some(bound),
        ..DelayConfig::default()
    };
    let mut random = CpuDelayLayer::new(&config, 3, 3, &LOW, &HIGH, 2).unwrap();
    let mut fixed = cpu_layer(bound, 3, 3);
    let mut fake = FakeBatch::new(3, 3, 2, 40, 5);
    let mut log = fake.new_log();
    random.reset(&fake.initial()).unwrap();
    fixed.reset(&fake.initial()).unwrap();
    for step in 0..80u32 {
        let actions = vec![0.25; 6];
        let produced = fake.step(&actions, &mut log);
        let input = produced.input(&actions);
        random.step(&input).unwrap();
        fixed.step(&input).unwrap();
        assert_eq!(random.augmented(), fixed.augmented(), "step {step}");
        assert_eq!(random.ready(), fixed.ready());
        let aug = random.layout().augmented_dim();
        for c in 0..3 {
            let (ep, t) = (log[c].last().unwrap(), fake.t[c] as usize);
            if t >= bound {
                assert_eq!(
                    &random.augmented()[c * aug..c * aug + 3],
                    ep.states[t - bound].as_slice(),
                    "copy {c} acts on s_(t-Δmax)"
                );
            }
        }
    }
}

/// (c) The arrivals of random delays against a model of the channel built here from the
/// undelayed trace alone: each arrival is the true state `s_τ` it names, 1..=Δ_max steps old;
/// no state arrives twice and every one arrives in time; the state the conservative agent acts
/// on at `t` has arrived by `t`; ages spread over all of 1..=Δ_max (uniform draws) and states
/// overtake older ones (out of order); another seed gives other arrivals.
#[test]
fn random_delay_arrivals_follow_the_channel_model() {
    use dhrl::rollout::{InitialState, TraceStep, rollout};
    let bound = 5;
    let config = DelayConfig {
        random_delay: true,
        max_random_delay: Some(bound),
        ..DelayConfig::default()
    };
    // HalfCheetah does not terminate: 400 steps, no episode end.
    let state = InitialState {
        qpos: vec![0.0; 9],
        qvel: vec![0.0; 9],
    };
    // f32 actions: the delayed trace runs the training path, which takes actions as f32.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let actions: Vec<Vec<f64>> = (0..400)
        .map(|_| {
            (0..6)
                .map(|_| f64::from(rng.random_range(-1.0f32..1.0)))
                .collect()
        })
        .collect();
    let trace = |delay: Option<(&DelayConfig, DelayDevice)>, seed: u64| {
        let mut lines: Vec<TraceStep> = Vec::new();
        rollout(TaskName::HalfCheetah, &state, &actions, delay, seed, |l| {
            lines.push(l.clone())
        })
        .unwrap();
        lines
    };
    let truth: Vec<Vec<f64>> = trace(None, 0)
        .iter()
        .map(|l| {
            // The delay layer's precision.
            l.obs
                .as_ref()
                .unwrap()
                .iter()
                .map(|&v| f64::from(v as f32))
                .collect()
        })
        .collect();
    let arrivals_of = |seed: u64| {
        let lines = trace(Some((&config, DelayDevice::Cpu)), seed);
        assert_eq!(lines.len(), truth.len());
        let mut arrived_at = BTreeMap::new();
        for line in &lines[1..] {
            let t = line.t;
            for arrival in line
                .arrived
                .as_ref()
                .expect("every line lists its arrivals")
            {
                let age = t - arrival.tau;
                assert!(
                    (1..=bound).contains(&age),
                    "s_{} arrived {age} steps old at t {t}",
                    arrival.tau
                );
                assert_eq!(
                    arrival.obs, truth[arrival.tau],
                    "t {t}: the arrival named s_{} is another state",
                    arrival.tau
                );
                assert!(
                    arrived_at.insert(arrival.tau, t).is_none(),
                    "s_{} arrived twice",
                    arrival.tau
                );
            }
            if t >= bound {
                assert_eq!(
                    line.obs.as_ref(),
                    Some(&truth[t - bound]),
                    "t {t}: the agent acts on s_(t-Δmax)"
                );
                assert!(
                    arrived_at.get(&(t - bound)).is_some_and(|&at| at <= t),
                    "t {t}: s_(t-Δmax) has not arrived"
                );
            }
        }
        let last = lines.len() - 1;
        for tau in 0..=last - bound {
            assert!(arrived_at.contains_key(&tau), "s_{tau} never arrived");
        }
        arrived_at
    };
    let arrived_at = arrivals_of(9);
    let mut ages = vec![0usize; bound + 1];
    for (tau, at) in &arrived_at {
        ages[at - tau] += 1;
    }
    // ~80 of each age expected from ~400 uniform draws; a bias toward any age shows.
    for (age, &count) in ages.iter().enumerate().skip(1) {
        assert!(
            (40..=120).contains(&count),
            "{count} arrivals {age} steps old: {ages:?}"
        );
    }
    let overtaken = arrived_at
        .iter()
        .filter(|&(tau, at)| arrived_at.get(&(tau + 1)).is_some_and(|next| next < at))
        .count();
    assert!(
        overtaken > 20,
        "only {overtaken} observations were overtaken"
    );
    assert_ne!(arrivals_of(10), arrived_at, "the seed draws the delays");
}

/// Records of two layers as comparable lists.
fn record_list(records: &RecordBatch) -> Vec<(usize, [u32; 4], Vec<f32>)> {
    records
        .iter()
        .map(|r| {
            let m = r.meta;
            let mut data = r.state.to_vec();
            data.extend_from_slice(r.action);
            data.push(r.reward);
            (r.copy, [m.tau, m.episode, m.flags, m.slot], data)
        })
        .collect()
}

/// Steps both layers with `input` and checks that they agree on augmented states, counters
/// and records.
fn step_both(cpu: &mut CpuDelayLayer, gpu: &mut GpuDelayLayer, input: &StepInput<'_>, at: &str) {
    cpu.step(input).unwrap();
    gpu.step(input).unwrap();
    assert_eq!(gpu.read_augmented().unwrap(), cpu.augmented(), "{at}");
    // What training reads: the host copies of the outputs.
    assert_eq!(DelayLayer::augmented(gpu), cpu.augmented(), "{at}");
    assert_eq!(DelayLayer::ready(gpu), cpu.ready(), "{at}");
    assert_eq!(
        record_list(DelayLayer::records(gpu)),
        record_list(cpu.records()),
        "{at}"
    );
    assert_eq!(gpu.read_counters().unwrap(), cpu.counters(), "{at}");
    assert_eq!(
        record_list(&gpu.read_records().unwrap()),
        record_list(cpu.records()),
        "{at}"
    );
}

fn gpu_layer(
    config: &DelayConfig,
    copies: usize,
    obs_dim: usize,
    low: &[f64],
    high: &[f64],
) -> Option<GpuDelayLayer> {
    match GpuDelayLayer::new(config, copies, obs_dim, low, high, 7) {
        Ok(layer) => Some(layer),
        Err(e) if std::env::var("DHRL_SKIP_GPU_TESTS").as_deref() == Ok("1") => {
            eprintln!("SKIPPED (DHRL_SKIP_GPU_TESTS=1): the GPU delay-layer comparison: {e}");
            None
        }
        Err(e) => panic!(
            "{e}. These tests need a Vulkan adapter; without a GPU install Mesa's software \
             Vulkan (apt-get install mesa-vulkan-drivers; scripts/test.sh does it as root), or \
             set DHRL_SKIP_GPU_TESTS=1 to skip them knowingly"
        ),
    }
}

/// `copies` Hopper copies (which fall at different times) on two threads.
fn hopper_batch(copies: usize, seed: u64) -> BatchedEnv {
    BatchedEnv::new(&BatchConfig {
        task: TaskName::Hopper,
        envs: copies,
        threads: 2,
        seed,
        actuator_noise: 0.0,
    })
    .unwrap()
}

/// A CPU delay layer of fixed delay `delay` for `env`'s copies, started from their states.
fn cpu_layer_for(env: &BatchedEnv, delay: usize) -> CpuDelayLayer {
    let (low, high) = env.action_bounds();
    let mut cpu =
        CpuDelayLayer::new(&fixed(delay), env.len(), env.obs_dim(), low, high, 7).unwrap();
    cpu.reset(env.observations()).unwrap();
    cpu
}

/// [`cpu_layer_for`] and its GPU twin (`None` when GPU tests are knowingly skipped).
fn both_layers(env: &BatchedEnv, delay: usize) -> Option<(CpuDelayLayer, GpuDelayLayer)> {
    let (low, high) = env.action_bounds();
    let mut gpu = gpu_layer(&fixed(delay), env.len(), env.obs_dim(), low, high)?;
    gpu.reset(env.observations()).unwrap();
    Some((cpu_layer_for(env, delay), gpu))
}

/// (b) The WGSL kernels produce the same augmented states and records as the CPU reference,
/// across episode boundaries, with copies finishing at different times.
#[test]
fn gpu_matches_cpu_on_synthetic_episodes() {
    for delay in [0, 1, 4, 9] {
        let copies = 37;
        let config = fixed(delay);
        let Some(mut gpu) = gpu_layer(&config, copies, 3, &LOW, &HIGH) else {
            return;
        };
        let mut cpu = cpu_layer(delay, copies, 3);
        let mut fake = FakeBatch::new(copies, 3, 2, 15, delay as u64);
        let mut log = fake.new_log();
        cpu.reset(&fake.initial()).unwrap();
        gpu.reset(&fake.initial()).unwrap();
        assert_eq!(gpu.read_augmented().unwrap(), cpu.augmented());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for step in 0..70 {
            let actions: Vec<f32> = (0..copies * 2)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let produced = fake.step(&actions, &mut log);
            let input = produced.input(&actions);
            step_both(
                &mut cpu,
                &mut gpu,
                &input,
                &format!("Δ {delay} step {step}"),
            );
            if step == 35 {
                // Both write the same checkpoint, and a GPU layer resumes from the CPU's.
                let (mut from_cpu, mut from_gpu) = (Vec::new(), Vec::new());
                DelayLayer::save(&cpu, &mut from_cpu).unwrap();
                gpu.save(&mut from_gpu).unwrap();
                assert!(from_cpu == from_gpu, "Δ {delay}: the checkpoints differ");
                gpu = gpu_layer(&config, copies, 3, &LOW, &HIGH).unwrap();
                gpu.load(&mut from_cpu.as_slice()).unwrap();
                assert_eq!(gpu.read_counters().unwrap(), cpu.counters());
            }
        }
    }
}

/// (b) on real physics: a batch of Hopper copies (which fall at different times) through both.
#[test]
fn gpu_matches_cpu_on_hopper() {
    let (copies, delay) = (24, 6);
    let mut env = hopper_batch(copies, 3);
    let Some((mut cpu, mut gpu)) = both_layers(&env, delay) else {
        return;
    };
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut finished = 0;
    for step in 0..150 {
        let actions: Vec<f32> = (0..copies * env.act_dim())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        env.step(&actions).unwrap();
        finished += env.terminated().iter().filter(|&&t| t == 1).count();
        let input = StepInput::from_env(&env, &actions);
        step_both(&mut cpu, &mut gpu, &input, &format!("step {step}"));
    }
    assert!(
        finished > copies,
        "episodes should end at different times: {finished}"
    );
}

/// A saved and reloaded replay store holds the same transitions and samples the same batches,
/// and its file holds the stored steps only, not the empty capacity.
#[test]
fn replay_store_survives_save_and_load() {
    let (_, _, replay, _) = run_cpu(3, 3, 12, 40, 5);
    let mut bytes = Vec::new();
    replay.save(&mut bytes).unwrap();
    // The layout and capacity of run_cpu's store.
    let mut restored =
        ReplayStore::new(cpu_layer(3, 3, 3).layout(), replay_capacity(3, 40, 3)).unwrap();
    restored.load(&mut bytes.as_slice()).unwrap();
    assert_eq!(restored.len(), replay.len());
    assert!(
        bytes.len() < replay.len() * (replay.bytes_per_step() + 16) + 64,
        "only stored steps are written"
    );
    assert_eq!(restored.all(), replay.all());
    let mut a = ChaCha8Rng::seed_from_u64(9);
    let mut b = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..5 {
        assert_eq!(
            restored.sample(16, &mut a).unwrap(),
            replay.sample(16, &mut b).unwrap()
        );
    }
}

/// A copy whose simulation diverges (HalfCheetah sliding at 1,000 m/s: MuJoCo finds a bad
/// qpos/qvel/qacc in the 4th step and resets the state to `qpos0`) ends its episode there,
/// truncated, with reward 0 and flagged; the other copy goes on. The replay keeps the steps
/// before as context and learns from them, but never from the diverged step, whose "next
/// state" is MuJoCo's reset state (without the flag it would be sampled).
#[test]
fn a_diverged_copy_ends_its_episode_and_its_last_step_stays_out_of_the_replay() {
    let batch = BatchConfig {
        task: TaskName::HalfCheetah,
        envs: 2,
        threads: 1,
        seed: 5,
        actuator_noise: 0.0,
    };
    let delay = fixed(2);
    let mut delayed = DelayedBatch::new(&batch, &delay, DelayDevice::Cpu, 1).unwrap();
    let model = dhrl::sim::TaskModel::load(TaskName::HalfCheetah).unwrap();
    let mut sliding = vec![0.0; model.nv];
    sliding[0] = 1000.0;
    delayed
        .env_mut()
        .set_state(0, &model.init_qpos, &sliding)
        .unwrap();
    delayed
        .env_mut()
        .set_state(1, &model.init_qpos, &vec![0.0; model.nv])
        .unwrap();
    let observations = delayed.env().observations().to_vec();
    delayed.layer_mut().reset(&observations).unwrap();
    let layout = delayed.layout();
    let mut flagged = ReplayStore::new(layout, 1000).unwrap();
    let mut unflagged = ReplayStore::new(layout, 1000).unwrap();
    let actions = vec![0.0f32; 2 * model.action_low.len()];
    let mut diverged_at = None;
    for step in 1..=8 {
        delayed.step(&actions).unwrap();
        let env = delayed.env();
        if env.diverged()[0] == 1 {
            assert_eq!(diverged_at, None, "one divergence");
            diverged_at = Some(step);
            assert_eq!(env.truncated()[0], 1, "a diverged episode ends truncated");
            assert_eq!(env.terminated()[0], 0);
            assert_eq!(env.rewards()[0], 0.0, "the diverged step earns nothing");
            assert_eq!(env.episode_lengths()[0], step);
        }
        assert_eq!(env.diverged()[1], 0, "the other copy is stable");
        assert_eq!(env.truncated()[1], 0);
        // Training's own hand-off (the loop calls push_step), beside one without the flags.
        let diverged = flagged.push_step(&delayed).unwrap();
        assert_eq!(diverged, u64::from(diverged_at == Some(step)));
        unflagged.push(delayed.layer().records(), &[]).unwrap();
    }
    assert_eq!(
        diverged_at,
        Some(4),
        "the sliding copy diverges in its 4th step"
    );
    let taus = |replay: &ReplayStore| -> Vec<u32> {
        let all = replay.all();
        (0..all.len())
            .filter(|&k| all.copy[k] == 0 && all.episode[k] == 0)
            .map(|k| all.tau[k])
            .collect()
    };
    // Steps τ = 0..3 of the diverged episode; with Δ = 2, τ ≥ 2 are transitions: τ = 2 (its
    // next state s_3 is the last real one) is learnt from, τ = 3 (diverged) is not.
    assert_eq!(taus(&flagged), vec![2]);
    assert_eq!(
        taus(&unflagged),
        vec![2, 3],
        "without the flag τ = 3 would be sampled"
    );
}

/// Held copies (a Gymnasium next-step reset) stay exactly as they are and restarted ones (a
/// partial reset) begin a new episode, in the simulator and in both delay layers alike; the
/// transitions both layers write out agree too.
#[test]
fn held_and_restarted_copies_agree_on_cpu_and_gpu() {
    let (copies, delay) = (16, 3);
    let mut env = hopper_batch(copies, 5);
    let Some((mut cpu, mut gpu)) = both_layers(&env, delay) else {
        return;
    };
    let (obs, aug) = (env.obs_dim(), cpu.layout().augmented_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let (mut held, mut restarted) = (0, 0);
    for step in 0..120 {
        let actions: Vec<f32> = (0..copies * env.act_dim())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let controls: Vec<CopyStep> = (0..copies)
            .map(|_| match rng.random_range(0..10) {
                0 => CopyStep::Hold,
                1 => CopyStep::Restart,
                _ => CopyStep::Step,
            })
            .collect();
        let before_obs = env.observations().to_vec();
        let before_aug = cpu.augmented().to_vec();
        let before_counters = cpu.counters().to_vec();
        env.step_each(&actions, &controls).unwrap();
        let input = StepInput::from_env(&env, &actions);
        step_both(&mut cpu, &mut gpu, &input, &format!("step {step}"));
        assert_eq!(
            gpu.transitions().unwrap(),
            cpu.transitions().unwrap(),
            "step {step}"
        );
        for (i, control) in controls.iter().enumerate() {
            let c = cpu.counters()[i];
            match control {
                CopyStep::Step => continue,
                CopyStep::Hold => {
                    held += 1;
                    assert_eq!(
                        env.observations()[i * obs..(i + 1) * obs],
                        before_obs[i * obs..(i + 1) * obs]
                    );
                    assert_eq!(
                        cpu.augmented()[i * aug..(i + 1) * aug],
                        before_aug[i * aug..(i + 1) * aug]
                    );
                    assert_eq!(
                        (c.t, c.episode),
                        (before_counters[i].t, before_counters[i].episode)
                    );
                }
                CopyStep::Restart => {
                    restarted += 1;
                    assert_eq!((c.t, c.episode), (0, before_counters[i].episode + 1));
                    assert_eq!(cpu.ready()[i], 0, "Δ = {delay}: nothing observed yet");
                }
            }
            assert_eq!(env.rewards()[i], 0.0);
            assert_eq!((env.terminated()[i], env.truncated()[i]), (0, 0));
            assert_eq!(cpu.records().counts[i], 0, "no record completes");
        }
    }
    assert!(
        held > 50 && restarted > 50,
        "{held} held, {restarted} restarted"
    );
}

/// What the Python package hands the agent: the rewards delivered with an episode's
/// observations add up to its return, and the final augmented state rebuilt from the records
/// of the end step is `x_T`, the `x_{τ+1}` of its last transition.
#[test]
fn delivered_rewards_sum_to_the_return_and_the_final_augmented_state_is_x_t() {
    let (copies, delay) = (8, 4);
    let mut env = hopper_batch(copies, 2);
    let mut cpu = cpu_layer_for(&env, delay);
    let mut delivered = vec![0.0f64; copies];
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut ended = 0;
    for _ in 0..300 {
        let actions: Vec<f32> = (0..copies * env.act_dim())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        env.step(&actions).unwrap();
        cpu.step(&StepInput::from_env(&env, &actions)).unwrap();
        let transitions = cpu.transitions().unwrap();
        for i in 0..copies {
            delivered[i] += f64::from(cpu.records().delivered_reward(i));
            let mut x_t = Vec::new();
            let done = env.terminated()[i] == 1 || env.truncated()[i] == 1;
            let rebuilt = cpu.records().push_final_augmented(i, &mut x_t);
            if !done {
                assert!(!rebuilt);
                continue;
            }
            ended += 1;
            let ret = f64::from(env.episode_returns()[i]);
            assert!(
                (delivered[i] - ret).abs() <= 1e-4 * ret.abs().max(1.0),
                "copy {i}: delivered {} vs return {ret}",
                delivered[i]
            );
            delivered[i] = 0.0;
            let length = env.episode_lengths()[i] as usize;
            assert_eq!(rebuilt, length >= delay, "T = {length}");
            let aug = cpu.layout().augmented_dim();
            if let Some(k) = (0..transitions.len())
                .rev()
                .find(|&k| transitions.copy[k] == i)
                .filter(|&k| transitions.tau[k] as usize == length - 1)
            {
                assert_eq!(x_t, transitions.next_augmented[k * aug..(k + 1) * aug]);
            }
        }
    }
    assert!(ended > copies, "{ended} episodes ended");
}
