//! The perception tuning (`Default` is the source of truth).

use serde::{Deserialize, Serialize};

use super::PerceptionError;

/// Perception parameters. Lengths in metres, angles in degrees, times in seconds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// Obstacles whose nearest point is farther than this from the vehicle's reference
    /// point are not reported (the paper: 8 m).
    pub detection_radius: f64,
    /// Moving obstacles (a reported velocity that is not zero) are reported out to this
    /// distance instead: the car closes on them faster, so it must see them earlier
    /// (the larger of the two applies).
    pub moving_detection_radius: f64,
    /// A static obstacle out of the laser's sight (outside its field of view, beyond
    /// its range, or behind a nearer return) is remembered, not missed, while it is
    /// within this of the vehicle's reference point (a local map), metres; 0: forget
    /// it as the paper does, after `delete_misses` scans.
    pub memory_radius: f64,
    /// Only a track detected in at least this many scans is remembered: a few hits (a
    /// fragment, spurious returns) are no evidence of an object to keep out of sight.
    pub memory_min_hits: u32,
    /// A moving obstacle out of the laser's sight (a walker the car passed, now behind
    /// it) goes on at its velocity for up to this long since it was last measured,
    /// seconds, within `memory_radius`, instead of being missed: a car that turns back
    /// in ahead of walkers it overtook, or stops, must know they are coming. 0: missed
    /// at once.
    pub moving_memory_s: f64,
    /// The scanner's range noise (1 sigma); LMS111: 12 mm.
    pub range_noise_sigma: f64,

    // Clustering.
    /// lambda of the adaptive breakpoint: the most grazing incidence angle (beam to
    /// surface) at which consecutive hits still join, degrees.
    pub breakpoint_lambda_deg: f64,
    /// k of the adaptive breakpoint: noise allowance in range-noise sigmas.
    pub breakpoint_noise_factor: f64,
    /// Consecutive dropout beams (NaN, below range_min) bridged inside a cluster.
    pub max_dropout_beams: usize,
    /// Clusters with fewer hits are discarded.
    pub min_points: usize,

    // Shapes.
    /// Smallest cluster that is fitted with a circle.
    pub circle_min_points: usize,
    /// Plausible post radii.
    pub circle_radius_min: f64,
    pub circle_radius_max: f64,
    /// Largest RMS geometric residual of a post's circle.
    pub circle_rms_max: f64,
    /// A circle is preferred to a line when line RMS > ratio * circle RMS.
    pub circle_line_ratio: f64,
    /// The largest standard deviation of a post's fitted radius (from the fit's own
    /// covariance), metres. Ten noisy hits on a flat face 18 m away (a parked cart's
    /// end) can fit a circle 3-5 m wide that explains them a little better than the
    /// line, with a radius uncertain by a metre; a real post's radius is pinned to a
    /// few centimetres (the paper's 3 m circle seen over a 30 degree arc: 4-6 cm).
    pub circle_radius_sigma_max: f64,
    /// Smallest polyline piece that is a wall segment.
    pub line_min_points: usize,
    pub segment_min_length: f64,
    /// Iterative end-point fit: split where a point is farther than this from the chord.
    pub split_distance: f64,
    /// Smallest radius of a blob (an unknown object of a few hits).
    pub blob_min_radius: f64,

    // Walls as circle chains.
    /// Smallest radius of a wall's circles.
    pub wall_circle_min_radius: f64,
    /// Radius above the wall's half thickness, so a finite spacing covers it.
    pub wall_circle_margin: f64,
    /// The planner's vehicle radius r_0 (plus its safety margin), used to space the
    /// circles; 0 makes the circles cover the wall's footprint itself.
    pub vehicle_radius: f64,
    /// Wall segment association: largest direction change, degrees.
    pub wall_angle_gate_deg: f64,
    /// Wall segment association: largest distance of the new segment's midpoint from
    /// the old line.
    pub wall_offset_gate: f64,
    /// Wall segment association: largest gap between old and new extents along the line.
    pub wall_gap_gate: f64,

    // Tracking.
    /// M: hits needed within the first N scans of a track to confirm it.
    pub birth_hits: u32,
    /// N (at most 32).
    pub birth_window: u32,
    /// K: consecutive misses that delete a track.
    pub delete_misses: u32,
    /// Association gate: Mahalanobis distance squared (2 degrees of freedom; 13.8 is
    /// 99.9%).
    pub gate_chi2: f64,
    /// Association gate: always accepted below this Euclidean distance.
    pub gate_min_distance: f64,
    /// Association gate: never accepted beyond this Euclidean distance.
    pub gate_max_distance: f64,
    /// Spectral density of the white-noise acceleration, m^2/s^3.
    pub accel_noise: f64,
    /// Floor of the measured centre's standard deviation per axis.
    pub position_sigma_min: f64,
    /// Standard deviation of a new track's velocity per axis, m/s.
    pub initial_velocity_sigma: f64,
    /// Random walk of a tracked radius, m per sqrt(s).
    pub radius_process_sigma: f64,
    /// Speeds below this are reported as zero, m/s.
    pub velocity_dead_band: f64,
    /// Velocities with v' P_vv^-1 v below this are reported as zero (0 disables).
    pub velocity_significance_chi2: f64,
    /// Once a velocity has passed the significance test, it counts as significant
    /// until v' P_vv^-1 v falls below this (at most `velocity_significance_chi2`):
    /// a walker at 0.5 m/s, whose estimate's own covariance puts it right at the
    /// entry threshold, must not flicker out of motion every few scans.
    pub velocity_hold_chi2: f64,
    /// A velocity is reported only once it has passed the dead band and the
    /// significance test and held them (the hold threshold) on every scan for this
    /// long, seconds: a jump of the vehicle's own position (a GPS fix changing
    /// quality) or a fragment of an object briefly looks like motion and must not make
    /// a post a moving obstacle.
    pub moving_confirm_s: f64,
}

