//! Descriptor matching, RANSAC over triples of matches keeping the best distinct poses, and
//! their refinement and ranking.

use super::{Candidate, Descriptor, FeatureConfig, Features, Matching};
use super::{DESCRIPTOR_LEN, MIN_MUTUAL_MATCHES};
use crate::se3::Rigid;
use crate::search::{dispatch_by_lanes, Lanes, LastQuery, NearestGrid};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Draws evaluated between two checks of the stopping rule (and drawn on one thread first).
const BATCH: usize = 2048;
/// Distinct hypotheses kept during the search per candidate asked for: refining reorders
/// them, so more are kept than returned (6 instead of 3 finds a true pose in the top 10 for
/// one 96-degree turntable pair in 30 more, for twice the refining time).
pub(super) const POOL_PER_CANDIDATE: usize = 3;
/// The same for the screening of a set of scans' pairs, where each pair counts less: the
/// hypotheses of many pairs around loops place a scan. Refining one pose per candidate
/// instead of three gave the five visible 3DMatch rooms the same placements on three seeds
/// in 0.75 of the time (RESULTS.md, 2026-12-05, second session).
pub(super) const SCREENING_POOL_PER_CANDIDATE: usize = 1;
/// Rounds of refitting on the matches that are inliers of the current pose.
const MATCH_REFITS: usize = 5;
/// The ICP's pairing distance shrinks linearly from the inlier distance to this fraction of
/// it, so that the surfaces that do not overlap stop pulling once the pose is close (with a
/// fixed distance a pose started at the truth of a 96-degree turntable pair drifts 5-14
/// degrees away; shrinking to half keeps most within 3).
const ICP_FINAL_FRACTION: f64 = 0.5;
/// A triple whose source triangle is lower than this many inlier distances (its area over its
/// longest edge) fixes the rotation about that edge poorly; it is not tried.
const MIN_TRIANGLE_HEIGHT: f64 = 1.0;
/// Source descriptors handled together by [`nearest_both_ways`].
const MATCH_ROWS: usize = 64;

/// Source descriptors whose distances the matching sums together (`MATCH_ROWS` a multiple).
const ROWS_AT_ONCE: usize = 4;

/// A pose and its score: the number of matches it maps within the inlier distance.
#[derive(Clone, Copy, Debug)]
struct Hypothesis {
    score: usize,
    pose: Rigid,
}

/// The matched keypoints side by side (match k pairs `src[k]` with `tgt[k]`), with the
/// inlier tests.
struct Matched {
    src: Vec<[f64; 3]>,
    tgt: Vec<[f64; 3]>,
    src_n: Vec<[f64; 3]>,
    tgt_n: Vec<[f64; 3]>,
    /// Squared inlier distance.
    d2: f64,
    /// Cosine of the largest angle between the normals of an inlier.
    cos_min: f64,
}

impl Matched {
    fn new(
        pairs: &[(u32, u32)],
        source: &Features,
        target: &Features,
        config: &FeatureConfig,
    ) -> Matched {
        let pick = |values: &[[f64; 3]], side: fn(&(u32, u32)) -> u32| -> Vec<[f64; 3]> {
            pairs.iter().map(|p| values[side(p) as usize]).collect()
        };
        Matched {
            src: pick(&source.points, |p| p.0),
            tgt: pick(&target.points, |p| p.1),
            src_n: pick(&source.normals, |p| p.0),
            tgt_n: pick(&target.normals, |p| p.1),
            d2: config.inlier_distance * config.inlier_distance,
            cos_min: config.max_normal_angle_deg.to_radians().cos(),
        }
    }

    fn len(&self) -> usize {
        self.src.len()
    }

    /// Does `pose` map match `k` within `sqrt(d2)`, with the normals agreeing?
    #[inline(always)]
    fn fits(&self, k: usize, pose: &Rigid, d2: f64) -> bool {
        dist2(&pose.apply(&self.src[k]), &self.tgt[k]) <= d2
            && normals_agree(pose, &self.src_n[k], &self.tgt_n[k], self.cos_min)
    }

    /// Matches that `pose` fits within `sqrt(d2)`.
    fn count(&self, pose: &Rigid, d2: f64) -> usize {
        (0..self.len()).filter(|&k| self.fits(k, pose, d2)).count()
    }
}

/// The descriptor matches of a pair, with what [`support`] needs.
pub(super) struct PairMatchSet {
    matched: Matched,
    /// Source keypoint centroid: where two poses are compared ([`similar`]).
    centre: [f64; 3],
}

