//! The two task losses and the search structures behind them.
//!
//! Every evaluation moves every point of one cloud (or two) and asks one question per point
//! about the other cloud. Each loss asks only what it needs:
//! - the original task asks "is there a point within eps?" ([`IndexedCloud::has_point_within`]);
//! - the aiding task asks "how far is the nearest point, capped at `cap`?"
//!   ([`IndexedCloud::capped_distance`]).
//!
//! Two interchangeable search paths answer them. [`SearchMethod::Exact`] uses a KD-tree
//! (kiddo) and is the reference. [`SearchMethod::Fast`] answers in O(1) per point: the
//! within-eps test from a grid whose cells are marked "no point within eps anywhere in the
//! cell", "some point within eps of the whole cell", or "mixed" with a short candidate list
//! checked exactly, so its answers equal the KD-tree's; the capped distance from a distance
//! field sampled exactly at grid nodes and interpolated trilinearly, which is within one node
//! diagonal of the exact value (the distance is 1-Lipschitz).

use crate::se3::Rigid;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Which search structure answers the losses' nearest-neighbour questions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SearchMethod {
    /// KD-tree queries (the reference; slow).
    Exact,
    /// Occupancy grid and distance field (O(1) per point; same inlier counts as `Exact`).
    Fast,
}

/// Upper bound on cells of the inlier grid (32 MB of cell table per cloud at most).
const MAX_GRID_CELLS: usize = 1 << 23;
/// Upper bound on nodes of the distance field (16 MB per cloud at most; each node is one
/// KD-tree query at build time).
const MAX_FIELD_NODES: usize = 1 << 22;
/// Cell side of the inlier grid, in units of eps. Measured on bunny-a (paper run, 2 threads):
/// 1.0 ran the evolution in 1.64 s against 2.08 s for 0.5 (a smaller table stays in cache).
const INLIER_CELL_PER_EPS: f64 = 1.0;
/// Node spacing of the distance field, in units of eps. 2.0 builds the three fields of
/// bunny-a in about 0.1 s against 0.6 s for 1.0; the aiding loss only has to be coarse.
const FIELD_NODE_PER_EPS: f64 = 2.0;

/// Regular grid geometry shared by both fast structures.
#[derive(Clone, Debug)]
struct GridFrame {
    origin: [f64; 3],
    inv_cell: f64,
    cell: f64,
    dims: [usize; 3],
}

impl GridFrame {
    /// A grid of cells of side `cell` covering `[lo - margin, hi + margin]`, with the cell
    /// side enlarged if the grid would exceed `max_cells`.
    fn covering(lo: [f64; 3], hi: [f64; 3], margin: f64, cell: f64, max_cells: usize) -> GridFrame {
        let ext: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k] + 2.0 * margin);
        let mut cell = cell;
        loop {
            let dims: [usize; 3] = std::array::from_fn(|k| (ext[k] / cell).ceil() as usize + 1);
            let total = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
            if total <= max_cells {
                return GridFrame {
                    origin: std::array::from_fn(|k| lo[k] - margin),
                    inv_cell: 1.0 / cell,
                    cell,
                    dims,
                };
            }
            cell *= ((total as f64) / max_cells as f64).cbrt() * 1.01;
        }
    }

    fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    #[inline(always)]
    fn linear(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
}

const EMPTY: u32 = 0;
const FULL: u32 = 1;

/// Exact "is there a point within eps?" in O(1) per query (see the module docs).
#[derive(Clone, Debug)]
struct InlierGrid {
    frame: GridFrame,
    dims_f: [f64; 3],
    /// Per cell: `EMPTY`, `FULL`, or `2 + k` for candidate list `k`.
    cells: Vec<u32>,
    /// Candidate list `k` is `candidates[starts[k]..starts[k + 1]]`.
    starts: Vec<u32>,
    candidates: Vec<[f64; 3]>,
    /// Per mixed cell `k`, one bit per sub-cell of a 4x4x4 split: sub-cells wholly within eps
    /// of one candidate (`full`) and sub-cells out of reach of every candidate (`empty`).
    /// Only the remaining sub-cells test candidates.
    sub_full: Vec<u64>,
    sub_empty: Vec<u64>,
    eps2: f64,
}

