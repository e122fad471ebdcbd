//! An actuator ECU's place on the simulator's bus: the simulator's own ECU node, or
//! a physical ECU whose reports move the simulated vehicle; and the standalone ECU, a
//! simulated ECU alone on any interface as a stand-in for the hardware on a bench.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};

use embedded_can::nb::Can;
use firmware_bridge::can::QueueDrops;
use firmware_bridge::can::timed::Horizon;
use firmware_bridge::clock::Clock;
use firmware_bridge::{BridgeError, CanPort, Received};
use golf_car_can::{E2eStats, GolfCarMessage, Payload};
use serde::Serialize;

use super::{Ecu, EcuKind, EcuNode, EcuSections};
use crate::devices::map::EcuDevice;
use crate::faults::{CounterMode, RxFault, TxFault};

/// A node's CAN statistics.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NodeStats {
    pub e2e: E2eStats,
    pub undecodable: u64,
    pub bus_errors: u64,
    /// Other nodes' frames its port saw and its acceptance filter kept from it.
    pub overheard: u64,
    pub sent: u64,
    /// Times the safe state was entered: command timeout, heartbeat timeout, estop,
    /// fault report, second sender, its own hardware fault (the simulated ECU's; zero
    /// for a physical one).
    pub safe_state_trips: [u64; 6],
    /// Enables the simulated ECU refused, by reason, and whether it ever enabled
    /// (all zero for a physical one).
    pub enable: crate::ecu::safety::EnableRefusals,
    /// Reports received from the physical ECU (absent when the ECU is simulated).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physical_reports: Option<u64>,
    /// Frames the kernel dropped from its socket's full receive queue (HIL; absent on
    /// the memory bus, which cannot drop one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub queue_drops: Option<u32>,
    /// The first [`REJECTIONS_KEPT`] frames E2E rejected, each with the simulated time
    /// it was read and why (which stream, which counters): what a skipped counter in
    /// a failed bench run lost.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub first_rejections: Vec<String>,
}

/// The rejected frames a station describes in its statistics.
pub const REJECTIONS_KEPT: usize = 8;

/// What plays an actuator ECU in the run.
#[derive(Debug)]
enum Twin {
    /// The simulator's own ECU (boxed: far larger than the physical one's state).
    Simulated(Box<EcuNode>),
    /// A physical ECU (on a physical bus behind the gateway): the simulated twin stays
    /// silent and the vehicle follows the physical ECU's reports.
    Physical(Reported),
}

/// The last report of a physical ECU.
#[derive(Debug, Default)]
struct Reported {
    reports: u64,
    enabled: bool,
    /// Road-wheel angle (a steering ECU's).
    angle_rad: f64,
    /// Steering rate (a steering ECU's).
    rate_deg_s: f64,
    /// Wheel speed (a throttle ECU's).
    speed_m_s: f64,
}

impl Reported {
    fn handle(&mut self, kind: EcuKind, message: &GolfCarMessage) {
        use GolfCarMessage as M;
        match (kind, message) {
            (EcuKind::Steering, M::SteeringReport(r)) => {
                self.enabled = r.enabled;
                self.angle_rad = r.angle.to_radians();
                self.rate_deg_s = r.rate;
            }
            (EcuKind::Throttle, M::ThrottleReport(r)) => {
                self.enabled = r.enabled;
                self.speed_m_s = r.wheel_speed;
            }
            _ => return,
        }
        self.reports += 1;
    }
}

/// One rejected frame for [`NodeStats::first_rejections`]: when, the message's name
/// when the DBC has its ID, and the E2E check's finding.
fn describe_rejection(now: f64, e: &golf_car_can::E2eError) -> String {
    let name = e
        .id()
        .and_then(|id| golf_car_can::NETWORK.message(id))
        .map_or("?", |m| &m.name);
    format!("t={now:.3} s {name}: {e}")
}

