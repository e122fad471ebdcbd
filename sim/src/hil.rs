//! HIL: the simulator on the real wires in real time — NMEA on a pty paced at the
//! baud rate, laser frames over iceoryx2, the simulated ECUs on SocketCAN — with the
//! controller as a separate process: started here (`--controller BINARY`) or by the
//! user.
//!
//! The binary opens the run's endpoints ([`Endpoints::open`]: the ECUs' CAN sockets,
//! the recorder's tap, the GPS line, the laser, the gateways) and hands them to
//! [`run_scenario`], which orchestrates the run: the controller's process
//! ([`process`]), the real-time tick loop ([`run_hil`]), the judging and the results.

mod lockstep;
mod process;
mod wires;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use firmware_bridge::can::gated::{Gate, Gated};
use firmware_bridge::can::paced::Pacer;
use firmware_bridge::can::timed::{Horizon, TimedSocket};
use firmware_bridge::clock::{Clock, WallClock};
use firmware_bridge::gateway::GatewayError;
use firmware_bridge::{BridgeError, CanPort};
use ugv_controller::config::ControllerConfig;
use ugv_controller::trace::Trace;

pub use lockstep::{ACK_TIMEOUT, FIRST_ACK_TIMEOUT, Lockstep, run_lockstep};
pub use process::{ControllerProcess, ensure_no_controller, spawn_controller, wait_for_controller};
pub use wires::{RunEnded, RunState, WireMap, Wires, gateway_log};

use crate::devices::gps::GpsError;
use crate::devices::map::{ControllerSite, GpsOutput};
use crate::ecu::EcuKind;
use crate::faults::ProcessFault;
use crate::isolate::IsolateError;
use crate::measure::fix_latency;
use crate::mode::Mode;
use crate::record::live::LiveView;
use crate::record::tap::SocketTap;
use crate::record::{Outputs, RecordError, RecordMode, Recorder, Recording, run_info};
use crate::run::{Outcome, Sim, SimError, Snapshot};
use crate::scenario::Scenario;
use crate::verdict::{RunEnd, judge_and_write};
use vcan_setup::netns::NetNs;

