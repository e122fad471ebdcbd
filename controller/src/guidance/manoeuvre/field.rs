//! The local map the manoeuvre planner searches in: a distance field over a window of
//! the world (each cell the distance from its centre to the nearest obstacle's edge,
//! capped) and the car's rectangle checked against it. The field settles most poses at
//! once (every disc covering the rectangle clear, or a disc inside it touched); the
//! rest are decided exactly, rectangle against circle, with the obstacles near the
//! pose. Never the planning circle: the rectangle, grown by the manoeuvre margin.

use super::super::footprint::Footprint;
use super::path::PathPoint;
use crate::grid::{CellMap, Grid};
use crate::perception::SeenWindow;

/// Distances are capped at this, metres (beyond it every pose is clear anyway).
const CAP: f64 = 1.5;
/// Side of the buckets the obstacles are filed in for the exact check, metres.
const BUCKET: f64 = 2.0;
/// Discs covering the rectangle along its axis for the quick check.
const COVER: usize = 3;

/// An obstacle as the manoeuvre planner sees it: a disc, world frame. The rectangle
/// keeps `r` plus its margin from the centre; `r` is negative for an obstacle the car
/// already stands nearer than the margin (`ManoeuvreRequest::field`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disc {
    pub x: f64,
    pub y: f64,
    pub r: f64,
}

/// The distance field over a window, and the car's rectangle.
#[derive(Clone, Debug)]
pub struct Field {
    grid: Grid,
    dist: Vec<f32>,
    discs: Vec<Disc>,
    buckets: CellMap<Vec<u32>>,
    /// The largest disc's radius (how far from its bucket a disc reaches).
    max_r: f64,
    car: Footprint,
    /// The radius of the [`COVER`] discs covering the rectangle, its margin included.
    cover: f64,
    /// Space seen free: the car backs only into it (None: everywhere).
    seen: Option<SeenWindow>,
    /// The box (x and y lows, then highs) within which a pose has its rectangle's
    /// corners in the window whatever its heading: the window less the farthest
    /// corner's reach and a micrometre, far more than the corners' rounding.
    sure_inside: [f64; 4],
}

impl Field {
    /// The field over the window `lo`..`hi` (world frame) at `res` metres per cell,
    /// for the car's rectangle `car` (its margin included).
    pub fn new(lo: [f64; 2], hi: [f64; 2], res: f64, discs: Vec<Disc>, car: Footprint) -> Field {
        let grid = Grid::covering(lo, hi, res);
        let half = (car.front + car.rear) / 2.0;
        let reach = car.front.max(car.rear).hypot(car.half_width) + 1e-6;
        let top = grid.hi();
        let mut field = Field {
            grid,
            dist: vec![CAP as f32; grid.len()],
            discs: Vec::new(),
            buckets: CellMap::default(),
            max_r: 0.0,
            car,
            cover: (half / COVER as f64).hypot(car.half_width) + car.margin,
            seen: None,
            sure_inside: [
                grid.x0 + reach,
                grid.y0 + reach,
                top[0] - reach,
                top[1] - reach,
            ],
        };
        for d in discs {
            field.add(d);
        }
        field
    }

    /// The window `lo`..`hi` (cells of `res`: whether a corner lies in it is all they
    /// answer) with the obstacles filed for the exact check only, no distances: every pose is then decided exactly, rectangle against circle, which
    /// for a few poses (a path being followed) costs far less than the distances over
    /// the window would. Not for a search: [`Field::distance`] knows nothing there.
    pub fn exact_only(
        lo: [f64; 2],
        hi: [f64; 2],
        res: f64,
        discs: Vec<Disc>,
        car: Footprint,
    ) -> Field {
        let mut field = Field::new(lo, hi, res, Vec::new(), car);
        field.dist = Vec::new();
        for d in discs {
            field.file(d);
        }
        field
    }

    /// The field with backward motion only into `seen`.
    pub fn with_seen(self, seen: Option<SeenWindow>) -> Field {
        Field { seen, ..self }
    }

    /// Whether the car may be at `p`: the rectangle clear and, reached backwards, in
    /// seen space.
    pub fn passable(&self, p: &PathPoint) -> bool {
        self.passable_turned(p, p.theta.sin_cos())
    }

    /// [`Field::passable`], the sine and cosine of the heading given (`turn`).
    pub fn passable_turned(&self, p: &PathPoint, turn: (f64, f64)) -> bool {
        self.clear_turned(p.pose(), turn) && (p.forward || self.seen_turned(p.pose(), turn))
    }

    /// Whether the rectangle at `pose` lies in seen space
    /// ([`crate::perception::rectangle_seen`]), the sine and cosine of its heading given
    /// (`turn`).
    pub fn seen_turned(&self, [x, y, _]: [f64; 3], turn: (f64, f64)) -> bool {
        let Some(seen) = &self.seen else {
            return true;
        };
        let f = &self.car;
        seen.rectangle_seen([x, y], turn, [f.front, f.rear, f.half_width])
    }

