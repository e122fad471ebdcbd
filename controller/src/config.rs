//! The controller's configuration: the mission, the vehicle's calibration, and the
//! tuning of planner, follower and safety. TOML, every field defaulted (`Default` is
//! the seed paper's mission on the golf car), errors naming the file, line and field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    #[error("{file}: {field}: {message}")]
    Invalid {
        file: String,
        field: String,
        message: String,
    },
}

pub use firmware_bridge::geodesy::Datum;

/// Where to go: the straight line from `start` to `goal` is the reference the planner
/// keeps close to (the paper's L).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Mission {
    pub datum: Datum,
    pub start_x: f64,
    pub start_y: f64,
    pub goal_x: f64,
    pub goal_y: f64,
    /// Heading at the goal, degrees CCW from East; default: along the line.
    pub goal_heading_deg: Option<f64>,
    /// Distance from the goal at which the mission is complete, metres.
    pub goal_tolerance: f64,
}

impl Default for Mission {
    fn default() -> Self {
        Mission {
            datum: Datum::default(),
            start_x: 0.0,
            start_y: 0.0,
            goal_x: 30.0,
            goal_y: 15.0,
            goal_heading_deg: None,
            goal_tolerance: 1.0,
        }
    }
}

/// The golf car's calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Vehicle {
    pub wheelbase: f64,
    /// Road-wheel angle limit of the steering actuator, degrees.
    pub max_steer_deg: f64,
    /// Steering rate to ask for, degrees per second (0: the ECU's own limit).
    pub steer_rate_deg_s: f64,
    pub max_speed: f64,
    /// The circle the planner treats the car as, around the rear axle (the paper's r_0).
    pub radius: f64,
    /// GPS antenna position in the vehicle frame (x forward, y left of the rear axle).
    pub antenna_x: f64,
    pub antenna_y: f64,
    /// Laser scanner mounting pose in the vehicle frame; yaw in degrees.
    pub laser_x: f64,
    pub laser_y: f64,
    pub laser_yaw_deg: f64,
}

impl Default for Vehicle {
    fn default() -> Self {
        Vehicle {
            wheelbase: 1.65,
            max_steer_deg: 35.0,
            steer_rate_deg_s: 0.0,
            max_speed: 6.7,
            radius: 2.0,
            antenna_x: 0.5,
            antenna_y: 0.0,
            laser_x: 2.0,
            laser_y: 0.0,
            laser_yaw_deg: 0.0,
        }
    }
}

/// Planner tuning (the paper leaves T_s, t_f and the margins open).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Replanning period T_s, seconds.
    pub replan_period_s: f64,
    /// Added to the vehicle radius for every obstacle, metres.
    pub safety_margin: f64,
    /// Cruise speed; t_f - t_k = (x_f - x_k) / cruise_speed, m/s.
    pub cruise_speed: f64,
    /// Fraction of the steering limit a planned path may use.
    pub steer_usage: f64,
    /// Closer than this to the goal (along the line), no replanning, metres.
    pub final_approach: f64,
    /// Paces tried when a moving obstacle is in view, as fractions of the cruise speed,
    /// fastest first: t_f - t_k = (x_f - x_k) / (fraction * cruise_speed) becomes a
    /// second free parameter of the plan, so the car can yield by slowing down. The
    /// fastest pace with a feasible path is taken; with none, the car stops.
    pub pace_fractions: Vec<f64>,
    /// Moving obstacles are planned as swept over +- this long along their velocity
    /// (their estimated timing, and the car's, may be off by that much), seconds.
    pub moving_time_margin_s: f64,
    /// Added to the radius of moving obstacles on top of `safety_margin`, metres.
    pub moving_margin: f64,
    /// Among the feasible paces the one with the least mean squared deviation from the
    /// start-goal line (m^2) plus this weight times the time per metre lost against the
    /// fastest pace (s/m) is taken, m^3/s.
    pub pace_time_weight: f64,
    /// When the car heads more than this away from the start-goal line (a y(x) path
    /// cannot start steeper than 90 degrees, nor well within the steering limit beyond
    /// about this), it first turns towards the goal on full planned lock, degrees.
    pub align_enter_deg: f64,
    /// The turn ends (and planning resumes) once within this of the line, degrees.
    pub align_exit_deg: f64,
    /// Speed of that turn, m/s.
    pub align_speed: f64,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            replan_period_s: 0.5,
            safety_margin: 0.3,
            cruise_speed: 2.0,
            steer_usage: 0.85,
            final_approach: 1.5,
            pace_fractions: vec![1.0, 0.8, 0.6, 0.45, 0.3, 0.2],
            moving_time_margin_s: 1.0,
            moving_margin: 0.2,
            pace_time_weight: 2.0,
            align_enter_deg: 65.0,
            align_exit_deg: 30.0,
            align_speed: 1.0,
        }
    }
}

