//! One SAC gradient update (256-256, batch 256) at HalfCheetah sizes on the CPU, and BPQL /
//! D2HPG at Δ = 10 beside it.
use criterion::{Criterion, criterion_group, criterion_main};
use dhrl::algos::{AgentSpec, Algo, Hyper, Lifting, build_agent};
use dhrl::delay::Transitions;
use dhrl::learn::{Devices, LearnDevice};
use rand::{Rng, SeedableRng};

fn batch(spec: &AgentSpec, n: usize) -> Transitions {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mut random = |len: usize| {
        (0..len)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect::<Vec<f32>>()
    };
    let (aug, obs, act) = (spec.augmented_dim(), spec.obs_dim, spec.act_dim);
    Transitions {
        copy: vec![0; n],
        episode: vec![0; n],
        tau: vec![0; n],
        augmented: random(n * aug),
        state: random(n * obs),
        action: random(n * act),
        reward: random(n),
        next_augmented: random(n * aug),
        next_state: random(n * obs),
        terminated: vec![0; n],
    }
}

fn updates(c: &mut Criterion) {
    let mut group = c.benchmark_group("update/half-cheetah sizes, batch 256");
    group.sample_size(20);
    let devices = Devices::new(LearnDevice::Cpu).unwrap();
    for (algo, delay) in [(Algo::Sac, 0), (Algo::Bpql, 10), (Algo::D2hpg, 10)] {
        let spec = AgentSpec {
            obs_dim: 17,
            act_dim: 6,
            delay,
            action_low: vec![-1.0; 6],
            action_high: vec![1.0; 6],
        };
        let mut agent = build_agent(
            algo,
            &spec,
            &Hyper::default(),
            &Lifting::default(),
            &devices,
            0,
        );
        let data = batch(&spec, 256);
        group.bench_function(format!("{algo} Δ={delay}"), |b| {
            b.iter(|| agent.update(&data))
        });
    }
    group.finish();
}

criterion_group!(benches, updates);
criterion_main!(benches);
