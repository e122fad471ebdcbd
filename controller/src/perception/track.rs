//! Multi-target tracking: constant-velocity Kalman filters for posts and blobs, wall
//! tracks with the velocity their faces' normal motion gives, M-of-N birth, K-miss
//! deletion, a local map of what is out of sight, and the planner's circles.

use std::collections::VecDeque;

use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};
use serde::{Deserialize, Serialize};

use super::config::PerceptionConfig;
use super::detect::{
    CircleMeasurement, Detections, Hit, ObstacleKind, Seen, SegmentMeasurement, View,
    cover_segment, detect_with, distance, distance_to_segment,
};
use super::frame::{BeamDirections, Pose2, ScanPoint, ValidScan};
use super::{PerceptionError, check_finite};
use crate::planner::Obstacle;

/// A tracked disc: the planner's [`Obstacle`] (world frame, at the scan's stamp; its
/// velocity after the dead band, zero for static obstacles) and what the tracker knows
/// of it. Serialized flat, the disc's fields beside the others.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrackedObstacle {
    /// Track id (shared by all circles of one wall).
    pub id: u64,
    /// Index of the circle in its wall's chain (0 for posts and blobs).
    pub part: u32,
    /// The disc the planner takes, as it takes it.
    #[serde(flatten)]
    pub disc: Obstacle,
    /// The filter's velocity before the dead band, m/s.
    pub velocity_estimate: [f64; 2],
    pub kind: ObstacleKind,
    /// Fraction of hits over the last `birth_window` scans.
    pub confidence: f64,
    /// Seconds since the track's first detection.
    pub age: f64,
    /// Scans in which the track was detected.
    pub hits: u32,
    /// Consecutive scans without a detection (coasting when > 0).
    pub misses: u32,
}

/// A tracked wall segment, for plotting.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WallSegment {
    pub id: u64,
    pub p0: [f64; 2],
    pub p1: [f64; 2],
    pub half_thickness: f64,
    pub rms: f64,
    pub confidence: f64,
    pub age: f64,
    pub hits: u32,
    pub misses: u32,
}

/// The tracker's answer to one scan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PerceptionOutput {
    pub stamp: f64,
    /// Confirmed obstacles within the detection radius, by id then part.
    pub obstacles: Vec<TrackedObstacle>,
    /// Confirmed wall segments reaching into the detection radius, by id.
    pub segments: Vec<WallSegment>,
}

impl PerceptionOutput {
    /// The planner's obstacles.
    pub fn planner_obstacles(&self) -> Vec<Obstacle> {
        self.obstacles.iter().map(|o| o.disc).collect()
    }
}

/// Birth and death bookkeeping.
#[derive(Clone, Copy, Debug)]
struct Life {
    /// Bit 0: the latest scan; 1 = hit.
    history: u32,
    scans: u32,
    hits: u32,
    misses: u32,
    confirmed: bool,
    born: f64,
}

impl Life {
    fn new(stamp: f64, cfg: &PerceptionConfig) -> Self {
        Life {
            history: 1,
            scans: 1,
            hits: 1,
            misses: 0,
            confirmed: cfg.birth_hits <= 1,
            born: stamp,
        }
    }

    fn window_hits(&self, cfg: &PerceptionConfig) -> u32 {
        let mask = if cfg.birth_window >= 32 {
            u32::MAX
        } else {
            (1u32 << cfg.birth_window) - 1
        };
        (self.history & mask).count_ones()
    }

    fn record(&mut self, hit: bool, cfg: &PerceptionConfig) {
        self.history = (self.history << 1) | u32::from(hit);
        self.scans = self.scans.saturating_add(1);
        if hit {
            self.hits = self.hits.saturating_add(1);
            self.misses = 0;
        } else {
            self.misses = self.misses.saturating_add(1);
        }
        if !self.confirmed
            && self.scans <= cfg.birth_window
            && self.window_hits(cfg) >= cfg.birth_hits
        {
            self.confirmed = true;
        }
    }

    fn dead(&self, cfg: &PerceptionConfig) -> bool {
        self.misses >= cfg.delete_misses || (!self.confirmed && self.scans >= cfg.birth_window)
    }

    fn confidence(&self, cfg: &PerceptionConfig) -> f64 {
        let window = self.scans.min(cfg.birth_window).max(1);
        f64::from(self.window_hits(cfg)) / f64::from(window)
    }

    /// Seen often enough for the local map to keep what goes out of sight of it
    /// (a local map there is: `memory_radius` above zero).
    fn memorable(&self, cfg: &PerceptionConfig) -> bool {
        cfg.memory_radius > 0.0 && self.confirmed && self.hits >= cfg.memory_min_hits
    }
}

const H: Matrix2x4<f64> = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);

/// A post or blob: constant-velocity Kalman filter (x, y, vx, vy) and a radius filter.
#[derive(Clone, Debug)]
struct PointTrack {
    id: u64,
    state: Vector4<f64>,
    cov: Matrix4<f64>,
    radius: f64,
    radius_var: f64,
    kind: ObstacleKind,
    life: Life,
    /// Since when the velocity has been significant on every scan.
    moving_since: Option<f64>,
    /// The position as of the last scan that measured it.
    measured: [f64; 2],
    /// The stamp of the last scan that measured it.
    last_hit: f64,
}

impl PointTrack {
    /// The measurement's centre covariance plus `position_sigma_min^2` per axis; a blob
    /// measuring a post (a few hits of it, e.g. at the edge of the field of view) may
    /// be any part of it: plus the post's radius squared per axis.
    fn measurement_covariance(
        &self,
        m: &CircleMeasurement,
        cfg: &PerceptionConfig,
    ) -> Matrix2<f64> {
        let c = m.centre_covariance;
        let mut extra = cfg.position_sigma_min * cfg.position_sigma_min;
        if self.kind == ObstacleKind::Post && m.kind != ObstacleKind::Post {
            extra += self.radius * self.radius;
        }
        Matrix2::new(c[0][0] + extra, c[0][1], c[1][0], c[1][1] + extra)
    }