/// Matches the features of a pair as `config.matching` says.
pub(super) fn match_pair(
    source: &Features,
    target: &Features,
    config: &FeatureConfig,
) -> PairMatchSet {
    let pairs = if source.len() < 3 || target.len() < 3 {
        Vec::new()
    } else {
        match_descriptors(&source.descriptors, &target.descriptors, config.matching)
    };
    PairMatchSet {
        matched: Matched::new(&pairs, source, target, config),
        centre: mean(&source.points),
    }
}

impl PairMatchSet {
    /// Matches that `pose` maps within half the inlier distance, normals agreeing (the
    /// ranking score of the candidates, [`Candidate::matches`]).
    pub(super) fn support(&self, pose: &Rigid) -> usize {
        self.matched.count(pose, self.matched.d2 / 4.0)
    }

    /// Matches that `pose` fits within a quarter of the inlier distance.
    pub(super) fn tight_support(&self, pose: &Rigid) -> usize {
        self.matched.count(pose, self.matched.d2 / 16.0)
    }

    /// Matches whose source keypoint `pose` puts where `on_target` holds.
    pub(super) fn landed(&self, pose: &Rigid, on_target: impl Fn(&[f64; 3]) -> bool) -> usize {
        self.matched
            .src
            .iter()
            .filter(|p| on_target(&pose.apply(p)))
            .count()
    }

    /// Are `a` and `b` the same candidate ([`FeatureConfig::nms_angle_deg`] and
    /// [`FeatureConfig::nms_distance`])?
    pub(super) fn same(&self, a: &Rigid, b: &Rigid, config: &FeatureConfig) -> bool {
        similar(a, b, &self.centre, config)
    }
}

