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
    if let Some(d) = scenario.controller.seen_behind_m {
        cfg.planner.seen_behind_at_start_m = d;
    }
    if let Some(w) = scenario.controller.seen_behind_width_m {
        cfg.planner.seen_behind_at_start_width_m = w;
    }
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

/// The version of `mission.toml`'s layout ([`MissionFile`]): raised when a key changes
/// meaning or goes away.
pub const MISSION_FILE_VERSION: u32 = 1;

/// What a controller of one's own needs to know of a run, written as `mission.toml`
/// beside `wires.json` (docs/wire-contract.md, "The mission"): the datum, the start, the
/// route and the goal with their tolerances, and the car's geometry and sensor
/// mounting. The same values as `controller.toml`'s `[mission]` and `[vehicle]`,
/// without the project's controller's tuning.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MissionFile {
    /// [`MISSION_FILE_VERSION`].
    pub version: u32,
    /// The origin of the world frame (x East, y North).
    pub datum: firmware_bridge::geodesy::Datum,
    pub start: StartFile,
    pub goal: GoalFile,
    /// Points to pass in order before the goal.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<ugv_controller::route::Waypoint>,
    pub vehicle: VehicleFile,
}

/// Where the rear axle starts, metres (its heading: the GPS's HDT).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StartFile {
    pub x: f64,
    pub y: f64,
}

/// The goal: the run ends "goal reached" when the rear axle is within `tolerance`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GoalFile {
    pub x: f64,
    pub y: f64,
    pub tolerance: f64,
    /// Degrees counter-clockwise from East.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_deg: Option<f64>,
    /// m/s on the last leg.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub speed_limit: Option<f64>,
}

/// The car: geometry (rear-axle frame, x forward, y left), limits, sensor mounting.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct VehicleFile {
    pub wheelbase: f64,
    pub max_steer_deg: f64,
    pub max_speed: f64,
    pub length: f64,
    pub width: f64,
    pub rear_overhang: f64,
    pub antenna_x: f64,
    pub antenna_y: f64,
    pub laser_x: f64,
    pub laser_y: f64,
    pub laser_yaw_deg: f64,
}

/// The mission file of a run whose controller configuration is `config`.
pub fn mission_file(config: &ControllerConfig) -> MissionFile {
    let (m, v) = (&config.mission, &config.vehicle);
    MissionFile {
        version: MISSION_FILE_VERSION,
        datum: m.datum,
        start: StartFile {
            x: m.start_x,
            y: m.start_y,
        },
        goal: GoalFile {
            x: m.goal_x,
            y: m.goal_y,
            tolerance: m.goal_tolerance,
            heading_deg: m.goal_heading_deg,
            speed_limit: m.goal_speed_limit,
        },
        waypoints: m.waypoints.clone(),
        vehicle: VehicleFile {
            wheelbase: v.wheelbase,
            max_steer_deg: v.max_steer_deg,
            max_speed: v.max_speed,
            length: v.length,
            width: v.width,
            rear_overhang: v.rear_overhang,
            antenna_x: v.antenna_x,
            antenna_y: v.antenna_y,
            laser_x: v.laser_x,
            laser_y: v.laser_y,
            laser_yaw_deg: v.laser_yaw_deg,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mission_file_of_the_paper_and_of_a_route() -> Result<(), Box<dyn std::error::Error>> {
        let paper = crate::Scenario::paper()?;
        let text = toml::to_string_pretty(&mission_file(&controller_config(
            &paper,
            FollowerKind::Optimal,
        )))?;
        let value: toml::Table = toml::from_str(&text)?;
        assert_eq!(value["version"].as_integer(), Some(1), "{text}");
        assert_eq!(value["goal"]["x"].as_float(), Some(30.0), "{text}");
        assert_eq!(value["goal"]["y"].as_float(), Some(15.0), "{text}");
        assert_eq!(value["goal"]["tolerance"].as_float(), Some(1.0), "{text}");
        assert_eq!(
            value["datum"]["latitude"].as_float(),
            Some(37.2307),
            "{text}"
        );
        assert_eq!(
            value["vehicle"]["antenna_x"].as_float(),
            Some(0.5),
            "{text}"
        );
        assert_eq!(value["vehicle"]["laser_x"].as_float(), Some(2.0), "{text}");
        assert!(!value.contains_key("waypoints"), "{text}");
        assert!(!value.contains_key("planner"), "no tuning: {text}");
        // A route: its waypoints, in order, with their tolerances.
        let mut route = paper;
        route.waypoints = vec![ugv_controller::route::Waypoint {
            x: 10.0,
            y: 10.0,
            tolerance: 1.5,
            heading_deg: None,
            speed_limit: None,
        }];
        let text = toml::to_string_pretty(&mission_file(&controller_config(
            &route,
            FollowerKind::Optimal,
        )))?;
        let value: toml::Table = toml::from_str(&text)?;
        let points = value["waypoints"].as_array().ok_or("no waypoints")?;
        assert_eq!(points.len(), 1, "{text}");
        assert_eq!(points[0]["tolerance"].as_float(), Some(1.5), "{text}");
        Ok(())
    }
}
