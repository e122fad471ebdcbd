//! The scenario's sections as TOML reads them (`[start]`, `[goal]`, `[[obstacles]]`,
//! `[vehicle]`, `[steering]`, `[throttle]`, `[can]`, `[sim]`, `[success]`,
//! `[controller]`): plain data with the seed paper's defaults, imported by the
//! components each takes its own section; the devices' sections live with the
//! devices (`gps::GpsConfig`, `laser::LaserConfig`, `map::DeviceMap`).

use serde::{Deserialize, Serialize};

pub use firmware_bridge::geodesy::Datum;

/// A pose in the world frame: metres, heading counter-clockwise from +x (East).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    #[serde(default)]
    pub heading_deg: f64,
}

impl Pose {
    pub fn heading(&self) -> f64 {
        self.heading_deg.to_radians()
    }
}

/// The goal and when it counts as reached.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Goal {
    pub x: f64,
    pub y: f64,
    /// Desired heading at the goal; `None` leaves it to the controller.
    pub heading_deg: Option<f64>,
    /// Distance of the rear-axle reference point from the goal that counts as reached.
    pub tolerance: f64,
    /// Speed limit on the last leg (into the goal), m/s.
    pub speed_limit: Option<f64>,
}

impl Default for Goal {
    fn default() -> Self {
        Goal {
            x: 30.0,
            y: 15.0,
            heading_deg: None,
            tolerance: 1.0,
            speed_limit: None,
        }
    }
}

/// How an obstacle moves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Motion {
    /// Constant velocity from the obstacle's position at t = 0.
    Velocity { vx: f64, vy: f64 },
    /// Along waypoints at a constant speed, from the first; it stops at the last unless
    /// `cyclic`, which returns to the first and goes round again.
    Waypoints {
        points: Vec<[f64; 2]>,
        speed: f64,
        #[serde(default)]
        cyclic: bool,
    },
}

/// An obstacle in the world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Obstacle {
    /// A post (the paper's cylinder).
    Circle {
        x: f64,
        y: f64,
        radius: f64,
        #[serde(default)]
        motion: Option<Motion>,
    },
    /// A rectangle centred at (x, y).
    Box {
        x: f64,
        y: f64,
        length: f64,
        width: f64,
        #[serde(default)]
        heading_deg: f64,
        #[serde(default)]
        motion: Option<Motion>,
    },
    /// A wall along a polyline (two or more points) with a thickness.
    Wall {
        points: Vec<[f64; 2]>,
        thickness: f64,
    },
}

impl Obstacle {
    /// Whether it moves (a post or a box with a motion; walls stand).
    pub fn moves(&self) -> bool {
        matches!(
            self,
            Obstacle::Circle {
                motion: Some(_),
                ..
            } | Obstacle::Box {
                motion: Some(_),
                ..
            }
        )
    }
}

/// The golf car's geometry and limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// Rear axle to front axle, metres.
    pub wheelbase: f64,
    /// Footprint length and width, metres.
    pub length: f64,
    pub width: f64,
    /// From the rear bumper to the rear axle (the reference point), metres.
    pub rear_overhang: f64,
    /// Road-wheel angle limit, degrees.
    pub max_steer_deg: f64,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// The radius of the circle the planner treats the car as (the paper's r_0).
    pub radius: f64,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        let car = ugv_controller::car::PAPER_CAR;
        VehicleConfig {
            wheelbase: car.wheelbase,
            length: car.length,
            width: car.width,
            rear_overhang: car.rear_overhang,
            max_steer_deg: car.max_steer_deg,
            max_speed: car.max_speed,
            radius: car.radius,
        }
    }
}

/// The steering ECU's actuator: dead time, first-order lag, rate and angle limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringConfig {
    pub dead_time_s: f64,
    pub time_constant_s: f64,
    /// The motor's own rate limit (a command's MaxRate can only lower it), deg/s.
    pub max_rate_deg_s: f64,
    /// Motor current at rest and per deg/s of rate, amperes (for the report).
    pub idle_current_a: f64,
    pub current_per_rate_a: f64,
    /// A disturbance: the angle sensor's zero is off by this much, so the road wheels
    /// stand at the commanded (and reported) angle plus this bias, degrees (0: none;
    /// at most 10).
    pub bias_deg: f64,
}