/// Sub-cells per cell side in the inlier grid's mixed cells (4 -> 64 bits).
const SUB: usize = 4;

/// Squared distances from `p` to the nearest and the farthest point of the box `[b0, b0 + h]^3`.
#[inline]
fn box_distances2(p: &[f64; 3], b0: [f64; 3], h: f64) -> (f64, f64) {
    let mut near = 0.0;
    let mut far = 0.0;
    for a in 0..3 {
        let b1 = b0[a] + h;
        let m = (b0[a] - p[a]).max(0.0).max(p[a] - b1);
        near += m * m;
        let f = (p[a] - b0[a]).abs().max((p[a] - b1).abs());
        far += f * f;
    }
    (near, far)
}

impl InlierGrid {
    fn build(points: &[[f64; 3]], lo: [f64; 3], hi: [f64; 3], eps: f64) -> InlierGrid {
        let frame = GridFrame::covering(
            lo,
            hi,
            eps * 1.001,
            eps * INLIER_CELL_PER_EPS,
            MAX_GRID_CELLS,
        );
        let h = frame.cell;
        let eps2 = eps * eps;
        // Margins make the classification robust to rounding in the cell lookup; the final
        // test on a mixed cell is the exact one.
        let full_below = eps2 * (1.0 - 1e-9);
        let near_below = eps2 * (1.0 + 1e-9);
        let mut cells = vec![EMPTY; frame.len()];
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (pi, p) in points.iter().enumerate() {
            let range: [(usize, usize); 3] = std::array::from_fn(|k| {
                let a = ((p[k] - eps - frame.origin[k]) * frame.inv_cell)
                    .floor()
                    .max(0.0) as usize;
                let b = ((p[k] + eps - frame.origin[k]) * frame.inv_cell).floor() as usize;
                (a, b.min(frame.dims[k] - 1))
            });
            for k in range[2].0..=range[2].1 {
                for j in range[1].0..=range[1].1 {
                    for i in range[0].0..=range[0].1 {
                        let idx = [i, j, k];
                        let b0 = std::array::from_fn(|a| frame.origin[a] + idx[a] as f64 * h);
                        let (dmin, dmax) = box_distances2(p, b0, h);
                        let c = frame.linear(i, j, k);
                        if dmax <= full_below {
                            cells[c] = FULL;
                        } else if dmin <= near_below {
                            pairs.push((c as u32, pi as u32));
                        }
                    }
                }
            }
        }
        pairs.sort_unstable();
        let mut starts = vec![0u32];
        let mut candidates = Vec::new();
        let mut sub_full = Vec::new();
        let mut sub_empty = Vec::new();
        let hs = h / SUB as f64;
        let mut g = 0;
        while g < pairs.len() {
            let c = pairs[g].0;
            let mut e = g;
            while e < pairs.len() && pairs[e].0 == c {
                e += 1;
            }
            if cells[c as usize] != FULL {
                cells[c as usize] = 2 + (starts.len() as u32 - 1);
                let first = candidates.len();
                candidates.extend(pairs[g..e].iter().map(|&(_, pi)| points[pi as usize]));
                starts.push(candidates.len() as u32);
                let cu = c as usize;
                let cell_idx = [
                    cu % frame.dims[0],
                    (cu / frame.dims[0]) % frame.dims[1],
                    cu / (frame.dims[0] * frame.dims[1]),
                ];
                let (mut full, mut empty) = (0u64, 0u64);
                for bit in 0..SUB * SUB * SUB {
                    let sub = [bit % SUB, (bit / SUB) % SUB, bit / (SUB * SUB)];
                    let b0 = std::array::from_fn(|a| {
                        frame.origin[a] + cell_idx[a] as f64 * h + sub[a] as f64 * hs
                    });
                    let mut any_near = false;
                    for q in &candidates[first..] {
                        let (dmin, dmax) = box_distances2(q, b0, hs);
                        if dmax <= full_below {
                            full |= 1 << bit;
                        }
                        any_near |= dmin <= near_below;
                    }
                    if !any_near {
                        empty |= 1 << bit;
                    }
                }
                sub_full.push(full);
                sub_empty.push(empty);
            }
            g = e;
        }
        let dims_f = std::array::from_fn(|k| frame.dims[k] as f64);
        InlierGrid {
            frame,
            dims_f,
            cells,
            starts,
            candidates,
            sub_full,
            sub_empty,
            eps2,
        }
    }

