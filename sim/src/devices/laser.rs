//! The simulated laser scanner: SICK LMS111-like by default, an LMS291-style 180°
//! profile on request, ray-cast in the rapier2d world from its mounting pose and
//! delivered as a [`LaserFrame`] (ROS LaserScan semantics; see `firmware_bridge::laser`).
//!
//! # Geometry
//!
//! Beam `i` of `n` points at `angle_min + i * step` from the scanner's forward axis,
//! counter-clockwise, symmetric about it (`angle_min = -(n - 1) * step / 2`). The
//! scanner sits at `(mount_x, mount_y)` in the vehicle frame (x forward, y left of the
//! rear axle) and is yawed by `mount_yaw_deg`, so beam `i` travels in the world at
//! `theta + mount_yaw + angle_i`.
//!
//! # Ranges
//!
//! The true range is the first hit of the ray within `range_max`. Then:
//! - no hit within `range_max`: `f32::INFINITY` (no return);
//! - a hit closer than `range_min` (too close for the scanner to resolve; also a
//!   scanner mounted inside an obstacle): `f32::INFINITY` as well, i.e. no return;
//! - with probability `dropout_probability`: `f32::NAN` (no echo although something
//!   is there);
//! - otherwise the true range plus zero-mean Gaussian noise of `range_noise_sigma`,
//!   clamped to `[range_min, range_max]`.
//!
//! Intensities are a constant per obstacle kind (`intensity_circle`, `intensity_box`,
//! `intensity_wall`; 0 for beams without a measurement).
//!
//! The scan is instantaneous: every beam is cast at the pose and world time given,
//! while the frame's `time_increment` says when a real scanner would have taken it
//! (no motion skew is simulated).
//!
//! # Determinism
//!
//! The noise stream is ChaCha8 seeded from the scenario's `sim.seed` mixed with
//! [`NOISE_SOURCE`], so it differs from other devices' streams and is identical for the
//! same seed. Every beam draws the same number of random numbers whatever it hits, so
//! the stream stays aligned across scans and scenes.

use firmware_bridge::laser::{LASER_FRAME_VERSION, LaserFrame, MAX_BEAMS};
use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::FieldError;
use crate::scenario::{Obstacle, Scenario};
use crate::world::World;

/// The per-source constant the laser's noise seed is derived with (ASCII "LASER").
pub const NOISE_SOURCE: u64 = 0x4C41_5345_5200_0001;

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

