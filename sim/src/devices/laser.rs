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
//! The noise seed is the scenario's `sim.seed` mixed with [`NOISE_SOURCE`], so it
//! differs from other devices' seeds and is the same for the same `sim.seed`. Each beam
//! of each scan draws from a stream of its own ([`noise`]), keyed by the seed, the
//! scan's sequence number and the beam: a normal, and a uniform for the dropout when
//! `dropout_probability` is above 0. A beam's noise is therefore the same whatever the
//! other beams hit (an obstacle added to a scene leaves the other beams' ranges as
//! they were), and beams without a return draw nothing.
//!
//! # Ray casting
//!
//! The beams' directions are computed once ([`Fan`]) and turned by the scanner's
//! heading per scan; the world's ray caster ([`crate::world::ray`]) tests each shape
//! within range only against the beams its bounding circle subtends.

use firmware_bridge::laser::{LASER_FRAME_VERSION, LaserFrame};
use rand::RngExt;
use rand_distr::StandardNormal;

use super::FieldError;
use crate::scenario::schema::Obstacle;
use crate::world::World;
use crate::world::ray::{Fan, Hit, ScannerPose};

mod config;
mod noise;

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
    let mix = |mut z: u64| noise::splitmix64(&mut z);
    mix(sim_seed ^ mix(NOISE_SOURCE))
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
    /// The seed every beam's noise stream is keyed by ([`noise::BeamNoise`]).
    noise_seed: u64,
    epoch_ns: u64,
    sequence: u64,
    /// The beams' directions relative to the forward axis.
    fan: Fan,
    /// Each beam's nearest hit in the last scan (kept to reuse its memory).
    hits: Vec<Hit>,
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
        let fan = Fan::new(
            spec.angle_min(),
            spec.resolution_deg.to_radians(),
            spec.beams(),
        );
        Ok(LaserDevice {
            config: config.clone(),
            spec,
            intensity,
            noise_seed: noise_seed(sim_seed),
            epoch_ns,
            sequence: 0,
            fan,
            hits: Vec::new(),
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
    pub fn scanner_pose(&self, x: f64, y: f64, theta: f64) -> ScannerPose {
        let (s, c) = theta.sin_cos();
        let (mx, my) = (self.config.mount_x, self.config.mount_y);
        ScannerPose {
            x: x + mx * c - my * s,
            y: y + mx * s + my * c,
            heading_rad: theta + self.config.mount_yaw_deg.to_radians(),
        }
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
        let pose = self.scanner_pose(x, y, theta);
        self.header(t, frame);
        let mut hits = std::mem::take(&mut self.hits);
        world.scan(pose, &self.fan, self.spec.range_max, &mut hits);
        let n = hits.len();
        for (beam, ((hit, range), intensity)) in hits
            .iter()
            .zip(&mut frame.ranges)
            .zip(&mut frame.intensities)
            .enumerate()
        {
            (*range, *intensity) = self.measure(*hit, beam);
        }
        self.hits = hits;
        zero_tail(&mut frame.ranges[n..]);
        zero_tail(&mut frame.intensities[n..]);
        self.sequence += 1;
    }

    /// The frame's header for a scan at `t`.
    fn header(&self, t: f64, frame: &mut LaserFrame) {
        let s = &self.spec;
        frame.version = LASER_FRAME_VERSION;
        frame.count = self.fan.len() as u32;
        frame.sequence = self.sequence;
        frame.stamp_ns = unix_ns(self.epoch_ns, t);
        frame.angle_min = s.angle_min() as f32;
        frame.angle_increment = s.resolution_deg.to_radians() as f32;
        frame.time_increment = s.time_increment() as f32;
        frame.scan_time = s.scan_time() as f32;
        frame.range_min = s.range_min as f32;
        frame.range_max = s.range_max as f32;
    }

    /// Beam `beam`'s range and intensity from its true hit: noise, dropout, limits.
    fn measure(&self, (r, obstacle): Hit, beam: usize) -> (f32, f32) {
        let s = &self.spec;
        if !(r >= s.range_min && r <= s.range_max) {
            // Nothing within range_max, or closer than range_min: no return.
            return (f32::INFINITY, 0.0);
        }
        let mut rng = noise::BeamNoise::new(self.noise_seed, self.sequence, beam);
        let noise: f64 = rng.sample(StandardNormal);
        let p_drop = self.config.dropout_probability;
        if p_drop > 0.0 && rng.random::<f64>() < p_drop {
            (f32::NAN, 0.0)
        } else {
            let measured = (r + noise * s.range_noise_sigma).clamp(s.range_min, s.range_max);
            let intensity = self.intensity.get(obstacle).copied().unwrap_or(0.0);
            (measured as f32, intensity)
        }
    }
}

/// Zero the entries past the beams in use, unless they are already (a new frame's are:
/// checking costs a tenth of writing them again).
fn zero_tail(tail: &mut [f32]) {
    if tail.iter().fold(0, |any, v| any | v.to_bits()) != 0 {
        tail.fill(0.0);
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
    fn a_frames_tail_is_zeroed_whatever_it_held() {
        for held in [0.0f32, -0.0, 1.5, f32::NAN, f32::INFINITY] {
            let mut tail = [0.0f32; 9];
            tail[4] = held;
            zero_tail(&mut tail);
            assert!(tail.iter().all(|v| v.to_bits() == 0), "{held}");
        }
    }

    #[test]
    fn a_reused_frame_reads_as_a_new_one() {
        let obstacles = [Obstacle::Circle {
            x: 5.0,
            y: 1.0,
            radius: 0.5,
            motion: None,
        }];
        let world = World::new(&obstacles);
        let device = || LaserDevice::new(&LaserConfig::default(), &obstacles, 7, 0);
        let (mut a, mut b) = (device().expect("valid"), device().expect("valid"));
        let fresh = a.scan(&world, 0.02, 0.0, 0.0, 0.1);
        let mut reused = Box::new(LaserFrame {
            version: 0,
            count: 3,
            sequence: 99,
            stamp_ns: 1,
            angle_min: 1.0,
            angle_increment: -1.0,
            time_increment: 9.0,
            scan_time: 9.0,
            range_min: 5.0,
            range_max: 1.0,
            ranges: [-2.5; firmware_bridge::laser::MAX_BEAMS],
            intensities: [f32::NAN; firmware_bridge::laser::MAX_BEAMS],
        });
        b.scan_into(&world, 0.02, 0.0, 0.0, 0.1, &mut reused);
        assert!(*reused == fresh, "the reused frame differs");
        assert!(
            fresh.ranges[..fresh.count as usize]
                .iter()
                .any(|r| r.is_finite())
        );
    }

    #[test]
    fn stamps_are_epoch_plus_sim_time() {
        assert_eq!(unix_ns(1_000_000_000, 0.02), 1_020_000_000);
        assert_eq!(unix_ns(5, -1.0), 0);
    }
}