    #[inline(always)]
    fn has_point_within(&self, p: &[f64; 3]) -> bool {
        let f = &self.frame;
        let fx = (p[0] - f.origin[0]) * f.inv_cell;
        let fy = (p[1] - f.origin[1]) * f.inv_cell;
        let fz = (p[2] - f.origin[2]) * f.inv_cell;
        // The negated form is also false for NaN.
        if !(fx >= 0.0
            && fy >= 0.0
            && fz >= 0.0
            && fx < self.dims_f[0]
            && fy < self.dims_f[1]
            && fz < self.dims_f[2])
        {
            return false;
        }
        let c = f.linear(fx as usize, fy as usize, fz as usize);
        match self.cells[c] {
            EMPTY => false,
            FULL => true,
            v => {
                let k = (v - 2) as usize;
                // f >= 0 here, so truncation is floor (and avoids a libm call).
                let sub = |f: f64| (((f - (f as usize) as f64) * SUB as f64) as usize).min(SUB - 1);
                let bit = 1u64 << (sub(fx) + SUB * (sub(fy) + SUB * sub(fz)));
                if self.sub_full[k] & bit != 0 {
                    return true;
                }
                if self.sub_empty[k] & bit != 0 {
                    return false;
                }
                let (s, e) = (self.starts[k] as usize, self.starts[k + 1] as usize);
                self.candidates[s..e]
                    .iter()
                    .any(|q| dist2(p, q) <= self.eps2)
            }
        }
    }

    fn memory_bytes(&self) -> usize {
        self.cells.len() * 4
            + self.starts.len() * 4
            + self.candidates.len() * 24
            + self.sub_full.len() * 16
    }
}

/// Capped distance to the nearest point, sampled at grid nodes and interpolated.
#[derive(Clone, Debug)]
struct DistanceField {
    frame: GridFrame,
    /// Highest valid lower-corner index per axis, as f64 (`dims - 1`).
    last_f: [f64; 3],
    values: Vec<f32>,
    cap: f64,
}

impl DistanceField {
    fn build(
        tree: &ImmutableKdTree<f64, 3>,
        lo: [f64; 3],
        hi: [f64; 3],
        spacing: f64,
        cap: f64,
    ) -> DistanceField {
        // Nodes reach `cap` beyond the bounds, so everything outside the field is at least
        // `cap` away from every point.
        let frame = GridFrame::covering(lo, hi, cap + spacing, spacing, MAX_FIELD_NODES);
        let [nx, ny, _] = frame.dims;
        let h = frame.cell;
        let values: Vec<f32> = (0..frame.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|c| {
                let i = c % nx;
                let j = (c / nx) % ny;
                let k = c / (nx * ny);
                let q = [
                    frame.origin[0] + i as f64 * h,
                    frame.origin[1] + j as f64 * h,
                    frame.origin[2] + k as f64 * h,
                ];
                let nn = tree
                    .query(&q)
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute();
                nn.distance.sqrt().min(cap) as f32
            })
            .collect();
        let last_f = std::array::from_fn(|k| (frame.dims[k] - 1) as f64);
        DistanceField {
            frame,
            last_f,
            values,
            cap,
        }
    }

