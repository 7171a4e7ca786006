//! One cloud's keypoints, normals and FPFH descriptors.

use super::{Descriptor, FeatureConfig, Features, NormalOrientation, BINS_PER_FEATURE};
use super::{DESCRIPTOR_LEN as LEN, MIN_KEYPOINTS};
use crate::angle::{atan2_approx, clear_of_edges};
use crate::refine::plane_fit;
use crate::search::NearestGrid;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// A cloud whose keypoints are thinner than this many voxels in their thinnest direction
/// (the square root of the smallest covariance eigenvalue) is flat or linear: its features
/// cannot fix a pose, so it gets none.
const MIN_THICKNESS_VOXELS: f64 = 1.0;

pub(super) fn describe(points: &[[f64; 3]], config: &FeatureConfig) -> Features {
    let finite: Vec<[f64; 3]> = points
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .copied()
        .collect();
    let keypoints = voxel_downsample(&finite, config.voxel);
    if keypoints.len() < MIN_KEYPOINTS
        || thickness(&keypoints) < MIN_THICKNESS_VOXELS * config.voxel
    {
        return Features::default();
    }
    let near = neighbourhoods(&keypoints, config);
    let normals = normals(&keypoints, &near, config);
    let descriptors = fpfh(&keypoints, &near, &normals, config);
    let mut out = Features::default();
    for ((p, n), d) in keypoints.iter().zip(&normals).zip(descriptors) {
        if let (Some(n), Some(d)) = (n, d) {
            out.points.push(*p);
            out.normals.push(*n);
            out.descriptors.push(d);
        }
    }
    if out.len() < MIN_KEYPOINTS {
        return Features::default();
    }
    out
}

/// One point per occupied voxel (cells of side `voxel` from the cloud's lower corner): the
/// mean of its points, summed in input order; voxels in lexicographic order of their cell.
pub(super) fn voxel_downsample(points: &[[f64; 3]], voxel: f64) -> Vec<[f64; 3]> {
    if points.is_empty() {
        return Vec::new();
    }
    let (lo, _) = crate::cloud::bounds(points);
    // `as` saturates, so even absurd extents cannot overflow (far cells would merge).
    let cell = |p: &[f64; 3]| -> [i64; 3] {
        std::array::from_fn(|k| ((p[k] - lo[k]) / voxel).floor() as i64)
    };
    let mut keyed: Vec<([i64; 3], u32)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (cell(p), i as u32))
        .collect();
    keyed.sort_unstable();
    let mut out = Vec::new();
    let mut start = 0;
    while start < keyed.len() {
        let key = keyed[start].0;
        let mut end = start;
        let mut sum = [0.0; 3];
        while end < keyed.len() && keyed[end].0 == key {
            let p = &points[keyed[end].1 as usize];
            for k in 0..3 {
                sum[k] += p[k];
            }
            end += 1;
        }
        let n = (end - start) as f64;
        out.push(sum.map(|s| s / n));
        start = end;
    }
    out
}

/// Square root of the smallest eigenvalue of the points' covariance: their spread in the
/// thinnest direction.
fn thickness(points: &[[f64; 3]]) -> f64 {
    let fit = plane_fit(points.iter());
    let spread: f64 = points
        .iter()
        .map(|p| fit.normal.dot(&(Vector3::from(*p) - fit.centroid)).powi(2))
        .sum::<f64>()
        / points.len().max(1) as f64;
    spread.sqrt()
}

