//! Point clouds: validation, centring, bounds, subsampling, noise.

use crate::error::{Error, Result};
use crate::se3::{Rigid, Transform};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::seq::index;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::num::NonZero;

/// The largest coordinate magnitude [`PointCloud::validate`] accepts (1e30: the observable
/// universe is 9e26 m across). Beyond about 1e150 squared distances overflow f64 and the
/// transforms become NaN; beyond about 1e37 the fast distance field, which stores distances
/// as f32 (at most 3.4e38), overflows and the costs become NaN (fuzzing found both). Rescale
/// such data (other units) or re-centre it before registering it.
pub const MAX_COORDINATE: f64 = 1e30;

/// [`PointCloud::validate`] rejects a cloud as collinear when the variance of its points along
/// their second principal axis is at most this fraction of the variance along the first (a
/// width, as a standard deviation, of at most 1e-6 of the length): the rotation about the
/// line is then undetermined.
pub const COLLINEAR_RATIO: f64 = 1e-12;

/// [`PointCloud::is_planar`] calls a cloud planar when the variance of its points along their
/// third principal axis is at most this fraction of the variance along the first (a thickness,
/// as a standard deviation, of at most 1/1000 of the spread).
pub const PLANAR_RATIO: f64 = 1e-6;

/// A set of 3D points (coordinates in f64, in the data's units).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    points: Vec<[f64; 3]>,
    /// Where the scanner stood, when known (see [`PointCloud::with_viewpoint`]).
    viewpoint: Option<[f64; 3]>,
}

/// How a cloud is downsampled before registration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// Farthest-point sampling starting at index 0 (deterministic; the paper's choice).
    Farthest,
    /// Uniform random sampling without replacement (seeded by the run's seed).
    Random,
}

impl PointCloud {
    /// A cloud from its points (not validated; see [`PointCloud::validate`]).
    pub fn new(points: Vec<[f64; 3]>) -> Self {
        PointCloud {
            points,
            viewpoint: None,
        }
    }

    /// The cloud with the position of the scanner that saw it (in the cloud's frame): a
    /// depth camera's centre, a laser scanner's origin. The registration then also checks
    /// free space: a right pose never puts one scan's surface where the other scanner saw
    /// through. Without one, that check is absent.
    pub fn with_viewpoint(self, viewpoint: [f64; 3]) -> Self {
        PointCloud {
            viewpoint: Some(viewpoint),
            ..self
        }
    }

    /// The scanner's position, when known.
    pub fn viewpoint(&self) -> Option<[f64; 3]> {
        self.viewpoint
    }

    /// A cloud from a flat `[x0, y0, z0, x1, ...]` slice; its length must be a multiple of 3.
    pub fn from_flat(coords: &[f64]) -> Result<Self> {
        if coords.len() % 3 != 0 {
            return Err(Error::InvalidInput(format!(
                "a flat coordinate list must have a multiple of 3 values, got {}",
                coords.len()
            )));
        }
        Ok(PointCloud::new(
            coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        ))
    }

