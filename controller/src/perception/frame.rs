//! Scans, poses and the laser -> vehicle -> world transformation.

use std::f64::consts::TAU;
use std::ops::Deref;

use firmware_bridge::laser::LaserFrame;
use nalgebra::{Isometry2, Point2, Vector2};
use serde::{Deserialize, Serialize};

use super::{PerceptionError, check_finite};

/// A planar pose: position and yaw (radians, counter-clockwise). As the laser's mount it
/// is in the vehicle frame; as the vehicle's pose (rear axle, heading theta) it is in
/// the world frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
}

impl Pose2 {
    pub fn new(x: f64, y: f64, yaw: f64) -> Self {
        Pose2 { x, y, yaw }
    }

    /// The rigid transformation from this pose's frame into its parent frame.
    pub fn isometry(&self) -> Isometry2<f64> {
        Isometry2::new(Vector2::new(self.x, self.y), self.yaw)
    }

    /// `P_parent = R(yaw) P_child + (x, y)`: the paper's `W_P = W_R R_P + W_P_ORG`.
    pub fn transform(&self, p: [f64; 2]) -> [f64; 2] {
        let q = self.isometry() * Point2::new(p[0], p[1]);
        [q.x, q.y]
    }

    /// The pose of a frame given in this one (`inner`), in this one's parent: for the
    /// vehicle pose and the laser mount, the laser's pose in the world.
    pub fn compose(&self, inner: &Pose2) -> Pose2 {
        let [x, y] = self.transform([inner.x, inner.y]);
        Pose2 {
            x,
            y,
            yaw: self.yaw + inner.yaw,
        }
    }

    pub(crate) fn validate(
        &self,
        x: &'static str,
        y: &'static str,
        yaw: &'static str,
    ) -> Result<(), PerceptionError> {
        check_finite(x, self.x)?;
        check_finite(y, self.y)?;
        check_finite(yaw, self.yaw)
    }
}

/// One sweep of the scanner (ROS LaserScan semantics, without intensities), as given:
/// [`Scan::validate`] makes it the [`ValidScan`] perception takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scan<'a> {
    /// Acquisition time, seconds.
    pub stamp: f64,
    /// Angle of beam 0, radians CCW from the scanner's forward axis.
    pub angle_min: f64,
    /// Angle between consecutive beams, radians (negative for a clockwise sweep).
    pub angle_increment: f64,
    /// Valid range interval, metres.
    pub range_min: f64,
    pub range_max: f64,
    /// One range per beam, metres; +inf: no return; NaN: dropout.
    pub ranges: &'a [f32],
}

/// What one beam measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Beam {
    /// A return at this range.
    Hit(f64),
    /// No return within range_max (+inf or above range_max): free space along the beam.
    NoReturn,
    /// No information (NaN, negative, below range_min).
    Dropout,
}

/// A scan whose header is finite and fits its ranges ([`Scan::validate`]): what
/// perception and the controller take, so that a scan is checked once, where it enters
/// (a laser frame: [`ValidScan::from_frame`]), and never again. It reads as the
/// [`Scan`] it holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidScan<'a>(Scan<'a>);

impl<'a> Deref for ValidScan<'a> {
    type Target = Scan<'a>;

    fn deref(&self) -> &Scan<'a> {
        &self.0
    }
}

impl<'a> ValidScan<'a> {
    /// A laser frame (already checked as a frame by its port) as perception reads it,
    /// stamped with the controller's time `stamp`, checked as a scan.
    pub fn from_frame(frame: &'a LaserFrame, stamp: f64) -> Result<Self, PerceptionError> {
        Scan {
            stamp,
            angle_min: f64::from(frame.angle_min),
            angle_increment: f64::from(frame.angle_increment),
            range_min: f64::from(frame.range_min),
            range_max: f64::from(frame.range_max),
            ranges: frame.ranges(),
        }
        .validate()
    }
}

impl<'a> Scan<'a> {
    /// Checks the scan's header against its ranges: the scan, valid.
    pub fn validate(&self) -> Result<ValidScan<'a>, PerceptionError> {
        check_finite("stamp", self.stamp)?;
        check_finite("angle_min", self.angle_min)?;
        check_finite("angle_increment", self.angle_increment)?;
        check_finite("range_min", self.range_min)?;
        check_finite("range_max", self.range_max)?;
        if self.range_min < 0.0 || self.range_max <= self.range_min {
            return Err(PerceptionError::InvalidRangeLimits {
                range_min: self.range_min,
                range_max: self.range_max,
            });
        }
        let beams = self.ranges.len();
        if beams > 1 {
            if self.angle_increment == 0.0 {
                return Err(PerceptionError::ZeroAngleIncrement { beams });
            }
            // Beams 0 and n-1 are (n - 1) increments apart; a full revolution of n beams
            // spans TAU - increment. Allow rounding of the increment.
            let span = (beams - 1) as f64 * self.angle_increment.abs();
            if span > TAU * (1.0 + 1e-9) {
                return Err(PerceptionError::BeamCountMismatch {
                    beams,
                    angle_increment: self.angle_increment,
                    span,
                });
            }
        }
        Ok(ValidScan(*self))
    }

    /// Beam i's angle in the laser frame.
    pub fn beam_angle(&self, i: usize) -> f64 {
        self.angle_min + i as f64 * self.angle_increment
    }

    /// What beam i measured (Dropout when out of bounds).
    pub fn beam(&self, i: usize) -> Beam {
        match self.ranges.get(i) {
            Some(&r) => {
                let r = f64::from(r);
                if r.is_nan() || r < self.range_min {
                    Beam::Dropout
                } else if r > self.range_max {
                    // Includes +inf.
                    Beam::NoReturn
                } else {
                    Beam::Hit(r)
                }
            }
            None => Beam::Dropout,
        }
    }
}

