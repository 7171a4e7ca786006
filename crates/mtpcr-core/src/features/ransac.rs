//! Descriptor matching and RANSAC over triples of matches, keeping the best distinct poses.

use super::{Candidate, Descriptor, FeatureConfig, Features, DESCRIPTOR_LEN, MIN_MUTUAL_MATCHES};
use crate::se3::Rigid;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Draws evaluated between two checks of the stopping rule (and drawn on one thread first).
const BATCH: usize = 2048;
/// Distinct hypotheses kept during the search per candidate asked for: refitting reorders
/// them, so more are kept than returned.
const POOL_PER_CANDIDATE: usize = 3;
/// Rounds of refitting on the matches that are inliers of the current pose.
const MATCH_REFITS: usize = 5;
/// Rounds of point-to-point ICP on the keypoints after the match refits.
const ICP_ROUNDS: usize = 5;
/// A triple whose source triangle is lower than this many inlier distances (its area over its
/// longest edge) fixes the rotation about that edge poorly; it is not tried.
const MIN_TRIANGLE_HEIGHT: f64 = 1.0;

/// A pose and its score: the number of matches it maps within the inlier distance.
#[derive(Clone, Copy, Debug)]
struct Hypothesis {
    score: usize,
    pose: Rigid,
}

pub(super) fn candidates(
    source: &Features,
    target: &Features,
    config: &FeatureConfig,
) -> Vec<Candidate> {
    if source.len() < 3 || target.len() < 3 {
        return Vec::new();
    }
    let matches = match_descriptors(
        &source.descriptors,
        &target.descriptors,
        config.mutual_filter,
    );
    if matches.len() < 3 {
        return Vec::new();
    }
    let src: Vec<[f64; 3]> = matches
        .iter()
        .map(|m| source.points[m.0 as usize])
        .collect();
    let tgt: Vec<[f64; 3]> = matches
        .iter()
        .map(|m| target.points[m.1 as usize])
        .collect();
    let centre = mean(&source.points);
    let same = |a: &Rigid, b: &Rigid| similar(a, b, &centre, config);
    let pool = search(&src, &tgt, config, &same);
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&target.points) else {
        return Vec::new();
    };
    let mut refined: Vec<Candidate> = pool
        .par_iter()
        .map(|h| refine(h.pose, &src, &tgt, source, target, &tree, config))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    // Stable: equal scores keep the search's order.
    refined.sort_by(|a, b| rank_key(b).total_cmp(&rank_key(a)));
    let mut out: Vec<(Candidate, Rigid)> = Vec::new();
    for c in refined {
        let r = Rigid::from_matrix(&c.t_target_source);
        if !out.iter().any(|(_, k)| same(k, &r)) {
            out.push((c, r));
            if out.len() == config.num_candidates {
                break;
            }
        }
    }
    out.into_iter().map(|(c, _)| c).collect()
}

/// What candidates are ranked by (larger is better).
fn rank_key(c: &Candidate) -> f64 {
    c.matches as f64
}

/// Pairs (source index, target index) of nearest neighbours in descriptor space; with
/// `mutual`, only pairs that are each other's nearest, unless fewer than
/// [`MIN_MUTUAL_MATCHES`] are.
fn match_descriptors(
    source: &[Descriptor],
    target: &[Descriptor],
    mutual: bool,
) -> Vec<(u32, u32)> {
    let (Ok(target_tree), Ok(source_tree)) = (
        ImmutableKdTree::<f32, DESCRIPTOR_LEN>::new_from_slice(target),
        ImmutableKdTree::<f32, DESCRIPTOR_LEN>::new_from_slice(source),
    ) else {
        return Vec::new();
    };
    let nearest =
        |tree: &ImmutableKdTree<f32, DESCRIPTOR_LEN>, queries: &[Descriptor]| -> Vec<u32> {
            queries
                .par_iter()
                .with_min_len(64)
                .map(|q| {
                    tree.query(q)
                        .nearest_one::<SquaredEuclidean<f32>>()
                        .execute()
                        .item
                })
                .collect()
        };
    let forward = nearest(&target_tree, source);
    let one_way: Vec<(u32, u32)> = forward
        .iter()
        .enumerate()
        .map(|(i, &j)| (i as u32, j))
        .collect();
    if !mutual {
        return one_way;
    }
    let backward = nearest(&source_tree, target);
    let both: Vec<(u32, u32)> = one_way
        .iter()
        .copied()
        .filter(|&(i, j)| backward[j as usize] == i)
        .collect();
    if both.len() >= MIN_MUTUAL_MATCHES {
        both
    } else {
        one_way
    }
}

