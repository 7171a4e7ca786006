//! The fast distance index: the capped distance to the nearest point, sampled exactly (by
//! KD-tree queries) at the nodes of a grid and interpolated trilinearly. The distance is
//! 1-Lipschitz, so the interpolation is within one node diagonal of the exact value.

use super::grid_frame::GridFrame;
use super::lanes::{dispatch_by_lanes, floor_in_range, Lanes};
use super::{DistanceIndex, CHUNK};
use crate::se3::Rigid;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Upper bound on nodes of the distance field (32 MB per cloud at most; each node is one
/// KD-tree query at build time). Node indexes fit in u32 lanes (`capped_distances`).
const MAX_FIELD_NODES: usize = 1 << 22;

/// Every this many nodes per axis, the build queries a coarse node first (see `build`).
const COARSE: usize = 4;
/// Nodes per axis of the blocks the build fills together (see `build`).
const BLOCK: usize = 2;

/// Capped distance to the nearest point, sampled at grid nodes and interpolated.
#[derive(Clone, Debug)]
pub struct DistanceField {
    frame: GridFrame,
    /// Highest valid lower-corner index per axis, as f64 (`dims - 1`).
    last_f: [f64; 3],
    /// Node values, rounded to f32 (the precision they were tested at) and stored as f64
    /// so that the lookup reads them without converting.
    values: Vec<f64>,
    cap: f64,
    /// The copy of `sum_capped_distance` that runs (never wider than the CPU's).
    lanes: Lanes,
}

impl DistanceField {
    /// The field of `points` (indexed by `tree`, bounds `lo`, `hi`), nodes `spacing` apart,
    /// capped at `cap`.
    pub fn build(
        points: &[[f64; 3]],
        tree: &ImmutableKdTree<f64, 3>,
        lo: [f64; 3],
        hi: [f64; 3],
        spacing: f64,
        cap: f64,
    ) -> DistanceField {
        // Nodes reach `cap` beyond the bounds, so everything outside the field is at least
        // `cap` away from every point.
        let frame = GridFrame::covering(lo, hi, cap + spacing, spacing, MAX_FIELD_NODES);
        let [nx, ny, nz] = frame.dims;
        let h = frame.cell;
        let node = |i: usize, j: usize, k: usize| {
            [
                frame.origin[0] + i as f64 * h,
                frame.origin[1] + j as f64 * h,
                frame.origin[2] + k as f64 * h,
            ]
        };
        let nearest = |q: &[f64; 3]| {
            tree.query(q)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute()
                .distance
                .sqrt()
        };
        // Exact distances at every COARSE-th node first. The distance is 1-Lipschitz, so a
        // node whose coarse neighbour is farther than `cap` plus the distance between them
        // (with a margin for rounding) is itself beyond `cap`: its value is `cap` without a
        // query, exactly what the query would give. Most nodes of the margin are such.
        let coarse_dims = [nx, ny, nz].map(|n| (n - 1) / COARSE + 1);
        let coarse: Vec<f64> = (0..coarse_dims.iter().product::<usize>())
            .into_par_iter()
            .with_min_len(256)
            .map(|c| {
                let a = c % coarse_dims[0];
                let b = (c / coarse_dims[0]) % coarse_dims[1];
                let d = c / (coarse_dims[0] * coarse_dims[1]);
                nearest(&node(a * COARSE, b * COARSE, d * COARSE))
            })
            .collect();
        let far_enough = cap * (1.0 + 1e-9) + 1e-12;
        // The coarse node nearest to fine index `i` on an axis of `coarse_n` coarse nodes.
        let round = |i: usize, coarse_n: usize| ((i + COARSE / 2) / COARSE).min(coarse_n - 1);
        let beyond_cap = |i: usize, j: usize, k: usize| {
            let (a, b, d) = (
                round(i, coarse_dims[0]),
                round(j, coarse_dims[1]),
                round(k, coarse_dims[2]),
            );
            let offset = [
                i.abs_diff(a * COARSE),
                j.abs_diff(b * COARSE),
                k.abs_diff(d * COARSE),
            ];
            let apart = h * ((offset.iter().map(|o| o * o).sum::<usize>()) as f64).sqrt();
            coarse[a + coarse_dims[0] * (b + coarse_dims[1] * d)] - apart >= far_enough
        };
        // The other nodes in blocks of BLOCK^3: one query at the block's centre bounds where
        // the nearest point of every node of the block can be (within the centre's distance
        // plus twice the block's half-diagonal, and within the cap plus one half-diagonal
        // for a value below the cap); the nodes then take the minimum over those points,
        // computed as the KD-tree computes it, so every value is the same as a query's.
        let half_diagonal = h * (BLOCK - 1) as f64 * 3f64.sqrt() / 2.0;
        let mut values = vec![cap as f32; frame.len()];
        values
            .par_chunks_mut(nx * ny * BLOCK)
            .enumerate()
            .for_each(|(slab, out)| {
                let k0 = slab * BLOCK;
                let mut near: Vec<[f64; 3]> = Vec::new();
                let mut open: Vec<(usize, usize, usize)> = Vec::with_capacity(BLOCK.pow(3));
                for j0 in (0..ny).step_by(BLOCK) {
                    for i0 in (0..nx).step_by(BLOCK) {
                        open.clear();
                        for k in k0..(k0 + BLOCK).min(nz) {
                            for j in j0..(j0 + BLOCK).min(ny) {
                                for i in i0..(i0 + BLOCK).min(nx) {
                                    if !beyond_cap(i, j, k) {
                                        open.push((i, j, k));
                                    }
                                }
                            }
                        }
                        if open.is_empty() {
                            continue;
                        }
                        let corner = node(i0, j0, k0);
                        let centre = corner.map(|v| v + h * (BLOCK - 1) as f64 / 2.0);
                        let reach = (nearest(&centre) + 2.0 * half_diagonal)
                            .min(cap + half_diagonal)
                            * (1.0 + 1e-9)
                            + 1e-12;
                        near.clear();
                        near.extend(
                            tree.query(&centre)
                                .within::<SquaredEuclidean<f64>>(reach * reach)
                                .unsorted()
                                .execute()
                                .iter()
                                .map(|r| points[r.item as usize]),
                        );
                        for &(i, j, k) in &open {
                            let q = node(i, j, k);
                            let d2 = near.iter().fold(f64::INFINITY, |best, p| {
                                let (dx, dy, dz) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
                                best.min(dx * dx + dy * dy + dz * dz)
                            });
                            out[i + nx * (j + ny * (k - k0))] = d2.sqrt().min(cap) as f32;
                        }
                    }
                }
            });
        let last_f = std::array::from_fn(|k| (frame.dims[k] - 1) as f64);
        DistanceField {
            frame,
            last_f,
            values: values.into_iter().map(f64::from).collect(),
            cap,
            lanes: Lanes::widest(),
        }
    }

    /// The field answering `sum_capped_distance` with the copy `lanes` (or the widest this
    /// CPU runs, where that is narrower), so the tests check every copy.
    #[cfg(test)]
    pub(super) fn with_lanes(self, lanes: Lanes) -> DistanceField {
        DistanceField {
            lanes: lanes.on_this_cpu(),
            ..self
        }
    }
}

impl DistanceField {
    /// `sum_capped_distance` in code that vectorizes (see `lanes`): per chunk of points,
    /// their values as `capped_distance` gives them, then added in order.
    #[inline(always)]
    fn sum_capped_distance_portable(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        start: f64,
        divisor: f64,
        limit: f64,
    ) -> Option<f64> {
        let mut sum = start;
        let mut values = [0.0; CHUNK];
        for chunk in points.chunks(CHUNK) {
            let values = &mut values[..chunk.len()];
            self.capped_distances(chunk, t, values);
            for v in values.iter() {
                sum += v;
            }
            if sum / divisor >= limit {
                return None;
            }
        }
        Some(sum)
    }

    /// `capped_distance(t.apply(p))` of each of at most CHUNK points into `out`, without
    /// branches in the locating loop.
    #[inline(always)]
    fn capped_distances(&self, points: &[[f64; 3]], t: &Rigid, out: &mut [f64]) {
        let f = &self.frame;
        let (d0, d1) = (f.dims[0] as u32, f.dims[1] as u32);
        let mut base = [0u32; CHUNK];
        let mut weights = [[0.0; 3]; CHUNK];
        let mut inside = [false; CHUNK];
        for (((p, base), weights), inside) in points
            .iter()
            .zip(&mut base)
            .zip(&mut weights)
            .zip(&mut inside)
        {
            let p = t.apply(p);
            let g: [f64; 3] = std::array::from_fn(|k| (p[k] - f.origin[k]) * f.inv_cell);
            // The negated form is also false for NaN.
            *inside = g[0] >= 0.0
                && g[1] >= 0.0
                && g[2] >= 0.0
                && g[0] < self.last_f[0]
                && g[1] < self.last_f[1]
                && g[2] < self.last_f[2];
            let [i, j, k] = g.map(floor_in_range);
            *weights = [g[0] - i as f64, g[1] - j as f64, g[2] - k as f64];
            let b = i.wrapping_add(d0.wrapping_mul(j.wrapping_add(d1.wrapping_mul(k))));
            *base = if *inside { b } else { 0 };
        }
        for (((out, &b), &[u, v, w]), &inside) in
            out.iter_mut().zip(&base).zip(&weights).zip(&inside)
        {
            let value = self.interpolate(b as usize, u, v, w);
            *out = if inside { value } else { self.cap };
        }
    }

    /// The trilinear interpolation in the cell whose lowest node is `b`, at weights `u, v, w`.
    #[inline(always)]
    fn interpolate(&self, b: usize, u: f64, v: f64, w: f64) -> f64 {
        let f = &self.frame;
        let sx = 1;
        let sy = f.dims[0];
        let sz = f.dims[0] * f.dims[1];
        let g = |o: usize| self.values[b + o];
        let c00 = g(0) + (g(sx) - g(0)) * u;
        let c10 = g(sy) + (g(sy + sx) - g(sy)) * u;
        let c01 = g(sz) + (g(sz + sx) - g(sz)) * u;
        let c11 = g(sz + sy) + (g(sz + sy + sx) - g(sz + sy)) * u;
        let c0 = c00 + (c10 - c00) * v;
        let c1 = c01 + (c11 - c01) * v;
        c0 + (c1 - c0) * w
    }
}

// `sum_capped_distance_lanes`: `sum_capped_distance_portable` as compiled for the field's
// `lanes`.
dispatch_by_lanes!(
    DistanceField,
    fn sum_capped_distance_lanes(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        start: f64,
        divisor: f64,
        limit: f64
    ) -> Option<f64>
        => sum_capped_distance_portable
);

impl DistanceIndex for DistanceField {
    fn cap(&self) -> f64 {
        self.cap
    }

    fn error_bound(&self) -> f64 {
        self.frame.cell * 3f64.sqrt()
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
        // In range here, so the 32-bit truncation is floor (and cheaper than to usize).
        let (i, j, k) = (fx as i32, fy as i32, fz as i32);
        let (u, v, w) = (fx - i as f64, fy - j as f64, fz - k as f64);
        let b = f.linear(i as usize, j as usize, k as usize);
        self.interpolate(b, u, v, w)
    }

    fn sum_capped_distance(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        start: f64,
        divisor: f64,
        limit: f64,
    ) -> Option<f64> {
        self.sum_capped_distance_lanes(points, t, start, divisor, limit)
    }

    fn memory_bytes(&self) -> usize {
        self.values.len() * 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points on a wavy sheet (a scan-like surface) with a few loose points.
    fn sheet(seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..3000)
            .map(|_| {
                let (x, y): (f64, f64) = (rng.random_range(0.0..1.0), rng.random_range(0.0..0.6));
                [x, y, 0.1 * (5.0 * x).sin() * (3.0 * y).cos()]
            })
            .collect()
    }

    #[test]
    fn every_node_holds_the_exact_capped_distance_skipped_or_not() {
        for (seed, cap) in [(1, 0.05), (2, 0.2), (3, 0.6)] {
            let points = sheet(seed);
            let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points).unwrap();
            let field =
                DistanceField::build(&points, &tree, [0.0, 0.0, -0.1], [1.0, 0.6, 0.1], 0.02, cap);
            let [nx, ny, _] = field.frame.dims;
            let h = field.frame.cell;
            let mut at_cap = 0;
            for (c, &v) in field.values.iter().enumerate() {
                let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
                let q = [
                    field.frame.origin[0] + i as f64 * h,
                    field.frame.origin[1] + j as f64 * h,
                    field.frame.origin[2] + k as f64 * h,
                ];
                let d = tree
                    .query(&q)
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute()
                    .distance
                    .sqrt();
                assert_eq!(v, d.min(cap) as f32 as f64, "node {c} (cap {cap})");
                at_cap += usize::from(v == cap as f32 as f64);
            }
            // The test covers nodes beyond the cap (the ones the build may skip).
            assert!(
                at_cap > field.values.len() / 10,
                "{at_cap} of {}",
                field.values.len()
            );
        }
    }
}
