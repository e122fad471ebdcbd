//! The CAN gateway between the simulator's bus and a physical one: the HIL promise
//! that any ECU, or the controller itself, can be a physical device on a physical
//! SocketCAN interface (can0, a USB adapter) while the rest stays simulated on vcan0.
//!
//! - [`routing`]: which frames cross, from the DBC's senders and receivers and the
//!   nodes the user declares physical. A frame read on one side crosses iff its sender
//!   lives on that side and one of its receivers lives on the other; FAULT_REPORT's
//!   sender is its `Source` signal. Everything else stays local, counted by reason.
//! - the forwarding engine ([`Gateway::spawn`]): one socket per interface, one thread
//!   per direction (order kept per direction), frames forwarded byte for byte (E2E is
//!   the endpoints' business), a full transmit queue waited out and retried (counted),
//!   never a silent drop, per-message counts, per-frame latency from the kernel's
//!   receive timestamp, an optional candump log ([`log`]), and a serialisable
//!   [`GatewayStats`] snapshot at any time.
//!
//! Why the gateway never loops or echoes: it reads each interface on the same socket
//! it writes it with, and that socket has `CAN_RAW_RECV_OWN_MSGS` off, so the gateway
//! never reads a frame it sent (see [`socket`]); and the routing rule forwards a frame
//! only from the side its sender lives on, so even a frame that came back (through a
//! second gateway, say) would stay local as `sender_on_other_side`.
//!
//! ```no_run
//! use firmware_bridge::gateway::{Gateway, GatewayConfig};
//! # fn main() -> Result<(), firmware_bridge::gateway::GatewayError> {
//! let gateway = Gateway::spawn(GatewayConfig {
//!     sim_iface: "vcan0".into(),
//!     physical_iface: "can0".into(),
//!     physical_nodes: vec!["STEERING_ECU".into()],
//!     ..GatewayConfig::default()
//! })?;
//! // ... run ...
//! let stats = gateway.stop();
//! println!("{}", stats.to_physical.forwarded);
//! # Ok(()) }
//! ```

pub mod log;
pub mod routing;
pub mod socket;
pub mod stats;

use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use golf_car_can::NETWORK;
use nix::errno::Errno;

pub use routing::{LocalReason, RoutingTable, Side, Verdict};
pub use stats::{DirectionStats, GatewayStats, LatencySummary, LocalCounts, MessageCounts};

use log::ForwardLog;
use socket::{GatewaySocket, RawFrame, ReadOutcome};

use crate::can::QueueDrops;
use stats::DirectionCounters;

use crate::sync::lock;

/// How long a read waits before looking at the stop flag again.
const READ_TIMEOUT: Duration = Duration::from_millis(100);
/// Pause after a receive error that may clear (an interface going down and up).
const ERROR_PAUSE: Duration = Duration::from_millis(100);