    fn new(id: u64, m: &CircleMeasurement, stamp: f64, cfg: &PerceptionConfig) -> Self {
        let v0 = cfg.initial_velocity_sigma * cfg.initial_velocity_sigma;
        let mut track = PointTrack {
            id,
            state: Vector4::new(m.centre[0], m.centre[1], 0.0, 0.0),
            cov: Matrix4::from_diagonal(&Vector4::new(0.0, 0.0, v0, v0)),
            radius: m.radius,
            radius_var: m.radius_variance + cfg.range_noise_sigma * cfg.range_noise_sigma,
            kind: m.kind,
            life: Life::new(stamp, cfg),
            moving_since: None,
            measured: m.centre,
            last_hit: stamp,
        };
        let r = track.measurement_covariance(m, cfg);
        track.cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&r);
        track
    }

    fn predict(&mut self, dt: f64, cfg: &PerceptionConfig) {
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        let q = cfg.accel_noise;
        let (q11, q12, q22) = (q * dt.powi(3) / 3.0, q * dt * dt / 2.0, q * dt);
        let qm = Matrix4::new(
            q11, 0.0, q12, 0.0, //
            0.0, q11, 0.0, q12, //
            q12, 0.0, q22, 0.0, //
            0.0, q12, 0.0, q22,
        );
        self.state = f * self.state;
        self.cov = f * self.cov * f.transpose() + qm;
        self.radius_var += cfg.radius_process_sigma * cfg.radius_process_sigma * dt;
    }

    /// Innovation, its covariance's inverse, Mahalanobis distance squared and Euclidean
    /// distance; None when the covariance is singular.
    fn innovation(
        &self,
        m: &CircleMeasurement,
        cfg: &PerceptionConfig,
    ) -> Option<(Vector2<f64>, Matrix2<f64>, f64, f64)> {
        let z = Vector2::new(m.centre[0], m.centre[1]);
        let y = z - H * self.state;
        let s = H * self.cov * H.transpose() + self.measurement_covariance(m, cfg);
        let s_inv = s.try_inverse()?;
        let d2 = (y.transpose() * s_inv * y)[(0, 0)];
        Some((y, s_inv, d2, y.norm()))
    }

    fn gated_distance(&self, m: &CircleMeasurement, cfg: &PerceptionConfig) -> Option<f64> {
        let (_, _, d2, d) = self.innovation(m, cfg)?;
        (d <= cfg.gate_max_distance && (d2 <= cfg.gate_chi2 || d <= cfg.gate_min_distance))
            .then_some(d)
    }

    /// Corrects the track with `m`; false when `m` only shows the object is there.
    fn update(&mut self, m: &CircleMeasurement, cfg: &PerceptionConfig) -> bool {
        if m.truncated && m.kind == ObstacleKind::Unknown && self.moving_since.is_some() {
            // A blob cut by the edge of the field of view: its centre lies where the
            // visible part ends, not where the object is (a walker leaving the view
            // seemed to speed up and turn). Of a mover whose motion is established, it
            // shows the object is there; the track coasts on as predicted, its motion
            // held. Anything else (a cart coming into view from behind, a post) is
            // measured as before: its motion is yet to be found, or it has none.
            self.life.record(true, cfg);
            return false;
        }
        if let Some((y, s_inv, _, _)) = self.innovation(m, cfg) {
            let r = self.measurement_covariance(m, cfg);
            let k = self.cov * H.transpose() * s_inv;
            let i_kh = Matrix4::identity() - k * H;
            self.state += k * y;
            self.cov = i_kh * self.cov * i_kh.transpose() + k * r * k.transpose();
        }
        self.measured = [self.state[0], self.state[1]];
        let use_radius = match (self.kind, m.kind) {
            (_, ObstacleKind::Post) => {
                self.kind = ObstacleKind::Post;
                true
            }
            (ObstacleKind::Post, _) => false,
            _ => true,
        };
        if use_radius {
            let var = m.radius_variance + cfg.range_noise_sigma * cfg.range_noise_sigma;
            let gain = self.radius_var / (self.radius_var + var);
            self.radius += gain * (m.radius - self.radius);
            self.radius_var *= 1.0 - gain;
        }
        self.life.record(true, cfg);
        true
    }

    /// The filter's velocity passes the dead band and the significance test with
    /// `chi2` as its threshold (0 disables the test).
    fn velocity_significant(&self, cfg: &PerceptionConfig, chi2: f64) -> bool {
        let v = Vector2::new(self.state[2], self.state[3]);
        if v.norm() < cfg.velocity_dead_band {
            return false;
        }
        if chi2 > 0.0 {
            let pvv: Matrix2<f64> = self.cov.fixed_view::<2, 2>(2, 2).into_owned();
            if let Some(inv) = pvv.try_inverse() {
                let m2 = (v.transpose() * inv * v)[(0, 0)];
                if m2 < chi2 {
                    return false;
                }
            }
        }
        true
    }

    /// Track the persistence of a significant velocity at `stamp`: it begins when the
    /// velocity passes the significance test and lasts while it passes the (lower)
    /// hold threshold.
    fn note_motion(&mut self, stamp: f64, cfg: &PerceptionConfig) {
        let chi2 = if self.moving_since.is_some() {
            cfg.velocity_hold_chi2
        } else {
            cfg.velocity_significance_chi2
        };
        if self.velocity_significant(cfg, chi2) {
            self.moving_since.get_or_insert(stamp);
        } else {
            self.moving_since = None;
        }
    }

    /// The velocity to report at `stamp`: zero unless significant for
    /// `moving_confirm_s`.
    fn reported_velocity(&self, stamp: f64, cfg: &PerceptionConfig) -> [f64; 2] {
        confirmed_velocity(
            self.moving_since,
            [self.state[2], self.state[3]],
            stamp,
            cfg,
        )
    }

    /// Measured standing still ([`cluster_still`]): the velocity is zero, known to
    /// within [`STILL_SPEED`], whatever the centre's shifts made of it (a neighbour's
    /// fragment taken for it, a window onto a larger object sliding as the view moves,
    /// a cluster cut into other pieces than the last scan's), and motion starts anew.
    fn hold_still(&mut self) {
        self.state[2] = 0.0;
        self.state[3] = 0.0;
        for i in 0..4 {
            for j in 2..4 {
                self.cov[(i, j)] = 0.0;
                self.cov[(j, i)] = 0.0;
            }
        }
        self.cov[(2, 2)] = STILL_SPEED * STILL_SPEED;
        self.cov[(3, 3)] = STILL_SPEED * STILL_SPEED;
        self.moving_since = None;
    }
}

/// An earlier scan, for [`cluster_still`].
#[derive(Clone, Debug)]
struct PastView {
    stamp: f64,
    /// The laser's pose in the world frame.
    laser: Pose2,
    view: View,
}

/// How far back the scan lies that a cluster's hits are compared with, at least,
/// seconds: long enough for a walker at 0.5 m/s to leave the surface it showed (by
/// 0.15 m, against `STILL_TOLERANCE`), short enough for a static object's view to
/// overlap (the car moves 0.6 m at 2 m/s).
const STILL_BASELINE_S: f64 = 0.3;
/// How near a hit must lie to the earlier scan's surface to be on it, metres: the
/// range noise of two scans (3 sigma of 12 mm each) and the spacing of beams on an
/// oblique surface.
const STILL_TOLERANCE: f64 = 0.06;
/// The speed a still cluster may yet have, m/s: the tolerance over the baseline.
const STILL_SPEED: f64 = STILL_TOLERANCE / STILL_BASELINE_S;

/// Whether a cluster's `points` stand still since the scan `past`: at least half of
/// them (and two) lie on a surface it saw there, and at most a tenth in the space its
/// beams went through. The rest it could not see (hidden behind something nearer, or
/// out of its view): a static object seen from a moving vehicle shows new parts of it,
/// never a part where the earlier beams passed. An object moving at more than
/// [`STILL_SPEED`] leaves its surface: crossing, its leading side stands where the
/// beams passed; coming or going, most of its hits are off the earlier surface.
///
/// A cluster of more than [`STILL_SAMPLES`] hits is judged by that many of them,
/// spread evenly along it (a wall or a large post returns a hundred hits a scan, and
/// the fractions of a sample spread along it are the cluster's within a few per cent).
/// The hits are looked at in order until the answer is settled whatever the rest
/// show: the counts only grow, so too many in free space or too few left to make half
/// on a surface is no, and enough on a surface with too few left to make a tenth in
/// free space is yes.
fn cluster_still(points: &[ScanPoint], past: &PastView, hits: &mut [Option<Hit>]) -> bool {
    let sample = still_sample(points);
    let n = sample.len();
    let still = |surface: usize, free: usize| surface >= 2 && 2 * surface >= n && 10 * free <= n;
    let (mut surface, mut free) = (0usize, 0usize);
    for (i, p) in sample.enumerate() {
        match past
            .view
            .surface_at_cached(&past.laser, p.world, STILL_TOLERANCE, hits)
        {
            Seen::Surface => surface += 1,
            Seen::Free => free += 1,
            Seen::Unknown => {}
        }
        let rest = n - i - 1;
        if 10 * free > n || 2 * (surface + rest) < n || surface + rest < 2 {
            return false;
        }
        if still(surface, free + rest) {
            return true;
        }
    }
    still(surface, free)
}

/// The most hits of a cluster [`cluster_still`] looks at.
const STILL_SAMPLES: usize = 24;

/// The hits of a cluster [`cluster_still`] looks at: all of them, or
/// [`STILL_SAMPLES`] spread evenly from the first.
fn still_sample(points: &[ScanPoint]) -> impl ExactSizeIterator<Item = &ScanPoint> {
    let m = points.len().min(STILL_SAMPLES);
    // i < m <= len, so i * len / m < len.
    (0..m).map(move |i| &points[i * points.len() / m])
}

/// `velocity` once it has been significant since `moving_since` for
/// `moving_confirm_s` at `stamp`, else zero.
fn confirmed_velocity(
    moving_since: Option<f64>,
    velocity: [f64; 2],
    stamp: f64,
    cfg: &PerceptionConfig,
) -> [f64; 2] {
    match moving_since {
        Some(since) if stamp - since >= cfg.moving_confirm_s - 1e-9 => velocity,
        _ => [0.0, 0.0],
    }
}

