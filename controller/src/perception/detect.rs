//! One scan's detections: clusters classified as posts, wall segments and blobs.

use std::f64::consts::PI;
use std::ops::Range;

use serde::{Deserialize, Serialize};

use super::PerceptionError;
use super::cluster::cluster_points;
use super::config::PerceptionConfig;
use super::fit::{CircleFit, LineFit, fit_circle, fit_line, split_and_merge};
use super::frame::{BeamDirections, Pose2, ScanPoint, ValidScan, scan_points_with};

/// What an obstacle is taken for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObstacleKind {
    /// A cluster explained by a circle (a post, a tree trunk, a leg).
    Post,
    /// One circle of the chain standing for a wall segment.
    WallPiece,
    /// A cluster too small or too irregular for a shape: its enclosing circle.
    Unknown,
}

/// A circular measurement: a post's circle fit or a blob's enclosing circle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CircleMeasurement {
    /// Centre in the world frame.
    pub centre: [f64; 2],
    pub radius: f64,
    /// Covariance of the centre (from the fit; a blob's is (r/2)^2 per axis).
    pub centre_covariance: [[f64; 2]; 2],
    /// Variance of the radius.
    pub radius_variance: f64,
    /// Post or Unknown.
    pub kind: ObstacleKind,
    /// RMS residual of the circle fit (0 for a blob).
    pub rms: f64,
    /// Number of hits.
    pub points: usize,
    /// Index of the cluster in [`Detections::clusters`].
    pub cluster: usize,
    /// The cluster runs to the first or the last beam of the scan: the edge of the
    /// field of view may cut the object.
    pub truncated: bool,
}

/// A straight wall piece (world frame), p0 at the end of the lower beam index.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SegmentMeasurement {
    pub p0: [f64; 2],
    pub p1: [f64; 2],
    /// Half the spread of the hits across the fitted line.
    pub half_thickness: f64,
    /// RMS perpendicular residual.
    pub rms: f64,
    pub points: usize,
    pub cluster: usize,
}

impl SegmentMeasurement {
    pub fn length(&self) -> f64 {
        (self.p1[0] - self.p0[0]).hypot(self.p1[1] - self.p0[1])
    }
}

/// Everything one scan shows.
#[derive(Clone, Debug, PartialEq)]
pub struct Detections {
    pub stamp: f64,
    /// The laser's pose in the world frame.
    pub laser: Pose2,
    /// The hits in beam order.
    pub points: Vec<ScanPoint>,
    /// Clusters as index ranges into `points`.
    pub clusters: Vec<Range<usize>>,
    /// Posts and blobs.
    pub circles: Vec<CircleMeasurement>,
    /// Wall segments.
    pub segments: Vec<SegmentMeasurement>,
    /// What the scan could have seen.
    pub view: View,
}

/// A return nearer than an object by more than this hides it, metres.
const OCCLUSION_SLACK: f64 = 0.3;

/// What one scan could see: its beams (laser frame) and what each returned, so that a
/// track outside the field of view, beyond the range or behind a nearer return is not
/// counted as missed (the local map remembers it).
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub angle_min: f64,
    pub angle_increment: f64,
    pub range_max: f64,
    /// One range per beam; +inf: no return; NaN: no echo (it shows nothing).
    pub ranges: Vec<f32>,
}

impl View {
    /// Whether the disc (x, y, r) in the world frame would show in this scan taken
    /// from `laser` (world frame): within the range, and some beam towards it within
    /// the field of view returned no nearer than the disc (less a slack).
    pub fn sees(&self, laser: &Pose2, x: f64, y: f64, r: f64) -> bool {
        self.shows(laser, x, y, r, 1)
    }

