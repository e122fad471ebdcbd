//! The plausible range of every physical parameter of the controller's configuration,
//! each with its source (the configuration's table of them is `config::BOUNDS`), and the ranges the simulator's
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

use ugv_fields::Range;

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
