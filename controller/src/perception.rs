//! Obstacle detection with the 2D laser scanner: scan points into the vehicle and world
//! frames, clustering, circle and line fits, tracking with velocity estimates, and the
//! circles the planner takes.
//!
//! # Frames (the seed paper's "Coordinate Transformation")
//!
//! Beam i of a [`Scan`] has the angle `a_i = angle_min + i angle_increment`, radians
//! counter-clockwise from the scanner's forward axis, and the laser-frame point
//! `L_P = r_i (cos a_i, sin a_i)`. The laser's mounting pose in the vehicle frame
//! (x forward, y left, origin at the rear axle centre, yaw CCW) and the vehicle pose in
//! the world frame (rear-axle x, y, heading theta CCW from +x) are both [`Pose2`]s, and
//! each maps a point by the paper's `W_P = W_R R_P + W_P_ORG`:
//!
//! ```text
//! V_P = R(mount.yaw) L_P + (mount.x, mount.y)
//! W_P = R(theta)     V_P + (x, y)            R(a) = [cos a  -sin a; sin a  cos a]
//! ```
//!
//! The vehicle pose must be the one at the scan's stamp (the caller interpolates); the
//! beams of one sweep are treated as simultaneous (no motion de-skew).
//!
//! # Beams
//!
//! A range is a hit when it is finite and within `[range_min, range_max]`. `+inf` (and
//! any range above `range_max`) is a no-return: the beam saw free space, so it always
//! separates clusters. NaN, negative and below-`range_min` ranges are dropouts: no
//! information; up to [`PerceptionConfig::max_dropout_beams`] consecutive ones are
//! bridged when clustering.
//!
//! # Pipeline of one scan ([`detect`], then [`Perception::update`])
//!
//! Each input is checked once. A scan where it enters: [`Scan::validate`] makes the
//! [`ValidScan`] every step takes (the controller makes it from the laser frame,
//! [`ValidScan::from_frame`]); the configuration when the [`Perception`] is built; the
//! stamp's order, the mount and the pose at the update.
//!
//! 1. Clustering ([`cluster_points`]): consecutive hits belong to the same object when
//!    their distance is below Borges and Aldon's adaptive breakpoint
//!    `D = min(r_a, r_b) sin(dphi) / sin(lambda - dphi) + k sigma_r` (dphi the angle
//!    between the two beams, lambda the steepest incidence angle a surface may have,
//!    default 10 degrees, k = 3, sigma_r = 12 mm). Clusters with fewer than
//!    `min_points` hits are dropped.
//! 2. Shape ([`fit_circle`], [`fit_line`], [`split_and_merge`]): a cluster of at least
//!    `circle_min_points` hits is fitted with a circle (Taubin's algebraic fit, then
//!    Levenberg-Marquardt on the geometric distances) and a line (total least squares).
//!    It is a post when the circle is plausible (radius within
//!    `[circle_radius_min, circle_radius_max]`, RMS residual at most `circle_rms_max`,
//!    the laser outside the circle and the centre behind the points, the radius pinned
//!    down by the hits: its standard deviation from the fit's covariance at most
//!    `circle_radius_sigma_max`) and explains the points clearly better than the line
//!    (`line_rms > circle_line_ratio circle_rms`).
//!    Otherwise the cluster is split into a polyline (iterative end-point fit with
//!    `split_distance`, adjacent pieces merged back while they stay within it); pieces
//!    with `line_min_points` hits and `segment_min_length` become wall segments, the
//!    rest (and small clusters) become blobs of kind [`ObstacleKind::Unknown`]: the
//!    centroid pushed away from the laser by `2 r / pi` (the offset of the centroid of a
//!    half circle seen from outside), r half the cluster's chord.
//! 3. Tracking ([`Perception`]): posts and blobs are tracked with a constant-velocity
//!    Kalman filter in the world frame (state x, y, vx, vy; white-noise acceleration of
//!    spectral density `accel_noise`). The measurement covariance is the circle fit's
//!    own (s^2 (J'J)^-1 at the geometric solution) plus `position_sigma_min^2` per
//!    axis, plus the post's radius squared per axis when a blob (a few hits somewhere
//!    on it) updates a post's track. Association is greedy global nearest neighbour on
//!    the Euclidean distance inside a gate: Mahalanobis distance squared at most
//!    `gate_chi2`, or Euclidean distance at most `gate_min_distance`, never beyond
//!    `gate_max_distance`. The radius has its own scalar filter. Wall segments are
//!    associated to wall tracks by direction, offset and overlap. A track is confirmed
//!    after `birth_hits` hits within its first `birth_window` scans (else deleted) and
//!    deleted after `delete_misses` consecutive misses; confirmed tracks are reported,
//!    coasting ones at their predicted position.
//!
//! # Velocity dead band
//!
//! The reported velocity is exactly zero when the estimated speed is below
//! `velocity_dead_band` (0.1 m/s) or when the velocity is not significant against its
//! own covariance (`v' P_vv^-1 v < velocity_significance_chi2`, 9.21: 99% for two
//! degrees of freedom), so static obstacles read zero instead of the filter's jitter,
//! and until the velocity has passed both tests, and held them on every scan since,
//! for `moving_confirm_s` (0.5 s; held: above the dead band and
//! `velocity_hold_chi2`, 4.61, 90%, so a walker at 0.5 m/s, right at the entry
//! threshold, does not flicker out of motion and stay a post): a jump of the vehicle's own position estimate (a GPS fix changing quality
//! shifts every obstacle in the world frame at once) or a fragment briefly looks like
//! motion, and a post taken for a moving obstacle makes the planner sweep it in time
//! and yield to it for nothing. The filter's own state is never clipped.
//!
//! A cluster whose hits lie on the surfaces the scan of 0.3 s before saw in the same
//! place (at least half of them, within 6 cm) and hardly any in the space that scan's
//! beams went through stands still ([`View::surface_at`]): the tracks it measures
//! (posts, blobs, walls) have their velocity set to zero and their motion restarts.
//! A static object seen from a moving car shows new parts of itself and hides others,
//! but never appears where the beams passed; an object moving faster than 0.2 m/s
//! leaves its surface. So the shifts of a centre that come from the view, not from
//! motion, make no velocity: a window onto a wall between nearer posts sliding along
//! it as the car moves, a cluster cut into other pieces than the scan before, a track
//! that took a neighbour's fragment, a wall's velocity along itself (which its faces'
//! normal motion cannot correct). In a field of BARN's posts these were reported as
//! moving in most runs, and the planner swept them in time.
//!
//! A measurement that matches no track but is centred inside a confirmed track's
//! circle is a fragment of that object (a partial view, a cluster split by beam
//! dropouts) and starts no new track.
//!
//! # What the planner gets
//!
//! Discs only: each [`TrackedObstacle`] holds the planner's own obstacle type
//! ([`crate::planner::Obstacle`], its `disc`), which goes to guidance and the planner
//! unchanged, with the tracker's diagnostics beside it. A wall segment
//! becomes a chain of circles ([`cover_segment`]) of radius
//! `r = max(wall_circle_min_radius, h + wall_circle_margin)`, h the wall's half
//! thickness estimate (half the spread of the points across the fitted line), centred on
//! the segment, both ends included, spaced by at most
//! `2 sqrt((r + r0)^2 - (h + r0)^2)` with r0 = `vehicle_radius`: then the circles grown
//! by r0 (what the planner checks the rear axle against) contain every point within
//! `h + r0` of the segment, i.e. every position where the vehicle's circle would touch
//! the wall. The condition only gets easier as r0 grows, so `vehicle_radius` must be a
//! lower bound of the planner's r_0 (plus margin); with 0 the circles cover the wall's
//! footprint itself. The fitted segments are also reported ([`WallSegment`]) for
//! plotting. A wall track keeps the latest segment associated with it (no map of the
//! parts seen before). Its velocity comes from the segment's normal motion over at
//! least 0.2 s (a line's motion along itself is not observable); the segments of one
//! cluster are one rigid body, so a cart's front and side give its whole velocity.
//! Walls slower than 0.3 m/s, or moving for less than `moving_confirm_s`, are reported
//! with zero velocity.
//!
//! A confirmed static track detected in at least `memory_min_hits` scans that the scan
//! could not have seen ([`View::sees`]: out of the field of view, beyond the range, or
//! behind a nearer return) is remembered, where it was, instead of missed while within
//! `memory_radius` of the vehicle (a local map). A confirmed moving track the scan could
//! not have seen goes on at its velocity (the filter's prediction, its motion held as
//! last measured) for up to `moving_memory_s` after its last measurement, within
//! `memory_radius`, instead of being missed: the walkers the car overtook are still
//! there, coming up behind it, when it turns back in or stops.
//!
//! Only obstacles whose nearest point is within `detection_radius` (the paper's 8 m)
//! of the vehicle's reference point (the rear axle centre, the pose's origin) are
//! reported; tracking goes on beyond it so that velocities have converged when an
//! obstacle enters the radius. Moving obstacles (a reported velocity that is not zero)
//! are reported out to `moving_detection_radius` (16 m): the car closes on them at the
//! sum of both speeds, and the planner needs them early enough to yield or swerve
//! (an obstacle walking head-on at 0.8 m/s entering 8 m leaves under 3 s).