/// An actuator ECU and its connection to the simulator's bus.
#[derive(Debug)]
pub struct Station<B> {
    kind: EcuKind,
    twin: Twin,
    port: CanPort<B>,
    sent: u64,
    /// Wall-clock times of the node's periodic reports (HIL jitter).
    report_times: Vec<f64>,
    /// Since when (simulated time) the node's reports say it is disabled, after it
    /// had been enabled: when the bus learnt of its safe state.
    safe_since: Option<f64>,
    was_enabled: bool,
    /// Each entry into the safe state: simulated time and the ECU's fault then.
    safe_entries: Vec<(f64, Option<crate::ecu::safety::Cause>)>,
    /// Frames held back by an injected delay: due time, ID, bytes (sending), or the
    /// message (receiving).
    delayed_tx: VecDeque<(f64, u16, Vec<u8>)>,
    delayed_rx: VecDeque<(f64, GolfCarMessage)>,
    /// Frames received from the bus (any, accepted or not), and raw frames sent.
    received: u64,
    raw_sent: u64,
    /// The first rejected frames described ([`NodeStats::first_rejections`]).
    first_rejections: Vec<String>,
    /// The last payload sent per ID (an injected repeated counter sends it again).
    last_sent: HashMap<u16, Payload>,
}

impl<B: Can + QueueDrops> Station<B> {
    /// The ECU `kind` on `port`, simulated or physical as `device` says. The ECU takes
    /// only its node's messages (an ECU's acceptance filter: another node's stream is
    /// not its business, not even a gap in its counter); the port still sees, and
    /// counts, the others'.
    pub fn new(
        kind: EcuKind,
        device: &EcuDevice,
        sections: &EcuSections<'_>,
        mut port: CanPort<B>,
    ) -> Self {
        port.hear_only(&kind.accepts());
        Station {
            kind,
            twin: match device {
                EcuDevice::Simulated {} => Twin::Simulated(Box::new(EcuNode::new(kind, sections))),
                EcuDevice::Physical { .. } => Twin::Physical(Reported::default()),
            },
            port,
            sent: 0,
            report_times: Vec::new(),
            safe_since: None,
            was_enabled: false,
            safe_entries: Vec::new(),
            delayed_tx: VecDeque::new(),
            delayed_rx: VecDeque::new(),
            last_sent: HashMap::new(),
            received: 0,
            raw_sent: 0,
            first_rejections: Vec::new(),
        }
    }

    /// Take every frame waiting on the bus. A simulated ECU whose receiver sees a
    /// second sender on any counter stream goes to its safe state.
    pub fn drain(&mut self, now: f64) {
        self.drain_with(now, &mut |_| RxFault::Pass);
    }

    /// [`Self::drain`] with `rx` deciding, frame by frame, what an injected fault does
    /// to what the ECU receives.
    pub fn drain_with(&mut self, now: f64, rx: &mut dyn FnMut(&GolfCarMessage) -> RxFault) {
        while self.delayed_rx.front().is_some_and(|d| d.0 <= now + 1e-9) {
            if let Some((_, m)) = self.delayed_rx.pop_front() {
                self.handle(now, &m);
            }
        }
        while let Some(r) = self.port.try_recv() {
            if !matches!(r, Received::BusError(_)) {
                self.received += 1;
            }
            match r {
                Received::Message(m) => match rx(&m) {
                    RxFault::Pass => self.handle(now, &m),
                    RxFault::Drop => {}
                    RxFault::Delay(d) => self.delayed_rx.push_back((now + d, m)),
                },
                Received::Rejected(e) if self.first_rejections.len() < REJECTIONS_KEPT => {
                    self.first_rejections.push(describe_rejection(now, &e));
                }
                _ => {}
            }
        }
        if let (Twin::Simulated(node), Some(id)) = (&mut self.twin, self.port.second_sender()) {
            node.on_second_sender(now, id);
        }
    }

    fn handle(&mut self, now: f64, m: &GolfCarMessage) {
        match &mut self.twin {
            Twin::Simulated(node) => node.handle(now, m),
            Twin::Physical(reported) => reported.handle(self.kind, m),
        }
    }

