//! The controller's loop: the one piece of code that runs the controller on its three
//! ports, for the binary on the wall clock and the real wires (serial GPS, iceoryx2
//! laser, SocketCAN) and for SIL on the lockstep clock and memory ports.
//!
//! Every 10 ms tick takes the inputs in one order (CAN reports, then GPS bytes, then
//! laser frames), runs [`Controller::tick`] and sends its messages. What can go wrong
//! on a port is one of two things ([`InputError`]): a malformed input (a sentence that
//! fails its checksum, a frame of another version) is counted and skipped; a port that
//! is gone (the GPS device closed, the shared-memory service broken) is a fault: the
//! controller estops (estop heartbeat, FAULT_REPORT, both ECUs commanded disabled) and
//! keeps telling the bus so for [`LOST_PORT_GRACE`] before the loop ends. The trace
//! goes out while the loop runs ([`TraceWriter`]), so whatever ends the process leaves
//! it on disk; so does the controller's own recording of its ports, when made
//! ([`Runtime::with_recorder`]).

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};

use chrono::Timelike;
use firmware_bridge::clock::{Clock, monotonic_ns};
use firmware_bridge::laser::{LaserError, LaserFrame, LaserSubscriber};
use firmware_bridge::nmea::{NmeaError, NmeaLink, NmeaReader, ReadEvent, ReaderConfig};
use firmware_bridge::{BridgeError, CanPort};
use golf_car_can::{
    ControllerHeartbeat, ControllerHeartbeatState, FaultReportCode, GolfCarMessage,
};
use serde::Serialize;
use serde_json::json;

use crate::control::{COMMAND_PERIOD, Controller, HEARTBEAT_PERIOD, Mode};
use crate::record::{BackgroundWriter, RecordSummary, Writer, topics};
use crate::trace::{FixTiming, Trace, TraceWriter};

/// How long a controller that lost a port keeps sending its estop before the loop
/// ends, seconds: several heartbeat and FAULT_REPORT periods, and longer than the
/// ECUs' 100 ms command timeout, so they are in their safe state by the estop, not by
/// the silence that follows.
pub const LOST_PORT_GRACE: f64 = 0.5;

/// The environment variable through which the simulator that starts a controller
/// (`ugv-sim run --controller`) gives it its process id: the controller then ends
/// with that process (`ugv-controller run`, the parent-death signal), and refuses to
/// start when it is already gone.
pub const SIMULATOR_PID_ENV: &str = "UGV_SIM_PID";

/// How long the loop sends estop heartbeats after a stop was requested, seconds.
pub const STOP_GRACE: f64 = 0.1;

/// Most laser frames taken in one tick (a backlog after a stall drains over a few
/// ticks; a flood cannot hold the loop).
const MAX_FRAMES_PER_TICK: usize = 16;

/// What went wrong on an input port.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InputError {
    /// One input was malformed; the port goes on.
    #[error("malformed input: {0}")]
    Malformed(String),
    /// The port is gone.
    #[error("port lost: {0}")]
    Lost(String),
}

/// The GPS port: NMEA bytes in, readings out, never blocking.
pub trait GpsInput {
    /// The events completed by what the port has now.
    fn poll(&mut self) -> Result<Vec<ReadEvent>, InputError>;

    /// The bytes the last poll read off the line (for the controller's recording).
    fn last_read(&self) -> &[u8];
}

/// The laser port: validated frames, oldest first, never blocking. Boxed: a frame is
/// 8.7 kB, moved out of the port and into the loop without copying it again.
pub trait LaserInput {
    fn try_recv(&mut self) -> Result<Option<Box<LaserFrame>>, InputError>;

    /// A frame the loop has done with, for the port to fill again (SIL hands it back to
    /// the simulator's scanner: no new 8.7 kB frame to zero per scan). Dropped by default.
    fn recycle(&mut self, _frame: Box<LaserFrame>) {}
}

impl<P: Read + Write> GpsInput for NmeaLink<P> {
    fn poll(&mut self) -> Result<Vec<ReadEvent>, InputError> {
        NmeaLink::poll(self).map_err(|e| match e {
            NmeaError::Io { .. } => InputError::Lost(e.to_string()),
            other => InputError::Malformed(other.to_string()),
        })
    }

    fn last_read(&self) -> &[u8] {
        NmeaLink::last_read(self)
    }
}

