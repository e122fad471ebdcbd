//! Scenarios: the world, the vehicle, its devices and the verdict's criteria, as TOML.
//!
//! Every struct has a `Default` that is the seed paper's simulation (start (0,0)
//! heading 45 degrees, goal (30,15), one post of radius 3 m at (19,8)), so a scenario
//! file only states what differs. A malformed or inconsistent file is refused with an
//! error naming the file, the line and the field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use ugv_fields::{
    FieldError, FieldPath, LocatedError, angle_deg, coordinate, positive, positive_up_to, size,
    within,
};

/// The paper's scenario, shipped embedded as the default.
pub const PAPER_SCENARIO: &str = include_str!("../scenarios/paper.toml");

/// Why a scenario was refused.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("{file}: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// Syntax errors and unknown or mistyped fields (the TOML error names line and column).
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    /// A well-formed value that makes no sense (a negative radius, a goal inside a
    /// wall...), with the file and line it is on.
    #[error(transparent)]
    Invalid(#[from] LocatedError),
}

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
            length: 2.4,
            width: 1.2,
            rear_overhang: 0.375,
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
        SteeringConfig {
            dead_time_s: 0.02,
            time_constant_s: 0.08,
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
        ThrottleConfig {
            dead_time_s: 0.05,
            time_constant_s: 0.4,
            max_accel: 1.5,
            max_decel: 2.5,
            brake_decel: 4.0,
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
}

impl Default for CanConfig {
    fn default() -> Self {
        CanConfig {
            interface: "vcan0".to_owned(),
            fault_clear_ms: 250,
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
}

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    pub description: String,
    pub datum: Datum,
    pub start: Pose,
    pub goal: Goal,
    /// Points to pass in order before the goal (`[[waypoints]]`): with them the
    /// mission is a route, start, waypoints, goal; without, the one leg start-goal.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<ugv_controller::route::Waypoint>,
    pub obstacles: Vec<Obstacle>,
    pub vehicle: VehicleConfig,
    pub steering: SteeringConfig,
    pub throttle: ThrottleConfig,
    pub can: CanConfig,
    pub gps: crate::devices::gps::GpsConfig,
    pub laser: crate::devices::laser::LaserConfig,
    pub sim: SimConfig,
    pub success: SuccessCriteria,
    /// Which devices are simulated and which physical (all simulated by default).
    pub devices: crate::devices::map::DeviceMap,
    /// The controller's tuning for this scenario, where it differs from its defaults.
    pub controller: ControllerTuning,
    /// Faults injected during the run (`[[faults]]`), in the order written.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<crate::faults::FaultSpec>,
    /// What must follow the faults.
    pub expect: crate::faults::Expectations,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: "paper".to_owned(),
            description: "The seed paper's simulation: one post between start and goal".to_owned(),
            datum: Datum::default(),
            start: Pose {
                x: 0.0,
                y: 0.0,
                heading_deg: 45.0,
            },
            goal: Goal::default(),
            waypoints: Vec::new(),
            obstacles: vec![Obstacle::Circle {
                x: 19.0,
                y: 8.0,
                radius: 3.0,
                motion: None,
            }],
            vehicle: VehicleConfig::default(),
            steering: SteeringConfig::default(),
            throttle: ThrottleConfig::default(),
            can: CanConfig::default(),
            gps: Default::default(),
            laser: Default::default(),
            sim: SimConfig::default(),
            success: SuccessCriteria::default(),
            devices: Default::default(),
            controller: ControllerTuning::default(),
            faults: Vec::new(),
            expect: Default::default(),
        }
    }
}

fn check_points(path: &FieldPath, points: &[[f64; 2]], min: usize) -> Result<(), FieldError> {
    if points.len() < min {
        return Err(FieldError::new(
            path.clone(),
            format!("needs at least {min} points, has {}", points.len()),
        ));
    }
    if points.len() > MAX_POINTS {
        return Err(FieldError::new(
            path.clone(),
            format!(
                "has {} points, at most {MAX_POINTS} are allowed",
                points.len()
            ),
        ));
    }
    for (i, p) in points.iter().enumerate() {
        coordinate(&path.index(i), p[0])?;
        coordinate(&path.index(i), p[1])?;
    }
    Ok(())
}

/// Most obstacles in a scenario.
const MAX_OBSTACLES: usize = 10_000;