fn finite(field: &'static str, v: f64) -> Result<(), FieldError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(FieldError::new(
            field,
            format!("{v} is not a finite number"),
        ))
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

    pub fn validate(&self) -> Result<(), FieldError> {
        for (field, v) in [
            ("mount_x", self.mount_x),
            ("mount_y", self.mount_y),
            ("mount_yaw_deg", self.mount_yaw_deg),
        ] {
            finite(field, v)?;
        }
        // The scanner sits on the car; a yaw is at most a turn either way.
        for (field, v, limit, unit) in [
            ("mount_x", self.mount_x, 20.0, "m of the rear axle"),
            ("mount_y", self.mount_y, 20.0, "m of the rear axle"),
            ("mount_yaw_deg", self.mount_yaw_deg, 360.0, "degrees"),
        ] {
            if v.abs() > limit {
                return Err(FieldError::new(
                    field,
                    format!("must be within [-{limit}, {limit}] {unit}, is {v}"),
                ));
            }
        }
        let s = self.spec();
        let profile = format!("{:?}", self.profile).to_lowercase();
        let from = |field: &'static str, set: bool| {
            if set {
                field.to_owned()
            } else {
                format!("{field} of the {profile} profile")
            }
        };
        finite("fov_deg", s.fov_deg)?;
        if !(s.fov_deg > 0.0 && s.fov_deg <= 360.0) {
            return Err(FieldError::new(
                "fov_deg",
                format!("must be in (0, 360] degrees, is {}", s.fov_deg),
            ));
        }
        finite("resolution_deg", s.resolution_deg)?;
        if s.resolution_deg <= 0.0 {
            return Err(FieldError::new(
                "resolution_deg",
                format!("must be positive, is {}", s.resolution_deg),
            ));
        }
        if s.resolution_deg > s.fov_deg {
            return Err(FieldError::new(
                "resolution_deg",
                format!(
                    "{} exceeds the field of view {}",
                    s.resolution_deg, s.fov_deg
                ),
            ));
        }
        if s.beams() > MAX_BEAMS {
            return Err(FieldError::new(
                "resolution_deg",
                format!(
                    "{} degrees over {} degrees gives {} beams, a frame holds at most {MAX_BEAMS}",
                    s.resolution_deg,
                    s.fov_deg,
                    s.beams()
                ),
            ));
        }
        finite("rate_hz", s.rate_hz)?;
        if !(s.rate_hz > 0.0 && s.rate_hz <= 1000.0) {
            return Err(FieldError::new(
                "rate_hz",
                format!("must be in (0, 1000] Hz, is {}", s.rate_hz),
            ));
        }
        finite("range_min", s.range_min)?;
        finite("range_max", s.range_max)?;
        if s.range_min < 0.0 {
            return Err(FieldError::new(
                "range_min",
                format!("must not be negative, is {}", s.range_min),
            ));
        }
        if s.range_min >= s.range_max {
            let field = if self.range_min.is_some() {
                "range_min"
            } else {
                "range_max"
            };
            return Err(FieldError::new(
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
        if s.range_max > 1000.0 {
            return Err(FieldError::new(
                "range_max",
                format!("must be at most 1000 m, is {}", s.range_max),
            ));
        }
        finite("range_noise_sigma", s.range_noise_sigma)?;
        if s.range_noise_sigma < 0.0 {
            return Err(FieldError::new(
                "range_noise_sigma",
                format!("must not be negative, is {}", s.range_noise_sigma),
            ));
        }
        if !(0.0..=1.0).contains(&self.dropout_probability) {
            return Err(FieldError::new(
                "dropout_probability",
                format!("must be within [0, 1], is {}", self.dropout_probability),
            ));
        }
        for (field, v) in [
            ("intensity_circle", self.intensity_circle),
            ("intensity_box", self.intensity_box),
            ("intensity_wall", self.intensity_wall),
        ] {
            finite(field, v)?;
            if v < 0.0 || v > f64::from(f32::MAX) {
                return Err(FieldError::new(
                    field,
                    format!("must be within [0, f32::MAX], is {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// Why a laser device could not be built.
#[derive(Debug, thiserror::Error)]
pub enum LaserDeviceError {
    #[error("laser.{field}: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
}

impl From<FieldError> for LaserDeviceError {
    fn from(e: FieldError) -> Self {
        LaserDeviceError::Config {
            field: e.field,
            message: e.message,
        }
    }
}

/// The noise seed of the laser for a scenario seed: SplitMix64 of the seed mixed with
/// [`NOISE_SOURCE`], so that devices sharing `sim.seed` get unrelated streams.
pub fn noise_seed(sim_seed: u64) -> u64 {
    fn splitmix64(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    splitmix64(sim_seed ^ splitmix64(NOISE_SOURCE))
}

/// Nanoseconds since the UNIX epoch of `epoch_s + t` (both seconds), saturating.
fn unix_ns(epoch_ns: u64, t: f64) -> u64 {
    let dt = (t * 1e9).round();
    if dt >= 0.0 {
        epoch_ns.saturating_add(dt.min(u64::MAX as f64) as u64)
    } else {
        epoch_ns.saturating_sub((-dt).min(u64::MAX as f64) as u64)
    }
}

/// A simulated laser scanner: turns the world and the vehicle's pose into frames.
#[derive(Debug)]
pub struct LaserDevice {
    config: LaserConfig,
    spec: LaserSpec,
    /// Intensity of a return from obstacle `i` of the scenario.
    intensity: Vec<f32>,
    rng: ChaCha8Rng,
    epoch_ns: u64,
    sequence: u64,
    /// Beam angles relative to the forward axis, radians.
    angles: Vec<f64>,
}

impl LaserDevice {
    /// A scanner configured by `config`, in a world of `obstacles` (for the intensity of
    /// each), noise seeded from `sim_seed`, stamping frames from `epoch_ns` (UTC
    /// nanoseconds since the UNIX epoch at simulated time 0).
    pub fn new(
        config: &LaserConfig,
        obstacles: &[Obstacle],
        sim_seed: u64,
        epoch_ns: u64,
    ) -> Result<LaserDevice, LaserDeviceError> {
        config.validate()?;
        let spec = config.spec();
        let intensity = obstacles
            .iter()
            .map(|o| match o {
                Obstacle::Circle { .. } => config.intensity_circle,
                Obstacle::Box { .. } => config.intensity_box,
                Obstacle::Wall { .. } => config.intensity_wall,
            } as f32)
            .collect();
        let step = spec.resolution_deg.to_radians();
        let angles = (0..spec.beams())
            .map(|i| spec.angle_min() + i as f64 * step)
            .collect();
        Ok(LaserDevice {
            config: config.clone(),
            spec,
            intensity,
            rng: ChaCha8Rng::seed_from_u64(noise_seed(sim_seed)),
            epoch_ns,
            sequence: 0,
            angles,
        })
    }

    /// The scanner of a scenario: its `[laser]`, obstacles, `sim.seed` and `sim.epoch`.
    pub fn from_scenario(scenario: &Scenario) -> Result<LaserDevice, LaserDeviceError> {
        let epoch_ns = scenario.sim.epoch.unix_ns();
        LaserDevice::new(
            &scenario.laser,
            &scenario.obstacles,
            scenario.sim.seed,
            epoch_ns,
        )
    }

    /// The effective figures (profile plus overrides).
    pub fn spec(&self) -> &LaserSpec {
        &self.spec
    }

    /// Seconds between scans.
    pub fn period(&self) -> f64 {
        self.spec.scan_time()
    }

    /// The sequence number the next frame gets.
    pub fn next_sequence(&self) -> u64 {
        self.sequence
    }

    /// The scanner's position and forward direction in the world for a vehicle pose
    /// (rear axle `x`, `y`, heading `theta`, radians).
    pub fn scanner_pose(&self, x: f64, y: f64, theta: f64) -> (f64, f64, f64) {
        let (s, c) = theta.sin_cos();
        let (mx, my) = (self.config.mount_x, self.config.mount_y);
        (
            x + mx * c - my * s,
            y + mx * s + my * c,
            theta + self.config.mount_yaw_deg.to_radians(),
        )
    }

    /// One scan at simulated time `t` (the world must already be at `t`: see
    /// [`World::set_time`]) from the vehicle pose (rear axle `x`, `y`, heading `theta`).
    pub fn scan(&mut self, world: &World, t: f64, x: f64, y: f64, theta: f64) -> LaserFrame {
        let mut frame = LaserFrame::default();
        self.scan_into(world, t, x, y, theta, &mut frame);
        frame
    }

    /// [`LaserDevice::scan`] into an existing frame (no 8.7 kB copy).
    pub fn scan_into(
        &mut self,
        world: &World,
        t: f64,
        x: f64,
        y: f64,
        theta: f64,
        frame: &mut LaserFrame,
    ) {
        let (sx, sy, heading) = self.scanner_pose(x, y, theta);
        let s = &self.spec;
        let n = self.angles.len();
        frame.version = LASER_FRAME_VERSION;
        frame.count = n as u32;
        frame.sequence = self.sequence;
        frame.stamp_ns = unix_ns(self.epoch_ns, t);
        frame.angle_min = s.angle_min() as f32;
        frame.angle_increment = s.resolution_deg.to_radians() as f32;
        frame.time_increment = s.time_increment() as f32;
        frame.scan_time = s.scan_time() as f32;
        frame.range_min = s.range_min as f32;
        frame.range_max = s.range_max as f32;
        let p_drop = self.config.dropout_probability;
        for (i, angle) in self.angles.iter().enumerate() {
            // Always two draws per beam, whatever it hits.
            let noise: f64 = self.rng.sample(StandardNormal);
            let drop: f64 = self.rng.random();
            let (range, intensity) = match world.cast_ray(sx, sy, heading + angle, s.range_max) {
                Some((obstacle, r)) if r >= s.range_min => {
                    if drop < p_drop {
                        (f32::NAN, 0.0)
                    } else {
                        let measured =
                            (r + noise * s.range_noise_sigma).clamp(s.range_min, s.range_max);
                        (
                            measured as f32,
                            self.intensity.get(obstacle).copied().unwrap_or(0.0),
                        )
                    }
                }
                // Nothing within range_max, or closer than range_min: no return.
                _ => (f32::INFINITY, 0.0),
            };
            frame.ranges[i] = range;
            frame.intensities[i] = intensity;
        }
        frame.ranges[n..].fill(0.0);
        frame.intensities[n..].fill(0.0);
        self.sequence += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lms111_defaults_match_the_datasheet_figures() {
        let s = LaserConfig::default().spec();
        assert_eq!(s.beams(), 541);
        assert!((s.angle_min().to_degrees() + 135.0).abs() < 1e-9);
        assert_eq!(
            (s.rate_hz, s.range_min, s.range_max, s.range_noise_sigma),
            (50.0, 0.5, 20.0, 0.012)
        );
        let s = LaserProfile::Lms291.spec();
        assert_eq!(s.beams(), 361);
        assert!((s.angle_min().to_degrees() + 90.0).abs() < 1e-9);
    }

    #[test]
    fn noise_seeds_differ_per_scenario_seed_and_from_the_seed_itself() {
        assert_ne!(noise_seed(1), noise_seed(2));
        assert_ne!(noise_seed(1), 1);
        assert_eq!(noise_seed(7), noise_seed(7));
    }

    #[test]
    fn stamps_are_epoch_plus_sim_time() {
        assert_eq!(unix_ns(1_000_000_000, 0.02), 1_020_000_000);
        assert_eq!(unix_ns(5, -1.0), 0);
    }
}
