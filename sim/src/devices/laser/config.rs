//! The laser scanner's configuration (`[laser]` in a scenario): the profile (LMS111,
//! LMS291) with its figures, the overrides, the mounting pose and the noise, with
//! the checks a scenario's `[laser]` gets.

use firmware_bridge::laser::MAX_BEAMS;
use serde::{Deserialize, Serialize};

use super::super::{FieldError, invalid};

/// The scanner model whose figures are the defaults.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LaserProfile {
    /// SICK LMS111: 270°, 0.5° steps (541 beams), 50 Hz, 0.5-20 m, sigma 12 mm.
    #[default]
    Lms111,
    /// SICK LMS291-style: 180°, 0.5° steps (361 beams, two interlaced 75 Hz sweeps:
    /// 37.5 Hz), 0.1-80 m, sigma 10 mm.
    Lms291,
}

/// The figures of a profile (or of a configuration, overrides applied).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaserSpec {
    /// Field of view, degrees, centred on the forward axis.
    pub fov_deg: f64,
    /// Angle between beams, degrees.
    pub resolution_deg: f64,
    /// Scans per second.
    pub rate_hz: f64,
    /// Metres.
    pub range_min: f64,
    pub range_max: f64,
    /// Standard deviation of the range noise, metres.
    pub range_noise_sigma: f64,
}

impl LaserSpec {
    /// Beams per scan: `fov / resolution + 1` (541 for 270° at 0.5°).
    pub fn beams(&self) -> usize {
        ((self.fov_deg / self.resolution_deg + 1e-6).floor() as usize).saturating_add(1)
    }

    /// Angle of the first beam, radians (the scan is symmetric about the forward axis).
    pub fn angle_min(&self) -> f64 {
        -((self.beams() - 1) as f64 * self.resolution_deg).to_radians() / 2.0
    }

    /// Seconds between scans.
    pub fn scan_time(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// Seconds between beams: the mirror sweeps 360° per scan period.
    pub fn time_increment(&self) -> f64 {
        self.scan_time() * self.resolution_deg / 360.0
    }
}

impl LaserProfile {
    pub fn spec(self) -> LaserSpec {
        match self {
            LaserProfile::Lms111 => LaserSpec {
                fov_deg: 270.0,
                resolution_deg: 0.5,
                rate_hz: 50.0,
                range_min: 0.5,
                range_max: 20.0,
                range_noise_sigma: 0.012,
            },
            LaserProfile::Lms291 => LaserSpec {
                fov_deg: 180.0,
                resolution_deg: 0.5,
                rate_hz: 37.5,
                range_min: 0.1,
                range_max: 80.0,
                range_noise_sigma: 0.010,
            },
        }
    }
}

/// The laser scanner's configuration (`[laser]` in a scenario). The scanner's figures
/// come from `profile`; each `Option` field overrides one of them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaserConfig {
    /// Mounting pose in the vehicle frame (x forward, y left of the rear axle), metres,
    /// and yaw, degrees counter-clockwise.
    pub mount_x: f64,
    pub mount_y: f64,
    pub mount_yaw_deg: f64,
    /// `"lms111"` (default) or `"lms291"`.
    pub profile: LaserProfile,
    /// Overrides of the profile's field of view (degrees, up to 360), resolution
    /// (degrees), scan rate (Hz), range limits (m) and range noise sigma (m, 0 = off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub resolution_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range_min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range_max: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range_noise_sigma: Option<f64>,
    /// Probability that a beam with a target returns no echo (NaN), 0 to 1.
    pub dropout_probability: f64,
    /// Intensity of a return from a post, a box and a wall (device units, >= 0).
    pub intensity_circle: f64,
    pub intensity_box: f64,
    pub intensity_wall: f64,
}

impl Default for LaserConfig {
    fn default() -> Self {
        let car = ugv_controller::car::PAPER_CAR;
        LaserConfig {
            mount_x: car.laser[0],
            mount_y: car.laser[1],
            mount_yaw_deg: car.laser_yaw_deg,
            profile: LaserProfile::Lms111,
            fov_deg: None,
            resolution_deg: None,
            rate_hz: None,
            range_min: None,
            range_max: None,
            range_noise_sigma: None,
            dropout_probability: 0.0,
            intensity_circle: 200.0,
            intensity_box: 150.0,
            intensity_wall: 100.0,
        }
    }
}

impl LaserConfig {
    /// The profile's figures with this configuration's overrides.
    pub fn spec(&self) -> LaserSpec {
        let p = self.profile.spec();
        LaserSpec {
            fov_deg: self.fov_deg.unwrap_or(p.fov_deg),
            resolution_deg: self.resolution_deg.unwrap_or(p.resolution_deg),
            rate_hz: self.rate_hz.unwrap_or(p.rate_hz),
            range_min: self.range_min.unwrap_or(p.range_min),
            range_max: self.range_max.unwrap_or(p.range_max),
            range_noise_sigma: self.range_noise_sigma.unwrap_or(p.range_noise_sigma),
        }
    }

    /// Every field checked: the mounting and the scanner's figures (the profile's, or
    /// the overrides) within their ranges (the table [`crate::scenario::ranges::LASER`],
    /// each range with its source), the range limits ordered, the beams within a frame.
    pub fn validate(&self) -> Result<(), FieldError> {
        let s = self.spec();
        // Before the ranges: an override beyond the profile's other limit is named
        // with the profile it collides with.
        if s.range_min >= s.range_max {
            let profile = format!("{:?}", self.profile).to_lowercase();
            let from = |field: &'static str, set: bool| {
                if set {
                    field.to_owned()
                } else {
                    format!("{field} of the {profile} profile")
                }
            };
            let field = if self.range_min.is_some() {
                "range_min"
            } else {
                "range_max"
            };
            return Err(invalid(
                field,
                format!(
                    "range_min {} ({}) must be below range_max {} ({})",
                    s.range_min,
                    from("range_min", self.range_min.is_some()),
                    s.range_max,
                    from("range_max", self.range_max.is_some()),
                ),
            ));
        }
        ugv_fields::check_bounds(self, crate::scenario::ranges::LASER)?;
        if s.resolution_deg > s.fov_deg {
            return Err(invalid(
                "resolution_deg",
                format!(
                    "{} exceeds the field of view {}",
                    s.resolution_deg, s.fov_deg
                ),
            ));
        }
        if s.beams() > MAX_BEAMS {
            return Err(invalid(
                "resolution_deg",
                format!(
                    "{} degrees over {} degrees gives {} beams, a frame holds at most {MAX_BEAMS}",
                    s.resolution_deg,
                    s.fov_deg,
                    s.beams()
                ),
            ));
        }
        Ok(())
    }
}