    /// Whether at least `beams` beams of this scan taken from `laser` (world frame)
    /// reach the disc (x, y, r) in the world frame ([`View::sees`] with one): a disc
    /// at the edge of the field of view that one beam grazes would give a cluster too
    /// small to detect, so its absence from the detections is no evidence that it has
    /// gone.
    pub fn shows(&self, laser: &Pose2, x: f64, y: f64, r: f64, beams: usize) -> bool {
        let (dx, dy) = (x - laser.x, y - laser.y);
        let d = (dx * dx + dy * dy).sqrt();
        if d.is_nan() || d - r > self.range_max {
            return false;
        }
        let last = self.ranges.len() as f64 - 1.0;
        if self.angle_increment == 0.0 || last < 0.0 || !self.angle_increment.is_finite() {
            return false;
        }
        let bearing = firmware_bridge::geodesy::normalize_rad_pi(dy.atan2(dx) - laser.yaw);
        let half = if d > r { (r / d).asin() } else { PI };
        let beam = |a: f64| (a - self.angle_min) / self.angle_increment;
        let (k0, k1) = (beam(bearing - half), beam(bearing + half));
        let lo = k0.min(k1).ceil().max(0.0);
        let hi = k0.max(k1).floor().min(last);
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return false;
        }
        let near = d - r - OCCLUSION_SLACK;
        (lo as usize..=hi as usize)
            .filter_map(|k| self.ranges.get(k))
            .filter(|&&range| f64::from(range) >= near)
            .nth(beams.saturating_sub(1))
            .is_some()
    }

    /// What this scan, taken from `laser` (world frame), saw at the world point `p`:
    /// a surface there (within `tolerance` of the piece of surface its two nearest beams
    /// returned from), free space (both beams went further, or returned nothing within
    /// the range), or nothing to tell (out of the field of view or the range, hidden
    /// behind something nearer, no echo, or beams that disagree).
    pub fn surface_at(&self, laser: &Pose2, p: [f64; 2], tolerance: f64) -> Seen {
        self.surface_via(laser, p, tolerance, |k| self.hit(laser, k))
    }

    /// [`View::surface_at`] for many points of one scan: each beam's hit is computed
    /// once (its `sin` and `cos`) and kept in `hits` (one slot per beam, `None` until
    /// needed; [`View::hit_cache`] makes it), the same values `surface_at` computes
    /// each time.
    pub fn surface_at_cached(
        &self,
        laser: &Pose2,
        p: [f64; 2],
        tolerance: f64,
        hits: &mut [Option<Hit>],
    ) -> Seen {
        self.surface_via(laser, p, tolerance, |k| match hits.get_mut(k) {
            Some(Some(h)) => *h,
            Some(slot) => *slot.insert(self.hit(laser, k)),
            None => self.hit(laser, k),
        })
    }

    /// An empty cache of beam hits for [`View::surface_at_cached`].
    pub fn hit_cache(&self) -> Vec<Option<Hit>> {
        vec![None; self.ranges.len()]
    }

    /// Beam `k`'s hit in the world frame, or None without a return; the range with
    /// it. None for a beam without an echo (or none in the scan).
    fn hit(&self, laser: &Pose2, k: usize) -> Hit {
        let range = f64::from(*self.ranges.get(k)?);
        if range.is_nan() {
            return None;
        }
        let a = laser.yaw + self.angle_min + k as f64 * self.angle_increment;
        let point = (range <= self.range_max)
            .then(|| [laser.x + range * a.cos(), laser.y + range * a.sin()]);
        Some((point, range))
    }

    fn surface_via(
        &self,
        laser: &Pose2,
        p: [f64; 2],
        tolerance: f64,
        mut hit: impl FnMut(usize) -> Hit,
    ) -> Seen {
        let (dx, dy) = (p[0] - laser.x, p[1] - laser.y);
        let d = (dx * dx + dy * dy).sqrt();
        let last = self.ranges.len() as f64 - 1.0;
        if d.is_nan() || d > self.range_max || self.angle_increment == 0.0 || last < 0.0 {
            return Seen::Unknown;
        }
        let bearing = firmware_bridge::geodesy::normalize_rad_pi(dy.atan2(dx) - laser.yaw);
        let k = (bearing - self.angle_min) / self.angle_increment;
        if !(0.0..=last).contains(&k) {
            return Seen::Unknown;
        }
        let (Some((h0, r0)), Some((h1, r1))) = (hit(beam_floor(k)), hit(beam_ceil(k))) else {
            return Seen::Unknown;
        };
        let near = |h: Option<[f64; 2]>| h.is_some_and(|h| distance(h, p) <= tolerance);
        let on_chord = || match (h0, h1) {
            (Some(a), Some(b)) => {
                distance(a, b) <= CHORD_MAX && distance_to_segment(p, a, b) <= tolerance
            }
            _ => false,
        };
        if near(h0) || near(h1) || on_chord() {
            Seen::Surface
        } else if r0.min(r1) > d + tolerance {
            Seen::Free
        } else {
            Seen::Unknown
        }
    }
}