/// How far from the vehicle an obstacle moving at `velocity` is reported.
fn reach(velocity: [f64; 2], cfg: &PerceptionConfig) -> f64 {
    if velocity != [0.0, 0.0] {
        cfg.moving_detection_radius.max(cfg.detection_radius)
    } else {
        cfg.detection_radius
    }
}

/// A wall: the latest segment associated with it, and its velocity. A line's motion
/// along itself cannot be told from more or less of it coming into view, so a segment
/// measures only its normal speed: its offset from an anchor segment taken at least
/// `WALL_SPEED_WINDOW_S` earlier (over a shorter time the vehicle's own pose noise
/// would dominate). The segments of one cluster are one rigid object: two faces at an
/// angle (a cart's front and side) give the whole velocity, one face updates the
/// velocity's component along its normal and keeps the rest (from the other face, or
/// inherited by a face newly in view).
#[derive(Clone, Debug)]
struct WallTrack {
    id: u64,
    segment: SegmentMeasurement,
    life: Life,
    /// The segment the normal speed is measured from, and its stamp.
    anchor: (SegmentMeasurement, f64),
    /// The unit normal and the filtered normal speed, once measured.
    normal_speed: Option<([f64; 2], f64)>,
    /// The object's velocity, m/s.
    velocity: [f64; 2],
    /// Since when the velocity has been above the dead band on every scan.
    moving_since: Option<f64>,
}

/// Shortest time over which a wall's normal speed is measured, seconds.
const WALL_SPEED_WINDOW_S: f64 = 0.2;

/// Slowest speed a wall is reported moving at (above `velocity_dead_band` if that is
/// higher), m/s: the fitted line of an irregular object (a hedge, a tree's trunk and
/// crown) shifts a little as more or less of it comes into view, and the vehicle's
/// pose moves with GPS noise; a wall slower than this is taken as static.
const WALL_MIN_SPEED: f64 = 0.3;

/// Fastest plausible normal speed of a wall, m/s: a faster apparent motion is a
/// segment associated with another piece of the same wall (a bend, a hedge's
/// irregular edge), not motion, and restarts the measurement.
const WALL_MAX_SPEED: f64 = 6.0;

/// Two faces whose normals' cross product squared is below this (about 30 degrees
/// apart) give only their common normal velocity.
const WALL_FACES_MIN_SIN2: f64 = 0.25;

impl WallTrack {
    fn new(id: u64, segment: SegmentMeasurement, stamp: f64, cfg: &PerceptionConfig) -> Self {
        WallTrack {
            id,
            segment,
            life: Life::new(stamp, cfg),
            anchor: (segment, stamp),
            normal_speed: None,
            velocity: [0.0, 0.0],
            moving_since: None,
        }
    }

    /// Takes the associated segment `new`; measures the normal speed once the
    /// anchor is old enough.
    fn associate(&mut self, new: &SegmentMeasurement, stamp: f64) {
        self.segment = *new;
        let (old, since) = self.anchor;
        let dt = stamp - since;
        if dt < WALL_SPEED_WINDOW_S - 1e-9 {
            return;
        }
        self.anchor = (*new, stamp);
        let (Some(u), Some(offset)) = (direction(&old), normal_offset(&old, new)) else {
            self.normal_speed = None;
            return;
        };
        let n = [-u[1], u[0]];
        let speed = offset / dt;
        if speed.abs() > WALL_MAX_SPEED {
            self.normal_speed = None;
            return;
        }
        // Half-way per window: the filter's memory is about two windows.
        let speed = match self.normal_speed {
            Some((m, previous)) => 0.5 * (speed + previous * (m[0] * n[0] + m[1] * n[1])),
            None => speed,
        };
        self.normal_speed = Some((n, speed));
    }

    /// Sets the velocity from the object's faces and notes the motion at `stamp`.
    fn set_velocity(&mut self, faces: &[([f64; 2], f64)], stamp: f64, cfg: &PerceptionConfig) {
        self.velocity = match faces {
            [] => return,
            [(n, s)] => {
                let along = s - (n[0] * self.velocity[0] + n[1] * self.velocity[1]);
                [
                    self.velocity[0] + along * n[0],
                    self.velocity[1] + along * n[1],
                ]
            }
            _ => rigid_velocity(faces),
        };
        if self.velocity[0].hypot(self.velocity[1]) >= cfg.velocity_dead_band.max(WALL_MIN_SPEED) {
            self.moving_since.get_or_insert(stamp);
        } else {
            self.moving_since = None;
        }
    }

    /// The velocity to report at `stamp`: zero unless above the dead band (and
    /// `WALL_MIN_SPEED`) for `moving_confirm_s`.
    fn reported_velocity(&self, stamp: f64, cfg: &PerceptionConfig) -> [f64; 2] {
        confirmed_velocity(self.moving_since, self.velocity, stamp, cfg)
    }

    /// Measured standing still ([`cluster_still`]): no velocity, along the wall
    /// either (which its faces' normal motion cannot correct), and motion starts anew.
    fn hold_still(&mut self) {
        self.velocity = [0.0, 0.0];
        self.normal_speed = self.normal_speed.map(|(n, _)| (n, 0.0));
        self.moving_since = None;
    }

    /// A static wall the local map keeps, out of sight wholly or in part.
    fn memorable(&self, stamp: f64, cfg: &PerceptionConfig) -> bool {
        self.life.memorable(cfg) && self.reported_velocity(stamp, cfg) == [0.0, 0.0]
    }
}

/// A wall's remembered end is kept only this near the new segment's line, metres:
/// farther, the wall bends there (or the fit turned), and the new line would carry
/// the end off the wall.
const EXTENT_MAX_OFFSET: f64 = 0.5;
/// Beyond a measured end, the stretch not looked at for being in view (but for the
/// remembered end itself), metres: the beams just past an end the scan did see.
const EXTENT_END_SLACK: f64 = 0.5;
/// Spacing of the points checked for being out of view, metres.
const EXTENT_STEP: f64 = 0.25;

/// The segment `new` measured on a static wall, lengthened along its line over what
/// the wall's previous extent `old` covered beyond its ends and this scan could not
/// see (`sees`, [`super::detect::View::sees`]: out of the field of view, beyond the
/// range, hidden behind something nearer). So a hedge the car drives along keeps the
/// stretch behind the scanner, and the car does not turn (or back) into what it
/// passed. An end the scan could see stays where it was measured: a union of every
/// measured extent would grow outwards with each noisy end, and closed a gate under
/// GPS noise.
fn keep_unseen_extent(
    old: &SegmentMeasurement,
    new: &SegmentMeasurement,
    sees: &impl Fn(f64, f64, f64) -> bool,
) -> SegmentMeasurement {
    let Some(u) = direction(new) else {
        return *new;
    };
    let len = new.length();
    let at = |t: f64| [new.p0[0] + t * u[0], new.p0[1] + t * u[1]];
    let r = new.half_thickness.max(0.0);
    // No point from `from` to `to` along the line is in view.
    let unseen = |from: f64, to: f64| {
        let n = ((to - from).abs() / EXTENT_STEP).ceil().clamp(1.0, 1e4) as usize;
        (0..=n).all(|i| {
            let p = at(from + (to - from) * i as f64 / n as f64);
            !sees(p[0], p[1], r)
        })
    };
    // The old end at `t`, beyond the measured end at `end`, is out of view, and so is
    // all between, but for the slack.
    let out_of_view = |end: f64, t: f64| {
        let from = if (t - end).abs() > EXTENT_END_SLACK {
            end + EXTENT_END_SLACK * (t - end).signum()
        } else {
            t
        };
        unseen(from, t)
    };
    let (mut t0, mut t1) = (0.0f64, len);
    for p in [old.p0, old.p1] {
        let (t, across) = line_coords(new.p0, u, p);
        if across.abs() > EXTENT_MAX_OFFSET {
            continue;
        }
        if t < 0.0 && out_of_view(0.0, t) {
            t0 = t0.min(t);
        } else if t > len && out_of_view(len, t) {
            t1 = t1.max(t);
        }
    }
    SegmentMeasurement {
        p0: if t0 < 0.0 { at(t0) } else { new.p0 },
        p1: if t1 > len { at(t1) } else { new.p1 },
        ..*new
    }
}