/// RANSAC over triples of matches: the best distinct hypotheses by score, best first.
fn search(
    src: &[[f64; 3]],
    tgt: &[[f64; 3]],
    config: &FeatureConfig,
    same: &(impl Fn(&Rigid, &Rigid) -> bool + Sync),
) -> Vec<Hypothesis> {
    let m = src.len();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut pool = Pool {
        kept: Vec::new(),
        capacity: (POOL_PER_CANDIDATE * config.num_candidates).max(10),
    };
    let mut needed = config.max_iterations;
    let mut done = 0;
    while done < needed {
        let batch = BATCH.min(needed - done);
        let draws: Vec<[usize; 3]> = (0..batch).map(|_| draw_three(&mut rng, m)).collect();
        let found: Vec<Option<Hypothesis>> = draws
            .par_iter()
            .with_min_len(32)
            .map(|d| try_triple(d, src, tgt, config))
            .collect();
        for h in found.into_iter().flatten() {
            pool.offer(h, same);
        }
        done += batch;
        if let Some(best) = pool.kept.first() {
            needed = needed.min(draws_needed(
                best.score,
                m,
                config.confidence,
                config.max_iterations,
            ));
        }
    }
    pool.kept
}

/// Draws for a triple of inliers to be seen with probability `confidence` when `inliers` of
/// `m` matches are inliers (Open3D's rule), capped at `max`.
fn draws_needed(inliers: usize, m: usize, confidence: f64, max: usize) -> usize {
    let w = inliers as f64 / m as f64;
    let p = w * w * w;
    if p >= 1.0 {
        return 1;
    }
    let k = (1.0 - confidence).ln() / (1.0 - p).ln();
    if k.is_finite() && k < max as f64 {
        k.ceil().max(1.0) as usize
    } else {
        max
    }
}

/// Three distinct indices below `m` (>= 3).
fn draw_three(rng: &mut ChaCha8Rng, m: usize) -> [usize; 3] {
    let a = rng.random_range(0..m);
    let mut b = rng.random_range(0..m - 1);
    if b >= a {
        b += 1;
    }
    let (lo, hi) = (a.min(b), a.max(b));
    let mut c = rng.random_range(0..m - 2);
    if c >= lo {
        c += 1;
    }
    if c >= hi {
        c += 1;
    }
    [a, b, c]
}

/// The hypothesis of one triple of matches, if it passes the checks: similar edge lengths,
/// a triangle that is not too thin, every match within the inlier distance after the fit.
fn try_triple(
    d: &[usize; 3],
    src: &[[f64; 3]],
    tgt: &[[f64; 3]],
    config: &FeatureConfig,
) -> Option<Hypothesis> {
    let s = d.map(|i| Vector3::from(src[i]));
    let t = d.map(|i| Vector3::from(tgt[i]));
    let ratio = config.edge_length_ratio;
    let mut longest: f64 = 0.0;
    for (a, b) in [(0, 1), (1, 2), (2, 0)] {
        let ls = (s[a] - s[b]).norm();
        let lt = (t[a] - t[b]).norm();
        if ls < ratio * lt || lt < ratio * ls {
            return None;
        }
        longest = longest.max(ls);
    }
    let area2 = (s[1] - s[0]).cross(&(s[2] - s[0])).norm();
    if area2 < MIN_TRIANGLE_HEIGHT * config.inlier_distance * longest {
        return None;
    }
    let pose = kabsch(d.iter().map(|&i| (&src[i], &tgt[i])))?;
    let d2 = config.inlier_distance * config.inlier_distance;
    if d.iter().any(|&i| dist2(&pose.apply(&src[i]), &tgt[i]) > d2) {
        return None;
    }
    let score = count_inliers(&pose, src, tgt, d2);
    Some(Hypothesis { score, pose })
}

fn count_inliers(pose: &Rigid, src: &[[f64; 3]], tgt: &[[f64; 3]], d2: f64) -> usize {
    src.iter()
        .zip(tgt)
        .filter(|(s, t)| dist2(&pose.apply(s), t) <= d2)
        .count()
}