/// `k.floor() as usize` for a beam index `k` in `[0, 2^52]`: the conversion truncates,
/// which for a non-negative number is the floor (the build's target has no rounding
/// instruction, and `floor` is a call of some 25 instructions).
fn beam_floor(k: f64) -> usize {
    k as usize
}

/// `k.ceil() as usize` for a beam index `k` in `[0, 2^52]`: the floor, one more when
/// `k` has a fraction.
fn beam_ceil(k: f64) -> usize {
    let floor = k as usize;
    if (floor as f64) < k { floor + 1 } else { floor }
}

/// One beam of a [`View`] in the world frame: its hit point (None: no return within
/// the range) and its range; None for a beam without an echo.
pub type Hit = Option<(Option<[f64; 2]>, f64)>;

/// What an earlier scan saw at a point ([`View::surface_at`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Seen {
    /// A surface, where the point is.
    Surface,
    /// Free space: its beams passed the point.
    Free,
    /// Nothing to tell.
    Unknown,
}

/// Neighbouring beams' hits farther apart than this are not taken for one surface,
/// metres.
const CHORD_MAX: f64 = 0.5;

/// Distance from `p` to the segment from `a` to `b`.
pub(crate) fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (p[0] - a[0] - t * dx, p[1] - a[1] - t * dy);
    (ex * ex + ey * ey).sqrt()
}

/// Distance between two points: the square root of the squared sum (no `hypot`:
/// world coordinates in metres are far from its overflow and underflow guards).
pub(super) fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    (dx * dx + dy * dy).sqrt()
}

/// Detects the obstacles of one scan (no tracking): transformation, clustering and
/// shape classification (see the module documentation). `cfg` is checked first; a
/// [`super::Perception`], whose configuration was checked when it was built, detects
/// without checking it again ([`detect_with`]).
pub fn detect(
    scan: &ValidScan<'_>,
    mount: &Pose2,
    pose: &Pose2,
    cfg: &PerceptionConfig,
) -> Result<Detections, PerceptionError> {
    cfg.validate()?;
    detect_with(scan, mount, pose, cfg, None)
}

/// [`detect`] with a configuration already checked.
pub(super) fn detect_with(
    scan: &ValidScan<'_>,
    mount: &Pose2,
    pose: &Pose2,
    cfg: &PerceptionConfig,
    directions: Option<&mut BeamDirections>,
) -> Result<Detections, PerceptionError> {
    let points = scan_points_with(scan, mount, pose, directions)?;
    let clusters = cluster_points(scan, &points, cfg);
    let laser = pose.compose(mount);
    let origin = [laser.x, laser.y];
    let mut circles = Vec::new();
    let mut segments = Vec::new();
    let last_beam = scan.ranges.len().saturating_sub(1);
    let edge = |p: Option<&ScanPoint>| p.is_some_and(|p| p.beam == 0 || p.beam == last_beam);
    // One buffer for every cluster's world points.
    let mut world = Vec::new();
    for (index, range) in clusters.iter().enumerate() {
        let cluster = &points[range.clone()];
        world.clear();
        world.extend(cluster.iter().map(|p| p.world));
        let from = circles.len();
        classify(&world, origin, index, cfg, &mut circles, &mut segments);
        let truncated = edge(cluster.first()) || edge(cluster.last());
        for c in &mut circles[from..] {
            c.truncated = truncated;
        }
    }
    Ok(Detections {
        stamp: scan.stamp,
        laser,
        points,
        clusters,
        circles,
        segments,
        view: View {
            angle_min: scan.angle_min,
            angle_increment: scan.angle_increment,
            range_max: scan.range_max,
            ranges: scan.ranges.to_vec(),
        },
    })
}

