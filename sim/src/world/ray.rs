//! The laser's ray caster, specialised for the world's two solid shapes (posts are
//! circles; boxes and wall segments are oriented rectangles; a wall's joints are
//! circles), in f64, with a broad phase per scan: a shape is a candidate only when its
//! bounding circle comes within the scanner's range (in a world of many shapes, only
//! those binned near the scanner are looked at: [`Bins`]), and each candidate is
//! tested only against the beams inside its angular interval (the bearing of its
//! centre plus or minus the half-angle its bounding circle subtends).
//!
//! Semantics are rapier's solid ray cast: a ray starting inside a shape hits it at
//! range 0; a hit counts up to and including the maximum range; the nearest hit wins.

use std::f64::consts::TAU;

/// A shape's geometry in its own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Form {
    /// A disc of radius `r` about the centre.
    Circle { r: f64 },
    /// A rectangle of half-extents `hx` (along its heading) and `hy`.
    Rect { hx: f64, hy: f64 },
}

/// One shape of the world: its obstacle, its geometry and where it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prim {
    /// Index of the scenario's obstacle it belongs to.
    pub obstacle: usize,
    pub form: Form,
    /// Centre, world frame, metres.
    pub x: f64,
    pub y: f64,
    /// Heading, radians, and its cosine and sine (rectangles).
    pub heading: f64,
    pub cos: f64,
    pub sin: f64,
    /// Radius of the bounding circle about the centre.
    pub bound: f64,
}

impl Prim {
    pub fn circle(obstacle: usize, x: f64, y: f64, r: f64) -> Prim {
        Prim {
            obstacle,
            form: Form::Circle { r },
            x,
            y,
            heading: 0.0,
            cos: 1.0,
            sin: 0.0,
            bound: r,
        }
    }

    pub fn rect(obstacle: usize, x: f64, y: f64, heading: f64, hx: f64, hy: f64) -> Prim {
        let (sin, cos) = heading.sin_cos();
        Prim {
            obstacle,
            form: Form::Rect { hx, hy },
            x,
            y,
            heading,
            cos,
            sin,
            bound: hx.hypot(hy),
        }
    }

    /// Range along the unit direction `(dx, dy)` from `(ox, oy)` to the shape, if the
    /// line hits it ahead (0 when the origin is inside).
    pub fn toi(&self, ox: f64, oy: f64, dx: f64, dy: f64) -> Option<f64> {
        let (cx, cy) = (self.x - ox, self.y - oy);
        match self.form {
            Form::Circle { r } => circle_toi(cx, cy, cx * cx + cy * cy - r * r, dx, dy),
            Form::Rect { hx, hy } => {
                // The origin and the direction in the rectangle's frame.
                let (px, py) = (
                    -(cx * self.cos + cy * self.sin),
                    cx * self.sin - cy * self.cos,
                );
                let (qx, qy) = (dx * self.cos + dy * self.sin, dy * self.cos - dx * self.sin);
                rect_toi(px, py, qx, qy, hx, hy)
            }
        }
    }
}

/// A circle's centre at `(cx, cy)` from the origin, `cc = |c|^2 - r^2`.
fn circle_toi(cx: f64, cy: f64, cc: f64, dx: f64, dy: f64) -> Option<f64> {
    if cc <= 0.0 {
        return Some(0.0);
    }
    let b = dx * cx + dy * cy;
    if b <= 0.0 {
        return None;
    }
    let disc = b * b - cc;
    // The nearer root, in the form without cancellation.
    (disc >= 0.0).then(|| cc / (b + disc.sqrt()))
}

/// Slab test of a ray from `(px, py)` along `(qx, qy)` against `|x| <= hx, |y| <= hy`.
fn rect_toi(px: f64, py: f64, qx: f64, qy: f64, hx: f64, hy: f64) -> Option<f64> {
    if px.abs() <= hx && py.abs() <= hy {
        return Some(0.0);
    }
    let (mut near, mut far) = (0.0_f64, f64::INFINITY);
    for (p, q, h) in [(px, qx, hx), (py, qy, hy)] {
        if q == 0.0 {
            if p.abs() > h {
                return None;
            }
        } else {
            let (t1, t2) = ((-h - p) / q, (h - p) / q);
            near = near.max(t1.min(t2));
            far = far.min(t1.max(t2));
        }
    }
    (near <= far).then_some(near)
}

