//! Space the laser has seen free: every beam marks the cells between the scanner and its
//! return (or its range, capped) as seen, and the car's own rectangle is seen where it
//! stands; the cell of each return is remembered as a hit until beams passing through
//! it outweigh the returns from it (a post's cell is grazed by beams that pass beside
//! it, scan after scan, as well as returned from). The laser looks forward, so what lies behind the car is known only from what
//! it saw before (or from where it drove): a manoeuvre backs only into seen space
//! (`guidance::manoeuvre`). A world grid of 0.25 m cells, filed in chunks of 8 x 8 m, so
//! a long route costs memory only where the car has been.

use super::{Beam, Pose2, Scan};
use crate::grid::{CellMap, Grid};

/// Side of a cell, metres.
pub const CELL: f64 = 0.25;
/// Cells per side of a chunk (one row a `u32`).
const CHUNK: i64 = 32;
/// A beam marks at most this far, metres (manoeuvres back into what is near).
const REACH: f64 = 10.0;
/// Before a return, this much of the beam is not marked (the obstacle's near side).
const SHORT_OF_HIT: f64 = 0.3;
/// Beams marked per scan are at least this far apart, radians (1.5 degrees: 0.26 m
/// apart at the reach).
const BEAM_SPACING: f64 = 0.026;
/// The evidence a return adds to its cell, a beam passing through takes away, and the
/// most a cell holds: a cell is a hit while it holds any. Returned from three times as
/// strongly as passed through, a surface stays remembered though beams graze its cell;
/// a walker's cells clear within [`HIT_CAP`] beams once it has gone.
const HIT_GAIN: u8 = 3;
const PASS_LOSS: u8 = 1;
const HIT_CAP: u8 = 12;

/// A chunk's hit evidence, one byte a cell.
type Evidence = [[u8; CHUNK as usize]; CHUNK as usize];

/// The seen space. Its chunks are filed by their coordinates; nothing iterates them in
/// an order that matters ([`SeenSpace::hits_in`] sorts).
#[derive(Clone, Debug, Default)]
pub struct SeenSpace {
    chunks: Chunks,
    /// Evidence of returns per cell ([`HIT_GAIN`]): what the laser saw of the
    /// obstacles, remembered once they are out of its view (perception's tracks of
    /// them are dropped then).
    hits: CellMap<Evidence>,
}

/// SeenSpace space over a window of the world, copied out for one search.
#[derive(Clone, Debug, PartialEq)]
pub struct SeenWindow {
    grid: Grid,
    cells: Vec<bool>,
    /// The cells not seen below and left of each grid corner (a summed-area table,
    /// `nx + 1` corners a row): whether a box of cells is all seen is four lookups.
    unseen: Vec<u32>,
}

fn cell(x: f64, y: f64) -> (i64, i64) {
    ((x / CELL).floor() as i64, (y / CELL).floor() as i64)
}

/// The cells a ray from (x, y) in the direction (c, s) (a unit vector) crosses over
/// `length` metres, in order (Amanatides and Woo's traversal: one step per cell, no
/// rounding per point), each yielded as the ray reaches it, so that the cells are
/// marked as they come rather than gathered first.
fn traverse(x: f64, y: f64, c: f64, s: f64, length: f64) -> Traversal {
    let (i, j) = cell(x, y);
    let axis = |p: f64, d: f64, k: i64| {
        if d.abs() < 1e-12 {
            return (0, f64::INFINITY, f64::INFINITY);
        }
        let step = if d > 0.0 { 1 } else { -1 };
        let edge = (k + i64::from(d > 0.0)) as f64 * CELL;
        (step, (edge - p) / d, CELL / d.abs())
    };
    let (si, ti, di) = axis(x, c, i);
    let (sj, tj, dj) = axis(y, s, j);
    Traversal {
        here: (i, j),
        last: cell(x + length * c, y + length * s),
        step: (si, sj),
        next_edge: (ti, tj),
        per_cell: (di, dj),
        // A ray crosses at most this many cells (the guard against rounding at the end).
        left: ((length / CELL) * 2.0).ceil() as usize + 2,
    }
}

