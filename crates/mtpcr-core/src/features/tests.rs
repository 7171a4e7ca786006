//! Tests of the feature hypotheses: synthetic registrations across large rotations,
//! determinism, degenerate input, descriptor invariance (the table on real scans is
//! `tests/features_table.rs`).

use super::describe::{pair_features, voxel_downsample};
use super::ransac::{kabsch, rotation_angle_deg};
use super::*;
use crate::se3::{decode, random_rigid, rotation_error_deg, translation, translation_error, Rigid};
use crate::synthetic::three_views;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The first candidate of a synthetic pair must be this close to the truth (degrees).
const FIRST_CANDIDATE_DEGREES: f64 = 3.0;
/// ... and this close in translation, in voxels.
const FIRST_CANDIDATE_VOXELS: f64 = 2.0;
/// Descriptors of a moved cloud equal the original's to this (bins hold up to 200).
const DESCRIPTOR_TOLERANCE: f32 = 1e-3;

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

fn moved(points: &[[f64; 3]], t: &Transform) -> Vec<[f64; 3]> {
    let r = Rigid::from_matrix(t);
    points.iter().map(|p| r.apply(p)).collect()
}

#[test]
fn features_register_synthetic_views_far_apart() {
    let mut angles = Vec::new();
    for seed in [1, 2, 3] {
        let problem = three_views(seed, 8000);
        let clouds: Vec<&[[f64; 3]]> = problem.clouds.iter().map(|c| c.points()).collect();
        let config = FeatureConfig::for_clouds(&clouds, DEFAULT_VOXEL_FRACTION).unwrap();
        let features: Vec<Features> = clouds
            .iter()
            .map(|c| describe(c, &config).unwrap())
            .collect();
        // Pairs 1 -> 2 and 2 -> 3 (views about 60 degrees apart), each in its own random frame.
        for (s, t, gt) in [
            (0, 1, problem.ground_truth[0]),
            (1, 2, problem.ground_truth[1]),
        ] {
            let angle = rotation_error_deg(&gt, &Transform::identity());
            angles.push(angle);
            let found = candidates(&features[s], &features[t], &config).unwrap();
            assert!(!found.is_empty(), "seed {seed} pair {s}->{t}: no candidate");
            let first = &found[0];
            let rot = rotation_error_deg(&first.t_target_source, &gt);
            let tra = translation_error(&first.t_target_source, &gt);
            assert!(
                rot < FIRST_CANDIDATE_DEGREES && tra < FIRST_CANDIDATE_VOXELS * config.voxel,
                "seed {seed} pair {s}->{t} ({angle:.0} deg apart): first candidate off by \
                 {rot:.2} deg, {tra:.4} (voxel {:.4}); {} candidates",
                config.voxel,
                found.len()
            );
            assert!(found.len() <= config.num_candidates);
            assert!(first.fitness > 0.0 && first.fitness <= 1.0 && first.inliers > 0);
            assert!(first.rmse <= config.inlier_distance);
            assert!(crate::se3::is_rigid(&first.t_target_source, 1e-9));
        }
    }
    assert!(
        angles.iter().any(|&a| (60.0..=180.0).contains(&a)),
        "the test must cover wide rotations: {angles:?}"
    );
}

#[test]
fn features_register_a_resampled_copy_rotated_by_60_to_180_degrees() {
    // One surface, sampled twice independently, the second copy rotated by 60..180 degrees
    // about a random axis and shifted.
    let problem = three_views(11, 8000);
    let source = problem.clouds[0].points().to_vec();
    let again = three_views(11, 16000);
    let other = &again.clouds[0].points()[8000..];
    let config = FeatureConfig::for_clouds(&[&source], DEFAULT_VOXEL_FRACTION).unwrap();
    let fs = describe(&source, &config).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for angle in [60.0, 100.0, 140.0, 180.0] {
        let axis = loop {
            let v = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            if v.norm() > 0.1 && v.norm() <= 1.0 {
                break nalgebra::Unit::new_normalize(v);
            }
        };
        let rot = nalgebra::Rotation3::from_axis_angle(&axis, f64::to_radians(angle));
        let mut gt = rot.to_homogeneous();
        for k in 0..3 {
            gt[(k, 3)] = rng.random_range(-0.2..0.2);
        }
        let target = moved(other, &gt);
        let ft = describe(&target, &config).unwrap();
        let found = candidates(&fs, &ft, &config).unwrap();
        assert!(!found.is_empty(), "{angle} deg: no candidate");
        let err = rotation_error_deg(&found[0].t_target_source, &gt);
        assert!(
            err < FIRST_CANDIDATE_DEGREES,
            "{angle} deg: first candidate off by {err:.2} deg"
        );
    }
}

