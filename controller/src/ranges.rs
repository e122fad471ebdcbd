//! The plausible range of every physical parameter of the controller's configuration,
//! each with its source, in one table ([`CONFIG`]), and the ranges the simulator's
//! scenarios share with it (the car's geometry and actuators, the GPS rate: one place
//! each). A range is generous enough for other Ackermann carts and scanners and for
//! every configuration and scenario in the repository, and closed: values no golf car
//! has (a wheelbase of 1e-9 m or 1e300 m, a 1e-9 s lag) are refused, the refusal giving
//! the range and its source.
//!
//! The sources: the golf car of the seed paper (`car.rs`: about 2.4 m long and 1.2 m
//! wide, wheelbase 1.65 m, top speed 6.7 m/s), the DBC's signal ranges
//! (`can-dbc/golf_car.dbc`) where a value ends up on the bus, and the receivers' and
//! scanners' datasheets. Relations between fields (a cruise speed up to the top speed,
//! a footprint inside the planning circle) are checked by `ControllerConfig::validate`.

use ugv_fields::{Bound, Range};

use crate::config::ControllerConfig;

/// Rear axle to front axle.
pub const WHEELBASE: Range = Range::new(
    0.5,
    5.0,
    "m",
    "the golf car's is 1.6-1.7 m; 0.5-5 m spans small carts to utility vehicles",
);
/// The footprint's length.
pub const LENGTH: Range = Range::new(
    1.0,
    8.0,
    "m",
    "the golf car is about 2.4 m long; up to a utility vehicle's 8 m",
);
/// The footprint's width.
pub const WIDTH: Range = Range::new(
    0.5,
    3.0,
    "m",
    "the golf car is about 1.2 m wide; road vehicles are at most 2.55 m",
);
/// The rear bumper behind the rear axle.
pub const REAR_OVERHANG: Range = Range::new(0.0, 3.0, "m", "the golf car's is 0.375 m");
/// The planner's circle around the rear axle (the paper's r_0).
pub const RADIUS: Range = Range::new(
    0.5,
    10.0,
    "m",
    "the paper's r_0 is 2 m for the golf car; it holds the footprint, at most 8 m by 3 m",
);
/// The road-wheel angle limit.
pub const MAX_STEER_DEG: Range = Range::new(
    10.0,
    45.0,
    "degrees",
    "the DBC's STEERING_CMD.TargetAngle is +-45 degrees; golf cars steer 30-40 degrees",
);
/// The top speed.
pub const MAX_SPEED: Range = Range::new(
    0.2,
    10.0,
    "m/s",
    "the DBC's THROTTLE_CMD.TargetSpeed is 0-10 m/s; a golf car's top speed is 5-7 m/s",
);
/// A speed commanded below the top speed (cruise, passage, alignment, limits).
pub const SPEED: Range = Range::new(
    0.1,
    10.0,
    "m/s",
    "the DBC's THROTTLE_CMD.TargetSpeed is 0-10 m/s; below 0.1 m/s the car only creeps",
);
/// A sensor's position on the car (GPS antenna, laser scanner), either axis.
pub const MOUNT: Range = Range::new(
    -10.0,
    10.0,
    "m from the rear axle",
    "the sensor sits on the car, within a vehicle length (at most 8 m) of its rear axle",
);
/// An actuator's dead time (steering, speed loop).
pub const DEAD_TIME: Range = Range::new(
    0.0,
    5.0,
    "s",
    "the golf car's are 0.02-0.05 s (car.rs); the controller's command history covers 5 s (monitor.rs)",
);
/// The steering actuator's first-order time constant.
pub const STEER_TIME_CONSTANT: Range = Range::new(
    0.001,
    2.0,
    "s",
    "the golf car's is 0.08 s (car.rs); 1 ms is no lag at all, 2 s no steering the law can use",
);
/// The speed loop's first-order time constant.
pub const SPEED_TIME_CONSTANT: Range = Range::new(
    0.001,
    5.0,
    "s",
    "the golf car's is 0.4 s (car.rs); 1 ms is no lag at all",
);
/// Deceleration at full brake.
pub const BRAKE_DECEL: Range = Range::new(
    1.0,
    10.0,
    "m/s^2",
    "the golf car brakes at about 4 m/s^2 (car.rs); under 1 m/s^2 it needs over 22 m to stop from 6.7 m/s, over 10 m/s^2 (1 g) is beyond its tyres' grip",
);
/// A deceleration or lateral acceleration the controller asks for.
pub const ACCEL: Range = Range::new(
    0.1,
    10.0,
    "m/s^2",
    "about 1 g (10 m/s^2) is beyond a golf car's tyres' grip; under 0.1 m/s^2 nothing happens",
);
/// The GPS receiver's epoch rate.
pub const GPS_RATE: Range = Range::new(1.0, 20.0, "Hz", "RTK receivers offer 1-20 Hz epochs");
/// Distance from the goal at which the mission is complete.
pub const GOAL_TOLERANCE: Range = Range::new(
    0.05,
    10.0,
    "m",
    "RTK fixes are good to about 2 cm; the suite uses 1 m; 10 m is four car lengths",
);
/// Clearances added to obstacles.
pub const MARGIN: Range = Range::new(
    0.0,
    5.0,
    "m",
    "the golf car is 1.2 m wide: 5 m is four car widths",
);