/// Most points of a wall or a waypoint path.
const MAX_POINTS: usize = 10_000;

/// The fastest an obstacle may move, m/s (a car on a course road, with room to spare).
const MAX_OBSTACLE_SPEED: f64 = 50.0;

fn check_motion(path: &FieldPath, motion: &Option<Motion>) -> Result<(), FieldError> {
    match motion {
        None => Ok(()),
        Some(Motion::Velocity { vx, vy }) => {
            within(
                &path.key("vx"),
                *vx,
                -MAX_OBSTACLE_SPEED,
                MAX_OBSTACLE_SPEED,
                "m/s",
            )?;
            within(
                &path.key("vy"),
                *vy,
                -MAX_OBSTACLE_SPEED,
                MAX_OBSTACLE_SPEED,
                "m/s",
            )
        }
        Some(Motion::Waypoints { points, speed, .. }) => {
            check_points(&path.key("points"), points, 2)?;
            positive_up_to(&path.key("speed"), *speed, MAX_OBSTACLE_SPEED, "m/s")
        }
    }
}

impl Scenario {
    /// Parse and validate TOML text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<Scenario, ScenarioError> {
        let scenario: Scenario = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            file: file.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        scenario.validate().map_err(|e| e.located(text, file))?;
        Ok(scenario)
    }

    /// The scenario with the faults of `plan` added after its own (and its `[expect]`
    /// when the plan has one), validated again.
    pub fn with_fault_plan(
        mut self,
        plan: crate::faults::plan::PlanFile,
    ) -> Result<Scenario, FieldError> {
        self.faults.extend(plan.faults);
        if let Some(expect) = plan.expect {
            self.expect = expect;
        }
        self.validate()?;
        Ok(self)
    }

    /// Read a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            file: path.display().to_string(),
            source,
        })?;
        Scenario::from_toml(&text, &path.display().to_string())
    }

    /// The paper's scenario (embedded).
    pub fn paper() -> Result<Scenario, ScenarioError> {
        Scenario::from_toml(PAPER_SCENARIO, "scenarios/paper.toml (embedded)")
    }

    /// Load `path`, or the paper's scenario when none is given.
    pub fn load_or_paper(path: Option<&PathBuf>) -> Result<Scenario, ScenarioError> {
        match path {
            Some(p) => Scenario::load(p),
            None => Scenario::paper(),
        }
    }

    /// The first field that makes no sense, and why: every number finite, of the
    /// right sign and within plausible bounds (positions within
    /// [`ugv_fields::PLAUSIBLE_COORDINATE`], so the physics' `f32` never sees an
    /// infinity), the DBC's signal ranges where a value ends up on the bus, and the
    /// start and goal usable.
    pub(crate) fn validate(&self) -> Result<(), FieldError> {
        let at = |keys: &[&'static str]| FieldPath::of(keys);
        crate::faults::plan::validate_plan(&self.faults, &self.expect)?;
        let d = &self.datum;
        within(
            &at(&["datum", "latitude"]),
            d.latitude,
            -89.0,
            89.0,
            "degrees",
        )?;
        within(
            &at(&["datum", "longitude"]),
            d.longitude,
            -180.0,
            180.0,
            "degrees",
        )?;
        within(
            &at(&["datum", "altitude"]),
            d.altitude,
            -1_000.0,
            10_000.0,
            "m",
        )?;
        coordinate(&at(&["start", "x"]), self.start.x)?;
        coordinate(&at(&["start", "y"]), self.start.y)?;
        angle_deg(&at(&["start", "heading_deg"]), self.start.heading_deg)?;
        coordinate(&at(&["goal", "x"]), self.goal.x)?;
        coordinate(&at(&["goal", "y"]), self.goal.y)?;
        if let Some(h) = self.goal.heading_deg {
            angle_deg(&at(&["goal", "heading_deg"]), h)?;
        }
        positive_up_to(&at(&["goal", "tolerance"]), self.goal.tolerance, 50.0, "m")?;
        if let Some(v) = self.goal.speed_limit {
            positive_up_to(
                &at(&["goal", "speed_limit"]),
                v,
                self.vehicle.max_speed,
                "m/s (vehicle.max_speed)",
            )?;
        }
        if let Some(r) = self.controller.detection_radius {
            positive_up_to(
                &at(&["controller", "detection_radius"]),
                r,
                self.laser.spec().range_max,
                "m (the laser's range_max)",
            )?;
        }
        // The controller's own rule (its mission.waypoints): every leg has a length.
        ugv_controller::route::check_waypoints(
            &at(&["waypoints"]),
            &self.waypoints,
            (self.start.x, self.start.y),
            (self.goal.x, self.goal.y),
            &at(&["goal"]),
            self.vehicle.max_speed,
        )?;

        let v = &self.vehicle;
        let vp = |k: &'static str| at(&["vehicle", k]);
        for (k, x) in [
            ("wheelbase", v.wheelbase),
            ("length", v.length),
            ("width", v.width),
            ("radius", v.radius),
        ] {
            positive_up_to(&vp(k), x, 20.0, "m")?;
        }
        within(&vp("rear_overhang"), v.rear_overhang, 0.0, 20.0, "m")?;
        if v.rear_overhang + v.wheelbase > v.length {
            return Err(FieldError::new(
                vp("wheelbase"),
                format!(
                    "rear_overhang {} + wheelbase {} exceed the length {}",
                    v.rear_overhang, v.wheelbase, v.length
                ),
            ));
        }
        if !(v.max_steer_deg > 0.0 && v.max_steer_deg < 60.0) {
            return Err(FieldError::new(
                vp("max_steer_deg"),
                format!("must be in (0, 60), is {}", v.max_steer_deg),
            ));
        }
        // The DBC's ranges bound what can be commanded at all.
        if v.max_steer_deg > 45.0 {
            return Err(FieldError::new(
                vp("max_steer_deg"),
                "exceeds the DBC's TargetAngle range of 45 degrees",
            ));
        }
        positive(&vp("max_speed"), v.max_speed)?;
        if v.max_speed > 10.0 {
            return Err(FieldError::new(
                vp("max_speed"),
                "exceeds the DBC's TargetSpeed range of 10 m/s",
            ));
        }

        let s = &self.steering;
        let sp = |k: &'static str| at(&["steering", k]);
        within(&sp("dead_time_s"), s.dead_time_s, 0.0, 5.0, "s")?;
        positive_up_to(&sp("time_constant_s"), s.time_constant_s, 10.0, "s")?;
        positive_up_to(&sp("max_rate_deg_s"), s.max_rate_deg_s, 1_000.0, "deg/s")?;
        // The DBC's MotorCurrent range.
        within(&sp("idle_current_a"), s.idle_current_a, 0.0, 25.5, "A")?;
        within(
            &sp("current_per_rate_a"),
            s.current_per_rate_a,
            0.0,
            10.0,
            "A per deg/s",
        )?;
        within(&sp("bias_deg"), s.bias_deg, -10.0, 10.0, "degrees")?;
        let t = &self.throttle;
        let tp = |k: &'static str| at(&["throttle", k]);
        within(&tp("dead_time_s"), t.dead_time_s, 0.0, 5.0, "s")?;
        positive_up_to(&tp("time_constant_s"), t.time_constant_s, 10.0, "s")?;
        positive_up_to(&tp("max_accel"), t.max_accel, 20.0, "m/s^2")?;
        positive_up_to(&tp("max_decel"), t.max_decel, 20.0, "m/s^2")?;
        positive_up_to(&tp("brake_decel"), t.brake_decel, 20.0, "m/s^2")?;
        within(
            &tp("throttle_per_speed"),
            t.throttle_per_speed,
            0.0,
            100.0,
            "% per m/s",
        )?;
        if self.can.interface.is_empty() || self.can.interface.len() > 15 {
            return Err(FieldError::new(
                at(&["can", "interface"]),
                "must be 1 to 15 characters",
            ));
        }
        if self.can.fault_clear_ms > 60_000 {
            return Err(FieldError::new(
                at(&["can", "fault_clear_ms"]),
                format!("must be at most 60000 ms, is {}", self.can.fault_clear_ms),
            ));
        }

        // A section's fields may be nested (`rtk.hdop`): each part is a key.
        let section = |name: &'static str, field: &'static str| {
            field
                .split('.')
                .fold(at(&[name]), |path, key| path.key(key))
        };
        self.gps
            .validate()
            .map_err(|e| FieldError::new(section("gps", e.field), e.message))?;
        self.laser
            .validate()
            .map_err(|e| FieldError::new(section("laser", e.field), e.message))?;
        self.devices
            .validate(&self.can.interface)
            .map_err(|e| device_field(&e))?;
        let sim = &self.sim;
        within(
            &at(&["sim", "physics_hz"]),
            sim.physics_hz,
            10.0,
            2000.0,
            "Hz",
        )?;
        positive_up_to(
            &at(&["sim", "time_limit_s"]),
            sim.time_limit_s,
            86_400.0,
            "s",
        )?;
        within(
            &at(&["success", "min_clearance"]),
            self.success.min_clearance,
            0.0,
            100.0,
            "m",
        )?;

        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(FieldError::new(
                at(&["obstacles"]),
                format!(
                    "has {} obstacles, at most {MAX_OBSTACLES} are allowed",
                    self.obstacles.len()
                ),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            let p = at(&["obstacles"]).index(i);
            match o {
                Obstacle::Circle {
                    x,
                    y,
                    radius,
                    motion,
                } => {
                    coordinate(&p.key("x"), *x)?;
                    coordinate(&p.key("y"), *y)?;
                    size(&p.key("radius"), *radius)?;
                    check_motion(&p.key("motion"), motion)?;
                }
                Obstacle::Box {
                    x,
                    y,
                    length,
                    width,
                    heading_deg,
                    motion,
                } => {
                    coordinate(&p.key("x"), *x)?;
                    coordinate(&p.key("y"), *y)?;
                    size(&p.key("length"), *length)?;
                    size(&p.key("width"), *width)?;
                    angle_deg(&p.key("heading_deg"), *heading_deg)?;
                    check_motion(&p.key("motion"), motion)?;
                }
                Obstacle::Wall { points, thickness } => {
                    check_points(&p.key("points"), points, 2)?;
                    size(&p.key("thickness"), *thickness)?;
                    for (j, w) in points.windows(2).enumerate() {
                        if w[0] == w[1] {
                            return Err(FieldError::new(
                                p.key("points").index(j + 1),
                                "repeats the previous point",
                            ));
                        }
                    }
                }
            }
        }
        // Consistency: the start and the goal must be free (the footprint at the start,
        // the planner's circle at the goal), or nothing would ever pass.
        let world = crate::world::World::new(self);
        let start = crate::vehicle::VehicleState::at(&self.start);
        if let Some(i) = world.footprint_hits(&self.vehicle, &start).first() {
            return Err(FieldError::new(
                at(&["start"]),
                format!("the vehicle's footprint at the start overlaps obstacles[{i}]"),
            ));
        }
        if self.success.reach_goal
            && let Some(i) = world
                .circle_hits(self.goal.x, self.goal.y, self.goal.tolerance.min(0.5))
                .first()
        {
            return Err(FieldError::new(
                at(&["goal"]),
                format!(
                    "the goal lies inside obstacles[{i}] at t = 0 but success.reach_goal is true"
                ),
            ));
        }
        Ok(())
    }
}

/// The error of a device map read from its own bench file `file` (text `text`).
pub(crate) fn invalid_device(
    text: &str,
    file: &str,
    e: &crate::devices::map::DeviceError,
) -> ScenarioError {
    ScenarioError::Invalid(device_field(e).located(text, file))
}

/// A device map error as a field error of the whole file.
fn device_field(e: &crate::devices::map::DeviceError) -> FieldError {
    FieldError::new(
        FieldPath::of(&["devices", e.path[0], e.path[1]]),
        e.message.clone(),
    )
}

/// Fault plan files load like scenarios (their errors are scenario errors).
impl crate::faults::plan::PlanFile {
    /// Parse and validate TOML text; `file` names it in errors.
    pub fn from_toml(
        text: &str,
        file: &str,
    ) -> Result<crate::faults::plan::PlanFile, ScenarioError> {
        let plan: crate::faults::plan::PlanFile =
            toml::from_str(text).map_err(|e| ScenarioError::Parse {
                file: file.to_owned(),
                message: e.to_string().trim_end().to_owned(),
            })?;
        crate::faults::plan::validate_plan(&plan.faults, &plan.expect.clone().unwrap_or_default())
            .map_err(|e| e.located(text, file))?;
        Ok(plan)
    }

    pub fn load(path: &std::path::Path) -> Result<crate::faults::plan::PlanFile, ScenarioError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            file: file.clone(),
            source,
        })?;
        crate::faults::plan::PlanFile::from_toml(&text, &file)
    }
}
