//! One run: the world, the vehicle and the simulated ECUs stepped on a fixed timestep,
//! the ECUs talking golf_car.dbc on a CAN bus (SocketCAN in HIL, the memory bus in
//! SIL), and the verdict's bookkeeping.

use embedded_can::nb::Can;
use firmware_bridge::can::QueueDrops;
use firmware_bridge::{BridgeError, CanPort};
use golf_car_can::CanMessage;
use serde::Serialize;

use crate::busload::{BusLoad, BusLoadReport};
use crate::devices::gps::{GpsDevice, GpsEpoch, GpsError};
use crate::devices::laser::{LaserDevice, LaserDeviceError};
use crate::devices::map::EcuDevice;
use crate::ecu::EcuKind;
use crate::ecu::station::{NodeStats, Station};
use crate::faults::{FaultRecord, Injector, Node, ProcessFault};
use crate::measure::Jitter;
use crate::scenario::Scenario;
use crate::vehicle::VehicleState;
use crate::verdict::route::{RouteCheck, RouteReport};
use crate::world::{Clearances, World};
use firmware_bridge::laser::LaserFrame;

/// Why a run could not go on.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Bus(#[from] BridgeError),
    #[error("GPS: {0}")]
    Gps(#[from] GpsError),
    #[error("laser: {0}")]
    Laser(#[from] LaserDeviceError),
    #[error("fault plan: {0}")]
    Faults(#[from] ugv_fields::FieldError),
}

/// What the sensors produced in one step (the runner puts it on the wires).
#[derive(Debug, Default)]
pub struct SensorOutput {
    pub gps: Option<GpsEpoch>,
    pub laser: Option<Box<LaserFrame>>,
}

/// Seconds between samples of the driven path.
const TRAJECTORY_EVERY: f64 = 0.05;

/// How a run ended.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Outcome {
    GoalReached {
        time: f64,
    },
    Collision {
        time: f64,
        obstacle: usize,
    },
    TimeLimit {
        time: f64,
    },
    /// Ended from outside (Ctrl-C, the controller's exit).
    Stopped {
        time: f64,
        reason: String,
    },
}

/// What the terminal shows and the verdict is built from.
#[derive(Clone, Debug, Serialize)]
pub struct Snapshot {
    pub time: f64,
    pub vehicle: VehicleState,
    pub steering_enabled: bool,
    pub steering_fault: Option<crate::ecu::safety::Cause>,
    pub throttle_enabled: bool,
    pub throttle_fault: Option<crate::ecu::safety::Cause>,
    pub distance_to_goal: f64,
}

/// The simulator's state during a run.
#[derive(Debug)]
pub struct Sim<B> {
    pub scenario: Scenario,
    pub world: World,
    pub vehicle: VehicleState,
    steering: Station<B>,
    throttle: Station<B>,
    dt: f64,
    tick: u64,
    /// Closest approach of the footprint to each obstacle so far.
    clearances: Clearances,
    pub max_steer_deg: f64,
    pub max_steer_rate_deg_s: f64,
    /// How late the ticks came (HIL), seconds.
    lateness: Vec<f64>,
    gps: Option<GpsDevice>,
    laser: Option<LaserDevice>,
    next_scan: f64,
    /// A frame the controller has done with, scanned into next ([`Sim::reuse_frame`]).
    spare_frame: Option<Box<LaserFrame>>,
    outputs: SensorOutput,
    /// The driven path, sampled every 50 ms.
    pub trajectory: Vec<(f64, VehicleState)>,
    /// Since the controller went away: the run goes on until the car is safe.
    wind_down: Option<WindDown>,
    /// The scenario's fault plan, applied at the wires.
    faults: Injector,
    /// Frames on the bus against its bit rate (counted at the steering station,
    /// which sees every frame but its own, and its own).
    bus: BusLoad,
    bus_frames_seen: u64,
    /// The route followed (with waypoints): the goal counts only once it is driven.
    route: Option<RouteCheck>,
}

/// How long the run goes on after the controller went away, waiting for both ECUs'
/// safe state and the car to stop, simulated seconds; past it the run ends anyway, as
/// a failure.
pub const WIND_DOWN_LIMIT: f64 = 10.0;

/// One ECU's way to its safe state after the controller went away.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EcuSafeState {
    /// The last command the ECU received, simulated seconds.
    pub last_command_s: Option<f64>,
    /// When its reports first said it was disabled, simulated seconds.
    pub safe_report_s: Option<f64>,
    /// From the last command to that report, ms: the watchdog's reaction when the
    /// controller vanished; negative when the ECU was already safe before the
    /// controller's last command (the controller estopped it, then kept commanding it
    /// disabled for a while).
    pub latency_ms: Option<f64>,
    /// The ECU's command timeout plus one report period, ms: the contract.
    pub bound_ms: f64,
    pub within_bound: bool,
    /// Whether the controller had ever enabled it (if not, it was safe all along).
    pub was_enabled: bool,
}

