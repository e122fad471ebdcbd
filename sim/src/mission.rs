//! What the controller is told about a scenario: the mission (datum, start, goal) and
//! the vehicle's calibration (geometry, antenna and laser mounting, the steering's
//! dead time and time constant, the brake's deceleration), exactly as a field team would configure the car.
//! Nothing else of the scenario (obstacles, noise, the steering sensor's bias) reaches
//! the controller except through its sensors.

use ugv_controller::config::{ControllerConfig, FollowerKind};

use crate::scenario::Scenario;

/// The controller configuration for a scenario, with the follower to use.
pub fn controller_config(scenario: &Scenario, follower: FollowerKind) -> ControllerConfig {
    let mut cfg = ControllerConfig::default();
    let m = &mut cfg.mission;
    m.datum = scenario.datum;
    m.start_x = scenario.start.x;
    m.start_y = scenario.start.y;
    m.goal_x = scenario.goal.x;
    m.goal_y = scenario.goal.y;
    m.goal_heading_deg = scenario.goal.heading_deg;
    m.goal_tolerance = scenario.goal.tolerance;
    m.goal_speed_limit = scenario.goal.speed_limit;
    m.waypoints = scenario.waypoints.clone();
    let v = &mut cfg.vehicle;
    v.wheelbase = scenario.vehicle.wheelbase;
    v.max_steer_deg = scenario.vehicle.max_steer_deg;
    v.max_speed = scenario.vehicle.max_speed;
    v.radius = scenario.vehicle.radius;
    v.length = scenario.vehicle.length;
    v.width = scenario.vehicle.width;
    v.rear_overhang = scenario.vehicle.rear_overhang;
    v.antenna_x = scenario.gps.antenna_x;
    v.antenna_y = scenario.gps.antenna_y;
    v.laser_x = scenario.laser.mount_x;
    v.laser_y = scenario.laser.mount_y;
    v.laser_yaw_deg = scenario.laser.mount_yaw_deg;
    // The actuators' timing is calibration a field team measures (step responses);
    // the steering sensor's bias is not: the controller estimates that itself.
    v.steer_dead_time_s = scenario.steering.dead_time_s;
    v.steer_time_constant_s = scenario.steering.time_constant_s;
    v.speed_dead_time_s = scenario.throttle.dead_time_s;
    v.speed_time_constant_s = scenario.throttle.time_constant_s;
    v.brake_decel = scenario.throttle.brake_decel;
    cfg.safety.gps_rate_hz = scenario.gps.rate_hz;
    if let Some(r) = scenario.controller.detection_radius {
        cfg.perception.detection_radius = r;
    }
    cfg.planner.cruise_speed = cfg.planner.cruise_speed.min(scenario.vehicle.max_speed);
    cfg.follower.kind = follower;
    cfg
}

/// The controller configuration for a scenario with the follower (and ANFIS model) to
/// use, checked exactly as the controller checks it: what `ugv-sim check` accepts,
/// `run` and `suite` accept too.
pub fn checked_controller_config(
    scenario: &Scenario,
    follower: FollowerKind,
    anfis_model: Option<std::path::PathBuf>,
) -> Result<ControllerConfig, ugv_fields::FieldError> {
    let mut cfg = controller_config(scenario, follower);
    cfg.follower.anfis_model = anfis_model;
    cfg.validate()?;
    Ok(cfg)
}