    #[inline(always)]
    fn capped_distance(&self, p: &[f64; 3]) -> f64 {
        let f = &self.frame;
        let fx = (p[0] - f.origin[0]) * f.inv_cell;
        let fy = (p[1] - f.origin[1]) * f.inv_cell;
        let fz = (p[2] - f.origin[2]) * f.inv_cell;
        if !(fx >= 0.0
            && fy >= 0.0
            && fz >= 0.0
            && fx < self.last_f[0]
            && fy < self.last_f[1]
            && fz < self.last_f[2])
        {
            return self.cap;
        }
        let (i, j, k) = (fx as usize, fy as usize, fz as usize);
        let (u, v, w) = (fx - i as f64, fy - j as f64, fz - k as f64);
        let sx = 1;
        let sy = f.dims[0];
        let sz = f.dims[0] * f.dims[1];
        let b = f.linear(i, j, k);
        let g = |o: usize| self.values[b + o] as f64;
        let c00 = g(0) + (g(sx) - g(0)) * u;
        let c10 = g(sy) + (g(sy + sx) - g(sy)) * u;
        let c01 = g(sz) + (g(sz + sx) - g(sz)) * u;
        let c11 = g(sz + sy) + (g(sz + sy + sx) - g(sz + sy)) * u;
        let c0 = c00 + (c10 - c00) * v;
        let c1 = c01 + (c11 - c01) * v;
        c0 + (c1 - c0) * w
    }

    fn memory_bytes(&self) -> usize {
        self.values.len() * 4
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
const CHUNK: usize = 64;

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

/// One prepared cloud with its search structures, built once and shared read-only.
#[derive(Debug)]
pub struct IndexedCloud {
    points: Vec<[f64; 3]>,
    tree: ImmutableKdTree<f64, 3>,
    grid: Option<InlierGrid>,
    field: Option<DistanceField>,
    eps: f64,
    cap: f64,
}

impl IndexedCloud {
    /// Builds the structures for the inlier radius `eps` and the distance cap `cap`. The
    /// KD-tree is always built; the grid and the field only for [`SearchMethod::Fast`].
    /// `points` must be non-empty and finite (the registration checks this first).
    pub fn new(points: Vec<[f64; 3]>, eps: f64, cap: f64, method: SearchMethod) -> IndexedCloud {
        let points = morton_sorted(points);
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points)
            .expect("a non-empty finite cloud always builds a KD-tree");
        let (lo, hi) = crate::cloud::PointCloud::new(points.clone()).bounds();
        let (grid, field) = match method {
            SearchMethod::Exact => (None, None),
            SearchMethod::Fast => (
                Some(InlierGrid::build(&points, lo, hi, eps)),
                Some(DistanceField::build(
                    &tree,
                    lo,
                    hi,
                    eps * FIELD_NODE_PER_EPS,
                    cap,
                )),
            ),
        };
        IndexedCloud {
            points,
            tree,
            grid,
            field,
            eps,
            cap,
        }
    }

    /// The points (in a space-filling-curve order, which keeps queries cache-friendly).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// The inlier radius the structures were built for.
    pub fn eps(&self) -> f64 {
        self.eps
    }

    /// The distance cap the structures were built for.
    pub fn cap(&self) -> f64 {
        self.cap
    }

    /// Bytes held by the fast structures.
    pub fn fast_memory_bytes(&self) -> usize {
        self.grid.as_ref().map_or(0, InlierGrid::memory_bytes)
            + self.field.as_ref().map_or(0, DistanceField::memory_bytes)
    }

    /// Is some point of this cloud within `eps` of `p` (distance <= eps)? Uses the grid when it
    /// was built and `method` is `Fast`, else the KD-tree.
    #[inline]
    pub fn has_point_within(&self, p: &[f64; 3], method: SearchMethod) -> bool {
        match (&self.grid, method) {
            (Some(g), SearchMethod::Fast) => g.has_point_within(p),
            _ => self.exact_nearest2(p) <= self.eps * self.eps,
        }
    }

    /// `min(distance to the nearest point, cap)`.
    #[inline]
    pub fn capped_distance(&self, p: &[f64; 3], method: SearchMethod) -> f64 {
        match (&self.field, method) {
            (Some(f), SearchMethod::Fast) => f.capped_distance(p),
            _ => self.exact_nearest2(p).sqrt().min(self.cap),
        }
    }

    #[inline]
    fn exact_nearest2(&self, p: &[f64; 3]) -> f64 {
        self.tree
            .query(p)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute()
            .distance
    }

    /// Number of `points`, moved by `t`, that have a point of this cloud within eps; `None`
    /// as soon as fewer than `needed` can be reached (`needed = 0` never gives up).
    pub fn count_within(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        method: SearchMethod,
        needed: usize,
    ) -> Option<usize> {
        match (&self.grid, method) {
            (Some(g), SearchMethod::Fast) => {
                count_chunked(points, needed, |p| g.has_point_within(&t.apply(p)))
            }
            _ => {
                let e2 = self.eps * self.eps;
                count_chunked(points, needed, |p| self.exact_nearest2(&t.apply(p)) <= e2)
            }
        }
    }

    /// Sum over `points`, moved by `t`, of the capped distance to this cloud, added to `start`
    /// in order; `None` as soon as `sum / divisor >= limit` is certain.
    pub fn sum_capped_distance(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        method: SearchMethod,
        start: f64,
        divisor: f64,
        limit: f64,
    ) -> Option<f64> {
        match (&self.field, method) {
            (Some(f), SearchMethod::Fast) => sum_chunked(points, start, divisor, limit, |p| {
                f.capped_distance(&t.apply(p))
            }),
            _ => sum_chunked(points, start, divisor, limit, |p| {
                self.exact_nearest2(&t.apply(p)).sqrt().min(self.cap)
            }),
        }
    }

    /// The largest possible difference between the fast and the exact capped distance of one
    /// point (one node diagonal of the field), or 0 without a field.
    pub fn field_error_bound(&self) -> f64 {
        self.field
            .as_ref()
            .map_or(0.0, |f| f.frame.cell * 3f64.sqrt())
    }
}

/// Sorts points along a Morton (Z-order) curve so that consecutive queries touch nearby cells.
fn morton_sorted(mut points: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    if points.len() < 2 {
        return points;
    }
    let (lo, hi) = crate::cloud::PointCloud::new(points.clone()).bounds();
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
    points.sort_by_cached_key(|p| (key(p), p[0].to_bits(), p[1].to_bits(), p[2].to_bits()));
    points
}

/// A task loss: the cost of one candidate transform `source -> target`. Lower is better.
pub trait Loss: Sync {
    /// The cost of `t` if it is below `limit`; `None` only when the cost is certainly
    /// `>= limit` (the evaluation may stop early then). The value returned is the same as
    /// without a limit.
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64>;

