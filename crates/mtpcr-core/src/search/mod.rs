//! Nearest-neighbour indexes: the questions the losses ask about a cloud, and the structures
//! that answer them.
//!
//! Every evaluation moves every point of one cloud (or two) and asks one question per point
//! about the other cloud:
//! - the original task: "is there a point within eps?" ([`InlierIndex`]);
//! - the aiding task: "how far is the nearest point, capped at `cap`?" ([`DistanceIndex`]).
//!
//! Implementations: [`KdTreeIndex`] (exact, the reference; answers both), [`InlierGrid`] (O(1),
//! the same answers as the KD-tree) and [`DistanceField`] (O(1), within
//! [`DistanceIndex::error_bound`] of the KD-tree). [`IndexedCloud`] holds a cloud's points with
//! one index of each kind, chosen by [`SearchMethod`]; the losses take any of them.
//! `NearestGrid` answers a third question, for the feature candidates' keypoint ICP: "which
//! point is nearest, if one is within r?".
//!
//! **Adding a structure**: one file implementing [`InlierIndex`] or [`DistanceIndex`], one
//! line in the oracle lists of this module's tests (which check it against the KD-tree on
//! random and real-size queries), and a [`SearchMethod`] variant if users should select it.

mod field;
mod grid;
mod grid_frame;
mod kdtree;
mod lanes;
mod nearest;

pub use field::DistanceField;
pub use grid::InlierGrid;
pub use kdtree::KdTreeIndex;
pub(crate) use lanes::{dispatch_by_lanes, Lanes};
pub(crate) use nearest::{LastQuery, NearestGrid};

use crate::se3::Rigid;
use std::sync::Arc;

/// Which indexes answer the losses' nearest-neighbour questions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SearchMethod {
    /// KD-tree queries (the reference; slow).
    Exact,
    /// Occupancy grid and distance field (O(1) per point; same inlier counts as `Exact`).
    Fast,
}

/// Node spacing of the distance field, in units of eps. 2.0 builds the three fields of
/// bunny-a in about 0.1 s against 0.6 s for 1.0; the aiding loss only has to be coarse: 3.0
/// (3.4x fewer nodes again) gave the same successes and errors on the six problems, the
/// 48-degree turntable triples and the bunny triples (2026-12-02).
const FIELD_NODE_PER_EPS: f64 = 3.0;

/// Answers "is some point of the cloud within eps of `p` (distance <= eps)?".
pub trait InlierIndex: Send + Sync + std::fmt::Debug {
    /// The radius the index was built for.
    fn eps(&self) -> f64;

    /// Is some point within eps of `p`? False for non-finite `p`.
    fn has_point_within(&self, p: &[f64; 3]) -> bool;

    /// Number of `points`, moved by `t`, that have a point within eps; `None` as soon as
    /// fewer than `needed` can be reached (`needed = 0` never gives up).
    fn count_within(&self, points: &[[f64; 3]], t: &Rigid, needed: usize) -> Option<usize> {
        count_chunked(points, needed, |p| self.has_point_within(&t.apply(p)))
    }

    /// Bytes held beyond the points.
    fn memory_bytes(&self) -> usize {
        0
    }
}

/// Answers "how far is the nearest point of the cloud from `p`, capped at `cap`?".
pub trait DistanceIndex: Send + Sync + std::fmt::Debug {
    /// The cap the index was built for.
    fn cap(&self) -> f64;

    /// `min(distance to the nearest point, cap)`, within [`DistanceIndex::error_bound`].
    fn capped_distance(&self, p: &[f64; 3]) -> f64;

    /// The largest possible difference from the exact capped distance (0 for exact indexes).
    fn error_bound(&self) -> f64 {
        0.0
    }

    /// Sum over `points`, moved by `t`, of the capped distance, added to `start` in order;
    /// `None` as soon as `sum / divisor >= limit` is certain.
    fn sum_capped_distance(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        start: f64,
        divisor: f64,
        limit: f64,
    ) -> Option<f64> {
        sum_chunked(points, start, divisor, limit, |p| {
            self.capped_distance(&t.apply(p))
        })
    }

    /// Bytes held beyond the points.
    fn memory_bytes(&self) -> usize {
        0
    }
}

/// One prepared cloud with its two indexes, built once and shared read-only.
#[derive(Debug)]
pub struct IndexedCloud {
    points: Vec<[f64; 3]>,
    inlier: Arc<dyn InlierIndex>,
    distance: Arc<dyn DistanceIndex>,
}