pub(super) fn candidates(
    set: &PairMatchSet,
    source: &Features,
    target: &Features,
    config: &FeatureConfig,
    keep: &(dyn Fn(&Rigid) -> bool + Sync),
    pool_per_candidate: usize,
) -> Vec<Candidate> {
    let matched = &set.matched;
    if matched.len() < 3 {
        return Vec::new();
    }
    let same = |a: &Rigid, b: &Rigid| set.same(a, b, config);
    let capacity = (pool_per_candidate * config.num_candidates).max(10);
    let pool = search(matched, config, &same, keep, capacity);
    // The refinement pairs keypoints within the inlier distance at most.
    let grid = NearestGrid::new(&target.points, matched.d2.sqrt());
    let mut refined: Vec<Candidate> = pool
        .par_iter()
        .map(|h| refine(h.pose, matched, source, target, &grid, config))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    // Stable: equal scores keep the search's order.
    refined.sort_by_key(|c| std::cmp::Reverse((c.matches, c.inliers)));
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

/// Pairs (source index, target index) of nearest neighbours in descriptor space, as
/// `matching` says.
fn match_descriptors(
    source: &[Descriptor],
    target: &[Descriptor],
    matching: Matching,
) -> Vec<(u32, u32)> {
    let (forward, backward) = nearest_both_ways(source, target);
    let one_way: Vec<(u32, u32)> = forward
        .iter()
        .enumerate()
        .map(|(i, &j)| (i as u32, j))
        .collect();
    match matching {
        Matching::Forward => one_way,
        Matching::BothWays => {
            let mut all = one_way;
            all.extend(backward.iter().enumerate().map(|(j, &i)| (i, j as u32)));
            all.sort_unstable();
            all.dedup();
            all
        }
        Matching::Mutual => {
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
    }
}

/// A block of source rows' nearest targets, and each target's (distance, nearest row) in it.
type BlockNearest = (Vec<u32>, Vec<(f32, u32)>);

/// The nearest target descriptor of every source descriptor and the nearest source descriptor
/// of every target descriptor (squared Euclidean distance; ties go to the lower index), by
/// brute force over the distance matrix. The targets are stored one dimension at a time so
/// that the inner loop runs over targets and vectorises: in 33 dimensions this is three times
/// faster than two KD-tree (kiddo) searches, with the same matches.
fn nearest_both_ways(source: &[Descriptor], target: &[Descriptor]) -> (Vec<u32>, Vec<u32>) {
    let nt = target.len();
    let mut columns = vec![0.0f32; DESCRIPTOR_LEN * nt];
    for (j, d) in target.iter().enumerate() {
        for (k, v) in d.iter().enumerate() {
            columns[k * nt + j] = *v;
        }
    }
    let columns = DescriptorColumns {
        columns,
        nt,
        lanes: Lanes::widest(),
    };
    // Per block of source rows: each row's nearest target, and each target's nearest row in
    // the block as (distance, row). Merging blocks by the smaller (distance, row) gives the
    // same answer in any order.
    let blocks: Vec<BlockNearest> = source
        .par_chunks(MATCH_ROWS)
        .enumerate()
        .map(|(b, rows)| columns.block_nearest(b * MATCH_ROWS, rows))
        .collect();
    let mut forward = Vec::with_capacity(source.len());
    let mut best_row = vec![(f32::INFINITY, 0u32); nt];
    for (nearest, rows) in blocks {
        forward.extend(nearest);
        for (best, r) in best_row.iter_mut().zip(rows) {
            if r.0 < best.0 {
                *best = r;
            }
        }
    }
    (forward, best_row.into_iter().map(|(_, i)| i).collect())
}

/// Target descriptors one dimension at a time (`columns[k * nt + j]`: dimension `k` of
/// target `j`), and the widest vectors this CPU runs.
struct DescriptorColumns {
    columns: Vec<f32>,
    nt: usize,
    lanes: Lanes,
}

impl DescriptorColumns {
    /// For source rows `first..first + rows.len()`: each row's nearest target, and each
    /// target's nearest row among them as (distance, row).
    #[inline(always)]
    fn block_nearest_portable(&self, first: usize, rows: &[Descriptor]) -> BlockNearest {
        let nt = self.nt;
        let mut best_row = vec![(f32::INFINITY, u32::MAX); nt];
        let mut nearest = Vec::with_capacity(rows.len());
        // Four rows' distances at once: each column value loaded once serves four rows (the
        // loop is bound by loading the columns); every sum still runs over the dimensions in
        // order.
        let mut dist = vec![0.0f32; ROWS_AT_ONCE * nt];
        for (g, group) in rows.chunks(ROWS_AT_ONCE).enumerate() {
            dist.iter_mut().for_each(|d| *d = 0.0);
            if let [q0, q1, q2, q3] = group {
                let (d0, rest) = dist.split_at_mut(nt);
                let (d1, rest) = rest.split_at_mut(nt);
                let (d2, d3) = rest.split_at_mut(nt);
                for k in 0..DESCRIPTOR_LEN {
                    let col = &self.columns[k * nt..(k + 1) * nt];
                    let (a0, a1, a2, a3) = (q0[k], q1[k], q2[k], q3[k]);
                    for ((((&c, e0), e1), e2), e3) in col
                        .iter()
                        .zip(d0.iter_mut())
                        .zip(d1.iter_mut())
                        .zip(d2.iter_mut())
                        .zip(d3.iter_mut())
                    {
                        *e0 += (a0 - c) * (a0 - c);
                        *e1 += (a1 - c) * (a1 - c);
                        *e2 += (a2 - c) * (a2 - c);
                        *e3 += (a3 - c) * (a3 - c);
                    }
                }
            } else {
                for (q, d) in group.iter().zip(dist.chunks_mut(nt)) {
                    for (k, &a) in q.iter().enumerate() {
                        let col = &self.columns[k * nt..(k + 1) * nt];
                        for (d, &c) in d.iter_mut().zip(col) {
                            *d += (a - c) * (a - c);
                        }
                    }
                }
            }
            for (r, d) in dist.chunks(nt).take(group.len()).enumerate() {
                let i = (first + g * ROWS_AT_ONCE + r) as u32;
                let (mut arg, mut min) = (0u32, f32::INFINITY);
                for (j, (&d, best)) in d.iter().zip(best_row.iter_mut()).enumerate() {
                    if d < min {
                        (arg, min) = (j as u32, d);
                    }
                    if d < best.0 {
                        *best = (d, i);
                    }
                }
                nearest.push(arg);
            }
        }
        (nearest, best_row)
    }
}

// `block_nearest`: `block_nearest_portable` as compiled for the widest vectors (the same sums
// in the same order, so the same matches bit for bit).
dispatch_by_lanes!(
    DescriptorColumns,
    fn block_nearest(&self, first: usize, rows: &[Descriptor]) -> BlockNearest
        => block_nearest_portable
);

/// RANSAC over triples of matches: the best `capacity` distinct hypotheses by score, best
/// first.
fn search(
    matched: &Matched,
    config: &FeatureConfig,
    same: &(impl Fn(&Rigid, &Rigid) -> bool + Sync),
    keep: &(dyn Fn(&Rigid) -> bool + Sync),
    capacity: usize,
) -> Vec<Hypothesis> {
    let m = matched.len();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut pool = Pool {
        kept: Vec::new(),
        capacity,
    };
    let mut needed = config.max_iterations;
    let mut done = 0;
    while done < needed {
        let batch = BATCH.min(needed - done);
        let draws: Vec<[usize; 3]> = (0..batch).map(|_| draw_three(&mut rng, m)).collect();
        // Only a hypothesis that could enter the pool is worth `keep`'s time.
        let floor = match pool.kept.last() {
            Some(last) if pool.full() => last.score,
            _ => 0,
        };
        let found: Vec<Option<Hypothesis>> = draws
            .par_iter()
            .with_min_len(32)
            .map(|d| try_triple(d, matched, config).filter(|h| h.score > floor && keep(&h.pose)))
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
    // Where RANSAC could not reach its confidence (too few inliers among the matches: a
    // scene pair at low overlap), the compatibility graph's seeds search on; where it could
    // (the object scans), they would add nothing but time.
    if done < config.max_iterations {
        return pool.kept;
    }
    let mut found = consensus_hypotheses(matched, config);
    // Best first, so that `keep` is asked only about poses that would enter the pool.
    found.sort_by_key(|h| std::cmp::Reverse(h.score));
    let mut rest = found.into_iter().peekable();
    loop {
        // The next few that could enter the pool, their `keep` asked in parallel.
        let mut batch = Vec::new();
        while batch.len() < KEEP_BATCH {
            let Some(h) = rest.next_if(|h| {
                !(pool.full() && pool.kept.last().is_some_and(|l| l.score >= h.score))
            }) else {
                break;
            };
            if !pool.covers(&h, same) {
                batch.push(h);
            }
        }
        if batch.is_empty() {
            break;
        }
        let kept: Vec<bool> = batch.par_iter().map(|h| keep(&h.pose)).collect();
        for (h, k) in batch.into_iter().zip(kept) {
            if k {
                pool.offer(h, same);
            }
        }
    }
    pool.kept
}

/// Hypotheses whose `keep` is asked together.
const KEEP_BATCH: usize = 16;
/// Matches joined to each seed: those sharing the most compatible matches with it.
const CONSENSUS_SIZE: usize = 30;
/// Most matches the compatibility graph is built over (a stride sample of them beyond).
const MAX_CONSENSUS_MATCHES: usize = 5000;

/// Hypotheses from the compatibility graph of the matches, as SC2-PCR (Chen et al., CVPR
/// 2022): two matches are compatible when they keep their distance (within the inlier
/// distance); each seed match is fitted with the [`CONSENSUS_SIZE`] compatible matches that
/// share the most compatible matches with it (second-order compatibility), then refitted on
/// those that fit; up to [`FeatureConfig::consensus_seeds`] seeds, the matches compatible
/// with the most others, no two within the inlier distance of each other on both sides.
/// Where RANSAC's triples are mostly outliers (a scene pair at 10-30 %
/// overlap), these seeds still find the true pose: on 150 3DLoMatch pairs it was among the
/// 10 candidates for 41 % of them instead of 33 %. Seeds at least twice the inlier distance
/// apart instead of once: 46.3 / 53.0 % of 300 3DLoMatch pairs registered (seeds 1 / 2)
/// instead of 47.3 / 55.7 %, in 0.15-0.17 s a pair instead of 0.22.
fn consensus_hypotheses(matched: &Matched, config: &FeatureConfig) -> Vec<Hypothesis> {
    let m = matched.len();
    if m < 3 || config.consensus_seeds == 0 {
        return Vec::new();
    }
    let stride = m.div_ceil(MAX_CONSENSUS_MATCHES);
    let ids: Vec<usize> = (0..m).step_by(stride).collect();
    let n = ids.len();
    let tau = config.inlier_distance;
    let graph = CompatibilityGraph {
        rows: compatibility(matched, &ids, tau),
        lanes: Lanes::widest(),
    };
    let rows = &graph.rows;
    let degree: Vec<u32> = rows
        .iter()
        .map(|r| r.iter().map(|w| w.count_ones()).sum())
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&a| (std::cmp::Reverse(degree[a]), a));
    let r2 = tau * tau;
    let mut seeds: Vec<usize> = Vec::new();
    for a in order {
        if seeds.len() == config.consensus_seeds || degree[a] < 2 {
            break;
        }
        let i = ids[a];
        let near = |b: &usize| {
            let j = ids[*b];
            dist2(&matched.src[i], &matched.src[j]) < r2
                && dist2(&matched.tgt[i], &matched.tgt[j]) < r2
        };
        if !seeds.iter().any(near) {
            seeds.push(a);
        }
    }
    seeds
        .par_iter()
        .filter_map(|&a| {
            let mut joined = graph.shared_neighbours(a);
            joined.sort_by_key(|&(s, b)| (std::cmp::Reverse(s), b));
            joined.truncate(CONSENSUS_SIZE);
            let mut set: Vec<usize> = std::iter::once(a)
                .chain(joined.iter().map(|&(_, b)| b))
                .map(|b| ids[b])
                .collect();
            let mut pose = kabsch(set.iter().map(|&k| (&matched.src[k], &matched.tgt[k])))?;
            for _ in 0..3 {
                set.retain(|&k| matched.fits(k, &pose, matched.d2));
                pose = kabsch(set.iter().map(|&k| (&matched.src[k], &matched.tgt[k])))?;
            }
            let score = matched.count(&pose, matched.d2);
            Some(Hypothesis { score, pose })
        })
        .collect()
}

/// Bit rows of the compatibility graph of the matches `ids`: bit `b` of row `a` is set when
/// matches `ids[a]` and `ids[b]` (a != b) keep their distance within `tau` on both sides.
fn compatibility(matched: &Matched, ids: &[usize], tau: f64) -> Vec<Vec<u64>> {
    compatibility_with(matched, ids, tau, Lanes::widest())
}

/// [`compatibility`] computed by the copy `lanes` of the row test.
fn compatibility_with(matched: &Matched, ids: &[usize], tau: f64, lanes: Lanes) -> Vec<Vec<u64>> {
    // Single precision, one coordinate at a time, so that the inner loop vectorises; about
    // the points' centroid, so that far-off coordinates (a survey's) keep their precision.
    let column = |v: &[[f64; 3]], k: usize| -> Vec<f32> {
        let centre = ids.iter().map(|&i| v[i][k]).sum::<f64>() / ids.len().max(1) as f64;
        ids.iter().map(|&i| (v[i][k] - centre) as f32).collect()
    };
    let ends = MatchEnds {
        s: [0, 1, 2].map(|k| column(&matched.src, k)),
        t: [0, 1, 2].map(|k| column(&matched.tgt, k)),
        tau: tau as f32,
        lanes,
    };
    let n = ids.len();
    let words = n.div_ceil(64);
    // Each row from its own block of 64 on (half the work): the test is symmetric to the
    // last bit (the same squares summed in the same order), so the blocks left of the
    // diagonal are filled in below from the rows above them.
    let mut rows: Vec<Vec<u64>> = (0..n)
        .into_par_iter()
        .with_min_len(16)
        .map(|a| ends.row_from_diagonal(a))
        .collect();
    // Block (rows of block a, word b) is the transpose of block (rows of block b, word a).
    for wa in 1..words {
        for wb in 0..wa {
            let mut block = [0u64; 64];
            for (k, x) in block.iter_mut().enumerate() {
                *x = rows[wb * 64 + k][wa];
            }
            transpose_bits(&mut block);
            for (row, x) in rows[wa * 64..].iter_mut().zip(block) {
                row[wb] = x;
            }
        }
    }
    rows
}

/// The compatibility graph's bit rows ([`compatibility`]).
struct CompatibilityGraph {
    rows: Vec<Vec<u64>>,
    lanes: Lanes,
}

impl CompatibilityGraph {
    /// Each neighbour `b` of match `a` with the number of neighbours they share
    /// (second-order compatibility), in `b`'s order.
    #[inline(always)]
    fn shared_neighbours_portable(&self, a: usize) -> Vec<(u32, usize)> {
        let row = &self.rows[a];
        let mut joined: Vec<(u32, usize)> = Vec::new();
        for (w, &word) in row.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let b = w * 64 + bits.trailing_zeros() as usize;
                let shared = row
                    .iter()
                    .zip(&self.rows[b])
                    .map(|(x, y)| (x & y).count_ones());
                joined.push((shared.sum::<u32>(), b));
                bits &= bits - 1;
            }
        }
        joined
    }
}

