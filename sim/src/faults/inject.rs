//! The fault plan at run time: which faults are in force, what each does to the
//! frames, epochs and scans crossing the simulator's side of the wires, what the
//! controller and the ECUs did about it, and the figures of the verdict. The same
//! injector runs in SIL and HIL: `Sim::step` consults it at the wire seam.

use std::collections::BTreeSet;

use golf_car_can::{ControllerHeartbeatState, FaultReportCode, FaultReportSource, GolfCarMessage};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::Serialize;

use super::plan::{CounterMode, EcuFaultCode, EcuName, Fault, FaultKind, Node, Start};
use crate::devices::gps::{FixKind, GpsEpoch};
use crate::ecu::safety::Cause;
use crate::ecu::steering::SteeringFaults;
use crate::ecu::throttle::ThrottleFaults;
use firmware_bridge::laser::LaserFrame;

/// The random stream of fault draws (apart from the sensors' noise streams).
const FAULT_STREAM: u64 = 0xfa17;

/// What an injected fault does to one frame an ECU sends.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TxFault {
    pub drop: bool,
    pub delay_s: f64,
    pub corrupt_crc: bool,
    pub counter: Option<CounterMode>,
    /// Send only this many bytes.
    pub dlc: Option<u8>,
}

/// What an injected fault does to one frame an ECU receives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RxFault {
    Pass,
    Drop,
    Delay(f64),
}

/// The actuator faults in force.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ActuatorFaults {
    pub steering: SteeringFaults,
    pub throttle: ThrottleFaults,
    pub steering_code: Option<EcuFaultCode>,
    pub throttle_code: Option<EcuFaultCode>,
}

/// The GPS receiver faults in force: the fix kind forced, and the reported position's
/// offset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpsReceiverFaults {
    pub fix: Option<FixKind>,
    pub east_m: f64,
    pub north_m: f64,
}

/// What the controller's process is made to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessFault {
    Running,
    /// SIGSTOP (SIL: not stepped) until the fault ends.
    Stopped,
    /// SIGKILL (SIL: never stepped again).
    Killed,
}

/// A reaction seen on the bus: the controller's estop or FAULT_REPORT.
#[derive(Clone, Debug, PartialEq)]
struct Reaction {
    at_s: f64,
    /// The episode's latest sighting.
    last_s: f64,
    what: String,
    /// The code it names (see [`reaction_codes`]).
    code: &'static str,
}

#[derive(Clone, Debug, Default)]
struct FaultRun {
    started_s: Option<f64>,
    injected: u64,
}

/// The fault plan of a run, applied.
#[derive(Debug)]
pub struct Injector {
    faults: Vec<Fault>,
    runs: Vec<FaultRun>,
    rng: ChaCha8Rng,
    last_gps_text: Option<String>,
    last_scan: Option<Box<LaserFrame>>,
    babble_due: f64,
    reactions: Vec<Reaction>,
    last_state: Option<ControllerHeartbeatState>,
}

/// How long a FAULT_REPORT code must be absent before it counts as a new reaction, s
/// (longer than the 500 ms a node repeats its FAULT_REPORT at).
const REPORT_EPISODE_S: f64 = 1.5;

