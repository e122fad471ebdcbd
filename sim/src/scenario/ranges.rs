//! The plausible range of every physical parameter of a scenario, each with its
//! source, one table per section type: [`SCENARIO`] (goal, vehicle, steering and
//! throttle ECUs, timing), [`GPS`] and [`FIX_MODEL`] (`[gps]`, `[gps.rtk]`, ...),
//! [`LASER`] (`[laser]`, the profile's figures with the overrides), and the obstacles'
//! sizes and speeds. What the scenario shares with the controller's configuration
//! (the car's geometry and actuators, the GPS rate, the sensors' mounting) is the
//! controller's range ([`ugv_controller::ranges`]), one place each.
//!
//! The sources: the golf car (about 2.4 m by 1.2 m, wheelbase 1.65 m, 5-7 m/s), the
//! DBC's signal ranges (`can-dbc/golf_car.dbc`), the SICK LMS111 datasheet (270
//! degrees, 0.25 or 0.5 degree steps, 25 or 50 Hz, 0.5-20 m) and the LMS291's, RTK
//! receivers and NMEA's fields. Every range admits every scenario in the repository
//! and refuses values no golf car has (1e-9, 1e300).

use ugv_controller::ranges as car;
use ugv_fields::{Bound, Range};

use super::Scenario;
use crate::devices::gps::{FixModel, GpsConfig};
use crate::devices::laser::LaserConfig;

/// A post's radius, a box's length or width.
pub const OBSTACLE_SIZE: Range = Range::new(
    0.01,
    100.0,
    "m",
    "the suite's posts, trees and carts are 0.2-3 m; 1 cm is a wire, 100 m a building",
);
/// A wall's thickness.
pub const WALL_THICKNESS: Range = Range::new(
    0.01,
    10.0,
    "m",
    "the suite's fences and hedges are 0.1-0.8 m thick",
);
/// An obstacle's speed, either axis or along its waypoints.
pub const OBSTACLE_SPEED: Range = Range::new(
    -20.0,
    20.0,
    "m/s",
    "walkers 1-1.5 m/s, carts 5-7 m/s, a car on a course road up to 20 m/s (72 km/h)",
);

/// An obstacle's speed along its waypoints.
pub const OBSTACLE_PACE: Range = Range::new(
    0.05,
    20.0,
    "m/s",
    "walkers 1-1.5 m/s, carts 5-7 m/s, a car on a course road up to 20 m/s (72 km/h)",
);

/// One row of a table whose field is always set: `path.to.field` of `$t`.
macro_rules! row {
    ($t:ty, $range:expr, $first:ident $(. $rest:ident)*) => {
        Bound {
            field: &[stringify!($first) $(, stringify!($rest))*],
            value: |s: &$t| Some(f64::from(s.$first $(. $rest)*)),
            range: $range,
        }
    };
}