/// A scanner's beams: unit directions relative to its forward axis, computed once.
#[derive(Clone, Debug, PartialEq)]
pub struct Fan {
    /// Angle of beam 0 from the forward axis, and between beams, radians.
    pub angle_min: f64,
    pub step: f64,
    dirs: Vec<(f64, f64)>,
}

impl Fan {
    pub fn new(angle_min: f64, step: f64, beams: usize) -> Fan {
        let dirs = (0..beams)
            .map(|i| {
                let (s, c) = (angle_min + i as f64 * step).sin_cos();
                (c, s)
            })
            .collect();
        Fan {
            angle_min,
            step,
            dirs,
        }
    }

    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }

    /// The beam indices whose angles (from beam 0, radians, `[0, 2 pi)` for `mid`)
    /// lie within `half` of `mid`, as up to three ranges (the interval may wrap).
    fn beams_within(&self, mid: f64, half: f64) -> impl Iterator<Item = std::ops::Range<usize>> {
        let last = self.dirs.len() as f64 - 1.0;
        let step = self.step;
        [-TAU, 0.0, TAU].into_iter().filter_map(move |shift| {
            let lo = ((mid + shift - half) / step).ceil().max(0.0);
            let hi = ((mid + shift + half) / step).floor().min(last);
            (lo <= hi).then(|| lo as usize..hi as usize + 1)
        })
    }
}

/// The nearest hit of a beam: range and obstacle (`f64::INFINITY` for none).
pub type Hit = (f64, usize);

/// Where a scan is taken from, in the world frame: the scanner's position (metres)
/// and its forward direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScannerPose {
    pub x: f64,
    pub y: f64,
    pub heading_rad: f64,
}

/// Side of a cell of [`Bins`], metres.
const BIN: f64 = 4.0;
/// Worlds of up to this many shapes are scanned shape by shape, without [`Bins`].
const BINNED_FROM: usize = 64;

/// The shapes that stand binned on a grid of [`BIN`] metres by their bounding
/// circles, so a scan visits those near the scanner only; the moving ones apart,
/// always visited. Empty for a small world (every shape visited).
#[derive(Clone, Debug, Default)]
pub struct Bins {
    origin: [f64; 2],
    size: [usize; 2],
    /// Cell `k`'s shapes are `shapes[start[k]..start[k + 1]]`.
    start: Vec<usize>,
    shapes: Vec<usize>,
    moving: Vec<usize>,
}

impl Bins {
    /// The bins of `prims`, `moves` telling which move.
    pub fn new(prims: &[Prim], moves: impl Fn(usize) -> bool) -> Bins {
        if prims.len() <= BINNED_FROM {
            return Bins::default();
        }
        let fixed: Vec<usize> = (0..prims.len()).filter(|&i| !moves(i)).collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in fixed.iter().map(|&i| &prims[i]) {
            lo = [lo[0].min(p.x - p.bound), lo[1].min(p.y - p.bound)];
            hi = [hi[0].max(p.x + p.bound), hi[1].max(p.y + p.bound)];
        }
        let mut bins = Bins {
            origin: lo,
            size: [0, 1].map(|k| ((hi[k] - lo[k]) / BIN).floor().max(0.0) as usize + 1),
            moving: (0..prims.len()).filter(|&i| moves(i)).collect(),
            ..Bins::default()
        };
        let mut cells: Vec<Vec<usize>> = vec![Vec::new(); bins.size[0] * bins.size[1]];
        for &i in &fixed {
            let p = &prims[i];
            bins.each_cell(p.x, p.y, p.bound, |k| cells[k].push(i));
        }
        bins.start.push(0);
        for cell in cells {
            bins.shapes.extend(cell);
            bins.start.push(bins.shapes.len());
        }
        bins
    }

