//! The fast inlier index: an occupancy grid that answers "is there a point within eps?" in
//! O(1) per query with exactly the KD-tree's answers. One bit per cell says whether any point
//! is within eps of some part of the cell; such a cell has a record with a 4x4x4 sub-cell
//! mask and a short candidate list checked exactly. The bits (about 60 kB for a bunny scan)
//! stay in cache where a table of 4-byte codes (1.7 MB) did not: most queries of a search
//! land in empty cells.

use super::grid_frame::GridFrame;
use super::lanes::{dispatch_by_lanes, floor_in_range, Lanes};
use super::{dist2, InlierIndex, CHUNK};
use crate::se3::Rigid;
use rayon::prelude::*;

/// Upper bound on cells of the inlier grid (a 32 MB table while building, 1 MB of bits after).
/// Cell indexes fit in u32 lanes (`InlierGrid::locate`).
const MAX_GRID_CELLS: usize = 1 << 23;
/// Cell side of the inlier grid, in units of eps. Measured on bunny-a (paper run, 2 threads):
/// 1.0 ran the evolution in 1.64 s against 2.08 s for 0.5 (a smaller table stays in cache).
const INLIER_CELL_PER_EPS: f64 = 1.0;

const EMPTY: u32 = 0;
const FULL: u32 = 1;

/// Cells per word of the occupancy bitmap.
const WORD: usize = 64;

/// Exact "is there a point within eps?" in O(1) per query (see the module docs).
#[derive(Clone, Debug)]
pub struct InlierGrid {
    frame: GridFrame,
    /// Sub-cells per unit of length (`SUB / cell`).
    inv_sub: f64,
    /// Sub-cells per axis, as f64.
    sub_dims_f: [f64; 3],
    /// One bit per cell, set when the cell has a record; one more (clear) bit past the last
    /// cell is what every query outside the grid reads.
    occupied: Vec<u64>,
    /// Per word of `occupied`: the records of the cells before it (a cell's record is
    /// `records[rank[w] + set bits before it in word w]`).
    rank: Vec<u32>,
    /// One per occupied cell, in cell order.
    records: Vec<MixedCell>,
    candidates: Vec<[f64; 3]>,
    eps2: f64,
    /// The copy of `count_within` that runs (never wider than the CPU's).
    lanes: Lanes,
}

/// What a query landing in an occupied cell reads, in one place. A cell wholly within eps of
/// a point has every `full` bit set and no candidates.
#[derive(Clone, Copy, Debug)]
struct MixedCell {
    /// One bit per sub-cell of a 4x4x4 split: sub-cells wholly within eps of one candidate.
    full: u64,
    /// Sub-cells out of reach of every candidate. Only the remaining sub-cells test
    /// candidates.
    empty: u64,
    /// The cell's candidates are `candidates[start..end]`.
    start: u32,
    end: u32,
}

/// Sub-cells per cell side in the inlier grid's mixed cells, as a power of two (4 -> 64 bits).
const SUB_SHIFT: u32 = 2;
const SUB: usize = 1 << SUB_SHIFT;

/// Squared distances from `p` to the nearest and the farthest point of `[b0, b0 + h]` on one
/// axis.
#[inline]
fn axis_distances2(p: f64, b0: f64, h: f64) -> (f64, f64) {
    let b1 = b0 + h;
    let m = (b0 - p).max(0.0).max(p - b1);
    let f = (p - b0).abs().max((p - b1).abs());
    (m * m, f * f)
}

/// Squared distances from `p` to the nearest and the farthest point of the box `[b0, b0 + h]^3`
/// (the axes' terms added in axis order, as the sub-cell masks of `build` add them).
#[inline]
fn box_distances2(p: &[f64; 3], b0: [f64; 3], h: f64) -> (f64, f64) {
    let mut near = 0.0;
    let mut far = 0.0;
    for a in 0..3 {
        let (m, f) = axis_distances2(p[a], b0[a], h);
        near += m;
        far += f;
    }
    (near, far)
}