/// Which steering law follows the planned path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum FollowerKind {
    /// The paper's optimal control law (feed-forward along the path) with feedback.
    Optimal,
    /// An ANFIS model trained offline (`ugv-controller anfis train`).
    Anfis,
}

/// Path-follower tuning.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FollowerConfig {
    pub kind: FollowerKind,
    /// The ANFIS model (JSON) when kind = "anfis".
    pub anfis_model: Option<PathBuf>,
    /// Natural frequency and damping of the lateral error dynamics, rad/s and 1.
    pub omega: f64,
    pub zeta: f64,
    /// Lateral acceleration allowed in curves, m/s^2.
    pub max_lateral_accel: f64,
    /// Deceleration used to approach the goal and to stop, m/s^2.
    pub decel: f64,
    /// Acceleration limit sent to the throttle ECU, m/s^2.
    pub accel_limit: f64,
}

impl Default for FollowerConfig {
    fn default() -> Self {
        FollowerConfig {
            kind: FollowerKind::Optimal,
            anfis_model: None,
            omega: 0.9,
            zeta: 0.8,
            max_lateral_accel: 1.5,
            decel: 1.0,
            accel_limit: 1.0,
        }
    }
}

/// When to stop: timeouts of the sensors and the actuators' reports. The ECUs guard
/// the commands themselves (100 ms, golf_car.dbc); the controller's report timeout
/// only has to catch a dead ECU, so it allows a few missed reports (25 at 10 ms).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyConfig {
    pub gps_timeout_s: f64,
    pub laser_timeout_s: f64,
    pub report_timeout_s: f64,
    /// Accept RTK float (true) or only RTK fixed (false).
    pub accept_rtk_float: bool,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            gps_timeout_s: 0.5,
            laser_timeout_s: 0.25,
            report_timeout_s: 0.25,
            accept_rtk_float: true,
        }
    }
}

/// The whole configuration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    pub mission: Mission,
    pub vehicle: Vehicle,
    pub planner: PlannerConfig,
    pub follower: FollowerConfig,
    pub safety: SafetyConfig,
    pub perception: crate::perception::PerceptionConfig,
}