/// Why the wires could not be set up or used.
#[derive(Debug, thiserror::Error)]
pub enum HilError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("GPS port: {0}")]
    Gps(#[from] GpsError),
    #[error("laser service {service}: {message}")]
    Laser { service: String, message: String },
    #[error("starting the controller {binary}: {source}")]
    Spawn {
        binary: String,
        #[source]
        source: std::io::Error,
    },
    #[error("waiting for a controller on {iface}: {source}")]
    Wait {
        iface: String,
        #[source]
        source: BridgeError,
    },
    #[error("no controller heartbeat on {iface} within {seconds} s")]
    NoController { iface: String, seconds: u64 },
    #[error(
        "CAN interface {iface}: another controller is on the bus ({heartbeats} CONTROLLER_HEARTBEAT frames in {listened_ms} ms, state {state}); stop it before starting a run ({running})"
    )]
    BusTaken {
        iface: String,
        heartbeats: usize,
        listened_ms: u128,
        state: String,
        running: String,
    },
    #[error("devices.controller is on a board: the simulator cannot start it (drop --controller)")]
    BoardControllerStarted,
    #[error(
        "devices.gps.peer: the GPS goes out on a serial device; name the far end of its cable (peer) for the controller started here"
    )]
    SerialGpsWithoutPeer,
    #[error(
        "the fault plan kills or stops the controller's process, which needs a controller started by ugv-sim (--controller)"
    )]
    ProcessFaultWithoutProcess,
    #[error("isolating the run: {0}")]
    Isolate(#[from] IsolateError),
    #[error("gateway {sim} <-> {physical}: {source}")]
    Gateway {
        sim: String,
        physical: String,
        #[source]
        source: GatewayError,
    },
    #[error("encoding the controller configuration: {0}")]
    EncodeConfig(#[from] toml::ser::Error),
    #[error("CAN interface {iface}: {source}")]
    Can {
        iface: String,
        #[source]
        source: BridgeError,
    },
    #[error("writing the results: {0}")]
    Results(#[from] crate::verdict::ResultsError),
    #[error("recording: {0}")]
    Record(#[from] crate::record::RecordError),
    #[error("lockstep: {0}")]
    Clock(String),
    #[error("lockstep: {0}")]
    NotInLockstep(&'static str),
}

/// A simulated ECU's CAN socket: timed (see firmware_bridge::can::timed) and, in
/// lockstep, gated (see firmware_bridge::can::gated).
pub type EcuSocket = Gated<TimedSocket>;

/// The simulator's endpoints of one HIL run, opened by the binary and handed to
/// [`run_scenario`]: the ECUs' CAN sockets (timed, sharing one horizon, and paced at
/// the bit rate when the scenario asks: `can.bit_timing`), the recorder's tap on the
/// same bus, and the wires. With `--isolate`, all of them live
/// in the run's private network namespace, which lasts as long as they do.
pub struct Endpoints {
    steering: CanPort<EcuSocket>,
    throttle: CanPort<EcuSocket>,
    /// The pacing of the ECUs' transmissions (`can.bit_timing`).
    pacer: Option<Pacer>,
    tap: Option<SocketTap>,
    wires: Wires,
    /// Dropped last: the namespace the sockets were opened in.
    _isolated: Option<NetNs>,
}

impl std::fmt::Debug for Endpoints {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Endpoints")
            .field("wires", &self.wires)
            .field("tap", &self.tap.is_some())
            .finish()
    }
}

impl Endpoints {
    /// Check that `options` fit the scenario's device map, enter the private namespace
    /// when asked, and open the endpoints of `scenario` on its CAN interface. `log`
    /// gets a line for each thing the user should know.
    pub fn open(
        scenario: &Scenario,
        options: &HilOptions,
        log: &mut dyn FnMut(&str),
    ) -> Result<Endpoints, HilError> {
        let sc = scenario;
        if options.lockstep {
            check_lockstep(sc)?;
        }
        if options.controller.is_some() {
            if matches!(sc.devices.controller, ControllerSite::Board { .. }) {
                return Err(HilError::BoardControllerStarted);
            }
            if matches!(sc.devices.gps, GpsOutput::Serial { peer: None, .. }) {
                return Err(HilError::SerialGpsWithoutPeer);
            }
        }
        // --isolate: this thread, its sockets and the controller it starts live in a
        // private network namespace until the endpoints are dropped.
        let isolated = match &options.isolate {
            Some(name) => Some(crate::isolate::enter(sc, name, log)?),
            None => None,
        };
        let iface = sc.can.interface.clone();
        let horizon = Horizon::new();
        // The simulator sends once per physics step: a frame whose turn on the bus
        // comes before the next step goes at once.
        let pacer = sc
            .can
            .bit_timing
            .then(|| Pacer::new(golf_car_can::NETWORK.baudrate, 1.0 / sc.sim.physics_hz));
        let gate = options.lockstep.then(Gate::new);
        let open = |what: &str| {
            CanPort::open_timed(&iface, horizon.clone(), pacer.as_ref(), gate.clone()).map_err(
                |source| HilError::Can {
                    iface: format!("{iface} ({what})"),
                    source,
                },
            )
        };
        let (steering, throttle) = (open("steering ECU")?, open("throttle ECU")?);
        // The steering ECU's socket is the simulator's view of the whole bus: it
        // counts every frame for the bus load and reports the other nodes' frames to
        // the pacer, so it takes all. The throttle ECU's takes only its node's IDs, as
        // a real ECU's acceptance filter does.
        throttle
            .accept_only(&EcuKind::Throttle.accepts())
            .map_err(|source| HilError::Can {
                iface: format!("{iface} (throttle ECU)"),
                source,
            })?;
        // The tap feeds the recording and the live view alike.
        let tap =
            match options.record || options.live.is_some() {
                true => Some(SocketTap::open(&iface, gate.clone()).map_err(|source| {
                    RecordError::Tap {
                        iface: iface.clone(),
                        source,
                    }
                })?),
                false => None,
            };
        let gps_link = options.gps_link.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("ugv-hil-{}-gps", options.run_id))
        });
        let gateway_logs = options.record.then_some(options.results.as_path());
        let wires = Wires::open(
            sc,
            &gps_link,
            &options.run_id,
            horizon,
            gateway_logs,
            options.rt_priority,
            gate,
        )?;
        Ok(Endpoints {
            steering,
            throttle,
            pacer,
            tap,
            wires,
            _isolated: isolated,
        })
    }
}