impl IndexedCloud {
    /// Sorts `points` for cache-friendly queries and builds the indexes of `method` for the
    /// inlier radius `eps` and the distance cap `cap`. `points` must be non-empty and finite
    /// (the registration checks this first).
    pub fn new(points: Vec<[f64; 3]>, eps: f64, cap: f64, method: SearchMethod) -> IndexedCloud {
        let points = morton_sorted(points);
        let kd = Arc::new(KdTreeIndex::new(&points, eps, cap));
        match method {
            SearchMethod::Exact => IndexedCloud {
                points,
                inlier: kd.clone(),
                distance: kd,
            },
            SearchMethod::Fast => {
                let (lo, hi) = crate::cloud::bounds(&points);
                // Side by side: three clouds on two threads otherwise leave one idle.
                let (grid, field) = rayon::join(
                    || InlierGrid::build(&points, lo, hi, eps),
                    || {
                        let spacing = eps * FIELD_NODE_PER_EPS;
                        DistanceField::build(&points, kd.tree(), lo, hi, spacing, cap)
                    },
                );
                IndexedCloud {
                    points,
                    inlier: Arc::new(grid),
                    distance: Arc::new(field),
                }
            }
        }
    }

    /// A cloud with indexes built elsewhere (they must index exactly `points`).
    pub fn with_indexes(
        points: Vec<[f64; 3]>,
        inlier: Arc<dyn InlierIndex>,
        distance: Arc<dyn DistanceIndex>,
    ) -> IndexedCloud {
        IndexedCloud {
            points,
            inlier,
            distance,
        }
    }

    /// The points (in a space-filling-curve order, which keeps queries cache-friendly).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// The inlier radius the indexes were built for.
    pub fn eps(&self) -> f64 {
        self.inlier.eps()
    }

    /// The distance cap the indexes were built for.
    pub fn cap(&self) -> f64 {
        self.distance.cap()
    }

    /// The inlier index.
    pub fn inliers(&self) -> &dyn InlierIndex {
        &*self.inlier
    }

    /// The distance index.
    pub fn distances(&self) -> &dyn DistanceIndex {
        &*self.distance
    }

    /// Bytes held by the indexes.
    pub fn memory_bytes(&self) -> usize {
        self.inlier.memory_bytes() + self.distance.memory_bytes()
    }
}

/// Where a point was last queried against a cloud and its nearest distance there. A point
/// that has since moved less than that distance's excess over a radius is still beyond the
/// radius (triangle inequality): the ICPs skip its query, deciding exactly as the query would.
#[derive(Clone, Copy, Debug)]
pub(crate) struct QueryAnchor {
    at: [f64; 3],
    distance: f64,
}

impl QueryAnchor {
    /// Not queried yet: never certainly beyond.
    pub(crate) const NONE: QueryAnchor = QueryAnchor {
        at: [0.0; 3],
        distance: f64::NEG_INFINITY,
    };

    /// Is a point now at `q` certainly farther than `radius` from the cloud? (A relative
    /// margin of 1e-9, far above rounding, keeps "certainly" true.)
    #[inline(always)]
    pub(crate) fn still_beyond(&self, q: &[f64; 3], radius: f64) -> bool {
        self.distance - dist2(q, &self.at).sqrt() > radius * (1.0 + 1e-9)
    }

    /// Records a query at `q` whose nearest point was `distance` away.
    #[inline(always)]
    pub(crate) fn set(&mut self, q: [f64; 3], distance: f64) {
        *self = QueryAnchor { at: q, distance };
    }
}

#[inline(always)]
fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let dx = a[0] - b[0];
    let dy = a[1] - b[1];
    let dz = a[2] - b[2];
    dx * dx + dy * dy + dz * dz
}

/// Points between two checks of an early exit.
pub(super) const CHUNK: usize = 64;

/// Counts the points that pass `hit`; gives up (`None`) once `needed` is out of reach.
#[inline(always)]
fn count_chunked(
    points: &[[f64; 3]],
    needed: usize,
    hit: impl Fn(&[f64; 3]) -> bool,
) -> Option<usize> {
    let mut count = 0usize;
    let mut left = points.len();
    for chunk in points.chunks(CHUNK) {
        count += chunk.iter().filter(|p| hit(p)).count();
        left -= chunk.len();
        if count + left < needed {
            return None;
        }
    }
    Some(count)
}

/// Adds `value` over the points to `start` in order; gives up (`None`) once the running sum
/// divided by `divisor` reaches `limit` (every value is >= 0, so the sum only grows).
#[inline(always)]
fn sum_chunked(
    points: &[[f64; 3]],
    start: f64,
    divisor: f64,
    limit: f64,
    value: impl Fn(&[f64; 3]) -> f64,
) -> Option<f64> {
    let mut sum = start;
    for chunk in points.chunks(CHUNK) {
        for p in chunk {
            sum += value(p);
        }
        if sum / divisor >= limit {
            return None;
        }
    }
    Some(sum)
}