/// A ray's walk through the cells ([`traverse`]).
struct Traversal {
    here: (i64, i64),
    last: (i64, i64),
    /// The cell steps along x and y (-1, 0 or 1).
    step: (i64, i64),
    /// The ray's length at the next cell edge across x and across y.
    next_edge: (f64, f64),
    /// The ray's length across one cell along x and along y.
    per_cell: (f64, f64),
    /// The cells it may yet yield.
    left: usize,
}

impl Iterator for Traversal {
    type Item = (i64, i64);

    fn next(&mut self) -> Option<(i64, i64)> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        let here = self.here;
        if here == self.last {
            self.left = 0;
        } else if self.next_edge.0 < self.next_edge.1 {
            self.next_edge.0 += self.per_cell.0;
            self.here.0 += self.step.0;
        } else {
            self.next_edge.1 += self.per_cell.1;
            self.here.1 += self.step.1;
        }
        Some(here)
    }
}

type Chunks = CellMap<[u32; CHUNK as usize]>;

/// log2 of [`CHUNK`]: a cell's chunk and its place in it by shift and mask, as
/// `div_euclid` and `rem_euclid` by [`CHUNK`] give them (negative cells too).
const CHUNK_SHIFT: u32 = CHUNK.trailing_zeros();
const _: () = assert!(CHUNK == 1 << CHUNK_SHIFT);

fn chunk_of((i, j): (i64, i64)) -> (i64, i64) {
    (i >> CHUNK_SHIFT, j >> CHUNK_SHIFT)
}

/// A cell's column and row within its chunk.
fn within((i, j): (i64, i64)) -> (usize, usize) {
    ((i & (CHUNK - 1)) as usize, (j & (CHUNK - 1)) as usize)
}

fn get(chunks: &Chunks, cell: (i64, i64)) -> bool {
    let (u, v) = within(cell);
    chunks
        .get(&chunk_of(cell))
        .is_some_and(|c| c[v] & (1 << u) != 0)
}

impl SeenSpace {
    /// Cells seen free, in the order of a ray or a row (neighbours mostly share a
    /// chunk, looked up once for them): no obstacle remembered there either.
    fn mark_cells(&mut self, cells: impl IntoIterator<Item = (i64, i64)>) {
        let mut cells = cells.into_iter();
        let mut next = cells.next();
        while let Some(first) = next {
            let key = chunk_of(first);
            let seen = self.chunks.entry(key).or_insert([0; CHUNK as usize]);
            let mut hits = self.hits.get_mut(&key);
            // One pass over the run of cells in this chunk.
            let mut c = first;
            next = loop {
                let (u, v) = within(c);
                seen[v] |= 1 << u;
                if let Some(h) = hits.as_deref_mut() {
                    h[v][u] = h[v][u].saturating_sub(PASS_LOSS);
                }
                match cells.next() {
                    Some(n) if chunk_of(n) == key => c = n,
                    other => break other,
                }
            };
        }
    }

    fn cell_seen(&self, cell: (i64, i64)) -> bool {
        get(&self.chunks, cell)
    }

    /// The centres of the cells beams returned from within `lo`..`hi`.
    pub fn hits_in(&self, lo: [f64; 2], hi: [f64; 2]) -> Vec<[f64; 2]> {
        let (i0, j0) = cell(lo[0], lo[1]);
        let (i1, j1) = cell(hi[0], hi[1]);
        let mut out = Vec::new();
        for (&(ci, cj), rows) in &self.hits {
            let (bi, bj) = (ci * CHUNK, cj * CHUNK);
            if bi + CHUNK <= i0 || bi > i1 || bj + CHUNK <= j0 || bj > j1 {
                continue;
            }
            for (r, row) in rows.iter().enumerate() {
                for (b, &e) in row.iter().enumerate() {
                    let (i, j) = (bi + b as i64, bj + r as i64);
                    if e > 0 && (i0..=i1).contains(&i) && (j0..=j1).contains(&j) {
                        out.push([(i as f64 + 0.5) * CELL, (j as f64 + 0.5) * CELL]);
                    }
                }
            }
        }
        // The map's order is not the same from run to run: sorted, a search over them
        // is.
        out.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
        out
    }

    /// Whether (x, y) has been seen.
    pub fn seen(&self, x: f64, y: f64) -> bool {
        self.cell_seen(cell(x, y))
    }

