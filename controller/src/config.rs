//! The controller's configuration: the mission, the vehicle's calibration, and the
//! tuning of planner, follower and safety. TOML, every field defaulted (`Default` is
//! the seed paper's mission on the golf car), errors naming the file, line and field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use ugv_fields::{
    Bound, FieldError, FieldPath, Range, angle_deg, coordinate, positive_up_to, within,
};

use crate::ranges::{
    ACCEL, BRAKE_DECEL, DEAD_TIME, GOAL_TOLERANCE, GPS_RATE, LENGTH, MARGIN, MAX_SPEED,
    MAX_STEER_DEG, MOUNT, RADIUS, REAR_OVERHANG, SPEED, SPEED_TIME_CONSTANT, STEER_TIME_CONSTANT,
    WHEELBASE, WIDTH,
};

/// Why a configuration was refused.
pub type ConfigError = ugv_fields::FileError;

pub use firmware_bridge::geodesy::Datum;

pub use crate::route::Mission;

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
    /// The footprint: length, width and the rear bumper's distance behind the rear
    /// axle, metres (passages narrower than the circle are checked with it).
    pub length: f64,
    pub width: f64,
    pub rear_overhang: f64,
    /// GPS antenna position in the vehicle frame (x forward, y left of the rear axle).
    pub antenna_x: f64,
    pub antenna_y: f64,
    /// Laser scanner mounting pose in the vehicle frame; yaw in degrees.
    pub laser_x: f64,
    pub laser_y: f64,
    pub laser_yaw_deg: f64,
    /// The steering actuator's dead time, seconds, as measured on the car: the state is
    /// propagated over it (with the commands still on their way) before planning and
    /// steering, so the law acts on where the car will be when the command bites.
    pub steer_dead_time_s: f64,
    /// The steering actuator's first-order time constant, seconds (the same prediction).
    pub steer_time_constant_s: f64,
    /// The speed loop's dead time and first-order time constant, seconds, as measured
    /// on the car: a car at speed v rolls on about v times their sum after a lower
    /// speed is commanded, so every stop (the path's end, the goal, the end of a
    /// reversal) is commanded that much earlier.
    pub speed_dead_time_s: f64,
    pub speed_time_constant_s: f64,
    /// Deceleration at full brake, m/s^2, as measured on the car: what a stop that
    /// the speed loop alone cannot make in time brakes with, and what the actuator
    /// monitor expects of a commanded brake (`safety/monitor.rs`).
    pub brake_decel: f64,
}

impl Vehicle {
    /// How far the car at speed `v` rolls on before a lower speed commanded now takes
    /// hold: the speed loop's dead time and time constant at that speed, metres.
    pub fn coast_m(&self, v: f64) -> f64 {
        v.abs() * (self.speed_dead_time_s + self.speed_time_constant_s)
    }
}

impl Default for Vehicle {
    fn default() -> Self {
        let car = crate::car::PAPER_CAR;
        Vehicle {
            wheelbase: car.wheelbase,
            max_steer_deg: car.max_steer_deg,
            steer_rate_deg_s: 0.0,
            max_speed: car.max_speed,
            radius: car.radius,
            length: car.length,
            width: car.width,
            rear_overhang: car.rear_overhang,
            antenna_x: car.antenna[0],
            antenna_y: car.antenna[1],
            laser_x: car.laser[0],
            laser_y: car.laser[1],
            laser_yaw_deg: car.laser_yaw_deg,
            steer_dead_time_s: car.steer_dead_time_s,
            steer_time_constant_s: car.steer_time_constant_s,
            speed_dead_time_s: car.speed_dead_time_s,
            speed_time_constant_s: car.speed_time_constant_s,
            brake_decel: car.brake_decel,
        }
    }
}