/// Step in real time on absolute deadlines, the sensors' output on the wires, until
/// the run is over, `stop` is raised, or the controller exits (in lockstep, when the
/// wires have a clock: [`run_lockstep`]). Returns the outcome and the monotonic time
/// of tick 0 (see [`fix_latency`]).
pub fn run_hil(
    sim: &mut Sim<EcuSocket>,
    wires: &mut Wires,
    mut controller: Option<&mut ControllerProcess>,
    stop: &AtomicBool,
    status_every: f64,
    status: &mut dyn FnMut(&Snapshot),
    mut recording: Option<&mut Recording<SocketTap>>,
) -> Result<(Outcome, u64), HilError> {
    if let Some(lockstep) = wires.lockstep.take() {
        return run_lockstep(
            sim,
            wires,
            &lockstep,
            controller,
            stop,
            status_every,
            status,
            recording,
        );
    }
    let mut clock = WallClock::new(sim.dt());
    let started = clock.start_monotonic_ns();
    let every = ((status_every / sim.dt()).round() as u64).max(1);
    let mut process = ProcessFault::Running;
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok((stopped_by_signal(sim.time()), started));
        }
        let k = sim.next_tick();
        let late = clock.wait_tick(k);
        // A late tick takes only the frames that arrived by its deadline: catching up,
        // each tick gets those of its own period (firmware_bridge::can::timed).
        wires.can_horizon.set_for_tick(late);
        let now = k as f64 * sim.dt();
        let outcome = sim.step(clock.now(), late)?;
        let out = sim.take_outputs();
        if let Some(r) = recording.as_deref_mut() {
            r.sensors(now, &out);
            r.after_step(now, sim, None);
        }
        if let Some(epoch) = &out.gps {
            wires.gps.enqueue(epoch);
        }
        wires.gps.pace(now)?;
        if let Some(frame) = &out.laser {
            wires.publish(frame)?;
        }
        if k.is_multiple_of(every) {
            status(&sim.snapshot());
        }
        if let Some(o) = outcome {
            return Ok((o, started));
        }
        signal_process_fault(sim, controller.as_deref_mut(), &mut process)?;
        // The run goes on until the car is safe, so the verdict can say how fast each
        // ECU got there.
        if k.is_multiple_of(20)
            && let Some(c) = controller.as_deref_mut()
            && let Ok(Some(exit)) = c.child.try_wait()
        {
            sim.controller_gone(format!("the controller exited ({exit})"));
        }
    }
}

/// Signal the controller's process when the fault plan changes what it should be
/// doing (killed, stopped, running); `process` is what it was told last.
fn signal_process_fault(
    sim: &Sim<EcuSocket>,
    controller: Option<&mut ControllerProcess>,
    process: &mut ProcessFault,
) -> Result<(), HilError> {
    let wanted = sim.process_fault();
    if wanted == *process {
        return Ok(());
    }
    let Some(c) = controller else {
        return Err(HilError::ProcessFaultWithoutProcess);
    };
    use nix::sys::signal::Signal;
    c.signal(match wanted {
        ProcessFault::Killed => Signal::SIGKILL,
        ProcessFault::Stopped => Signal::SIGSTOP,
        ProcessFault::Running => Signal::SIGCONT,
    });
    *process = wanted;
    Ok(())
}

/// What lockstep cannot run: devices outside the simulator (they keep their own
/// time), and a bus paced at its bit rate on the wall clock.
fn check_lockstep(sc: &Scenario) -> Result<(), HilError> {
    if !sc.devices.all_simulated() {
        return Err(HilError::NotInLockstep(
            "the device map puts a device outside the simulator, and a physical device keeps its own time (run it in real time, without --lockstep)",
        ));
    }
    if sc.can.bit_timing {
        return Err(HilError::NotInLockstep(
            "can.bit_timing paces the bus on the wall clock (run it in real time, without --lockstep)",
        ));
    }
    Ok(())
}