/// What followed the controller going away (its process exited, or its loop ended).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SafeStateReport {
    /// Why the controller went away.
    pub reason: String,
    /// When the simulator noticed, simulated seconds.
    pub noticed_s: f64,
    /// The car's speed then, m/s.
    pub speed_then: f64,
    pub steering: EcuSafeState,
    pub throttle: EcuSafeState,
    /// When the car came to a stop, simulated seconds.
    pub stopped_s: Option<f64>,
}

#[derive(Clone, Debug)]
struct WindDown {
    reason: String,
    since: f64,
    speed_then: f64,
    stopped: Option<f64>,
}

/// Below this speed the car counts as stopped, m/s.
const STOPPED: f64 = 0.05;

impl<B: Can + QueueDrops> Sim<B> {
    /// A run of `scenario` with the steering and throttle ECUs on their own bus endpoints.
    pub fn new(scenario: Scenario, steering: CanPort<B>, throttle: CanPort<B>) -> Sim<B> {
        let world = World::new(&scenario.obstacles);
        let vehicle = VehicleState::at(&scenario.start);
        let clearances = Clearances::new(&world, &scenario.vehicle, &vehicle);
        let sections = scenario.ecu_sections();
        let station = |kind, device: &EcuDevice, port| Station::new(kind, device, &sections, port);
        Sim {
            steering: station(EcuKind::Steering, &scenario.devices.steering, steering),
            throttle: station(EcuKind::Throttle, &scenario.devices.throttle, throttle),
            dt: 1.0 / scenario.sim.physics_hz,
            tick: 0,
            world,
            vehicle,
            clearances,
            max_steer_deg: 0.0,
            max_steer_rate_deg_s: 0.0,
            lateness: Vec::new(),
            gps: None,
            laser: None,
            next_scan: 0.0,
            spare_frame: None,
            outputs: SensorOutput::default(),
            trajectory: vec![(0.0, vehicle)],
            wind_down: None,
            faults: Injector::new(Vec::new(), 0),
            bus: BusLoad::new(golf_car_can::NETWORK.baudrate),
            bus_frames_seen: 0,
            route: RouteCheck::new(&scenario),
            scenario,
        }
    }

    /// A laser frame to scan into next instead of a new one (if any): the scan writes
    /// every field and every beam (those past its count zero), so what it held does not
    /// matter.
    pub fn reuse_frame(&mut self, frame: Option<Box<LaserFrame>>) {
        if frame.is_some() {
            self.spare_frame = frame;
        }
    }

    /// Add the scenario's GPS receiver and laser scanner: each step then leaves their
    /// output in [`Sim::take_outputs`].
    pub fn with_sensors(mut self) -> Result<Sim<B>, SimError> {
        self.gps = Some(self.scenario.gps_device()?);
        self.laser = Some(self.scenario.laser_device()?);
        self.faults = Injector::new(
            crate::faults::plan::typed_plan(&self.scenario.faults)?,
            self.scenario.sim.seed,
        );
        Ok(self)
    }

