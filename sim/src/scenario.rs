//! Scenarios: the world, the vehicle, its devices and the verdict's criteria, as TOML.
//!
//! Every struct has a `Default` that is the seed paper's simulation (start (0,0)
//! heading 45 degrees, goal (30,15), one post of radius 3 m at (19,8)), so a scenario
//! file only states what differs. A malformed or inconsistent file is refused with an
//! error naming the file, the line and the field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

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
    /// A well-formed value that makes no sense (a negative radius, a goal inside a wall...).
    #[error("{file}:{line}: {field}: {message}")]
    Invalid {
        file: String,
        line: usize,
        field: String,
        message: String,
    },
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
}

impl Default for Goal {
    fn default() -> Self {
        Goal {
            x: 30.0,
            y: 15.0,
            heading_deg: None,
            tolerance: 1.0,
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
        VehicleConfig {
            wheelbase: 1.65,
            length: 2.4,
            width: 1.2,
            rear_overhang: 0.375,
            max_steer_deg: 35.0,
            max_speed: 6.7,
            radius: 2.0,
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
    /// UTC at t = 0, RFC 3339 (`2026-05-04T14:00:00Z`).
    pub epoch: String,
    /// Seed of the noise sources (each source derives its own stream).
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            physics_hz: 200.0,
            time_limit_s: 60.0,
            epoch: "2026-05-04T14:00:00Z".to_owned(),
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

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    pub description: String,
    pub datum: Datum,
    pub start: Pose,
    pub goal: Goal,
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
        }
    }
}

/// A field that failed validation: its path (`obstacles[1].radius`) and why.
struct Bad {
    path: Vec<PathPart>,
    message: String,
}

#[derive(Clone)]
enum PathPart {
    Key(&'static str),
    Index(usize),
}

fn bad(path: &[PathPart], message: impl Into<String>) -> Bad {
    Bad {
        path: path.to_vec(),
        message: message.into(),
    }
}

fn path_text(path: &[PathPart]) -> String {
    let mut s = String::new();
    for p in path {
        match p {
            PathPart::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            PathPart::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

use PathPart::{Index, Key};

fn finite(path: &[PathPart], v: f64) -> Result<(), Bad> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(bad(path, format!("{v} is not a finite number")))
    }
}

fn positive(path: &[PathPart], v: f64) -> Result<(), Bad> {
    finite(path, v)?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(bad(path, format!("must be positive, is {v}")))
    }
}

fn non_negative(path: &[PathPart], v: f64) -> Result<(), Bad> {
    finite(path, v)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(bad(path, format!("must not be negative, is {v}")))
    }
}

fn with(path: &[PathPart], part: PathPart) -> Vec<PathPart> {
    let mut p = path.to_vec();
    p.push(part);
    p
}

fn check_points(path: &[PathPart], points: &[[f64; 2]], min: usize) -> Result<(), Bad> {
    if points.len() < min {
        return Err(bad(
            path,
            format!("needs at least {min} points, has {}", points.len()),
        ));
    }
    for (i, p) in points.iter().enumerate() {
        finite(&with(path, Index(i)), p[0])?;
        finite(&with(path, Index(i)), p[1])?;
    }
    Ok(())
}

fn check_motion(path: &[PathPart], motion: &Option<Motion>) -> Result<(), Bad> {
    match motion {
        None => Ok(()),
        Some(Motion::Velocity { vx, vy }) => {
            finite(&with(path, Key("vx")), *vx)?;
            finite(&with(path, Key("vy")), *vy)
        }
        Some(Motion::Waypoints { points, speed, .. }) => {
            check_points(&with(path, Key("points")), points, 2)?;
            positive(&with(path, Key("speed")), *speed)
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
        scenario.validate().map_err(|b| ScenarioError::Invalid {
            file: file.to_owned(),
            line: locate(text, &b.path),
            field: path_text(&b.path),
            message: b.message,
        })?;
        Ok(scenario)
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

    fn validate(&self) -> Result<(), Bad> {
        let d = &self.datum;
        if !(d.latitude.is_finite() && d.latitude.abs() <= 89.0) {
            return Err(bad(
                &[Key("datum"), Key("latitude")],
                "must be within [-89, 89] degrees",
            ));
        }
        if !(d.longitude.is_finite() && d.longitude.abs() <= 180.0) {
            return Err(bad(
                &[Key("datum"), Key("longitude")],
                "must be within [-180, 180] degrees",
            ));
        }
        finite(&[Key("datum"), Key("altitude")], d.altitude)?;
        for (k, v) in [
            ("x", self.start.x),
            ("y", self.start.y),
            ("heading_deg", self.start.heading_deg),
        ] {
            finite(&[Key("start"), Key(k)], v)?;
        }
        finite(&[Key("goal"), Key("x")], self.goal.x)?;
        finite(&[Key("goal"), Key("y")], self.goal.y)?;
        if let Some(h) = self.goal.heading_deg {
            finite(&[Key("goal"), Key("heading_deg")], h)?;
        }
        positive(&[Key("goal"), Key("tolerance")], self.goal.tolerance)?;

        let v = &self.vehicle;
        let vp = |k| [Key("vehicle"), Key(k)];
        for (k, x) in [
            ("wheelbase", v.wheelbase),
            ("length", v.length),
            ("width", v.width),
            ("max_speed", v.max_speed),
            ("radius", v.radius),
        ] {
            positive(&vp(k), x)?;
        }
        non_negative(&vp("rear_overhang"), v.rear_overhang)?;
        if v.rear_overhang + v.wheelbase > v.length {
            return Err(bad(
                &vp("wheelbase"),
                format!(
                    "rear_overhang {} + wheelbase {} exceed the length {}",
                    v.rear_overhang, v.wheelbase, v.length
                ),
            ));
        }
        if !(v.max_steer_deg > 0.0 && v.max_steer_deg < 60.0) {
            return Err(bad(
                &vp("max_steer_deg"),
                format!("must be in (0, 60), is {}", v.max_steer_deg),
            ));
        }
        // The DBC's ranges bound what can be commanded at all.
        if v.max_steer_deg > 45.0 {
            return Err(bad(
                &vp("max_steer_deg"),
                "exceeds the DBC's TargetAngle range of 45 degrees",
            ));
        }
        if v.max_speed > 10.0 {
            return Err(bad(
                &vp("max_speed"),
                "exceeds the DBC's TargetSpeed range of 10 m/s",
            ));
        }

        let s = &self.steering;
        non_negative(&[Key("steering"), Key("dead_time_s")], s.dead_time_s)?;
        positive(
            &[Key("steering"), Key("time_constant_s")],
            s.time_constant_s,
        )?;
        positive(&[Key("steering"), Key("max_rate_deg_s")], s.max_rate_deg_s)?;
        non_negative(&[Key("steering"), Key("idle_current_a")], s.idle_current_a)?;
        non_negative(
            &[Key("steering"), Key("current_per_rate_a")],
            s.current_per_rate_a,
        )?;
        finite(&[Key("steering"), Key("bias_deg")], s.bias_deg)?;
        if s.bias_deg.abs() > 10.0 {
            return Err(bad(
                &[Key("steering"), Key("bias_deg")],
                format!("must be within [-10, 10] degrees, is {}", s.bias_deg),
            ));
        }
        let t = &self.throttle;
        non_negative(&[Key("throttle"), Key("dead_time_s")], t.dead_time_s)?;
        positive(
            &[Key("throttle"), Key("time_constant_s")],
            t.time_constant_s,
        )?;
        positive(&[Key("throttle"), Key("max_accel")], t.max_accel)?;
        positive(&[Key("throttle"), Key("max_decel")], t.max_decel)?;
        positive(&[Key("throttle"), Key("brake_decel")], t.brake_decel)?;
        non_negative(
            &[Key("throttle"), Key("throttle_per_speed")],
            t.throttle_per_speed,
        )?;
        if self.can.interface.is_empty() || self.can.interface.len() > 15 {
            return Err(bad(
                &[Key("can"), Key("interface")],
                "must be 1 to 15 characters",
            ));
        }

        self.gps
            .validate()
            .map_err(|e| bad(&[Key("gps"), Key(e.field)], e.message))?;
        self.laser
            .validate()
            .map_err(|e| bad(&[Key("laser"), Key(e.field)], e.message))?;
        self.devices
            .validate(&self.can.interface)
            .map_err(|e| bad(&[Key("devices"), Key(e.path[0]), Key(e.path[1])], e.message))?;
        let sim = &self.sim;
        if !(sim.physics_hz.is_finite() && (10.0..=2000.0).contains(&sim.physics_hz)) {
            return Err(bad(
                &[Key("sim"), Key("physics_hz")],
                "must be within [10, 2000] Hz",
            ));
        }
        positive(&[Key("sim"), Key("time_limit_s")], sim.time_limit_s)?;
        crate::epoch::parse_rfc3339(&sim.epoch).map_err(|e| bad(&[Key("sim"), Key("epoch")], e))?;
        non_negative(
            &[Key("success"), Key("min_clearance")],
            self.success.min_clearance,
        )?;

        for (i, o) in self.obstacles.iter().enumerate() {
            let p = [Key("obstacles"), Index(i)];
            match o {
                Obstacle::Circle {
                    x,
                    y,
                    radius,
                    motion,
                } => {
                    finite(&with(&p, Key("x")), *x)?;
                    finite(&with(&p, Key("y")), *y)?;
                    positive(&with(&p, Key("radius")), *radius)?;
                    check_motion(&with(&p, Key("motion")), motion)?;
                }
                Obstacle::Box {
                    x,
                    y,
                    length,
                    width,
                    heading_deg,
                    motion,
                } => {
                    finite(&with(&p, Key("x")), *x)?;
                    finite(&with(&p, Key("y")), *y)?;
                    positive(&with(&p, Key("length")), *length)?;
                    positive(&with(&p, Key("width")), *width)?;
                    finite(&with(&p, Key("heading_deg")), *heading_deg)?;
                    check_motion(&with(&p, Key("motion")), motion)?;
                }
                Obstacle::Wall { points, thickness } => {
                    check_points(&with(&p, Key("points")), points, 2)?;
                    positive(&with(&p, Key("thickness")), *thickness)?;
                    for (j, w) in points.windows(2).enumerate() {
                        if w[0] == w[1] {
                            return Err(bad(
                                &with(&with(&p, Key("points")), Index(j + 1)),
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
            return Err(bad(
                &[Key("start")],
                format!("the vehicle's footprint at the start overlaps obstacles[{i}]"),
            ));
        }
        if self.success.reach_goal {
            if let Some(i) = world
                .circle_hits(self.goal.x, self.goal.y, self.goal.tolerance.min(0.5))
                .first()
            {
                return Err(bad(
                    &[Key("goal")],
                    format!(
                        "the goal lies inside obstacles[{i}] at t = 0 but success.reach_goal is true"
                    ),
                ));
            }
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
    let path = [Key("devices"), Key(e.path[0]), Key(e.path[1])];
    ScenarioError::Invalid {
        file: file.to_owned(),
        line: locate(text, &path),
        field: path_text(&path),
        message: e.message.clone(),
    }
}

/// The 1-based line of a field in the TOML text (the nearest existing ancestor when
/// the field itself is absent and came from the defaults).
fn locate(text: &str, path: &[PathPart]) -> usize {
    let Ok(root) = toml::de::DeTable::parse(text) else {
        return 1;
    };
    let mut span = root.span();
    let mut value: Option<&toml::de::DeValue<'_>> = None;
    let mut table = Some(root.get_ref());
    for part in path {
        let next = match (part, table, value) {
            (Key(k), Some(t), _) => t
                .iter()
                .find(|(key, _)| key.get_ref().as_ref() == *k)
                .map(|(_, v)| v),
            (Index(i), _, Some(toml::de::DeValue::Array(items))) => items.get(*i),
            _ => None,
        };
        let Some(next) = next else { break };
        span = next.span();
        value = Some(next.get_ref());
        table = match next.get_ref() {
            toml::de::DeValue::Table(t) => Some(t),
            _ => None,
        };
    }
    text[..span.start.min(text.len())].matches('\n').count() + 1
}
