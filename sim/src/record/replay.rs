//! Replay: a recording's GPS bytes, laser frames and ECU reports fed into the
//! controller library (its loop on memory ports) in lockstep, and the commands it
//! sends compared with the recorded ones.
//!
//! Inputs go in at the controller tick at or after their log time, as SIL's loop
//! delivers them; the controller ticks on SIL's grid (every `COMMAND_PERIOD` on the
//! physics steps). A SIL recording therefore replays byte for byte
//! ([`Tolerance::EXACT`]). A HIL recording was made with the controller in a process of
//! its own, on its own clock and behind a paced serial line, so its commands come at
//! other instants than the replay's: it is compared with [`Tolerance::HIL`], which
//! pairs each replayed command with the recorded one of the same message nearest in
//! time and compares signal values within bounds (README, "Replay"). The controller's
//! own recording (`ugv-controller run --record`: on the car, on the bench, beside a HIL
//! run) holds every input at the tick that took it, the ticks its loop skipped and
//! the ticks it took each replanning at and the one it was asked to stop at: it
//! replays byte for byte too.

//!
//! A recording is read and checked whole before anything is replayed ([`read`]: the
//! records' CRCs and lengths, the message times, the channels and metadata a replay
//! needs): a damaged one is refused ([`ReplayError::is_damaged`], `ugv-sim replay`'s
//! exit code [`DAMAGED_EXIT`]) with the byte offset of the damage. A recording cut by
//! a kill is replayed and compared up to the last instant whose inputs and commands
//! the file holds whole ([`Recorded::whole_until_ns`]).

mod compare;
#[cfg(test)]
mod damage_tests;
mod read;
mod scan;

use std::collections::BTreeMap;

use embedded_can::Frame;
use firmware_bridge::CanPort;
use firmware_bridge::can::membus::{MemBus, MemEndpoint, MemFrame};
use firmware_bridge::nmea::ReaderConfig;
use golf_car_can::spec::NetworkSpec;
use serde::Serialize;
use ugv_controller::control::{COMMAND_PERIOD, Controller};
use ugv_controller::runtime::{MemGps, MemLaser, Runtime};
use ugv_controller::trace::TraceWriter;

use super::RecordMode;
use super::tap::{BusTap, TapFrame};
use compare::Comparer;
pub use compare::{Divergence, MessageStats, Tolerance};
use read::Input;
pub use read::{MAX_GAP_NS, REQUIRED_TOPICS, Recorded, ReplayError};

/// `ugv-sim replay`'s exit code for a damaged or invalid recording (0: the replay
/// agrees, 1: it diverges, 4: any other error).
pub const DAMAGED_EXIT: u8 = 3;

/// What a replay found.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    pub scenario: String,
    pub mode: RecordMode,
    pub tolerance: Tolerance,
    /// When the replayed controller started, simulated seconds: 0 for SIL, the
    /// recorded controller's first frame for HIL.
    pub controller_start_s: f64,
    /// Simulated seconds replayed, from the controller's start.
    pub replayed_s: f64,
    /// A recording cut by a kill or whose recorder lost entries: its commands were
    /// compared before this instant, simulated seconds (the last one its inputs and
    /// commands are whole before, less the tolerance's window); none when it is whole.
    pub compared_until_s: Option<f64>,
    pub inputs: u64,
    pub divergence: Option<Divergence>,
    pub messages: BTreeMap<String, MessageStats>,
    /// Why the recording ended before its file did, if it did.
    pub truncated: Option<String>,
    pub skipped_frames: u64,
    /// How the controller's loop ended during the replay, if it did.
    pub controller_exit: Option<String>,
    /// Why writing the replayed controller's trace stopped, if it did.
    pub trace_error: Option<String>,
}

impl ReplayReport {
    /// Whether the replay produced the recorded commands.
    pub fn identical(&self) -> bool {
        self.divergence.is_none()
    }
}