/// How to run a scenario on the wires.
#[derive(Clone, Debug)]
pub struct HilOptions {
    /// Start this controller binary with the wire locations.
    pub controller: Option<PathBuf>,
    /// Extra arguments for it.
    pub controller_args: Vec<String>,
    /// Wait for a controller started separately (implied when it is on a board).
    pub wait_for_controller: bool,
    /// The GPS link (a symlink to the pty); a temporary path named after the run
    /// when absent.
    pub gps_link: Option<PathBuf>,
    /// Names the run's iceoryx2 services.
    pub run_id: String,
    /// Where verdict.json, the traces and the figure go.
    pub results: PathBuf,
    /// Simulated seconds between status calls.
    pub status_every: f64,
    /// Run in a private network namespace of this name (`--isolate`, see
    /// [`crate::isolate`]): the CAN interface is created there, and no process
    /// outside can open it.
    pub isolate: Option<String>,
    /// Record the run into `results` (see [`crate::record`]).
    pub record: bool,
    /// Draw the run into `results` (figure.svg, figure.png).
    pub figures: bool,
    /// Have the controller started here record its own ports into
    /// `results`/[`CONTROLLER_LOG_DIR`](crate::record::CONTROLLER_LOG_DIR).
    pub controller_log: bool,
    /// Serve the run's channels on this live view (see [`crate::record::live`]); start
    /// it before [`Endpoints::open`], which may enter a private network namespace.
    pub live: Option<Arc<LiveView>>,
    /// SCHED_FIFO priority of the tick loop while it runs, 0 for none (see
    /// [`firmware_bridge::realtime`]).
    pub rt_priority: u8,
    /// Lockstep: the simulator and the controller wait on each other's ticks over the
    /// clock wire (see [`run_lockstep`]), instead of both running on the wall clock.
    pub lockstep: bool,
}
/// The controller `ugv-sim run --controller` starts, once its bus is known to be free
/// (none without --controller).
fn start_controller(
    options: &HilOptions,
    iface: &str,
    config_path: &std::path::Path,
    wires: &WireMap,
    trace_path: &std::path::Path,
    log: &mut dyn FnMut(&str),
) -> Result<Option<ControllerProcess>, HilError> {
    let Some(binary) = &options.controller else {
        return Ok(None);
    };
    ensure_no_controller(iface)?;
    log(&format!(
        "starting {} (configuration {})",
        binary.display(),
        config_path.display()
    ));
    // docs/recording.md: "The controller's own recording".
    let own_log = options
        .controller_log
        .then(|| options.results.join(crate::record::CONTROLLER_LOG_DIR));
    spawn_controller(
        binary,
        config_path,
        wires,
        trace_path,
        own_log.as_deref(),
        &options.controller_args,
    )
    .map(Some)
}