/// The velocity of a rigid object from the normal speeds of two or more faces: the
/// least-squares solution of n_i . v = s_i when two faces are at an angle, else the
/// mean normal speed along the first face's normal (signs aligned to it).
fn rigid_velocity(faces: &[([f64; 2], f64)]) -> [f64; 2] {
    let Some((first, _)) = faces.first() else {
        return [0.0, 0.0];
    };
    let (mut a, mut b, mut mean) = ([[0.0; 2]; 2], [0.0; 2], 0.0);
    for (n, s) in faces {
        let aligned = n[0] * first[0] + n[1] * first[1];
        mean += aligned.signum() * s;
        for i in 0..2 {
            b[i] += n[i] * s;
            for j in 0..2 {
                a[i][j] += n[i] * n[j];
            }
        }
    }
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    if det >= WALL_FACES_MIN_SIN2 {
        [
            (a[1][1] * b[0] - a[0][1] * b[1]) / det,
            (a[0][0] * b[1] - a[1][0] * b[0]) / det,
        ]
    } else {
        let mean = mean / faces.len() as f64;
        [mean * first[0], mean * first[1]]
    }
}

/// Each cluster's faces move together: sets the velocity of the walls that
/// `wall_of` associates (with the segments of `detections`) from their cluster's
/// faces, or holds them still when their cluster stands still.
fn move_walls(
    walls: &mut [WallTrack],
    cfg: &PerceptionConfig,
    detections: &Detections,
    wall_of: &[Option<usize>],
    still: &[bool],
) {
    let faces_of = |cluster: usize| -> Vec<([f64; 2], f64)> {
        detections
            .segments
            .iter()
            .zip(wall_of)
            .filter(|(s, _)| s.cluster == cluster)
            .filter_map(|(_, w)| w.and_then(|wi| walls.get(wi)?.normal_speed))
            .collect()
    };
    let faces: Vec<_> = detections
        .segments
        .iter()
        .map(|s| faces_of(s.cluster))
        .collect();
    for ((s, w), f) in detections.segments.iter().zip(wall_of).zip(&faces) {
        if let Some(wall) = w.and_then(|wi| walls.get_mut(wi)) {
            wall.set_velocity(f, detections.stamp, cfg);
            if still.get(s.cluster) == Some(&true) {
                wall.hold_still();
            }
        }
    }
}

/// Association cost of a new segment to a wall (offset plus gap, metres), or None when
/// outside the gates.
fn wall_cost(
    old: &SegmentMeasurement,
    new: &SegmentMeasurement,
    cfg: &PerceptionConfig,
) -> Option<f64> {
    let len = old.length();
    if len <= 0.0 {
        return None;
    }
    let d = [(old.p1[0] - old.p0[0]) / len, (old.p1[1] - old.p0[1]) / len];
    let nl = new.length();
    if nl <= 0.0 {
        return None;
    }
    let e = [(new.p1[0] - new.p0[0]) / nl, (new.p1[1] - new.p0[1]) / nl];
    // Angle between the undirected lines.
    let sin = (d[0] * e[1] - d[1] * e[0]).abs();
    let cos = (d[0] * e[0] + d[1] * e[1]).abs();
    if sin.atan2(cos) > cfg.wall_angle_gate_deg.to_radians() {
        return None;
    }
    let mid = [0.5 * (new.p0[0] + new.p1[0]), 0.5 * (new.p0[1] + new.p1[1])];
    let offset = ((mid[0] - old.p0[0]) * d[1] - (mid[1] - old.p0[1]) * d[0]).abs();
    if offset > cfg.wall_offset_gate {
        return None;
    }
    let t = |p: [f64; 2]| (p[0] - old.p0[0]) * d[0] + (p[1] - old.p0[1]) * d[1];
    let (ta, tb) = (t(new.p0), t(new.p1));
    let (lo, hi) = (ta.min(tb), ta.max(tb));
    let gap = (lo - len).max(-hi).max(0.0);
    (gap <= cfg.wall_gap_gate).then_some(offset + gap)
}

/// The (track, measurement, distance) pairs within the gate, in track then measurement
/// order. A pair gates only within `gate_max_distance` of each other, so measurements
/// are sorted by x and each track looks only at those whose x, then y, is within that
/// distance of its own (widened by a relative 1e-9 against rounding): the same pairs as
/// trying every track with every measurement, at the cost of the pairs that are near.
fn gate(
    tracks: &[PointTrack],
    circles: &[CircleMeasurement],
    cfg: &PerceptionConfig,
) -> Vec<(usize, usize, f64)> {
    // A non-finite centre is never within the gate.
    let mut by_x: Vec<(f64, usize)> = circles
        .iter()
        .enumerate()
        .filter(|(_, m)| m.centre[0].is_finite() && m.centre[1].is_finite())
        .map(|(i, m)| (m.centre[0], i))
        .collect();
    by_x.sort_by(|a, b| a.0.total_cmp(&b.0));
    let reach = cfg.gate_max_distance * (1.0 + 1e-9) + 1e-12;
    let mut candidates = Vec::new();
    let mut near = Vec::new();
    for (ti, t) in tracks.iter().enumerate() {
        let x = t.state[0];
        let lo = by_x.partition_point(|m| m.0 < x - reach);
        let hi = by_x.partition_point(|m| m.0 <= x + reach);
        near.clear();
        near.extend(by_x.get(lo..hi).unwrap_or_default().iter().map(|m| m.1));
        near.sort_unstable();
        for &mi in &near {
            let Some(m) = circles.get(mi) else {
                continue;
            };
            // Out of reach in y as well: no innovation to compute.
            if (m.centre[1] - t.state[1]).abs() > reach {
                continue;
            }
            if let Some(d) = t.gated_distance(m, cfg) {
                candidates.push((ti, mi, d));
            }
        }
    }
    candidates
}

/// Greedy global nearest neighbour: pairs (track, measurement) by increasing cost.
fn assign(
    mut candidates: Vec<(usize, usize, f64)>,
    tracks: usize,
    measurements: usize,
) -> Vec<Option<usize>> {
    candidates.sort_by(|a, b| a.2.total_cmp(&b.2));
    let mut track_of = vec![None; measurements];
    let mut taken = vec![false; tracks];
    for (t, m, _) in candidates {
        if !taken[t] && track_of[m].is_none() {
            taken[t] = true;
            track_of[m] = Some(t);
        }
    }
    track_of
}

/// The perception pipeline with its tracks: feed it every scan in time order.
#[derive(Clone, Debug)]
pub struct Perception {
    cfg: PerceptionConfig,
    tracks: Vec<PointTrack>,
    walls: Vec<WallTrack>,
    next_id: u64,
    last_stamp: Option<f64>,
    /// The scans of the last `STILL_BASELINE_S` and the newest one before, for
    /// [`Perception::still_clusters`].
    past: VecDeque<PastView>,
    /// The laser's beam directions, computed once.
    directions: BeamDirections,
}

impl Perception {
    pub fn new(cfg: PerceptionConfig) -> Result<Self, PerceptionError> {
        cfg.validate()?;
        Ok(Perception {
            cfg,
            tracks: Vec::new(),
            walls: Vec::new(),
            next_id: 1,
            last_stamp: None,
            past: VecDeque::new(),
            directions: BeamDirections::default(),
        })
    }

    pub fn config(&self) -> &PerceptionConfig {
        &self.cfg
    }

    /// Forgets every track (ids keep increasing).
    pub fn reset(&mut self) {
        self.tracks.clear();
        self.walls.clear();
        self.last_stamp = None;
        self.past.clear();
    }