/// The recorded inputs in the order they reached the controller, each with that time
/// (ns on the log time). SIL: at their log time (memory ports). HIL: a GPS sentence
/// once its last byte crossed the line at the baud rate (ten bits a byte), the line
/// carrying the sentences one after the other from when the simulator queued them;
/// laser frames and CAN frames at their log time (the publish time, the kernel's
/// receive time).
fn arrivals(rec: &Recorded) -> Vec<(u64, &Input)> {
    let ns_per_byte = 10.0 * 1e9 / f64::from(rec.info.gps_baud.max(1));
    let mut line_free = 0u64;
    let mut out: Vec<(u64, &Input)> = rec
        .inputs
        .iter()
        .map(|(ns, input)| match (rec.info.mode, input) {
            (RecordMode::Hil, Input::Gps(bytes)) => {
                let end = (*ns).max(line_free) + (bytes.len() as f64 * ns_per_byte) as u64;
                line_free = end;
                (end, input)
            }
            _ => (*ns, input),
        })
        .collect();
    out.sort_by_key(|(ns, _)| *ns);
    out
}

/// The controller's ticks to replay: (its clock, ns on the log time by which the
/// tick's inputs had arrived): every `COMMAND_PERIOD` on the physics steps from
/// `start_ns` to `last_ns`, as the SIL loop ran it. A HIL recording is replayed on the
/// same grid from the recorded controller's start (its own ticks, read off the bursts
/// of frames it sent, replayed worse in the recordings measured: README, "Replay").
/// The controller's own recording: its loop's ticks, less those it skipped.
fn ticks(rec: &Recorded, start_ns: u64, last_ns: u64) -> impl Iterator<Item = (f64, u64)> {
    let ns_of = move |t: f64| start_ns + (t.max(0.0) * 1e9).round() as u64;
    let dt = 1.0 / rec.info.physics_hz;
    let control_every = ((COMMAND_PERIOD / dt).round() as u64).max(1);
    let skipped = rec.ticks_skipped.clone();
    (0..)
        .map(move |k: u64| (k * control_every) as f64 * dt)
        .map(move |now| (now, ns_of(now)))
        .take_while(move |(_, ns)| *ns <= last_ns)
        .filter(move |(now, _)| {
            let k = (now / COMMAND_PERIOD).round() as u64;
            !skipped
                .iter()
                .any(|&(first, n)| (first..first + n).contains(&k))
        })
}

/// How many bytes of NMEA a serial line (a pty's or a tty's receive buffer) keeps for
/// a reader that has not opened it yet: Linux's N_TTY buffer.
const LINE_BUFFER: usize = 4096;

/// Where the replayed controller's clock starts, nanoseconds on the recording's log
/// time. SIL and the controller's own recording: at the recording's epoch, as the
/// controller's loop did. HIL: at the
/// recorded controller's first frame, since its process started on its own clock some
/// time after the simulator began recording (a controller that starts at the epoch
/// would wait for ECUs that the recording shows enabling only later, and estop).
fn controller_start(rec: &Recorded) -> u64 {
    match rec.info.mode {
        RecordMode::Sil | RecordMode::Lockstep | RecordMode::Field => rec.info.epoch_unix_ns,
        RecordMode::Hil => rec
            .commands
            .first()
            .map_or(rec.info.epoch_unix_ns, |c| c.ns),
    }
}

/// How long before its first frame the recorded controller's CAN socket is taken to
/// have been open: its start-up (socket opened, first inputs read, first tick) within
/// one command period of sending.
const SOCKET_OPEN_BEFORE_NS: u64 = 10_000_000;

/// What a controller starting at `start_ns` finds waiting on its ports, and the index
/// of the first input after that. The GPS line keeps the newest whole sentences that
/// fit its buffer, the laser service keeps its newest frame (the subscriber's
/// history), and a CAN socket holds the frames sent since it was opened
/// ([`SOCKET_OPEN_BEFORE_NS`] before the first frame the controller sent: the
/// reports its first tick read, and why that tick already enabled the ECUs).
fn waiting_at_start<'a>(arrived: &[(u64, &'a Input)], start_ns: u64) -> (Vec<&'a Input>, usize) {
    let first_after = arrived.partition_point(|(ns, _)| *ns < start_ns);
    let before = &arrived[..first_after];
    let mut waiting = Vec::new();
    let mut line_bytes = 0;
    let opened = start_ns.saturating_sub(SOCKET_OPEN_BEFORE_NS);
    for &(ns, input) in before.iter().rev() {
        match input {
            Input::Can { .. } if ns >= opened => waiting.push(input),
            Input::Gps(bytes) if line_bytes + bytes.len() <= LINE_BUFFER => {
                line_bytes += bytes.len();
                waiting.push(input);
            }
            // The line is full: older sentences were lost.
            Input::Gps(_) => line_bytes = LINE_BUFFER + 1,
            Input::Laser(_) if !waiting.iter().any(|i| matches!(i, Input::Laser(_))) => {
                waiting.push(input);
            }
            Input::Laser(_) | Input::Can { .. } => {}
        }
    }
    waiting.reverse();
    (waiting, first_after)
}

