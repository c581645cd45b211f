//! The CPU delay layer alone at HalfCheetah sizes, fed with synthetic steps (a twentieth of
//! the copies finishing each step), for Δ = 5, 10, 20: a step, and a step with its completed
//! transitions gathered (what the Python batch hands back each step).
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dhrl::delay::{CpuDelayLayer, DelayConfig, DelayLayer, StepInput};

const ENVS: usize = 4096;
const OBS: usize = 17;
const ACT: usize = 6;

fn delay_layer_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("delay/cpu half-cheetah sizes");
    group.throughput(Throughput::Elements(ENVS as u64));
    let observations: Vec<f32> = (0..ENVS * OBS).map(|i| i as f32 * 1e-3).collect();
    let actions = vec![0.1f32; ENVS * ACT];
    let rewards = vec![1.0f32; ENVS];
    let never = vec![0u32; ENVS];
    let some: Vec<u32> = (0..ENVS).map(|i| u32::from(i % 20 == 0)).collect();
    for delay in [5, 10, 20] {
        let mut layer = CpuDelayLayer::new(
            &DelayConfig::fixed(delay),
            ENVS,
            OBS,
            &[-1.0; ACT],
            &[1.0; ACT],
            0,
        )
        .unwrap();
        layer.reset(&observations).unwrap();
        let mut step = 0usize;
        for with_transitions in [false, true] {
            let what = if with_transitions {
                ", transitions"
            } else {
                ""
            };
            group.bench_function(format!("{ENVS} copies, delay {delay}{what}"), |b| {
                b.iter(|| {
                    step += 1;
                    let truncated = if step % 50 == 0 { &some } else { &never };
                    let input = StepInput {
                        actions: &actions,
                        observations: &observations,
                        final_observations: &observations,
                        rewards: &rewards,
                        terminated: &never,
                        truncated,
                        controls: None,
                    };
                    layer.step(&input).unwrap();
                    if with_transitions {
                        std::hint::black_box(layer.transitions().unwrap());
                    }
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, delay_layer_step);
criterion_main!(benches);