    /// The injected actuator faults in force from `now` (a physical ECU has its own).
    pub fn set_faults(&mut self, now: f64, faults: &crate::faults::ActuatorFaults) {
        if let Twin::Simulated(node) = &mut self.twin {
            node.set_faults(now, faults);
        }
    }

    /// Move the simulated actuator by `dt` ending at `now` (a physical one moves itself).
    pub fn step(&mut self, now: f64, dt: f64) {
        if let Twin::Simulated(node) = &mut self.twin {
            node.step(now, dt);
        }
    }

    /// Send what the simulated ECU has due at `now`; `wall` is the wall-clock time.
    pub fn send_due(&mut self, now: f64, wall: f64) -> Result<(), BridgeError> {
        self.send_due_with(now, wall, &mut |_| TxFault::default())
    }

    /// [`Self::send_due`] with `tx` deciding, frame by frame, what an injected fault
    /// does to what the ECU sends.
    pub fn send_due_with(
        &mut self,
        now: f64,
        wall: f64,
        tx: &mut dyn FnMut(&GolfCarMessage) -> TxFault,
    ) -> Result<(), BridgeError> {
        while self.delayed_tx.front().is_some_and(|d| d.0 <= now + 1e-9) {
            if let Some((_, id, bytes)) = self.delayed_tx.pop_front() {
                self.port.send_bytes(id, &bytes)?;
                self.sent += 1;
            }
        }
        let Twin::Simulated(node) = &mut self.twin else {
            return Ok(());
        };
        for m in node.due(now) {
            let enabled = match &m {
                GolfCarMessage::SteeringReport(r) => Some(r.enabled),
                GolfCarMessage::ThrottleReport(r) => Some(r.enabled),
                _ => None,
            };
            if let Some(enabled) = enabled {
                self.report_times.push(wall);
                if enabled {
                    self.was_enabled = true;
                    self.safe_since = None;
                } else if self.was_enabled && self.safe_since.is_none() {
                    self.safe_since = Some(now);
                    self.safe_entries.push((now, node.safety_ref().fault()));
                }
            }
            let fault = tx(&m);
            if fault.drop {
                continue;
            }
            let (id, mut data) = self.port.seal_message(&m)?;
            match fault.counter {
                // One counter value used up and never sent.
                Some(CounterMode::Skip) => data = self.port.seal_message(&m)?.1,
                Some(CounterMode::Repeat) => {
                    if let Some(previous) = self.last_sent.get(&id) {
                        data = *previous;
                    }
                }
                None => {}
            }
            self.last_sent.insert(id, data);
            if fault.corrupt_crc {
                data[7] ^= 0x5a;
            }
            let bytes = &data[..fault.dlc.map_or(data.len(), usize::from)];
            if fault.delay_s > 0.0 {
                self.delayed_tx
                    .push_back((now + fault.delay_s, id, bytes.to_vec()));
            } else {
                self.port.send_bytes(id, bytes)?;
                self.sent += 1;
            }
        }
        Ok(())
    }

    /// Send bytes as they are from this station's endpoint (a babbling node).
    pub fn send_raw(&mut self, id: u16, bytes: &[u8]) -> Result<(), BridgeError> {
        self.port.send_bytes(id, bytes)?;
        self.raw_sent += 1;
        Ok(())
    }

    /// Every frame this station has seen cross the bus: received (its node's and the
    /// others'), and sent.
    pub fn bus_frames(&self) -> u64 {
        self.received + self.port.overheard() + self.sent + self.raw_sent
    }

    /// Each entry into the safe state (reported disabled after being enabled):
    /// simulated time and the fault the ECU reported then.
    pub fn safe_entries(&self) -> &[(f64, Option<crate::ecu::safety::Cause>)] {
        &self.safe_entries
    }