/// Diagonal of the box of `points` aligned with their principal axes: a size that does not
/// change when the cloud is moved (0 for fewer than two finite points).
pub fn pca_diagonal(points: &[[f64; 3]]) -> f64 {
    let finite: Vec<&[f64; 3]> = points
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .collect();
    if finite.len() < 2 {
        return 0.0;
    }
    let n = finite.len() as f64;
    let mean = finite
        .iter()
        .fold(Vector3::zeros(), |a, p| a + Vector3::from(**p))
        / n;
    let cov = finite.iter().fold(Matrix3::zeros(), |a, p| {
        let d = Vector3::from(**p) - mean;
        a + d * d.transpose()
    }) / n;
    let axes = cov.symmetric_eigen().eigenvectors;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &finite {
        let d = Vector3::from(**p) - mean;
        for k in 0..3 {
            let x = axes.column(k).dot(&d);
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
        }
    }
    (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
}

/// Each keypoint's neighbours (index, squared distance; itself included), nearest first
/// (equally near ones by index): those within the larger of the normals' and the features'
/// radius, at most the larger of their counts. One query serves both: each takes the prefix
/// it needs ([`within`]). A grid of cells as wide as the radius finds them (the 27 cells
/// around a keypoint hold them all) in less time than a KD-tree's nearest-n query.
fn neighbourhoods(points: &[[f64; 3]], config: &FeatureConfig) -> Vec<Vec<(u32, f64)>> {
    let most = config
        .normal_max_neighbours
        .max(config.feature_max_neighbours);
    let radius = config.normal_radius.max(config.feature_radius);
    let grid = NearestGrid::new(points, radius);
    points
        .par_iter()
        .with_min_len(64)
        .map(|p| {
            // Sorted by (squared distance, index), the distance's bits standing in for it
            // (non-negative floats order as their bits do): a plain sort of integer pairs.
            let mut hood: Vec<(u64, u32)> = Vec::new();
            grid.each_within(p, radius * radius, |i, d2| hood.push((d2.to_bits(), i)));
            if hood.len() > most {
                hood.select_nth_unstable(most - 1);
                hood.truncate(most);
            }
            hood.sort_unstable();
            hood.into_iter()
                .map(|(d2, i)| (i, f64::from_bits(d2)))
                .collect()
        })
        .collect()
}

/// The nearest `count` of a keypoint's `neighbourhood` within `radius`: what a query for them
/// alone finds, as the neighbourhood holds at least as many, nearest first.
fn within(
    neighbourhood: &[(u32, f64)],
    radius: f64,
    count: usize,
) -> impl Iterator<Item = &(u32, f64)> + Clone {
    let r2 = radius * radius;
    neighbourhood
        .iter()
        .take_while(move |(_, d2)| *d2 <= r2)
        .take(count)
}

/// The unit normal of each keypoint from a plane fit over its neighbours within
/// `normal_radius` (at most `normal_max_neighbours`, itself included), signed by
/// `orientation`; `None` with fewer than three neighbours.
fn normals(
    points: &[[f64; 3]],
    near: &[Vec<(u32, f64)>],
    config: &FeatureConfig,
) -> Vec<Option<[f64; 3]>> {
    let centroid = points
        .iter()
        .fold(Vector3::zeros(), |a, p| a + Vector3::from(*p))
        / points.len() as f64;
    let sign = match config.orientation {
        NormalOrientation::AwayFromCentroid => 1.0,
        NormalOrientation::TowardsCentroid => -1.0,
    };
    points
        .par_iter()
        .zip(near)
        .with_min_len(64)
        .map(|(p, hood)| {
            let nn = || within(hood, config.normal_radius, config.normal_max_neighbours);
            if nn().count() < 3 {
                return None;
            }
            let mut n = plane_fit(nn().map(|&(j, _)| &points[j as usize])).normal;
            if !n.iter().all(|c| c.is_finite()) {
                return None;
            }
            if sign * n.dot(&(Vector3::from(*p) - centroid)) < 0.0 {
                n = -n;
            }
            Some([n[0], n[1], n[2]])
        })
        .collect()
}

/// The FPFH of each keypoint with a normal and at least one neighbour with a normal within
/// `feature_radius` (at most `feature_max_neighbours` points, itself included).
fn fpfh(
    points: &[[f64; 3]],
    near: &[Vec<(u32, f64)>],
    normals: &[Option<[f64; 3]>],
    config: &FeatureConfig,
) -> Vec<Option<Descriptor>> {
    // Neighbours (index, distance) of each keypoint with a normal, itself excluded.
    let neighbours: Vec<Vec<(u32, f64)>> = near
        .par_iter()
        .with_min_len(64)
        .enumerate()
        .map(|(i, hood)| {
            if normals[i].is_none() {
                return Vec::new();
            }
            within(hood, config.feature_radius, config.feature_max_neighbours)
                .filter(|&&(j, _)| j as usize != i && normals[j as usize].is_some())
                .map(|&(j, d2)| (j, d2.sqrt()))
                .collect()
        })
        .collect();
    let spfh: Vec<[f64; LEN]> = (0..points.len())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let mut h = [0.0; LEN];
            let Some(ni) = normals[i] else { return h };
            let list = &neighbours[i];
            if list.is_empty() {
                return h;
            }
            let step = 100.0 / list.len() as f64;
            for &(j, _) in list {
                let j = j as usize;
                let nj = normals[j].expect("neighbours have normals");
                let [y, x, alpha, phi] = pair_feature_parts(&points[i], &ni, &points[j], &nj);
                h[theta_bin(y, x)] += step;
                h[BINS_PER_FEATURE + bin(alpha, -1.0, 1.0)] += step;
                h[2 * BINS_PER_FEATURE + bin(phi, -1.0, 1.0)] += step;
            }
            h
        })
        .collect();
    (0..points.len())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let list = &neighbours[i];
            if list.is_empty() {
                return None;
            }
            // The neighbours' SPFH weighted by 1 / distance (Rusu et al. 2009), each angle's
            // histogram normalised to 100 (as Open3D), plus the point's own SPFH.
            let mut sum = [0.0; LEN];
            for &(j, d) in list {
                if d > 0.0 {
                    let w = 1.0 / d;
                    for (s, v) in sum.iter_mut().zip(&spfh[j as usize]) {
                        *s += w * v;
                    }
                }
            }
            let mut out = [0.0f32; LEN];
            for f in 0..3 {
                let block = f * BINS_PER_FEATURE..(f + 1) * BINS_PER_FEATURE;
                let total: f64 = sum[block.clone()].iter().sum();
                let scale = if total > 0.0 { 100.0 / total } else { 0.0 };
                for b in block {
                    out[b] = (sum[b] * scale + spfh[i][b]) as f32;
                }
            }
            Some(out)
        })
        .collect()
}