    /// The cost of `t`.
    fn evaluate(&self, t: &Rigid) -> f64 {
        self.evaluate_below(t, f64::INFINITY)
            .expect("no cost is certainly >= infinity")
    }
}

/// The original task's local part: `1 - (n1 + n2) / (Ns + Nt)` with `n1` the source points
/// that land within eps of the target and `n2` the target points within eps of the moved
/// source (tested as `T^-1 q` against the source).
#[derive(Clone, Copy, Debug)]
pub struct InlierLoss<'a> {
    /// Cloud moved by the transform.
    pub source: &'a IndexedCloud,
    /// Cloud it is moved onto.
    pub target: &'a IndexedCloud,
    /// Search path.
    pub method: SearchMethod,
}

impl InlierLoss<'_> {
    /// `(n1, n2)` for `t`.
    pub fn inlier_counts(&self, t: &Rigid) -> (usize, usize) {
        let n1 = self
            .target
            .count_within(self.source.points(), t, self.method, 0);
        let n2 = self
            .source
            .count_within(self.target.points(), &t.inverse(), self.method, 0);
        (n1.unwrap_or(0), n2.unwrap_or(0))
    }

    fn total(&self) -> usize {
        self.source.points().len() + self.target.points().len()
    }

    /// The cost of `k` inliers, computed exactly as the loss computes it.
    fn cost_of(&self, k: usize) -> f64 {
        1.0 - k as f64 / self.total() as f64
    }
}