/// Sorts points along a Morton (Z-order) curve so that consecutive queries touch nearby cells.
fn morton_sorted(points: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    crate::cloud::morton_order(&points)
        .into_iter()
        .map(|i| points[i])
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::lanes::Lanes;
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points of a wavy 2 x 2 surface.
    pub(crate) fn surface_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let u: f64 = rng.random_range(-1.0..1.0);
                let v: f64 = rng.random_range(-1.0..1.0);
                [u, v, 0.2 * (3.0 * u).sin() * (2.0 * v).cos()]
            })
            .collect()
    }

    type MakeInlier = fn(&[[f64; 3]], f64) -> Arc<dyn InlierIndex>;
    type MakeDistance = fn(&[[f64; 3]], f64, f64) -> Arc<dyn DistanceIndex>;

    /// Every inlier index, checked against the KD-tree (add a new structure here). The
    /// grid and the field once per copy of their batched lookups (`lanes`): where the CPU
    /// lacks a copy's features, its entry runs the widest copy the CPU has.
    const INLIER_INDEXES: &[(&str, MakeInlier)] = &[
        ("grid on AVX-512 lanes", |p, eps| {
            grid_on(p, eps, Lanes::Avx512)
        }),
        ("grid on AVX2 lanes", |p, eps| grid_on(p, eps, Lanes::Avx2)),
        ("grid on portable lanes", |p, eps| {
            grid_on(p, eps, Lanes::Portable)
        }),
    ];

    /// Every distance index, checked against the KD-tree within its error bound.
    const DISTANCE_INDEXES: &[(&str, MakeDistance)] = &[
        ("field on AVX-512 lanes", |p, eps, cap| {
            field_on(p, eps, cap, Lanes::Avx512)
        }),
        ("field on AVX2 lanes", |p, eps, cap| {
            field_on(p, eps, cap, Lanes::Avx2)
        }),
        ("field on portable lanes", |p, eps, cap| {
            field_on(p, eps, cap, Lanes::Portable)
        }),
    ];

    fn grid_on(p: &[[f64; 3]], eps: f64, lanes: Lanes) -> Arc<dyn InlierIndex> {
        let (lo, hi) = crate::cloud::bounds(p);
        Arc::new(InlierGrid::build(p, lo, hi, eps).with_lanes(lanes))
    }

    fn field_on(p: &[[f64; 3]], eps: f64, cap: f64, lanes: Lanes) -> Arc<dyn DistanceIndex> {
        let (lo, hi) = crate::cloud::bounds(p);
        let kd = KdTreeIndex::new(p, eps, cap);
        Arc::new(DistanceField::build(p, kd.tree(), lo, hi, 2.0 * eps, cap).with_lanes(lanes))
    }

    #[test]
    fn inlier_indexes_answer_as_the_kd_tree_on_random_queries() {
        let pts = surface_points(3000, 1);
        let eps = 0.03;
        let exact = KdTreeIndex::new(&pts, eps, 0.2);
        for (name, make) in INLIER_INDEXES {
            let index = make(&pts, eps);
            let mut rng = ChaCha8Rng::seed_from_u64(2);
            let mut hits = 0;
            for _ in 0..200_000 {
                let q = [
                    rng.random_range(-1.1..1.1),
                    rng.random_range(-1.1..1.1),
                    rng.random_range(-0.3..0.3),
                ];
                let fast = index.has_point_within(&q);
                assert_eq!(fast, exact.has_point_within(&q), "{name} {q:?}");
                hits += fast as usize;
            }
            assert!(hits > 1000, "the test must exercise both answers ({hits})");
        }
    }

    #[test]
    fn inlier_counts_of_moved_points_equal_the_kd_tree_at_any_length() {
        // Batched counting works in stages of points: lengths around the stage sizes.
        let pts = surface_points(3000, 12);
        let queries = surface_points(1100, 13);
        let eps = 0.03;
        let exact = KdTreeIndex::new(&pts, eps, 0.2);
        let mut rng = ChaCha8Rng::seed_from_u64(14);
        // Half near the identity (many inliers), half anywhere.
        let moves: Vec<Rigid> = (0..6)
            .map(|k| {
                if k % 2 == 0 {
                    let angles: [f64; 3] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
                    let shift: [f64; 3] = std::array::from_fn(|_| rng.random_range(-0.02..0.02));
                    Rigid::from_individual(&[
                        angles[0], angles[1], angles[2], shift[0], shift[1], shift[2],
                    ])
                } else {
                    Rigid::from_matrix(&crate::se3::random_rigid(&mut rng, 1.0))
                }
            })
            .collect();
        for (name, make) in INLIER_INDEXES {
            let index = make(&pts, eps);
            let mut hits = 0;
            for t in &moves {
                for n in [1, 15, 16, 17, 63, 64, 65, 1001, 1100] {
                    let got = index.count_within(&queries[..n], t, 0);
                    assert_eq!(got, exact.count_within(&queries[..n], t, 0), "{name} {n}");
                    hits += got.unwrap_or(0);
                }
            }
            assert!(hits > 1000, "the test must exercise inliers ({hits})");
        }
    }

    #[test]
    fn summed_distances_of_moved_points_are_the_single_answers_added_in_order() {
        // Batched sums work in chunks: lengths around the chunk size, moves near the
        // identity (values below the cap) and anywhere (mostly outside the index).
        let pts = surface_points(3000, 15);
        let queries = surface_points(1100, 16);
        let (eps, cap) = (0.03, 0.2);
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let moves: Vec<Rigid> = (0..6)
            .map(|k| {
                if k % 2 == 0 {
                    let angles: [f64; 3] = std::array::from_fn(|_| rng.random_range(-0.3..0.3));
                    Rigid::from_individual(&[angles[0], angles[1], angles[2], 0.01, 0.0, -0.02])
                } else {
                    Rigid::from_matrix(&crate::se3::random_rigid(&mut rng, 1.0))
                }
            })
            .collect();
        for (name, make) in DISTANCE_INDEXES {
            let index = make(&pts, eps, cap);
            let mut below_cap = 0;
            for t in &moves {
                for n in [1, 63, 64, 65, 1001, 1100] {
                    let single: Vec<f64> = queries[..n]
                        .iter()
                        .map(|p| index.capped_distance(&t.apply(p)))
                        .collect();
                    let expected = single.iter().fold(0.5, |sum, v| sum + v);
                    let got = index.sum_capped_distance(&queries[..n], t, 0.5, 1.0, f64::MAX);
                    assert_eq!(got, Some(expected), "{name} {n}");
                    below_cap += single.iter().filter(|&&v| v < cap).count();
                }
            }
            assert!(
                below_cap > 1000,
                "the test must exercise values below the cap"
            );
        }
    }

    #[test]
    fn inlier_indexes_agree_on_cell_boundaries_and_the_points_themselves() {
        let pts = surface_points(500, 3);
        let exact = KdTreeIndex::new(&pts, 0.05, 0.2);
        for (name, make) in INLIER_INDEXES {
            let index = make(&pts, 0.05);
            for p in &pts {
                assert!(index.has_point_within(p), "{name}");
                for d in [0.05, -0.05, 0.0499999, 0.0500001] {
                    let q = [p[0] + d, p[1], p[2]];
                    assert_eq!(index.has_point_within(&q), exact.has_point_within(&q));
                }
            }
            assert!(!index.has_point_within(&[f64::NAN, 0.0, 0.0]), "{name}");
            assert!(!index.has_point_within(&[1e300, 0.0, 0.0]), "{name}");
        }
    }

    #[test]
    fn distance_indexes_are_within_their_bound_of_the_kd_tree() {
        let pts = surface_points(3000, 4);
        let exact = KdTreeIndex::new(&pts, 0.03, 0.2);
        for (name, make) in DISTANCE_INDEXES {
            let index = make(&pts, 0.03, 0.2);
            let bound = index.error_bound();
            assert!(bound > 0.0 && bound < 0.2, "{name}: {bound}");
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let mut worst: f64 = 0.0;
            for _ in 0..50_000 {
                let q = [
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-0.6..0.6),
                ];
                worst = worst.max((index.capped_distance(&q) - exact.capped_distance(&q)).abs());
            }
            assert!(worst <= bound, "{name}: {worst} > {bound}");
            assert_eq!(index.capped_distance(&[50.0, 0.0, 0.0]), 0.2, "{name}");
        }
    }

    #[test]
    fn huge_extent_enlarges_cells_instead_of_exhausting_memory() {
        let mut pts = surface_points(200, 9);
        pts.push([100.0, 100.0, 100.0]);
        let c = IndexedCloud::new(pts, 1e-3, 0.5, SearchMethod::Fast);
        assert!(c.memory_bytes() < 64 << 20);
        let q = [100.0, 100.0, 100.0 + 5e-4];
        assert!(c.inliers().has_point_within(&q));
    }
}