    fn add(&mut self, d: Disc) {
        let reach = d.r + CAP;
        let (i0, j0) = self.grid.cell(d.x - reach, d.y - reach);
        let (i1, j1) = self.grid.cell(d.x + reach, d.y + reach);
        let g = self.grid;
        for j in j0.max(0)..=j1.min(g.ny as i64 - 1) {
            let dy = g.centre_y(j) - d.y;
            for i in i0.max(0)..=i1.min(g.nx as i64 - 1) {
                let k = j as usize * g.nx + i as usize;
                let dx = g.centre_x(i) - d.x;
                if surely_not_nearer(dx, dy, d.r, self.dist[k]) {
                    continue;
                }
                let e = (dx.hypot(dy) - d.r) as f32;
                if e < self.dist[k] {
                    self.dist[k] = e;
                }
            }
        }
        self.file(d);
    }

    /// File `d` for the exact check.
    fn file(&mut self, d: Disc) {
        self.max_r = self.max_r.max(d.r);
        let id = self.discs.len() as u32;
        self.discs.push(d);
        let key = bucket(d.x, d.y);
        self.buckets.entry(key).or_default().push(id);
    }

    /// Whether (x, y) lies in the window.
    pub fn inside(&self, x: f64, y: f64) -> bool {
        self.grid.index(x, y).is_some()
    }

    /// The distance from (x, y) to the nearest obstacle's edge, to within half a cell's
    /// diagonal (capped; 0 outside the window).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        self.grid
            .index(x, y)
            .and_then(|k| self.dist.get(k))
            .map_or(0.0, |&d| f64::from(d))
    }

    /// How far a cell's distance may be off at a point in it, metres.
    fn slack(&self) -> f64 {
        self.grid.res * std::f64::consts::FRAC_1_SQRT_2
    }

    /// The window's corners.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        ([self.grid.x0, self.grid.y0], self.grid.hi())
    }

    pub fn footprint(&self) -> &Footprint {
        &self.car
    }

    /// Whether the car's rectangle (grown by its margin) at `pose` clears every
    /// obstacle and lies in the window.
    pub fn clear(&self, pose: [f64; 3]) -> bool {
        self.clear_turned(pose, pose[2].sin_cos())
    }

    /// [`Field::clear`], the sine and cosine of the heading given (`turn`).
    pub fn clear_turned(&self, [x, y, _]: [f64; 3], turn: (f64, f64)) -> bool {
        let f = &self.car;
        let (s, c) = turn;
        let half = (f.front + f.rear) / 2.0;
        let mid = (f.front - f.rear) / 2.0;
        if self.dist.is_empty() {
            return self.corners_inside(x, y, c, s) && self.exact(x, y, c, s);
        }
        let slack = self.slack();
        let on_axis = |u: f64| (x + u * c, y + u * s);
        // Every covering disc clear: clear.
        let covered = (0..COVER).all(|k| {
            let u = mid - half + half / COVER as f64 * (2 * k + 1) as f64;
            let (px, py) = on_axis(u);
            self.grid
                .index(px, py)
                .is_some_and(|k| f64::from(self.dist[k]) - slack >= self.cover)
        });
        if covered {
            return self.corners_inside(x, y, c, s);
        }
        // A disc of the half width inside the rectangle touched: not clear.
        let inner = f.half_width + f.margin;
        let touched = [-f.rear + f.half_width, mid, f.front - f.half_width]
            .into_iter()
            .any(|u| {
                let (px, py) = on_axis(u);
                self.distance(px, py) + slack < inner
            });
        if touched {
            return false;
        }
        self.corners_inside(x, y, c, s) && self.exact(x, y, c, s)
    }

    /// Whether the rectangle's corners lie in the window (beyond it nothing is known),
    /// the car at (x, y) heading (cos `c`, sin `s`).
    fn corners_inside(&self, x: f64, y: f64, c: f64, s: f64) -> bool {
        let [x0, y0, x1, y1] = self.sure_inside;
        if x >= x0 && y >= y0 && x <= x1 && y <= y1 {
            return true;
        }
        let f = &self.car;
        [
            (f.front, f.half_width),
            (f.front, -f.half_width),
            (-f.rear, f.half_width),
            (-f.rear, -f.half_width),
        ]
        .into_iter()
        .all(|(u, v)| self.inside(x + u * c - v * s, y + u * s + v * c))
    }

    /// The exact check, rectangle against each obstacle near it (compared squared: a
    /// disc's radius plus the margin is never negative).
    fn exact(&self, x: f64, y: f64, c: f64, s: f64) -> bool {
        let f = &self.car;
        let reach = f.front.max(f.rear).hypot(f.half_width) + f.margin + self.max_r;
        let (b0, b1) = (bucket(x - reach, y - reach), bucket(x + reach, y + reach));
        for bj in b0.1..=b1.1 {
            for bi in b0.0..=b1.0 {
                let Some(ids) = self.buckets.get(&(bi, bj)) else {
                    continue;
                };
                for &id in ids {
                    let d = self.discs[id as usize];
                    let (du, dv) = f.outside(c, s, d.x - x, d.y - y);
                    let keep = d.r + f.margin;
                    if du * du + dv * dv <= keep * keep {
                        return false;
                    }
                }
            }
        }
        true
    }
}