/// The scenario's own sections (the GPS, the laser and the obstacles have theirs).
pub const SCENARIO: &[Bound<Scenario>] = &[
    row!(Scenario, car::GOAL_TOLERANCE, goal.tolerance),
    Bound {
        field: &["goal", "speed_limit"],
        value: |s| s.goal.speed_limit,
        range: car::SPEED,
    },
    Bound {
        field: &["controller", "detection_radius"],
        value: |s| s.controller.detection_radius,
        range: Range::new(
            1.0,
            100.0,
            "m",
            "perception's detection radius, at most 100 m; the LMS291 reaches 80 m",
        ),
    },
    Bound {
        field: &["controller", "seen_behind_m"],
        value: |s| s.controller.seen_behind_m,
        range: Range::new(0.0, 30.0, "m", "what an operator checks behind the car"),
    },
    Bound {
        field: &["controller", "seen_behind_width_m"],
        value: |s| s.controller.seen_behind_width_m,
        range: Range::new(0.0, 60.0, "m", "what an operator checks behind the car"),
    },
    row!(Scenario, car::WHEELBASE, vehicle.wheelbase),
    row!(Scenario, car::LENGTH, vehicle.length),
    row!(Scenario, car::WIDTH, vehicle.width),
    row!(Scenario, car::RADIUS, vehicle.radius),
    row!(Scenario, car::REAR_OVERHANG, vehicle.rear_overhang),
    row!(Scenario, car::MAX_STEER_DEG, vehicle.max_steer_deg),
    row!(Scenario, car::MAX_SPEED, vehicle.max_speed),
    row!(Scenario, car::DEAD_TIME, steering.dead_time_s),
    row!(Scenario, car::STEER_TIME_CONSTANT, steering.time_constant_s),
    row!(
        Scenario,
        Range::new(
            5.0,
            500.0,
            "deg/s",
            "the DBC's STEERING_CMD.MaxRate is 0-500 deg/s; the golf car's motor turns 60 deg/s",
        ),
        steering.max_rate_deg_s
    ),
    row!(
        Scenario,
        Range::new(
            0.0,
            25.5,
            "A",
            "the DBC's STEERING_REPORT.MotorCurrent is 0-25.5 A"
        ),
        steering.idle_current_a
    ),
    row!(
        Scenario,
        Range::new(
            0.0,
            1.0,
            "A per deg/s",
            "the DBC's MotorCurrent (25.5 A) reached at 25 deg/s",
        ),
        steering.current_per_rate_a
    ),
    row!(
        Scenario,
        Range::new(
            -10.0,
            10.0,
            "degrees",
            "a steering sensor's zero off by a few degrees; the controller estimates up to 10",
        ),
        steering.bias_deg
    ),
    row!(Scenario, car::DEAD_TIME, throttle.dead_time_s),
    row!(Scenario, car::SPEED_TIME_CONSTANT, throttle.time_constant_s),
    row!(Scenario, car::ACCEL, throttle.max_accel),
    row!(Scenario, car::ACCEL, throttle.max_decel),
    row!(Scenario, car::BRAKE_DECEL, throttle.brake_decel),
    row!(
        Scenario,
        Range::new(
            0.0,
            100.0,
            "% per m/s",
            "the DBC's THROTTLE_REPORT.Throttle is 0-100 %",
        ),
        throttle.throttle_per_speed
    ),
    row!(
        Scenario,
        Range::new(
            10.0,
            2000.0,
            "Hz",
            "10 Hz resolves the golf car's 0.4 s speed loop; beyond 2 kHz only costs time",
        ),
        sim.physics_hz
    ),
    row!(
        Scenario,
        Range::new(1.0, 86_400.0, "s", "a run of a second up to a day"),
        sim.time_limit_s
    ),
    row!(Scenario, car::MARGIN, success.min_clearance),
];

/// `[gps]`, relative to it.
pub const GPS: &[Bound<GpsConfig>] = &[
    row!(GpsConfig, car::MOUNT, antenna_x),
    row!(GpsConfig, car::MOUNT, antenna_y),
    row!(
        GpsConfig,
        Range::new(
            0.0,
            5.0,
            "m above ground",
            "on the roof: the golf car's antenna is 1.8 m up",
        ),
        antenna_z
    ),
    row!(GpsConfig, car::GPS_RATE, rate_hz),
    row!(
        GpsConfig,
        Range::new(
            0.0,
            30.0,
            "degrees",
            "about 0.1 degrees with a 1 m baseline; 30 degrees is no heading at all",
        ),
        heading_sigma_deg
    ),
    row!(
        GpsConfig,
        Range::new(0.0, 999.9, "s", "GGA's age of corrections field"),
        correction_age_s
    ),
    row!(
        GpsConfig,
        Range::new(
            -200.0,
            200.0,
            "m",
            "the geoid lies within about 110 m of the ellipsoid",
        ),
        geoid_separation_m
    ),
];