    /// Detects and tracks one scan; `mount` is the laser's pose in the vehicle frame,
    /// `pose` the vehicle's in the world frame at the scan's stamp. Stamps must
    /// increase. A refused scan leaves the tracks unchanged. Each input is checked
    /// once: the scan when it was made a [`ValidScan`], the configuration when this
    /// was built, the stamp's order here, the mount and the pose by the detection.
    pub fn update(
        &mut self,
        scan: &ValidScan<'_>,
        mount: &Pose2,
        pose: &Pose2,
    ) -> Result<PerceptionOutput, PerceptionError> {
        self.check_stamp_order(scan.stamp)?;
        let detections = detect_with(scan, mount, pose, &self.cfg, Some(&mut self.directions))?;
        Ok(self.track(&detections, pose))
    }

    /// Tracks one scan's detections (from [`super::detect`], e.g. kept for plotting),
    /// its stamp and `pose` checked.
    pub fn update_detections(
        &mut self,
        detections: &Detections,
        pose: &Pose2,
    ) -> Result<PerceptionOutput, PerceptionError> {
        check_finite("stamp", detections.stamp)?;
        pose.validate("pose.x", "pose.y", "pose.yaw")?;
        self.check_stamp_order(detections.stamp)?;
        Ok(self.track(detections, pose))
    }

    /// Tracks one scan's detections, its stamp and `pose` checked.
    fn track(&mut self, detections: &Detections, pose: &Pose2) -> PerceptionOutput {
        let stamp = detections.stamp;
        let dt = self.last_stamp.map_or(0.0, |last| stamp - last);
        self.last_stamp = Some(stamp);
        let still = self.still_clusters(detections);
        self.track_points(detections, pose, dt, &still);
        self.track_walls(detections, pose, &still);
        self.output(stamp, pose, true)
    }

    /// Posts and blobs: predicts, associates, updates, remembers or misses, and
    /// starts new tracks; `still` says which clusters stand still
    /// ([`Perception::still_clusters`]).
    fn track_points(&mut self, detections: &Detections, pose: &Pose2, dt: f64, still: &[bool]) {
        let stamp = detections.stamp;
        let cfg = &self.cfg;
        for t in &mut self.tracks {
            t.predict(dt, cfg);
        }
        let candidates = gate(&self.tracks, &detections.circles, cfg);
        let track_of = assign(candidates, self.tracks.len(), detections.circles.len());
        // Which tracks this scan updated, and which hold their motion unjudged: seen
        // only at the edge of the view, or out of sight.
        let mut updated = vec![false; self.tracks.len()];
        let mut held = vec![false; self.tracks.len()];
        for (m, t) in detections.circles.iter().zip(&track_of) {
            if let Some(ti) = t {
                if let Some(track) = self.tracks.get_mut(*ti) {
                    let corrected = track.update(m, cfg);
                    track.last_hit = stamp;
                    if corrected && still.get(m.cluster) == Some(&true) {
                        track.hold_still();
                    }
                    if let Some(h) = held.get_mut(*ti) {
                        *h = !corrected;
                    }
                }
                if let Some(u) = updated.get_mut(*ti) {
                    *u = true;
                }
            }
        }
        // The local map: a confirmed static track the scan could not have seen is
        // remembered, not missed, while within `memory_radius`. A mover is in sight
        // only when enough beams to make a cluster (`min_points`) reach the inner half
        // of its disc: beams grazing its edge (a walker leaving the field of view) may
        // miss it or make a cluster too small to keep, so their silence is no miss.
        let sees = |x: f64, y: f64, r: f64| detections.view.sees(&detections.laser, x, y, r);
        let sees_mover = |x: f64, y: f64, r: f64| {
            detections
                .view
                .shows(&detections.laser, x, y, 0.5 * r, cfg.min_points)
        };
        let nearby =
            |x: f64, y: f64, r: f64| distance([x, y], [pose.x, pose.y]) - r <= cfg.memory_radius;
        let remembered = |x: f64, y: f64, r: f64, life: &Life, moving: bool| {
            life.memorable(cfg) && !moving && nearby(x, y, r) && !sees(x, y, r)
        };
        for ((t, u), h) in self.tracks.iter_mut().zip(&updated).zip(&mut held) {
            let moving = t.reported_velocity(stamp, cfg) != [0.0, 0.0];
            if *u {
                continue;
            }
            if moving
                && t.life.confirmed
                && stamp - t.last_hit <= cfg.moving_memory_s
                && nearby(t.state[0], t.state[1], t.radius)
                && !sees_mover(t.state[0], t.state[1], t.radius)
            {
                // Moving out of sight: it goes on where its velocity takes it (the
                // prediction above), its motion held as last measured.
                *h = true;
            } else if remembered(t.state[0], t.state[1], t.radius, &t.life, moving) {
                // Static: the filter's velocity below the dead band is noise, and with
                // no measurement to correct it the remembered position would drift.
                t.state[2] = 0.0;
                t.state[3] = 0.0;
            } else {
                t.life.record(false, cfg);
            }
        }
        for (t, _) in self.tracks.iter_mut().zip(&held).filter(|(_, h)| !**h) {
            t.note_motion(stamp, cfg);
        }
        self.tracks.retain(|t| {
            !t.life.dead(cfg)
                && (cfg.memory_radius <= 0.0
                    || distance([t.state[0], t.state[1]], [pose.x, pose.y]) - t.radius
                        <= cfg.memory_radius
                    || sees(t.state[0], t.state[1], t.radius))
        });
        for (m, t) in detections.circles.iter().zip(&track_of) {
            // A measurement centred inside a confirmed track's circle is a fragment of
            // that object (a partial view, a cluster split by dropouts), not a new one.
            let fragment = || {
                self.tracks.iter().any(|t| {
                    t.life.confirmed
                        && distance([t.state[0], t.state[1]], m.centre) < t.radius.max(m.radius)
                })
            };
            if t.is_none() && !fragment() {
                self.tracks
                    .push(PointTrack::new(self.next_id, m, stamp, cfg));
                self.next_id += 1;
            }
        }
    }

    /// Walls: associates segments, measures their motion, remembers or misses them,
    /// and starts new ones; `still` as for [`Perception::track_points`].
    fn track_walls(&mut self, detections: &Detections, pose: &Pose2, still: &[bool]) {
        let stamp = detections.stamp;
        let cfg = &self.cfg;
        let sees = |x: f64, y: f64, r: f64| detections.view.sees(&detections.laser, x, y, r);
        let mut candidates = Vec::new();
        for (ti, w) in self.walls.iter().enumerate() {
            for (mi, s) in detections.segments.iter().enumerate() {
                if let Some(c) = wall_cost(&w.segment, s, cfg) {
                    candidates.push((ti, mi, c));
                }
            }
        }
        let wall_of = assign(candidates, self.walls.len(), detections.segments.len());
        let mut updated = vec![false; self.walls.len()];
        for (s, w) in detections.segments.iter().zip(&wall_of) {
            if let Some(wi) = w
                && let Some(wall) = self.walls.get_mut(*wi)
            {
                let before = wall.segment;
                let static_map = wall.memorable(stamp, cfg);
                wall.associate(s, stamp);
                if static_map {
                    wall.segment = keep_unseen_extent(&before, &wall.segment, &sees);
                }
                wall.life.record(true, cfg);
                if let Some(u) = updated.get_mut(*wi) {
                    *u = true;
                }
            }
        }
        move_walls(&mut self.walls, cfg, detections, &wall_of, still);
        // A new face of a tracked object moves with it: its velocity, per cluster.
        let motion_of_cluster = |cluster: usize| {
            detections
                .segments
                .iter()
                .zip(&wall_of)
                .filter(|(s, _)| s.cluster == cluster)
                .find_map(|(_, w)| w.and_then(|wi| self.walls.get(wi)))
                .map(|w| (w.velocity, w.moving_since))
        };
        let inherited: Vec<_> = detections
            .segments
            .iter()
            .zip(&wall_of)
            .map(|(s, w)| w.is_none().then(|| motion_of_cluster(s.cluster)).flatten())
            .collect();
        // A wall is seen when some point of it is (every metre, both ends).
        let wall_seen = |s: &SegmentMeasurement| {
            let length = (s.p1[0] - s.p0[0]).hypot(s.p1[1] - s.p0[1]);
            let n = length.ceil().clamp(1.0, 1e4) as usize;
            (0..=n).any(|i| {
                let t = i as f64 / n as f64;
                let x = s.p0[0] + t * (s.p1[0] - s.p0[0]);
                let y = s.p0[1] + t * (s.p1[1] - s.p0[1]);
                sees(x, y, s.half_thickness.max(0.0))
            })
        };
        let near = |s: &SegmentMeasurement| {
            distance_to_segment([pose.x, pose.y], s.p0, s.p1) <= cfg.memory_radius
        };
        for (w, u) in self.walls.iter_mut().zip(&updated) {
            let kept = w.memorable(stamp, cfg) && near(&w.segment) && !wall_seen(&w.segment);
            if !u && !kept {
                w.life.record(false, cfg);
            }
        }
        self.walls.retain(|w| {
            !w.life.dead(cfg)
                && (cfg.memory_radius <= 0.0 || near(&w.segment) || wall_seen(&w.segment))
        });
        for ((s, w), motion) in detections.segments.iter().zip(&wall_of).zip(inherited) {
            if w.is_none() {
                let mut wall = WallTrack::new(self.next_id, *s, stamp, cfg);
                if let Some((velocity, moving_since)) = motion {
                    wall.velocity = velocity;
                    wall.moving_since = moving_since;
                }
                self.walls.push(wall);
                self.next_id += 1;
            }
        }
    }