#[test]
fn features_and_candidates_are_the_same_on_one_and_two_threads() {
    let problem = three_views(4, 6000);
    let clouds: Vec<&[[f64; 3]]> = problem.clouds.iter().map(|c| c.points()).collect();
    let config = FeatureConfig {
        seed: 9,
        ..FeatureConfig::for_clouds(&clouds, DEFAULT_VOXEL_FRACTION).unwrap()
    };
    let run = |threads: usize| {
        pool(threads).install(|| {
            let f: Vec<Features> = clouds
                .iter()
                .map(|c| describe(c, &config).unwrap())
                .collect();
            let c = candidates(&f[2], &f[0], &config).unwrap();
            (f, c)
        })
    };
    let (f1, c1) = run(1);
    let (f2, c2) = run(2);
    assert!(!c1.is_empty());
    assert_eq!(f1, f2, "features");
    assert_eq!(c1, c2, "candidates");
    let other = FeatureConfig {
        seed: 10,
        ..config.clone()
    };
    let c3 = pool(2).install(|| candidates(&f1[2], &f1[0], &other).unwrap());
    assert!(!c3.is_empty(), "another seed also finds candidates");
}

#[test]
fn features_of_degenerate_inputs_give_no_candidates() {
    let config = FeatureConfig::for_spacing(0.01);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let good = three_views(2, 4000);
    let good = describe(
        good.clouds[0].points(),
        &FeatureConfig::for_clouds(&[good.clouds[0].points()], 0.02).unwrap(),
    )
    .unwrap();
    let flat: Vec<[f64; 3]> = (0..5000)
        .map(|_| [rng.random_range(0.0..1.0), rng.random_range(0.0..1.0), 0.0])
        .collect();
    let line: Vec<[f64; 3]> = (0..5000)
        .map(|i| {
            let s = i as f64 / 5000.0;
            [s, 2.0 * s, -s]
        })
        .collect();
    let same = vec![[0.3, 0.2, 0.1]; 500];
    let nan = vec![[f64::NAN, 0.0, 0.0]; 500];
    let inf_and_few = vec![[f64::INFINITY, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let sparse: Vec<[f64; 3]> = (0..50)
        .map(|_| {
            [
                rng.random_range(0.0..10.0),
                rng.random_range(0.0..10.0),
                rng.random_range(0.0..10.0),
            ]
        })
        .collect();
    for (name, points) in [
        ("empty", Vec::new()),
        ("one point", vec![[1.0, 2.0, 3.0]]),
        ("flat", flat),
        ("collinear", line),
        ("identical", same),
        ("nan", nan),
        ("inf and few", inf_and_few),
        ("sparse", sparse),
    ] {
        let f = describe(&points, &config).unwrap();
        assert!(f.is_empty(), "{name}: {} keypoints", f.len());
        let found = candidates(&f, &f, &config).unwrap();
        assert!(found.is_empty(), "{name}");
        assert!(
            candidates(&f, &good, &config).unwrap().is_empty(),
            "{name} -> good"
        );
        assert!(
            candidates(&good, &f, &config).unwrap().is_empty(),
            "good -> {name}"
        );
    }
    // Keypoints whose descriptors are all equal: matches exist, no pose is verified twice
    // over (every draw is degenerate or checked away); must not panic.
    let mut blank = good.clone();
    blank
        .descriptors
        .iter_mut()
        .for_each(|d| *d = [1.0; DESCRIPTOR_LEN]);
    let _ = candidates(&blank, &blank, &config).unwrap();
    // Mismatched lengths and bad settings are errors, not panics.
    let mut broken = good.clone();
    broken.normals.pop();
    assert!(candidates(&broken, &good, &config).is_err());
    let mut broken = good.clone();
    broken.points[3][1] = f64::NAN;
    assert!(candidates(&good, &broken, &config).is_err());
    let bad = FeatureConfig {
        voxel: 0.0,
        ..config.clone()
    };
    let e = describe(&[[0.0; 3]], &bad).unwrap_err();
    assert!(e.to_string().contains("voxel"), "{e}");
    let bad = FeatureConfig {
        edge_length_ratio: 1.0,
        ..config
    };
    let e = candidates(&good, &good, &bad).unwrap_err();
    assert!(e.to_string().contains("edge_length_ratio"), "{e}");
    assert!(FeatureConfig::for_clouds(&[&[[1.0, 1.0, 1.0]]], 0.02).is_err());
}

#[test]
fn features_fpfh_does_not_change_when_the_cloud_is_moved() {
    let problem = three_views(5, 6000);
    let points = problem.clouds[0].points();
    let spacing = FeatureConfig::for_clouds(&[points], DEFAULT_VOXEL_FRACTION)
        .unwrap()
        .voxel;
    // A voxel far below the point spacing keeps every point as it is, so only the normals and
    // FPFH are compared (the voxel grid itself is tied to the frame).
    let config = FeatureConfig {
        voxel: spacing * 1e-6,
        ..FeatureConfig::for_spacing(spacing / 2.0)
    };
    let original = describe(points, &config).unwrap();
    // Every point is a keypoint, but for the few without three neighbours for a normal.
    assert!(
        original.len() > points.len() * 99 / 100,
        "{} keypoints",
        original.len()
    );
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let t = random_rigid(&mut rng, 1.0);
    let moved_features = describe(&moved(points, &t), &config).unwrap();
    assert_eq!(moved_features.len(), original.len());
    let tree = kiddo::ImmutableKdTree::<f64, 3>::new_from_slice(&original.points).unwrap();
    let back = Rigid::from_matrix(&t).inverse();
    let mut worst = 0.0f32;
    for (k, p) in moved_features.points.iter().enumerate() {
        let nn = tree
            .query(&back.apply(p))
            .nearest_one::<kiddo::SquaredEuclidean<f64>>()
            .execute();
        assert!(nn.distance < 1e-18, "keypoint {k} has no original");
        let i = nn.item as usize;
        // Normals turn with the cloud.
        let n = Rigid {
            r: Rigid::from_matrix(&t).r,
            t: [0.0; 3],
        }
        .apply(&original.normals[i]);
        let m = moved_features.normals[k];
        assert!((0..3).all(|c| (n[c] - m[c]).abs() < 1e-6), "normal {k}");
        for (a, b) in original.descriptors[i]
            .iter()
            .zip(&moved_features.descriptors[k])
        {
            worst = worst.max((a - b).abs());
        }
    }
    assert!(
        worst <= DESCRIPTOR_TOLERANCE,
        "largest descriptor difference {worst}"
    );
    let sums: Vec<f32> = (0..3)
        .map(|f| {
            original.descriptors[0][f * BINS_PER_FEATURE..(f + 1) * BINS_PER_FEATURE]
                .iter()
                .sum()
        })
        .collect();
    assert!(sums.iter().all(|s| (s - 200.0).abs() < 1e-3), "{sums:?}");
}

#[test]
fn features_pair_features_do_not_depend_on_the_order_of_the_pair() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let unit = |rng: &mut ChaCha8Rng| {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        [v[0], v[1], v[2]]
    };
    for _ in 0..1000 {
        let p1 = [
            rng.random_range(-1.0..1.0),
            0.0,
            rng.random_range(-1.0..1.0),
        ];
        let p2 = [0.5, rng.random_range(-1.0..1.0), 0.2];
        let (n1, n2) = (unit(&mut rng), unit(&mut rng));
        let a = pair_features(&p1, &n1, &p2, &n2);
        let b = pair_features(&p2, &n2, &p1, &n1);
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-9, "{a:?} {b:?}");
        }
        assert!(a[0].abs() <= std::f64::consts::PI && a[1].abs() <= 1.0 && a[2].abs() <= 1.0);
    }
    assert_eq!(
        pair_features(&[0.0; 3], &[0.0, 0.0, 1.0], &[0.0; 3], &[0.0, 0.0, 1.0]),
        [0.0; 3]
    );
}

