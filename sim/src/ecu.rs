//! The simulated actuator ECUs as CAN nodes: each reacts to the frames it receives,
//! moves its actuator, and says when its report and its fault reports are due. The
//! same node runs on a SocketCAN interface (HIL) or in lockstep (SIL).

pub mod safety;
pub mod station;
pub mod steering;
pub mod throttle;

use golf_car_can::{
    CanMessage, FaultReport, FaultReportCode, FaultReportSource, GolfCarMessage, NETWORK,
    SteeringReport, ThrottleReport,
};

use crate::scenario::schema::{
    CanConfig, SimConfig, SteeringConfig, ThrottleConfig, VehicleConfig,
};
use safety::{Safety, SafetyTiming};
pub use steering::SteeringEcu;
pub use throttle::ThrottleEcu;

/// The period of a message from the DBC, seconds.
pub fn period_of<M: CanMessage>() -> f64 {
    f64::from(M::spec().cycle_time_ms.unwrap_or(10)) / 1000.0
}

/// What the ECUs take of a scenario: their actuators' sections, the vehicle's limits
/// their commands are clamped to, the bus's fault-clear time, and the physics rate a
/// standalone ECU ticks at.
#[derive(Clone, Copy, Debug)]
pub struct EcuSections<'a> {
    pub steering: &'a SteeringConfig,
    pub throttle: &'a ThrottleConfig,
    pub vehicle: &'a VehicleConfig,
    pub can: &'a CanConfig,
    pub sim: &'a SimConfig,
}

/// The watchdog timing from the DBC's receiver timeouts and the `[can]` section.
pub fn safety_timing(can: &CanConfig, command: u16) -> SafetyTiming {
    let timeout = |id: u16| {
        NETWORK
            .message(id)
            .and_then(|m| m.timeout_ms)
            .map_or(0.1, |ms| f64::from(ms) / 1000.0)
    };
    SafetyTiming {
        command_timeout: timeout(command),
        heartbeat_timeout: timeout(golf_car_can::ControllerHeartbeat::ID),
        fault_clear: f64::from(can.fault_clear_ms) / 1000.0,
    }
}

/// Which ECU a node is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EcuKind {
    Steering,
    Throttle,
}

impl EcuKind {
    /// Its node in golf_car.dbc.
    pub fn node(self) -> &'static str {
        match self {
            EcuKind::Steering => "STEERING_ECU",
            EcuKind::Throttle => "THROTTLE_ECU",
        }
    }

    /// The IDs its acceptance filter lets through: what the DBC has it send or
    /// receive.
    pub fn accepts(self) -> Vec<u16> {
        golf_car_can::NETWORK.ids_of_node(self.node())
    }
}

/// A simulated ECU on the bus.
#[derive(Clone, Debug)]
pub enum Ecu {
    Steering(SteeringEcu),
    Throttle(ThrottleEcu),
}

/// One ECU node with its send schedule.
#[derive(Clone, Debug)]
pub struct EcuNode {
    pub ecu: Ecu,
    next_report: f64,
    /// The enabled state the last report carried.
    reported_enabled: Option<bool>,
    next_fault: f64,
    /// Frames the node ignored (not addressed to it: other reports, its own kind).
    pub ignored: u64,
    /// The CAN ID of the last stream seen with a second sender (FAULT_REPORT detail).
    second_sender: Option<u16>,
}

impl EcuNode {
    pub fn new(kind: EcuKind, sections: &EcuSections<'_>) -> EcuNode {
        let s = sections;
        let ecu = match kind {
            EcuKind::Steering => Ecu::Steering(SteeringEcu::new(
                s.steering.clone(),
                s.vehicle.max_steer_deg,
                Safety::new(safety_timing(s.can, golf_car_can::SteeringCmd::ID)),
            )),
            EcuKind::Throttle => Ecu::Throttle(ThrottleEcu::new(
                s.throttle.clone(),
                s.vehicle.max_speed,
                Safety::new(safety_timing(s.can, golf_car_can::ThrottleCmd::ID)),
            )),
        };
        EcuNode {
            ecu,
            next_report: 0.0,
            reported_enabled: None,
            next_fault: 0.0,
            ignored: 0,
            second_sender: None,
        }
    }

    fn safety(&mut self) -> &mut Safety {
        match &mut self.ecu {
            Ecu::Steering(e) => &mut e.safety,
            Ecu::Throttle(e) => &mut e.safety,
        }
    }

    pub fn safety_ref(&self) -> &Safety {
        match &self.ecu {
            Ecu::Steering(e) => &e.safety,
            Ecu::Throttle(e) => &e.safety,
        }
    }