    /// Since when the simulated ECU has reported its safe state (disabled after it had
    /// been enabled), simulated seconds; `None` while enabled, or never driven.
    pub fn safe_since(&self) -> Option<f64> {
        self.safe_since
    }

    /// The ECU is in its safe state: its reports say so, or it was never enabled.
    pub fn safe(&self) -> bool {
        !self.was_enabled || self.safe_since.is_some()
    }

    /// Whether it was ever enabled.
    pub fn was_enabled(&self) -> bool {
        self.was_enabled
    }

    /// When the simulated ECU received its last command, simulated seconds.
    pub fn last_command(&self) -> Option<f64> {
        match &self.twin {
            Twin::Simulated(node) => node.safety_ref().last_command(),
            Twin::Physical(_) => None,
        }
    }

    /// Wall-clock times of the periodic reports sent.
    pub fn report_times(&self) -> &[f64] {
        &self.report_times
    }

    /// The node's CAN statistics.
    pub fn stats(&self) -> NodeStats {
        NodeStats {
            e2e: self.port.stats(),
            undecodable: self.port.undecodable(),
            bus_errors: self.port.bus_errors(),
            overheard: self.port.overheard(),
            sent: self.sent,
            safe_state_trips: match &self.twin {
                Twin::Simulated(node) => node.safety_ref().trips,
                Twin::Physical(_) => [0; 6],
            },
            enable: match &self.twin {
                Twin::Simulated(node) => node.safety_ref().refusals,
                Twin::Physical(_) => Default::default(),
            },
            physical_reports: match &self.twin {
                Twin::Simulated(_) => None,
                Twin::Physical(r) => Some(r.reports),
            },
            queue_drops: self.port.queue_drops(),
            first_rejections: self.first_rejections.clone(),
        }
    }

    /// Enabled, and the fault the simulated ECU is in (a physical one's is in its report).
    pub fn state(&self) -> (bool, Option<crate::ecu::safety::Cause>) {
        match &self.twin {
            Twin::Simulated(node) => (node.safety_ref().enabled(), node.safety_ref().fault()),
            Twin::Physical(r) => (r.enabled, None),
        }
    }

    /// What the actuator does: a steering ECU's road-wheel angle and rate, a throttle
    /// ECU's wheel speed (the other ECU's quantities zero).
    pub fn actuator(&self) -> ActuatorReading {
        match &self.twin {
            Twin::Simulated(node) => match &node.ecu {
                Ecu::Steering(e) => ActuatorReading {
                    angle_rad: e.angle(),
                    rate_deg_s: e.rate_deg_s(),
                    ..ActuatorReading::default()
                },
                Ecu::Throttle(e) => ActuatorReading {
                    speed_m_s: e.speed(),
                    ..ActuatorReading::default()
                },
            },
            Twin::Physical(r) => ActuatorReading {
                angle_rad: r.angle_rad,
                rate_deg_s: r.rate_deg_s,
                speed_m_s: r.speed_m_s,
            },
        }
    }
}

/// What an ECU's actuator does ([`Station::actuator`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ActuatorReading {
    /// The steering's road-wheel angle.
    pub angle_rad: f64,
    /// The steering's rate.
    pub rate_deg_s: f64,
    /// The drive's wheel speed.
    pub speed_m_s: f64,
}

/// A standalone ECU's state for status lines.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StandaloneStatus {
    pub time: f64,
    pub enabled: bool,
    pub fault: Option<super::safety::Cause>,
    /// Road-wheel angle (deg) or wheel speed (m/s).
    pub value: f64,
    pub stats: NodeStats,
}