// `shared_neighbours`: compiled with POPCNT and wider vectors where the CPU has them (the
// baseline x86-64 counts bits without POPCNT); integer counts, the same on every copy.
dispatch_by_lanes!(
    CompatibilityGraph,
    fn shared_neighbours(&self, a: usize) -> Vec<(u32, usize)> => shared_neighbours_portable
);

/// The matches' ends as single-precision columns about their centroids, for
/// [`compatibility`].
struct MatchEnds {
    s: [Vec<f32>; 3],
    t: [Vec<f32>; 3],
    tau: f32,
    lanes: Lanes,
}

impl MatchEnds {
    /// Row `a` of the compatibility bits from its own block of 64 on (the words before it
    /// zero), its own bit cleared.
    #[inline(always)]
    fn row_from_diagonal_portable(&self, a: usize) -> Vec<u64> {
        let (s, t) = (&self.s, &self.t);
        let n = s[0].len();
        let mut row = vec![0u64; n.div_ceil(64)];
        let mut gap = [0f32; 64];
        for (w, word) in row.iter_mut().enumerate().skip(a / 64) {
            let lo = w * 64;
            let hi = (lo + 64).min(n);
            for (b, g) in (lo..hi).zip(gap.iter_mut()) {
                let ds = (s[0][b] - s[0][a]).powi(2)
                    + (s[1][b] - s[1][a]).powi(2)
                    + (s[2][b] - s[2][a]).powi(2);
                let dt = (t[0][b] - t[0][a]).powi(2)
                    + (t[1][b] - t[1][a]).powi(2)
                    + (t[2][b] - t[2][a]).powi(2);
                *g = (ds.sqrt() - dt.sqrt()).abs();
            }
            for (k, g) in gap[..hi - lo].iter().enumerate() {
                *word |= u64::from(*g < self.tau) << k;
            }
        }
        row[a / 64] &= !(1 << (a % 64));
        row
    }
}