    /// Call `f` with each cell the square of half-side `r` about `(x, y)` meets.
    fn each_cell(&self, x: f64, y: f64, r: f64, mut f: impl FnMut(usize)) {
        let span = |k: usize, c: f64| {
            let at = |v: f64| {
                ((v - self.origin[k]) / BIN)
                    .floor()
                    .clamp(0.0, (self.size[k] - 1) as f64)
            };
            at(c - r) as usize..=at(c + r) as usize
        };
        for j in span(1, y) {
            for i in span(0, x) {
                f(j * self.size[0] + i);
            }
        }
    }

    /// Into `out`: the shapes whose bounding circles may come within `reach` of
    /// `(x, y)`, each once, in their order in the world; None for a world not binned.
    fn near(&self, x: f64, y: f64, reach: f64, out: &mut Vec<usize>) -> Option<()> {
        if self.start.is_empty() {
            return None;
        }
        out.clear();
        out.extend_from_slice(&self.moving);
        self.each_cell(x, y, reach, |k| {
            out.extend_from_slice(&self.shapes[self.start[k]..self.start[k + 1]]);
        });
        out.sort_unstable();
        out.dedup();
        Some(())
    }
}

/// One scan from `pose` up to `range_max` against `prims` (binned in `bins`): `hits[i]`
/// is beam `i`'s nearest hit (`hits` is resized to the fan).
pub fn scan(
    prims: &[Prim],
    bins: &Bins,
    fan: &Fan,
    pose: ScannerPose,
    range_max: f64,
    hits: &mut Vec<Hit>,
) {
    let ScannerPose {
        x: ox,
        y: oy,
        heading_rad: heading,
    } = pose;
    hits.clear();
    hits.resize(fan.len(), (f64::INFINITY, usize::MAX));
    let (hs, hc) = heading.sin_cos();
    let mut visit = |p: &Prim| {
        let Some((mid, half)) = interval(p, ox, oy, heading + fan.angle_min, range_max) else {
            return;
        };
        for beams in fan.beams_within(mid, half) {
            for (hit, &(ux, uy)) in hits[beams.clone()].iter_mut().zip(&fan.dirs[beams]) {
                let (dx, dy) = (hc * ux - hs * uy, hs * ux + hc * uy);
                if let Some(t) = p.toi(ox, oy, dx, dy)
                    && t <= range_max
                    && t < hit.0
                {
                    *hit = (t, p.obstacle);
                }
            }
        }
    };
    let mut near = Vec::new();
    match bins.near(ox, oy, range_max, &mut near) {
        Some(()) => near.iter().for_each(|&i| visit(&prims[i])),
        None => prims.iter().for_each(visit),
    }
}

/// The broad phase of one shape for a scan from `(ox, oy)` whose beam 0 points at
/// `start` (radians): `None` when its bounding circle lies beyond `range_max`, else the
/// bearing of its centre from beam 0 (`[0, 2 pi)`) and the half-angle it subtends
/// (pi, every beam, when the scanner is inside the bounding circle).
pub fn interval(p: &Prim, ox: f64, oy: f64, start: f64, range_max: f64) -> Option<(f64, f64)> {
    let (cx, cy) = (p.x - ox, p.y - oy);
    let d2 = cx * cx + cy * cy;
    let reach = range_max + p.bound;
    if d2 > reach * reach {
        return None;
    }
    let mid = (cy.atan2(cx) - start).rem_euclid(TAU);
    let d = d2.sqrt();
    let half = match p.form {
        Form::Rect { hx, hy } if d <= p.bound => rect_half_angle(p, cx, cy, hx, hy),
        _ if d <= p.bound => std::f64::consts::PI,
        _ => (p.bound / d).asin(),
    };
    // A hair wider than the exact half-angle, so rounding never drops a grazing beam.
    Some((mid, half + 1e-9))
}