/// Errors of the gateway.
#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    /// A physical node that the DBC does not define.
    #[error("{node:?} is not a node of golf_car.dbc; the nodes are: {valid}")]
    UnknownNode { node: String, valid: String },
    /// No node declared physical.
    #[error(
        "no physical node given, so nothing would cross the gateway; name one or more of: {valid}"
    )]
    NoPhysicalNode { valid: String },
    /// Both sides on one interface.
    #[error(
        "the simulated and the physical side are both {iface}; the gateway joins two different interfaces"
    )]
    SameInterface { iface: String },
    /// Not a possible interface name.
    #[error("{iface:?} is not an interface name (1-15 characters, no '/' or spaces)")]
    BadInterfaceName { iface: String },
    /// The interface does not exist.
    #[error(
        "CAN interface {iface} does not exist: for a simulated bus create it with `vcan-setup up {iface}`; for a USB adapter plug it in and look for its name with `ip -details link show type can`"
    )]
    NoInterface { iface: String },
    /// The interface exists but is down.
    #[error(
        "CAN interface {iface} is down: bring it up with `ip link set {iface} up` (a physical adapter needs its bitrate too: `ip link set {iface} up type can bitrate 500000`)"
    )]
    InterfaceDown { iface: String },
    /// The interface is not a CAN interface.
    #[error("interface {iface} is not a CAN interface (link type {link_type}; CAN is 280)")]
    NotCan { iface: String, link_type: u32 },
    /// A socket call failed.
    #[error("CAN interface {iface}: {what}: {source}")]
    Socket {
        iface: String,
        what: &'static str,
        #[source]
        source: io::Error,
    },
    /// The interface went away while forwarding (an adapter unplugged).
    #[error("CAN interface {iface} went away while forwarding: {source}")]
    InterfaceGone {
        iface: String,
        #[source]
        source: io::Error,
    },
    /// The log file could not be created.
    #[error("creating the forwarded-frame log {path}: {source}")]
    Log {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// A forwarding thread could not be started.
    #[error("starting a forwarding thread: {0}")]
    Thread(#[source] io::Error),
}

/// What the gateway joins and how (serde: a `[gateway]` table of a run configuration;
/// missing fields take the defaults).
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct GatewayConfig {
    /// The simulator's interface.
    pub sim_iface: String,
    /// The physical interface.
    pub physical_iface: String,
    /// DBC nodes that are physical (case-insensitive): their frames come from, and
    /// frames for them go to, `physical_iface`.
    pub physical_nodes: Vec<String>,
    /// Log of the forwarded frames in `candump -l -x` format (see [`log`]).
    pub log: Option<PathBuf>,
    /// How long a frame waits for a full transmit queue (or a down interface) before it
    /// is given up and counted in `tx_dropped`, milliseconds.
    pub tx_give_up_ms: u64,
    /// Receive buffer asked for on each socket, bytes (the kernel doubles it; without
    /// CAP_NET_ADMIN it is capped at net.core.rmem_max).
    pub rcvbuf_bytes: usize,
    /// SCHED_FIFO priority of the two forwarding threads (0: ordinary scheduling).
    /// The gateway stands for a wire: a frame it holds up is late at the ECU behind
    /// it, whose 100 ms heartbeat watchdog a busy machine must not trip (an ordinary
    /// thread in a loaded VM held a heartbeat 124 ms). Refused without root or
    /// CAP_SYS_NICE, which [`GatewayStats::scheduling`] says.
    pub rt_priority: u8,
}

impl Default for GatewayConfig {
    fn default() -> Self {
        GatewayConfig {
            sim_iface: "vcan0".to_owned(),
            physical_iface: "can0".to_owned(),
            physical_nodes: Vec::new(),
            log: None,
            tx_give_up_ms: 1000,
            rcvbuf_bytes: crate::can::DEEP_QUEUE_BYTES,
            rt_priority: crate::realtime::DEFAULT_PRIORITY,
        }
    }
}

/// Whether the gateway runs. Everything that changes it (a thread starting or ending,
/// a failure, a stop) takes the one lock, and a snapshot reads it under the same lock:
/// a failure stores its error and `stopped` in one critical section, so no reader can
/// see the gateway stopped by a failure without the failure's error (the two used to be
/// separate, error first and flag second, and a snapshot between them said "stopped,
/// no error").
#[derive(Debug, Default)]
struct RunState {
    /// Forwarding threads started and not yet ended.
    threads: usize,
    /// Stop asked, by the handle or by a failure.
    stopped: bool,
    /// The first error that stopped the gateway.
    error: Option<String>,
}

impl RunState {
    /// Both directions forwarding.
    fn running(&self) -> bool {
        self.threads == 2 && !self.stopped
    }
}

/// State shared by the handle and the forwarding threads.
#[derive(Debug)]
struct Shared {
    table: RoutingTable,
    sim_iface: String,
    physical_iface: String,
    to_physical: Mutex<DirectionCounters>,
    to_sim: Mutex<DirectionCounters>,
    log: Option<Mutex<ForwardLog>>,
    log_error: Mutex<Option<String>>,
    /// Whether the gateway runs, and why it stopped: one lock, so a snapshot sees
    /// either "running" or "stopped" with the error that stopped it, never a mix.
    state: Mutex<RunState>,
    /// Each forwarding thread's scheduling, as it started.
    scheduling: Mutex<Vec<String>>,
    /// The forwarding threads' cue to stop (read without a lock on every frame);
    /// [`RunState::stopped`] is set first, under the state's lock. Never read to tell
    /// whether the gateway runs: that is the state's.
    stop: AtomicBool,
    started: Instant,
    tx_give_up: Duration,
}

impl Shared {
    /// The state of a gateway about to start (no thread running yet).
    fn new(table: RoutingTable, config: &GatewayConfig, log: Option<Mutex<ForwardLog>>) -> Self {
        Shared {
            to_physical: Mutex::new(DirectionCounters::new(
                &config.sim_iface,
                &config.physical_iface,
                Side::Sim,
                &table,
            )),
            to_sim: Mutex::new(DirectionCounters::new(
                &config.physical_iface,
                &config.sim_iface,
                Side::Physical,
                &table,
            )),
            table,
            sim_iface: config.sim_iface.clone(),
            physical_iface: config.physical_iface.clone(),
            log,
            log_error: Mutex::new(None),
            state: Mutex::new(RunState::default()),
            scheduling: Mutex::new(Vec::with_capacity(2)),
            stop: AtomicBool::new(false),
            started: Instant::now(),
            tx_give_up: Duration::from_millis(config.tx_give_up_ms),
        }
    }

    /// Flush the forwarded-frame log, when there is one; the first error is kept.
    fn flush_log(&self) {
        if let Some(log) = &self.log
            && let Err(e) = lock(log).flush()
        {
            lock(&self.log_error).get_or_insert(e.to_string());
        }
    }

    fn counters(&self, from: Side) -> &Mutex<DirectionCounters> {
        match from {
            Side::Sim => &self.to_physical,
            Side::Physical => &self.to_sim,
        }
    }

    /// Stop the gateway for `error` (the first one is kept).
    fn fail(&self, error: String) {
        tracing::error!("gateway stopped: {error}");
        let mut state = lock(&self.state);
        state.error.get_or_insert(error);
        self.halt(&mut state);
    }

    /// Ask the forwarding threads to stop (the state's lock held).
    fn halt(&self, state: &mut RunState) {
        state.stopped = true;
        self.stop.store(true, Ordering::SeqCst);
    }

    /// A forwarding thread starting (`+1`) or ending (`-1`).
    fn thread_count(&self, delta: isize) {
        let mut state = lock(&self.state);
        state.threads = state.threads.saturating_add_signed(delta);
    }

    fn is_running(&self) -> bool {
        lock(&self.state).running()
    }

    fn snapshot(&self) -> GatewayStats {
        let (running, mut error) = {
            let state = lock(&self.state);
            (state.running(), state.error.clone())
        };
        if let Some(log_error) = lock(&self.log_error).as_ref() {
            let text = format!("log: {log_error}");
            error = Some(match error {
                Some(e) => format!("{e}; {text}"),
                None => text,
            });
        }
        GatewayStats {
            sim_iface: self.sim_iface.clone(),
            physical_iface: self.physical_iface.clone(),
            physical_nodes: self.table.physical_nodes().to_vec(),
            sim_nodes: self.table.sim_nodes().to_vec(),
            uptime_s: self.started.elapsed().as_secs_f64(),
            running,
            error,
            scheduling: lock(&self.scheduling).clone(),
            to_physical: lock(&self.to_physical).snapshot(&self.table),
            to_sim: lock(&self.to_sim).snapshot(&self.table),
        }
    }
}

/// The gateway (see the module documentation); [`Gateway::spawn`] starts it.
#[derive(Debug)]
pub struct Gateway;

/// A running gateway: its statistics at any time, and stop (also on drop, which joins
/// the threads).
#[derive(Debug)]
pub struct GatewayHandle {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Gateway {
    /// Check the configuration and both interfaces, open one socket on each, and start
    /// forwarding on two threads (one per direction). Errors name the interface or
    /// node and say what to do.
    pub fn spawn(config: GatewayConfig) -> Result<GatewayHandle, GatewayError> {
        let table = RoutingTable::new(&NETWORK, &config.physical_nodes)?;
        if config.sim_iface == config.physical_iface {
            return Err(GatewayError::SameInterface {
                iface: config.sim_iface,
            });
        }
        socket::check_interface(&config.sim_iface)?;
        socket::check_interface(&config.physical_iface)?;
        let sim = Arc::new(GatewaySocket::open(
            &config.sim_iface,
            config.rcvbuf_bytes,
            READ_TIMEOUT,
        )?);
        let physical = Arc::new(GatewaySocket::open(
            &config.physical_iface,
            config.rcvbuf_bytes,
            READ_TIMEOUT,
        )?);
        let log = match &config.log {
            Some(path) => Some(Mutex::new(ForwardLog::create(path).map_err(|source| {
                GatewayError::Log {
                    path: path.clone(),
                    source,
                }
            })?)),
            None => None,
        };
        tracing::info!(
            sim = %config.sim_iface,
            physical = %config.physical_iface,
            physical_nodes = ?table.physical_nodes(),
            rcvbuf = ?(sim.rcvbuf(), physical.rcvbuf()),
            "gateway starting"
        );
        let shared = Arc::new(Shared::new(table, &config, log));
        let mut handle = GatewayHandle {
            shared: Arc::clone(&shared),
            threads: Vec::with_capacity(2),
        };
        for (side, from, to) in [
            (Side::Sim, Arc::clone(&sim), Arc::clone(&physical)),
            (Side::Physical, physical, sim),
        ] {
            let shared = Arc::clone(&shared);
            shared.thread_count(1);
            let rt_priority = config.rt_priority;
            let spawned = std::thread::Builder::new()
                .name(format!("gateway {}->{}", from.iface(), to.iface()))
                .spawn(move || {
                    let rt = crate::realtime::promote(rt_priority);
                    lock(&shared.scheduling).push(rt.promotion.describe(&format!(
                        "{}->{}",
                        from.iface(),
                        to.iface()
                    )));
                    if let Err(e) = forward(&shared, side, &from, &to) {
                        shared.fail(e.to_string());
                    }
                    shared.thread_count(-1);
                });
            match spawned {
                Ok(t) => handle.threads.push(t),
                Err(e) => {
                    handle.shared.thread_count(-1);
                    // Dropping the handle stops and joins what started.
                    return Err(GatewayError::Thread(e));
                }
            }
        }
        Ok(handle)
    }
}

impl GatewayHandle {
    /// A snapshot of the counters (cheap; callable from any thread at any time).
    pub fn stats(&self) -> GatewayStats {
        self.shared.snapshot()
    }

    /// The routing table in use.
    pub fn routing(&self) -> &RoutingTable {
        &self.shared.table
    }

    /// Whether both directions are still forwarding (false after a fatal error, with
    /// the error in [`GatewayStats::error`]).
    pub fn is_running(&self) -> bool {
        self.shared.is_running()
    }

    /// Stop forwarding, join both threads, flush the log, and return the final counts.
    pub fn stop(mut self) -> GatewayStats {
        self.shutdown();
        self.shared.snapshot()
    }

    fn shutdown(&mut self) {
        self.shared.halt(&mut lock(&self.shared.state));
        for t in self.threads.drain(..) {
            if t.join().is_err() {
                self.shared.fail("a forwarding thread panicked".to_owned());
            }
        }
        self.shared.flush_log();
    }
}

impl Drop for GatewayHandle {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Why a frame could not be sent.
enum SendFailure {
    /// Given up after the queue stayed full (or on an error a later frame may not hit).
    GaveUp(Errno),
    /// The interface is gone.
    Gone(Errno),
}

/// Send one frame, waiting out a full transmit queue; returns the retries it took.
fn send_insist(
    to: &GatewaySocket,
    bytes: &[u8; socket::CAN_MTU],
    stop: &AtomicBool,
    give_up: Duration,
) -> (u64, Result<(), SendFailure>) {
    let mut retries = 0u64;
    let mut first_failure: Option<Instant> = None;
    let mut pause = Duration::from_micros(10);
    loop {
        match to.try_send(bytes) {
            Ok(()) => return (retries, Ok(())),
            Err(Errno::EINTR) => {}
            // ENOBUFS: the interface's queue is full; EAGAIN: the socket's send buffer
            // is; ENETDOWN: the interface is down for now.
            Err(e @ (Errno::ENOBUFS | Errno::EAGAIN | Errno::ENETDOWN)) => {
                retries += 1;
                let since = *first_failure.get_or_insert_with(Instant::now);
                if since.elapsed() >= give_up || stop.load(Ordering::Relaxed) {
                    return (retries, Err(SendFailure::GaveUp(e)));
                }
                if retries % 64 < 8 {
                    std::thread::yield_now();
                } else {
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(Duration::from_millis(1));
                }
            }
            Err(e @ (Errno::ENODEV | Errno::ENXIO)) => return (retries, Err(SendFailure::Gone(e))),
            Err(e) => return (retries, Err(SendFailure::GaveUp(e))),
        }
    }
}

/// A monotonic instant and the wall-clock time at that instant: the tightest of a few
/// tries (a thread preempted between the two clock reads, as a VM's vCPU can be for
/// milliseconds, would skew every time derived from the pair).
fn wall_clock_base() -> (Instant, SystemTime) {
    let mut best: Option<(Duration, Instant, SystemTime)> = None;
    for _ in 0..5 {
        let before = Instant::now();
        let wall = SystemTime::now();
        let after = Instant::now();
        let gap = after.duration_since(before);
        let mid = before + gap / 2;
        if best.is_none_or(|(g, _, _)| gap < g) {
            best = Some((gap, mid, wall));
        }
        if gap < Duration::from_micros(20) {
            break;
        }
    }
    best.map_or_else(|| (Instant::now(), SystemTime::now()), |(_, i, w)| (i, w))
}

/// One direction: read `from`, forward what the table says to `to`, count everything.
fn forward(
    shared: &Shared,
    side: Side,
    from: &GatewaySocket,
    to: &GatewaySocket,
) -> Result<(), GatewayError> {
    let counters = shared.counters(side);
    let mut cmsg = from.cmsg_buffer();
    let mut logged_errors = 0u32;
    // Wall-clock time of the end of a transmit, from the monotonic clock and a base
    // pair refreshed every second: one clock read per frame less (clock reads cost
    // microseconds in an emulated VM, whose clock source is the HPET).
    let mut wall_base = wall_clock_base();
    while !shared.stop.load(Ordering::Relaxed) {
        let (frame, drops) = match from.read(&mut cmsg) {
            Ok(ReadOutcome::Frame(frame, drops)) => (frame, drops),
            Ok(ReadOutcome::Timeout) => {
                // The bus is idle: the kernel's drop count, and the log on disk.
                count_queue_drops(from, counters);
                shared.flush_log();
                continue;
            }
            Err(e) => {
                receive_error(from, counters, e, &mut logged_errors)?;
                continue;
            }
        };
        let read_at = Instant::now();
        let verdict = shared.table.route(side, frame.can_id(), frame.data());
        let message = match verdict {
            Verdict::Local { reason, message } => {
                let mut c = lock(counters);
                c.received();
                if let Some(d) = drops {
                    c.overflow_total(d);
                }
                c.local(reason, message);
                continue;
            }
            Verdict::Forward { message } => message,
        };
        let (retries, sent) = send_insist(to, &frame.bytes, &shared.stop, shared.tx_give_up);
        let sent_at = Instant::now();
        if sent_at.saturating_duration_since(wall_base.0) > Duration::from_secs(1) {
            wall_base = wall_clock_base();
        }
        let passage = Passage {
            read_at,
            sent_at,
            sent_wall: wall_base.1 + sent_at.saturating_duration_since(wall_base.0),
            retries,
            sent,
        };
        count_passage(counters, to, &frame, drops, message, &passage);
        match passage.sent {
            Ok(()) => log_forwarded(shared, &frame, from, to, &passage),
            Err(SendFailure::Gone(e)) => {
                return Err(GatewayError::InterfaceGone {
                    iface: to.iface().to_owned(),
                    source: io::Error::from(e),
                });
            }
            Err(SendFailure::GaveUp(_)) => {}
        }
    }
    count_queue_drops(from, counters);
    Ok(())
}

/// The kernel's count of frames dropped from `from`'s receive queue, when it says.
fn count_queue_drops(from: &GatewaySocket, counters: &Mutex<DirectionCounters>) {
    if let Some(d) = from.queue_drops() {
        lock(counters).overflow_total(d);
    }
}

/// A receive error: the end of forwarding when the interface is gone; otherwise
/// counted (the first ten logged) and waited out for [`ERROR_PAUSE`].
fn receive_error(
    from: &GatewaySocket,
    counters: &Mutex<DirectionCounters>,
    e: io::Error,
    logged_errors: &mut u32,
) -> Result<(), GatewayError> {
    match e.raw_os_error() {
        Some(libc::ENODEV | libc::ENXIO) => Err(GatewayError::InterfaceGone {
            iface: from.iface().to_owned(),
            source: e,
        }),
        _ => {
            lock(counters).rx_errors += 1;
            if *logged_errors < 10 {
                *logged_errors += 1;
                tracing::warn!(iface = from.iface(), "receive error: {e}");
            }
            std::thread::sleep(ERROR_PAUSE);
            Ok(())
        }
    }
}

/// A frame's way through the gateway: when it was read, when its send ended
/// (monotonic and wall-clock), the retries the send took and how it ended.
struct Passage {
    read_at: Instant,
    sent_at: Instant,
    sent_wall: SystemTime,
    retries: u64,
    sent: Result<(), SendFailure>,
}

/// Count a frame routed to `to` (DBC message `message`): received, forwarded with
/// its latency (from the kernel's receive stamp when there is one, else from the
/// read), or given up (the first ten and every power of two logged).
fn count_passage(
    counters: &Mutex<DirectionCounters>,
    to: &GatewaySocket,
    frame: &RawFrame,
    drops: Option<u32>,
    message: usize,
    passage: &Passage,
) {
    let mut c = lock(counters);
    c.received();
    if let Some(d) = drops {
        c.overflow_total(d);
    }
    c.tx_retries += passage.retries;
    match &passage.sent {
        Ok(()) => {
            let handling = passage.sent_at.duration_since(passage.read_at);
            let latency = frame
                .stamp
                .map(|t| passage.sent_wall.duration_since(t).unwrap_or_default())
                .unwrap_or(handling);
            c.forwarded(message, latency, frame.stamp.is_some(), handling);
        }
        Err(SendFailure::GaveUp(e)) => {
            c.tx_dropped += 1;
            if c.tx_dropped <= 10 || c.tx_dropped.is_power_of_two() {
                tracing::warn!(
                    to = to.iface(),
                    dropped = c.tx_dropped,
                    "frame {:#x} given up after {} retries: {e}",
                    frame.can_id(),
                    passage.retries
                );
            }
        }
        Err(SendFailure::Gone(_)) => {}
    }
}

/// Write a forwarded frame to the log, when there is one: received at the kernel's
/// stamp (or the read, back from the send's wall-clock time), sent at the send's end.
/// The first write error is kept (and logged); forwarding goes on.
fn log_forwarded(
    shared: &Shared,
    frame: &RawFrame,
    from: &GatewaySocket,
    to: &GatewaySocket,
    passage: &Passage,
) {
    let Some(log) = &shared.log else {
        return;
    };
    let sent_wall = passage.sent_wall;
    let rx = frame.stamp.unwrap_or_else(|| {
        sent_wall
            .checked_sub(passage.sent_at.duration_since(passage.read_at))
            .unwrap_or(sent_wall)
    });
    if let Err(e) = lock(log).write(frame, from.iface(), to.iface(), rx, sent_wall) {
        let mut err = lock(&shared.log_error);
        if err.is_none() {
            tracing::error!("writing the forwarded-frame log: {e}");
            *err = Some(e.to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn config_defaults_and_serde() {
        let c: GatewayConfig = serde_json::from_str(
            r#"{"sim_iface": "vcan0", "physical_iface": "can1", "physical_nodes": ["STEERING_ECU"]}"#,
        )
        .unwrap();
        assert_eq!(c.physical_iface, "can1");
        assert_eq!(c.tx_give_up_ms, GatewayConfig::default().tx_give_up_ms);
        assert_eq!(c.log, None);
        let err = serde_json::from_str::<GatewayConfig>(r#"{"physical_node": []}"#).unwrap_err();
        assert!(err.to_string().contains("physical_node"), "{err}");
    }

    /// A forwarding thread failing while another thread takes snapshots: no snapshot
    /// may say "stopped" without the error that stopped it (the vcan test unplugging
    /// the physical interface read that torn state about once in 80 runs).
    #[test]
    fn a_snapshot_never_sees_the_gateway_stopped_without_its_error() {
        let config = GatewayConfig {
            physical_nodes: vec!["STEERING_ECU".into()],
            ..GatewayConfig::default()
        };
        for round in 0..1000 {
            let table = RoutingTable::new(&NETWORK, &config.physical_nodes).unwrap();
            let shared = Arc::new(Shared::new(table, &config, None));
            lock(&shared.state).threads = 2;
            let barrier = Arc::new(std::sync::Barrier::new(2));
            let failing = {
                let shared = Arc::clone(&shared);
                let barrier = Arc::clone(&barrier);
                std::thread::spawn(move || {
                    barrier.wait();
                    shared.fail("can1 went away".to_owned());
                })
            };
            barrier.wait();
            let mut snapshots = 0u64;
            loop {
                let stats = shared.snapshot();
                snapshots += 1;
                if !stats.running {
                    assert_eq!(
                        stats.error.as_deref(),
                        Some("can1 went away"),
                        "round {round}, snapshot {snapshots}: stopped without its error"
                    );
                    break;
                }
            }
            failing.join().unwrap();
        }
    }

    #[test]
    fn spawn_refuses_bad_configurations_before_touching_a_socket() {
        let spawn = |c: GatewayConfig| Gateway::spawn(c).unwrap_err();
        let base = GatewayConfig {
            sim_iface: "ugvnosuch0".into(),
            physical_iface: "ugvnosuch1".into(),
            physical_nodes: vec!["STEERING_ECU".into()],
            ..GatewayConfig::default()
        };
        assert!(matches!(
            spawn(GatewayConfig {
                physical_nodes: vec![],
                ..base.clone()
            }),
            GatewayError::NoPhysicalNode { .. }
        ));
        assert!(matches!(
            spawn(GatewayConfig {
                physical_nodes: vec!["GPS".into()],
                ..base.clone()
            }),
            GatewayError::UnknownNode { .. }
        ));
        assert!(matches!(
            spawn(GatewayConfig {
                physical_iface: "ugvnosuch0".into(),
                ..base.clone()
            }),
            GatewayError::SameInterface { .. }
        ));
        let err = spawn(base);
        assert!(
            matches!(&err, GatewayError::NoInterface { iface } if iface == "ugvnosuch0"),
            "{err}"
        );
        assert!(
            err.to_string().contains("vcan-setup up ugvnosuch0"),
            "{err}"
        );
    }
}