// `row_from_diagonal`: the portable row as compiled for the widest vectors (the same IEEE
// operations in the same order, square roots exact in every width: the same bits).
dispatch_by_lanes!(
    MatchEnds,
    fn row_from_diagonal(&self, a: usize) -> Vec<u64> => row_from_diagonal_portable
);

/// Transposes a 64 x 64 bit matrix in place: bit `j` of `m[k]` becomes bit `k` of `m[j]`
/// (swapping ever smaller blocks: Hacker's Delight, 7-3).
fn transpose_bits(m: &mut [u64; 64]) {
    let mut width = 32;
    let mut mask: u64 = 0x0000_0000_FFFF_FFFF;
    while width != 0 {
        let mut k = 0;
        while k < 64 {
            // Row k's high half-block and row k + width's low one trade places.
            let t = ((m[k] >> width) ^ m[k + width]) & mask;
            m[k + width] ^= t;
            m[k] ^= t << width;
            k = (k + width + 1) & !width;
        }
        width >>= 1;
        mask ^= mask << width;
    }
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

/// The hypothesis of one triple of matches, if it passes the checks: similar edge lengths
/// (Open3D's edge-length checker), a triangle that is not too thin, every match of the triple
/// fitted within the inlier distance with agreeing normals (the distance and normal
/// checkers); only then are all matches counted.
fn try_triple(d: &[usize; 3], matched: &Matched, config: &FeatureConfig) -> Option<Hypothesis> {
    let (src, tgt) = (&matched.src, &matched.tgt);
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
    if d.iter().any(|&i| !matched.fits(i, &pose, matched.d2)) {
        return None;
    }
    let score = matched.count(&pose, matched.d2);
    Some(Hypothesis { score, pose })
}

/// Refits `pose` on the matches it fits (a few rounds), then by symmetric point-to-plane ICP
/// on the keypoints with a shrinking pairing distance, and scores it. `None` when a refit
/// degenerates.
fn refine(
    mut pose: Rigid,
    matched: &Matched,
    source: &Features,
    target: &Features,
    grid: &NearestGrid,
    config: &FeatureConfig,
) -> Option<Candidate> {
    let d2 = matched.d2;
    let mut last = 0;
    for _ in 0..MATCH_REFITS {
        let fitted: Vec<usize> = (0..matched.len())
            .filter(|&k| matched.fits(k, &pose, d2))
            .collect();
        if fitted.len() < 3 || fitted.len() == last {
            break;
        }
        last = fitted.len();
        pose = kabsch(fitted.iter().map(|&k| (&matched.src[k], &matched.tgt[k])))?;
    }
    // (source keypoint, nearest target keypoint, squared distance) within sqrt(d2), normals
    // agreeing. A keypoint certainly still beyond sqrt(d2) since its last query needs none.
    let mut last = vec![LastQuery::NONE; source.points.len()];
    let mut pairs_within = |pose: &Rigid, d2: f64| -> Vec<(usize, usize, f64)> {
        source
            .points
            .iter()
            .zip(&mut last)
            .enumerate()
            .filter_map(|(i, (p, last))| {
                let (j, distance) = grid.nearest_from(&pose.apply(p), d2, last)?;
                let ok = normals_agree(
                    pose,
                    &source.normals[i],
                    &target.normals[j],
                    matched.cos_min,
                );
                ok.then_some((i, j, distance))
            })
            .collect()
    };
    let rounds = config.icp_iterations;
    for round in 0..rounds {
        let t = if rounds > 1 {
            round as f64 / (rounds - 1) as f64
        } else {
            1.0
        };
        let f = 1.0 + (ICP_FINAL_FRACTION - 1.0) * t;
        let pairs = pairs_within(&pose, d2 * f * f);
        if pairs.len() < 6 {
            break;
        }
        pose = point_to_plane_step(&pose, &pairs, source, target)?;
    }
    let pairs = pairs_within(&pose, d2);
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
        matches: matched.count(&pose, d2 / 4.0),
    })
}