impl LaserInput for LaserSubscriber {
    fn try_recv(&mut self) -> Result<Option<Box<LaserFrame>>, InputError> {
        match LaserSubscriber::try_recv(self) {
            Ok(frame) => Ok(frame.map(Box::new)),
            Err(e @ (LaserError::Ipc { .. } | LaserError::ServiceName { .. })) => {
                Err(InputError::Lost(e.to_string()))
            }
            Err(other) => Err(InputError::Malformed(other.to_string())),
        }
    }
}

/// A GPS port in memory (SIL): bytes pushed in are read by the NMEA reader at the next
/// poll, exactly as the binary reads its serial port.
#[derive(Debug)]
pub struct MemGps {
    reader: NmeaReader,
    pending: Vec<u8>,
    /// What the last poll read.
    last: Vec<u8>,
    lost: Option<String>,
}

impl MemGps {
    pub fn new(config: ReaderConfig) -> MemGps {
        MemGps {
            reader: NmeaReader::new(config),
            pending: Vec::new(),
            last: Vec::new(),
            lost: None,
        }
    }

    /// Bytes that arrived on the line.
    pub fn push(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
    }

    /// The port goes away (the cable pulled): the next poll reports it lost.
    pub fn close(&mut self, why: &str) {
        self.lost = Some(why.to_owned());
    }
}

impl GpsInput for MemGps {
    fn poll(&mut self) -> Result<Vec<ReadEvent>, InputError> {
        if let Some(why) = &self.lost {
            return Err(InputError::Lost(why.clone()));
        }
        self.last.clear();
        std::mem::swap(&mut self.last, &mut self.pending);
        Ok(self.reader.feed(&self.last).collect())
    }

    fn last_read(&self) -> &[u8] {
        &self.last
    }
}

/// A laser port in memory (SIL): frames are validated when taken, as the iceoryx2
/// subscriber does.
#[derive(Debug, Default)]
pub struct MemLaser {
    frames: VecDeque<Box<LaserFrame>>,
    lost: Option<String>,
    /// The last frame the loop has done with ([`LaserInput::recycle`]).
    spent: Option<Box<LaserFrame>>,
}

impl MemLaser {
    pub fn push(&mut self, frame: Box<LaserFrame>) {
        self.frames.push_back(frame);
    }

    /// The last frame the loop has done with, to be written again.
    pub fn take_spent(&mut self) -> Option<Box<LaserFrame>> {
        self.spent.take()
    }

    /// The service goes away: the next receive reports it lost.
    pub fn close(&mut self, why: &str) {
        self.lost = Some(why.to_owned());
    }
}

impl LaserInput for MemLaser {
    fn try_recv(&mut self) -> Result<Option<Box<LaserFrame>>, InputError> {
        if let Some(why) = &self.lost {
            return Err(InputError::Lost(why.clone()));
        }
        match self.frames.pop_front() {
            None => Ok(None),
            Some(f) => f
                .validate()
                .map(|()| Some(f))
                .map_err(|e| InputError::Malformed(e.to_string())),
        }
    }

    fn recycle(&mut self, frame: Box<LaserFrame>) {
        self.spent = Some(frame);
    }
}

/// Why the loop ended.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "exit", rename_all = "snake_case")]
pub enum Exit {
    /// The mission is complete: arrived and stopped.
    Finished,
    /// A port was lost; the estop went out for [`LOST_PORT_GRACE`].
    PortLost { reason: String },
    /// A stop was requested (a signal) while in estop.
    StoppedInEstop,
    /// A stop was requested (a signal).
    Stopped,
    /// The CAN port failed: nothing more can be said to the ECUs, whose command
    /// timeouts take them to their safe state.
    CanLost { reason: String },
    /// The simulator whose clock the loop ran on ended the run (lockstep).
    RunOver,
}

impl Exit {
    /// In words, for logs and verdicts.
    pub fn describe(&self) -> String {
        match self {
            Exit::Finished => "mission complete".to_owned(),
            Exit::PortLost { reason } => format!("safety stop: {reason}"),
            Exit::StoppedInEstop => "stopped in estop".to_owned(),
            Exit::Stopped => "stopped".to_owned(),
            Exit::CanLost { reason } => format!("CAN lost: {reason}"),
            Exit::RunOver => "the simulator ended the run".to_owned(),
        }
    }