/// Run the simulated ECU `kind` alone on `port` (a stand-in for the hardware: it
/// answers commands, watches the heartbeat and reports, as in a run) on `clock`,
/// at the scenario's physics rate (`sections.sim`), until `stop`. `horizon`, when
/// the port reads through it ([`firmware_bridge::can::timed`]), is set at each tick's
/// deadline, so ticks that catch up after a stall take the frames of their own
/// periods, as in a HIL run. `status` is called every `status_every` seconds. Returns
/// the final status.
#[allow(clippy::too_many_arguments)]
pub fn run_standalone<B: Can + QueueDrops>(
    kind: EcuKind,
    sections: &EcuSections<'_>,
    port: CanPort<B>,
    horizon: Option<&Horizon>,
    clock: &mut dyn Clock,
    stop: &AtomicBool,
    status_every: f64,
    status: &mut dyn FnMut(&StandaloneStatus),
) -> Result<StandaloneStatus, BridgeError> {
    let mut station = Station::new(kind, &EcuDevice::Simulated {}, sections, port);
    let dt = 1.0 / sections.sim.physics_hz;
    let every = ((status_every / dt).round() as u64).max(1);
    let snapshot = |station: &Station<B>, now: f64| {
        let (enabled, fault) = station.state();
        let actuator = station.actuator();
        StandaloneStatus {
            time: now,
            enabled,
            fault,
            value: match kind {
                EcuKind::Steering => actuator.angle_rad.to_degrees(),
                EcuKind::Throttle => actuator.speed_m_s,
            },
            stats: station.stats(),
        }
    };
    let mut k = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let late = clock.wait_tick(k);
        if let Some(h) = horizon {
            h.set_for_tick(late);
        }
        let now = k as f64 * dt;
        station.drain(now);
        station.step(now, dt);
        station.send_due(now, clock.now())?;
        if k.is_multiple_of(every) {
            status(&snapshot(&station, now));
        }
        k += 1;
    }
    Ok(snapshot(&station, k.saturating_sub(1) as f64 * dt))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use firmware_bridge::can::membus::{MemBus, MemEndpoint};
    use golf_car_can::e2e::{counter_of, protect};
    use golf_car_can::{
        CanMessage, ControllerHeartbeat, ControllerHeartbeatState, FaultReport, FaultReportCode,
        SteeringCmd,
    };

    use crate::ecu::safety::Cause;

    /// A steering station on a memory bus with a controller's endpoint and a spare one
    /// (a forger's), stepped at 200 Hz with a heartbeat every 20 ms and a command every
    /// 10 ms (`send` says whether each command reaches the bus).
    struct Bench {
        station: Station<MemEndpoint>,
        controller: CanPort<MemEndpoint>,
        forger: CanPort<MemEndpoint>,
        k: u64,
        /// Every message the controller received.
        seen: Vec<GolfCarMessage>,
    }

    impl Bench {
        fn new() -> Bench {
            let bus = MemBus::new();
            let scenario = Scenario::default();
            Bench {
                station: Station::new(
                    EcuKind::Steering,
                    &EcuDevice::Simulated {},
                    &scenario.ecu_sections(),
                    CanPort::new(bus.endpoint(), "mem"),
                ),
                controller: CanPort::new(bus.endpoint(), "mem"),
                forger: CanPort::new(bus.endpoint(), "mem"),
                k: 0,
                seen: Vec::new(),
            }
        }

        /// Step 5 ms: the controller's STEERING_CMD on even steps (reaching the bus when
        /// `send_command`), and with `forge` a forger's answer to it carrying the next
        /// counter and 35 degrees.
        fn step(&mut self, send_command: bool, forge: bool) {
            let now = self.k as f64 * 0.005;
            if self.k.is_multiple_of(4) {
                let _ = self.controller.send(&ControllerHeartbeat {
                    state: ControllerHeartbeatState::Auto,
                });
            }
            if self.k.is_multiple_of(2) {
                let cmd = SteeringCmd {
                    enable: now > 0.05,
                    target_angle: 2.0,
                    max_rate: 0.0,
                };
                // The controller's counter advances whether or not the frame arrives.
                let mut data = cmd.encode().unwrap_or_default();
                let counter = ((self.k / 2) % 16) as u8;
                protect(SteeringCmd::ID, &mut data, counter);
                if send_command {
                    let _ = self.controller.send_payload(SteeringCmd::ID, &data);
                }
                if forge {
                    let mut forged = SteeringCmd {
                        target_angle: 35.0,
                        ..cmd
                    }
                    .encode()
                    .unwrap_or_default();
                    protect(SteeringCmd::ID, &mut forged, counter_of(&data) + 1);
                    let _ = self.forger.send_payload(SteeringCmd::ID, &forged);
                }
            }
            self.station.drain(now);
            self.station.step(now, 0.005);
            let _ = self.station.send_due(now, now);
            while let Some(r) = self.controller.try_recv() {
                if let Received::Message(m) = r {
                    self.seen.push(m);
                }
            }
            while self.forger.try_recv().is_some() {}
            self.k += 1;
        }

        fn fault_reports(&self) -> Vec<FaultReport> {
            self.seen
                .iter()
                .filter_map(|m| match m {
                    GolfCarMessage::FaultReport(f) => Some(*f),
                    _ => None,
                })
                .collect()
        }
    }

    #[test]
    fn a_forger_answering_each_command_puts_the_steering_ecu_in_its_safe_state() {
        let mut b = Bench::new();
        for _ in 0..200 {
            b.step(true, false);
        }
        assert!(b.station.state().0, "enabled before the forger");
        let before = b.station.actuator().angle_rad.to_degrees();
        for _ in 0..100 {
            b.step(true, true);
        }
        let (enabled, fault) = b.station.state();
        assert!(!enabled);
        assert_eq!(fault, Some(Cause::SecondSender));
        let stats = b.station.stats();
        assert_eq!(stats.e2e.second_sender, 1, "{stats:?}");
        assert_eq!(stats.safe_state_trips[Cause::SecondSender as usize], 1);
        // Found within a few frames: the wheels barely moved towards the forged 35 deg.
        let angle = b.station.actuator().angle_rad.to_degrees();
        eprintln!("wheels {before:.2} -> {angle:.2} deg before the safe state");
        assert!(angle - before < 3.0, "{before} -> {angle}");
        let reports = b.fault_reports();
        assert!(
            reports
                .iter()
                .any(|f| f.code == FaultReportCode::SecondSender && f.detail == SteeringCmd::ID),
            "{reports:?}"
        );
    }

    #[test]
    fn occasional_lost_commands_never_trip_the_second_sender_fault() {
        let mut b = Bench::new();
        // 30 s: one command in 25 lost, and a burst of 8 lost (80 ms, under the
        // command timeout) every 5 s.
        for k in 0..6000u64 {
            let lost = (k / 2) % 25 == 7 || (500..516).contains(&(k % 1000));
            b.step(!lost, false);
            if k > 100 {
                assert!(b.station.state().0, "step {k}: {:?}", b.station.state());
            }
        }
        let stats = b.station.stats();
        assert_eq!(stats.e2e.second_sender, 0, "{stats:?}");
        assert!(stats.e2e.skipped_counter > 100, "{stats:?}");
        assert!(b.fault_reports().is_empty());
    }

    #[test]
    fn the_first_rejected_frames_are_described_with_their_stream_and_counters() {
        let mut b = Bench::new();
        // Commands at steps 0, 2, 4, ...; the one at step 10 (counter 5) is lost.
        for k in 0..40u64 {
            b.step(k != 10, false);
        }
        let stats = b.station.stats();
        assert_eq!(stats.e2e.skipped_counter, 1, "{stats:?}");
        assert_eq!(
            stats.first_rejections,
            ["t=0.060 s STEERING_CMD: CAN ID 0x100: counter skipped from 4 to 6 (expected 5)"]
        );
        // Only the first few are kept.
        for k in 40..4000u64 {
            b.step(k % 20 != 0, false);
        }
        let stats = b.station.stats();
        assert!(stats.e2e.skipped_counter > 100, "{stats:?}");
        assert_eq!(stats.first_rejections.len(), REJECTIONS_KEPT);
    }
}