/// One Gauss-Newton step of symmetric point-to-plane ICP from `pose`: each pair's offset is
/// measured along the mean of its two normals (the source one turned by the pose).
fn point_to_plane_step(
    pose: &Rigid,
    pairs: &[(usize, usize, f64)],
    source: &Features,
    target: &Features,
) -> Option<Rigid> {
    let mut h = Matrix6::<f64>::zeros();
    let mut g = Vector6::<f64>::zeros();
    for &(i, j, _) in pairs {
        let q = Vector3::from(pose.apply(&source.points[i]));
        let y = Vector3::from(target.points[j]);
        let nt = Vector3::from(target.normals[j]);
        let ns = rotate(pose, &source.normals[i]);
        // (Normals of opposite signs only meet here with the normal check turned off.)
        let sum = if ns.dot(&nt) >= 0.0 { nt + ns } else { nt - ns };
        let n = if sum.norm() > 1e-9 {
            sum.normalize()
        } else {
            nt
        };
        let r = n.dot(&(q - y));
        // d(residual) / d(small rotation w, translation v) of `q + w x q + v`.
        let a = q.cross(&n);
        let jac = Vector6::new(a[0], a[1], a[2], n[0], n[1], n[2]);
        h += jac * jac.transpose();
        g += jac * r;
    }
    let x = h.cholesky()?.solve(&(-g));
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    let rot = nalgebra::Rotation3::new(Vector3::new(x[0], x[1], x[2])).into_inner();
    let r = rot * Matrix3::from_fn(|a, b| pose.r[a][b]);
    let t = rot * Vector3::from(pose.t) + Vector3::new(x[3], x[4], x[5]);
    Some(Rigid {
        r: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
        t: [t[0], t[1], t[2]],
    })
}