mod cluster;
mod config;
mod detect;
mod fit;
mod frame;
mod seen;
mod track;

pub use cluster::cluster_points;
pub use config::PerceptionConfig;
pub(crate) use detect::distance_to_segment;
pub use detect::{
    CircleMeasurement, Detections, Hit, ObstacleKind, Seen, SegmentMeasurement, View,
    cover_segment, detect,
};
pub use fit::{CircleFit, LineFit, fit_circle, fit_line, split_and_merge};
pub use frame::{Beam, Pose2, Scan, ScanPoint, ValidScan, scan_points};
pub use seen::{CELL as SEEN_CELL, SeenSpace, SeenWindow, rectangle_seen};
pub use track::{Perception, PerceptionOutput, TrackedObstacle, WallSegment};

/// Why a scan, a pose or a configuration was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PerceptionError {
    /// A scan or pose field is NaN or infinite.
    #[error("{field} is not a finite number ({value})")]
    NonFinite { field: &'static str, value: f64 },
    /// angle_increment == 0 with more than one beam: every beam would point the same way.
    #[error("angle_increment is zero with {beams} beams")]
    ZeroAngleIncrement { beams: usize },
    /// range_min < 0 or range_max <= range_min.
    #[error("invalid range limits: range_min {range_min}, range_max {range_max}")]
    InvalidRangeLimits { range_min: f64, range_max: f64 },
    /// The number of ranges does not fit angle_increment: the beams would span more than
    /// one revolution.
    #[error(
        "{beams} ranges at an increment of {angle_increment} rad span {span} rad, more than one revolution"
    )]
    BeamCountMismatch {
        beams: usize,
        angle_increment: f64,
        span: f64,
    },
    /// A scan stamped at or before the previous one given to the tracker.
    #[error("scan stamp {stamp} is not after the previous scan's {previous}")]
    StampNotIncreasing { stamp: f64, previous: f64 },
    /// A configuration value out of its domain.
    #[error("configuration {field}: {message}")]
    InvalidConfig {
        field: &'static str,
        message: String,
    },
}

/// Checks that a value is finite.
pub(crate) fn check_finite(field: &'static str, value: f64) -> Result<(), PerceptionError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(PerceptionError::NonFinite { field, value })
    }
}
