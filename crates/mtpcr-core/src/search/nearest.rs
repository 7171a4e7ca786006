//! The nearest point of a cloud within a fixed radius, from a dense grid of cells at least
//! that wide: the 27 cells around a query hold every point within the radius. The keypoint
//! ICP of the feature candidates asks this of every keypoint in every round; with a KD-tree
//! those queries were most of the time of screening a room's pairs (kiddo's `nearest_one`,
//! 57 % of a 38-fragment room). With this grid the same answers came in 0.84x the time of
//! 600 3DMatch / 3DLoMatch pairs and 0.85x that of the 38-fragment room (RESULTS.md, 2026-12-04).
//! A query that remembers its last answer ([`NearestGrid::nearest_from`]) searches only as far
//! as the point found last time can now be, and one outside the cloud's box none (RESULTS.md,
//! 2026-12-06, third session).

use super::{dist2, QueryAnchor};
use crate::cloud::bounds;

/// Cells a grid holds at most (4 bytes each); a cloud spread wider gets wider cells.
const MAX_CELLS: usize = 1 << 22;

/// A cloud's points sorted into cells of side `cell` (at least the radius it was built for).
#[derive(Debug)]
pub(crate) struct NearestGrid {
    origin: [f64; 3],
    /// The points' bounding box is `origin..=top`.
    top: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    /// Where each cell's points start in `points` (one more entry than cells).
    starts: Vec<u32>,
    /// The points, cell by cell, with their index in the cloud.
    points: Vec<([f64; 3], u32)>,
}

/// What a query found: the nearest point when it lies within the grid's cell size, and a
/// distance the nearest point is certainly not closer than.
pub(crate) struct Nearest {
    /// `(index, squared distance)` of the nearest point, when it is within the cell size.
    pub(crate) hit: Option<(usize, f64)>,
    /// The exact distance of `hit`; otherwise a lower bound of the nearest point's distance.
    pub(crate) distance: f64,
}

/// What a point's last query found, for its next query from nearby (the keypoint ICP asks
/// about every keypoint in every round while the pose moves a little).
#[derive(Clone, Copy)]
pub(crate) struct LastQuery {
    /// Where it was asked, and the nearest point's distance: exact when `exact`, else a
    /// lower bound.
    anchor: QueryAnchor,
    exact: bool,
}

impl LastQuery {
    /// Not queried yet.
    pub(crate) const NONE: LastQuery = LastQuery {
        anchor: QueryAnchor::NONE,
        exact: false,
    };
}

impl NearestGrid {
    /// The grid of `points` (finite) answering exactly for every query radius up to `radius`.
    pub(crate) fn new(points: &[[f64; 3]], radius: f64) -> NearestGrid {
        let (lo, hi) = bounds(points);
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let mut cell = if radius > 0.0 && radius.is_finite() {
            radius
        } else {
            extent.max(1.0)
        };
        let dims = loop {
            let dims: [usize; 3] =
                std::array::from_fn(|a| ((hi[a] - lo[a]) / cell).floor() as usize + 1);
            if dims
                .iter()
                .try_fold(1usize, |n, &d| n.checked_mul(d))
                .is_some_and(|n| n <= MAX_CELLS)
            {
                break dims;
            }
            cell *= 2.0;
        };
        let index = |p: &[f64; 3]| -> usize {
            let c: [usize; 3] =
                std::array::from_fn(|a| (((p[a] - lo[a]) / cell) as usize).min(dims[a] - 1));
            (c[2] * dims[1] + c[1]) * dims[0] + c[0]
        };
        let cell_of: Vec<usize> = points.iter().map(index).collect();
        let cells = dims[0] * dims[1] * dims[2];
        let mut starts = vec![0u32; cells + 1];
        for &c in &cell_of {
            starts[c + 1] += 1;
        }
        for c in 0..cells {
            starts[c + 1] += starts[c];
        }
        let mut next = starts.clone();
        let mut sorted = vec![([0.0; 3], 0u32); points.len()];
        for (i, (p, &c)) in points.iter().zip(&cell_of).enumerate() {
            sorted[next[c] as usize] = (*p, i as u32);
            next[c] += 1;
        }
        NearestGrid {
            origin: lo,
            top: hi,
            cell,
            dims,
            starts,
            points: sorted,
        }
    }