/// An input onto the replayed controller's ports; a CAN frame from the ECUs' side of
/// the bus (a standard ID, checked when read, and at most 8 bytes; the memory bus never
/// fails).
fn feed(rt: &mut Runtime<MemGps, MemLaser, MemEndpoint>, ecus: &mut MemEndpoint, input: &Input) {
    match input {
        Input::Gps(bytes) => rt.gps_mut().push(bytes),
        Input::Laser(frame) => rt.laser_mut().push(frame.clone()),
        Input::Can { id, data } => {
            if let Some(f) =
                embedded_can::StandardId::new(*id).and_then(|sid| MemFrame::new(sid, data))
            {
                let _ = embedded_can::nb::Can::transmit(ecus, &f);
            }
        }
    }
}

/// The controller a replay of `rec` runs: the library's loop on memory ports, on one
/// endpoint of `bus`, its plans taken as the recorded controller took them (the
/// binary replans on a thread: in HIL its plan is taken at the next tick; its own
/// recording says at which).
fn replayed_controller(
    rec: &Recorded,
    bus: &MemBus,
    trace: Option<TraceWriter>,
) -> Result<Runtime<MemGps, MemLaser, MemEndpoint>, ReplayError> {
    let controller = match rec.info.mode {
        RecordMode::Sil | RecordMode::Lockstep => Controller::new(&rec.config)?,
        RecordMode::Hil => Controller::new(&rec.config)?.with_plans_taken_next_tick(),
        RecordMode::Field => {
            Controller::new(&rec.config)?.with_plans_taken_at(rec.plans_taken_at.clone())
        }
    };
    let can = CanPort::new(bus.endpoint(), "replay");
    ugv_controller::runtime::accept_controller_ids(&can)?;
    let rt = Runtime::new(
        controller,
        MemGps::new(ReaderConfig {
            complete_when: rec.info.gps_sentences,
            ..ReaderConfig::default()
        }),
        MemLaser::default(),
        can,
    );
    Ok(match trace {
        Some(w) => rt.with_trace(w),
        None => rt,
    })
}

/// The last instant to replay, ns on the log time: the last input's or command's, and
/// in a recording cut by a kill, before the first instant it may hold only partly.
fn last_tick_ns(rec: &Recorded) -> u64 {
    let last = rec
        .inputs
        .last()
        .map(|(ns, _)| *ns)
        .max(rec.commands.last().map(|c| c.ns))
        .unwrap_or(rec.info.epoch_unix_ns);
    match rec.whole_until_ns {
        Some(whole) => last.min(whole.saturating_sub(1)),
        None => last,
    }
}