/// Planner tuning (the paper leaves T_s, t_f and the margins open).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Replanning period T_s, seconds.
    pub replan_period_s: f64,
    /// The local goal lies this far along the route ahead of the car's place on it
    /// (the receding horizon; within the laser's range), metres.
    pub horizon_m: f64,
    /// A local goal inside an obstacle is moved on along the route, or else back
    /// towards the car down to this distance, metres.
    pub horizon_min_m: f64,
    /// Added to the vehicle radius for every obstacle, metres.
    pub safety_margin: f64,
    /// Passages narrower than the planning circle: when no path clears it, paths are
    /// planned with half the car's width plus this as the circle and taken only where
    /// the car's rectangle clears every obstacle by this, metres (a gate of car width
    /// plus twice this, plus the walls' perceived half thickness, passes).
    pub passage_margin: f64,
    /// Speed through such a passage, m/s.
    pub passage_speed: f64,
    /// Give way to the right of oncoming traffic (false: to the left).
    pub keep_right: bool,
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
    /// Recovery: standing still with no feasible forward path for this long, the car
    /// reverses along a checked path and replans, seconds.
    pub recover_after_s: f64,
    /// Length of one reversal (the rear axle's arc), metres.
    pub reverse_distance_m: f64,
    /// Speed of a reversal (a magnitude: THROTTLE_CMD in gear R), m/s.
    pub reverse_speed: f64,
    /// Reversals allowed before progress; then (or with no clear path backwards) a
    /// controlled stop.
    pub max_reversals: u32,
    /// Progress along the route past the place of the last reversal that gives the
    /// car its `max_reversals` again (a later dead end on a long route is a new one),
    /// metres.
    pub reversal_reset_m: f64,
    /// Manoeuvres (where no polynomial path is feasible: a Hybrid A* search over the
    /// local map, forward and backward): the clearance the car's rectangle keeps from
    /// every obstacle, metres.
    pub manoeuvre_margin: f64,
    /// A car hemmed in at `manoeuvre_margin` (every step from where it stands comes
    /// nearer an obstacle than that) creeps out on an escape that keeps twice this,
    /// else this, until the full margin clears it again, metres.
    pub manoeuvre_escape_margin: f64,
    /// Speed of a manoeuvre's forward segments, m/s (its backward ones go at
    /// `reverse_speed`).
    pub manoeuvre_speed: f64,
    /// Fraction of the steering limit a manoeuvre may use.
    pub manoeuvre_steer_usage: f64,
    /// Expansions one manoeuvre search may take (a bound on its effort that does not
    /// depend on the machine's speed).
    pub manoeuvre_expansions: u32,
    /// New manoeuvres taken without `manoeuvre_progress_m` of progress along the route
    /// past the best before; then a controlled stop (a dead end shuffled in for ever is
    /// no way through).
    pub max_manoeuvres: u32,
    pub manoeuvre_progress_m: f64,
    /// A manoeuvre backs only into space the laser has seen (it looks forward) or the
    /// car stood in; at the start, a rectangle behind the rear bumper this deep and
    /// `seen_behind_at_start_width_m` wide (centred) counts as seen: the operator who
    /// starts the mission checks it, metres.
    pub seen_behind_at_start_m: f64,
    pub seen_behind_at_start_width_m: f64,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            replan_period_s: 0.5,
            horizon_m: 20.0,
            horizon_min_m: 8.0,
            safety_margin: 0.3,
            passage_margin: 0.25,
            passage_speed: 1.0,
            keep_right: true,
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
            recover_after_s: 1.0,
            reverse_distance_m: 4.0,
            reverse_speed: 0.5,
            max_reversals: 2,
            reversal_reset_m: 10.0,
            manoeuvre_margin: 0.25,
            manoeuvre_escape_margin: 0.05,
            manoeuvre_speed: 0.8,
            manoeuvre_steer_usage: 0.8,
            manoeuvre_expansions: 20_000,
            max_manoeuvres: 10,
            manoeuvre_progress_m: 1.0,
            seen_behind_at_start_m: 2.6,
            seen_behind_at_start_width_m: 1.2,
        }
    }
}

