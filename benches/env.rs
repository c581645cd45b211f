//! Batched simulator throughput against a raw single-thread `mj_step` loop (the anchor).
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dhrl::bench::{ActionTable, raw_mj_step_rate};
use dhrl::sim::{BatchConfig, BatchedEnv};
use dhrl::tasks::TaskName;

const ENVS: usize = 256;

fn batched_step(c: &mut Criterion) {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    for task in [TaskName::HalfCheetah, TaskName::Humanoid] {
        let mut group = c.benchmark_group(format!("env/{task}"));
        group.sample_size(10);
        group.throughput(Throughput::Elements(ENVS as u64));
        let mut env = BatchedEnv::new(&BatchConfig {
            task,
            envs: ENVS,
            threads,
            seed: 0,
            actuator_noise: 0.0,
        })
        .unwrap();
        let (low, high) = env.action_bounds();
        let actions = ActionTable::uniform(low, high, ENVS, 16, 0);
        let mut step = 0;
        group.bench_function(format!("batched {ENVS} copies, {threads} threads"), |b| {
            b.iter(|| {
                step += 1;
                env.step(actions.row(step)).unwrap();
            })
        });
        // One raw env step per iteration, timed the same way as `dhrl bench env`'s anchor.
        group.throughput(Throughput::Elements(1));
        group.bench_function("raw mj_step, 1 thread", |b| {
            b.iter_custom(|iters| {
                let rate = raw_mj_step_rate(task, 1, iters as usize).unwrap();
                std::time::Duration::from_secs_f64(iters as f64 / rate)
            })
        });
        group.finish();
    }
}

criterion_group!(benches, batched_step);
criterion_main!(benches);