fn classify(
    pts: &[[f64; 2]],
    origin: [f64; 2],
    cluster: usize,
    cfg: &PerceptionConfig,
    circles: &mut Vec<CircleMeasurement>,
    segments: &mut Vec<SegmentMeasurement>,
) {
    let n = pts.len();
    if n >= cfg.circle_min_points
        && !too_long_for_a_post(pts, cfg)
        && let Some(c) = fit_circle(pts, cfg.range_noise_sigma)
        && is_post(&c, pts, origin, cfg)
    {
        circles.push(CircleMeasurement {
            centre: c.centre,
            radius: c.radius,
            centre_covariance: [
                [c.covariance[0][0], c.covariance[0][1]],
                [c.covariance[1][0], c.covariance[1][1]],
            ],
            radius_variance: c.covariance[2][2],
            kind: ObstacleKind::Post,
            rms: c.rms,
            points: n,
            cluster,
            truncated: false,
        });
        return;
    }
    if n >= cfg.line_min_points {
        for piece in split_and_merge(pts, cfg.split_distance) {
            let sub = &pts[piece];
            let line = (sub.len() >= cfg.line_min_points)
                .then(|| fit_line(sub))
                .flatten()
                .filter(|l| l.length() >= cfg.segment_min_length);
            match line {
                Some(l) => segments.push(segment(&l, sub.len(), cluster)),
                None => circles.extend(blob(sub, origin, cluster, cfg)),
            }
        }
    } else {
        circles.extend(blob(pts, origin, cluster, cfg));
    }
}

/// Outliers' residual in [`too_long_for_a_post`], metres.
const POST_OUTLIER: f64 = 1.0;

/// Whether no circle fit of `pts` can pass [`is_post`]'s radius and RMS tests (radius
/// at most `circle_radius_max` = R, RMS at most `circle_rms_max` = rho), so the fit
/// need not be made (a hedge or a wall seen as one cluster). For such a circle, fewer
/// than m = n rho^2 / d^2 points have a residual over d = [`POST_OUTLIER`] (their
/// squares alone would exceed the n rho^2 the RMS allows), so any m of the points hold
/// one with a smaller residual, within R + d of the centre. Two such groups (the
/// first, middle and last m points of the cluster) farther apart than 2 (R + d) at
/// their nearest therefore rule every passing circle out: [`classify`] then goes on as
/// it would after a fit that failed [`is_post`]. Margins of 1e-9 cover the rounding.
fn too_long_for_a_post(pts: &[[f64; 2]], cfg: &PerceptionConfig) -> bool {
    let (radius, rms) = (cfg.circle_radius_max, cfg.circle_rms_max);
    if !(radius.is_finite() && rms.is_finite()) {
        return false;
    }
    let n = pts.len();
    let outliers = n as f64 * rms * rms / (POST_OUTLIER * POST_OUTLIER) * (1.0 + 1e-9);
    let m = outliers.floor() as usize + 1;
    if 3 * m > n {
        return false;
    }
    let apart = 2.0 * (radius + POST_OUTLIER) * (1.0 + 1e-9);
    let mid = (n - m) / 2;
    let (Some(first), Some(middle), Some(last)) =
        (pts.get(..m), pts.get(mid..mid + m), pts.get(n - m..))
    else {
        return false;
    };
    let far = |a: &[[f64; 2]], b: &[[f64; 2]]| {
        a.iter().all(|p| b.iter().all(|q| distance(*p, *q) > apart))
    };
    far(first, middle) || far(first, last) || far(middle, last)
}