    /// The points.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// Consumes the cloud, giving its points.
    pub fn into_points(self) -> Vec<[f64; 3]> {
        self.points
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Checks that the cloud is usable for registration: at least `min_points` points, all
    /// coordinates finite and at most [`MAX_COORDINATE`] in absolute value (so squared
    /// distances and bounding box sides stay finite), not all points identical, and not all
    /// on one line (see [`COLLINEAR_RATIO`]: the rotation about that line would be
    /// undetermined). `name` is used in the error message.
    ///
    /// A planar cloud passes; [`PointCloud::is_planar`] tells the front-ends to warn about it.
    pub fn validate(&self, name: &str, min_points: usize) -> Result<()> {
        if self.points.is_empty() {
            return Err(Error::EmptyCloud {
                cloud: name.to_string(),
            });
        }
        if let Some((index, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
        {
            let value = p
                .iter()
                .find(|v| !v.is_finite())
                .copied()
                .unwrap_or(f64::NAN);
            return Err(Error::NonFiniteCoordinate {
                cloud: name.to_string(),
                index,
                value: value.to_string(),
            });
        }
        if let Some((index, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| v.abs() > MAX_COORDINATE))
        {
            let value = p
                .iter()
                .copied()
                .find(|v| v.abs() > MAX_COORDINATE)
                .unwrap_or(f64::INFINITY);
            return Err(Error::CoordinateTooLarge {
                cloud: name.to_string(),
                index,
                value: format!("{value:e}"),
                limit: format!("{MAX_COORDINATE:e}"),
            });
        }
        if self.points.len() < min_points {
            return Err(Error::TooFewPoints {
                cloud: name.to_string(),
                points: self.points.len(),
                needed: min_points,
            });
        }
        let (lo, hi) = self.bounds();
        if (0..3).all(|k| hi[k] - lo[k] <= 0.0) {
            return Err(Error::DegenerateCloud {
                cloud: name.to_string(),
            });
        }
        if self.principal_ratios()[0] <= COLLINEAR_RATIO {
            return Err(Error::CollinearCloud {
                cloud: name.to_string(),
            });
        }
        Ok(())
    }

    /// True when the cloud is (nearly) flat: the variance of the points along their thinnest
    /// principal axis is at most [`PLANAR_RATIO`] (1e-6) times the variance along their widest,
    /// i.e. its thickness (standard deviation) is at most 1/1000 of its spread. Such a cloud
    /// can be registered, but its rotation about the plane's normal rests on the in-plane
    /// shape alone and is weakly determined; the CLI and Python warn about it.
    /// A collinear or empty cloud is planar too.
    pub fn is_planar(&self) -> bool {
        self.principal_ratios()[1] <= PLANAR_RATIO
    }

    /// The principal component analysis of the points: the variances along the second and
    /// the third principal axes divided by the variance along the first (each in `0..=1`;
    /// both 0 for a cloud with no extent). Computed on the centred points scaled by the
    /// largest bounding box side, so it neither overflows nor depends on the units.
    fn principal_ratios(&self) -> [f64; 2] {
        let side = self.largest_side();
        if self.points.len() < 2 || !(side > 0.0 && side.is_finite()) {
            return [0.0, 0.0];
        }
        let c = self.centroid();
        let mut cov = nalgebra::Matrix3::<f64>::zeros();
        for p in &self.points {
            let d = nalgebra::Vector3::new(
                (p[0] - c[0]) / side,
                (p[1] - c[1]) / side,
                (p[2] - c[2]) / side,
            );
            cov += d * d.transpose();
        }
        cov /= self.points.len() as f64;
        let mut eig: Vec<f64> = cov
            .symmetric_eigenvalues()
            .iter()
            .map(|v| v.max(0.0))
            .collect();
        eig.sort_by(|a, b| b.total_cmp(a));
        if !(eig[0] > 0.0 && eig[0].is_finite()) {
            return [0.0, 0.0];
        }
        [eig[1] / eig[0], eig[2] / eig[0]]
    }

    /// Mean of the points (the origin for an empty cloud).
    pub fn centroid(&self) -> [f64; 3] {
        if self.points.is_empty() {
            return [0.0; 3];
        }
        let mut s = [0.0; 3];
        for p in &self.points {
            for k in 0..3 {
                s[k] += p[k];
            }
        }
        let n = self.points.len() as f64;
        [s[0] / n, s[1] / n, s[2] / n]
    }

    /// Axis-aligned bounds `(min, max)`; both are zero for an empty cloud.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        bounds(&self.points)
    }

    /// The longest side of the axis-aligned bounding box.
    pub fn largest_side(&self) -> f64 {
        let (lo, hi) = self.bounds();
        (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
    }

    /// The cloud translated by `v`.
    pub fn translated(&self, v: [f64; 3]) -> PointCloud {
        let shift = |p: &[f64; 3]| [p[0] + v[0], p[1] + v[1], p[2] + v[2]];
        PointCloud {
            points: self.points.iter().map(shift).collect(),
            viewpoint: self.viewpoint.as_ref().map(shift),
        }
    }

    /// The cloud moved by the rigid transform `t` (`p' = R p + t`).
    pub fn transformed(&self, t: &Transform) -> PointCloud {
        let r = Rigid::from_matrix(t);
        PointCloud {
            points: self.points.iter().map(|p| r.apply(p)).collect(),
            viewpoint: self.viewpoint.map(|v| r.apply(&v)),
        }
    }

    /// The points at the given indices.
    pub fn select(&self, indices: &[usize]) -> PointCloud {
        PointCloud {
            points: indices.iter().map(|&i| self.points[i]).collect(),
            viewpoint: self.viewpoint,
        }
    }

    /// Indices of `count` points chosen by farthest-point sampling, starting at index 0.
    /// Ties go to the lowest index, so the result is fully deterministic.
    pub fn farthest_point_indices(&self, count: usize) -> Vec<usize> {
        self.farthest_point_indices_until(count, &|| false)
            .unwrap_or_default()
    }

    /// [`PointCloud::farthest_point_indices`], checking `stop` every 256 picks; `None` when
    /// it asked to stop.
    pub fn farthest_point_indices_until(
        &self,
        count: usize,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> Option<Vec<usize>> {
        let n = self.points.len();
        let count = count.min(n);
        if count == 0 {
            return Some(Vec::new());
        }
        // The points in blocks of nearby points (Morton order), each with its bounding box
        // and the largest of its points' distances to the chosen set. A pick changes only the
        // blocks whose box is closer to it than that largest distance: late picks touch a few
        // blocks instead of every point. The distances and the picks are exactly those of the
        // plain algorithm (the box's distance is computed with the same monotone operations,
        // so it never exceeds a point's).
        let order = morton_order(&self.points);
        let xs: Vec<f64> = order.iter().map(|&i| self.points[i][0]).collect();
        let ys: Vec<f64> = order.iter().map(|&i| self.points[i][1]).collect();
        let zs: Vec<f64> = order.iter().map(|&i| self.points[i][2]).collect();
        let mut blocks: Vec<FpsBlock> = (0..n)
            .step_by(FPS_BLOCK)
            .map(|s| {
                let e = (s + FPS_BLOCK).min(n);
                let (lo, hi) = bounds(&(s..e).map(|i| [xs[i], ys[i], zs[i]]).collect::<Vec<_>>());
                FpsBlock {
                    lo,
                    hi,
                    far: f64::INFINITY,
                    far_index: order[s..e].iter().copied().min().unwrap_or(0),
                }
            })
            .collect();
        let mut nearest = vec![f64::INFINITY; n];
        let mut chosen = Vec::with_capacity(count);
        // Ties go to the lowest index of the input, as in one pass over it.
        let mut current = 0usize;
        for pick in 0..count {
            if pick % 256 == 255 && stop() {
                return None;
            }
            chosen.push(current);
            let c = self.points[current];
            for (b, block) in blocks.iter_mut().enumerate() {
                let mut bound = 0.0;
                for ((&lo, &hi), &ck) in block.lo.iter().zip(&block.hi).zip(&c) {
                    let d = (lo - ck).max(0.0).max(ck - hi);
                    bound += d * d;
                }
                if bound >= block.far {
                    continue;
                }
                let (s, e) = (b * FPS_BLOCK, ((b + 1) * FPS_BLOCK).min(n));
                for i in s..e {
                    let dx = xs[i] - c[0];
                    let dy = ys[i] - c[1];
                    let dz = zs[i] - c[2];
                    nearest[i] = (dx * dx + dy * dy + dz * dz).min(nearest[i]);
                }
                block.far = nearest[s..e]
                    .iter()
                    .copied()
                    .fold(f64::NEG_INFINITY, f64::max);
                block.far_index = (s..e)
                    .filter(|&i| nearest[i] == block.far)
                    .map(|i| order[i])
                    .min()
                    .unwrap_or(usize::MAX);
            }
            let far = blocks
                .iter()
                .map(|b| b.far)
                .fold(f64::NEG_INFINITY, f64::max);
            current = blocks
                .iter()
                .filter(|b| b.far == far)
                .map(|b| b.far_index)
                .min()
                .unwrap_or(0);
        }
        Some(chosen)
    }

    /// `count` points by farthest-point sampling (see [`PointCloud::farthest_point_indices`]).
    pub fn farthest_point_sample(&self, count: usize) -> PointCloud {
        self.select(&self.farthest_point_indices(count))
    }

    /// `count` points drawn uniformly without replacement, in increasing index order.
    pub fn random_sample<R: Rng + ?Sized>(&self, count: usize, rng: &mut R) -> PointCloud {
        let count = count.min(self.points.len());
        let mut idx = index::sample(rng, self.points.len(), count).into_vec();
        idx.sort_unstable();
        self.select(&idx)
    }

    /// Mean distance from each point to its nearest other point in the same cloud
    /// (0 for fewer than two points).
    pub fn mean_nearest_neighbor_distance(&self) -> f64 {
        if self.points.len() < 2 {
            return 0.0;
        }
        let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&self.points) else {
            return 0.0;
        };
        let two = NonZero::new(2usize).expect("2 is not zero");
        // Queried in parallel, summed in order: the same sum for any number of threads.
        let distances: Vec<f64> = self
            .points
            .par_iter()
            .map(|p| {
                let nn = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f64>>(two)
                    .execute();
                nn.iter().map(|r| r.distance).fold(0.0, f64::max).sqrt()
            })
            .collect();
        distances.iter().sum::<f64>() / self.points.len() as f64
    }

    /// The cloud without its stray points: points whose third-nearest neighbour in the cloud
    /// is more than [`STRAY_FACTOR`] times the median such distance away (isolated points and
    /// pairs or triples far from the surface). Meant for evenly spread samples (farthest-point
    /// sampling), where a clean scan has none: its neighbour distances are within a factor of
    /// about two of each other. Returns the cloud and the number of points removed.
    pub fn without_strays(&self) -> (PointCloud, usize) {
        const K: usize = 3;
        if self.points.len() <= 2 * K {
            return (self.clone(), 0);
        }
        let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&self.points) else {
            return (self.clone(), 0);
        };
        let k = NonZero::new(K + 1).expect("K + 1 is not zero");
        let far: Vec<f64> = self
            .points
            .par_iter()
            .map(|p| {
                let nn = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f64>>(k)
                    .execute();
                nn.iter().map(|r| r.distance).fold(0.0, f64::max).sqrt()
            })
            .collect();
        let mut sorted = far.clone();
        sorted.sort_by(f64::total_cmp);
        let limit = STRAY_FACTOR * sorted[sorted.len() / 2];
        let kept: Vec<[f64; 3]> = self
            .points
            .iter()
            .zip(&far)
            .filter(|(_, d)| **d <= limit)
            .map(|(p, _)| *p)
            .collect();
        let removed = self.points.len() - kept.len();
        (
            PointCloud {
                points: kept,
                viewpoint: self.viewpoint,
            },
            removed,
        )
    }

    /// The noise protocol of the paper: centre the cloud, divide by its largest absolute
    /// coordinate, add Gaussian noise of standard deviation `sigma` to every coordinate, scale
    /// back and undo the centring.
    pub fn with_normalized_noise<R: Rng + ?Sized>(
        &self,
        sigma: f64,
        rng: &mut R,
    ) -> Result<PointCloud> {
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "noise sigma must be finite and >= 0, got {sigma}"
            )));
        }
        let c = self.centroid();
        let scale = self
            .points
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - c[k]).abs()))
            .fold(0.0, f64::max);
        if scale == 0.0 || sigma == 0.0 {
            return Ok(self.clone());
        }
        let normal = Normal::new(0.0, sigma).map_err(|e| Error::InvalidInput(e.to_string()))?;
        let points = self
            .points
            .iter()
            .map(|p| {
                let mut q = [0.0; 3];
                for k in 0..3 {
                    let unit = (p[k] - c[k]) / scale + normal.sample(rng);
                    q[k] = unit * scale + c[k];
                }
                q
            })
            .collect();
        Ok(PointCloud {
            points,
            viewpoint: self.viewpoint,
        })
    }
}

