//! The controller, free of I/O: frames, fixes and scans go in, CAN messages come out
//! of [`Controller::tick`], called every 10 ms, which runs the mode machine (waiting
//! for the sensors, enabling the ECUs, driving, arrived, estop), asks guidance for the
//! steering and speed, and stops the car on what [`crate::safety`] finds. The loop
//! (`runtime.rs`, one loop over clock and ports) wires it to the real endpoints (the
//! binary) or to memory ports in lockstep (SIL, replay) through the same codecs.

use firmware_bridge::Received;
use firmware_bridge::clock::next_slot;
use firmware_bridge::nmea::GpsReading;
use golf_car_can::{
    ControllerHeartbeat, ControllerHeartbeatState, FaultReport, FaultReportCode, FaultReportSource,
    GolfCarMessage, SteeringCmd, SteeringReport, SteeringReportFault, ThrottleCmd, ThrottleCmdGear,
    ThrottleReport, ThrottleReportFault,
};
use serde::Serialize;

use crate::config::ControllerConfig;
use crate::guidance::{
    FollowInputs, Guidance, GuidanceError, Navigator, PlanOutcome, PlanRequest, Reuse,
};
use crate::localisation::{Localiser, Pose, propagate};
use crate::perception::{Perception, PerceptionError, Pose2, ValidScan};
use crate::planner::Obstacle;
use crate::safety::intrusion::ActuationWatch;
use crate::safety::monitor::{ActuatorMonitor, SteerCommand};
use crate::safety::{Fault, Inputs, shows_the_laser_sees};

/// Command period (STEERING_CMD, THROTTLE_CMD), seconds.
pub const COMMAND_PERIOD: f64 = 0.01;

/// Heartbeat period, seconds.
pub const HEARTBEAT_PERIOD: f64 = 0.02;
/// FAULT_REPORT repetition while a fault lasts, seconds.
pub const FAULT_PERIOD: f64 = 0.1;
/// How long the enable bit stays low before the explicit enable edge, seconds.
const ENABLE_LOW: f64 = 0.05;
/// How long the ECUs get to report enabled after the edge, seconds.
const ENABLE_TIMEOUT: f64 = 1.0;
/// Below this speed the car counts as stopped, m/s.
const STOPPED: f64 = 0.05;

/// A stop the speed loop alone cannot make in time brakes: it aims this far short of
/// the stop, metres...
const STOP_MARGIN_M: f64 = 0.3;
/// ...with this much more brake than the calibrated deceleration says it needs.
const BRAKE_MARGIN: f64 = 1.25;

/// The brake a car at wheel speed `v` needs to stop within `room` metres, percent: none
/// while the deceleration the speed profile plans with (`follower.decel`) is enough;
/// otherwise what stops it [`STOP_MARGIN_M`] short with the brake's calibrated
/// deceleration (`vehicle.brake_decel`), [`BRAKE_MARGIN`] times over. A drive that
/// does not slow (a stuck throttle) so meets a commanded brake, which the actuator
/// monitor expects to see work (`safety/monitor.rs`).
fn stop_brake(v: f64, room: f64, cfg: &ControllerConfig) -> f64 {
    let needed = v * v / (2.0 * (room - STOP_MARGIN_M).max(0.05));
    if needed <= cfg.follower.decel {
        return 0.0;
    }
    (BRAKE_MARGIN * needed / cfg.vehicle.brake_decel * 100.0).min(100.0)
}