/// Replay `rec` into the controller library and compare its commands with the
/// recorded ones within `tol`; `trace`, when given, gets the replayed controller's
/// trace (the format of the binary's `--trace`, to set beside the recorded
/// `controller-trace.jsonl`). A recording cut by a kill is replayed up to its
/// [`Recorded::whole_until_ns`], and compared where the comparison can be whole
/// ([`ReplayReport::compared_until_s`]).
pub fn replay(
    rec: &Recorded,
    tol: Tolerance,
    trace: Option<TraceWriter>,
) -> Result<ReplayReport, ReplayError> {
    let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC)?;
    let bus = MemBus::new();
    let mut rt = replayed_controller(rec, &bus, trace)?;
    // The ECUs' side of the bus: recorded reports go out, the controller's come in.
    let mut ecus: MemEndpoint = bus.endpoint();
    let mut heard: Vec<TapFrame> = Vec::new();
    let start_ns = controller_start(rec);
    let mut cmp = Comparer::new(
        &spec,
        tol,
        &rec.commands,
        rec.info.epoch_unix_ns,
        start_ns + (tol.settle_s * 1e9).round() as u64,
        rec.whole_until_ns.unwrap_or(u64::MAX),
    );
    let arrived = arrivals(rec);
    let (backlog, mut next_input) = waiting_at_start(&arrived, start_ns);
    for input in backlog {
        feed(&mut rt, &mut ecus, input);
    }
    let mut exit = None;
    let mut replayed_s = 0.0;
    for (now, tick_ns) in ticks(rec, start_ns, last_tick_ns(rec)) {
        while let Some((ns, input)) = arrived.get(next_input) {
            if *ns > tick_ns {
                break;
            }
            feed(&mut rt, &mut ecus, input);
            next_input += 1;
        }
        if rec.stop_requested.is_some_and(|t| t <= now + 1e-6) {
            rt.request_stop(now);
        }
        if let Some(e) = rt.step(now) {
            exit = Some(e.describe());
        }
        replayed_s = now;
        // Only the controller talks to this endpoint (a node never hears itself).
        let _ = ecus.drain(&mut heard);
        cmp.close_before(tick_ns);
        for f in heard.drain(..) {
            cmp.replayed(tick_ns, f.id, &f.data);
        }
        if exit.is_some() {
            break;
        }
    }
    cmp.close_before(u64::MAX);
    if exit.is_none() {
        rt.finish_trace(replayed_s);
    }
    Ok(ReplayReport {
        scenario: rec.info.scenario.clone(),
        mode: rec.info.mode,
        tolerance: tol,
        controller_start_s: cmp.time(start_ns),
        replayed_s,
        compared_until_s: rec
            .whole_until_ns
            .map(|w| cmp.time(w.saturating_sub((tol.window_s * 1e9).round() as u64))),
        inputs: next_input as u64,
        divergence: cmp.divergence,
        messages: cmp.messages,
        truncated: rec.truncated.clone(),
        skipped_frames: rec.skipped,
        controller_exit: exit,
        trace_error: rt.trace_error().map(str::to_owned),
    })
}

#[cfg(test)]
mod tests {
    use super::read::{Command, DEFAULT_GPS_BAUD};
    use super::*;
    use crate::record::RunInfo;
    use ugv_controller::config::ControllerConfig;

    fn recording(mode: RecordMode, inputs: Vec<(u64, Input)>, commands: Vec<Command>) -> Recorded {
        Recorded {
            info: RunInfo {
                mode,
                scenario: "test".to_owned(),
                physics_hz: 200.0,
                epoch_unix_ns: 1_000,
                can_interface: "vcan0".to_owned(),
                gps_sentences: ReaderConfig::default().complete_when,
                gps_baud: DEFAULT_GPS_BAUD,
                controller_toml: String::new(),
            },
            config: ControllerConfig::default(),
            inputs,
            commands,
            truncated: None,
            whole_until_ns: None,
            skipped: 0,
            plans_taken_at: Vec::new(),
            ticks_skipped: Vec::new(),
            stop_requested: None,
        }
    }

    fn heartbeat(ns: u64) -> Command {
        Command {
            ns,
            id: 0x100,
            data: vec![0; 8],
        }
    }

    #[test]
    fn a_hil_controller_starts_at_its_first_frame_and_a_sil_one_at_the_epoch() {
        let commands = vec![heartbeat(5_000), heartbeat(6_000)];
        let hil = recording(RecordMode::Hil, Vec::new(), commands.clone());
        assert_eq!(controller_start(&hil), 5_000);
        let sil = recording(RecordMode::Sil, Vec::new(), commands);
        assert_eq!(controller_start(&sil), 1_000);
        // No command at all: the epoch.
        assert_eq!(
            controller_start(&recording(RecordMode::Hil, Vec::new(), Vec::new())),
            1_000
        );
    }

