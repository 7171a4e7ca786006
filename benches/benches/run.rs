//! A whole `Config::paper()` run (preparation included) on bunny-a, on 1 and 2 threads, a
//! `Config::default()` run on 2 threads beside the default it replaced, default runs on
//! 40k- and 1M-point scans, and a default run on 15 scans in no known order.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mtpcr_benches::{bunny_a_or_synthetic, dragon_all_or_synthetic};
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

    // The recommended setting, the one it replaced on 2026-12-01 (clouds in loop order,
    // no feature hypotheses, all sampled points, four full restarts of 100 x 30), and the
    // population of the default before 2026-12-03 (50 x 20, at most 4000 samples; today's
    // refinement and distance field in both): one run of this group gives the ratios.
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
    let previous = Config {
        order: mtpcr_core::Order::Given,
        hypotheses: 0,
        max_sample_points: 0,
        stop_when_restarts_agree: false,
        population_size: 100,
        generations: 30,
        ..config.clone()
    };
    let population_50x20 = Config {
        max_sample_points: 4000,
        population_size: 50,
        generations: 20,
        ..config.clone()
    };
    for (name, other) in [
        ("previous_default/threads/2", &previous),
        ("population_50x20/threads/2", &population_50x20),
    ] {
        group.bench_function(name, |bench| {
            bench.iter(|| register(&clouds, other, None).expect("runs"))
        });
    }
    group.finish();
}

/// A default run on synthetic views of 40,000 and of 1,000,000 points each (the same shape):
/// with `max_sample_points`, preparation and search cost about the same at any scan size.
fn by_scan_size(c: &mut Criterion) {
    let mut group = c.benchmark_group("default_run_by_scan_size");
    group.sample_size(10);
    for points in [40_000usize, 1_000_000] {
        let clouds = mtpcr_core::synthetic::three_views(1, points).clouds;
        let config = Config {
            seed: Some(1),
            num_threads: 2,
            ..Config::default()
        };
        group.bench_with_input(
            BenchmarkId::new("points", points),
            &clouds,
            |bench, clouds| bench.iter(|| register(clouds, &config, None).expect("runs")),
        );
    }
    group.finish();
}

/// A default run on 15 scans in no known order (the dragon turntable ring, or synthetic).
fn fifteen_scans(c: &mut Criterion) {
    let (clouds, label) = dragon_all_or_synthetic();
    let mut group = c.benchmark_group(format!("default_run_15_scans/{label}"));
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

criterion_group!(benches, whole_run, by_scan_size, fifteen_scans);
criterion_main!(benches);