    /// A beam returned from `(i, j)`: [`HIT_GAIN`] more evidence there.
    fn returned(&mut self, cell: (i64, i64)) {
        let chunk = self
            .hits
            .entry(chunk_of(cell))
            .or_insert([[0; CHUNK as usize]; CHUNK as usize]);
        let (u, v) = within(cell);
        let e = &mut chunk[v][u];
        *e = e.saturating_add(HIT_GAIN).min(HIT_CAP);
    }

    /// Mark what the scan saw, the laser at `laser` (world frame).
    pub fn update(&mut self, scan: &Scan<'_>, laser: &Pose2) {
        let n = scan.ranges.len();
        let every = (BEAM_SPACING / scan.angle_increment.abs().max(1e-6))
            .ceil()
            .max(1.0) as usize;
        for i in (0..n).step_by(every) {
            let a = laser.yaw + scan.beam_angle(i);
            let (c, s) = (a.cos(), a.sin());
            let (reach, hit) = match scan.beam(i) {
                Beam::Hit(r) if r <= REACH => (r - SHORT_OF_HIT, Some(r)),
                Beam::Hit(_) => (REACH, None),
                Beam::NoReturn => (REACH.min(scan.range_max), None),
                Beam::Dropout => continue,
            };
            self.mark_cells(traverse(laser.x, laser.y, c, s, reach.max(0.0)));
            if let Some(r) = hit {
                self.returned(cell(laser.x + r * c, laser.y + r * s));
            }
        }
    }

    /// Mark the space `depth` metres deep behind a line `from` metres behind the pose
    /// (x, y, heading), `half_width` either side: what the operator saw clear behind the
    /// car at the start. A cell is marked where any point falls in it, so marks reach up
    /// to a cell's extent along the heading past a rectangle's far end; this one is
    /// marked half that shorter, so that they reach at most half a cell's extent past
    /// what was checked, as if cells were marked by their centres (a whole cell let a
    /// reversal under GPS noise end 0.1 m from a cart 0.4 m beyond the checked depth).
    pub fn mark_checked_behind(&mut self, pose: [f64; 3], from: f64, depth: f64, half_width: f64) {
        let reach = CELL / 2.0 * (pose[2].cos().abs() + pose[2].sin().abs());
        self.mark_rectangle(pose, from + (depth - reach).max(0.0), -from, half_width);
    }

    /// Mark the rectangle from `back` metres behind the pose (x, y, heading) to `front`
    /// ahead of it, `half_width` either side: where the car stands.
    pub fn mark_rectangle(&mut self, pose: [f64; 3], back: f64, front: f64, half_width: f64) {
        let (c, s) = (pose[2].cos(), pose[2].sin());
        let nu = ((back + front) / (CELL / 2.0)).ceil() as usize;
        let nv = (2.0 * half_width / (CELL / 2.0)).ceil() as usize;
        for a in 0..=nu {
            let u = -back + (back + front) * a as f64 / nu as f64;
            self.mark_cells((0..=nv).map(|b| {
                let v = -half_width + 2.0 * half_width * b as f64 / nv as f64;
                cell(pose[0] + u * c - v * s, pose[1] + u * s + v * c)
            }));
        }
    }

    /// The seen space over the window `lo`..`hi`.
    pub fn window(&self, lo: [f64; 2], hi: [f64; 2]) -> SeenWindow {
        let (i0, j0) = cell(lo[0], lo[1]);
        let (i1, j1) = cell(hi[0], hi[1]);
        let (nx, ny) = ((i1 - i0 + 1).max(1) as usize, (j1 - j0 + 1).max(1) as usize);
        let mut cells = Vec::with_capacity(nx * ny);
        for j in j0..j0 + ny as i64 {
            // Along a row the chunk changes every CHUNK cells: looked up once for them.
            let mut chunk: Option<(i64, Option<&[u32; CHUNK as usize]>)> = None;
            for i in i0..i0 + nx as i64 {
                let ci = i.div_euclid(CHUNK);
                let rows = match chunk {
                    Some((at, rows)) if at == ci => rows,
                    _ => {
                        let rows = self.chunks.get(&(ci, j.div_euclid(CHUNK)));
                        chunk = Some((ci, rows));
                        rows
                    }
                };
                let bit = 1 << i.rem_euclid(CHUNK);
                cells.push(rows.is_some_and(|r| r[j.rem_euclid(CHUNK) as usize] & bit != 0));
            }
        }
        let grid = Grid {
            x0: i0 as f64 * CELL,
            y0: j0 as f64 * CELL,
            res: CELL,
            nx,
            ny,
        };
        SeenWindow {
            unseen: unseen_sums(&grid, &cells),
            grid,
            cells,
        }
    }
}