/// Localisation tuning: how fixes are filtered and how the steering sensor's bias is
/// estimated.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalisationConfig {
    /// Time constant of the fix filter for RTK fixed fixes, seconds: each fix pulls the
    /// dead-reckoned pose (position and heading) towards it by 1 - exp(-dt / this) (at
    /// most half way), dt the time since the last fix (0: every fix is taken as it is).
    pub fix_time_constant_s: f64,
    /// The same for RTK float (and worse) fixes, which are noisier, seconds.
    pub float_fix_time_constant_s: f64,
    /// Gain of the steering-bias estimator per metre window driven straight-ish at
    /// speed (0: no estimation): the bias moves by this fraction of what the window's
    /// heading change, against the dead-reckoned one, says is left.
    pub steer_bias_gain: f64,
    /// The estimated steering bias stays within +- this, degrees.
    pub max_steer_bias_deg: f64,
}

impl Default for LocalisationConfig {
    fn default() -> Self {
        LocalisationConfig {
            fix_time_constant_s: 0.5,
            float_fix_time_constant_s: 1.25,
            steer_bias_gain: 0.2,
            max_steer_bias_deg: 5.0,
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
    /// The GPS receiver's configured epoch rate, 1-20 Hz: between fixes the pose is
    /// dead-reckoned, and the GPS timeout follows from it unless set.
    pub gps_rate_hz: f64,
    /// No fix for this long is GPS loss, seconds; default [`SafetyConfig::gps_timeout`]
    /// (2.5 epochs, at least 0.5 s).
    pub gps_timeout_s: Option<f64>,
    pub laser_timeout_s: f64,
    pub report_timeout_s: f64,
    /// Before enabling the ECUs, every input (fix with heading, scan, both reports)
    /// must have been fresh this long without a break, and the first replanning
    /// done: start-up transients (processes still starting, a stalled bus, the first
    /// planning) pass while the ECUs are disabled, not as an estop; seconds, 0-10.
    pub settle_s: f64,
    /// Accept RTK float (true) or only RTK fixed (false).
    pub accept_rtk_float: bool,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            gps_rate_hz: 10.0,
            gps_timeout_s: None,
            laser_timeout_s: 0.25,
            report_timeout_s: 0.25,
            settle_s: 0.5,
            accept_rtk_float: true,
        }
    }
}

/// Epochs a GPS may miss before it counts as lost (with the derived timeout).
const GPS_EPOCHS_MISSED: f64 = 2.5;
/// The derived GPS timeout is never shorter than this (at high rates a few missed
/// epochs are no loss), seconds.
const GPS_TIMEOUT_MIN: f64 = 0.5;

impl SafetyConfig {
    /// How long without a fix is GPS loss: `gps_timeout_s` if set, else 2.5 epochs
    /// at `gps_rate_hz` and at least 0.5 s (0.5 s at 2-20 Hz, 2.5 s at 1 Hz).
    pub fn gps_timeout(&self) -> f64 {
        self.gps_timeout_s
            .unwrap_or((GPS_EPOCHS_MISSED / self.gps_rate_hz).max(GPS_TIMEOUT_MIN))
    }
}

/// The whole configuration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    pub mission: Mission,
    pub vehicle: Vehicle,
    pub localisation: LocalisationConfig,
    pub planner: PlannerConfig,
    pub follower: FollowerConfig,
    pub safety: SafetyConfig,
    pub perception: crate::perception::PerceptionConfig,
}