impl InlierGrid {
    /// The grid of `points` (bounds `lo`, `hi`) for the radius `eps`.
    pub fn build(points: &[[f64; 3]], lo: [f64; 3], hi: [f64; 3], eps: f64) -> InlierGrid {
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
        // The mixed cells: each cell's run of pairs, then its sub-cell masks (most of the
        // build's work, independent per cell, so in parallel; collected in cell order).
        let mut runs: Vec<(usize, usize)> = Vec::new();
        let mut g = 0;
        while g < pairs.len() {
            let mut e = g;
            while e < pairs.len() && pairs[e].0 == pairs[g].0 {
                e += 1;
            }
            if cells[pairs[g].0 as usize] != FULL {
                runs.push((g, e));
            }
            g = e;
        }
        let hs = h / SUB as f64;
        let masks: Vec<(u64, u64)> = runs
            .par_iter()
            .with_min_len(64)
            .map(|&(g, e)| {
                let cu = pairs[g].0 as usize;
                let cell_idx = [
                    cu % frame.dims[0],
                    (cu / frame.dims[0]) % frame.dims[1],
                    cu / (frame.dims[0] * frame.dims[1]),
                ];
                // A sub-cell's distances are sums of one term per axis, and each axis has
                // only SUB sub-cell positions: per candidate, 3 x SUB terms, then 64 sums.
                let (mut full, mut near) = (0u64, 0u64);
                for &(_, pi) in &pairs[g..e] {
                    let p = &points[pi as usize];
                    let terms: [[(f64, f64); SUB]; 3] = std::array::from_fn(|a| {
                        std::array::from_fn(|s| {
                            let b0 = frame.origin[a] + cell_idx[a] as f64 * h + s as f64 * hs;
                            axis_distances2(p[a], b0, hs)
                        })
                    });
                    for bit in 0..SUB * SUB * SUB {
                        let sub = [bit % SUB, (bit / SUB) % SUB, bit / (SUB * SUB)];
                        let (mut dmin, mut dmax) = (0.0, 0.0);
                        for a in 0..3 {
                            dmin += terms[a][sub[a]].0;
                            dmax += terms[a][sub[a]].1;
                        }
                        full |= ((dmax <= full_below) as u64) << bit;
                        near |= ((dmin <= near_below) as u64) << bit;
                    }
                }
                let empty = !near;
                (full, empty)
            })
            .collect();
        let mut mixed = Vec::with_capacity(runs.len());
        let mut candidates = Vec::new();
        for (&(g, e), &(full, empty)) in runs.iter().zip(&masks) {
            cells[pairs[g].0 as usize] = 2 + mixed.len() as u32;
            let first = candidates.len();
            candidates.extend(pairs[g..e].iter().map(|&(_, pi)| points[pi as usize]));
            mixed.push(MixedCell {
                full,
                empty,
                start: first as u32,
                end: candidates.len() as u32,
            });
        }
        let words = (cells.len() + 1).div_ceil(WORD);
        let mut occupied = vec![0u64; words];
        let mut rank = vec![0u32; words];
        let mut records = Vec::with_capacity(mixed.len());
        for (c, &code) in cells.iter().enumerate() {
            if c % WORD == 0 {
                rank[c / WORD] = records.len() as u32;
            }
            let record = match code {
                EMPTY => continue,
                FULL => MixedCell {
                    full: !0,
                    empty: 0,
                    start: 0,
                    end: 0,
                },
                v => mixed[(v - 2) as usize],
            };
            occupied[c / WORD] |= 1 << (c % WORD);
            records.push(record);
        }
        InlierGrid {
            inv_sub: frame.inv_cell * SUB as f64,
            sub_dims_f: std::array::from_fn(|k| (frame.dims[k] * SUB) as f64),
            frame,
            occupied,
            rank,
            records,
            candidates,
            eps2,
            lanes: Lanes::widest(),
        }
    }

    /// The grid answering `count_within` with the copy `lanes` (or the widest this CPU
    /// runs, where that is narrower), so the tests check every copy.
    #[cfg(test)]
    pub(super) fn with_lanes(self, lanes: Lanes) -> InlierGrid {
        InlierGrid {
            lanes: lanes.on_this_cpu(),
            ..self
        }
    }
}

