//! Scenarios: the world, the vehicle, its devices and the verdict's criteria, as TOML.
//!
//! Every section has a `Default` that is the seed paper's (start (0,0) heading 45
//! degrees, goal (30,15), its golf car, scanner and receiver), so a scenario file only
//! states what differs; its obstacles default to none, so a file lists every obstacle
//! it has. The paper's scenario, its post of radius 3 m at (19,8) included, is
//! [`Scenario::paper`] (`sim/scenarios/paper.toml`). A malformed or inconsistent file
//! is refused with an error naming the file, the line and the field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use ugv_fields::{FieldError, FieldPath, angle_deg, coordinate, within};

use crate::devices::gps::{GpsConfig, GpsDevice, GpsError};
use crate::devices::laser::{LaserConfig, LaserDevice, LaserDeviceError};
use crate::devices::map::DeviceMap;
use crate::ecu::EcuSections;
use crate::faults::plan::PlanFile;
use crate::faults::{Expectations, FaultSpec};
use fields::check_obstacles;

pub mod fields;
pub mod ranges;
pub mod schema;

pub use fields::ScenarioError;
pub use schema::*;

/// The paper's scenario, shipped embedded: what `ugv-sim run` runs without a file.
pub const PAPER_SCENARIO: &str = include_str!("../scenarios/paper.toml");

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
    pub gps: GpsConfig,
    pub laser: LaserConfig,
    pub sim: SimConfig,
    pub success: SuccessCriteria,
    /// Which devices are simulated and which physical (all simulated by default).
    pub devices: DeviceMap,
    /// The controller's tuning for this scenario, where it differs from its defaults.
    pub controller: ControllerTuning,
    /// Faults injected during the run (`[[faults]]`), in the order written.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultSpec>,
    /// What must follow the faults.
    pub expect: Expectations,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: "unnamed".to_owned(),
            description: String::new(),
            datum: Datum::default(),
            start: Pose {
                x: 0.0,
                y: 0.0,
                heading_deg: 45.0,
            },
            goal: Goal::default(),
            waypoints: Vec::new(),
            obstacles: Vec::new(),
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

impl Scenario {
    /// The GPS receiver of the scenario: its `[gps]`, `datum`, `sim` and wheelbase.
    pub fn gps_device(&self) -> Result<GpsDevice, GpsError> {
        GpsDevice::new(&self.gps, &self.datum, &self.sim, self.vehicle.wheelbase)
    }

    /// The laser scanner of the scenario: its `[laser]`, obstacles, `sim.seed` and
    /// `sim.epoch`.
    pub fn laser_device(&self) -> Result<LaserDevice, LaserDeviceError> {
        LaserDevice::new(
            &self.laser,
            &self.obstacles,
            self.sim.seed,
            self.sim.epoch.unix_ns(),
        )
    }