/// A pace, as a fraction of the cruise speed (`planner.pace_fractions`).
pub const PACE_FRACTION: Range = Range::new(0.05, 1.0, "", "a fraction of the cruise speed");

/// One row of [`CONFIG`]: `section.field` (always set) and its range.
macro_rules! row {
    ($section:ident . $field:ident, $range:expr) => {
        Bound {
            field: &[stringify!($section), stringify!($field)],
            value: |c: &ControllerConfig| Some(f64::from(c.$section.$field)),
            range: $range,
        }
    };
}

/// Every physical parameter of the controller's configuration and its range, in the
/// order `validate` checks them (the first out of range is the error). The pace
/// fractions (a list) are checked with the same [`Range`] in `validate`.
pub const CONFIG: &[Bound<ControllerConfig>] = &[
    row!(mission.goal_tolerance, GOAL_TOLERANCE),
    Bound {
        field: &["mission", "goal_speed_limit"],
        value: |c| c.mission.goal_speed_limit,
        range: SPEED,
    },
    row!(vehicle.wheelbase, WHEELBASE),
    row!(vehicle.max_steer_deg, MAX_STEER_DEG),
    row!(
        vehicle.steer_rate_deg_s,
        Range::new(
            0.0,
            500.0,
            "deg/s",
            "the DBC's STEERING_CMD.MaxRate is 0-500 deg/s, 0 the ECU's own limit",
        )
    ),
    row!(vehicle.max_speed, MAX_SPEED),
    row!(vehicle.radius, RADIUS),
    row!(vehicle.length, LENGTH),
    row!(vehicle.width, WIDTH),
    row!(vehicle.rear_overhang, REAR_OVERHANG),
    row!(vehicle.antenna_x, MOUNT),
    row!(vehicle.antenna_y, MOUNT),
    row!(vehicle.laser_x, MOUNT),
    row!(vehicle.laser_y, MOUNT),
    row!(vehicle.steer_dead_time_s, DEAD_TIME),
    row!(vehicle.steer_time_constant_s, STEER_TIME_CONSTANT),
    row!(vehicle.speed_dead_time_s, DEAD_TIME),
    row!(vehicle.speed_time_constant_s, SPEED_TIME_CONSTANT),
    row!(vehicle.brake_decel, BRAKE_DECEL),
    row!(
        localisation.fix_time_constant_s,
        Range::new(
            0.0,
            5.0,
            "s",
            "RTK fixed fixes at 1-20 Hz, 0: taken as they are"
        )
    ),
    row!(
        localisation.float_fix_time_constant_s,
        Range::new(
            0.0,
            10.0,
            "s",
            "RTK float fixes wander over tens of seconds"
        )
    ),
    row!(
        localisation.steer_bias_gain,
        Range::new(0.0, 1.0, "", "a fraction of the bias left")
    ),
    row!(
        localisation.max_steer_bias_deg,
        Range::new(
            0.0,
            10.0,
            "degrees",
            "a steering sensor's zero is off by a few degrees at most",
        )
    ),
    row!(
        planner.replan_period_s,
        Range::new(
            0.05,
            5.0,
            "s",
            "the paper's T_s, 0.5 s here; 0.05 s is under a 25 Hz scan, 5 s is 33 m blind at 6.7 m/s",
        )
    ),
    row!(
        planner.horizon_m,
        Range::new(
            5.0,
            200.0,
            "m",
            "within the laser's range: 20 m for the LMS111, 80 m for the LMS291",
        )
    ),
    row!(
        planner.horizon_min_m,
        Range::new(2.0, 200.0, "m", "up to horizon_m")
    ),
    row!(planner.safety_margin, MARGIN),
    row!(planner.passage_margin, MARGIN),
    row!(planner.passage_speed, SPEED),
    row!(planner.cruise_speed, SPEED),
    row!(
        planner.steer_usage,
        Range::new(0.1, 1.0, "", "a fraction of the steering limit")
    ),
    row!(
        planner.final_approach,
        Range::new(
            0.0,
            20.0,
            "m",
            "no replanning on what the LMS111 (20 m) cannot see",
        )
    ),
    row!(
        planner.moving_time_margin_s,
        Range::new(0.0, 10.0, "s", "timing errors of a tracked walker or cart")
    ),
    row!(planner.moving_margin, MARGIN),
    row!(
        planner.pace_time_weight,
        Range::new(0.0, 1e6, "m^3/s", "a weight of the planner's cost")
    ),
    row!(planner.align_speed, SPEED),
    row!(
        planner.recover_after_s,
        Range::new(0.1, 60.0, "s", "standing still before reversing")
    ),
    row!(
        planner.reverse_distance_m,
        Range::new(0.5, 10.0, "m", "a few car lengths back, blind behind")
    ),
    row!(
        planner.reverse_speed,
        Range::new(0.1, 2.0, "m/s", "walking pace, blind behind")
    ),
    row!(
        planner.max_reversals,
        Range::new(0.0, 10.0, "", "reversals before a controlled stop")
    ),
    row!(
        planner.reversal_reset_m,
        Range::new(1.0, 1000.0, "m", "progress along the route")
    ),
    row!(
        follower.omega,
        Range::new(
            0.05,
            20.0,
            "rad/s",
            "the lateral dynamics of a car; 0.9 rad/s here",
        )
    ),
    row!(
        follower.zeta,
        Range::new(0.1, 10.0, "", "damping of the lateral dynamics; 0.8 here")
    ),
    row!(follower.max_lateral_accel, ACCEL),
    row!(follower.decel, ACCEL),
    row!(
        follower.accel_limit,
        Range::new(
            0.0,
            5.0,
            "m/s^2",
            "the DBC's THROTTLE_CMD.AccelLimit is 0-5 m/s^2, 0 the ECU's own limit",
        )
    ),
    row!(safety.gps_rate_hz, GPS_RATE),
    Bound {
        field: &["safety", "gps_timeout_s"],
        value: |c| c.safety.gps_timeout_s,
        range: Range::new(0.05, 10.0, "s", "an epoch at 20 Hz up to 10 s"),
    },
    row!(
        safety.laser_timeout_s,
        Range::new(
            0.05,
            10.0,
            "s",
            "over a scan period: 20 ms for the LMS111 at 50 Hz",
        )
    ),
    row!(
        safety.report_timeout_s,
        Range::new(
            0.02,
            10.0,
            "s",
            "over the ECUs' 10 ms report period (golf_car.dbc)",
        )
    ),
    row!(
        safety.settle_s,
        Range::new(0.0, 10.0, "s", "inputs fresh before the ECUs are enabled")
    ),
];