/// The error model of one fix state (`[gps.rtk]`, `[gps.float]`, `[gps.single]`),
/// relative to its section.
pub const FIX_MODEL: &[Bound<FixModel>] = &[
    row!(
        FixModel,
        Range::new(
            0.0,
            100.0,
            "m",
            "RTK fixed 1.5 cm, float 0.25 m, single 1.5 m; no receiver reports a fix 100 m off",
        ),
        horizontal_sigma_m
    ),
    row!(
        FixModel,
        Range::new(0.0, 200.0, "m", "about twice the horizontal error",),
        vertical_sigma_m
    ),
    row!(
        FixModel,
        Range::new(
            0.1,
            3600.0,
            "s",
            "multipath and the atmosphere wander over seconds to an hour (30-120 s here)",
        ),
        time_constant_s
    ),
    row!(
        FixModel,
        Range::new(0.0, 1.0, "", "a share of the variance"),
        white_fraction
    ),
    row!(
        FixModel,
        Range::new(
            0.0,
            10.0,
            "m/s",
            "Doppler velocities are good to a few cm/s",
        ),
        velocity_sigma_mps
    ),
    row!(
        FixModel,
        Range::new(0.0, 99.0, "", "GGA's two digits"),
        satellites
    ),
    row!(
        FixModel,
        Range::new(
            0.3,
            99.99,
            "",
            "the best geometries give about 0.5; GGA carries up to 99.99",
        ),
        hdop
    ),
];

/// One row of [`LASER`] read from the profile's figures with the overrides.
macro_rules! spec_row {
    ($field:ident, $range:expr) => {
        Bound {
            field: &[stringify!($field)],
            value: |l: &LaserConfig| Some(l.spec().$field),
            range: $range,
        }
    };
}

/// `[laser]`, relative to it: the mounting, then the scanner's figures (the profile's,
/// or the overrides).
pub const LASER: &[Bound<LaserConfig>] = &[
    row!(LaserConfig, car::MOUNT, mount_x),
    row!(LaserConfig, car::MOUNT, mount_y),
    row!(
        LaserConfig,
        Range::new(-360.0, 360.0, "degrees", "a turn either way"),
        mount_yaw_deg
    ),
    spec_row!(
        fov_deg,
        Range::new(
            10.0,
            360.0,
            "degrees",
            "the LMS111 sees 270 degrees, the LMS291 180; up to a full turn",
        )
    ),
    spec_row!(
        resolution_deg,
        Range::new(
            0.05,
            5.0,
            "degrees",
            "the LMS111 steps 0.25 or 0.5 degrees, the LMS291 0.25-1",
        )
    ),
    spec_row!(
        rate_hz,
        Range::new(
            1.0,
            100.0,
            "Hz",
            "the LMS111 scans at 25 or 50 Hz, the LMS291 at 37.5-75 Hz",
        )
    ),
    spec_row!(
        range_min,
        Range::new(
            0.0,
            5.0,
            "m",
            "the LMS111 measures from 0.5 m, the LMS291 from 0.1 m",
        )
    ),
    spec_row!(
        range_max,
        Range::new(
            1.0,
            200.0,
            "m",
            "the LMS111 reaches 20 m, the LMS291 80 m, long-range scanners 200 m",
        )
    ),
    spec_row!(
        range_noise_sigma,
        Range::new(
            0.0,
            0.5,
            "m",
            "the LMS111's statistical error is 12 mm, its systematic 30 mm",
        )
    ),
    row!(
        LaserConfig,
        Range::new(0.0, 1.0, "", "a probability"),
        dropout_probability
    ),
    row!(LaserConfig, INTENSITY, intensity_circle),
    row!(LaserConfig, INTENSITY, intensity_box),
    row!(LaserConfig, INTENSITY, intensity_wall),
];

/// A return's intensity, device units.
const INTENSITY: Range = Range::new(0.0, f32::MAX as f64, "", "device units, carried as an f32");
