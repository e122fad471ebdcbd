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

use firmware_bridge::laser::{LASER_FRAME_VERSION, LaserFrame};
use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
use rand_distr::StandardNormal;

use super::FieldError;
use crate::scenario::schema::Obstacle;
use crate::world::World;

mod config;

pub use config::{LaserConfig, LaserProfile, LaserSpec};

/// The per-source constant the laser's noise seed is derived with (ASCII "LASER").
pub const NOISE_SOURCE: u64 = 0x4C41_5345_5200_0001;

/// Why a laser device could not be built.
#[derive(Debug, thiserror::Error)]
pub enum LaserDeviceError {
    #[error("{0}")]
    Config(FieldError),
}

impl From<FieldError> for LaserDeviceError {
    fn from(e: FieldError) -> Self {
        LaserDeviceError::Config(e.under(&ugv_fields::FieldPath::of(&["laser"])))
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