impl InlierGrid {
    /// `p` in units of sub-cells from the grid's origin.
    #[inline(always)]
    fn sub_coordinates(&self, p: &[f64; 3]) -> [f64; 3] {
        let f = &self.frame;
        std::array::from_fn(|k| (p[k] - f.origin[k]) * self.inv_sub)
    }

    /// The sub-cell at sub-cell coordinates `g` (whole sub-cells per axis), or `None` when
    /// `g` is outside the grid (or NaN).
    #[inline(always)]
    fn sub_cell(&self, g: [f64; 3]) -> Option<[usize; 3]> {
        // The negated form is also false for NaN.
        if !(g[0] >= 0.0
            && g[1] >= 0.0
            && g[2] >= 0.0
            && g[0] < self.sub_dims_f[0]
            && g[1] < self.sub_dims_f[1]
            && g[2] < self.sub_dims_f[2])
        {
            return None;
        }
        // 0 <= g < 2^31, so truncation is floor (and cheaper to i32 than to usize).
        Some(g.map(|v| v as i32 as usize))
    }

    /// The cell of sub-cell `s` (`frame.len()` for `None`) and the index of `s` in its
    /// cell's 4x4x4 split.
    #[inline(always)]
    fn cell_and_sub_bit(&self, s: Option<[usize; 3]>) -> (usize, u32) {
        match s {
            Some(s) => (
                self.frame.linear(s[0] / SUB, s[1] / SUB, s[2] / SUB),
                (s[0] % SUB + SUB * (s[1] % SUB + SUB * (s[2] % SUB))) as u32,
            ),
            None => (self.frame.len(), 0),
        }
    }

    /// The answer for the point `p()` in sub-cell `sub_bit` of cell `c`, whose word of
    /// `occupied` is `word`.
    #[inline(always)]
    fn answer(&self, c: usize, word: u64, sub_bit: u32, p: impl Fn() -> [f64; 3]) -> bool {
        (word >> (c % WORD)) & 1 != 0 && self.answer_occupied(c, word, sub_bit, p)
    }

    /// `answer` for a cell whose bit in `word` is set.
    #[inline(always)]
    fn answer_occupied(&self, c: usize, word: u64, sub_bit: u32, p: impl Fn() -> [f64; 3]) -> bool {
        let before = (word & ((1u64 << (c % WORD)) - 1)).count_ones() as usize;
        let cell = &self.records[self.rank[c / WORD] as usize + before];
        let bit = 1u64 << sub_bit;
        if cell.full & bit != 0 {
            return true;
        }
        if cell.empty & bit != 0 {
            return false;
        }
        let (start, end) = (cell.start as usize, cell.end as usize);
        let p = p();
        self.candidates[start..end]
            .iter()
            .any(|q| dist2(&p, q) <= self.eps2)
    }

    /// The cells and sub-cell bits of the moved points `map(points[i])` (`map` in sub-cell
    /// units: rows `a`, shift `b`), as `cell_and_sub_bit(sub_cell(..))` gives them, written
    /// without branches or early exits in 32-bit lanes so that the loop vectorizes.
    #[inline(always)]
    fn locate(
        &self,
        a: &[[f64; 3]; 3],
        b: &[f64; 3],
        points: &[[f64; 3]],
        cells: &mut [u32],
        bits: &mut [u32],
    ) {
        let [dx, dy, dz] = self.sub_dims_f;
        let (d0, d1) = (self.frame.dims[0] as u32, self.frame.dims[1] as u32);
        let outside = self.frame.len() as u32;
        for ((p, cell), bit) in points.iter().zip(cells).zip(bits) {
            let g: [f64; 3] =
                std::array::from_fn(|k| a[k][0] * p[0] + a[k][1] * p[1] + a[k][2] * p[2] + b[k]);
            // The negated form is also false for NaN.
            let inside =
                g[0] >= 0.0 && g[1] >= 0.0 && g[2] >= 0.0 && g[0] < dx && g[1] < dy && g[2] < dz;
            let s = g.map(floor_in_range);
            let [i, j, k] = s.map(|v| v >> SUB_SHIFT);
            let c = i.wrapping_add(d0.wrapping_mul(j.wrapping_add(d1.wrapping_mul(k))));
            let [u, v, w] = s.map(|v| v & (SUB as u32 - 1));
            *cell = if inside { c } else { outside };
            *bit = if inside {
                u | (v << SUB_SHIFT) | (w << (2 * SUB_SHIFT))
            } else {
                0
            };
        }
    }
}