    /// Which clusters of `detections` stand still: most of their hits lie on the
    /// surfaces the scan of at least `STILL_BASELINE_S` earlier saw in the same place,
    /// and almost none in the space its beams went through ([`cluster_still`]). Keeps
    /// the scan for the comparisons to come.
    fn still_clusters(&mut self, detections: &Detections) -> Vec<bool> {
        let stamp = detections.stamp;
        let baseline = self
            .past
            .iter()
            .rev()
            .find(|v| stamp - v.stamp >= STILL_BASELINE_S - 1e-9);
        // The baseline's beam hits, each computed once for all the clusters.
        let mut hits = baseline.map_or_else(Vec::new, |past| past.view.hit_cache());
        let still = detections
            .clusters
            .iter()
            .map(|c| {
                baseline.is_some_and(|past| {
                    detections
                        .points
                        .get(c.clone())
                        .is_some_and(|points| cluster_still(points, past, &mut hits))
                })
            })
            .collect();
        self.past.push_back(PastView {
            stamp,
            laser: detections.laser,
            view: detections.view.clone(),
        });
        while self
            .past
            .get(1)
            .is_some_and(|v| stamp - v.stamp >= STILL_BASELINE_S - 1e-9)
        {
            self.past.pop_front();
        }
        still
    }

    /// Every track, tentative ones included, without the detection radius (for
    /// diagnostics), as of the last scan.
    pub fn all_tracks(&self) -> Vec<TrackedObstacle> {
        let stamp = self.last_stamp.unwrap_or(0.0);
        let pose = Pose2::new(0.0, 0.0, 0.0);
        self.output(stamp, &pose, false).obstacles
    }

    /// The output as of `stamp`: every track and wall (as segments and as the discs
    /// that cover them), with `filtered` only the confirmed ones within the detection
    /// radius (widened by how far a mover reaches) around `pose`.
    fn output(&self, stamp: f64, pose: &Pose2, filtered: bool) -> PerceptionOutput {
        let within = Within { pose, filtered };
        let mut obstacles = self.point_obstacles(stamp, &within);
        let mut segments = Vec::new();
        for w in &self.walls {
            if filtered && !w.life.confirmed {
                continue;
            }
            let s = &w.segment;
            if !filtered
                || distance_to_segment([pose.x, pose.y], s.p0, s.p1) <= self.cfg.detection_radius
            {
                segments.push(w.segment_output(stamp, &self.cfg));
            }
            obstacles.extend(w.pieces(stamp, &self.cfg, &within));
        }
        obstacles.sort_by_key(|o| (o.id, o.part));
        segments.sort_by_key(|s| s.id);
        PerceptionOutput {
            stamp,
            obstacles,
            segments,
        }
    }

    /// The point tracks as obstacles: a track sliding along a static wall, or missed
    /// and not moving, stands where it was last measured and still.
    fn point_obstacles(&self, stamp: f64, within: &Within<'_>) -> Vec<TrackedObstacle> {
        let cfg = &self.cfg;
        let static_walls: Vec<&SegmentMeasurement> = self
            .walls
            .iter()
            .filter(|w| w.life.confirmed && w.reported_velocity(stamp, cfg) == [0.0, 0.0])
            .map(|w| &w.segment)
            .collect();
        let mut obstacles = Vec::new();
        for t in &self.tracks {
            if within.filtered && !t.life.confirmed {
                continue;
            }
            let (mut x, mut y) = (t.state[0], t.state[1]);
            let mut velocity = t.reported_velocity(stamp, cfg);
            if static_walls
                .iter()
                .any(|w| slides_along(w, [x, y], t.radius, velocity))
            {
                velocity = [0.0, 0.0];
            }
            // Missed, and not moving: where it was last measured. Coasting on a
            // velocity estimate below the dead band (or not yet confirmed) carried a
            // wall's end into the gate beside it at 1 m/s.
            if t.life.misses > 0 && velocity == [0.0, 0.0] {
                [x, y] = t.measured;
            }
            let [vx, vy] = velocity;
            if !within.radius(x, y, t.radius, reach([vx, vy], cfg)) {
                continue;
            }
            obstacles.push(TrackedObstacle {
                id: t.id,
                part: 0,
                disc: Obstacle {
                    x,
                    y,
                    radius: t.radius,
                    vx,
                    vy,
                },
                velocity_estimate: [t.state[2], t.state[3]],
                kind: t.kind,
                confidence: t.life.confidence(cfg),
                age: stamp - t.life.born,
                hits: t.life.hits,
                misses: t.life.misses,
            });
        }
        obstacles
    }

    /// A (finite) stamp after the previous scan's.
    fn check_stamp_order(&self, stamp: f64) -> Result<(), PerceptionError> {
        match self.last_stamp {
            Some(previous) if stamp <= previous => {
                Err(PerceptionError::StampNotIncreasing { stamp, previous })
            }
            _ => Ok(()),
        }
    }
}

/// Which outputs are kept: with `filtered`, only those within a radius of `pose`.
struct Within<'a> {
    pose: &'a Pose2,
    filtered: bool,
}

impl Within<'_> {
    /// Whether a disc at (x, y) of radius `r` comes within `radius` of the pose (or
    /// nothing is filtered).
    fn radius(&self, x: f64, y: f64, r: f64, radius: f64) -> bool {
        !self.filtered || distance([x, y], [self.pose.x, self.pose.y]) - r <= radius
    }
}

impl WallTrack {
    /// The wall as a segment of the output.
    fn segment_output(&self, stamp: f64, cfg: &PerceptionConfig) -> WallSegment {
        let s = &self.segment;
        WallSegment {
            id: self.id,
            p0: s.p0,
            p1: s.p1,
            half_thickness: s.half_thickness,
            rms: s.rms,
            confidence: self.life.confidence(cfg),
            age: stamp - self.life.born,
            hits: self.life.hits,
            misses: self.life.misses,
        }
    }

    /// The discs that cover the wall, as obstacles (those `within` keeps).
    fn pieces(
        &self,
        stamp: f64,
        cfg: &PerceptionConfig,
        within: &Within<'_>,
    ) -> Vec<TrackedObstacle> {
        let s = &self.segment;
        let confidence = self.life.confidence(cfg);
        let age = stamp - self.life.born;
        let [vx, vy] = self.reported_velocity(stamp, cfg);
        let reach = reach([vx, vy], cfg);
        let (radius, centres) = cover_segment(s.p0, s.p1, s.half_thickness, cfg);
        let mut pieces = Vec::new();
        for (part, c) in centres.iter().enumerate() {
            if !within.radius(c[0], c[1], radius, reach) {
                continue;
            }
            pieces.push(TrackedObstacle {
                id: self.id,
                part: u32::try_from(part).unwrap_or(u32::MAX),
                disc: Obstacle {
                    x: c[0],
                    y: c[1],
                    radius,
                    vx,
                    vy,
                },
                velocity_estimate: self.velocity,
                kind: ObstacleKind::WallPiece,
                confidence,
                age,
                hits: self.life.hits,
                misses: self.life.misses,
            });
        }
        pieces
    }
}