    /// The sections the simulated ECUs take.
    pub fn ecu_sections(&self) -> EcuSections<'_> {
        EcuSections {
            steering: &self.steering,
            throttle: &self.throttle,
            vehicle: &self.vehicle,
            can: &self.can,
            sim: &self.sim,
        }
    }

    /// Parse and validate TOML text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<Scenario, ScenarioError> {
        let scenario: Scenario = ugv_fields::parse_toml(text, file)?;
        scenario.validate().map_err(|e| e.located(text, file))?;
        Ok(scenario)
    }

    /// The scenario with what the command line changes of it, validated again as a
    /// whole (a new bus can collide with a physical device's, a fault plan with the
    /// time limit): the error names the field the change broke.
    pub fn with_overrides(mut self, overrides: Overrides) -> Result<Scenario, FieldError> {
        let Overrides {
            can,
            devices,
            time_limit_s,
            faults,
        } = overrides;
        if let Some(iface) = can {
            self.can.interface = iface;
        }
        if let Some(devices) = devices {
            self.devices = devices;
        }
        if let Some(limit) = time_limit_s {
            self.sim.time_limit_s = limit;
        }
        if let Some(plan) = faults {
            self.faults.extend(plan.faults);
            if let Some(expect) = plan.expect {
                self.expect = expect;
            }
        }
        self.validate()?;
        Ok(self)
    }

    /// Read a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = ugv_fields::read_file(path)?;
        Scenario::from_toml(&text, &path.display().to_string())
    }

    /// The paper's scenario (embedded): the defaults with its post of radius 3 m at
    /// (19, 8), the one place the post is defined.
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

    /// The first field that makes no sense, and why: every number finite, every
    /// physical parameter within its plausible range (the tables of [`ranges`], each
    /// range with its source: the golf car, the DBC's signal ranges, the LMS111's
    /// datasheet), positions within [`ugv_fields::PLAUSIBLE_COORDINATE`] (so the
    /// physics' `f32` never sees an infinity), the fields' relations, and the start
    /// and goal usable (the goal not reached at the start, neither inside an obstacle).
    pub(crate) fn validate(&self) -> Result<(), FieldError> {
        let at = |keys: &[&'static str]| FieldPath::of(keys);
        crate::faults::plan::validate_plan(&self.faults, &self.expect)?;
        self.check_places()?;
        ugv_fields::check_bounds(self, ranges::SCENARIO)?;
        self.check_relations()?;
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
        self.gps.validate().map_err(|e| e.under(&at(&["gps"])))?;
        self.laser
            .validate()
            .map_err(|e| e.under(&at(&["laser"])))?;
        self.devices
            .validate(&self.can.interface)
            .map_err(|e| e.under(&at(&["devices"])))?;
        check_obstacles(&at(&["obstacles"]), &self.obstacles)?;
        self.check_start_and_goal_free()
    }

    /// The datum, the start and the goal: places and headings.
    fn check_places(&self) -> Result<(), FieldError> {
        let at = |keys: &[&'static str]| FieldPath::of(keys);
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
        Ok(())
    }

    /// Relations between fields whose ranges the table checked: speeds up to the top
    /// speed, the perception within the laser's range, the route (the controller's own
    /// rules: every leg has a length, the goal is not reached at the start), the
    /// wheelbase within the length.
    fn check_relations(&self) -> Result<(), FieldError> {
        let at = |keys: &[&'static str]| FieldPath::of(keys);
        let v = &self.vehicle;
        if let Some(limit) = self.goal.speed_limit
            && limit > v.max_speed
        {
            return Err(FieldError::new(
                at(&["goal", "speed_limit"]),
                format!("{limit} exceeds vehicle.max_speed {}", v.max_speed),
            ));
        }
        let range_max = self.laser.spec().range_max;
        if let Some(r) = self.controller.detection_radius
            && r > range_max
        {
            return Err(FieldError::new(
                at(&["controller", "detection_radius"]),
                format!("{r} m exceeds the laser's range_max {range_max} m"),
            ));
        }
        let (start, goal) = ((self.start.x, self.start.y), (self.goal.x, self.goal.y));
        ugv_controller::route::check_waypoints(
            &at(&["waypoints"]),
            &self.waypoints,
            start,
            goal,
            &at(&["goal"]),
            v.max_speed,
        )?;
        ugv_controller::route::check_goal_not_at_start(
            &at(&["goal", "tolerance"]),
            self.goal.tolerance,
            start,
            goal,
        )?;
        if v.rear_overhang + v.wheelbase > v.length {
            return Err(FieldError::new(
                at(&["vehicle", "wheelbase"]),
                format!(
                    "rear_overhang {} + wheelbase {} exceed the length {}",
                    v.rear_overhang, v.wheelbase, v.length
                ),
            ));
        }
        Ok(())
    }

    /// The start and the goal must be free (the footprint at the start, the planner's
    /// circle at the goal), or nothing would ever pass.
    fn check_start_and_goal_free(&self) -> Result<(), FieldError> {
        let world = crate::world::World::new(&self.obstacles);
        let start = crate::vehicle::VehicleState::at(&self.start);
        if let Some(i) = world.footprint_hits(&self.vehicle, &start).first() {
            return Err(FieldError::new(
                FieldPath::of(&["start"]),
                format!("the vehicle's footprint at the start overlaps obstacles[{i}]"),
            ));
        }
        if self.success.reach_goal
            && let Some(i) = world
                .circle_hits(self.goal.x, self.goal.y, self.goal.tolerance.min(0.5))
                .first()
        {
            return Err(FieldError::new(
                FieldPath::of(&["goal"]),
                format!(
                    "the goal lies inside obstacles[{i}] at t = 0 but success.reach_goal is true"
                ),
            ));
        }
        Ok(())
    }
}

/// What the command line may change of a scenario (`ugv-sim run`, `suite --hil`).
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    /// `--can`: the simulator's bus.
    pub can: Option<String>,
    /// `--devices`: a bench file's device map.
    pub devices: Option<DeviceMap>,
    /// `--time-limit`, seconds.
    pub time_limit_s: Option<f64>,
    /// `--faults`: a fault plan whose faults follow the scenario's own (and whose
    /// `[expect]`, when it has one, replaces the scenario's).
    pub faults: Option<PlanFile>,
}
