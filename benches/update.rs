//! One SAC gradient update (256-256, batch 256) at HalfCheetah sizes on the CPU, and BPQL /
//! D2HPG / delayed SAC / VDPO (without its cloning stage) at Δ = 10 beside it, each on its learners' thread count as in training.
use criterion::{Criterion, criterion_group, criterion_main};
use dhrl::algos::{AgentSpec, AlgoSettings, UpdateContext, random_batch};
use dhrl::learn::{Devices, LearnDevice};
use dhrl::tasks::TaskName;
use dhrl::train::learner_pool;

fn updates(c: &mut Criterion) {
    let mut group = c.benchmark_group("update/half-cheetah sizes, batch 256");
    group.sample_size(20);
    let devices = Devices::new(LearnDevice::Cpu).unwrap();
    for (name, delay) in [
        ("sac", 0),
        ("bpql", 10),
        ("d2hpg", 10),
        ("delayed-sac", 10),
        ("vdpo", 10),
    ] {
        let algo = AlgoSettings::new(name).unwrap();
        let spec = AgentSpec::for_task(TaskName::HalfCheetah, delay).unwrap();
        let mut agent = algo.build(&spec, &devices, 0);
        let pool = learner_pool(algo.info().learner_threads).unwrap();
        let data = random_batch(&spec, 256, 0);
        group.bench_function(format!("{name} Δ={delay}"), |b| {
            b.iter(|| {
                pool.install(|| agent.update(&mut UpdateContext::fixed(&data, 0, 0)))
                    .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, updates);
criterion_main!(benches);