/// The unit direction of `s` from p0 to p1; `None` for a segment of no length.
fn direction(s: &SegmentMeasurement) -> Option<[f64; 2]> {
    let len = s.length();
    (len > 0.0).then(|| [(s.p1[0] - s.p0[0]) / len, (s.p1[1] - s.p0[1]) / len])
}

/// Where `p` lies in the frame of the line through `origin` along unit `u`: how far
/// along it, and how far to its left (negative: to its right).
fn line_coords(origin: [f64; 2], u: [f64; 2], p: [f64; 2]) -> (f64, f64) {
    let (dx, dy) = (p[0] - origin[0], p[1] - origin[1]);
    (dx * u[0] + dy * u[1], -dx * u[1] + dy * u[0])
}

/// A point track this near a static wall's line (beyond the two's radii), moving along
/// it, is the wall's end (or a piece of it between gaps) sliding along as more or less
/// of the wall comes into view past an occluder, not an object: it is reported
/// static. Seen at a fence's gate: a 0.2 m "post" racing along the fence at 5.5 m/s
/// closed the gate for the planner.
const SLIDING_EDGE_GAP: f64 = 0.3;
/// Along the wall: within about 25 degrees of its direction.
const SLIDING_EDGE_MIN_COS: f64 = 0.9;

/// Whether a point track at `p` of `radius` moving at `velocity` is the sliding edge of
/// `wall` (see [`SLIDING_EDGE_GAP`]).
fn slides_along(wall: &SegmentMeasurement, p: [f64; 2], radius: f64, velocity: [f64; 2]) -> bool {
    let speed = velocity[0].hypot(velocity[1]);
    if speed == 0.0 {
        return false;
    }
    let Some(u) = direction(wall) else {
        return false;
    };
    let along = (velocity[0] * u[0] + velocity[1] * u[1]).abs() / speed;
    let across = line_coords(wall.p0, u, p).1.abs();
    along >= SLIDING_EDGE_MIN_COS && across <= wall.half_thickness + radius + SLIDING_EDGE_GAP
}