/// Run `scenario` in HIL with the controller configured by `config` on the endpoints
/// the binary opened: start or wait for the controller, step in real time until the
/// outcome, collect the controller's trace, judge and write the results. `log` gets
/// a line for each thing the user should know; `status` a snapshot every
/// `status_every` seconds.
pub fn run_scenario(
    scenario: &Scenario,
    config: &ControllerConfig,
    endpoints: Endpoints,
    options: &HilOptions,
    stop: &AtomicBool,
    log: &mut dyn FnMut(&str),
    status: &mut dyn FnMut(&Snapshot),
) -> Result<(crate::verdict::Verdict, Outcome), HilError> {
    let sc = scenario;
    let Endpoints {
        steering,
        throttle,
        pacer,
        tap,
        mut wires,
        _isolated,
    } = endpoints;
    let iface = sc.can.interface.clone();
    let mut sim = Sim::new(sc.clone(), steering, throttle).with_sensors()?;
    let mut recording = open_recording(tap, sc, config, options)?;
    log_wires(&wires.map, &iface, log);
    // From the first wires.json on, the file says where the run is, and how it ended
    // before the wires close (when `wires` drops), whatever ended it.
    let result = (|| {
        let (config_path, trace_path) = write_run_files(options, &wires.map, config)?;
        let mut controller =
            start_controller(options, &iface, &config_path, &wires.map, &trace_path, log)?;
        // In lockstep the simulator waits for the controller's answer to its start instead.
        if controller.is_none()
            && !options.lockstep
            && !await_controller(sc, options, &iface, &config_path, stop, log)?
        {
            return Ok(stopped_before_start(sc, &sim));
        }
        log(&format!(
            "physics {} Hz, time limit {} s",
            sc.sim.physics_hz, sc.sim.time_limit_s
        ));
        wires.map.state = RunState::Running;
        write_wires(options, &wires.map)?;
        // The controller and every helper thread were started: they stay ordinary.
        let rt_sched = firmware_bridge::realtime::promote(options.rt_priority);
        log(&rt_sched.promotion.describe("tick loop"));
        let run = run_hil(
            &mut sim,
            &mut wires,
            controller.as_mut(),
            stop,
            options.status_every,
            status,
            recording.as_mut(),
        );
        drop(rt_sched);
        if let Some(summary) = recording.and_then(Recording::finish) {
            log(&crate::record::describe(&summary));
        }
        // Whatever happened, the controller is asked to finish and its trace collected.
        let mut trace = controller.as_mut().and_then(|c| finish_controller(c, log));
        if let (true, Some(t)) = (options.lockstep, &mut trace) {
            // The controller's loop ended with the simulator's run: its length is the
            // simulator's, as in SIL (the controller's last tick may be a step before).
            t.duration = sim.time();
        }
        let (outcome, started_ns) = run?;
        if let Some(p) = &pacer {
            sim.bus_arbitrated(p.stats());
        }
        log_gps_input(&wires, log);
        let measured = |verdict: &mut crate::verdict::Verdict| {
            verdict.fix_latency = trace
                .as_ref()
                .and_then(|t| fix_latency(&t.fix_timing, sc.sim.epoch.unix_s(), started_ns));
            verdict.wires = Some(wires.stats());
        };
        let report = sim.report(outcome.clone());
        let end = RunEnd {
            mode: Mode::Hil,
            report,
            driven: &sim.trajectory,
            trace: trace.as_ref(),
        };
        let verdict = judge_and_write(
            sc,
            end,
            config.perception.detection_radius,
            &options.results,
            options.figures,
            measured,
        )?;
        Ok((verdict, outcome))
    })();
    wires.map.state = RunState::Ended;
    wires.map.end = Some(RunEnded::of(&result));
    if let Err(e) = write_wires(options, &wires.map) {
        log(&format!("{e} (the end of the run)"));
    }
    result
}

/// The outcome of a run stopped by signal (Ctrl-C) at `time`.
fn stopped_by_signal(time: f64) -> Outcome {
    Outcome::Stopped {
        time,
        reason: "stopped by signal".to_owned(),
    }
}

/// The verdict of a run stopped by signal while it waited for its controller.
fn stopped_before_start(sc: &Scenario, sim: &Sim<EcuSocket>) -> (crate::verdict::Verdict, Outcome) {
    let outcome = stopped_by_signal(0.0);
    let verdict = crate::verdict::Verdict::judge(Mode::Hil, sc, sim.report(outcome.clone()), None);
    (verdict, outcome)
}

/// What the controller wrote to the GPS port, if anything.
fn log_gps_input(wires: &Wires, log: &mut dyn FnMut(&str)) {
    let (lines, last) = wires.gps_input();
    if lines > 0 {
        log(&format!(
            "the controller wrote {lines} lines to the GPS port (last: {last:?})"
        ));
    }
}

/// The run's recording on the recorder's tap (none without one): into the results
/// when `--record`, onto the live view when there is one.
fn open_recording(
    tap: Option<SocketTap>,
    sc: &Scenario,
    config: &ControllerConfig,
    options: &HilOptions,
) -> Result<Option<Recording<SocketTap>>, HilError> {
    let Some(tap) = tap else {
        return Ok(None);
    };
    let toml = toml::to_string_pretty(config).unwrap_or_default();
    let mode = match options.lockstep {
        true => RecordMode::Lockstep,
        false => RecordMode::Hil,
    };
    let info = run_info(mode, sc, toml);
    let outputs = Outputs {
        dir: options.record.then_some(options.results.as_path()),
        live: options.live.as_deref(),
    };
    Ok(Some(Recording::new(
        Recorder::create(outputs, sc, info)?,
        tap,
    )))
}

