//! The fast distance index: the capped distance to the nearest point, sampled exactly (by
//! KD-tree queries) at the nodes of a grid and interpolated trilinearly. The distance is
//! 1-Lipschitz, so the interpolation is within one node diagonal of the exact value.

use super::grid_frame::GridFrame;
use super::DistanceIndex;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Upper bound on nodes of the distance field (16 MB per cloud at most; each node is one
/// KD-tree query at build time).
const MAX_FIELD_NODES: usize = 1 << 22;

/// Capped distance to the nearest point, sampled at grid nodes and interpolated.
#[derive(Clone, Debug)]
pub struct DistanceField {
    frame: GridFrame,
    /// Highest valid lower-corner index per axis, as f64 (`dims - 1`).
    last_f: [f64; 3],
    values: Vec<f32>,
    cap: f64,
}

impl DistanceField {
    /// The field of the points in `tree` (bounds `lo`, `hi`), nodes `spacing` apart, capped at `cap`.
    pub fn build(
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
}

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