impl Default for PerceptionConfig {
    fn default() -> Self {
        PerceptionConfig {
            detection_radius: 8.0,
            moving_detection_radius: 16.0,
            memory_radius: 25.0,
            memory_min_hits: 10,
            moving_memory_s: 5.0,
            range_noise_sigma: 0.012,
            breakpoint_lambda_deg: 10.0,
            breakpoint_noise_factor: 3.0,
            max_dropout_beams: 2,
            min_points: 2,
            circle_min_points: 6,
            circle_radius_min: 0.03,
            circle_radius_max: 5.0,
            circle_rms_max: 0.05,
            circle_line_ratio: 1.5,
            circle_radius_sigma_max: 0.25,
            line_min_points: 5,
            segment_min_length: 0.5,
            split_distance: 0.1,
            blob_min_radius: 0.1,
            wall_circle_min_radius: 0.25,
            wall_circle_margin: 0.05,
            vehicle_radius: 2.0,
            wall_angle_gate_deg: 15.0,
            wall_offset_gate: 0.5,
            wall_gap_gate: 1.0,
            birth_hits: 3,
            birth_window: 5,
            delete_misses: 10,
            gate_chi2: 13.8,
            gate_min_distance: 0.5,
            gate_max_distance: 3.0,
            accel_noise: 0.25,
            position_sigma_min: 0.02,
            initial_velocity_sigma: 3.0,
            radius_process_sigma: 0.02,
            velocity_dead_band: 0.1,
            velocity_significance_chi2: 9.21,
            velocity_hold_chi2: 4.61,
            moving_confirm_s: 0.5,
        }
    }
}

/// The largest magnitude any tuning value may have.
const PLAUSIBLE_LIMIT: f64 = 10_000.0;