/// Refits `pose` on the matches it explains, then by point-to-point ICP on the keypoints
/// (inliers within the inlier distance), and scores it. `None` when a refit degenerates.
fn refine(
    mut pose: Rigid,
    src: &[[f64; 3]],
    tgt: &[[f64; 3]],
    source: &Features,
    target: &Features,
    tree: &ImmutableKdTree<f64, 3>,
    config: &FeatureConfig,
) -> Option<Candidate> {
    let d2 = config.inlier_distance * config.inlier_distance;
    let mut last = 0;
    for _ in 0..MATCH_REFITS {
        let inliers: Vec<(&[f64; 3], &[f64; 3])> = src
            .iter()
            .zip(tgt)
            .filter(|(s, t)| dist2(&pose.apply(s), t) <= d2)
            .collect();
        if inliers.len() < 3 || inliers.len() == last {
            break;
        }
        last = inliers.len();
        pose = kabsch(inliers.into_iter())?;
    }
    let nearest = |pose: &Rigid| -> Vec<(usize, usize, f64)> {
        source
            .points
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let nn = tree
                    .query(&pose.apply(p))
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute();
                (nn.distance <= d2).then_some((i, nn.item as usize, nn.distance))
            })
            .collect()
    };
    for _ in 0..ICP_ROUNDS {
        let pairs = nearest(&pose);
        if pairs.len() < 3 {
            break;
        }
        let next = kabsch(
            pairs
                .iter()
                .map(|&(i, j, _)| (&source.points[i], &target.points[j])),
        )?;
        pose = next;
    }
    let pairs = nearest(&pose);
    let inliers = pairs.len();
    let rmse = if inliers > 0 {
        (pairs.iter().map(|p| p.2).sum::<f64>() / inliers as f64).sqrt()
    } else {
        0.0
    };
    Some(Candidate {
        t_target_source: pose.to_matrix(),
        inliers,
        fitness: inliers as f64 / source.len() as f64,
        rmse,
        matches: count_inliers(&pose, src, tgt, d2),
    })
}

/// The best distinct hypotheses seen, by score (ties: the first seen).
struct Pool {
    kept: Vec<Hypothesis>,
    capacity: usize,
}

impl Pool {
    fn offer(&mut self, h: Hypothesis, same: &impl Fn(&Rigid, &Rigid) -> bool) {
        if self.kept.len() == self.capacity && self.kept.last().is_some_and(|l| l.score >= h.score)
        {
            return;
        }
        if self
            .kept
            .iter()
            .any(|k| k.score >= h.score && same(&k.pose, &h.pose))
        {
            return;
        }
        self.kept.retain(|k| !same(&k.pose, &h.pose));
        let at = self.kept.partition_point(|k| k.score >= h.score);
        self.kept.insert(at, h);
        self.kept.truncate(self.capacity);
    }
}

/// Two poses are the same candidate: their rotations differ by less than the NMS angle and
/// they move `centre` (the source centroid) to within the NMS distance of each other.
fn similar(a: &Rigid, b: &Rigid, centre: &[f64; 3], config: &FeatureConfig) -> bool {
    if dist2(&a.apply(centre), &b.apply(centre)) >= config.nms_distance * config.nms_distance {
        return false;
    }
    rotation_angle_deg(a, b) < config.nms_angle_deg
}

/// Angle of `R_a^T R_b` in degrees.
pub(super) fn rotation_angle_deg(a: &Rigid, b: &Rigid) -> f64 {
    let mut trace = 0.0;
    for i in 0..3 {
        for k in 0..3 {
            trace += a.r[k][i] * b.r[k][i];
        }
    }
    ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The least-squares rigid motion taking the first point of each pair onto the second
/// (Kabsch: SVD of the cross-covariance, determinant +1). `None` for fewer than three pairs or
/// a failed decomposition.
pub(super) fn kabsch<'a>(
    pairs: impl Iterator<Item = (&'a [f64; 3], &'a [f64; 3])> + Clone,
) -> Option<Rigid> {
    let mut n = 0usize;
    let (mut ms, mut mt) = (Vector3::zeros(), Vector3::zeros());
    for (s, t) in pairs.clone() {
        ms += Vector3::from(*s);
        mt += Vector3::from(*t);
        n += 1;
    }
    if n < 3 {
        return None;
    }
    ms /= n as f64;
    mt /= n as f64;
    let mut h = Matrix3::zeros();
    for (s, t) in pairs {
        h += (Vector3::from(*s) - ms) * (Vector3::from(*t) - mt).transpose();
    }
    let svd = h.try_svd(true, true, 1e-12, 100)?;
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    d[(2, 2)] = (v_t.transpose() * u.transpose()).determinant().signum();
    let r = v_t.transpose() * d * u.transpose();
    let t = mt - r * ms;
    if !(r.iter().all(|v| v.is_finite()) && t.iter().all(|v| v.is_finite())) {
        return None;
    }
    Some(Rigid {
        r: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
        t: [t[0], t[1], t[2]],
    })
}

fn mean(points: &[[f64; 3]]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for p in points {
        for k in 0..3 {
            m[k] += p[k];
        }
    }
    m.map(|v| v / points.len().max(1) as f64)
}

#[inline(always)]
fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let dx = a[0] - b[0];
    let dy = a[1] - b[1];
    let dz = a[2] - b[2];
    dx * dx + dy * dy + dz * dz
}