impl Injector {
    /// The plan `faults`, drawing with the scenario's `seed`.
    pub fn new(faults: Vec<Fault>, seed: u64) -> Injector {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(FAULT_STREAM);
        Injector {
            runs: vec![FaultRun::default(); faults.len()],
            faults,
            rng,
            last_gps_text: None,
            last_scan: None,
            babble_due: 0.0,
            reactions: Vec::new(),
            last_state: None,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.faults.is_empty()
    }

    /// Start the faults whose time or distance has come (`odometer`: metres driven).
    pub fn update(&mut self, now: f64, odometer: f64) {
        for (f, r) in self.faults.iter().zip(&mut self.runs) {
            if r.started_s.is_none() {
                let due = match f.start {
                    Start::At(t) => now + 1e-9 >= t,
                    Start::After(d) => odometer >= d,
                };
                if due {
                    r.started_s = Some(now);
                }
            }
            // Faults of the actuators and the controller's process act on every
            // physics step they are in force: those steps are what they inject.
            let per_step = matches!(
                f.kind,
                FaultKind::SteeringStuck
                    | FaultKind::SteeringRateCut { .. }
                    | FaultKind::SteeringOffset { .. }
                    | FaultKind::ThrottleStuck
                    | FaultKind::BrakeWeak { .. }
                    | FaultKind::EcuFault { .. }
                    | FaultKind::DriverOverride { .. }
                    | FaultKind::ControllerKill
                    | FaultKind::ControllerStop
            );
            if per_step && Self::in_force(f, r, now) {
                r.injected += 1;
            }
        }
    }

    fn in_force(f: &Fault, r: &FaultRun, now: f64) -> bool {
        r.started_s
            .is_some_and(|s| now + 1e-9 >= s && f.duration_s.is_none_or(|d| now < s + d - 1e-9))
    }

    /// The faults in force at `now`, with their index.
    fn active(&self, now: f64) -> impl Iterator<Item = (usize, &FaultKind)> {
        self.faults
            .iter()
            .zip(&self.runs)
            .enumerate()
            .filter(move |(_, (f, r))| Self::in_force(f, r, now))
            .map(|(i, (f, _))| (i, &f.kind))
    }

    /// [`Self::active`], owned: the injector changes its counts and draws while
    /// it goes through them.
    fn active_owned(&self, now: f64) -> Vec<(usize, FaultKind)> {
        self.active(now).map(|(i, k)| (i, k.clone())).collect()
    }

    fn count(&mut self, i: usize) {
        self.runs[i].injected += 1;
    }

    /// The actuator faults in force at `now`.
    pub fn actuators(&self, now: f64) -> ActuatorFaults {
        let mut a = ActuatorFaults::default();
        for (_, k) in self.active(now) {
            match *k {
                FaultKind::SteeringStuck => a.steering.stuck = true,
                FaultKind::SteeringRateCut { factor } => a.steering.rate_factor *= factor,
                FaultKind::SteeringOffset { deg } => a.steering.offset_deg += deg,
                FaultKind::DriverOverride { deg } => a.steering.driver_deg = Some(deg),
                FaultKind::ThrottleStuck => a.throttle.stuck = true,
                FaultKind::BrakeWeak { factor } => a.throttle.brake_factor *= factor,
                FaultKind::EcuFault {
                    ecu: EcuName::Steering,
                    code,
                } => a.steering_code = Some(code),
                FaultKind::EcuFault {
                    ecu: EcuName::Throttle,
                    code,
                } => a.throttle_code = Some(code),
                _ => {}
            }
        }
        a
    }

    /// The receiver's state at `now`: the fix kind forced, and the position offset.
    pub fn gps_receiver(&self, now: f64) -> GpsReceiverFaults {
        let mut receiver = GpsReceiverFaults::default();
        for (_, k) in self.active(now) {
            match *k {
                FaultKind::GpsQuality { fix: f } => receiver.fix = Some(f),
                FaultKind::GpsJump { east_m, north_m } => {
                    receiver.east_m += east_m;
                    receiver.north_m += north_m;
                }
                _ => {}
            }
        }
        receiver
    }

    /// What the faults in force do to a frame the ECU `node` sends at `now`.
    pub fn on_ecu_tx(&mut self, now: f64, node: Node) -> TxFault {
        let mut out = TxFault::default();
        let hits = self.active_owned(now);
        for (i, k) in hits {
            let on_node = |n: Node| n == node;
            let hit = match k {
                FaultKind::CanBusOff => {
                    out.drop = true;
                    true
                }
                FaultKind::CanSilence { node: n } if on_node(n) => {
                    out.drop = true;
                    true
                }
                FaultKind::CanDrop {
                    node: n,
                    probability,
                } if on_node(n) => {
                    let drop = self.rng.random::<f64>() < probability;
                    out.drop |= drop;
                    drop
                }
                FaultKind::CanDelay { node: n, delay_s } if on_node(n) => {
                    out.delay_s += delay_s;
                    true
                }
                FaultKind::CanCorruptCrc { node: n } if on_node(n) => {
                    out.corrupt_crc = true;
                    true
                }
                FaultKind::CanCounter { node: n, mode } if on_node(n) => {
                    out.counter = Some(mode);
                    true
                }
                FaultKind::CanDlc { node: n, dlc } if on_node(n) => {
                    out.dlc = Some(dlc);
                    true
                }
                _ => false,
            };
            if hit {
                self.count(i);
            }
        }
        out
    }

    /// What the faults in force do to a frame an ECU receives at `now`; `counted`
    /// says whether this receiver's hits count (both ECUs receive every frame: one of
    /// them counts). The controller's estop and FAULT_REPORTs are noted as reactions.
    pub fn on_ecu_rx(&mut self, now: f64, m: &GolfCarMessage, counted: bool) -> RxFault {
        self.observe(now, m);
        let from_controller = match m {
            GolfCarMessage::ControllerHeartbeat(_)
            | GolfCarMessage::SteeringCmd(_)
            | GolfCarMessage::ThrottleCmd(_) => true,
            GolfCarMessage::FaultReport(f) => f.source == FaultReportSource::Controller,
            _ => false,
        };
        let heartbeat = matches!(m, GolfCarMessage::ControllerHeartbeat(_));
        let mut out = RxFault::Pass;
        let hits = self.active_owned(now);
        for (i, k) in hits {
            let on = |n: Node| match n {
                Node::Controller => from_controller,
                Node::Heartbeat => heartbeat,
                Node::Steering | Node::Throttle => false,
            };
            let hit = match k {
                FaultKind::CanBusOff => {
                    out = RxFault::Drop;
                    true
                }
                FaultKind::CanSilence { node } if on(node) => {
                    out = RxFault::Drop;
                    true
                }
                FaultKind::CanDrop { node, probability } if on(node) => {
                    let drop = self.rng.random::<f64>() < probability;
                    if drop {
                        out = RxFault::Drop;
                    }
                    drop
                }
                FaultKind::CanDelay { node, delay_s } if on(node) => {
                    if out == RxFault::Pass {
                        out = RxFault::Delay(delay_s);
                    }
                    true
                }
                _ => false,
            };
            if hit && counted {
                self.count(i);
            }
        }
        out
    }

    fn observe(&mut self, now: f64, m: &GolfCarMessage) {
        match m {
            GolfCarMessage::ControllerHeartbeat(h) => {
                if h.state == ControllerHeartbeatState::Estop
                    && self.last_state != Some(ControllerHeartbeatState::Estop)
                {
                    self.reactions.push(Reaction {
                        at_s: now,
                        last_s: now,
                        what: "controller: estop".to_owned(),
                        code: ControllerHeartbeatState::Estop.label(),
                    });
                }
                self.last_state = Some(h.state);
            }
            GolfCarMessage::FaultReport(f) if f.source == FaultReportSource::Controller => {
                let code = f.code.label();
                let what = format!("controller: FAULT_REPORT {code}");
                match self.reactions.iter_mut().rev().find(|r| r.what == what) {
                    // The same episode while the reports keep coming.
                    Some(r) if now - r.last_s < REPORT_EPISODE_S => r.last_s = now,
                    _ => self.reactions.push(Reaction {
                        at_s: now,
                        last_s: now,
                        what,
                        code,
                    }),
                }
            }
            _ => {}
        }
    }

    /// The GPS epoch as the faults in force leave it (`None`: nothing goes out).
    pub fn gps(&mut self, now: f64, epoch: Option<GpsEpoch>) -> Option<GpsEpoch> {
        let mut epoch = epoch?;
        let original = epoch.text.clone();
        let hits = self.active_owned(now);
        let mut stale = false;
        for (i, k) in hits {
            match k {
                FaultKind::GpsOutage => {
                    self.count(i);
                    return None;
                }
                // The receiver made this epoch with the fix kind or offset forced.
                FaultKind::GpsQuality { .. } | FaultKind::GpsJump { .. } => self.count(i),
                FaultKind::GpsStale => {
                    if let Some(old) = &self.last_gps_text {
                        epoch.text = old.clone();
                        stale = true;
                        self.count(i);
                    }
                }
                FaultKind::GpsHeadingLost => {
                    epoch.text = epoch
                        .text
                        .split_inclusive('\n')
                        .filter(|l| !matches!(l.get(3..6), Some("HDT" | "THS")))
                        .collect();
                    self.count(i);
                }
                FaultKind::GpsBadChecksum { probability } => {
                    let mut out = String::with_capacity(epoch.text.len());
                    for line in epoch.text.split_inclusive('\n') {
                        if self.rng.random::<f64>() < probability {
                            out.push_str(&bad_checksum(line));
                            self.count(i);
                        } else {
                            out.push_str(line);
                        }
                    }
                    epoch.text = out;
                }
                FaultKind::GpsGarbage { bytes } => {
                    // Line noise: any 7-bit byte, CR, LF, '$' and '*' included.
                    let garbage: String = (0..bytes)
                        .map(|_| char::from(self.rng.random::<u8>() & 0x7f))
                        .collect();
                    epoch.text = garbage + &epoch.text;
                    self.count(i);
                }
                FaultKind::GpsBaudMismatch => {
                    // What a UART at the wrong rate makes of the bytes: every one
                    // misframed, so no sentence survives.
                    epoch.text = epoch
                        .text
                        .bytes()
                        .map(|b| char::from((b.rotate_left(3) ^ 0x5a) & 0x7f))
                        .collect();
                    self.count(i);
                }
                _ => {}
            }
        }
        if !stale {
            self.last_gps_text = Some(original);
        }
        Some(epoch)
    }

    /// The laser scan as the faults in force leave it (`None`: nothing goes out).
    pub fn laser(&mut self, now: f64, frame: Option<Box<LaserFrame>>) -> Option<Box<LaserFrame>> {
        let mut frame = frame?;
        let hits = self.active_owned(now);
        let mut frozen = false;
        let n = (frame.count as usize).min(frame.ranges.len());
        for (i, k) in hits {
            match k {
                FaultKind::LaserBlackout => {
                    self.count(i);
                    return None;
                }
                FaultKind::LaserFrozen => {
                    if let Some(old) = &self.last_scan {
                        frame = old.clone();
                        frozen = true;
                        self.count(i);
                    }
                }
                FaultKind::LaserNanStorm => {
                    frame.ranges[..n].fill(f32::NAN);
                    self.count(i);
                }
                FaultKind::LaserZeroStorm => {
                    frame.ranges[..n].fill(0.0);
                    self.count(i);
                }
                FaultKind::LaserOccluded { from_deg, to_deg } => {
                    let (a, b) = (from_deg.to_radians(), to_deg.to_radians());
                    for j in 0..n {
                        let angle = f64::from(frame.angle_min)
                            + j as f64 * f64::from(frame.angle_increment);
                        if (a..=b).contains(&angle) {
                            frame.ranges[j] = f32::NAN;
                            frame.intensities[j] = 0.0;
                        }
                    }
                    self.count(i);
                }
                FaultKind::LaserPhantom {
                    range_m,
                    bearing_deg,
                    radius_m,
                } => {
                    let (cx, cy) = (
                        range_m * bearing_deg.to_radians().cos(),
                        range_m * bearing_deg.to_radians().sin(),
                    );
                    for j in 0..n {
                        let angle = f64::from(frame.angle_min)
                            + j as f64 * f64::from(frame.angle_increment);
                        if let Some(t) = ray_circle(angle, cx, cy, radius_m) {
                            let r = frame.ranges[j];
                            let t = t as f32;
                            if t >= frame.range_min && (r.is_nan() || t < r) {
                                frame.ranges[j] = t;
                                frame.intensities[j] = 100.0;
                            }
                        }
                    }
                    self.count(i);
                }
                _ => {}
            }
        }
        // Only a plan that can freeze the laser needs the last scan kept.
        if !frozen
            && self
                .faults
                .iter()
                .any(|f| matches!(f.kind, FaultKind::LaserFrozen))
        {
            match &mut self.last_scan {
                Some(last) => last.clone_from(&frame),
                None => self.last_scan = Some(frame.clone()),
            }
        }
        Some(frame)
    }

    /// Frames a babbling node sends in the step ending at `now` (`dt` long): its CAN
    /// ID and how many.
    pub fn babble(&mut self, now: f64, dt: f64) -> Option<(u16, usize)> {
        let (i, id, rate) = self.active(now).find_map(|(i, k)| match *k {
            FaultKind::CanBabble { id, rate_hz } => Some((i, id, rate_hz)),
            _ => None,
        })?;
        self.babble_due += rate * dt;
        let n = self.babble_due.floor();
        self.babble_due -= n;
        let n = n as usize;
        self.runs[i].injected += n as u64;
        Some((id, n))
    }

    /// What the controller's process is made to do at `now`.
    pub fn process(&self, now: f64) -> ProcessFault {
        let mut out = ProcessFault::Running;
        for (f, r) in self.faults.iter().zip(&self.runs) {
            match f.kind {
                FaultKind::ControllerKill if r.started_s.is_some_and(|s| now + 1e-9 >= s) => {
                    return ProcessFault::Killed;
                }
                FaultKind::ControllerStop if Self::in_force(f, r, now) => {
                    out = ProcessFault::Stopped;
                }
                _ => {}
            }
        }
        out
    }

    /// Each fault as the verdict reports it, with the ECUs' safe-state entries
    /// (simulated time, fault) to time them against.
    pub fn report(
        &self,
        steering: &[(f64, Option<Cause>)],
        throttle: &[(f64, Option<Cause>)],
    ) -> Vec<FaultRecord> {
        self.faults
            .iter()
            .zip(&self.runs)
            .map(|(f, r)| {
                let Some(start) = r.started_s else {
                    return FaultRecord {
                        fault: f.clone(),
                        started_s: None,
                        ended_s: None,
                        injected: 0,
                        detected_by: None,
                        detected_s: None,
                        detection_ms: None,
                        steering_safe_ms: None,
                        throttle_safe_ms: None,
                        steering_trip_ms: None,
                        throttle_trip_ms: None,
                        reactions: Vec::new(),
                        reaction_codes: Vec::new(),
                    };
                };
                let after = |entries: &[(f64, Option<Cause>)]| {
                    entries
                        .iter()
                        .find(|(t, _)| *t + 1e-9 >= start)
                        .map(|(t, c)| (*t, *c))
                };
                let (s, t) = (after(steering), after(throttle));
                // Entries for a fault (not a commanded disable, as at the mission's end).
                let tripped = |entries: &[(f64, Option<Cause>)]| {
                    entries
                        .iter()
                        .find(|(at, c)| *at + 1e-9 >= start && c.is_some())
                        .map(|(at, _)| (at - start) * 1e3)
                };
                // (time, what, code): a commanded disable names no code.
                let mut candidates: Vec<(f64, String, Option<&'static str>)> = self
                    .reactions
                    .iter()
                    .filter(|x| x.at_s + 1e-9 >= start)
                    .map(|x| (x.at_s, x.what.clone(), Some(x.code)))
                    .collect();
                for (name, e) in [("steering", s), ("throttle", t)] {
                    if let Some((at, cause)) = e {
                        let code = cause.map(cause_name);
                        candidates.push((
                            at,
                            format!("{name} ECU: {}", code.unwrap_or("disabled")),
                            code,
                        ));
                    }
                }
                candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
                let reactions = candidates
                    .iter()
                    .map(|(at, what, _)| format!("{what} (+{:.0} ms)", (at - start) * 1e3))
                    .collect();
                let reaction_codes = candidates.iter().filter_map(|c| c.2).collect();
                let first = candidates.into_iter().next();
                FaultRecord {
                    fault: f.clone(),
                    started_s: Some(start),
                    ended_s: f.duration_s.map(|d| start + d),
                    injected: r.injected,
                    detection_ms: first.as_ref().map(|x| (x.0 - start) * 1e3),
                    detected_s: first.as_ref().map(|x| x.0),
                    detected_by: first.map(|x| x.1),
                    steering_safe_ms: s.map(|x| (x.0 - start) * 1e3),
                    throttle_safe_ms: t.map(|x| (x.0 - start) * 1e3),
                    steering_trip_ms: tripped(steering),
                    throttle_trip_ms: tripped(throttle),
                    reactions,
                    reaction_codes,
                }
            })
            .collect()
    }
}

/// One injected fault in the verdict.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultRecord {
    #[serde(flatten)]
    pub fault: Fault,
    /// When it started (never, when its distance was not reached), simulated seconds.
    pub started_s: Option<f64>,
    pub ended_s: Option<f64>,
    /// What it altered, dropped or added: CAN frames, GPS epochs or sentences, laser
    /// scans; for actuator and process faults, the physics steps it was in force.
    pub injected: u64,
    /// The first reaction after its start: the controller's estop or FAULT_REPORT, or
    /// an ECU entering its safe state (with the fault it reported).
    pub detected_by: Option<String>,
    pub detected_s: Option<f64>,
    pub detection_ms: Option<f64>,
    /// From the fault's start to each ECU's next entry into its safe state, ms.
    pub steering_safe_ms: Option<f64>,
    pub throttle_safe_ms: Option<f64>,
    /// The same for an entry with a fault (a trip), not a commanded disable.
    pub steering_trip_ms: Option<f64>,
    pub throttle_trip_ms: Option<f64>,
    /// Every reaction from its start on, in order, with its time after the start.
    pub reactions: Vec<String>,
    /// The codes these reactions name, in order (a commanded disable names none):
    /// what `[expect] detected_by` must equal.
    #[serde(skip)]
    pub reaction_codes: Vec<&'static str>,
}

/// The expectations `expect` that the injected faults `records` did not meet, one
/// failure line each. `controller_gone_s`: when the controller went away (after it,
/// the ECUs trip by design: a ridden-out fault is judged up to then).
pub fn unmet(
    expect: &super::Expectations,
    records: &[FaultRecord],
    controller_gone_s: Option<f64>,
) -> Vec<String> {
    let mut out = Vec::new();
    for (i, r) in records.iter().enumerate() {
        let name = format!("faults[{i}] {}", r.fault.kind.name());
        let Some(start) = r.started_s else {
            out.push(format!(
                "{name} never started (its distance was not driven)"
            ));
            continue;
        };
        if r.injected == 0 {
            out.push(format!(
                "{name} at {start:.2} s: fault never injected (it altered, dropped or added nothing while in force)"
            ));
        }
        if let Some(limit) = expect.detected_within_s {
            match r.detection_ms {
                Some(ms) if ms <= limit * 1e3 + 1e-6 => {}
                Some(ms) => out.push(format!(
                    "{name} at {start:.2} s: detected after {ms:.0} ms ({}), beyond {:.0} ms",
                    r.detected_by.as_deref().unwrap_or("?"),
                    limit * 1e3
                )),
                None => out.push(format!("{name} at {start:.2} s: never detected")),
            }
        }
        if let Some(want) = &expect.detected_by
            && !r.reaction_codes.contains(&want.as_str())
        {
            out.push(format!(
                "{name}: no reaction names {want}; the reactions: {}",
                if r.reactions.is_empty() {
                    "none".to_owned()
                } else {
                    r.reactions.join(", ")
                }
            ));
        }
        for (ecu, ms, trip_ms) in [
            ("steering", r.steering_safe_ms, r.steering_trip_ms),
            ("throttle", r.throttle_safe_ms, r.throttle_trip_ms),
        ] {
            if let Some(limit) = expect.safe_within_s {
                match ms {
                    Some(ms) if ms <= limit * 1e3 + 1e-6 => {}
                    Some(ms) => out.push(format!(
                        "{name}: the {ecu} ECU safe after {ms:.0} ms, beyond {:.0} ms",
                        limit * 1e3
                    )),
                    None => out.push(format!(
                        "{name}: the {ecu} ECU never entered its safe state"
                    )),
                }
            }
            let before_gone = |ms: &f64| controller_gone_s.is_none_or(|g| start + ms / 1e3 < g);
            if expect.ecus_stay_enabled
                && let Some(ms) = trip_ms.filter(before_gone)
            {
                out.push(format!(
                    "{name}: the {ecu} ECU tripped to its safe state {ms:.0} ms after the fault, which was to be ridden out"
                ));
            }
        }
    }
    out
}

/// The codes a reaction can name, which `[expect] detected_by` must be one of: the
/// DBC's FAULT_REPORT codes (the controller's reports; its estop is `estop`) and the
/// faults an ECU enters its safe state for.
pub fn reaction_codes() -> BTreeSet<&'static str> {
    FaultReportCode::ALL
        .iter()
        .map(|c| c.label())
        .chain(ECU_CAUSES.iter().map(|&c| cause_name(c)))
        .collect()
}