impl SeenWindow {
    /// Whether (x, y) has been seen (outside the window: no).
    pub fn seen(&self, x: f64, y: f64) -> bool {
        self.grid.index(x, y).is_some_and(|k| self.cells[k])
    }

    /// [`rectangle_seen`] in this window, the same answer sooner: a rectangle, or a
    /// side, whose cells are all seen ([`SeenWindow::around_seen`]) is not sampled
    /// point by point.
    /// The rectangle at (x, y) heading (sin, cos) `turn`; `extent` its front, rear
    /// and half width.
    pub fn rectangle_seen(&self, at: [f64; 2], turn: (f64, f64), extent: [f64; 3]) -> bool {
        sides_seen(
            |x, y| self.seen(x, y),
            |points| self.around_seen(points),
            at,
            turn,
            extent,
        )
    }

    /// Whether every cell of the box round `points` grown by a cell lies in the window
    /// and is seen: then so is every point within a rounding error of the box (a
    /// sample along a side computed another way). False when unsure (a NaN).
    fn around_seen(&self, points: &[[f64; 2]]) -> bool {
        let g = &self.grid;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            if p[0].is_nan() || p[1].is_nan() {
                return false;
            }
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        // The box's first and last corners in the table along one axis: one cell before
        // the lowest point's and one past the highest's, within the window (where the
        // offsets are at least a cell, truncation is their floor).
        let span = |k: usize, origin: f64, n: usize| {
            let (u0, u1) = ((lo[k] - origin) / g.res, (hi[k] - origin) / g.res);
            let (i0, i1) = (u0 as u32 as usize, u1 as u32 as usize + 2);
            (u0 >= 1.0 && i1 <= n).then(|| (i0 - 1, i1))
        };
        let (Some((i0, i1)), Some((j0, j1))) = (span(0, g.x0, g.nx), span(1, g.y0, g.ny)) else {
            return false;
        };
        let at = |i: usize, j: usize| self.unseen[j * (g.nx + 1) + i];
        at(i1, j1) + at(i0, j0) == at(i0, j1) + at(i1, j0)
    }
}

/// The summed-area table of the cells not seen ([`SeenWindow::unseen`]).
fn unseen_sums(grid: &Grid, cells: &[bool]) -> Vec<u32> {
    let w = grid.nx + 1;
    let mut sums = vec![0u32; w * (grid.ny + 1)];
    for j in 0..grid.ny {
        let mut row = 0;
        for i in 0..grid.nx {
            row += u32::from(!cells[j * grid.nx + i]);
            sums[(j + 1) * w + i + 1] = sums[j * w + i + 1] + row;
        }
    }
    sums
}

/// Whether the car's rectangle at `pose` (`front` ahead of it, `rear` behind,
/// `half_width` either side) lies in seen space, by `seen` along its four sides every
/// half a cell at most. The sides are what moves into new space: a path sampled more
/// finely than a cell sweeps them over everything the rectangle covers. (Its corners
/// and the middles of its sides alone, 1.2 m apart, let a reversal end on a post the
/// laser never saw between them.)
pub fn rectangle_seen(
    seen: impl Fn(f64, f64) -> bool,
    pose: [f64; 3],
    front: f64,
    rear: f64,
    half_width: f64,
) -> bool {
    let [x, y, theta] = pose;
    let turn = (theta.sin(), theta.cos());
    sides_seen(seen, |_| false, [x, y], turn, [front, rear, half_width])
}

