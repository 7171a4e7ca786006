//! One evaluation of each loss, exact (KD-tree) and fast path, on bunny-size clouds at the
//! default sampling (about 2,000 points per cloud after farthest-point sampling), and the
//! building of one cloud's indexes.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use mtpcr_benches::bunny_a_or_synthetic;
use mtpcr_core::loss::{CappedDistanceLoss, InlierLoss, Loss};
use mtpcr_core::se3::{decode, random_rigid, Rigid};
use mtpcr_core::search::IndexedCloud;
use mtpcr_core::{Config, PreparedProblem, SearchMethod};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

fn losses(c: &mut Criterion) {
    let (clouds, label) = bunny_a_or_synthetic();
    // The same prepared points indexed both ways.
    let prepare = |search| {
        let config = Config {
            search,
            ..Config::default()
        };
        PreparedProblem::new(&clouds, &config).expect("prepares")
    };
    let (fast, exact) = (prepare(SearchMethod::Fast), prepare(SearchMethod::Exact));
    let prepared = &fast;
    let (a, b) = (&fast.clouds()[0], &fast.clouds()[1]);
    let by_method = |method| match method {
        SearchMethod::Fast => (&fast.clouds()[0], &fast.clouds()[1]),
        SearchMethod::Exact => (&exact.clouds()[0], &exact.clouds()[1]),
    };
    // A mix of poses like a population's: random ones and some near the identity.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut poses: Vec<Rigid> = (0..48)
        .map(|_| Rigid::from_matrix(&random_rigid(&mut rng, prepared.shift() * 0.5)))
        .collect();
    poses.extend(
        (0..16).map(|i| Rigid::from_matrix(&decode(&[i as f64, -2.0, 1.0, 0.0, 0.001, 0.0]))),
    );
    let points = (a.points().len() + b.points().len()) as u64;

    let mut group = c.benchmark_group(format!("original_loss/{label}"));
    group.throughput(Throughput::Elements(points * poses.len() as u64));
    for method in [SearchMethod::Exact, SearchMethod::Fast] {
        let (source, target) = by_method(method);
        let loss = InlierLoss { source, target };
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{method:?}")),
            &poses,
            |bench, poses| {
                bench.iter(|| {
                    poses
                        .iter()
                        .map(|t| loss.evaluate(black_box(t)))
                        .sum::<f64>()
                })
            },
        );
    }
    group.finish();

    let mut group = c.benchmark_group(format!("aiding_loss/{label}"));
    group.throughput(Throughput::Elements(
        a.points().len() as u64 * poses.len() as u64,
    ));
    for method in [SearchMethod::Exact, SearchMethod::Fast] {
        let (source, target) = by_method(method);
        let loss = CappedDistanceLoss {
            source,
            target,
            two_way: false,
        };
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{method:?}")),
            &poses,
            |bench, poses| {
                bench.iter(|| {
                    poses
                        .iter()
                        .map(|t| loss.evaluate(black_box(t)))
                        .sum::<f64>()
                })
            },
        );
    }
    group.finish();

    // What each loss's indexes cost to build, once per cloud and run: the KD-tree, the
    // inlier grid and the distance field of one prepared cloud (two threads, as a run has).
    let mut group = c.benchmark_group(format!("index_build/{label}"));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads");
    group.bench_function("Fast", |bench| {
        bench.iter(|| {
            pool.install(|| {
                IndexedCloud::new(a.points().to_vec(), a.eps(), a.cap(), SearchMethod::Fast)
            })
        })
    });
    group.finish();
}

criterion_group!(benches, losses);
criterion_main!(benches);