impl Default for SteeringConfig {
    /// A golf-car-class electric power steering retrofit.
    fn default() -> Self {
        let car = ugv_controller::car::PAPER_CAR;
        SteeringConfig {
            dead_time_s: car.steer_dead_time_s,
            time_constant_s: car.steer_time_constant_s,
            max_rate_deg_s: 60.0,
            idle_current_a: 0.5,
            current_per_rate_a: 0.12,
            bias_deg: 0.0,
        }
    }
}

/// The throttle/brake ECU: a speed loop with dead time, lag, acceleration and
/// deceleration limits, and a brake.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThrottleConfig {
    pub dead_time_s: f64,
    pub time_constant_s: f64,
    /// The drive's own limits, m/s^2 (a command's AccelLimit can only lower acceleration).
    pub max_accel: f64,
    pub max_decel: f64,
    /// Deceleration at 100 % brake, m/s^2.
    pub brake_decel: f64,
    /// Throttle % needed per m/s of steady speed (for the report).
    pub throttle_per_speed: f64,
}

impl Default for ThrottleConfig {
    /// A 48 V golf car drive.
    fn default() -> Self {
        let car = ugv_controller::car::PAPER_CAR;
        ThrottleConfig {
            dead_time_s: car.speed_dead_time_s,
            time_constant_s: car.speed_time_constant_s,
            max_accel: 1.5,
            max_decel: 2.5,
            brake_decel: car.brake_decel,
            throttle_per_speed: 12.0,
        }
    }
}

/// The CAN side of the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CanConfig {
    /// The SocketCAN interface the simulated ECUs sit on.
    pub interface: String,
    /// How long after the last FAULT_REPORT a fault counts as cleared, ms.
    pub fault_clear_ms: u32,
    /// Give the bus the wire's time at the DBC's bit rate, so frames wait for the bus
    /// and win it by ID and an overloaded schedule shows up as late frames (the
    /// verdict's `bus_load.arbitration`): in SIL the memory bus arbitrates every
    /// node's frames; in HIL the simulator's own transmissions are paced onto the
    /// interface, the other nodes' frames seen there taking their bit time. Off: a
    /// frame arrives as it is sent.
    pub bit_timing: bool,
}

impl Default for CanConfig {
    fn default() -> Self {
        CanConfig {
            interface: "vcan0".to_owned(),
            fault_clear_ms: 250,
            bit_timing: false,
        }
    }
}

/// Simulation timing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Physics rate, Hz.
    pub physics_hz: f64,
    /// The run ends with a time-out verdict after this long, seconds.
    pub time_limit_s: f64,
    /// UTC at t = 0, RFC 3339 (`2026-05-04T14:00:00Z`), parsed at load.
    pub epoch: crate::epoch::Epoch,
    /// Seed of the noise sources (each source derives its own stream).
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            physics_hz: 200.0,
            time_limit_s: 60.0,
            epoch: crate::epoch::Epoch::default(),
            seed: 1,
        }
    }
}

/// What a run must achieve to pass.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SuccessCriteria {
    /// Reach the goal (false for scenarios where stopping safely is the success).
    pub reach_goal: bool,
    /// Minimum clearance between the footprint and any obstacle, metres.
    pub min_clearance: f64,
}

impl Default for SuccessCriteria {
    fn default() -> Self {
        SuccessCriteria {
            reach_goal: true,
            min_clearance: 0.0,
        }
    }
}

/// What a scenario sets of the controller's tuning (`[controller]`), as a field team
/// would for a site; everything else is the controller's default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerTuning {
    /// Perception's detection radius, metres (default: the controller's 8 m, the
    /// paper's); up to the laser's range.
    pub detection_radius: Option<f64>,
    /// The space behind the car its operator checked clear at the start, depth and
    /// width, metres (default: the controller's 2.6 m by 1.2 m); the car backs only
    /// into space its forward-looking laser has seen, or this.
    pub seen_behind_m: Option<f64>,
    pub seen_behind_width_m: Option<f64>,
}