fn invalid(field: &'static str, message: impl Into<String>) -> PerceptionError {
    PerceptionError::InvalidConfig {
        field,
        message: message.into(),
    }
}

fn positive(field: &'static str, v: f64) -> Result<(), PerceptionError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be positive and finite, got {v}"),
        ))
    }
}

fn non_negative(field: &'static str, v: f64) -> Result<(), PerceptionError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be non-negative and finite, got {v}"),
        ))
    }
}

impl PerceptionConfig {
    /// Checks every field's domain.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        self.validate_ranges()?;
        self.validate_segmentation()?;
        self.validate_tracking()
    }

    /// The detection and memory radii, and every tuning value's magnitude.
    fn validate_ranges(&self) -> Result<(), PerceptionError> {
        positive("detection_radius", self.detection_radius)?;
        positive("moving_detection_radius", self.moving_detection_radius)?;
        // No tuning value is anywhere near this: larger ones are typing errors (and
        // beyond f32 they turn into infinities in the laser's single precision).
        for (field, v) in self.tuning_values() {
            if v.abs() > PLAUSIBLE_LIMIT {
                return Err(invalid(
                    field,
                    format!("must be at most {PLAUSIBLE_LIMIT} in magnitude, got {v}"),
                ));
            }
        }
        // The longest-range 2D scanners reach 80 m (LMS291).
        non_negative("memory_radius", self.memory_radius)?;
        for (field, v) in [
            ("detection_radius", self.detection_radius),
            ("moving_detection_radius", self.moving_detection_radius),
            ("memory_radius", self.memory_radius),
        ] {
            if v > 100.0 {
                return Err(invalid(field, format!("must be at most 100 m, got {v}")));
            }
        }
        non_negative("moving_confirm_s", self.moving_confirm_s)?;
        non_negative("moving_memory_s", self.moving_memory_s)?;
        Ok(())
    }

    /// The tuning values whose magnitude [`PLAUSIBLE_LIMIT`] bounds, by field.
    fn tuning_values(&self) -> [(&'static str, f64); 31] {
        [
            ("detection_radius", self.detection_radius),
            ("moving_detection_radius", self.moving_detection_radius),
            ("range_noise_sigma", self.range_noise_sigma),
            ("breakpoint_lambda_deg", self.breakpoint_lambda_deg),
            ("breakpoint_noise_factor", self.breakpoint_noise_factor),
            ("circle_radius_min", self.circle_radius_min),
            ("circle_radius_max", self.circle_radius_max),
            ("circle_rms_max", self.circle_rms_max),
            ("circle_line_ratio", self.circle_line_ratio),
            ("circle_radius_sigma_max", self.circle_radius_sigma_max),
            ("segment_min_length", self.segment_min_length),
            ("split_distance", self.split_distance),
            ("blob_min_radius", self.blob_min_radius),
            ("wall_circle_min_radius", self.wall_circle_min_radius),
            ("wall_circle_margin", self.wall_circle_margin),
            ("vehicle_radius", self.vehicle_radius),
            ("wall_angle_gate_deg", self.wall_angle_gate_deg),
            ("wall_offset_gate", self.wall_offset_gate),
            ("wall_gap_gate", self.wall_gap_gate),
            ("gate_chi2", self.gate_chi2),
            ("gate_min_distance", self.gate_min_distance),
            ("gate_max_distance", self.gate_max_distance),
            ("accel_noise", self.accel_noise),
            ("position_sigma_min", self.position_sigma_min),
            ("initial_velocity_sigma", self.initial_velocity_sigma),
            ("radius_process_sigma", self.radius_process_sigma),
            ("velocity_dead_band", self.velocity_dead_band),
            (
                "velocity_significance_chi2",
                self.velocity_significance_chi2,
            ),
            ("velocity_hold_chi2", self.velocity_hold_chi2),
            ("moving_confirm_s", self.moving_confirm_s),
            ("moving_memory_s", self.moving_memory_s),
        ]
    }

    /// The segmentation: range noise, breakpoints, circle and line fits, walls.
    fn validate_segmentation(&self) -> Result<(), PerceptionError> {
        positive("range_noise_sigma", self.range_noise_sigma)?;
        if !(self.breakpoint_lambda_deg > 0.0 && self.breakpoint_lambda_deg < 90.0) {
            return Err(invalid(
                "breakpoint_lambda_deg",
                format!("must be in (0, 90), got {}", self.breakpoint_lambda_deg),
            ));
        }
        non_negative("breakpoint_noise_factor", self.breakpoint_noise_factor)?;
        if self.min_points < 1 {
            return Err(invalid("min_points", "must be at least 1"));
        }
        if self.circle_min_points < 3 {
            return Err(invalid("circle_min_points", "must be at least 3"));
        }
        positive("circle_radius_min", self.circle_radius_min)?;
        positive("circle_radius_max", self.circle_radius_max)?;
        if self.circle_radius_max <= self.circle_radius_min {
            return Err(invalid(
                "circle_radius_max",
                "must be larger than circle_radius_min",
            ));
        }
        positive("circle_rms_max", self.circle_rms_max)?;
        positive("circle_line_ratio", self.circle_line_ratio)?;
        positive("circle_radius_sigma_max", self.circle_radius_sigma_max)?;
        if self.line_min_points < 2 {
            return Err(invalid("line_min_points", "must be at least 2"));
        }
        non_negative("segment_min_length", self.segment_min_length)?;
        positive("split_distance", self.split_distance)?;
        positive("blob_min_radius", self.blob_min_radius)?;
        positive("wall_circle_min_radius", self.wall_circle_min_radius)?;
        positive("wall_circle_margin", self.wall_circle_margin)?;
        non_negative("vehicle_radius", self.vehicle_radius)?;
        positive("wall_angle_gate_deg", self.wall_angle_gate_deg)?;
        positive("wall_offset_gate", self.wall_offset_gate)?;
        non_negative("wall_gap_gate", self.wall_gap_gate)?;
        Ok(())
    }

    /// The tracker: births and deletions, gating, the motion model and the velocity
    /// tests.
    fn validate_tracking(&self) -> Result<(), PerceptionError> {
        if self.birth_window < 1 || self.birth_window > 32 {
            return Err(invalid(
                "birth_window",
                format!("must be in 1..=32, got {}", self.birth_window),
            ));
        }
        if self.birth_hits < 1 || self.birth_hits > self.birth_window {
            return Err(invalid(
                "birth_hits",
                format!(
                    "must be in 1..=birth_window ({}), got {}",
                    self.birth_window, self.birth_hits
                ),
            ));
        }
        if self.delete_misses < 1 {
            return Err(invalid("delete_misses", "must be at least 1"));
        }
        positive("gate_chi2", self.gate_chi2)?;
        non_negative("gate_min_distance", self.gate_min_distance)?;
        positive("gate_max_distance", self.gate_max_distance)?;
        positive("accel_noise", self.accel_noise)?;
        positive("position_sigma_min", self.position_sigma_min)?;
        positive("initial_velocity_sigma", self.initial_velocity_sigma)?;
        non_negative("radius_process_sigma", self.radius_process_sigma)?;
        non_negative("velocity_dead_band", self.velocity_dead_band)?;
        non_negative(
            "velocity_significance_chi2",
            self.velocity_significance_chi2,
        )?;
        non_negative("velocity_hold_chi2", self.velocity_hold_chi2)?;
        if self.velocity_hold_chi2 > self.velocity_significance_chi2 {
            return Err(invalid(
                "velocity_hold_chi2",
                format!(
                    "must be at most velocity_significance_chi2 ({}), got {}",
                    self.velocity_significance_chi2, self.velocity_hold_chi2
                ),
            ));
        }
        Ok(())
    }
}