#[test]
fn features_kabsch_recovers_a_known_motion() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..100 {
        let t = random_rigid(&mut rng, 3.0);
        let r = Rigid::from_matrix(&t);
        let src: Vec<[f64; 3]> = (0..20)
            .map(|_| {
                [
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                ]
            })
            .collect();
        let tgt: Vec<[f64; 3]> = src.iter().map(|p| r.apply(p)).collect();
        let est = kabsch(src.iter().zip(&tgt)).unwrap();
        assert!((est.to_matrix() - t).norm() < 1e-9);
        assert!(rotation_angle_deg(&est, &r) < 1e-4);
    }
    assert!(
        kabsch([[0.0; 3]; 2].iter().zip(&[[1.0; 3]; 2])).is_none(),
        "two pairs"
    );
    let a = Rigid::from_matrix(&decode(&[0.0, 0.0, 30.0, 0.0, 0.0, 0.0]));
    let b = Rigid::from_matrix(&Transform::identity());
    assert!((rotation_angle_deg(&a, &b) - 30.0).abs() < 1e-9);
}

#[test]
fn features_voxel_downsampling_averages_each_cell() {
    let points = [
        [0.1, 0.1, 0.1],
        [0.3, 0.3, 0.3],
        [1.5, 0.2, 0.2],
        [0.2, 0.2, 0.8],
    ];
    let out = voxel_downsample(&points, 1.0);
    assert_eq!(out.len(), 2);
    assert!((out[0][0] - 0.2).abs() < 1e-12 && (out[0][2] - 0.4).abs() < 1e-12);
    assert_eq!(out[1], [1.5, 0.2, 0.2]);
    assert!(voxel_downsample(&[], 1.0).is_empty());
}