/// Whether a disc of radius `r` at (`dx`, `dy`) from a cell's centre surely leaves the
/// cell's distance `dist` as it is (`(dx.hypot(dy) - r) as f32 >= dist`), decided
/// without the dear `hypot`: the squared distance exceeds the square of `dist + r` by
/// far more than the roundings of the squares and of `hypot` (a few parts in 1e16),
/// so `hypot` is beyond `dist + r` and, the roundings being monotonic, the distance it
/// gives is not below `dist`.
fn surely_not_nearer(dx: f64, dy: f64, r: f64, dist: f32) -> bool {
    let t = f64::from(dist) + r;
    dx * dx + dy * dy > t * t * (1.0 + 1e-9)
}

fn bucket(x: f64, y: f64) -> (i64, i64) {
    ((x / BUCKET).floor() as i64, (y / BUCKET).floor() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const CAR: Footprint = Footprint {
        front: 2.025,
        rear: 0.375,
        half_width: 0.6,
        margin: 0.1,
    };

    /// Whether the rectangle clears every disc, checked the slow way.
    fn brute(pose: [f64; 3], discs: &[Disc]) -> bool {
        discs
            .iter()
            .all(|d| CAR.distance(pose[0], pose[1], pose[2], d.x, d.y) > d.r + CAR.margin)
    }

    #[test]
    fn the_field_and_the_exact_only_one_agree_with_the_exact_rectangle_check_everywhere() {
        let discs: Vec<Disc> = (0..40)
            .map(|k| {
                let a = f64::from(k) * 0.7;
                Disc {
                    x: 5.0 + 4.0 * a.cos() + f64::from(k % 3),
                    y: 5.0 + 4.0 * a.sin(),
                    r: 0.1 + 0.05 * f64::from(k % 4),
                }
            })
            .collect();
        let field = Field::new([-5.0, -5.0], [15.0, 15.0], 0.1, discs.clone(), CAR);
        let exact = Field::exact_only([-5.0, -5.0], [15.0, 15.0], 0.1, discs.clone(), CAR);
        let mut checked = 0;
        for i in 0..60 {
            for j in 0..60 {
                for h in 0..8 {
                    let pose = [
                        f64::from(i) * 0.2 - 1.0,
                        f64::from(j) * 0.2 - 1.0,
                        f64::from(h) * 0.8,
                    ];
                    let clear = brute(pose, &discs);
                    assert_eq!(field.clear(pose), clear, "{pose:?}");
                    assert_eq!(exact.clear(pose), clear, "exact only: {pose:?}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 28_800);
    }

    #[test]
    fn the_distances_are_those_of_hypot_for_every_disc() {
        // Discs crowded (most cells near many), some of negative radius, off the
        // cells' grid; a generator of its own keeps the test deterministic.
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let discs: Vec<Disc> = (0..300)
            .map(|_| Disc {
                x: 8.0 * next() - 1.0,
                y: 6.0 * next() - 1.0,
                r: 0.8 * next() - 0.2,
            })
            .collect();
        let field = Field::new([0.0, 0.0], [6.0, 4.0], 0.1, discs.clone(), CAR);
        for (k, &got) in field.dist.iter().enumerate() {
            let (cx, cy) = field.grid.centre(k);
            let want = discs
                .iter()
                .map(|d| ((cx - d.x).hypot(cy - d.y) - d.r) as f32)
                .fold(CAP as f32, f32::min);
            assert_eq!(got.to_bits(), want.to_bits(), "cell {k}");
        }
    }

    #[test]
    fn the_corners_are_in_the_window_where_the_sure_box_says() {
        let field = Field::new([0.0, 0.0], [10.0, 10.0], 0.1, Vec::new(), CAR);
        let corner_in = |x: f64, y: f64, c: f64, s: f64, u: f64, v: f64| {
            field.inside(x + u * c - v * s, y + u * s + v * c)
        };
        let mut sure = 0;
        for i in 0..400 {
            for h in 0..36 {
                // Across the window's diagonal and out beyond its corners.
                let x = -0.5 + f64::from(i) * 0.0275;
                let y = 10.5 - x * 0.9;
                let (s, c) = (f64::from(h) * 0.17).sin_cos();
                let every = [CAR.front, -CAR.rear].into_iter().all(|u| {
                    [CAR.half_width, -CAR.half_width]
                        .into_iter()
                        .all(|v| corner_in(x, y, c, s, u, v))
                });
                assert_eq!(field.corners_inside(x, y, c, s), every, "{x} {y} {h}");
                let [x0, y0, x1, y1] = field.sure_inside;
                sure += usize::from(x >= x0 && y >= y0 && x <= x1 && y <= y1);
            }
        }
        assert!(sure > 1000, "{sure}");
    }

    #[test]
    fn a_pose_reaching_out_of_the_window_is_not_clear() {
        let field = Field::new([0.0, 0.0], [10.0, 10.0], 0.1, Vec::new(), CAR);
        assert!(field.clear([5.0, 5.0, 0.0]));
        assert!(!field.clear([8.5, 5.0, 0.0]));
        assert_eq!(field.distance(-1.0, 5.0), 0.0);
    }
}