/// Differences of direction cosines below this are ties in [`pair_features`].
const TIE: f64 = 1e-9;

/// Bin of `v` in `[lo, hi]` cut into [`BINS_PER_FEATURE`] equal bins (the ends clamped).
#[inline]
fn bin(v: f64, lo: f64, hi: f64) -> usize {
    let b = BINS_PER_FEATURE as f64 * (v - lo) / (hi - lo);
    if b.is_nan() {
        BINS_PER_FEATURE / 2
    } else {
        // `as` truncates and saturates (negatives to 0): the floor of every b >= 0, and 0
        // below, without a call to libm's `floor` (three a neighbour pair).
        (b as usize).min(BINS_PER_FEATURE - 1)
    }
}

/// The Darboux-frame angles of a pair of oriented points, `[theta, alpha, phi]` (as Open3D's
/// `ComputePairFeatures`): the frame is set at the point whose normal makes the smaller angle
/// with the line joining them, so the result does not depend on the order of the pair.
/// Zeros when the points coincide or a normal is along the line.
#[cfg(test)]
pub(super) fn pair_features(
    p1: &[f64; 3],
    n1: &[f64; 3],
    p2: &[f64; 3],
    n2: &[f64; 3],
) -> [f64; 3] {
    let [y, x, alpha, phi] = pair_feature_parts(p1, n1, p2, n2);
    [y.atan2(x), alpha, phi]
}

/// Theta's bin ([`bin`] of `atan2(y, x)` over `[-pi, pi]`) from [`atan2_approx`] wherever the
/// angle is clear of every bin edge by more than its error, else from `atan2` itself: the
/// same bin as `atan2` gives, at a fraction of its cost (it was 5 % of a 3DLoMatch pair's
/// time).
#[inline]
fn theta_bin(y: f64, x: f64) -> usize {
    use std::f64::consts::PI;
    let width = 2.0 * PI / BINS_PER_FEATURE as f64;
    let scaled = (atan2_approx(y, x) + PI) / width;
    if clear_of_edges(scaled, width) {
        (scaled as usize).min(BINS_PER_FEATURE - 1)
    } else {
        bin(y.atan2(x), -PI, PI)
    }
}

/// [`pair_features`] with theta as the two legs of its angle, `[y, x, alpha, phi]`
/// (`theta = atan2(y, x)`; zeros where it is zero).
fn pair_feature_parts(p1: &[f64; 3], n1: &[f64; 3], p2: &[f64; 3], n2: &[f64; 3]) -> [f64; 4] {
    let (p1, n1, p2, n2) = (
        Vector3::from(*p1),
        Vector3::from(*n1),
        Vector3::from(*p2),
        Vector3::from(*n2),
    );
    let mut dp = p2 - p1;
    let d = dp.norm();
    if d == 0.0 {
        return [0.0; 4];
    }
    let angle1 = n1.dot(&dp) / d;
    let angle2 = n2.dot(&dp) / d;
    // The frame goes to the point whose normal is closer to the line (the larger |angle|).
    // Equal normals (neighbours with the same plane fit) tie exactly, and rounding in another
    // frame could break the tie either way: a tie goes to the frame giving phi >= 0.
    let swap = if (angle1.abs() - angle2.abs()).abs() <= TIE {
        -angle2 > angle1
    } else {
        angle1.abs() < angle2.abs()
    };
    let (u, n_other, phi) = if swap {
        dp = -dp;
        (n2, n1, -angle2)
    } else {
        (n1, n2, angle1)
    };
    let v = dp.cross(&u);
    let vn = v.norm();
    if vn == 0.0 {
        return [0.0; 4];
    }
    let v = v / vn;
    let w = u.cross(&v);
    let alpha = v.dot(&n_other);
    [w.dot(&n_other), u.dot(&n_other), alpha, phi]
}