/// The best distinct hypotheses seen, by score (ties: the first seen).
struct Pool {
    kept: Vec<Hypothesis>,
    capacity: usize,
}

impl Pool {
    fn full(&self) -> bool {
        self.kept.len() == self.capacity
    }

    /// Is `h` the same pose as a kept hypothesis that scores at least as well?
    fn covers(&self, h: &Hypothesis, same: &impl Fn(&Rigid, &Rigid) -> bool) -> bool {
        self.kept
            .iter()
            .any(|k| k.score >= h.score && same(&k.pose, &h.pose))
    }

    fn offer(&mut self, h: Hypothesis, same: &impl Fn(&Rigid, &Rigid) -> bool) {
        if self.full() && self.kept.last().is_some_and(|l| l.score >= h.score) {
            return;
        }
        if self.covers(&h, same) {
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

/// Is the angle between the source normal `ns` turned by `pose` and the target normal `nt`
/// within the one whose cosine is `cos_min`? (Always true when `cos_min <= -1`.)
#[inline(always)]
fn normals_agree(pose: &Rigid, ns: &[f64; 3], nt: &[f64; 3], cos_min: f64) -> bool {
    cos_min <= -1.0 || rotate(pose, ns).dot(&Vector3::from(*nt)) >= cos_min
}

/// The rotation of `pose` applied to the direction `n`.
#[inline(always)]
fn rotate(pose: &Rigid, n: &[f64; 3]) -> Vector3<f64> {
    let r = &pose.r;
    Vector3::new(
        r[0][0] * n[0] + r[0][1] * n[1] + r[0][2] * n[2],
        r[1][0] * n[0] + r[1][1] * n[1] + r[1][2] * n[2],
        r[2][0] * n[0] + r[2][1] * n[1] + r[2][2] * n[2],
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptors_match_alike_on_every_vector_width_and_as_brute_force_says() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut descriptor =
            || -> Descriptor { std::array::from_fn(|_| rng.random_range(0.0f32..1.0)) };
        let source: Vec<Descriptor> = (0..150).map(|_| descriptor()).collect();
        let target: Vec<Descriptor> = (0..77).map(|_| descriptor()).collect();
        let d2 = |a: &Descriptor, b: &Descriptor| -> f32 {
            a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
        };
        let nearest_in = |q: &Descriptor, set: &[Descriptor]| -> u32 {
            (0..set.len())
                .min_by(|&i, &j| d2(q, &set[i]).total_cmp(&d2(q, &set[j])))
                .map(|i| i as u32)
                .expect("a non-empty set")
        };
        let (forward, backward) = nearest_both_ways(&source, &target);
        let forward_brute: Vec<u32> = source.iter().map(|q| nearest_in(q, &target)).collect();
        let backward_brute: Vec<u32> = target.iter().map(|q| nearest_in(q, &source)).collect();
        assert_eq!(forward, forward_brute);
        assert_eq!(backward, backward_brute);
        // Each vector width this CPU runs gives the portable copy's answer bit for bit.
        let mut columns = DescriptorColumns {
            columns: (0..DESCRIPTOR_LEN)
                .flat_map(|k| target.iter().map(move |t| t[k]))
                .collect(),
            nt: target.len(),
            lanes: Lanes::Portable,
        };
        let portable = columns.block_nearest(64, &source[64..128]);
        for lanes in [Lanes::Avx2, Lanes::Avx512] {
            columns.lanes = lanes.on_this_cpu();
            assert_eq!(columns.block_nearest(64, &source[64..128]), portable);
        }
    }

    #[test]
    fn a_bit_matrix_transposes() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let m: [u64; 64] = std::array::from_fn(|_| rng.random::<u64>());
        let mut t = m;
        transpose_bits(&mut t);
        for (j, row) in t.iter().enumerate() {
            for (k, original) in m.iter().enumerate() {
                assert_eq!(row >> k & 1, original >> j & 1, "bit {k} of row {j}");
            }
        }
    }

    #[test]
    fn the_compatibility_graph_is_every_pair_tested_both_ways() {
        // 150 matches (not a multiple of 64), half of them inliers of one motion.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut point = || [0, 1, 2].map(|_| rng.random_range(-1.0..1.0));
        let (mut src, mut tgt) = (Vec::new(), Vec::new());
        for k in 0..150 {
            let p = point();
            src.push(p);
            tgt.push(if k % 2 == 0 {
                [p[0] + 0.5, p[1], p[2]]
            } else {
                point()
            });
        }
        let matched = Matched {
            src_n: vec![[0.0, 0.0, 1.0]; src.len()],
            tgt_n: vec![[0.0, 0.0, 1.0]; tgt.len()],
            src,
            tgt,
            d2: 0.01,
            cos_min: 0.5,
        };
        let ids: Vec<usize> = (0..150).collect();
        let tau = 0.1;
        let rows = compatibility(&matched, &ids, tau);
        let mut set = 0;
        for (a, row) in rows.iter().enumerate() {
            for b in 0..150 {
                let gap = (dist2(&matched.src[a], &matched.src[b]).sqrt()
                    - dist2(&matched.tgt[a], &matched.tgt[b]).sqrt())
                .abs();
                let bit = row[b / 64] >> (b % 64) & 1 == 1;
                if a == b || (gap - tau).abs() < 1e-4 {
                    // The diagonal is never set; a gap at tau is single precision's call.
                    assert!(a != b || !bit);
                    continue;
                }
                assert_eq!(bit, gap < tau, "matches {a} and {b}: gap {gap}");
                set += usize::from(bit);
            }
        }
        // The 75 inliers are all compatible with each other.
        assert!(set >= 75 * 74, "{set}");
        // Every vector width gives the same bits (the widths this CPU lacks run narrower).
        for lanes in [Lanes::Portable, Lanes::Avx2, Lanes::Avx512] {
            let wide = compatibility_with(&matched, &ids, tau, lanes.on_this_cpu());
            assert_eq!(wide, rows, "{lanes:?}");
        }
        // Second order: the neighbours each pair of neighbours shares, counted one by one,
        // and alike on every vector width.
        let bit = |a: usize, b: usize| rows[a][b / 64] >> (b % 64) & 1 == 1;
        let mut graph = CompatibilityGraph {
            rows: rows.clone(),
            lanes: Lanes::Portable,
        };
        for a in [0, 1, 63, 64, 149] {
            let expected: Vec<(u32, usize)> = (0..150)
                .filter(|&b| bit(a, b))
                .map(|b| {
                    (
                        (0..150).filter(|&c| bit(a, c) && bit(b, c)).count() as u32,
                        b,
                    )
                })
                .collect();
            for lanes in [Lanes::Portable, Lanes::Avx2, Lanes::Avx512] {
                graph.lanes = lanes.on_this_cpu();
                assert_eq!(graph.shared_neighbours(a), expected, "{lanes:?}, match {a}");
            }
        }
    }
}
