//! Regular grid geometry shared by the grid-based indexes: a box of cubic cells and the
//! linear index of a cell.

/// A grid of cubic cells covering a box.
#[derive(Clone, Debug)]
pub(crate) struct GridFrame {
    pub origin: [f64; 3],
    pub inv_cell: f64,
    pub cell: f64,
    pub dims: [usize; 3],
}
impl GridFrame {
    /// A grid of cells of side `cell` covering `[lo - margin, hi + margin]`, with the cell
    /// side enlarged if the grid would exceed `max_cells`.
    pub fn covering(
        lo: [f64; 3],
        hi: [f64; 3],
        margin: f64,
        cell: f64,
        max_cells: usize,
    ) -> GridFrame {
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

    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    #[inline(always)]
    pub fn linear(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
}