impl ControllerConfig {
    /// Parse and check TOML text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<ControllerConfig, ConfigError> {
        let cfg: ControllerConfig = ugv_fields::parse_toml(text, file)?;
        cfg.validate().map_err(|e| e.located(text, file))?;
        Ok(cfg)
    }

    pub fn load(path: &Path) -> Result<ControllerConfig, ConfigError> {
        let text = ugv_fields::read_file(path)?;
        ControllerConfig::from_toml(&text, &path.display().to_string())
    }

    /// The first field that makes no sense, and why: every physical parameter finite
    /// and within its plausible range (the table [`BOUNDS`], each range
    /// with its source: the golf car, the DBC's signal ranges, the datasheets), the
    /// fields' relations (speeds up to the top speed, the footprint inside the
    /// planning circle, a goal not reached at the start), and the perception tuning
    /// passes perception's own checks. `Controller::new` runs this too, so nothing
    /// builds a controller from a configuration `check-config` would refuse.
    pub fn validate(&self) -> Result<(), FieldError> {
        ugv_fields::check_bounds(self, BOUNDS)?;
        self.check_mission()?;
        self.check_vehicle()?;
        self.check_planner()?;
        let f = &self.follower;
        if f.kind == FollowerKind::Anfis && f.anfis_model.is_none() {
            return Err(FieldError::new(
                FieldPath::of(&["follower", "anfis_model"]),
                "is required when follower.kind = \"anfis\"",
            ));
        }
        let s = &self.safety;
        if let Some(t) = s.gps_timeout_s
            && t * s.gps_rate_hz < 1.0
        {
            return Err(FieldError::new(
                FieldPath::of(&["safety", "gps_timeout_s"]),
                format!(
                    "{t} s is shorter than one epoch at safety.gps_rate_hz = {} Hz",
                    s.gps_rate_hz
                ),
            ));
        }
        self.perception.validate().map_err(|e| match e {
            crate::perception::PerceptionError::InvalidConfig { field, message } => {
                FieldError::new(FieldPath::of(&["perception", field]), message)
            }
            other => FieldError::new(FieldPath::of(&["perception"]), other.to_string()),
        })
    }

    /// The mission's datum, places and route (its ranges checked by the table); the
    /// goal not reached at the start.
    fn check_mission(&self) -> Result<(), FieldError> {
        let m = &self.mission;
        let at = |k: &'static str| FieldPath::of(&["mission", k]);
        let d = &m.datum;
        within(
            &at("datum").key("latitude"),
            d.latitude,
            -89.0,
            89.0,
            "degrees",
        )?;
        within(
            &at("datum").key("longitude"),
            d.longitude,
            -180.0,
            180.0,
            "degrees",
        )?;
        within(
            &at("datum").key("altitude"),
            d.altitude,
            -1_000.0,
            10_000.0,
            "m",
        )?;
        coordinate(&at("start_x"), m.start_x)?;
        coordinate(&at("start_y"), m.start_y)?;
        coordinate(&at("goal_x"), m.goal_x)?;
        coordinate(&at("goal_y"), m.goal_y)?;
        if let Some(h) = m.goal_heading_deg {
            angle_deg(&at("goal_heading_deg"), h)?;
        }
        if let Some(v) = m.goal_speed_limit {
            up_to_max_speed(&at("goal_speed_limit"), v, self.vehicle.max_speed)?;
        }
        crate::route::check_waypoints(
            &at("waypoints"),
            &m.waypoints,
            (m.start_x, m.start_y),
            (m.goal_x, m.goal_y),
            &at("goal_x"),
            self.vehicle.max_speed,
        )?;
        crate::route::check_goal_not_at_start(
            &at("goal_tolerance"),
            m.goal_tolerance,
            (m.start_x, m.start_y),
            (m.goal_x, m.goal_y),
        )
    }

    /// The vehicle's relations: the rear overhang within the length, the footprint
    /// inside the planning circle (with the safety margin).
    fn check_vehicle(&self) -> Result<(), FieldError> {
        let v = &self.vehicle;
        within(
            &FieldPath::of(&["vehicle", "rear_overhang"]),
            v.rear_overhang,
            0.0,
            v.length,
            "m (up to length)",
        )?;
        angle_deg(
            &FieldPath::of(&["vehicle", "laser_yaw_deg"]),
            v.laser_yaw_deg,
        )?;
        let corner = (v.length - v.rear_overhang)
            .max(v.rear_overhang)
            .hypot(v.width / 2.0);
        if corner > v.radius + self.planner.safety_margin {
            return Err(FieldError::new(
                FieldPath::of(&["vehicle", "radius"]),
                format!(
                    "{} plus planner.safety_margin {} must contain the footprint (its farthest corner is {corner:.2} m from the rear axle)",
                    v.radius, self.planner.safety_margin
                ),
            ));
        }
        Ok(())
    }

    /// The planner's relations: the horizons ordered, the speeds up to the top speed,
    /// the pace fractions, the alignment angles ordered.
    fn check_planner(&self) -> Result<(), FieldError> {
        let pc = &self.planner;
        let at = |k: &'static str| FieldPath::of(&["planner", k]);
        let max_speed = self.vehicle.max_speed;
        within(
            &at("horizon_min_m"),
            pc.horizon_min_m,
            2.0,
            pc.horizon_m,
            "m (up to horizon_m)",
        )?;
        for (k, v) in [
            ("passage_speed", pc.passage_speed),
            ("cruise_speed", pc.cruise_speed),
            ("align_speed", pc.align_speed),
            ("reverse_speed", pc.reverse_speed),
            ("manoeuvre_speed", pc.manoeuvre_speed),
        ] {
            up_to_max_speed(&at(k), v, max_speed)?;
        }
        if pc.pace_fractions.is_empty() || pc.pace_fractions.len() > 32 {
            return Err(FieldError::new(
                at("pace_fractions"),
                format!("must be 1 to 32 fractions, has {}", pc.pace_fractions.len()),
            ));
        }
        for (i, f) in pc.pace_fractions.iter().enumerate() {
            crate::ranges::PACE_FRACTION.check(&at("pace_fractions").index(i), *f)?;
        }
        positive_up_to(&at("align_enter_deg"), pc.align_enter_deg, 90.0, "degrees")?;
        positive_up_to(&at("align_exit_deg"), pc.align_exit_deg, 90.0, "degrees")?;
        if !(pc.align_exit_deg < pc.align_enter_deg && pc.align_enter_deg < 90.0) {
            return Err(FieldError::new(
                at("align_enter_deg"),
                format!(
                    "need 0 < align_exit_deg < align_enter_deg < 90, have {} and {}",
                    pc.align_exit_deg, pc.align_enter_deg
                ),
            ));
        }
        Ok(())
    }
}