#[test]
fn features_config_defaults_follow_the_voxel() {
    let c = FeatureConfig::for_spacing(0.004);
    c.validate().unwrap();
    assert_eq!(c.normal_radius, 0.008);
    assert_eq!(c.feature_radius, 0.02);
    assert!((c.inlier_distance - 0.006).abs() < 1e-15);
    let e = FeatureConfig {
        confidence: 0.0,
        ..c.clone()
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("confidence"), "{e}");
    let e = FeatureConfig {
        num_candidates: 0,
        ..c
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("num_candidates"), "{e}");
    let pts = [[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]];
    let d = pca_diagonal(&pts);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let moved_pts = moved(&pts, &random_rigid(&mut rng, 5.0));
    assert!((pca_diagonal(&moved_pts) - d).abs() < 1e-9 && d > 4.0);
}

#[test]
fn the_default_setting_uses_the_measured_voxel_fraction() {
    assert_eq!(
        crate::config::Config::default().feature_voxel_ratio,
        DEFAULT_VOXEL_FRACTION
    );
}

#[test]
fn features_support_is_the_candidates_score_and_the_truth_has_the_most() {
    let problem = three_views(4, 8000);
    let clouds: Vec<&[[f64; 3]]> = problem.clouds.iter().map(|c| c.points()).collect();
    let config = FeatureConfig::for_clouds(&clouds, DEFAULT_VOXEL_FRACTION).unwrap();
    let (a, b) = (
        describe(clouds[0], &config).unwrap(),
        describe(clouds[1], &config).unwrap(),
    );
    let matches = PairMatches::new(&a, &b, &config).unwrap();
    let found = matches.candidates(&a, &b);
    assert!(!found.is_empty());
    for c in &found {
        assert_eq!(matches.support(&c.t_target_source), c.matches);
    }
    let truth = problem.ground_truth[0];
    let wrong = truth * decode(&[0.0, 0.0, 30.0, 0.0, 0.0, 0.0]);
    assert!(matches.same_pose(&truth, &found[0].t_target_source));
    assert!(!matches.same_pose(&truth, &wrong));
    assert!(matches.support(&truth) > 10 * matches.support(&wrong).max(1));
}