    fn source(&self) -> FaultReportSource {
        match self.ecu {
            Ecu::Steering(_) => FaultReportSource::SteeringEcu,
            Ecu::Throttle(_) => FaultReportSource::ThrottleEcu,
        }
    }

    /// A decoded frame from the bus.
    pub fn handle(&mut self, now: f64, message: &GolfCarMessage) {
        let own_source = self.source();
        match (message, &mut self.ecu) {
            (GolfCarMessage::ControllerHeartbeat(h), _) => self.safety().on_heartbeat(now, h.state),
            (GolfCarMessage::FaultReport(f), _) if f.source != own_source => {
                self.safety().on_fault_report(now)
            }
            (GolfCarMessage::SteeringCmd(c), Ecu::Steering(e)) => e.on_command(now, c),
            (GolfCarMessage::ThrottleCmd(c), Ecu::Throttle(e)) => e.on_command(now, c),
            _ => self.ignored += 1,
        }
    }

    /// The receiver found a second sender on the stream of CAN ID `id`: the safe state
    /// and a FAULT_REPORT (second_sender, detail `id`) while it lasts.
    pub fn on_second_sender(&mut self, now: f64, id: u16) {
        self.second_sender = Some(id);
        self.safety().on_second_sender(now);
    }

    /// The injected actuator faults in force from `now` on.
    pub fn set_faults(&mut self, now: f64, faults: &crate::faults::ActuatorFaults) {
        let code = match &mut self.ecu {
            Ecu::Steering(e) => {
                e.faults = faults.steering;
                faults.steering_code
            }
            Ecu::Throttle(e) => {
                e.faults = faults.throttle;
                faults.throttle_code
            }
        };
        if self.safety_ref().actuator_fault() != code {
            self.safety().set_actuator_fault(now, code);
        }
    }

    /// Move the actuator by `dt` ending at `now`.
    pub fn step(&mut self, now: f64, dt: f64) {
        match &mut self.ecu {
            Ecu::Steering(e) => e.step(now, dt),
            Ecu::Throttle(e) => e.step(now, dt),
        }
    }

    /// The messages due at `now`: the periodic report, and a FAULT_REPORT every 100 ms
    /// while a fault the ECU detected itself lasts.
    pub fn due(&mut self, now: f64) -> Vec<GolfCarMessage> {
        let mut out = Vec::new();
        // The report goes out on its period and, at once, when the ECU enters or
        // leaves its enabled state (on change, as actuator ECUs do): the bus learns of
        // a safe state within the physics step that caused it, not a period later.
        let enabled = self.safety_ref().enabled();
        let changed = self.reported_enabled != Some(enabled);
        let periodic = now + 1e-9 >= self.next_report;
        if periodic || changed {
            self.reported_enabled = Some(enabled);
            let (msg, period) = match &self.ecu {
                Ecu::Steering(e) => (
                    GolfCarMessage::SteeringReport(e.report()),
                    period_of::<SteeringReport>(),
                ),
                Ecu::Throttle(e) => (
                    GolfCarMessage::ThrottleReport(e.report()),
                    period_of::<ThrottleReport>(),
                ),
            };
            out.push(msg);
            if periodic {
                self.next_report = firmware_bridge::clock::next_slot(self.next_report, now, period);
            }
        }
        let own = match self.safety_ref().fault() {
            Some(safety::Cause::Actuator) => self.safety_ref().actuator_fault().map(|c| match c {
                crate::faults::EcuFaultCode::Overcurrent => FaultReportCode::ActuatorOvercurrent,
                crate::faults::EcuFaultCode::Sensor => FaultReportCode::ActuatorSensor,
                crate::faults::EcuFaultCode::Internal => FaultReportCode::ActuatorFault,
            }),
            cause => cause.and_then(|c| c.own_fault_code()),
        };
        match own {
            Some(code) if now + 1e-9 >= self.next_fault => {
                let detail = match (code, self.second_sender, &self.ecu) {
                    (FaultReportCode::SecondSender, Some(id), _) => id,
                    (_, _, Ecu::Steering(_)) => golf_car_can::SteeringCmd::ID,
                    (_, _, Ecu::Throttle(_)) => golf_car_can::ThrottleCmd::ID,
                };
                out.push(GolfCarMessage::FaultReport(FaultReport {
                    source: self.source(),
                    code,
                    detail,
                }));
                self.next_fault = now + period_of::<FaultReport>();
            }
            Some(_) => {}
            None => self.next_fault = now,
        }
        out
    }
}