    /// The binary's exit code: 0 mission complete, 1 safety stop, 3 ended by a
    /// signal or by the simulator (lockstep), 4 error.
    pub fn code(&self) -> u8 {
        match self {
            Exit::Finished => 0,
            Exit::PortLost { .. } | Exit::StoppedInEstop => 1,
            Exit::Stopped | Exit::RunOver => 3,
            Exit::CanLost { .. } => 4,
        }
    }
}

/// What the ports delivered that could not be used.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct InputStats {
    /// GPS reads that failed without losing the port.
    pub gps_errors: u64,
    /// Laser frames refused at the port (validation).
    pub laser_frames_refused: u64,
    /// Laser frames that repeated the previous one (sequence and stamp): a frozen
    /// scanner, skipped like silence.
    pub laser_frames_repeated: u64,
    /// The last such error, for the log.
    pub last_error: Option<String>,
}

/// The loop's state while it winds down.
#[derive(Clone, Debug)]
struct Closing {
    until: f64,
    exit: Exit,
    /// Estop heartbeats only (a requested stop), instead of the controller's messages.
    heartbeats_only: bool,
}

/// The controller on its ports.
#[derive(Debug)]
pub struct Runtime<G, L, B> {
    ctl: Controller,
    gps: G,
    laser: L,
    can: CanPort<B>,
    gps_lost: bool,
    laser_lost: bool,
    /// Sequence and stamp of the last laser frame taken.
    last_scan_id: Option<(u64, u64)>,
    closing: Option<Closing>,
    next_heartbeat: f64,
    trace: Option<TraceWriter>,
    trace_error: Option<String>,
    /// The controller's own recording (`run --record`), when made: written on a thread
    /// of its own.
    recorder: Option<BackgroundWriter>,
    /// Fix timings on the monotonic clock (the binary on the wires), when kept.
    fix_timing: Option<Vec<FixTiming>>,
    unanswered: Vec<(f64, u64)>,
    pub stats: InputStats,
    /// Ticks skipped because the loop came more than a period late (see [`Runtime::run`]).
    pub skipped_ticks: u64,
}

/// The controller's node in golf_car.dbc.
pub const NODE: &str = "CONTROLLER";

/// Set the controller's acceptance filter on `can`: only what the DBC has it send or
/// receive reaches it, so a bus flooded on other IDs does not load its loop. The
/// binary's socket, SIL's memory bus and the replay all take the same.
pub fn accept_controller_ids<B>(can: &CanPort<B>) -> Result<(), BridgeError>
where
    B: embedded_can::nb::Can + firmware_bridge::can::Filtered,
{
    can.accept_only(&golf_car_can::NETWORK.ids_of_node(NODE))
}

impl<G: GpsInput, L: LaserInput, B: embedded_can::nb::Can> Runtime<G, L, B> {
    pub fn new(ctl: Controller, gps: G, laser: L, can: CanPort<B>) -> Self {
        Runtime {
            ctl,
            gps,
            laser,
            can,
            gps_lost: false,
            laser_lost: false,
            last_scan_id: None,
            closing: None,
            next_heartbeat: 0.0,
            trace: None,
            trace_error: None,
            recorder: None,
            fix_timing: None,
            unanswered: Vec::new(),
            stats: InputStats::default(),
            skipped_ticks: 0,
        }
    }

    /// Write the trace as the run goes.
    pub fn with_trace(mut self, writer: TraceWriter) -> Self {
        self.trace = Some(writer);
        self
    }

    /// Record what crosses the ports into `writer` as the loop goes (the controller's
    /// own recording, [`crate::record`]): each input at the tick that took it, each
    /// frame sent, the ticks the replannings were taken at and the ticks skipped. The
    /// loop hands copies to a thread that encodes and writes them
    /// ([`BackgroundWriter`]); an error starting it is returned.
    pub fn with_recorder(mut self, writer: Writer) -> std::io::Result<Self> {
        self.record_into(writer)?;
        Ok(self)
    }

    /// [`Runtime::with_recorder`] on a running loop, from its next tick.
    pub fn record_into(&mut self, writer: Writer) -> std::io::Result<()> {
        self.recorder = Some(BackgroundWriter::spawn(writer)?);
        self.can.keep_frames();
        Ok(())
    }

    /// Close the recording, once what is queued is written; what it holds (none
    /// without one).
    pub fn finish_recording(&mut self) -> Option<RecordSummary> {
        self.recorder.take().and_then(BackgroundWriter::finish)
    }

