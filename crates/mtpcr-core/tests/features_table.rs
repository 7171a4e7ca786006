//! The feature hypotheses on real scans: a table of how often the first candidate is right.

use mtpcr_core::cloud::PointCloud;
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::shared::find_shared_dir;
use mtpcr_core::eval::{apply_motions, random_motions};
use mtpcr_core::features::{candidates, describe, FeatureConfig, Features, DEFAULT_VOXEL_FRACTION};
use mtpcr_core::io::read_ply;
use mtpcr_core::se3::{invert_rigid, rotation_error_deg, Transform};
use std::collections::BTreeMap;
use std::time::Instant;

/// The real-data table: for every pair of the turntable48 triples (48 and 96 degrees apart)
/// and of the shared problems, each scan moved by a seeded random motion first, the rank of
/// the first candidate within 5 degrees of the truth and the time. Run with
/// `cargo test -p mtpcr-core --release --test features_table -- --ignored --nocapture`;
/// `MTPCR_FEATURE_SUITES` replaces the problem folders or files (comma separated),
/// `MTPCR_FEATURE_FRACTION` the voxel fraction, `MTPCR_FEATURE_SEEDS` the seeds (comma
/// separated; each gives other motions and other RANSAC draws); with
/// `MTPCR_FEATURE_ALL_PAIRS` set, every pair of each problem's scans is tried (grouped by the
/// true rotation between them, rounded to 24 degrees).
#[test]
#[ignore = "a table on real scans: needs ../shared (and the generated suites), prints a table"]
fn features_real_scans() {
    let folders: Vec<std::path::PathBuf> = match std::env::var("MTPCR_FEATURE_SUITES") {
        Ok(s) => s.split(',').map(std::path::PathBuf::from).collect(),
        Err(_) => {
            let mut v = vec![std::path::PathBuf::from("/work/problems-gen/turntable48")];
            v.extend(find_shared_dir().map(|d| d.join("problems")));
            v
        }
    };
    let mut files = Vec::new();
    for f in &folders {
        if f.is_dir() {
            let mut v: Vec<_> = std::fs::read_dir(f)
                .unwrap()
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "json"))
                .collect();
            v.sort();
            files.extend(v);
        } else if f.is_file() {
            files.push(f.clone());
        } else {
            eprintln!("skipping {}: not found", f.display());
        }
    }
    assert!(
        !files.is_empty(),
        "no problem files found: give them in MTPCR_FEATURE_SUITES"
    );
    let fraction: f64 = std::env::var("MTPCR_FEATURE_FRACTION")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_VOXEL_FRACTION);
    let mut cache: BTreeMap<std::path::PathBuf, PointCloud> = BTreeMap::new();
    // Per pair type: (ranks, seconds per pair).
    let mut stats: BTreeMap<String, (Vec<Option<usize>>, Vec<f64>)> = BTreeMap::new();
    let mut describe_seconds = Vec::new();
    let mut keypoints = Vec::new();
    println!("problem            pair  type   keypts(s/t)  cands  rank  err_first  secs");
    let all_pairs = std::env::var("MTPCR_FEATURE_ALL_PAIRS").is_ok();
    let seeds: Vec<u64> = std::env::var("MTPCR_FEATURE_SEEDS")
        .unwrap_or("0".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let jobs: Vec<(usize, &std::path::PathBuf, u64)> = seeds
        .iter()
        .flat_map(|&sd| files.iter().enumerate().map(move |(pi, f)| (pi, f, sd)))
        .collect();
    for (pi, file, run_seed) in jobs {
        let Ok(mut problem) = Problem::load(file, None) else {
            eprintln!("skipping {}: cannot load", file.display());
            continue;
        };
        let scans: Vec<PointCloud> = problem
            .scans
            .iter()
            .map(|p| {
                cache
                    .entry(p.clone())
                    .or_insert_with(|| read_ply(p).unwrap())
                    .clone()
            })
            .collect();
        let graph = problem.graph().unwrap();
        let truth = problem.ground_truth().unwrap();
        let extent = scans.iter().map(|c| c.largest_side()).fold(0.0, f64::max);
        let motions = random_motions(1000 + pi as u64 + 7919 * run_seed, extent, scans.len());
        if run_seed > 0 {
            problem.name = format!("{}#{run_seed}", problem.name);
        }
        let (clouds, gt) = apply_motions(&scans, &graph, &truth, &motions);
        let refs: Vec<&[[f64; 3]]> = clouds.iter().map(|c| c.points()).collect();
        let mut config = FeatureConfig::for_clouds(&refs, fraction).unwrap();
        config.seed = run_seed;
        let features: Vec<Features> = refs
            .iter()
            .map(|c| {
                let start = Instant::now();
                let f = describe(c, &config).unwrap();
                describe_seconds.push(start.elapsed().as_secs_f64());
                keypoints.push(f.len() as f64);
                f
            })
            .collect();
        // (source, target, truth, pair type): the graph's edges, or every pair.
        let pairs: Vec<(usize, usize, Transform, String)> = if all_pairs {
            let n = clouds.len();
            (0..n)
                .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
                .map(|(i, j)| {
                    let t = invert_rigid(&problem.poses[j]) * problem.poses[i];
                    let angle = rotation_error_deg(&t, &Transform::identity());
                    let gt = motions[j] * t * invert_rigid(&motions[i]);
                    (
                        i,
                        j,
                        gt,
                        format!("~{:03.0}deg", (angle / 24.0).round() * 24.0),
                    )
                })
                .collect()
        } else {
            graph
                .edges()
                .iter()
                .enumerate()
                .map(|(e, edge)| {
                    let kind = match (problem.name.contains("48-k"), e) {
                        (true, 2) => "96deg",
                        (true, _) => "48deg",
                        _ => "shared",
                    };
                    (edge.source, edge.target, gt[e], kind.to_string())
                })
                .collect()
        };
        for (source, target, truth, kind) in pairs {
            let start = Instant::now();
            let found = candidates(&features[source], &features[target], &config).unwrap();
            let secs = start.elapsed().as_secs_f64();
            let errs: Vec<f64> = found
                .iter()
                .map(|c| rotation_error_deg(&c.t_target_source, &truth))
                .collect();
            let rank = errs.iter().position(|&d| d < 5.0).map(|r| r + 1);
            println!(
                "{:<18} {}->{}  {:<6} {:>5}/{:<5}  {:>5}  {:>4}  {:>8.1}  {:.3}",
                problem.name,
                source + 1,
                target + 1,
                kind,
                features[source].len(),
                features[target].len(),
                found.len(),
                rank.map_or("none".to_string(), |r| r.to_string()),
                errs.first().copied().unwrap_or(f64::NAN),
                secs
            );
            let s = stats.entry(kind).or_default();
            s.0.push(rank);
            s.1.push(secs);
        }
    }
    println!("\nvoxel fraction {fraction}");
    println!("type    pairs  rank1  top5  top10  secs/pair (mean, max)");
    for (kind, (ranks, secs)) in &stats {
        let hit = |k: usize| ranks.iter().filter(|r| r.is_some_and(|r| r <= k)).count();
        println!(
            "{kind:<7} {:>5}  {:>5}  {:>4}  {:>5}  {:.3}, {:.3}",
            ranks.len(),
            hit(1),
            hit(5),
            hit(10),
            secs.iter().sum::<f64>() / secs.len() as f64,
            secs.iter().copied().fold(0.0, f64::max)
        );
    }
    println!(
        "describe: {:.3} s per scan (mean), {:.0} keypoints per scan (mean)",
        describe_seconds.iter().sum::<f64>() / describe_seconds.len() as f64,
        keypoints.iter().sum::<f64>() / keypoints.len() as f64
    );
}
