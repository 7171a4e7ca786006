//! A whole `Config::paper()` run (preparation included) on bunny-a, on 1 and 2 threads, and a
//! `Config::default()` run on 2 threads.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mtpcr_benches::bunny_a_or_synthetic;
use mtpcr_core::{register, Config};

fn whole_run(c: &mut Criterion) {
    let (clouds, label) = bunny_a_or_synthetic();
    let mut group = c.benchmark_group(format!("paper_run/{label}"));
    group.sample_size(10);
    for threads in [1usize, 2] {
        let config = Config {
            seed: Some(1),
            num_threads: threads,
            ..Config::paper()
        };
        group.bench_with_input(
            BenchmarkId::new("threads", threads),
            &config,
            |bench, config| bench.iter(|| register(&clouds, config, None).expect("runs")),
        );
    }
    group.finish();

    // The recommended setting (4 restarts of 30 generations and joint ICP refinement).
    let mut group = c.benchmark_group(format!("default_run/{label}"));
    group.sample_size(10);
    let config = Config {
        seed: Some(1),
        num_threads: 2,
        ..Config::default()
    };
    group.bench_function("threads/2", |bench| {
        bench.iter(|| register(&clouds, &config, None).expect("runs"))
    });
    group.finish();
}

criterion_group!(benches, whole_run);
criterion_main!(benches);
