//! A grid of square cells over a rectangle of the world, indexed row by row: the
//! manoeuvre planner's distance field and holonomic heuristic and the seen space's
//! window are laid out on one.

/// A map keyed by cells (column, row) of some grid, hashed with FxHash: the default
/// SipHash cost some 200 instructions a lookup, and its keys, drawn anew in each
/// process, buy nothing here (no map's order of iteration matters).
pub type CellMap<V> = rustc_hash::FxHashMap<(i64, i64), V>;

/// Square cells of side `res` from (`x0`, `y0`), `nx` across and `ny` up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub x0: f64,
    pub y0: f64,
    pub res: f64,
    pub nx: usize,
    pub ny: usize,
}

impl Grid {
    /// The grid covering `lo`..`hi` in cells of `res` (at least one each way).
    pub fn covering(lo: [f64; 2], hi: [f64; 2], res: f64) -> Grid {
        Grid {
            x0: lo[0],
            y0: lo[1],
            res,
            nx: ((hi[0] - lo[0]) / res).ceil().max(1.0) as usize,
            ny: ((hi[1] - lo[1]) / res).ceil().max(1.0) as usize,
        }
    }

    /// Cells in the grid.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The column and row of the cell holding (x, y), outside the grid too (negative or
    /// past its size).
    pub fn cell(&self, x: f64, y: f64) -> (i64, i64) {
        (
            ((x - self.x0) / self.res).floor() as i64,
            ((y - self.y0) / self.res).floor() as i64,
        )
    }

    /// The index of the cell holding (x, y); None outside the grid (or for NaN). On
    /// the search's hottest path: the cell is found by truncation once the point is
    /// known not to lie before the grid, where truncation and `floor` agree.
    pub fn index(&self, x: f64, y: f64) -> Option<usize> {
        let (u, v) = ((x - self.x0) / self.res, (y - self.y0) / self.res);
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (i, j) = (u as usize, v as usize);
        (i < self.nx && j < self.ny).then(|| j * self.nx + i)
    }

    /// The centre of the cell at `index`.
    pub fn centre(&self, index: usize) -> (f64, f64) {
        let (i, j) = (index % self.nx, index / self.nx);
        (self.centre_x(i as i64), self.centre_y(j as i64))
    }

    /// The x of column `i`'s centres.
    pub fn centre_x(&self, i: i64) -> f64 {
        self.x0 + (i as f64 + 0.5) * self.res
    }

    /// The y of row `j`'s centres.
    pub fn centre_y(&self, j: i64) -> f64 {
        self.y0 + (j as f64 + 0.5) * self.res
    }

    /// The upper corner of the grid.
    pub fn hi(&self) -> [f64; 2] {
        [
            self.x0 + self.nx as f64 * self.res,
            self.y0 + self.ny as f64 * self.res,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_is_in_the_cell_floor_gives_and_none_outside() {
        let g = Grid::covering([-1.0, -2.0], [1.0, 0.0], 0.5);
        assert_eq!((g.nx, g.ny), (4, 4));
        assert_eq!(g.index(-1.0, -2.0), Some(0));
        assert_eq!(g.index(-0.51, -1.49), Some(4));
        assert_eq!(g.index(0.99, -0.01), Some(15));
        for (x, y) in [(-1.01, -1.0), (0.0, -2.01), (1.0, -1.0), (0.0, 0.0)] {
            assert_eq!(g.index(x, y), None, "({x}, {y})");
        }
        assert_eq!(g.index(f64::NAN, 0.0), None);
        assert_eq!(g.cell(-0.51, -1.49), (0, 1));
        assert_eq!(g.cell(-1.01, 0.2), (-1, 4));
        assert_eq!(g.centre(5), (-0.25, -1.25));
        assert_eq!(g.hi(), [1.0, 0.0]);
    }
}