    /// The largest radius the grid answers for exactly (its cell size, at least the radius it
    /// was built for).
    pub(crate) fn reach(&self) -> f64 {
        self.cell
    }

    /// The nearest point to `q` when within the cell size (of equally near points, the one
    /// met first), else a lower bound of its distance.
    #[inline]
    pub(crate) fn nearest(&self, q: &[f64; 3]) -> Nearest {
        self.nearest_within(q, self.cell * self.cell)
    }

    /// The nearest point to `q` when its squared distance is at most `radius2` (at most the
    /// cell size squared; of equally near points, the one met first), else a lower bound of
    /// its distance. Only the cells the sphere of that radius touches are searched (a few for the
    /// small radii [`NearestGrid::nearest_from`] asks with, instead of 3 x 3 x 3).
    #[inline]
    pub(crate) fn nearest_within(&self, q: &[f64; 3], radius2: f64) -> Nearest {
        if !q.iter().all(|v| v.is_finite()) {
            return Nearest {
                hit: None,
                distance: f64::NEG_INFINITY,
            };
        }
        let (radius2, reach) = self.search_radius(radius2);
        // Every point lies in the bounding box: a query far outside it needs no search, and
        // its distance to the box stays a lower bound for the next queries nearby.
        let outside = (0..3)
            .map(|a| {
                let d = (self.origin[a] - q[a]).max(q[a] - self.top[a]).max(0.0);
                d * d
            })
            .sum::<f64>()
            .sqrt();
        if outside > reach {
            return Nearest {
                hit: None,
                distance: outside,
            };
        }
        // (Searching q's own cell first and skipping the cells farther than the best so far
        // was slower: 44 s instead of 36 s for the screening of a 38-fragment room.)
        let Some((range, bound)) = self.block(q, reach) else {
            return Nearest {
                hit: None,
                distance: reach,
            };
        };
        let mut best: Option<(usize, f64)> = None;
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                for (p, i) in self.row(&range, y, z) {
                    let d = dist2(q, p);
                    if best.is_none_or(|(_, b)| d < b) {
                        best = Some((*i as usize, d));
                    }
                }
            }
        }
        // Every point outside the block is at least `bound` away.
        let bound = bound.max(outside).max(0.0);
        match best {
            Some((i, d)) if d <= radius2 => Nearest {
                hit: Some((i, d)),
                distance: d.sqrt(),
            },
            Some((_, d)) => Nearest {
                hit: None,
                distance: d.sqrt().min(bound),
            },
            None => Nearest {
                hit: None,
                distance: bound,
            },
        }
    }

    /// Every point within `sqrt(radius2)` of `q` (at most the cell size), given to `visit` as
    /// (index, squared distance) in no particular order; none for a non-finite `q`.
    #[inline]
    pub(crate) fn each_within(&self, q: &[f64; 3], radius2: f64, mut visit: impl FnMut(u32, f64)) {
        if !q.iter().all(|v| v.is_finite()) {
            return;
        }
        let (radius2, reach) = self.search_radius(radius2);
        let Some((range, _)) = self.block(q, reach) else {
            return;
        };
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                for (p, i) in self.row(&range, y, z) {
                    let d = dist2(q, p);
                    if d <= radius2 {
                        visit(*i, d);
                    }
                }
            }
        }
    }

    /// A query's squared radius, capped at the cell size squared, and how far its search
    /// reaches: a hair wider than the radius, so that no cell holding a point within it is
    /// missed.
    #[inline]
    fn search_radius(&self, radius2: f64) -> (f64, f64) {
        let radius2 = radius2.min(self.cell * self.cell);
        (radius2, radius2.sqrt() * (1.0 + 1e-12))
    }

    /// The block of cells (an inclusive range per axis, clipped to the grid) that a sphere of
    /// radius `reach` around `q` touches, and how far `q` is from the block's faces where
    /// points may lie beyond them; `None` when the sphere misses the grid. (Truncation is the
    /// floor of these non-negative cell coordinates, and unlike `floor` needs no call to libm
    /// on the baseline x86-64.)
    #[inline]
    fn block(&self, q: &[f64; 3], reach: f64) -> Option<([(usize, usize); 3], f64)> {
        let mut range = [(0usize, 0usize); 3];
        let mut bound = f64::INFINITY;
        for a in 0..3 {
            let x = (q[a] - self.origin[a]) / self.cell;
            // (A millionth of a cell more: rounding never leaves out a point's cell.)
            let span = reach / self.cell + 1e-6;
            let (low, high) = (x - span, x + span);
            let first = if low > 0.0 { low as usize } else { 0 };
            let last = if high >= 0.0 {
                (high as usize).min(self.dims[a] - 1)
            } else {
                0
            };
            if high < 0.0 || last < first {
                return None;
            }
            if first > 0 {
                bound = bound.min(q[a] - (self.origin[a] + first as f64 * self.cell));
            }
            if last < self.dims[a] - 1 {
                bound = bound.min(self.origin[a] + (last + 1) as f64 * self.cell - q[a]);
            }
            range[a] = (first, last);
        }
        Some((range, bound))
    }

    /// The points of the block's row `(y, z)` along x, contiguous in `points`.
    #[inline]
    fn row(&self, range: &[(usize, usize); 3], y: usize, z: usize) -> &[([f64; 3], u32)] {
        let row = (z * self.dims[1] + y) * self.dims[0];
        let from = self.starts[row + range[0].0] as usize;
        let to = self.starts[row + range[0].1 + 1] as usize;
        &self.points[from..to]
    }

    /// The nearest point to `q` when its squared distance is at most `radius2`, as
    /// [`NearestGrid::nearest_within`] finds it, knowing where the same point was last
    /// queried (`last`, updated). A point certainly still beyond the radius needs no search;
    /// one whose nearest point was found last time searches only as far as that point can now
    /// be (its distance then plus how far the point moved), a few cells instead of 27.
    #[inline]
    pub(crate) fn nearest_from(
        &self,
        q: &[f64; 3],
        radius2: f64,
        last: &mut LastQuery,
    ) -> Option<(usize, f64)> {
        // (Margins far above rounding keep "certainly" true.)
        let found = if last.exact {
            let moved = dist2(q, &last.anchor.at).sqrt();
            let reach = (last.anchor.distance + moved) * (1.0 + 1e-9) + 1e-9 * self.cell;
            self.nearest_within(q, radius2.min(reach * reach))
        } else if last.anchor.still_beyond(q, radius2.sqrt()) {
            return None;
        } else {
            self.nearest(q)
        };
        last.anchor.set(*q, found.distance);
        last.exact = found.hit.is_some();
        found.hit.filter(|&(_, d)| d <= radius2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_grid_finds_what_the_kd_tree_finds_within_the_radius() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // A surface (most of a scene's keypoints) and some scattered points.
        let mut points: Vec<[f64; 3]> = (0..3000)
            .map(|_| {
                [
                    rng.random_range(-2.0..2.0),
                    rng.random_range(-1.0..1.0),
                    0.0,
                ]
            })
            .collect();
        points.extend((0..500).map(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0))));
        let radius = 0.07;
        let grid = NearestGrid::new(&points, radius);
        let tree =
            ImmutableKdTree::<f64, 3>::new_from_slice(&points).expect("a tree of the points");
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..20_000 {
            let q: [f64; 3] = std::array::from_fn(|_| rng.random_range(-2.5..2.5) * 0.9);
            let q = [q[0], q[1] * 0.5, q[2] * 0.05];
            let nn = tree
                .query(&q)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            let found = grid.nearest(&q);
            // A smaller radius searches fewer cells and finds the same point within it.
            let r2 = (radius * rng.random_range(0.3..1.0)).powi(2);
            let within = grid.nearest_within(&q, r2);
            if nn.distance <= r2 {
                assert_eq!(within.hit, found.hit);
            } else {
                assert!(within.hit.is_none());
                assert!(within.distance <= nn.distance.sqrt() + 1e-12);
                assert!(within.distance >= r2.sqrt() * (1.0 - 1e-12));
            }
            if nn.distance <= radius * radius {
                let (i, d) = found.hit.expect("a point within the radius is found");
                assert!((d - nn.distance).abs() <= 1e-15, "{d} {}", nn.distance);
                assert_eq!(dist2(&q, &points[i]), d);
                assert!((found.distance - nn.distance.sqrt()).abs() <= 1e-12);
                hits += 1;
            } else {
                assert!(found.hit.is_none_or(|(_, d)| d > radius * radius));
                // The bound never overstates the distance.
                assert!(found.distance <= nn.distance.sqrt() + 1e-12);
                misses += 1;
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} {misses}");
    }

    #[test]
    fn a_query_remembering_its_last_answer_finds_what_a_fresh_query_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let points: Vec<[f64; 3]> = (0..2000)
            .map(|_| {
                [
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.05..0.05),
                ]
            })
            .collect();
        let radius = 0.06;
        let grid = NearestGrid::new(&points, radius);
        // Walkers moving by small steps (an ICP's rounds) and now and then far (a new
        // hypothesis), some of them outside the cloud's box, with a shrinking radius.
        let mut walkers: Vec<([f64; 3], LastQuery)> = (0..300)
            .map(|_| {
                let q = [
                    rng.random_range(-1.3..1.3),
                    rng.random_range(-1.3..1.3),
                    rng.random_range(-0.1..0.1),
                ];
                (q, LastQuery::NONE)
            })
            .collect();
        let (mut hits, mut misses) = (0, 0);
        for round in 0..40 {
            let r2 = (radius * (1.0 - 0.5 * (round % 15) as f64 / 14.0)).powi(2);
            for (q, last) in &mut walkers {
                let step = if rng.random_range(0.0..1.0) < 0.05 {
                    0.5
                } else {
                    0.01
                };
                for (a, v) in q.iter_mut().enumerate() {
                    let step = if a == 2 { step * 0.2 } else { step };
                    *v += rng.random_range(-step..step);
                }
                let fresh = grid.nearest_within(q, r2).hit;
                assert_eq!(grid.nearest_from(q, r2, last), fresh);
                if fresh.is_some() {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} {misses}");
    }

    #[test]
    fn far_queries_empty_clouds_and_non_finite_queries_find_nothing() {
        let grid = NearestGrid::new(&[[0.0; 3], [1.0, 0.0, 0.0]], 0.1);
        let far = grid.nearest(&[50.0, 0.0, 0.0]);
        assert!(far.hit.is_none() && far.distance > 0.0 && far.distance <= 49.0);
        assert!(grid.nearest(&[f64::NAN, 0.0, 0.0]).hit.is_none());
        assert_eq!(grid.nearest(&[1.05, 0.0, 0.0]).hit.map(|h| h.0), Some(1));
        let empty = NearestGrid::new(&[], 0.1);
        assert!(empty.nearest(&[0.0; 3]).hit.is_none());
    }

    #[test]
    fn a_cloud_spread_far_wider_than_the_radius_gets_wider_cells_and_stays_exact() {
        let points = vec![[0.0; 3], [1e6, 1e6, 1e6], [0.5, 0.0, 0.0]];
        let grid = NearestGrid::new(&points, 1e-3);
        assert!(grid.dims.iter().product::<usize>() <= MAX_CELLS);
        let found = grid.nearest(&[0.0004, 0.0, 0.0]);
        assert_eq!(found.hit.map(|h| h.0), Some(0));
    }
}