    /// What the fault plan makes the controller's process do now.
    pub fn process_fault(&self) -> ProcessFault {
        self.faults.process(self.time())
    }

    /// What the sensors produced in the last step.
    pub fn take_outputs(&mut self) -> SensorOutput {
        std::mem::take(&mut self.outputs)
    }

    /// The physics step, seconds.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The next tick's number.
    pub fn next_tick(&self) -> u64 {
        self.tick
    }

    /// Simulated time of the last completed tick.
    pub fn time(&self) -> f64 {
        self.tick.saturating_sub(1) as f64 * self.dt
    }

    /// One fixed step at `k * dt`: frames in, actuators, vehicle, world, verdict, frames
    /// out. `wall` is the wall-clock time of the tick (equal to sim time in lockstep),
    /// `late` how late the tick came. Returns the outcome when the run is over.
    pub fn step(&mut self, wall: f64, late: f64) -> Result<Option<Outcome>, SimError> {
        let now = self.tick as f64 * self.dt;
        self.tick += 1;
        self.lateness.push(late);
        self.actuate(now);
        self.transmit(now, wall)?;
        self.sense(now)?;
        Ok(self.outcome(now))
    }

    /// The ECUs take their frames (through the fault plan), step and move their
    /// actuators; the vehicle drives on them and the world moves on.
    fn actuate(&mut self, now: f64) {
        let faults = &mut self.faults;
        faults.update(now, self.vehicle.odometer);
        self.steering
            .drain_with(now, &mut |m| faults.on_ecu_rx(now, m, true));
        self.throttle
            .drain_with(now, &mut |m| faults.on_ecu_rx(now, m, false));
        if !faults.is_empty() {
            let actuators = faults.actuators(now);
            self.steering.set_faults(now, &actuators);
            self.throttle.set_faults(now, &actuators);
        }
        self.steering.step(now, self.dt);
        self.throttle.step(now, self.dt);
        let steering = self.steering.actuator();
        let (phi, rate) = (steering.angle_rad, steering.rate_deg_s);
        let v = self.throttle.actuator().speed_m_s;
        self.max_steer_deg = self.max_steer_deg.max(phi.to_degrees().abs());
        self.max_steer_rate_deg_s = self.max_steer_rate_deg_s.max(rate.abs());
        if now > 0.0 {
            self.vehicle
                .step(self.scenario.vehicle.wheelbase, v, phi, self.dt);
            self.world.set_time(now);
        }
    }

    /// The ECUs' frames that are due (through the fault plan), the babble it injects,
    /// and the bus load of the frames the bus carried.
    fn transmit(&mut self, now: f64, wall: f64) -> Result<(), SimError> {
        let faults = &mut self.faults;
        self.steering
            .send_due_with(now, wall, &mut |_| faults.on_ecu_tx(now, Node::Steering))?;
        self.throttle
            .send_due_with(now, wall, &mut |_| faults.on_ecu_tx(now, Node::Throttle))?;
        if let Some((id, n)) = faults.babble(now, self.dt) {
            for _ in 0..n {
                self.steering.send_raw(id, &[0xff; 8])?;
            }
        }
        let seen = self.steering.bus_frames();
        self.bus.step(now, seen - self.bus_frames_seen);
        self.bus_frames_seen = seen;
        Ok(())
    }

    /// The sensors' outputs due now (through the fault plan), and the driven path.
    fn sense(&mut self, now: f64) -> Result<(), SimError> {
        let faults = &mut self.faults;
        if let Some(gps) = &mut self.gps {
            if !faults.is_empty() {
                let receiver = faults.gps_receiver(now);
                gps.set_fix_override(receiver.fix);
                gps.set_position_offset(receiver.east_m, receiver.north_m);
            }
            self.outputs.gps = faults.gps(now, gps.poll(now, &self.vehicle)?);
        }
        if let Some(laser) = &mut self.laser
            && now + 1e-9 >= self.next_scan
        {
            let v = &self.vehicle;
            // Written in place into the frame that goes out.
            let mut scan = self.spare_frame.take().unwrap_or_default();
            laser.scan_into(&self.world, now, v.x, v.y, v.theta, &mut scan);
            self.outputs.laser = faults.laser(now, Some(scan));
            self.next_scan = firmware_bridge::clock::next_slot(self.next_scan, now, laser.period());
        }
        if self
            .trajectory
            .last()
            .is_some_and(|(t, _)| now - t >= TRAJECTORY_EVERY - 1e-9)
        {
            self.trajectory.push((now, self.vehicle));
        }
        Ok(())
    }

