//! How long the finite-domain tools take to refuse inputs too large to build: a random source
//! of 10^8 states × 100 actions, and a sample-complexity bench whose largest delay is too long.
//! (tests/tabular.rs checks that they are refused before anything is generated; this measures
//! how fast.)
use clap::Parser;
use criterion::{Criterion, criterion_group, criterion_main};
use dhrl_tabular::{BenchConfig, TabularArgs, run_bench, run_tabular};

#[derive(Parser)]
struct TabularCli {
    #[command(flatten)]
    args: TabularArgs,
}

fn refusals(c: &mut Criterion) {
    let mut group = c.benchmark_group("tabular/refusal");
    let cli = TabularCli::try_parse_from([
        "tabular",
        "--random",
        "--states",
        "100000000",
        "--actions",
        "100",
        "--delay",
        "0",
    ])
    .expect("valid arguments");
    group.bench_function("random source 1e8 x 100", |b| {
        b.iter(|| run_tabular(&cli.args).expect_err("too large"))
    });
    let config = BenchConfig {
        states: 4,
        actions: 2,
        min_delay: 0,
        max_delay: 30,
        ..BenchConfig::default()
    };
    group.bench_function("bench up to delay 30", |b| {
        b.iter(|| run_bench(&config).expect_err("too large"))
    });
    group.finish();
}

criterion_group!(benches, refusals);
criterion_main!(benches);