/// [`rectangle_seen`] side by side: true at once where `known` (given the rectangle's
/// corners, or a side's ends) knows them all seen, a side skipped where it knows that
/// side seen; the rectangle at (x, y) heading (sin, cos) `turn`, its extent its front,
/// rear and half width.
fn sides_seen(
    seen: impl Fn(f64, f64) -> bool,
    known: impl Fn(&[[f64; 2]]) -> bool,
    [x, y]: [f64; 2],
    (s, c): (f64, f64),
    [front, rear, half_width]: [f64; 3],
) -> bool {
    let point = |u: f64, v: f64| [x + u * c - v * s, y + u * s + v * c];
    let corners = [
        point(-rear, -half_width),
        point(-rear, half_width),
        point(front, -half_width),
        point(front, half_width),
    ];
    if known(&corners) {
        return true;
    }
    let at = |u: f64, v: f64| {
        let [px, py] = point(u, v);
        seen(px, py)
    };
    let steps = |len: f64| ((len / (CELL / 2.0)).ceil() as usize).max(1);
    let (nu, nv) = (steps(front + rear), steps(2.0 * half_width));
    let along = |k: usize| -rear + (front + rear) * k as f64 / nu as f64;
    let across = |k: usize| -half_width + 2.0 * half_width * k as f64 / nv as f64;
    let long = |v: f64, ends: [[f64; 2]; 2]| known(&ends) || (0..=nu).all(|k| at(along(k), v));
    let short = |u: f64, ends: [[f64; 2]; 2]| known(&ends) || (1..nv).all(|k| at(u, across(k)));
    let [rear_right, rear_left, front_right, front_left] = corners;
    long(-half_width, [rear_right, front_right])
        && long(half_width, [rear_left, front_left])
        && short(-rear, [rear_right, rear_left])
        && short(front, [front_right, front_left])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_beam_marks_up_to_short_of_its_return_and_nothing_behind_the_laser() {
        let ranges = [5.0f32, f32::INFINITY, f32::NAN];
        let scan = Scan {
            stamp: 0.0,
            angle_min: 0.0,
            angle_increment: std::f64::consts::FRAC_PI_2,
            range_min: 0.1,
            range_max: 20.0,
            ranges: &ranges,
        };
        let mut seen = SeenSpace::default();
        seen.update(
            &scan,
            &Pose2 {
                x: 1.0,
                y: 1.0,
                yaw: 0.0,
            },
        );
        // East: up to 0.3 m short of the return at x = 6.
        assert!(seen.seen(2.0, 1.1) && seen.seen(5.5, 1.1));
        assert!(!seen.seen(6.2, 1.1));
        // North: no return, marked to the reach.
        assert!(seen.seen(1.1, 10.5) && !seen.seen(1.1, 11.5));
        // The return is remembered, until beams passing through its cell outweigh it:
        // one return against three passes.
        assert_eq!(seen.hits_in([0.0, 0.0], [10.0, 10.0]), vec![[6.125, 1.125]]);
        assert!(seen.hits_in([7.0, 0.0], [10.0, 10.0]).is_empty());
        let far = [9.0f32];
        let through = Scan {
            angle_increment: 0.1,
            ranges: &far,
            ..scan
        };
        let laser = Pose2 {
            x: 1.0,
            y: 1.1,
            yaw: 0.0,
        };
        let near = |seen: &SeenSpace| {
            seen.hits_in([0.0, 0.0], [10.0, 10.0])
                .iter()
                .any(|h| h[0] < 9.0)
        };
        seen.update(&through, &laser);
        seen.update(&through, &laser);
        assert!(near(&seen), "grazed twice, still remembered");
        seen.update(&through, &laser);
        assert!(!near(&seen), "passed through three times, forgotten");
        // West (the dropout) and behind: nothing.
        assert!(!seen.seen(-1.0, 1.1));
        let w = seen.window([0.0, 0.0], [8.0, 8.0]);
        assert!(w.seen(3.0, 1.1) && !w.seen(-1.0, 1.1) && !w.seen(30.0, 1.1));
    }

    #[test]
    fn shift_and_mask_place_cells_as_euclidean_division_does() {
        for i in -200..200 {
            let c = (i, 3 - i);
            assert_eq!(
                chunk_of(c),
                (i.div_euclid(CHUNK), (3 - i).div_euclid(CHUNK))
            );
            let (u, v) = within(c);
            assert_eq!(
                (u as i64, v as i64),
                (i.rem_euclid(CHUNK), (3 - i).rem_euclid(CHUNK))
            );
        }
    }

    #[test]
    fn a_ray_crosses_every_cell_on_its_way_once_in_order() {
        let out: Vec<_> = traverse(0.1, 0.1, 1.0, 0.0, 1.0).collect();
        assert_eq!(out, vec![(0, 0), (1, 0), (2, 0), (3, 0), (4, 0)]);
        let (c, s) = (-0.6, -0.8);
        let out: Vec<_> = traverse(0.1, 0.1, c, s, 2.0).collect();
        assert_eq!(out.first(), Some(&(0, 0)));
        assert_eq!(out.last(), Some(&cell(0.1 + 2.0 * c, 0.1 + 2.0 * s)));
        // Each step moves to a neighbour across one side.
        assert!(
            out.windows(2)
                .all(|w| (w[0].0 - w[1].0).abs() + (w[0].1 - w[1].1).abs() == 1)
        );
    }

    #[test]
    fn the_rectangle_is_marked_turned_with_the_pose() {
        let mut seen = SeenSpace::default();
        seen.mark_rectangle([10.0, -10.0, std::f64::consts::FRAC_PI_2], 3.0, 2.0, 0.6);
        assert!(seen.seen(10.0, -12.9) && seen.seen(10.5, -8.1));
        assert!(!seen.seen(10.0, -13.4) && !seen.seen(11.0, -10.0));
    }

    #[test]
    fn a_rectangle_with_one_unseen_cell_on_its_side_or_back_is_not_seen() {
        // The golf car's rectangle at the origin, heading east; one cell unseen where
        // the old check (corners, middles of the sides) never looked.
        for hole in [[0.2, 0.6], [-0.375, 0.3], [1.5, -0.6], [2.025, -0.25]] {
            let seen = |x: f64, y: f64| {
                (x - hole[0]).abs() > CELL / 2.0 || (y - hole[1]).abs() > CELL / 2.0
            };
            assert!(
                !rectangle_seen(seen, [0.0, 0.0, 0.0], 2.025, 0.375, 0.6),
                "{hole:?}"
            );
        }
        assert!(rectangle_seen(
            |_, _| true,
            [0.0, 0.0, 0.0],
            2.025,
            0.375,
            0.6
        ));
    }

    #[test]
    fn the_window_answers_as_the_check_point_by_point() {
        // Seen space with holes and edges: a marked patch, two unseen cells in it.
        let mut seen = SeenSpace::default();
        seen.mark_rectangle([4.0, 4.0, 0.3], 3.0, 3.0, 2.5);
        let mut w = seen.window([0.0, 0.0], [8.0, 8.0]);
        for hole in [[3.0, 3.0], [5.5, 4.5]] {
            let k = w.grid.index(hole[0], hole[1]).unwrap();
            w.cells[k] = false;
        }
        w.unseen = unseen_sums(&w.grid, &w.cells);
        let (mut seen_poses, mut skipped) = (0, 0);
        for i in 0..50 {
            for j in 0..50 {
                for h in 0..12 {
                    let (x, y) = (f64::from(i) * 0.17, f64::from(j) * 0.17);
                    let theta = f64::from(h) * 0.53;
                    let turn = (theta.sin(), theta.cos());
                    let fast = w.rectangle_seen([x, y], turn, [2.025, 0.375, 0.6]);
                    let slow =
                        rectangle_seen(|x, y| w.seen(x, y), [x, y, theta], 2.025, 0.375, 0.6);
                    assert_eq!(fast, slow, "{x} {y} {theta}");
                    seen_poses += usize::from(slow);
                    skipped += usize::from(sides_seen(
                        |_, _| false,
                        |c| w.around_seen(c),
                        [x, y],
                        turn,
                        [2.025, 0.375, 0.6],
                    ));
                }
            }
        }
        // Both answers occur, and the table alone knows some seen poses seen.
        assert!(seen_poses > 1000 && seen_poses < 30_000, "{seen_poses}");
        assert!(skipped > 100, "{skipped} of {seen_poses}");
    }
}