/// A pair of matched keypoint sets where only `inliers` of `total` descriptor matches are
/// true: every source keypoint has an exact descriptor twin in the target, at the truth for
/// the first `inliers`, anywhere for the rest (a room pair at low overlap, in miniature).
fn mostly_wrong_matches(inliers: usize, total: usize, truth: &Rigid) -> (Features, Features) {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut cube = || std::array::from_fn(|_| rng.random_range(-2.0..2.0));
    let (mut source, mut target) = (Features::default(), Features::default());
    for k in 0..total {
        let p: [f64; 3] = cube();
        let q = if k < inliers { truth.apply(&p) } else { cube() };
        let n = Vector3::new(0.3, -0.2, 1.0).normalize();
        let d: Descriptor = std::array::from_fn(|b| ((k * 31 + b * 7) % 97) as f32);
        source.points.push(p);
        source.normals.push([n[0], n[1], n[2]]);
        source.descriptors.push(d);
        let turned = Rigid {
            t: [0.0; 3],
            ..*truth
        }
        .apply(&[n[0], n[1], n[2]]);
        target.points.push(q);
        target.normals.push(turned);
        target.descriptors.push(d);
    }
    (source, target)
}

#[test]
fn features_consensus_finds_the_pose_among_few_true_matches_without_ransac() {
    let truth = Rigid::from_matrix(&decode(&[0.4, -1.1, 0.7, 0.3, -0.2, 0.5]));
    let (source, target) = mostly_wrong_matches(40, 1000, &truth);
    // One RANSAC draw: whatever is found comes from the compatibility graph.
    let config = FeatureConfig {
        max_iterations: 1,
        icp_iterations: 0,
        ..FeatureConfig::for_spacing(0.05)
    };
    let found = candidates(&source, &target, &config).unwrap();
    let best = &found.first().expect("a candidate").t_target_source;
    assert!(rotation_error_deg(best, &truth.to_matrix()) < 1.0);
    assert!(translation_error(best, &truth.to_matrix()) < 0.05);
    // The same far from the origin (a survey's coordinates): as precise.
    let far_away = |f: &Features, by: f64| Features {
        points: f.points.iter().map(|p| p.map(|c| c + by)).collect(),
        ..f.clone()
    };
    let (shifted_source, shifted_target) = (far_away(&source, 4.0e7), far_away(&target, -3.0e7));
    let truth_shifted = translation([-3.0e7; 3]) * truth.to_matrix() * translation([-4.0e7; 3]);
    let found = candidates(&shifted_source, &shifted_target, &config).unwrap();
    let best = &found.first().expect("a candidate far away").t_target_source;
    assert!(rotation_error_deg(best, &truth_shifted) < 1.0);
    // A rule that refuses the truth leaves no candidate near it.
    let matches = PairMatches::new(&source, &target, &config).unwrap();
    let far = |t: &Transform| rotation_error_deg(t, &truth.to_matrix()) > 20.0;
    let refused = matches.candidates_where(&source, &target, &far);
    assert!(refused.iter().all(|c| far(&c.t_target_source)));
}

#[test]
fn features_tight_support_asks_half_the_distance_and_landed_counts_where_keypoints_land() {
    let truth = Rigid::from_matrix(&decode(&[0.4, -1.1, 0.7, 0.3, -0.2, 0.5]));
    let (source, target) = mostly_wrong_matches(40, 1000, &truth);
    let config = FeatureConfig::for_spacing(0.05);
    let matches = PairMatches::new(&source, &target, &config).unwrap();
    let t = truth.to_matrix();
    assert_eq!(matches.support(&t), 40);
    assert_eq!(matches.tight_support(&t), 40);
    // Shifted by 0.35 of the inlier distance: within support's half of it, beyond a quarter.
    let shifted = translation([0.35 * config.inlier_distance, 0.0, 0.0]) * t;
    assert_eq!(matches.support(&shifted), 40);
    assert_eq!(matches.tight_support(&shifted), 0);
    // Landed: the matches whose source keypoint the pose puts where the test holds, met or
    // not: all of them inside the target's cube at the truth, none when moved far away, and
    // a half-space and its complement share them.
    let all = matches.landed(&t, |_| true);
    assert!(all >= 1000, "{all}");
    let in_cube = |q: &[f64; 3]| q.iter().all(|c| c.abs() < 10.0);
    assert_eq!(matches.landed(&t, in_cube), all);
    let far = translation([100.0, 0.0, 0.0]) * t;
    assert_eq!(matches.landed(&far, in_cube), 0);
    let (east, west) = (
        matches.landed(&t, |q| q[0] > 0.0),
        matches.landed(&t, |q| q[0] <= 0.0),
    );
    assert!(east > all / 10 && west > all / 10, "{east} {west}");
    assert_eq!(east + west, all);
}