/// Every fault an ECU enters its safe state for (what [`cause_name`] names).
const ECU_CAUSES: [Cause; 6] = [
    Cause::CommandTimeout,
    Cause::HeartbeatTimeout,
    Cause::Estop,
    Cause::FaultReport,
    Cause::SecondSender,
    Cause::Actuator,
];

fn cause_name(c: Cause) -> &'static str {
    match c {
        Cause::CommandTimeout => "command_timeout",
        Cause::HeartbeatTimeout => "heartbeat_timeout",
        Cause::Estop => "estop",
        Cause::FaultReport => "fault_report",
        Cause::SecondSender => "second_sender",
        Cause::Actuator => "actuator_fault",
    }
}

/// The sentence `line` with its checksum wrong (every hex digit changed).
fn bad_checksum(line: &str) -> String {
    match line.rfind('*') {
        Some(star) if line.len() >= star + 3 => {
            let hex = &line[star + 1..star + 3];
            match u8::from_str_radix(hex, 16) {
                Ok(v) => format!("{}{:02X}{}", &line[..=star], v ^ 0xff, &line[star + 3..]),
                Err(_) => line.to_owned(),
            }
        }
        _ => line.to_owned(),
    }
}

/// Distance along the ray at `angle` from the origin to the circle (cx, cy, r), if
/// the ray meets it.
fn ray_circle(angle: f64, cx: f64, cy: f64, r: f64) -> Option<f64> {
    let (dx, dy) = (angle.cos(), angle.sin());
    let along = dx * cx + dy * cy;
    if along <= 0.0 {
        return None;
    }
    let miss2 = (cx * cx + cy * cy) - along * along;
    let h2 = r * r - miss2;
    (h2 >= 0.0).then(|| along - h2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_checksum_changes_only_the_checksum() {
        let line = "$GNGGA,1*4F\r\n";
        assert_eq!(bad_checksum(line), "$GNGGA,1*B0\r\n");
    }

    #[test]
    fn a_ray_meets_a_circle_ahead_at_its_near_side() {
        let t = ray_circle(0.0, 5.0, 0.0, 1.0).expect("hit");
        assert!((t - 4.0).abs() < 1e-12);
        assert!(ray_circle(std::f64::consts::PI, 5.0, 0.0, 1.0).is_none());
        assert!(ray_circle(0.5, 5.0, 0.0, 1.0).is_none());
    }

    /// A started fault's record with `injected` and the reactions naming `codes`.
    fn record(injected: u64, codes: &[&'static str]) -> FaultRecord {
        FaultRecord {
            fault: Fault {
                kind: FaultKind::GpsOutage,
                start: Start::At(1.0),
                duration_s: Some(2.0),
            },
            started_s: Some(1.0),
            ended_s: Some(3.0),
            injected,
            detected_by: codes
                .first()
                .map(|c| format!("controller: FAULT_REPORT {c}")),
            detected_s: Some(1.2),
            detection_ms: Some(200.0),
            steering_safe_ms: None,
            throttle_safe_ms: None,
            steering_trip_ms: None,
            throttle_trip_ms: None,
            reactions: codes
                .iter()
                .map(|c| format!("controller: FAULT_REPORT {c} (+200 ms)"))
                .collect(),
            reaction_codes: codes.to_vec(),
        }
    }

    #[test]
    fn detected_by_matches_a_reaction_code_exactly_not_a_part_of_one() {
        let expect = |code: &str| super::super::Expectations {
            detected_by: Some(code.to_owned()),
            ..Default::default()
        };
        let records = [record(10, &["gps_lost"])];
        assert_eq!(
            unmet(&expect("gps_lost"), &records, None),
            Vec::<String>::new()
        );
        let failures = unmet(&expect("gps_degraded"), &records, None);
        assert_eq!(
            failures,
            [
                "faults[0] gps_outage: no reaction names gps_degraded; the reactions: controller: FAULT_REPORT gps_lost (+200 ms)"
            ]
        );
        // A part of the code named (the old substring match passed it).
        let failures = unmet(&expect("gps"), &records, None);
        assert!(
            failures[0].contains("no reaction names gps;"),
            "{failures:?}"
        );
    }

    #[test]
    fn a_fault_that_never_took_effect_fails_the_run() {
        let expect = super::super::Expectations::default();
        assert_eq!(
            unmet(&expect, &[record(1, &[])], None),
            Vec::<String>::new()
        );
        let failures = unmet(&expect, &[record(0, &[])], None);
        assert_eq!(failures.len(), 1, "{failures:?}");
        assert!(
            failures[0].starts_with("faults[0] gps_outage at 1.00 s: fault never injected"),
            "{failures:?}"
        );
    }

    #[test]
    fn reaction_codes_are_the_dbc_report_codes_and_the_ecu_causes() {
        let codes = reaction_codes();
        for code in ["gps_lost", "e2e_errors", "estop", "report_timeout"] {
            assert!(codes.contains(code), "{code}: {codes:?}");
        }
        for code in ["command_timeout", "fault_report", "actuator_fault"] {
            assert!(codes.contains(code), "{code}: {codes:?}");
        }
        assert!(
            !codes.contains("disabled") && !codes.contains(""),
            "{codes:?}"
        );
    }
}