/// A speed (its range checked by the table) that must not exceed the top speed.
fn up_to_max_speed(path: &FieldPath, v: f64, max_speed: f64) -> Result<(), FieldError> {
    if v > max_speed {
        return Err(FieldError::new(
            path.clone(),
            format!("{v} exceeds vehicle.max_speed {max_speed}"),
        ));
    }
    Ok(())
}

/// One row of [`BOUNDS`]: `section.field` (always set) and its range.
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
pub const BOUNDS: &[Bound<ControllerConfig>] = &[
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
    row!(planner.manoeuvre_margin, MARGIN),
    row!(planner.manoeuvre_escape_margin, MARGIN),
    row!(planner.manoeuvre_speed, SPEED),
    row!(
        planner.manoeuvre_steer_usage,
        Range::new(0.1, 1.0, "", "a fraction of the steering limit")
    ),
    row!(
        planner.manoeuvre_expansions,
        Range::new(
            100.0,
            1e6,
            "",
            "search effort: at 20,000, p50 13 ms, p99 0.9 s here (BENCHMARKS.md)",
        )
    ),
    row!(
        planner.max_manoeuvres,
        Range::new(1.0, 1000.0, "", "manoeuvres before a controlled stop")
    ),
    row!(
        planner.manoeuvre_progress_m,
        Range::new(0.1, 100.0, "m", "progress along the route")
    ),
    row!(
        planner.seen_behind_at_start_m,
        Range::new(
            0.0,
            30.0,
            "m",
            "what an operator checks behind the car: a car length or so"
        )
    ),
    row!(
        planner.seen_behind_at_start_width_m,
        Range::new(
            0.0,
            60.0,
            "m",
            "what an operator checks behind the car: its width or so"
        )
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