impl ControllerConfig {
    /// Parse and check TOML text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<ControllerConfig, ConfigError> {
        let cfg: ControllerConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        cfg.validate()
            .map_err(|(field, message)| ConfigError::Invalid {
                file: file.to_owned(),
                field,
                message,
            })?;
        Ok(cfg)
    }

    pub fn load(path: &Path) -> Result<ControllerConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            file: path.display().to_string(),
            source,
        })?;
        ControllerConfig::from_toml(&text, &path.display().to_string())
    }

    /// The first field that makes no sense, and why.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let fields: [(&str, f64, bool); 22] = [
            ("mission.start_x", self.mission.start_x, false),
            ("mission.start_y", self.mission.start_y, false),
            ("mission.goal_x", self.mission.goal_x, false),
            ("mission.goal_y", self.mission.goal_y, false),
            ("mission.goal_tolerance", self.mission.goal_tolerance, true),
            ("vehicle.wheelbase", self.vehicle.wheelbase, true),
            ("vehicle.max_steer_deg", self.vehicle.max_steer_deg, true),
            ("vehicle.max_speed", self.vehicle.max_speed, true),
            ("vehicle.radius", self.vehicle.radius, true),
            ("vehicle.antenna_x", self.vehicle.antenna_x, false),
            ("vehicle.antenna_y", self.vehicle.antenna_y, false),
            ("vehicle.laser_x", self.vehicle.laser_x, false),
            ("vehicle.laser_y", self.vehicle.laser_y, false),
            (
                "planner.replan_period_s",
                self.planner.replan_period_s,
                true,
            ),
            ("planner.cruise_speed", self.planner.cruise_speed, true),
            ("planner.steer_usage", self.planner.steer_usage, true),
            ("follower.omega", self.follower.omega, true),
            ("follower.zeta", self.follower.zeta, true),
            ("follower.decel", self.follower.decel, true),
            ("safety.gps_timeout_s", self.safety.gps_timeout_s, true),
            ("safety.laser_timeout_s", self.safety.laser_timeout_s, true),
            (
                "safety.report_timeout_s",
                self.safety.report_timeout_s,
                true,
            ),
        ];
        for (name, v, positive) in fields {
            if !v.is_finite() {
                return Err((name.to_owned(), format!("{v} is not a finite number")));
            }
            if positive && v <= 0.0 {
                return Err((name.to_owned(), format!("must be positive, is {v}")));
            }
        }
        let m = &self.mission;
        if (m.goal_x - m.start_x).hypot(m.goal_y - m.start_y) < 1.0 {
            return Err((
                "mission.goal_x".to_owned(),
                "the goal must be at least 1 m from the start".to_owned(),
            ));
        }
        if !(-89.0..=89.0).contains(&m.datum.latitude)
            || !(-180.0..=180.0).contains(&m.datum.longitude)
        {
            return Err((
                "mission.datum".to_owned(),
                "latitude must be within ±89°, longitude within ±180°".to_owned(),
            ));
        }
        if self.vehicle.max_steer_deg >= 60.0 {
            return Err((
                "vehicle.max_steer_deg".to_owned(),
                "must be below 60 degrees".to_owned(),
            ));
        }
        if self.planner.steer_usage > 1.0 {
            return Err((
                "planner.steer_usage".to_owned(),
                "must not exceed 1".to_owned(),
            ));
        }
        if self.planner.pace_fractions.is_empty()
            || self
                .planner
                .pace_fractions
                .iter()
                .any(|f| !(f.is_finite() && *f > 0.0 && *f <= 1.0))
        {
            return Err((
                "planner.pace_fractions".to_owned(),
                "must be one or more fractions in (0, 1]".to_owned(),
            ));
        }
        for (name, v) in [
            (
                "planner.moving_time_margin_s",
                self.planner.moving_time_margin_s,
            ),
            ("planner.moving_margin", self.planner.moving_margin),
            ("planner.pace_time_weight", self.planner.pace_time_weight),
            ("planner.align_speed", self.planner.align_speed),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((name.to_owned(), format!("must not be negative, is {v}")));
            }
        }
        let pc = &self.planner;
        if !(pc.align_exit_deg > 0.0
            && pc.align_exit_deg < pc.align_enter_deg
            && pc.align_enter_deg < 90.0)
        {
            return Err((
                "planner.align_enter_deg".to_owned(),
                "need 0 < align_exit_deg < align_enter_deg < 90".to_owned(),
            ));
        }
        if self.planner.cruise_speed > self.vehicle.max_speed {
            return Err((
                "planner.cruise_speed".to_owned(),
                "exceeds vehicle.max_speed".to_owned(),
            ));
        }
        if self.follower.kind == FollowerKind::Anfis && self.follower.anfis_model.is_none() {
            return Err((
                "follower.anfis_model".to_owned(),
                "is required when follower.kind = \"anfis\"".to_owned(),
            ));
        }
        Ok(())
    }
}