/// A line for the wires, and one for each gateway to a physical bus.
fn log_wires(m: &WireMap, iface: &str, log: &mut dyn FnMut(&str)) {
    log(&format!(
        "wires: GPS {} ({}, {} baud), laser iceoryx2 service {:?} ({}), CAN {} (golf_car.dbc); controller {}",
        m.gps_link.display(),
        m.gps_line,
        m.gps_baud,
        m.laser_service,
        m.laser,
        m.can,
        m.controller,
    ));
    if let Some(clock) = &m.clock_service {
        log(&format!(
            "lockstep on {clock}: the simulator waits for each tick's acknowledgement"
        ));
    }
    for (physical, nodes) in &m.gateways {
        log(&format!(
            "gateway {iface} <-> {physical}: physical {}",
            nodes.join(", ")
        ));
    }
}

/// Write `wires.json` and `controller.toml` into the results and clear the last
/// run's controller trace; returns the configuration's and the trace's paths.
fn write_run_files(
    options: &HilOptions,
    map: &WireMap,
    config: &ControllerConfig,
) -> Result<(PathBuf, PathBuf), HilError> {
    let write = |name: &str, text: String| {
        let path = options.results.join(name);
        std::fs::write(&path, text).map_err(|source| results_error(&path, source))
    };
    write_wires(options, map)?;
    // The controller's configuration: given to the binary started here, and left for
    // a controller started by the user or flashed to a board.
    // The mission for a controller of one's own (docs/wire-contract.md); controller.toml
    // is written last, so a reader that waits for it finds the other two whole.
    let mission = crate::mission::mission_file(config);
    write("mission.toml", toml::to_string_pretty(&mission)?)?;
    let config_path = options.results.join("controller.toml");
    write("controller.toml", toml::to_string_pretty(config)?)?;
    let trace_path = options.results.join("controller-trace.jsonl");
    let _ = std::fs::remove_file(&trace_path);
    Ok((config_path, trace_path))
}

/// `wires.json` into the results, whole or not at all ([`WireMap::write`]).
fn write_wires(options: &HilOptions, map: &WireMap) -> Result<(), HilError> {
    map.write(&options.results)
        .map_err(|source| results_error(&options.results.join(WireMap::FILE), source))
}

/// An error writing `path` of the results.
fn results_error(path: &std::path::Path, source: std::io::Error) -> HilError {
    HilError::Results(crate::verdict::ResultsError::Write {
        path: path.display().to_string(),
        source,
    })
}

/// With no controller started here: when asked to (`--wait-for-controller`) or when
/// the controller is on a board, wait up to 60 s for its heartbeat. False when the
/// run was stopped first.
fn await_controller(
    sc: &Scenario,
    options: &HilOptions,
    iface: &str,
    config_path: &std::path::Path,
    stop: &AtomicBool,
    log: &mut dyn FnMut(&str),
) -> Result<bool, HilError> {
    let board = matches!(sc.devices.controller, ControllerSite::Board { .. });
    if !(options.wait_for_controller || board) {
        return Ok(true);
    }
    log(&format!(
        "waiting for a controller heartbeat on {iface} (configuration for it: {})",
        config_path.display()
    ));
    wait_for_controller(iface, Duration::from_secs(60), stop)
}

/// Ask the controller started here to finish, and read the trace it wrote while it
/// ran (there even when it was killed).
fn finish_controller(c: &mut ControllerProcess, log: &mut dyn FnMut(&str)) -> Option<Trace> {
    let exit = c.finish(Duration::from_secs(5));
    log(&format!("controller finished: {exit:?}"));
    std::fs::read_to_string(&c.trace)
        .ok()
        .and_then(|t| match Trace::from_jsonl(&t) {
            Ok(trace) => Some(trace),
            Err(e) => {
                log(&format!(
                    "the controller's trace {}: {e}",
                    c.trace.display()
                ));
                None
            }
        })
}