/// A sample point is a stray point when its third-nearest neighbour is farther than this many
/// times the median (see [`PointCloud::without_strays`]).
pub const STRAY_FACTOR: f64 = 10.0;

/// Points per block of farthest-point sampling.
const FPS_BLOCK: usize = 64;

/// A block of farthest-point sampling: its box, and its largest distance to the chosen set
/// with the lowest input index at that distance.
struct FpsBlock {
    lo: [f64; 3],
    hi: [f64; 3],
    far: f64,
    far_index: usize,
}

/// Indices of `points` along a Morton (Z-order) curve of their bounding box, so that
/// consecutive points are near each other; ties in the curve's key are broken by the
/// coordinates, so the order depends only on the points.
pub(crate) fn morton_order(points: &[[f64; 3]]) -> Vec<usize> {
    let (lo, hi) = bounds(points);
    let ext = (0..3)
        .map(|k| hi[k] - lo[k])
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let scale = 1023.0 / ext;
    let spread = |mut v: u64| {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    };
    let key = |p: &[f64; 3]| {
        let q: [u64; 3] = std::array::from_fn(|k| ((p[k] - lo[k]) * scale) as u64);
        spread(q[0]) | (spread(q[1]) << 1) | (spread(q[2]) << 2)
    };
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by_cached_key(|&i| {
        let p = &points[i];
        (key(p), p[0].to_bits(), p[1].to_bits(), p[2].to_bits(), i)
    });
    order
}