/// Whether the circle `c` fitted to `pts` makes them a post; the line fit, the last
/// test, is made only for a circle that passes the others.
fn is_post(c: &CircleFit, pts: &[[f64; 2]], origin: [f64; 2], cfg: &PerceptionConfig) -> bool {
    if !(c.radius >= cfg.circle_radius_min && c.radius <= cfg.circle_radius_max) {
        return false;
    }
    if c.rms > cfg.circle_rms_max {
        return false;
    }
    // Seen from outside: the laser outside the circle, the centre behind the hits.
    let to_laser = (origin[0] - c.centre[0]).hypot(origin[1] - c.centre[1]);
    if to_laser <= c.radius {
        return false;
    }
    let n = pts.len() as f64;
    let g = [
        pts.iter().map(|p| p[0]).sum::<f64>() / n,
        pts.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let behind =
        (c.centre[0] - g[0]) * (g[0] - origin[0]) + (c.centre[1] - g[1]) * (g[1] - origin[1]);
    if behind <= 0.0 {
        return false;
    }
    // The radius pinned down: a shallow arc of noisy hits on a flat face (a parked
    // cart's end 18 m away) fits a circle metres wide whose radius the hits hardly
    // constrain.
    if c.covariance[2][2].sqrt() > cfg.circle_radius_sigma_max {
        return false;
    }
    fit_line(pts).is_none_or(|l| l.rms > cfg.circle_line_ratio * c.rms)
}

fn segment(l: &LineFit, points: usize, cluster: usize) -> SegmentMeasurement {
    SegmentMeasurement {
        p0: l.p0,
        p1: l.p1,
        half_thickness: 0.5 * (l.residual_max - l.residual_min),
        rms: l.rms,
        points,
        cluster,
    }
}

/// The enclosing circle of a small or irregular cluster: r0 half its chord (at least
/// `blob_min_radius`), the centre the centroid pushed away from the laser by
/// 2 r0 / pi, the radius enlarged to enclose every hit.
fn blob(
    pts: &[[f64; 2]],
    origin: [f64; 2],
    cluster: usize,
    cfg: &PerceptionConfig,
) -> Option<CircleMeasurement> {
    let (first, last) = (pts.first()?, pts.last()?);
    let n = pts.len() as f64;
    let g = [
        pts.iter().map(|p| p[0]).sum::<f64>() / n,
        pts.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let r0 = (0.5 * (last[0] - first[0]).hypot(last[1] - first[1])).max(cfg.blob_min_radius);
    let (ux, uy) = (g[0] - origin[0], g[1] - origin[1]);
    let dist = ux.hypot(uy);
    let shift = 2.0 * r0 / PI;
    let centre = if dist > 0.0 {
        [g[0] + shift * ux / dist, g[1] + shift * uy / dist]
    } else {
        g
    };
    let radius = pts.iter().map(|p| distance(*p, centre)).fold(r0, f64::max);
    let s2 = (0.5 * radius).powi(2);
    Some(CircleMeasurement {
        centre,
        radius,
        centre_covariance: [[s2, 0.0], [0.0, s2]],
        radius_variance: s2,
        kind: ObstacleKind::Unknown,
        rms: 0.0,
        points: pts.len(),
        cluster,
        truncated: false,
    })
}

/// The circles standing for a wall segment: returns their common radius and their
/// centres, evenly spaced on p0-p1 with the first and last inset by r - h from its
/// ends (one circle at the middle when it is shorter than twice that). With h the half
/// thickness, r = max(`wall_circle_min_radius`, h + `wall_circle_margin`) and r0 =
/// `vehicle_radius`, the spacing is at most `2 sqrt((r + r0)^2 - (h + r0)^2)`, so the
/// circles grown by r0 contain every point within h + r0 of the segment (and with
/// r0 = 0 the circles contain the footprint: every point within h of it). Near an end,
/// a point within h + r0 of the segment is within (h + r0) + (r - h) = r + r0 of the
/// inset end circle, so the inset keeps that, and a wall reaches only h (not r) past
/// its ends: a gate between two walls stays as wide as it is.
pub fn cover_segment(
    p0: [f64; 2],
    p1: [f64; 2],
    half_thickness: f64,
    cfg: &PerceptionConfig,
) -> (f64, Vec<[f64; 2]>) {
    let h = if half_thickness.is_finite() {
        half_thickness.max(0.0)
    } else {
        0.0
    };
    let r = cfg.wall_circle_min_radius.max(h + cfg.wall_circle_margin);
    let big = r + cfg.vehicle_radius;
    let need = h + cfg.vehicle_radius;
    let spacing = 2.0 * ((big - need) * (big + need)).sqrt();
    let full = (p1[0] - p0[0]).hypot(p1[1] - p0[1]);
    let inset = r - h;
    if !(full.is_finite() && spacing > 0.0) {
        return (r, vec![p0]);
    }
    if full <= 2.0 * inset {
        return (r, vec![[(p0[0] + p1[0]) / 2.0, (p0[1] + p1[1]) / 2.0]]);
    }
    let (ux, uy) = ((p1[0] - p0[0]) / full, (p1[1] - p0[1]) / full);
    let p0 = [p0[0] + inset * ux, p0[1] + inset * uy];
    let p1 = [p1[0] - inset * ux, p1[1] - inset * uy];
    let length = full - 2.0 * inset;
    // ceil of a finite positive ratio; bounded so a degenerate config cannot explode.
    let intervals = (length / spacing).ceil().clamp(1.0, 1e5) as usize;
    let centres = (0..=intervals)
        .map(|i| {
            let t = i as f64 / intervals as f64;
            [p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])]
        })
        .collect();
    (r, centres)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_earlier_view_tells_surface_free_space_and_the_unseen_apart() {
        // Beams every degree from -10 to +10 degrees; a wall 5 m ahead across them, but
        // beam 15 (+5 degrees) stopped at 3 m by something nearer, and no return on
        // beams 0 and 1.
        let mut ranges: Vec<f32> = (0..21)
            .map(|i| (5.0 / (f64::from(i) - 10.0).to_radians().cos()) as f32)
            .collect();
        ranges[15] = 3.0;
        ranges[0] = f32::INFINITY;
        ranges[1] = f32::INFINITY;
        let view = View {
            angle_min: -10f64.to_radians(),
            angle_increment: 1f64.to_radians(),
            range_max: 20.0,
            ranges,
        };
        // The laser at (1, 2) heading +x.
        let laser = Pose2::new(1.0, 2.0, 0.0);
        let at = |deg: f64, x: f64| {
            let y = 2.0 + (x - 1.0) * deg.to_radians().tan();
            view.surface_at(&laser, [x, y], 0.06)
        };
        assert_eq!(at(2.3, 6.0), Seen::Surface, "on the wall between two beams");
        assert_eq!(at(2.3, 6.04), Seen::Surface, "within the tolerance");
        assert_eq!(at(2.3, 5.8), Seen::Free, "in front of the wall");
        assert_eq!(at(2.3, 6.3), Seen::Unknown, "behind the wall");
        assert_eq!(at(5.0, 5.0), Seen::Unknown, "behind the nearer object");
        assert_eq!(at(-9.5, 8.0), Seen::Free, "where nothing returned");
        assert_eq!(at(30.0, 3.0), Seen::Unknown, "out of the field of view");
        assert_eq!(at(0.0, 30.0), Seen::Unknown, "beyond the range");
        // The cached beam hits give the same answers, in any order of the points.
        let mut hits = view.hit_cache();
        for i in (0..400).rev() {
            let (deg, x) = (-12.0 + 0.06 * f64::from(i), 4.0 + 0.006 * f64::from(i));
            let p = [x, 2.0 + (x - 1.0) * deg.to_radians().tan()];
            assert_eq!(
                view.surface_at_cached(&laser, p, 0.06, &mut hits),
                view.surface_at(&laser, p, 0.06),
                "{p:?}"
            );
        }
    }

    #[test]
    fn beam_floor_and_ceil_are_those_of_the_float() {
        let ks = (0..20_000).map(|i| f64::from(i) * 0.0271).chain([
            0.0,
            1.0,
            540.0,
            1.0f64.next_down(),
            1.0f64.next_up(),
            539.999_999_999_999_9,
            f64::MIN_POSITIVE,
        ]);
        for k in ks {
            assert_eq!(beam_floor(k), k.floor() as usize, "{k}");
            assert_eq!(beam_ceil(k), k.ceil() as usize, "{k}");
        }
    }

    #[test]
    fn a_cluster_too_long_for_a_post_has_no_circle_fit_that_passes() {
        let cfg = PerceptionConfig::default();
        let mut skipped = 0;
        // Arcs of radius 2-40 m over 0.3-3 rad, and near-straight runs, with noise.
        for (k, radius) in [2.0, 4.0, 5.0, 6.0, 8.0, 12.0, 40.0]
            .into_iter()
            .enumerate()
        {
            for span in [0.3, 1.0, 2.0, 3.0] {
                let pts: Vec<[f64; 2]> = (0..300)
                    .map(|i| {
                        let t = span * f64::from(i) / 299.0;
                        let noise = 0.02 * (f64::from(i) * 1.7 + k as f64).sin();
                        let r = radius + noise;
                        [10.0 + r * t.cos(), 3.0 + r * t.sin()]
                    })
                    .collect();
                if too_long_for_a_post(&pts, &cfg) {
                    skipped += 1;
                    let passes = fit_circle(&pts, cfg.range_noise_sigma).is_some_and(|c| {
                        c.radius <= cfg.circle_radius_max && c.rms <= cfg.circle_rms_max
                    });
                    assert!(!passes, "radius {radius}, span {span}");
                }
            }
        }
        assert!(skipped > 0);
        // A post's arc is never ruled out.
        let post: Vec<[f64; 2]> = (0..40)
            .map(|i| {
                let t = 3.0 + 0.02 * f64::from(i);
                [5.0 + 0.3 * t.cos(), 0.3 * t.sin()]
            })
            .collect();
        assert!(!too_long_for_a_post(&post, &cfg));
    }

    #[test]
    fn chain_spacing_respects_the_waist_condition() {
        let cfg = PerceptionConfig {
            vehicle_radius: 1.0,
            ..PerceptionConfig::default()
        };
        let (r, c) = cover_segment([0.0, 0.0], [10.0, 0.0], 0.05, &cfg);
        assert!((r - 0.25).abs() < 1e-12);
        let s = c[1][0] - c[0][0];
        let waist = ((r + 1.0).powi(2) - (s / 2.0).powi(2)).sqrt();
        assert!(waist >= 1.05 - 1e-12, "waist {waist}");
        // The ends inset by r - h: the wall reaches h past them, not r.
        let first = c.first().copied().unwrap_or_default();
        let last = c.last().copied().unwrap_or_default();
        assert!(
            (first[0] - 0.2).abs() < 1e-12 && first[1] == 0.0,
            "{first:?}"
        );
        assert!((last[0] - 9.8).abs() < 1e-12 && last[1] == 0.0, "{last:?}");
    }

    #[test]
    fn the_grown_chain_contains_every_point_near_the_segment_ends_included() {
        let r0 = 0.15;
        let h = 0.1;
        let cfg = PerceptionConfig {
            vehicle_radius: r0,
            ..PerceptionConfig::default()
        };
        for (p1, label) in [([6.0, 3.0], "long"), ([0.2, 0.1], "short")] {
            let (r, c) = cover_segment([0.0, 0.0], p1, h, &cfg);
            let len = p1[0].hypot(p1[1]);
            let (ux, uy) = (p1[0] / len, p1[1] / len);
            // Points on a grid round the segment, within h + r0 of it.
            for i in -40..=40 {
                for j in -40..=40 {
                    let (a, b) = (f64::from(i) * 0.2, f64::from(j) * 0.02);
                    let (px, py) = (a * ux - b * uy, a * uy + b * ux);
                    let t = a.clamp(0.0, len);
                    let d = (px - t * ux).hypot(py - t * uy);
                    if d > h + r0 {
                        continue;
                    }
                    let covered = c
                        .iter()
                        .any(|q| (px - q[0]).hypot(py - q[1]) <= r + r0 + 1e-9);
                    assert!(covered, "{label}: ({px}, {py}) at {d} from the segment");
                }
            }
        }
    }

    #[test]
    fn zero_length_segment_is_one_circle() {
        let (_, c) = cover_segment([1.0, 2.0], [1.0, 2.0], 0.0, &PerceptionConfig::default());
        assert_eq!(c, vec![[1.0, 2.0]]);
    }
}