/// Why the controller could not start.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    #[error("configuration: {0}")]
    Config(#[from] ugv_fields::FieldError),
    #[error("datum: {0}")]
    Datum(#[from] firmware_bridge::geodesy::GeodesyError),
    #[error(transparent)]
    Guidance(#[from] GuidanceError),
    #[error("perception: {0}")]
    Perception(#[from] PerceptionError),
}

/// The controller's mode.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum Mode {
    /// Heartbeat idle until GPS (with heading), laser and both ECUs have been there
    /// for `safety.settle_s` without a break and the first path is planned.
    WaitingForSensors,
    /// Heartbeat auto, the enable edge sent, waiting for both ECUs to report enabled.
    Enabling { since: f64 },
    /// Driving the mission (or backing out of a dead end, or holding a controlled stop
    /// when no path is free).
    Auto,
    /// Within the goal tolerance: braking to a stop, then idle.
    Arrived { stopped: bool },
    /// A safety fault: estop heartbeat, ECUs disabled (brake, steering hold).
    Estop { code: String, reason: String },
}

/// One control tick, for the report, the plots and ANFIS training data.
#[derive(Clone, Copy, Debug, Serialize, serde::Deserialize)]
pub struct Sample {
    pub t: f64,
    pub pose: Pose,
    pub inputs: FollowInputs,
    /// Commanded road-wheel angle and speed.
    pub steer_cmd: f64,
    pub speed_cmd: f64,
}

/// What one tick asks of the actuators.
#[derive(Clone, Copy, Debug)]
struct Demand {
    /// The heartbeat's state.
    state: ControllerHeartbeatState,
    /// The steering's enable, and its angle, degrees.
    steer: (bool, f64),
    /// The throttle's enable, its speed (m/s) and the brake (percent).
    drive: (bool, f64, f64),
    /// Forward, but for a reversal.
    gear: ThrottleCmdGear,
}

impl Demand {
    /// `state`, `steer` and `drive` in forward gear.
    fn forward(
        state: ControllerHeartbeatState,
        steer: (bool, f64),
        drive: (bool, f64, f64),
    ) -> Demand {
        Demand {
            state,
            steer,
            drive,
            gear: ThrottleCmdGear::Forward,
        }
    }
}

/// Replanning on a thread of its own, so the 10 ms command loop never waits for it.
#[derive(Debug)]
struct PlanWorker {
    requests: std::sync::mpsc::Sender<PlanRequest>,
    outcomes: std::sync::mpsc::Receiver<PlanOutcome>,
    in_flight: bool,
}

impl PlanWorker {
    fn spawn() -> std::io::Result<PlanWorker> {
        let (requests, jobs) = std::sync::mpsc::channel::<PlanRequest>();
        let (done, outcomes) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("planner".to_owned())
            .spawn(move || {
                // Ends when the controller (the sender) is dropped.
                let mut reuse = Reuse::default();
                while let Ok(req) = jobs.recv() {
                    if done.send(reuse.solve(&req)).is_err() {
                        break;
                    }
                }
            })?;
        Ok(PlanWorker {
            requests,
            outcomes,
            in_flight: false,
        })
    }
}

/// Where replanning runs.
#[derive(Debug)]
enum Planning {
    /// In the tick that asks for it (SIL: deterministic).
    Inline,
    /// On a thread of its own, taken at the first tick after it finished (the binary).
    Thread(PlanWorker),
    /// In the tick that asks for it, taken at the next tick: the thread's timing when
    /// the plan takes less than a tick, deterministically (a replay of a HIL run).
    NextTick(Option<Box<PlanOutcome>>),
    /// In the tick that asks for it, taken at the first tick at or after the next of
    /// `taken_at` (controller seconds): the planning thread's timing as the
    /// controller's own recording kept it (a replay of that recording). None is asked
    /// for while one waits, as with the thread.
    Recorded {
        taken_at: std::collections::VecDeque<f64>,
        waiting: Option<Box<PlanOutcome>>,
    },
}

/// The controller.
#[derive(Debug)]
pub struct Controller {
    cfg: ControllerConfig,
    loc: Localiser,
    perception: Perception,
    pub nav: Navigator,
    mode: Mode,
    steering: Option<(f64, SteeringReport)>,
    throttle: Option<(f64, ThrottleReport)>,
    ecu_fault: Option<String>,
    last_scan: Option<f64>,
    /// Since when every input has been fresh without a break, while waiting for them.
    ready_since: Option<f64>,
    /// The ECUs' reports against the commands (a stuck actuator, a driver's hands).
    monitor: ActuatorMonitor,
    obstacles: Vec<Obstacle>,
    stop_reason: Option<String>,
    next_heartbeat: f64,
    next_command: f64,
    next_fault: f64,
    /// Scans perception refused.
    pub bad_scans: u64,
    /// Where replanning runs: off the command loop in HIL, inline in SIL.
    planning: Planning,
    /// Solves the replannings made on the command loop (the thread has its own).
    reuse: Reuse,
    /// The code sent in FAULT_REPORT while in estop.
    fault_code: FaultReportCode,
    /// The FAULT_REPORT detail while in estop (the CAN ID a finding concerns).
    fault_detail: u16,
    /// Commands the controller did not send, watched for on the bus.
    watch: ActuationWatch,
    pub samples: Vec<Sample>,
}

impl Controller {
    pub fn new(cfg: &ControllerConfig) -> Result<Controller, ControllerError> {
        cfg.validate()?;
        // Walls become chains of circles sized for the least the planner inflates by:
        // the passage margin the car's rectangle is checked with, or the margin a
        // manoeuvre being followed is held with.
        let mut perception = cfg.perception.clone();
        perception.vehicle_radius = cfg
            .planner
            .passage_margin
            .min(cfg.planner.manoeuvre_margin - crate::guidance::manoeuvre::HOLD_SLACK)
            .max(0.0);
        Ok(Controller {
            loc: Localiser::new(cfg)?,
            perception: Perception::new(perception)?,
            nav: Navigator::new(cfg)?,
            cfg: cfg.clone(),
            mode: Mode::WaitingForSensors,
            steering: None,
            throttle: None,
            ecu_fault: None,
            last_scan: None,
            ready_since: None,
            monitor: ActuatorMonitor::new(&cfg.vehicle),
            obstacles: Vec::new(),
            stop_reason: None,
            next_heartbeat: 0.0,
            next_command: 0.0,
            next_fault: 0.0,
            bad_scans: 0,
            planning: Planning::Inline,
            reuse: Reuse::default(),
            fault_code: FaultReportCode::Internal,
            fault_detail: 0,
            watch: ActuationWatch::new(),
            samples: Vec::new(),
        })
    }

    /// Replan on a thread of its own from now on (the binary does; SIL keeps replanning
    /// inline so runs stay deterministic).
    pub fn with_planning_thread(mut self) -> std::io::Result<Controller> {
        self.start_planning_thread()?;
        Ok(self)
    }

    /// [`Controller::with_planning_thread`] on a controller already built, before its
    /// first tick (a SIL run's, to plan as the binary does).
    pub fn start_planning_thread(&mut self) -> std::io::Result<()> {
        self.planning = Planning::Thread(PlanWorker::spawn()?);
        Ok(())
    }

    /// Take each replanning at the tick after the one that asked for it, as the
    /// planning thread does when a plan takes less than a tick, but deterministically:
    /// for replaying a run of the binary.
    pub fn with_plans_taken_next_tick(mut self) -> Controller {
        self.planning = Planning::NextTick(None);
        self
    }

    /// Take each replanning at the recorded instants `taken_at` (controller seconds,
    /// in order): for replaying the controller's own recording, whose loop took them
    /// from its planning thread then.
    pub fn with_plans_taken_at(mut self, taken_at: Vec<f64>) -> Controller {
        self.planning = Planning::Recorded {
            taken_at: taken_at.into(),
            waiting: None,
        };
        self
    }

    /// Start a replanning when one is due and take the finished ones.
    fn plan(&mut self, now: f64, pose: &Pose) {
        match &mut self.planning {
            Planning::Inline => {
                if self.nav.replan_due(now, pose) {
                    self.nav.issued(now);
                    let outcome = self
                        .reuse
                        .solve(&self.nav.request(now, pose, &self.obstacles));
                    self.nav.accept(outcome);
                }
            }
            Planning::NextTick(done) => {
                if let Some(outcome) = done.take() {
                    self.nav.accept(*outcome);
                }
                if self.nav.replan_due(now, pose) {
                    self.nav.issued(now);
                    *done = Some(Box::new(self.reuse.solve(&self.nav.request(
                        now,
                        pose,
                        &self.obstacles,
                    ))));
                }
            }
            Planning::Thread(w) => {
                while let Ok(outcome) = w.outcomes.try_recv() {
                    self.nav.accept(outcome);
                    w.in_flight = false;
                }
                if !w.in_flight && self.nav.replan_due(now, pose) {
                    self.nav.issued(now);
                    w.in_flight = w
                        .requests
                        .send(self.nav.request(now, pose, &self.obstacles))
                        .is_ok();
                }
            }
            Planning::Recorded { taken_at, waiting } => {
                if taken_at.front().is_some_and(|t| *t <= now + 1e-6)
                    && let Some(outcome) = waiting.take()
                {
                    taken_at.pop_front();
                    self.nav.accept(*outcome);
                }
                if waiting.is_none() && self.nav.replan_due(now, pose) {
                    self.nav.issued(now);
                    *waiting = Some(Box::new(self.reuse.solve(&self.nav.request(
                        now,
                        pose,
                        &self.obstacles,
                    ))));
                }
            }
        }
    }

    /// The pose `vehicle.steer_dead_time_s` after `now`, from the pose at `now`: the
    /// steering commands sent within the dead time are still on their way and act in
    /// it, in order, through the actuator's lag (bias removed, as the localiser
    /// corrects the reported angle). A command sent now acts from there, so planning
    /// and steering start from it.
    fn ahead(&self, now: f64, pose: &Pose) -> Pose {
        let v = &self.cfg.vehicle;
        let bias = self.loc.steer_bias();
        let steps = (v.steer_dead_time_s / COMMAND_PERIOD).round();
        let targets = (0..steps as u32).map(|j| {
            // The command acting in step j was sent at least this long before now.
            let age = v.steer_dead_time_s - f64::from(j) * COMMAND_PERIOD - 1e-9;
            match self.monitor.steer_command_as_of(now, age) {
                Some(SteerCommand {
                    enable: true,
                    angle_deg,
                }) => Some(angle_deg.to_radians() + bias),
                _ => None,
            }
        });
        propagate(
            pose,
            v.wheelbase,
            v.steer_time_constant_s,
            COMMAND_PERIOD,
            targets,
        )
    }

    /// Replan if due from `ahead` (the pose a steering dead time after `pose`, the one
    /// at `now`), recover from a dead end if stuck in one, then follow the current
    /// plan (or reversal) ([`Navigator::follow_ahead`]).
    fn plan_and_follow(&mut self, now: f64, pose: &Pose, ahead: &Pose) -> Guidance {
        self.plan(now, ahead);
        self.nav.recover(now, pose, &self.obstacles);
        self.nav.follow_ahead(pose, ahead)
    }

    pub fn mode(&self) -> &Mode {
        &self.mode
    }

    /// The reason of the current controlled stop, if guidance is holding one.
    pub fn stop_reason(&self) -> Option<&str> {
        self.stop_reason.as_deref()
    }

    /// The watch for commands the controller did not send (its findings).
    pub fn watch(&self) -> &ActuationWatch {
        &self.watch
    }

    /// The obstacles guidance plans around.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// The pose estimate at `now`.
    pub fn pose(&self, now: f64) -> Option<Pose> {
        self.loc.predict(now)
    }

    /// The mission is over: arrived and stopped.
    pub fn finished(&self) -> bool {
        matches!(self.mode, Mode::Arrived { stopped: true })
    }

    /// A frame from the bus.
    pub fn on_can(&mut self, now: f64, received: &Received) {
        // Commands it did not send: estop at once, in any mode, keeping the first.
        if let Some(f) = self.watch.on_can(now, received)
            && !matches!(self.mode, Mode::Estop { .. })
        {
            self.estop(f.code, f.reason);
            self.fault_detail = f.detail;
        }
        let Received::Message(m) = received else {
            return;
        };
        match m {
            GolfCarMessage::SteeringReport(r) => {
                if r.fault != SteeringReportFault::None && self.driving() {
                    self.ecu_fault = Some(format!("steering ECU reports {}", r.fault));
                }
                if self.driving() {
                    self.monitor.on_steering(now, r);
                }
                self.steering = Some((now, *r));
            }
            GolfCarMessage::ThrottleReport(r) => {
                if r.fault != ThrottleReportFault::None && self.driving() {
                    self.ecu_fault = Some(format!("throttle ECU reports {}", r.fault));
                }
                if self.driving() {
                    self.monitor.on_throttle(now, r);
                }
                self.throttle = Some((now, *r));
            }
            GolfCarMessage::FaultReport(f)
                if f.source != FaultReportSource::Controller && self.driving() =>
            {
                self.ecu_fault = Some(format!("FAULT_REPORT from {}: {}", f.source, f.code));
            }
            _ => {}
        }
        let speed = self.throttle.map_or(0.0, |(_, r)| r.wheel_speed);
        let phi = self.steering.map_or(0.0, |(_, r)| r.angle.to_radians());
        self.loc.on_actuators(now, speed, phi);
    }

    fn driving(&self) -> bool {
        matches!(self.mode, Mode::Auto | Mode::Arrived { stopped: false })
    }

    /// A GPS epoch.
    pub fn on_gps(&mut self, now: f64, reading: &GpsReading) {
        self.loc.on_fix(now, reading);
    }

    /// A laser frame taken at `now`, where a scan enters the controller: checked once,
    /// into the [`ValidScan`] perception takes ([`Controller::on_scan`]); a frame that
    /// is no scan is counted, as a scan perception refuses is.
    pub fn on_laser_frame(&mut self, now: f64, frame: &firmware_bridge::laser::LaserFrame) {
        match ValidScan::from_frame(frame, now) {
            Ok(scan) => self.on_scan(now, &scan),
            Err(_) => self.bad_scans += 1,
        }
    }

    /// A laser scan. Only a scan perception accepts counts as one for the laser-silence
    /// watchdog: a stream of scans it refuses (a bad frame, a mounting it cannot use)
    /// is blindness, and stops the car like silence does.
    pub fn on_scan(&mut self, now: f64, scan: &ValidScan<'_>) {
        // A scan whose beams are mostly dropouts (a NaN or zero-range storm) shows
        // nothing: it does not refresh the watchdog either.
        if !shows_the_laser_sees(scan) {
            self.bad_scans += 1;
            return;
        }
        let Some(pose) = self.loc.predict(now) else {
            // No pose to place it yet: a well-formed scan still shows the laser lives.
            self.last_scan = Some(now);
            return;
        };
        let v = &self.cfg.vehicle;
        let mount = Pose2 {
            x: v.laser_x,
            y: v.laser_y,
            yaw: v.laser_yaw_deg.to_radians(),
        };
        let at = Pose2 {
            x: pose.x,
            y: pose.y,
            yaw: pose.theta,
        };
        // A malformed scan is counted and skipped; silence is what the safety checks.
        match self.perception.update(scan, &mount, &at) {
            Ok(out) => {
                self.last_scan = Some(now);
                let (c, s) = (at.yaw.cos(), at.yaw.sin());
                let laser = Pose2 {
                    x: at.x + c * mount.x - s * mount.y,
                    y: at.y + s * mount.x + c * mount.y,
                    yaw: at.yaw + mount.yaw,
                };
                self.nav.observe(now, scan, &laser, [at.x, at.y, at.yaw]);
                self.obstacles = out.planner_obstacles();
            }
            Err(_) => self.bad_scans += 1,
        }
    }

    /// Every reason to stop now ([`crate::safety::check`]).
    fn safety_check(&self, now: f64) -> Result<(), Fault> {
        crate::safety::check(
            &self.cfg.safety,
            now,
            &Inputs {
                localiser: &self.loc,
                last_scan: self.last_scan,
                steering_report: self.steering.map(|s| s.0),
                throttle_report: self.throttle.map(|s| s.0),
                ecu_fault: self.ecu_fault.as_deref(),
                monitor: &self.monitor,
            },
        )
    }

    /// A fault found outside the controller (a port lost, a process stopping): estop now,
    /// with `code` in FAULT_REPORT and `reason` in the mode.
    pub fn fail(&mut self, code: FaultReportCode, reason: String) {
        if !matches!(self.mode, Mode::Estop { .. }) {
            self.estop(code, reason);
        }
    }

    fn estop(&mut self, code: FaultReportCode, reason: String) {
        self.mode = Mode::Estop {
            code: code.label().to_owned(),
            reason,
        };
        self.fault_code = code;
        self.fault_detail = 0;
        self.next_fault = 0.0;
    }

    fn measured_angle(&self) -> f64 {
        self.steering.map_or(0.0, |(_, r)| r.angle)
    }

    fn speed(&self) -> f64 {
        self.throttle.map_or(0.0, |(_, r)| r.wheel_speed)
    }

    /// The brake command that adds `decel` m/s^2 with the brake's calibrated
    /// deceleration, percent.
    fn brake_pct(&self, decel: f64) -> f64 {
        (decel / self.cfg.vehicle.brake_decel * 100.0).clamp(0.0, 100.0)
    }

    /// Advance the mode machine and return the messages due at `now`.
    pub fn tick(&mut self, now: f64) -> Vec<GolfCarMessage> {
        self.advance_mode(now);

        // What to ask of the actuators.
        let hold = self.measured_angle();
        let demand = match self.mode.clone() {
            Mode::WaitingForSensors => Demand::forward(
                ControllerHeartbeatState::Idle,
                (false, hold),
                (false, 0.0, 100.0),
            ),
            Mode::Enabling { since } => {
                let enable = now - since >= ENABLE_LOW;
                Demand::forward(
                    ControllerHeartbeatState::Auto,
                    (enable, hold),
                    (enable, 0.0, 100.0),
                )
            }
            Mode::Auto => self.auto_demand(now, hold),
            Mode::Arrived { stopped } => self.arrived_demand(stopped, hold),
            Mode::Estop { .. } => Demand::forward(
                ControllerHeartbeatState::Estop,
                (false, hold),
                (false, 0.0, 100.0),
            ),
        };

        self.messages(now, demand, hold)
    }

    /// What to ask of the actuators in auto at `now`: what guidance says from the
    /// car's pose (the brake half on while there is none); the wheels held at `hold`
    /// while stopping.
    fn auto_demand(&mut self, now: f64, hold: f64) -> Demand {
        let v = &self.cfg.vehicle;
        let limit = v.max_steer_deg.min(45.0);
        let top_speed = v.max_speed.min(10.0);
        let Some(pose) = self.loc.predict(now) else {
            return Demand::forward(
                ControllerHeartbeatState::Auto,
                (true, hold),
                (true, 0.0, 50.0),
            );
        };
        match self.plan_and_follow(now, &pose, &self.ahead(now, &pose)) {
            Guidance::Drive {
                steer,
                speed,
                room,
                brake,
                inputs,
            } => {
                self.stop_reason = None;
                let wanted = steer.to_degrees().clamp(-limit, limit);
                // The wheels stand at the reported angle plus the bias.
                let steer_deg = (wanted - self.loc.steer_bias().to_degrees()).clamp(-limit, limit);
                let speed = speed.clamp(0.0, top_speed);
                self.samples.push(Sample {
                    t: now,
                    pose,
                    inputs,
                    steer_cmd: wanted.to_radians(),
                    speed_cmd: speed,
                });
                let brake = stop_brake(self.speed(), room, &self.cfg).max(self.brake_pct(brake));
                Demand::forward(
                    ControllerHeartbeatState::Auto,
                    (true, steer_deg),
                    (true, speed, brake),
                )
            }
            Guidance::Reverse {
                steer,
                speed,
                brake,
            } => {
                self.stop_reason = None;
                let steer_deg = steer.to_degrees().clamp(-limit, limit);
                Demand {
                    gear: ThrottleCmdGear::Reverse,
                    ..Demand::forward(
                        ControllerHeartbeatState::Auto,
                        (true, steer_deg),
                        (true, speed.clamp(0.0, top_speed), self.brake_pct(brake)),
                    )
                }
            }
            Guidance::Stop { reason } => {
                self.stop_reason = Some(reason);
                Demand::forward(
                    ControllerHeartbeatState::Auto,
                    (true, hold),
                    (true, 0.0, 40.0),
                )
            }
            Guidance::Arrived => {
                self.mode = Mode::Arrived { stopped: false };
                Demand::forward(
                    ControllerHeartbeatState::Auto,
                    (true, hold),
                    (true, 0.0, 60.0),
                )
            }
        }
    }

    /// What to ask of the actuators once arrived: brake to a stop (the wheels held at
    /// `hold`), then idle with the ECUs disabled.
    fn arrived_demand(&mut self, stopped: bool, hold: f64) -> Demand {
        if !stopped && self.speed().abs() < STOPPED {
            self.mode = Mode::Arrived { stopped: true };
        }
        if stopped {
            Demand::forward(
                ControllerHeartbeatState::Idle,
                (false, hold),
                (false, 0.0, 100.0),
            )
        } else {
            Demand::forward(
                ControllerHeartbeatState::Auto,
                (true, hold),
                (true, 0.0, 60.0),
            )
        }
    }

    /// The mode machine's transitions at `now`: start-up (sensors, the first plan,
    /// the settling), enabling, and every safety check while driving.
    fn advance_mode(&mut self, now: f64) {
        match self.mode.clone() {
            Mode::WaitingForSensors => match self.loc.predict(now) {
                Some(pose) if self.safety_check(now).is_ok() && self.loc.heading_known() => {
                    // The first path is planned while the ECUs are still disabled.
                    self.plan(now, &pose);
                    let since = *self.ready_since.get_or_insert(now);
                    if now - since >= self.cfg.safety.settle_s && self.nav.planned(&pose) {
                        self.mode = Mode::Enabling { since: now };
                    }
                }
                _ => self.ready_since = None,
            },
            Mode::Enabling { since } => {
                if let Err(Fault { code, reason }) = self.safety_check(now) {
                    self.estop(code, reason);
                } else if self.steering.is_some_and(|s| s.1.enabled)
                    && self.throttle.is_some_and(|t| t.1.enabled)
                {
                    self.mode = Mode::Auto;
                } else if now - since > ENABLE_TIMEOUT {
                    self.estop(
                        FaultReportCode::ActuatorFault,
                        "the ECUs did not enable".to_owned(),
                    );
                }
            }
            Mode::Auto | Mode::Arrived { stopped: false } => {
                if let Err(Fault { code, reason }) = self.safety_check(now) {
                    self.estop(code, reason);
                }
            }
            Mode::Arrived { stopped: true } | Mode::Estop { .. } => {}
        }
    }

    /// The messages due at `now` for what `demand` asks of the actuators: the heartbeat,
    /// the commands and, in estop, the FAULT_REPORT; the monitors see them.
    fn messages(&mut self, now: f64, demand: Demand, hold: f64) -> Vec<GolfCarMessage> {
        let Demand {
            state,
            steer,
            drive,
            gear,
        } = demand;
        let v = &self.cfg.vehicle;
        let limit = v.max_steer_deg.min(45.0);
        let mut out = Vec::new();
        if now + 1e-9 >= self.next_heartbeat {
            out.push(GolfCarMessage::ControllerHeartbeat(ControllerHeartbeat {
                state,
            }));
            self.next_heartbeat = next_slot(self.next_heartbeat, now, HEARTBEAT_PERIOD);
        }
        if now + 1e-9 >= self.next_command {
            out.push(GolfCarMessage::SteeringCmd(SteeringCmd {
                enable: steer.0,
                target_angle: steer.1.clamp(-limit, limit),
                max_rate: v.steer_rate_deg_s.clamp(0.0, 500.0),
            }));
            out.push(GolfCarMessage::ThrottleCmd(ThrottleCmd {
                enable: drive.0,
                gear,
                brake: drive.2.clamp(0.0, 100.0),
                target_speed: drive.1.clamp(0.0, v.max_speed.min(10.0)),
                accel_limit: self.cfg.follower.accel_limit.clamp(0.0, 5.0),
            }));
            self.next_command = next_slot(self.next_command, now, COMMAND_PERIOD);
        }
        if matches!(self.mode, Mode::Estop { .. }) && now + 1e-9 >= self.next_fault {
            out.push(GolfCarMessage::FaultReport(FaultReport {
                source: FaultReportSource::Controller,
                code: self.fault_code,
                detail: self.fault_detail,
            }));
            self.next_fault = now + FAULT_PERIOD;
        }
        self.watch.commanded(now, &out, hold);
        self.monitor.commanded(now, &out);
        out
    }
}