/// The half-angle about the direction to its centre `(cx, cy)` that a rectangle
/// subtends from the origin: its corners' largest angle from that direction (a wall
/// beside the scanner is inside its own bounding circle, but spans under pi), or pi
/// when the origin is inside it.
fn rect_half_angle(p: &Prim, cx: f64, cy: f64, hx: f64, hy: f64) -> f64 {
    let (px, py) = (cx * p.cos + cy * p.sin, cy * p.cos - cx * p.sin);
    if px.abs() <= hx && py.abs() <= hy {
        return std::f64::consts::PI;
    }
    [(hx, hy), (hx, -hy), (-hx, hy), (-hx, -hy)]
        .into_iter()
        .map(|(lx, ly)| {
            // The corner from the origin, in the world frame.
            let (vx, vy) = (cx + lx * p.cos - ly * p.sin, cy + lx * p.sin + ly * p.cos);
            (cx * vy - cy * vx).atan2(cx * vx + cy * vy).abs()
        })
        .fold(0.0, f64::max)
}

/// The nearest hit of one ray (any direction, every shape in range).
pub fn cast(prims: &[Prim], ox: f64, oy: f64, angle: f64, range_max: f64) -> Option<Hit> {
    let (dy, dx) = angle.sin_cos();
    prims
        .iter()
        .filter_map(|p| Some((p.toi(ox, oy, dx, dy)?, p.obstacle)))
        .filter(|(t, _)| *t <= range_max)
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
    use rapier2d::parry::query::RayCast;
    use rapier2d::prelude::{Ball, Cuboid, Pose, Ray, Real, Vector};

    /// rapier's (parry's) solid cast of the same ray against the same shape, in f32.
    fn parry_toi(p: &Prim, o: (f64, f64), d: (f64, f64), max: f64) -> Option<f64> {
        let v = |x: f64, y: f64| Vector::new(x as Real, y as Real);
        let ray = Ray::new(v(o.0, o.1), v(d.0, d.1));
        let pose = Pose::new(v(p.x, p.y), p.heading as Real);
        match p.form {
            Form::Circle { r } => Ball::new(r as Real).cast_ray(&pose, &ray, max as Real, true),
            Form::Rect { hx, hy } => {
                Cuboid::new(v(hx, hy)).cast_ray(&pose, &ray, max as Real, true)
            }
        }
        .map(f64::from)
    }

    fn random_prim(rng: &mut ChaCha8Rng, obstacle: usize) -> Prim {
        let (x, y) = (rng.random_range(-15.0..15.0), rng.random_range(-15.0..15.0));
        if rng.random::<bool>() {
            Prim::circle(obstacle, x, y, rng.random_range(0.1..2.0))
        } else {
            let h = rng.random_range(-4.0..4.0);
            Prim::rect(
                obstacle,
                x,
                y,
                h,
                rng.random_range(0.05..4.0),
                rng.random_range(0.05..2.0),
            )
        }
    }

    #[test]
    fn hits_agree_with_rapiers_cast_on_circles_and_rectangles() {
        let mut rng = ChaCha8Rng::seed_from_u64(37);
        let (mut hits, mut misses, mut graze) = (0, 0, 0);
        for k in 0..20_000 {
            let p = random_prim(&mut rng, k);
            let o = (rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0));
            // Roughly at the shape, so that about half the rays hit.
            let at = (p.y - o.1).atan2(p.x - o.0) + rng.random_range(-0.4..0.4);
            let (s, c) = at.sin_cos();
            let ours = p.toi(o.0, o.1, c, s).filter(|t| *t <= 20.0);
            let theirs = parry_toi(&p, o, (c, s), 20.0);
            // Near an edge f32 and f64 may disagree on hit or miss, and the range is
            // steep in the ray's offset (rapier's f32 root loses digits there).
            let side = |e: f64| p.toi(o.0 - s * e, o.1 + c * e, c, s).filter(|t| *t <= 20.0);
            let steep = match (side(1e-5), side(-1e-5)) {
                (Some(a), Some(b)) => (a - b).abs() > 1e-4,
                (None, None) => false,
                _ => true,
            };
            let grazing = steep
                || side(1e-3).is_some() != side(-1e-3).is_some()
                || [ours, theirs]
                    .iter()
                    .flatten()
                    .any(|t| (t - 20.0).abs() < 1e-3);
            graze += usize::from(grazing);
            match (ours, theirs) {
                (Some(a), Some(b)) => {
                    // rapier is f32, and its circle root (b^2 - c of numbers near
                    // range^2) loses about 1e-4 m at 15 m: half a millimetre.
                    assert!(
                        grazing || (a - b).abs() < 5e-4,
                        "{p:?} from {o:?}: {a} vs {b}"
                    );
                    hits += 1;
                }
                (None, None) => misses += 1,
                (a, b) => assert!(grazing, "{p:?} from {o:?} along ({c}, {s}): {a:?} vs {b:?}"),
            }
        }
        assert!(graze < 200, "{graze} grazing rays");
        assert!(
            hits > 2_000 && misses > 2_000,
            "{hits} hits, {misses} misses"
        );
    }

    #[test]
    fn ranges_are_exact_on_known_geometry() {
        let c = Prim::circle(0, 10.0, 0.0, 1.0);
        assert_eq!(c.toi(0.0, 0.0, 1.0, 0.0), Some(9.0));
        assert_eq!(c.toi(0.0, 0.0, -1.0, 0.0), None);
        assert_eq!(c.toi(10.5, 0.0, 1.0, 0.0), Some(0.0), "inside: solid");
        // A square turned 45 degrees: its corner at 10 - sqrt(2).
        let r = Prim::rect(1, 10.0, 0.0, std::f64::consts::FRAC_PI_4, 1.0, 1.0);
        let t = r.toi(0.0, 0.0, 1.0, 0.0).unwrap();
        assert!((t - (10.0 - 2f64.sqrt())).abs() < 1e-12, "{t}");
        assert_eq!(r.toi(0.0, 3.0, 1.0, 0.0), None);
    }

    #[test]
    fn shapes_beyond_range_are_never_candidates() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for k in 0..5_000 {
            let p = random_prim(&mut rng, k);
            let gap = (p.x.hypot(p.y) - p.bound) - 5.0;
            let near = interval(&p, 0.0, 0.0, rng.random_range(-3.0..3.0), 5.0);
            assert_eq!(near.is_some(), gap <= 0.0, "{p:?}");
        }
    }

    #[test]
    fn the_broad_phase_scan_binned_or_not_equals_every_ray_against_every_shape() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut prims: Vec<Prim> = (0..60).map(|k| random_prim(&mut rng, k)).collect();
        // Long walls, often with the scanner inside their bounding circle.
        for k in 60..70 {
            let (x, y) = (rng.random_range(-10.0..10.0), rng.random_range(-10.0..10.0));
            let h = rng.random_range(-4.0..4.0);
            prims.push(Prim::rect(k, x, y, h, rng.random_range(10.0..30.0), 0.15));
        }
        // Binned (some shapes taken as moving), and shape by shape.
        let binned = Bins::new(&prims, |k| k % 7 == 0);
        assert!(!binned.start.is_empty() && !binned.moving.is_empty());
        let (mut hits, mut every, mut found) = (Vec::new(), Vec::new(), 0);
        for fov in [270.0f64, 360.0, 180.0] {
            let step = 0.5f64.to_radians();
            let n = (fov / 0.5) as usize + 1;
            let fan = Fan::new(-((n - 1) as f64) * step / 2.0, step, n);
            for _ in 0..40 {
                let o = (rng.random_range(-10.0..10.0), rng.random_range(-10.0..10.0));
                let heading = rng.random_range(-7.0..7.0);
                let pose = ScannerPose {
                    x: o.0,
                    y: o.1,
                    heading_rad: heading,
                };
                scan(&prims, &Bins::default(), &fan, pose, 12.0, &mut every);
                scan(&prims, &binned, &fan, pose, 12.0, &mut hits);
                assert_eq!(hits, every);
                for (i, hit) in hits.iter().enumerate() {
                    let a = heading + fan.angle_min + i as f64 * step;
                    match cast(&prims, o.0, o.1, a, 12.0) {
                        Some((t, _)) => {
                            assert!((t - hit.0).abs() < 1e-9, "beam {i}: {hit:?} vs {t}");
                            found += 1;
                        }
                        None => assert_eq!(hit.0, f64::INFINITY, "beam {i}"),
                    }
                }
            }
        }
        assert!(found > 10_000, "{found} hits");
    }
}