/// Axis-aligned bounds `(min, max)` of points; both are zero for no points.
pub fn bounds(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    if points.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

impl From<Vec<[f64; 3]>> for PointCloud {
    fn from(points: Vec<[f64; 3]>) -> Self {
        PointCloud::new(points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_cloud(n: usize, seed: u64) -> PointCloud {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        PointCloud::new(
            (0..n)
                .map(|_| {
                    [
                        rng.random::<f64>(),
                        rng.random::<f64>(),
                        rng.random::<f64>(),
                    ]
                })
                .collect(),
        )
    }

    /// Farthest-point sampling in its plain form: every pick updates every point.
    fn plain_farthest_point_indices(points: &[[f64; 3]], count: usize) -> Vec<usize> {
        let mut nearest = vec![f64::INFINITY; points.len()];
        let mut chosen = Vec::new();
        let mut current = 0;
        for _ in 0..count.min(points.len()) {
            chosen.push(current);
            let c = points[current];
            for (d, p) in nearest.iter_mut().zip(points) {
                let (dx, dy, dz) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
                *d = (dx * dx + dy * dy + dz * dz).min(*d);
            }
            let far = nearest.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            current = nearest.iter().position(|&d| d == far).unwrap();
        }
        chosen
    }

    #[test]
    fn blocked_farthest_point_sampling_picks_exactly_what_the_plain_one_picks() {
        // Random points, a grid (many equal distances: ties) with repeated points, a line.
        let grid: Vec<[f64; 3]> = (0..1500)
            .map(|i| {
                [
                    (i % 10) as f64,
                    ((i / 10) % 10) as f64,
                    (i / 100 % 10) as f64,
                ]
            })
            .collect();
        let line: Vec<[f64; 3]> = (0..700).map(|i| [i as f64 * 0.1, 1.0, 2.0]).collect();
        for points in [random_cloud(3000, 7).points().to_vec(), grid, line] {
            let c = PointCloud::new(points.clone());
            for count in [1, 2, 50, 400, points.len()] {
                assert_eq!(
                    c.farthest_point_indices(count),
                    plain_farthest_point_indices(&points, count),
                    "{count} of {}",
                    points.len()
                );
            }
        }
    }

    #[test]
    fn farthest_point_sampling_starts_at_zero_and_spreads() {
        let c = random_cloud(2000, 1);
        let idx = c.farthest_point_indices(100);
        assert_eq!(idx[0], 0);
        assert_eq!(idx.len(), 100);
        let mut sorted = idx.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 100, "no point is chosen twice");
        // Brute-force check of the greedy rule for the second pick.
        let p0 = c.points()[0];
        let far = (0..c.len())
            .max_by(|&a, &b| {
                let da: f64 = (0..3).map(|k| (c.points()[a][k] - p0[k]).powi(2)).sum();
                let db: f64 = (0..3).map(|k| (c.points()[b][k] - p0[k]).powi(2)).sum();
                da.total_cmp(&db)
            })
            .unwrap();
        assert_eq!(idx[1], far);
        // A sample spreads: its mean spacing is much larger than a random subset's would be
        // in the worst case; check it covers the cube (every octant has points).
        let s = c.select(&idx);
        for oct in 0..8 {
            let hit = s
                .points()
                .iter()
                .any(|p| (0..3).all(|k| (p[k] > 0.5) == ((oct >> k) & 1 == 1)));
            assert!(hit, "octant {oct} empty");
        }
    }

    #[test]
    fn validation_names_the_problem() {
        assert!(matches!(
            PointCloud::new(vec![]).validate("cloud 1", 3),
            Err(Error::EmptyCloud { .. })
        ));
        let e = PointCloud::new(vec![[0.0, f64::NAN, 0.0], [1.0, 1.0, 1.0]])
            .validate("cloud 2", 1)
            .unwrap_err();
        assert!(
            e.to_string().contains("cloud 2") && e.to_string().contains("point 0"),
            "{e}"
        );
        assert!(matches!(
            PointCloud::new(vec![[1.0, 2.0, 3.0]; 20]).validate("c", 3),
            Err(Error::DegenerateCloud { .. })
        ));
        assert!(matches!(
            random_cloud(5, 1).validate("c", 10),
            Err(Error::TooFewPoints {
                points: 5,
                needed: 10,
                ..
            })
        ));
        assert!(random_cloud(50, 1).validate("c", 10).is_ok());
    }

    #[test]
    fn huge_coordinates_are_rejected_naming_the_point() {
        let mut pts = random_cloud(50, 2).into_points();
        pts[7][1] = 1e308;
        let e = PointCloud::new(pts).validate("cloud 3", 10).unwrap_err();
        assert!(
            matches!(e, Error::CoordinateTooLarge { index: 7, .. }),
            "{e}"
        );
        let text = e.to_string();
        assert!(
            text.contains("cloud 3") && text.contains("point 7") && text.contains("1e308"),
            "{text}"
        );
        for (scale, ok) in [(1e300, false), (-1e31, false), (5e29, true)] {
            let scaled = PointCloud::new(
                random_cloud(50, 3)
                    .points()
                    .iter()
                    .map(|p| p.map(|v| (v + 0.5) * scale))
                    .collect(),
            );
            let r = scaled.validate("c", 10);
            assert_eq!(r.is_ok(), ok, "scale {scale}: {r:?}");
        }
    }

    /// Points `origin + t * direction` for `n` values of `t`, plus `offset(i)` off the line.
    fn line(n: usize, offset: impl Fn(usize) -> [f64; 3]) -> PointCloud {
        let (o, d) = ([3.0, -2.0, 7.0], [0.3, 0.5, -0.8]);
        PointCloud::new(
            (0..n)
                .map(|i| {
                    let t = i as f64 / 7.0;
                    let e = offset(i);
                    [0, 1, 2].map(|k| o[k] + t * d[k] + e[k])
                })
                .collect(),
        )
    }

    #[test]
    fn collinear_clouds_are_rejected_thin_ones_are_not() {
        let e = line(100, |_| [0.0; 3]).validate("cloud 2", 10).unwrap_err();
        assert!(matches!(e, Error::CollinearCloud { .. }), "{e}");
        assert!(
            e.to_string().contains("cloud 2") && e.to_string().contains("line"),
            "{e}"
        );
        // Far from the origin, in big units: still a line.
        let far = line(100, |_| [0.0; 3]).translated([1e7, -3e7, 2e7]);
        assert!(matches!(
            far.validate("c", 10),
            Err(Error::CollinearCloud { .. })
        ));
        // A thin rod (width about 1e-5 of its length) is a cloud, if a weak (and flat) one.
        let rod = line(100, |i| {
            let a = i as f64 * 2.4;
            [1e-4 * a.cos(), 1e-4 * a.sin(), 0.0]
        });
        assert!(rod.validate("c", 10).is_ok());
        assert!(rod.is_planar(), "a rod is flat too");
    }

    #[test]
    fn planar_clouds_are_detected_by_their_thickness() {
        let slab = |thickness: f64| {
            PointCloud::new(
                random_cloud(500, 8)
                    .points()
                    .iter()
                    .map(|p| [p[0] * 4.0, p[1] * 3.0 - 1.0, (p[2] - 0.5) * thickness])
                    .collect(),
            )
            .transformed(&crate::se3::decode(&[0.3, -1.1, 0.7, 5.0, 6.0, 7.0]))
        };
        for (thickness, planar) in [(0.0, true), (1e-4, true), (1e-2, false), (3.0, false)] {
            let c = slab(thickness);
            assert!(c.validate("c", 10).is_ok(), "thickness {thickness}");
            assert_eq!(c.is_planar(), planar, "thickness {thickness}");
        }
        assert!(!random_cloud(100, 9).is_planar());
    }

    #[test]
    fn mean_nearest_neighbor_distance_of_a_grid() {
        let mut pts = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                pts.push([i as f64 * 0.5, j as f64 * 0.5, 0.0]);
            }
        }
        let d = PointCloud::new(pts).mean_nearest_neighbor_distance();
        assert!((d - 0.5).abs() < 1e-12, "{d}");
    }

    #[test]
    fn noise_follows_the_normalised_protocol() {
        let c = random_cloud(20000, 4).translated([10.0, 0.0, 0.0]);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let noisy = c.with_normalized_noise(0.02, &mut rng).unwrap();
        let cen = c.centroid();
        let scale = c
            .points()
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - cen[k]).abs()))
            .fold(0.0, f64::max);
        let var: f64 = c
            .points()
            .iter()
            .zip(noisy.points())
            .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>())
            .sum::<f64>()
            / (3.0 * c.len() as f64);
        let sigma = var.sqrt() / scale;
        assert!((sigma - 0.02).abs() < 0.001, "{sigma}");
    }

    #[test]
    fn stray_points_are_removed_and_clean_samples_kept_whole() {
        let clean = random_cloud(2000, 8).farthest_point_sample(400);
        let (same, removed) = clean.without_strays();
        assert_eq!(
            (removed, &same),
            (0, &clean),
            "an even sample has no stray point"
        );
        let mut pts = clean.points().to_vec();
        pts.push([50.0, 0.0, 0.0]);
        pts.extend([[-20.0, 3.0, 1.0], [-20.001, 3.0, 1.0]]);
        let (kept, removed) = PointCloud::new(pts).without_strays();
        assert_eq!(removed, 3);
        assert_eq!(kept, clean);
    }

    #[test]
    fn random_sample_is_seeded() {
        let c = random_cloud(1000, 6);
        let a = c.random_sample(50, &mut ChaCha8Rng::seed_from_u64(7));
        let b = c.random_sample(50, &mut ChaCha8Rng::seed_from_u64(7));
        assert_eq!(a, b);
        assert_eq!(a.len(), 50);
    }
}