#[cfg(test)]
mod tests {
    use super::*;
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::num::NonZero;

    /// The normal and the FPFH each take a prefix of one neighbourhood query; each prefix must
    /// be what a query of its own radius and count finds, in the same order (the plane fit and
    /// the histogram sums depend on it).
    #[test]
    fn a_neighbourhood_prefix_is_what_its_own_query_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        // A wavy sheet (a surface, as scans are) and scattered points, dense enough that both
        // counts bind somewhere (about 250 points within the FPFH radius, 40 within the normal's).
        let mut points: Vec<[f64; 3]> = (0..8000)
            .map(|_| {
                let (x, y): (f64, f64) = (rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
                [x, y, 0.1 * (3.0 * x).sin()]
            })
            .collect();
        points.extend((0..300).map(|_| std::array::from_fn(|_| rng.random_range(0.0..2.0))));
        let config = FeatureConfig::for_spacing(0.02);
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points).expect("a tree");
        let near = neighbourhoods(&points, &config);
        let (mut full, mut compared) = ([0, 0], 0);
        for (p, hood) in points.iter().zip(&near).step_by(7) {
            for (k, (radius, count)) in [
                (config.normal_radius, config.normal_max_neighbours),
                (config.feature_radius, config.feature_max_neighbours),
            ]
            .into_iter()
            .enumerate()
            {
                let own: Vec<(u32, f64)> = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f64>>(NonZero::new(count).expect("count"))
                    .within(radius * radius)
                    .execute()
                    .iter()
                    .map(|r| (r.item, r.distance))
                    .collect();
                let prefix: Vec<(u32, f64)> = within(hood, radius, count).copied().collect();
                assert_eq!(prefix, own, "{p:?} radius {radius} count {count}");
                full[k] += usize::from(own.len() == count);
                compared += 1;
            }
        }
        // Both bounds were met: some neighbourhoods held more points than the count.
        assert!(
            compared > 1000 && full.iter().all(|&f| f > 10),
            "{compared} {full:?}"
        );
    }

    /// The bin is the floor of the scaled value, clamped to the ends, NaN in the middle.
    #[test]
    fn a_value_falls_in_the_bin_its_floor_names() {
        let by_floor = |v: f64, lo: f64, hi: f64| {
            let b = (BINS_PER_FEATURE as f64 * (v - lo) / (hi - lo)).floor();
            if b.is_nan() {
                BINS_PER_FEATURE / 2
            } else {
                (b.max(0.0) as usize).min(BINS_PER_FEATURE - 1)
            }
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let pi = std::f64::consts::PI;
        let mut values: Vec<f64> = (0..100_000).map(|_| rng.random_range(-4.0..4.0)).collect();
        values.extend([
            -pi,
            pi,
            -1.0,
            1.0,
            0.0,
            -0.0,
            -1e-300,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ]);
        for k in 0..=BINS_PER_FEATURE {
            values.push(-1.0 + 2.0 * k as f64 / BINS_PER_FEATURE as f64);
        }
        for v in values {
            for (lo, hi) in [(-pi, pi), (-1.0, 1.0)] {
                assert_eq!(bin(v, lo, hi), by_floor(v, lo, hi), "{v} in [{lo}, {hi}]");
            }
        }
    }

    /// Theta's bin from the approximated angle is the bin of `atan2` itself: at random, at
    /// and next to every bin edge (where the exact angle decides), at signed zeros and at
    /// numbers that are not.
    #[test]
    fn theta_falls_in_the_bin_atan2_gives() {
        use std::f64::consts::PI;
        let exact = |y: f64, x: f64| bin(y.atan2(x), -PI, PI);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut legs: Vec<(f64, f64)> = (0..200_000)
            .map(|_| (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)))
            .collect();
        for k in 0..=BINS_PER_FEATURE {
            let edge = -PI + 2.0 * PI * k as f64 / BINS_PER_FEATURE as f64;
            for offset in [-1e-3, -1e-5, -1e-9, -1e-15, 0.0, 1e-15, 1e-9, 1e-5, 1e-3] {
                for scale in [1e-200, 0.3, 1.0, 7e150] {
                    let a = edge + offset;
                    legs.push((scale * a.sin(), scale * a.cos()));
                }
            }
        }
        for y in [0.0, -0.0, 1.0, -1.0, f64::INFINITY, f64::NAN] {
            for x in [0.0, -0.0, 1.0, -1.0, f64::NEG_INFINITY, f64::NAN] {
                legs.push((y, x));
            }
        }
        for (y, x) in legs {
            assert_eq!(theta_bin(y, x), exact(y, x), "atan2({y}, {x})");
        }
    }
}