    /// The run's outcome, when it is over now: a collision, the car safe after the
    /// controller went away (or the wind-down's limit), the goal reached (after the
    /// route), or the time limit.
    fn outcome(&mut self, now: f64) -> Option<Outcome> {
        if let Some(r) = &mut self.route {
            r.update(now, self.vehicle.x, self.vehicle.y);
        }
        // The distances that could have changed give both the clearance bookkeeping and
        // the collision verdict (a distance of zero is a touch or an overlap).
        let touched = self
            .clearances
            .update(&self.world, &self.scenario.vehicle, &self.vehicle);
        if let Some(i) = touched {
            return Some(Outcome::Collision {
                time: now,
                obstacle: i,
            });
        }
        if let Some(w) = &mut self.wind_down {
            // The controller is gone: no goal counts any more; the run ends once the car
            // is safe (both ECUs report their safe state and it has stopped).
            if w.stopped.is_none() && self.vehicle.v.abs() < STOPPED {
                w.stopped = Some(now);
            }
            let safe = self.steering.safe() && self.throttle.safe();
            if (safe && w.stopped.is_some()) || now - w.since >= WIND_DOWN_LIMIT {
                return Some(Outcome::Stopped {
                    time: now,
                    reason: w.reason.clone(),
                });
            }
        } else if self.scenario.success.reach_goal
            && self.distance_to_goal() <= self.scenario.goal.tolerance
            && self.route.as_ref().is_none_or(RouteCheck::driven)
        {
            return Some(Outcome::GoalReached { time: now });
        }
        if now >= self.scenario.sim.time_limit_s {
            return Some(Outcome::TimeLimit { time: now });
        }
        None
    }

    /// The controller went away (`reason`): from now on the run waits for the car to
    /// be safe, up to [`WIND_DOWN_LIMIT`], and reports how it got there.
    pub fn controller_gone(&mut self, reason: String) {
        if self.wind_down.is_none() {
            self.wind_down = Some(WindDown {
                reason,
                since: self.time(),
                speed_then: self.vehicle.v,
                stopped: None,
            });
        }
    }

    /// The way to the safe state after the controller went away, if it did.
    pub fn safe_state(&self) -> Option<SafeStateReport> {
        let w = self.wind_down.as_ref()?;
        let ecu = |st: &Station<B>, command: u16| {
            let t = crate::ecu::safety_timing(&self.scenario.can, command);
            let period = crate::ecu::period_of::<golf_car_can::SteeringReport>();
            let bound_ms = (t.command_timeout + period) * 1e3;
            let last = st.last_command();
            let safe = st.safe_since();
            let latency_ms = match (last, safe) {
                (Some(c), Some(s)) => Some((s - c) * 1e3),
                _ => None,
            };
            EcuSafeState {
                last_command_s: last,
                safe_report_s: safe,
                latency_ms,
                bound_ms,
                // Never enabled: it was safe all along.
                within_bound: !st.was_enabled() || latency_ms.is_some_and(|l| l <= bound_ms + 1e-6),
                was_enabled: st.was_enabled(),
            }
        };
        Some(SafeStateReport {
            reason: w.reason.clone(),
            noticed_s: w.since,
            speed_then: w.speed_then,
            steering: ecu(&self.steering, golf_car_can::SteeringCmd::ID),
            throttle: ecu(&self.throttle, golf_car_can::ThrottleCmd::ID),
            stopped_s: w.stopped,
        })
    }