    /// Stamp each fix's read and the first steering command after it on the
    /// machine's monotonic clock (HIL latency figures; not deterministic, so not SIL).
    pub fn with_fix_timing(mut self) -> Self {
        self.fix_timing = Some(Vec::new());
        self
    }

    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.ctl
    }

    pub fn can(&self) -> &CanPort<B> {
        &self.can
    }

    pub fn gps_mut(&mut self) -> &mut G {
        &mut self.gps
    }

    pub fn laser_mut(&mut self) -> &mut L {
        &mut self.laser
    }

    /// The first error writing the trace, if any (the run goes on without it).
    pub fn trace_error(&self) -> Option<&str> {
        self.trace_error.as_deref()
    }

    /// End the run: estop heartbeats for [`STOP_GRACE`] from `now`, then the loop ends.
    pub fn request_stop(&mut self, now: f64) {
        if self.closing.is_none() {
            if let Some(w) = &mut self.recorder {
                w.log_other(topics::CONTROLLER_STOP, now, json!({ "requested": true }));
            }
            let exit = if matches!(self.ctl.mode(), Mode::Estop { .. }) {
                Exit::StoppedInEstop
            } else {
                Exit::Stopped
            };
            self.closing = Some(Closing {
                until: now + STOP_GRACE,
                exit,
                heartbeats_only: true,
            });
            self.next_heartbeat = now;
        }
    }

    fn lost(&mut self, now: f64, code: FaultReportCode, reason: String) {
        self.ctl.fail(code, reason.clone());
        if self.closing.is_none() {
            self.closing = Some(Closing {
                until: now + LOST_PORT_GRACE,
                exit: Exit::PortLost { reason },
                heartbeats_only: false,
            });
        }
    }

    fn note(&mut self, e: &InputError) {
        let mut text = e.to_string();
        text.truncate(200);
        self.stats.last_error = Some(text);
    }

    fn read_inputs(&mut self, now: f64) {
        while let Some(r) = self.can.try_recv() {
            self.ctl.on_can(now, &r);
        }
        if !self.gps_lost {
            let polled = self.gps.poll();
            if let Some(w) = &mut self.recorder {
                w.nmea(now, self.gps.last_read());
            }
            match polled {
                Ok(events) => {
                    for event in events {
                        if let ReadEvent::Fix(reading) = event {
                            if let Some(w) = &mut self.recorder {
                                w.reading(now, &reading);
                            }
                            if let (Some(_), Some(t)) = (&self.fix_timing, reading.time) {
                                self.unanswered.push((
                                    f64::from(t.num_seconds_from_midnight())
                                        + f64::from(t.nanosecond()) * 1e-9,
                                    monotonic_ns(),
                                ));
                            }
                            self.ctl.on_gps(now, &reading);
                        }
                    }
                }
                Err(e @ InputError::Malformed(_)) => {
                    self.stats.gps_errors += 1;
                    self.note(&e);
                }
                Err(InputError::Lost(why)) => {
                    self.gps_lost = true;
                    self.lost(
                        now,
                        FaultReportCode::GpsLost,
                        format!("GPS port lost: {why}"),
                    );
                }
            }
        }
        if !self.laser_lost {
            for _ in 0..MAX_FRAMES_PER_TICK {
                match self.laser.try_recv() {
                    Ok(Some(frame)) => {
                        if let Some(w) = &mut self.recorder {
                            w.laser(now, &frame);
                        }
                        self.take_scan(now, &frame);
                        self.laser.recycle(frame);
                    }
                    Ok(None) => break,
                    Err(e @ InputError::Malformed(_)) => {
                        self.stats.laser_frames_refused += 1;
                        self.note(&e);
                    }
                    Err(InputError::Lost(why)) => {
                        self.laser_lost = true;
                        self.lost(
                            now,
                            FaultReportCode::LaserSilent,
                            format!("laser port lost: {why}"),
                        );
                        break;
                    }
                }
            }
        }
    }

    /// A laser frame taken: a frozen scanner sends its last scan again (the same
    /// sequence and acquisition time), and only a new scan shows that it sees.
    fn take_scan(&mut self, now: f64, frame: &LaserFrame) {
        let id = (frame.sequence, frame.stamp_ns);
        if self.last_scan_id == Some(id) {
            self.stats.laser_frames_repeated += 1;
        } else {
            self.last_scan_id = Some(id);
            self.ctl.on_laser_frame(now, frame);
        }
    }

    /// The tick's frames and the controller after it onto the recording.
    fn record_tick(&mut self, now: f64, accepted_before: u64) {
        let Some(w) = &mut self.recorder else {
            return;
        };
        for f in self.can.take_frames() {
            w.can(now, f);
        }
        let taken = self.ctl.nav.accepted();
        if taken != accepted_before {
            w.log_other(topics::CONTROLLER_PLANNING, now, json!({ "taken": taken }));
        }
        w.controller(now, &self.ctl);
    }

    fn send(&mut self, m: &GolfCarMessage) -> Result<(), BridgeError> {
        self.can.send_message(m)?;
        if matches!(m, GolfCarMessage::SteeringCmd(_))
            && let Some(timing) = &mut self.fix_timing
        {
            let sent = monotonic_ns();
            timing.extend(self.unanswered.drain(..).map(|(utc_s, read_ns)| FixTiming {
                utc_s,
                read_ns,
                command_ns: sent,
            }));
        }
        Ok(())
    }

    fn write_trace(&mut self, now: f64, last: bool) {
        let fixes = self.fix_timing.as_deref().unwrap_or(&[]);
        if let Some(w) = &mut self.trace {
            let r = if last {
                w.finish(now, &self.ctl, fixes)
            } else {
                w.update(now, &self.ctl, fixes)
            };
            if let Err(e) = r {
                // A full disk must not stop the car's control: log once, go on.
                if self.trace_error.is_none() {
                    self.trace_error = Some(e.to_string());
                }
                self.trace = None;
            }
        }
    }

    /// The trace's last records (the state at `now`), flushed: for a loop stopped from
    /// outside (a replay at the recording's end) rather than by [`Runtime::step`].
    pub fn finish_trace(&mut self, now: f64) {
        self.write_trace(now, true);
    }

    /// One tick at controller time `now`: inputs, the controller, outputs, the trace.
    /// `Some` when the loop has ended (the trace is then complete).
    pub fn step(&mut self, now: f64) -> Option<Exit> {
        if let Some(c) = &self.closing
            && now + 1e-9 >= c.until
        {
            let exit = c.exit.clone();
            self.write_trace(now, true);
            return Some(exit);
        }
        let accepted_before = self.ctl.nav.accepted();
        self.read_inputs(now);
        let messages = self.ctl.tick(now);
        let heartbeats_only = self.closing.as_ref().is_some_and(|c| c.heartbeats_only);
        let out: Vec<GolfCarMessage> = if heartbeats_only {
            let mut v = Vec::new();
            if now + 1e-9 >= self.next_heartbeat {
                v.push(GolfCarMessage::ControllerHeartbeat(ControllerHeartbeat {
                    state: ControllerHeartbeatState::Estop,
                }));
                self.next_heartbeat =
                    firmware_bridge::clock::next_slot(self.next_heartbeat, now, HEARTBEAT_PERIOD);
            }
            v
        } else {
            messages
        };
        let sent = out.iter().try_for_each(|m| self.send(m));
        self.record_tick(now, accepted_before);
        if let Err(e) = sent {
            self.write_trace(now, true);
            return Some(Exit::CanLost {
                reason: e.to_string(),
            });
        }
        if self.ctl.finished() && self.closing.is_none() {
            self.write_trace(now, true);
            return Some(Exit::Finished);
        }
        self.write_trace(now, false);
        None
    }

    /// Run on `clock` (ticks of [`COMMAND_PERIOD`]) until the loop ends; `stop` asks it
    /// to end (a signal); `status` is called after every tick with the tick's index.
    pub fn run<C: Clock>(
        &mut self,
        clock: &mut C,
        stop: &AtomicBool,
        mut status: impl FnMut(u64, f64, &Runtime<G, L, B>),
    ) -> Exit {
        let mut k: u64 = 0;
        loop {
            let late = clock.wait_tick(k);
            if clock.ended() {
                self.write_trace(clock.now(), true);
                return Exit::RunOver;
            }
            // A tick more than a period late (the machine stalled): the ticks missed
            // are skipped, not run back to back, so the loop's time stays the wall
            // clock's and what arrived during the stall is taken as arriving now. Run
            // in a burst, those ticks would see no input while their time ran on, and
            // the laser and report watchdogs would trip on sensors that never stopped.
            // The lockstep clock is never late.
            let missed = (late / COMMAND_PERIOD).floor();
            if missed >= 1.0 && missed.is_finite() {
                let missed = missed as u64;
                if let Some(w) = &mut self.recorder {
                    let from = k as f64 * COMMAND_PERIOD;
                    w.log_other(topics::CONTROLLER_SKIPPED, from, json!({ "ticks": missed }));
                }
                self.skipped_ticks += missed;
                k += missed;
            }
            let now = k as f64 * COMMAND_PERIOD;
            k += 1;
            if stop.load(Ordering::Relaxed) {
                self.request_stop(now);
            }
            if let Some(exit) = self.step(now) {
                return exit;
            }
            status(k, now, self);
        }
    }

    /// The run's trace (in memory), with the fix timings kept, over `duration`.
    pub fn trace(&self, duration: f64) -> Trace {
        let mut t = Trace::of(&self.ctl, duration);
        t.fix_timing = self.fix_timing.clone().unwrap_or_default();
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ControllerConfig;
    use firmware_bridge::can::membus::MemBus;

    /// A clock that is late once: tick `at` comes `late` seconds after its deadline.
    struct StallingClock {
        at: u64,
        late: f64,
        asked: Vec<u64>,
    }

    impl Clock for StallingClock {
        fn now(&self) -> f64 {
            0.0
        }

        fn wait_tick(&mut self, k: u64) -> f64 {
            self.asked.push(k);
            if k == self.at { self.late } else { 0.0 }
        }
    }

    #[test]
    fn a_tick_that_comes_late_skips_the_ticks_it_missed() {
        let bus = MemBus::new();
        let dir = tempfile::tempdir().expect("tempdir");
        let cfg = ControllerConfig::default();
        let info = crate::record::RunInfo::field(
            "stalling clock".to_owned(),
            1_000_000_000,
            "mem".to_owned(),
            ReaderConfig::default().complete_when,
            115_200,
            &cfg,
        )
        .expect("run info");
        let writer =
            Writer::create(Some(dir.path()), foxglove::Context::new(), info).expect("recorder");
        let mut rt = Runtime::new(
            Controller::new(&cfg).expect("controller"),
            MemGps::new(ReaderConfig::default()),
            MemLaser::default(),
            CanPort::new(bus.endpoint(), "mem"),
        )
        .with_recorder(writer)
        .expect("the recorder's thread");
        let mut clock = StallingClock {
            at: 5,
            late: 0.105,
            asked: Vec::new(),
        };
        let stop = AtomicBool::new(false);
        let mut times = Vec::new();
        rt.run(&mut clock, &stop, |k, now, _| {
            times.push((now / COMMAND_PERIOD).round() as u64);
            if k >= 30 {
                stop.store(true, Ordering::Relaxed);
            }
        });
        // Tick 5 came 105 ms late: ticks 5 to 14 are skipped, tick 15 runs at once.
        assert_eq!(rt.skipped_ticks, 10);
        assert_eq!(&times[..7], &[0, 1, 2, 3, 4, 15, 16]);
        assert_eq!(&clock.asked[..7], &[0, 1, 2, 3, 4, 5, 16]);
        // Never late again: nothing more skipped.
        assert!(
            times.windows(2).skip(5).all(|w| w[1] == w[0] + 1),
            "{times:?}"
        );
        // The controller's own recording says which: ten ticks from tick 5 (50 ms),
        // and every heartbeat it sent (one every 20 ms while waiting for its sensors).
        let summary = rt.finish_recording().expect("a recording");
        assert_eq!(summary.error, None);
        let bytes = std::fs::read(dir.path().join(crate::record::MCAP_FILE)).expect("run.mcap");
        let mut skipped = Vec::new();
        let mut stops = Vec::new();
        let mut frames = 0;
        for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
            let m = m.expect("a message");
            match m.channel.topic.as_str() {
                topics::CONTROLLER_SKIPPED => skipped.push((
                    m.log_time - 1_000_000_000,
                    String::from_utf8_lossy(&m.data).into_owned(),
                )),
                topics::CONTROLLER_STOP => stops.push(m.log_time - 1_000_000_000),
                topics::CAN_RAW => frames += 1,
                _ => {}
            }
        }
        assert_eq!(skipped, [(50_000_000, r#"{"ticks":10}"#.to_owned())]);
        // And when it was asked to stop: once, at the tick after the 30th.
        assert_eq!(stops, [300_000_000]);
        assert_eq!(frames, summary.can_frames);
        assert!(frames >= 8, "{summary:?}");
    }
}