/// A hit in the three frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScanPoint {
    /// Beam index in the scan.
    pub beam: usize,
    /// Range, metres.
    pub range: f64,
    /// Beam angle in the laser frame, radians.
    pub angle: f64,
    /// Laser-frame point.
    pub laser: [f64; 2],
    /// Vehicle-frame point.
    pub vehicle: [f64; 2],
    /// World-frame point.
    pub world: [f64; 2],
}

/// The hits of a scan in beam order, transformed with the laser's mount (vehicle frame)
/// and the vehicle's pose at the scan's stamp (world frame); refused when the mount or
/// the pose is not finite.
pub fn scan_points(
    scan: &ValidScan<'_>,
    mount: &Pose2,
    pose: &Pose2,
) -> Result<Vec<ScanPoint>, PerceptionError> {
    scan_points_with(scan, mount, pose, None)
}

/// Each beam's direction in the laser frame, `(cos, sin)` of [`Scan::beam_angle`],
/// kept for as long as the scans keep their layout (a scanner's never changes): the
/// same values [`scan_points`] takes per hit, computed once instead of per scan.
#[derive(Clone, Debug, Default)]
pub struct BeamDirections {
    angle_min: f64,
    angle_increment: f64,
    directions: Vec<(f64, f64)>,
}

impl BeamDirections {
    /// The directions of `scan`'s beams, computed again if its layout differs.
    fn of(&mut self, scan: &Scan<'_>) -> &[(f64, f64)] {
        let same = self.angle_min.to_bits() == scan.angle_min.to_bits()
            && self.angle_increment.to_bits() == scan.angle_increment.to_bits()
            && self.directions.len() == scan.ranges.len();
        if !same {
            self.angle_min = scan.angle_min;
            self.angle_increment = scan.angle_increment;
            self.directions = (0..scan.ranges.len())
                .map(|beam| direction(scan.beam_angle(beam)))
                .collect();
        }
        &self.directions
    }
}

fn direction(angle: f64) -> (f64, f64) {
    (angle.cos(), angle.sin())
}

/// [`scan_points`] with the beams' directions kept in `directions` (None: computed
/// for each hit).
pub(super) fn scan_points_with(
    scan: &ValidScan<'_>,
    mount: &Pose2,
    pose: &Pose2,
    directions: Option<&mut BeamDirections>,
) -> Result<Vec<ScanPoint>, PerceptionError> {
    mount.validate("mount.x", "mount.y", "mount.yaw")?;
    pose.validate("pose.x", "pose.y", "pose.yaw")?;
    let to_vehicle = mount.isometry();
    let to_world = pose.isometry();
    let kept = directions.map(|d| d.of(scan));
    let mut points = Vec::with_capacity(scan.ranges.len());
    for beam in 0..scan.ranges.len() {
        if let Beam::Hit(range) = scan.beam(beam) {
            let angle = scan.beam_angle(beam);
            let (c, s) = match kept.and_then(|k| k.get(beam)) {
                Some(&d) => d,
                None => direction(angle),
            };
            let laser = Point2::new(range * c, range * s);
            let vehicle = to_vehicle * laser;
            let world = to_world * vehicle;
            points.push(ScanPoint {
                beam,
                range,
                angle,
                laser: [laser.x, laser.y],
                vehicle: [vehicle.x, vehicle.y],
                world: [world.x, world.y],
            });
        }
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_equals_two_transforms() {
        let pose = Pose2::new(3.0, -1.0, 0.7);
        let mount = Pose2::new(1.2, 0.4, -0.3);
        let p = [2.0, 0.5];
        let a = pose.transform(mount.transform(p));
        let b = pose.compose(&mount).transform(p);
        assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12);
    }

    #[test]
    fn kept_beam_directions_give_the_points_computed_per_hit() {
        let ranges: Vec<f32> = (0..541).map(|k| 2.0 + (k % 7) as f32).collect();
        let mount = Pose2::new(1.2, 0.1, 0.05);
        let pose = Pose2::new(3.0, -1.0, 0.7);
        let mut kept = BeamDirections::default();
        // The second layout makes the kept directions be computed again.
        for angle_min in [-2.356, -2.356, -1.5, -1.5] {
            let scan = Scan {
                stamp: 0.0,
                angle_min,
                angle_increment: 0.5f64.to_radians(),
                range_min: 0.05,
                range_max: 20.0,
                ranges: &ranges,
            };
            let scan = scan.validate().expect("valid");
            let fresh = scan_points(&scan, &mount, &pose).expect("finite");
            let with = scan_points_with(&scan, &mount, &pose, Some(&mut kept)).expect("finite");
            assert_eq!(fresh, with, "angle_min {angle_min}");
        }
    }

    #[test]
    fn beam_classes() {
        let ranges = [1.0f32, f32::INFINITY, f32::NAN, 0.01, 30.0, -1.0];
        let scan = Scan {
            stamp: 0.0,
            angle_min: 0.0,
            angle_increment: 0.01,
            range_min: 0.05,
            range_max: 20.0,
            ranges: &ranges,
        };
        assert_eq!(scan.beam(0), Beam::Hit(1.0));
        assert_eq!(scan.beam(1), Beam::NoReturn);
        assert_eq!(scan.beam(2), Beam::Dropout);
        assert_eq!(scan.beam(3), Beam::Dropout);
        assert_eq!(scan.beam(4), Beam::NoReturn);
        assert_eq!(scan.beam(5), Beam::Dropout);
        assert_eq!(scan.beam(6), Beam::Dropout);
    }
}