    pub fn distance_to_goal(&self) -> f64 {
        (self.vehicle.x - self.scenario.goal.x).hypot(self.vehicle.y - self.scenario.goal.y)
    }

    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            time: self.time(),
            vehicle: self.vehicle,
            steering_enabled: self.steering.state().0,
            steering_fault: self.steering.state().1,
            throttle_enabled: self.throttle.state().0,
            throttle_fault: self.throttle.state().1,
            distance_to_goal: self.distance_to_goal(),
        }
    }

    /// CAN statistics of the two ECUs.
    pub fn node_stats(&self) -> (NodeStats, NodeStats) {
        (self.steering.stats(), self.throttle.stats())
    }

    /// Jitter of the report periods (deviation of each interval from the DBC period).
    pub fn report_jitter(&self) -> Jitter {
        let period = crate::ecu::period_of::<golf_car_can::SteeringReport>();
        let deviations = [self.steering.report_times(), self.throttle.report_times()]
            .iter()
            .flat_map(|t| t.windows(2).map(|w| (w[1] - w[0] - period).abs()))
            .collect();
        Jitter::of(deviations)
    }

    /// How late the physics ticks came.
    pub fn tick_lateness(&self) -> Jitter {
        Jitter::of(self.lateness.clone())
    }

    /// The injected faults, timed against the ECUs' safe states.
    pub fn fault_records(&self) -> Vec<FaultRecord> {
        self.faults
            .report(self.steering.safe_entries(), self.throttle.safe_entries())
    }
}

/// The result of a run, as JSON for people and CI.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    pub scenario: String,
    #[serde(flatten)]
    pub outcome: Outcome,
    pub final_state: VehicleState,
    pub path_length: f64,
    pub distance_to_goal: f64,
    /// Closest approach of the footprint to each obstacle, metres.
    pub min_clearance: Vec<f64>,
    pub max_steer_deg: f64,
    pub max_steer_rate_deg_s: f64,
    pub steering_can: NodeStats,
    pub throttle_can: NodeStats,
    /// Deviation of the report intervals from their period (wall clock).
    pub report_jitter: Jitter,
    /// How late the physics ticks came (wall clock; zero in lockstep).
    pub tick_lateness: Jitter,
    /// After the controller went away: each ECU's time to its safe state.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safe_state: Option<SafeStateReport>,
    /// Every injected fault: when, how much, what detected it, how fast each ECU
    /// reached its safe state.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultRecord>,
    /// The bus's load against the DBC's bit rate (worst-case stuffing).
    pub bus_load: BusLoadReport,
    /// With waypoints: which were passed in order, and how far along the route the car
    /// got ([`crate::verdict::route`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub route: Option<RouteReport>,
}

impl<B: Can + QueueDrops> Sim<B> {
    /// The report of the run so far, ended by `outcome`.
    /// What the arbitration of a bus with the wire's time did (SIL with
    /// `can.bit_timing`), for the report's bus load.
    pub fn bus_arbitrated(&mut self, stats: firmware_bridge::can::arbiter::ArbitrationStats) {
        self.bus.arbitrated(stats);
    }

    pub fn report(&self, outcome: Outcome) -> RunReport {
        let (steering_can, throttle_can) = self.node_stats();
        RunReport {
            scenario: self.scenario.name.clone(),
            outcome,
            final_state: self.vehicle,
            path_length: self.vehicle.odometer,
            distance_to_goal: self.distance_to_goal(),
            min_clearance: self.clearances.resolved(&self.world),
            max_steer_deg: self.max_steer_deg,
            max_steer_rate_deg_s: self.max_steer_rate_deg_s,
            steering_can,
            throttle_can,
            report_jitter: self.report_jitter(),
            tick_lateness: self.tick_lateness(),
            safe_state: self.safe_state(),
            faults: self.fault_records(),
            bus_load: self.bus.report(),
            route: self.route.as_ref().map(RouteCheck::report),
        }
    }
}
