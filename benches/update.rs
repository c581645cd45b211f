//! One SAC gradient update (256-256, batch 256) at HalfCheetah sizes on the CPU, and BPQL /
//! D2HPG at Δ = 10 beside it.
use criterion::{Criterion, criterion_group, criterion_main};
use dhrl::algos::{AgentSpec, Algo, Hyper, Lifting, build_agent, random_batch};
use dhrl::learn::{Devices, LearnDevice};

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
        let data = random_batch(&spec, 256, 0);
        group.bench_function(format!("{algo} Δ={delay}"), |b| {
            b.iter(|| agent.update(&data))
        });
    }
    group.finish();
}

criterion_group!(benches, updates);
criterion_main!(benches);