/// How far segment `new` lies from segment `old` along `old`'s normal (left of p0 to
/// p1 positive), at the middle of the stretch both cover; `None` when they cover none
/// in common. Taken at a place both lines see, not at the new segment's middle: as
/// more or less of a wall comes into view its middle slides along it, and a fitted
/// direction a degree or two off turns that slide into an apparent normal motion
/// (a fence seen through a gate, 3 m of it more each 0.2 s, moved at 0.5 m/s).
fn normal_offset(old: &SegmentMeasurement, new: &SegmentMeasurement) -> Option<f64> {
    let u = direction(old)?;
    let len = old.length();
    let (a0, a1) = (
        line_coords(old.p0, u, new.p0).0,
        line_coords(old.p0, u, new.p1).0,
    );
    let lo = a0.min(a1).max(0.0);
    let hi = a0.max(a1).min(len);
    if hi <= lo {
        return None;
    }
    let centre = 0.5 * (lo + hi);
    // The new segment's point at that place along the old one.
    let t = if (a1 - a0).abs() > 1e-9 {
        (centre - a0) / (a1 - a0)
    } else {
        0.5
    };
    let q = [
        new.p0[0] + t * (new.p1[0] - new.p0[0]),
        new.p0[1] + t * (new.p1[1] - new.p0[1]),
    ];
    Some(line_coords(old.p0, u, q).1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tracked obstacle is written flat, its disc's fields beside the tracker's (as
    /// when they were its own), and reads back.
    #[test]
    fn a_tracked_obstacle_serialises_flat_and_reads_back() {
        let o = TrackedObstacle {
            id: 7,
            part: 2,
            disc: Obstacle {
                x: 1.5,
                y: -2.0,
                radius: 0.3,
                vx: 0.5,
                vy: 0.0,
            },
            velocity_estimate: [0.5, 0.01],
            kind: ObstacleKind::Post,
            confidence: 1.0,
            age: 2.5,
            hits: 100,
            misses: 0,
        };
        let json = serde_json::to_string(&o).expect("serialises");
        assert!(
            json.starts_with(
                r#"{"id":7,"part":2,"x":1.5,"y":-2.0,"radius":0.3,"vx":0.5,"vy":0.0,"#
            ),
            "{json}"
        );
        let back: TrackedObstacle = serde_json::from_str(&json).expect("reads back");
        assert_eq!(back, o);
    }

    #[test]
    fn gating_by_position_finds_the_pairs_all_against_all_does() {
        let cfg = PerceptionConfig::default();
        let circle = |x: f64, y: f64| CircleMeasurement {
            centre: [x, y],
            radius: 0.2,
            centre_covariance: [[0.01, 0.0], [0.0, 0.01]],
            radius_variance: 0.01,
            kind: ObstacleKind::Post,
            rms: 0.01,
            points: 8,
            cluster: 0,
            truncated: false,
        };
        // A field of posts 0.9-2.5 m apart, tracks a little off some of them, and
        // measurements that coincide in x or y.
        let at = |i: u32| {
            let f = f64::from(i);
            ((f * 0.37).sin() * 12.0 + f * 0.05, (f * 0.61).cos() * 9.0)
        };
        let circles: Vec<CircleMeasurement> = (0..120)
            .map(at)
            .chain([(3.0, 1.0), (3.0, 1.5), (3.5, 1.0)])
            .map(|(x, y)| circle(x, y))
            .collect();
        let tracks: Vec<PointTrack> = (0..90)
            .map(|i| {
                let (x, y) = at(i * 4 / 3);
                let m = circle(x + 0.4 * (f64::from(i)).sin(), y + 0.3);
                PointTrack::new(u64::from(i), &m, 0.0, &cfg)
            })
            .collect();
        let mut all = Vec::new();
        for (ti, t) in tracks.iter().enumerate() {
            for (mi, m) in circles.iter().enumerate() {
                if let Some(d) = t.gated_distance(m, &cfg) {
                    all.push((ti, mi, d));
                }
            }
        }
        assert!(all.len() > 90);
        assert_eq!(gate(&tracks, &circles, &cfg), all);
    }

    #[test]
    fn a_cluster_is_judged_still_as_counting_its_sampled_hits_judges_it() {
        // A wall 5 m ahead across 61 beams, with a gap of no returns and a nearer object.
        let mut ranges: Vec<f32> = (0..61)
            .map(|i| (5.0 / (f64::from(i) - 30.0).to_radians().cos()) as f32)
            .collect();
        ranges[40..46].fill(f32::INFINITY);
        ranges[10..14].fill(3.0);
        let past = PastView {
            stamp: 0.0,
            laser: Pose2::new(0.0, 0.0, 0.0),
            view: View {
                angle_min: -30f64.to_radians(),
                angle_increment: 1f64.to_radians(),
                range_max: 20.0,
                ranges,
            },
        };
        // Runs of hits on the wall, near it, in front of it and behind it.
        let points: Vec<ScanPoint> = (0..150u32)
            .map(|i| {
                let f = f64::from(i);
                let x = 5.0 + [0.0, 0.02, -0.5, 0.5][((i / 7 + i / 11) % 4) as usize];
                let world = [x, x * (-35.0 + 0.5 * f).to_radians().tan()];
                ScanPoint {
                    beam: i as usize,
                    range: 0.0,
                    angle: 0.0,
                    laser: world,
                    vehicle: world,
                    world,
                }
            })
            .collect();
        let counted = |c: &[ScanPoint]| {
            let seen: Vec<Seen> = still_sample(c)
                .map(|p| past.view.surface_at(&past.laser, p.world, STILL_TOLERANCE))
                .collect();
            let count = |s: Seen| seen.iter().filter(|&&x| x == s).count();
            let (surface, free, n) = (count(Seen::Surface), count(Seen::Free), seen.len());
            surface >= 2 && 2 * surface >= n && 10 * free <= n
        };
        let mut hits = past.view.hit_cache();
        let mut answers = [0; 2];
        for start in 0..points.len() {
            for len in [0, 1, 2, 3, 5, 8, 13, 21, 40, 150] {
                let c = &points[start..(start + len).min(points.len())];
                let still = cluster_still(c, &past, &mut hits);
                assert_eq!(still, counted(c), "{start} + {len}");
                answers[usize::from(still)] += 1;
            }
        }
        assert!(answers[0] > 100 && answers[1] > 100, "{answers:?}");
    }

    #[test]
    fn a_large_clusters_sample_spreads_from_its_first_hit_to_its_last() {
        let points: Vec<ScanPoint> = (0..100)
            .map(|beam| ScanPoint {
                beam,
                range: 1.0,
                angle: 0.0,
                laser: [0.0; 2],
                vehicle: [0.0; 2],
                world: [0.0; 2],
            })
            .collect();
        let beams =
            |n: usize| -> Vec<usize> { still_sample(&points[..n]).map(|p| p.beam).collect() };
        assert_eq!(
            beams(5),
            [0, 1, 2, 3, 4],
            "a small cluster is looked at whole"
        );
        let sample = beams(100);
        assert_eq!(sample.len(), STILL_SAMPLES);
        assert_eq!((sample[0], sample[STILL_SAMPLES - 1]), (0, 95));
        assert!(
            sample.windows(2).all(|w| (4..=5).contains(&(w[1] - w[0]))),
            "{sample:?}"
        );
    }

    #[test]
    fn m_of_n_birth_and_k_miss_deletion() {
        let cfg = PerceptionConfig::default();
        let mut life = Life::new(0.0, &cfg);
        life.record(false, &cfg);
        life.record(true, &cfg);
        assert!(!life.confirmed);
        life.record(true, &cfg);
        assert!(life.confirmed);
        for _ in 0..cfg.delete_misses - 1 {
            life.record(false, &cfg);
        }
        assert!(!life.dead(&cfg));
        life.record(false, &cfg);
        assert!(life.dead(&cfg));

        let mut tentative = Life::new(0.0, &cfg);
        for _ in 0..cfg.birth_window - 1 {
            tentative.record(false, &cfg);
        }
        assert!(tentative.dead(&cfg));
    }

    /// A thin wall piece from p0 to p1, fitted to 10 points.
    fn seg(p0: [f64; 2], p1: [f64; 2]) -> SegmentMeasurement {
        SegmentMeasurement {
            p0,
            p1,
            half_thickness: 0.0,
            rms: 0.0,
            points: 10,
            cluster: 0,
        }
    }

    #[test]
    fn wall_association_gates() {
        let cfg = PerceptionConfig::default();
        let old = seg([0.0, 0.0], [5.0, 0.0]);
        assert!(wall_cost(&old, &seg([4.0, 0.1], [8.0, 0.1]), &cfg).is_some());
        assert!(wall_cost(&old, &seg([8.0, 0.1], [4.0, 0.1]), &cfg).is_some());
        assert!(wall_cost(&old, &seg([7.0, 0.0], [9.0, 0.0]), &cfg).is_none());
        assert!(wall_cost(&old, &seg([1.0, 1.0], [4.0, 1.0]), &cfg).is_none());
        assert!(wall_cost(&old, &seg([1.0, 0.0], [4.0, 2.0]), &cfg).is_none());
    }

    #[test]
    fn a_wall_coming_into_view_is_measured_where_both_fits_see_it() {
        // A fence along y = 0 fitted 2 degrees off, 3 m more of it in view next time:
        // it has not moved where both fits see it.
        let tilt = 2f64.to_radians().tan();
        let old = seg([0.0, 0.0], [4.0, 4.0 * tilt]);
        let new = seg([0.0, 0.0], [7.0, 0.0]);
        let offset = normal_offset(&old, &new).expect("they overlap");
        // At the middle of the common 4 m, 2 m from p0: the tilt's 2 m * tan 2°, not
        // the new middle's 3.5 m * tan 2°.
        assert!((offset + 2.0 * tilt).abs() < 1e-3, "{offset}");
        // Moved 0.3 m along the normal, whatever came into view.
        let moved = seg([1.0, 0.3], [9.0, 0.3]);
        let offset = normal_offset(&seg([0.0, 0.0], [4.0, 0.0]), &moved).expect("overlap");
        assert!((offset - 0.3).abs() < 1e-9, "{offset}");
        assert!(normal_offset(&old, &seg([5.0, 0.0], [9.0, 0.0])).is_none());
    }

    #[test]
    fn a_point_sliding_along_a_static_wall_is_its_edge_and_one_crossing_it_is_not() {
        let fence = SegmentMeasurement {
            half_thickness: 0.1,
            ..seg([20.0, -25.0], [20.0, -1.0])
        };
        // On the fence's line, racing along it: the edge of what is in view.
        assert!(slides_along(&fence, [20.06, -6.94], 0.2, [-0.02, -5.49]));
        // Beside the fence but walking towards it, or along it 2 m away: objects.
        assert!(!slides_along(&fence, [19.5, -6.0], 0.3, [1.0, 0.1]));
        assert!(!slides_along(&fence, [18.0, -6.0], 0.3, [0.0, 1.0]));
        // Moving along it, but a metre off its line: an object.
        assert!(!slides_along(&fence, [21.0, -6.0], 0.2, [0.0, 1.0]));
    }

    #[test]
    fn a_wall_keeps_only_the_stretch_that_went_out_of_view() {
        // A hedge along y = 0 from x = 0 to 20, remembered whole; now only x >= 12 is
        // measured, the scanner seeing nothing below x = 11.6 (behind it).
        let old = seg([0.0, 0.0], [20.0, 0.0]);
        let new = seg([12.0, 0.05], [20.0, 0.05]);
        let behind = |x: f64, _: f64, _: f64| x > 11.6;
        let kept = keep_unseen_extent(&old, &new, &behind);
        assert!(dist(kept.p0, [0.0, 0.05]) < 1e-9, "{kept:?}");
        assert_eq!(kept.p1, new.p1);
        // Measured the other way round (p0 the far end): the same stretch kept.
        let reversed = seg([20.0, 0.05], [12.0, 0.05]);
        let kept = keep_unseen_extent(&old, &reversed, &behind);
        assert_eq!(kept.p0, reversed.p0);
        assert!(dist(kept.p1, [0.0, 0.05]) < 1e-9, "{kept:?}");
        // A stretch in view between (a gap in the hedge the scan looks through): the
        // wall is not there, so nothing beyond it is kept.
        let gap = |x: f64, _: f64, _: f64| x > 11.6 || (3.0..4.0).contains(&x);
        assert_eq!(keep_unseen_extent(&old, &new, &gap), new);
        // Ends in view stay as measured: no growth from one noisy end to the next.
        let everywhere = |_: f64, _: f64, _: f64| true;
        let fence = seg([5.0, 0.0], [8.2, 0.0]);
        let shorter = seg([5.1, 0.0], [8.0, 0.02]);
        assert_eq!(keep_unseen_extent(&fence, &shorter, &everywhere), shorter);
        // An end off the new line (a bend) is not carried onto it.
        let bent = seg([0.0, 2.0], [20.0, 0.0]);
        assert_eq!(keep_unseen_extent(&bent, &new, &behind).p0, new.p0);
        // An end just past the measured one, out of view: kept (the field of view's
        // edge sweeping along the hedge a few centimetres a scan); in view: not.
        let just = seg([11.5, 0.0], [20.0, 0.0]);
        assert!(dist(keep_unseen_extent(&just, &new, &behind).p0, [11.5, 0.05]) < 1e-9);
        let edge = |x: f64, _: f64, _: f64| x > 11.4;
        assert_eq!(keep_unseen_extent(&just, &new, &edge), new);
    }

    fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
        (a[0] - b[0]).hypot(a[1] - b[1])
    }
}