impl Loss for InlierLoss<'_> {
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64> {
        let total = self.total();
        // The fewest inliers whose cost is below `limit` (the cost falls as k grows).
        let needed = if limit == f64::INFINITY {
            0
        } else {
            let guess = ((1.0 - limit) * total as f64).floor().max(0.0) as usize;
            let mut k = guess.saturating_sub(2).min(total + 1);
            while k <= total && self.cost_of(k) >= limit {
                k += 1;
            }
            if k > total {
                return None;
            }
            k
        };
        let nt = self.target.points().len();
        let n1 = self.target.count_within(
            self.source.points(),
            t,
            self.method,
            needed.saturating_sub(nt),
        )?;
        let n2 = self.source.count_within(
            self.target.points(),
            &t.inverse(),
            self.method,
            needed.saturating_sub(n1),
        )?;
        Some(self.cost_of(n1 + n2))
    }
}

/// The aiding task's loss (Silva et al.): mean over source points of the distance to the target
/// capped at `cap`; optionally both directions (mean over the points of both clouds).
#[derive(Clone, Copy, Debug)]
pub struct CappedDistanceLoss<'a> {
    /// Cloud moved by the transform.
    pub source: &'a IndexedCloud,
    /// Cloud it is moved onto.
    pub target: &'a IndexedCloud,
    /// Search path.
    pub method: SearchMethod,
    /// Also measure target points against the moved source.
    pub two_way: bool,
}

