//! The paper's golf car: the one source of the vehicle numbers that the controller's
//! configuration defaults to and that the simulator's vehicle, GPS and laser default to.

/// The golf car of the seed paper, as a constant both crates read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Car {
    /// Rear axle to front axle, metres.
    pub wheelbase: f64,
    /// Road-wheel angle limit, degrees.
    pub max_steer_deg: f64,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// The circle the planner treats the car as, around the rear axle (the paper's
    /// r_0), metres.
    pub radius: f64,
    /// Footprint length and width, and the rear bumper's distance behind the rear axle,
    /// metres.
    pub length: f64,
    pub width: f64,
    pub rear_overhang: f64,
    /// GPS antenna position in the vehicle frame (x forward, y left of the rear axle),
    /// metres.
    pub antenna: [f64; 2],
    /// Laser scanner mounting position in the vehicle frame, metres, and yaw, degrees.
    pub laser: [f64; 2],
    pub laser_yaw_deg: f64,
    /// The steering actuator's dead time and first-order time constant, seconds (what
    /// the controller propagates the state over before planning and steering).
    pub steer_dead_time_s: f64,
    pub steer_time_constant_s: f64,
    /// The speed loop's (throttle/brake ECU's) dead time and first-order time
    /// constant, seconds (how far the car rolls on after a lower speed is commanded).
    pub speed_dead_time_s: f64,
    pub speed_time_constant_s: f64,
    /// Deceleration at full brake, m/s^2 (a 48 V golf car's drum brakes on dry
    /// tarmac, measured from 3 m/s).
    pub brake_decel: f64,
}

/// The paper's car.
pub const PAPER_CAR: Car = Car {
    wheelbase: 1.65,
    max_steer_deg: 35.0,
    max_speed: 6.7,
    radius: 2.0,
    length: 2.4,
    width: 1.2,
    rear_overhang: 0.375,
    antenna: [0.5, 0.0],
    laser: [2.0, 0.0],
    laser_yaw_deg: 0.0,
    steer_dead_time_s: 0.02,
    steer_time_constant_s: 0.08,
    speed_dead_time_s: 0.05,
    speed_time_constant_s: 0.4,
    brake_decel: 4.0,
};