/// Points whose cells are looked up before any is answered (see `count_within`).
const STAGE: usize = 16;

impl InlierGrid {
    /// `count_within` in code that vectorizes (see `lanes`).
    #[inline(always)]
    fn count_within_portable(
        &self,
        points: &[[f64; 3]],
        t: &Rigid,
        needed: usize,
    ) -> Option<usize> {
        // In stages of STAGE points: all are located (in vectors where the CPU has them) and
        // every cell's word is loaded before any answer, so the loads overlap instead of
        // waiting on each other; then only the points in occupied cells, most often none of
        // the stage's, go on to the unpredictable branches of a record.
        // `t` and the sub-cell coordinates are one affine map (scaling by 1/h and by SUB,
        // a power of two, so the sub-cells are those of `sub_coordinates`); the moved point
        // itself is only needed for the exact test of an undecided sub-cell.
        let f = &self.frame;
        let a: [[f64; 3]; 3] = t.r.map(|row| row.map(|v| v * self.inv_sub));
        let b: [f64; 3] = std::array::from_fn(|k| (t.t[k] - f.origin[k]) * self.inv_sub);
        let mut count = 0usize;
        let mut left = points.len();
        let mut cells = [0u32; STAGE];
        let mut bits = [0u32; STAGE];
        let mut words = [0u64; STAGE];
        for chunk in points.chunks(CHUNK) {
            for stage in chunk.chunks(STAGE) {
                let n = stage.len();
                self.locate(&a, &b, stage, &mut cells[..n], &mut bits[..n]);
                // One bit per point of the stage whose cell is occupied; only those go on.
                let mut occupied = 0u32;
                for (i, &c) in cells[..n].iter().enumerate() {
                    let c = c as usize;
                    words[i] = self.occupied[c / WORD];
                    occupied |= (((words[i] >> (c % WORD)) & 1) as u32) << i;
                }
                while occupied != 0 {
                    let i = occupied.trailing_zeros() as usize;
                    occupied &= occupied - 1;
                    let c = cells[i] as usize;
                    count +=
                        self.answer_occupied(c, words[i], bits[i], || t.apply(&stage[i])) as usize;
                }
            }
            left -= chunk.len();
            if count + left < needed {
                return None;
            }
        }
        Some(count)
    }
}

// `count_within_lanes`: `count_within_portable` as compiled for the grid's `lanes` (AVX2: about
// 2x the portable copy's throughput, AVX-512 1.2x more; `cargo bench --bench fitness`).
dispatch_by_lanes!(
    InlierGrid,
    fn count_within_lanes(&self, points: &[[f64; 3]], t: &Rigid, needed: usize) -> Option<usize>
        => count_within_portable
);

impl InlierIndex for InlierGrid {
    fn eps(&self) -> f64 {
        self.eps2.sqrt()
    }

    #[inline(always)]
    fn has_point_within(&self, p: &[f64; 3]) -> bool {
        let (c, sub_bit) = self.cell_and_sub_bit(self.sub_cell(self.sub_coordinates(p)));
        self.answer(c, self.occupied[c / WORD], sub_bit, || *p)
    }

    fn count_within(&self, points: &[[f64; 3]], t: &Rigid, needed: usize) -> Option<usize> {
        self.count_within_lanes(points, t, needed)
    }

    fn memory_bytes(&self) -> usize {
        self.occupied.len() * 8
            + self.rank.len() * 4
            + self.records.len() * std::mem::size_of::<MixedCell>()
            + self.candidates.len() * 24
    }
}