    #[test]
    fn a_late_controller_finds_the_newest_sentences_that_fit_the_line_the_newest_scan_and_the_last_frames()
     {
        let ms = 1_000_000;
        let sentence = |n: u8| Input::Gps(vec![n; 1500]);
        let frame = |n: u8| Input::Can {
            id: 0x200,
            data: vec![n],
        };
        let inputs = vec![
            (110 * ms, sentence(1)),
            (120 * ms, Input::Laser(Box::default())),
            (130 * ms, sentence(2)),
            (140 * ms, frame(1)),
            (150 * ms, sentence(3)),
            (160 * ms, Input::Laser(Box::default())),
            (170 * ms, sentence(4)),
            (195 * ms, frame(2)),
            (200 * ms, sentence(5)),
        ];
        let rec = recording(RecordMode::Hil, inputs, Vec::new());
        // As they arrived (here: at their log times).
        let arrived: Vec<(u64, &Input)> = rec.inputs.iter().map(|(ns, i)| (*ns, i)).collect();
        let (waiting, next) = waiting_at_start(&arrived, 200 * ms);
        // Sentence 5 is at the start itself: delivered at the first tick, not waiting.
        assert_eq!(next, 8);
        let kinds: Vec<String> = waiting
            .iter()
            .map(|i| match i {
                Input::Gps(b) => format!("gps{}", b[0]),
                Input::Laser(_) => "laser".to_owned(),
                Input::Can { data, .. } => format!("can{}", data[0]),
            })
            .collect();
        // 4096 bytes hold two 1500-byte sentences (the third would overflow): 3 and 4,
        // oldest first, with the newest scan between them; the frame sent within the
        // socket's 10 ms before the start, not the one before it was opened.
        assert_eq!(kinds, ["gps3", "laser", "gps4", "can2"]);
    }

    #[test]
    fn the_controllers_own_recording_replays_on_its_ticks_less_those_it_skipped() {
        let ms = 1_000_000;
        let inputs = vec![(1_000 + 30 * ms, Input::Gps(vec![b'$'; 1152]))];
        let mut rec = recording(RecordMode::Field, inputs, vec![heartbeat(1_000 + 200 * ms)]);
        rec.info.physics_hz = 100.0;
        rec.ticks_skipped = vec![(5, 10), (18, 1)];
        let at: Vec<u64> = ticks(&rec, controller_start(&rec), 1_000 + 200 * ms)
            .map(|(now, ns)| {
                assert_eq!(ns, 1_000 + (now * 1e9).round() as u64);
                (now * 100.0).round() as u64
            })
            .collect();
        let expected: Vec<u64> = (0..=20)
            .filter(|k| !(5..15).contains(k) && *k != 18)
            .collect();
        assert_eq!(at, expected);
        // Its inputs are fed at the tick that took them (the line's time is behind
        // them), and compared exactly.
        assert_eq!(arrivals(&rec)[0].0, 1_000 + 30 * ms);
        assert_eq!(Tolerance::for_mode(RecordMode::Field), Tolerance::EXACT);
    }

    #[test]
    fn in_hil_a_sentence_arrives_once_its_bytes_crossed_the_line() {
        let ms = 1_000_000;
        let inputs = vec![
            // 11.52 bytes a millisecond at 115200 baud: 1152 bytes take 100 ms.
            (0, Input::Gps(vec![b'$'; 1152])),
            // Queued while the first is on the line: it follows it.
            (5 * ms, Input::Gps(vec![b'$'; 576])),
            (
                6 * ms,
                Input::Can {
                    id: 1,
                    data: vec![],
                },
            ),
            (130 * ms, Input::Gps(vec![b'$'; 576])),
            // The line idle again: 50 ms after it was queued.
            (300 * ms, Input::Gps(vec![b'$'; 576])),
        ];
        let mut rec = recording(RecordMode::Hil, inputs, Vec::new());
        rec.info.gps_baud = 115_200;
        let at: Vec<u64> = arrivals(&rec).iter().map(|(ns, _)| *ns / ms).collect();
        assert_eq!(at, [6, 100, 150, 200, 350]);
        // SIL's memory ports deliver at once.
        rec.info.mode = RecordMode::Sil;
        let at: Vec<u64> = arrivals(&rec).iter().map(|(ns, _)| *ns / ms).collect();
        assert_eq!(at, [0, 5, 6, 130, 300]);
    }
}