impl Loss for CappedDistanceLoss<'_> {
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64> {
        let ns = self.source.points().len() as f64;
        if self.two_way {
            let n = ns + self.target.points().len() as f64;
            let forward = self.target.sum_capped_distance(
                self.source.points(),
                t,
                self.method,
                0.0,
                n,
                limit,
            )?;
            let both = self.source.sum_capped_distance(
                self.target.points(),
                &t.inverse(),
                self.method,
                forward,
                n,
                limit,
            )?;
            Some(both / n)
        } else {
            let forward = self.target.sum_capped_distance(
                self.source.points(),
                t,
                self.method,
                0.0,
                ns,
                limit,
            )?;
            Some(forward / ns)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::{random_rigid, Rigid};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn surface_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let u: f64 = rng.random_range(-1.0..1.0);
                let v: f64 = rng.random_range(-1.0..1.0);
                [u, v, 0.2 * (3.0 * u).sin() * (2.0 * v).cos()]
            })
            .collect()
    }

    #[test]
    fn grid_answers_equal_the_kd_tree_on_random_queries() {
        let pts = surface_points(3000, 1);
        let eps = 0.03;
        let c = IndexedCloud::new(pts, eps, 0.2, SearchMethod::Fast);
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut hits = 0;
        for _ in 0..200_000 {
            let q = [
                rng.random_range(-1.1..1.1),
                rng.random_range(-1.1..1.1),
                rng.random_range(-0.3..0.3),
            ];
            let fast = c.has_point_within(&q, SearchMethod::Fast);
            assert_eq!(fast, c.has_point_within(&q, SearchMethod::Exact), "{q:?}");
            hits += fast as usize;
        }
        assert!(hits > 1000, "the test must exercise both answers ({hits})");
    }

    #[test]
    fn queries_on_cell_boundaries_and_points_themselves_agree() {
        let pts = surface_points(500, 3);
        let c = IndexedCloud::new(pts.clone(), 0.05, 0.2, SearchMethod::Fast);
        for p in &pts {
            assert!(c.has_point_within(p, SearchMethod::Fast));
            for d in [0.05, -0.05, 0.0499999, 0.0500001] {
                let q = [p[0] + d, p[1], p[2]];
                assert_eq!(
                    c.has_point_within(&q, SearchMethod::Fast),
                    c.has_point_within(&q, SearchMethod::Exact)
                );
            }
        }
        assert!(!c.has_point_within(&[f64::NAN, 0.0, 0.0], SearchMethod::Fast));
        assert!(!c.has_point_within(&[1e300, 0.0, 0.0], SearchMethod::Fast));
    }

    #[test]
    fn distance_field_is_within_its_bound_of_the_exact_distance() {
        let pts = surface_points(3000, 4);
        let c = IndexedCloud::new(pts, 0.03, 0.2, SearchMethod::Fast);
        let bound = c.field_error_bound();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut worst: f64 = 0.0;
        for _ in 0..50_000 {
            let q = [
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
                rng.random_range(-0.6..0.6),
            ];
            let d = (c.capped_distance(&q, SearchMethod::Fast)
                - c.capped_distance(&q, SearchMethod::Exact))
            .abs();
            worst = worst.max(d);
        }
        assert!(worst <= bound, "{worst} > {bound}");
        assert_eq!(
            c.capped_distance(&[50.0, 0.0, 0.0], SearchMethod::Fast),
            0.2
        );
    }

    #[test]
    fn losses_agree_between_paths_on_random_transforms() {
        let a = IndexedCloud::new(surface_points(2000, 6), 0.03, 0.2, SearchMethod::Fast);
        let b = IndexedCloud::new(surface_points(2000, 7), 0.03, 0.2, SearchMethod::Fast);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for trial in 0..60 {
            // Half near the identity (many inliers), half anywhere.
            let t = if trial % 2 == 0 {
                Rigid::from_individual(&[
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                ])
            } else {
                Rigid::from_matrix(&random_rigid(&mut rng, 0.5))
            };
            let fast = InlierLoss {
                source: &a,
                target: &b,
                method: SearchMethod::Fast,
            };
            let exact = InlierLoss {
                method: SearchMethod::Exact,
                ..fast
            };
            assert_eq!(fast.inlier_counts(&t), exact.inlier_counts(&t));
            let fa = CappedDistanceLoss {
                source: &a,
                target: &b,
                method: SearchMethod::Fast,
                two_way: trial % 3 == 0,
            };
            let ex = CappedDistanceLoss {
                method: SearchMethod::Exact,
                ..fa
            };
            assert!(
                (fa.evaluate(&t) - ex.evaluate(&t)).abs()
                    <= b.field_error_bound().max(a.field_error_bound())
            );
        }
        let ident = Rigid::from_individual(&[0.0; 6]);
        let (n1, _) = InlierLoss {
            source: &a,
            target: &a,
            method: SearchMethod::Fast,
        }
        .inlier_counts(&ident);
        assert_eq!(n1, 2000, "a cloud is all inliers of itself");
    }

    #[test]
    fn a_limit_only_cuts_costs_that_reach_it() {
        let a = IndexedCloud::new(surface_points(1500, 10), 0.03, 0.2, SearchMethod::Fast);
        let b = IndexedCloud::new(surface_points(1500, 11), 0.03, 0.2, SearchMethod::Fast);
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for trial in 0..40 {
            let t = Rigid::from_individual(&[
                rng.random_range(-8.0..8.0),
                rng.random_range(-8.0..8.0),
                rng.random_range(-8.0..8.0),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                0.0,
            ]);
            let inl = InlierLoss {
                source: &a,
                target: &b,
                method: SearchMethod::Fast,
            };
            let aid = CappedDistanceLoss {
                source: &a,
                target: &b,
                method: SearchMethod::Fast,
                two_way: trial % 2 == 0,
            };
            for loss in [&inl as &dyn Loss, &aid as &dyn Loss] {
                let full = loss.evaluate(&t);
                for limit in [full * 0.5, full, full + 1e-12, full * 1.5, 0.0] {
                    match loss.evaluate_below(&t, limit) {
                        Some(v) => assert_eq!(v, full),
                        None => assert!(full >= limit, "cut {full} below limit {limit}"),
                    }
                }
                assert_eq!(loss.evaluate_below(&t, full * 1.5 + 1e-9), Some(full));
            }
        }
    }

    #[test]
    fn huge_extent_enlarges_cells_instead_of_exhausting_memory() {
        let mut pts = surface_points(200, 9);
        pts.push([100.0, 100.0, 100.0]);
        let c = IndexedCloud::new(pts, 1e-3, 0.5, SearchMethod::Fast);
        assert!(c.fast_memory_bytes() < 64 << 20);
        let q = [100.0, 100.0, 100.0 + 5e-4];
        assert!(c.has_point_within(&q, SearchMethod::Fast));
    }
}
