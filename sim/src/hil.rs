//! HIL: the simulator on the real wires in real time — NMEA on a pty paced at the
//! baud rate, laser frames over iceoryx2, the simulated ECUs on SocketCAN — with the
//! controller as a separate process: started here (`--controller BINARY`) or by the
//! user.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::can::timed::{Horizon, TimedSocket};
use firmware_bridge::clock::{Clock, WallClock};
use firmware_bridge::gateway::{Gateway, GatewayConfig, GatewayHandle, GatewayStats};
use firmware_bridge::laser::{LaserFrame, LaserPublisher, service_name};
use firmware_bridge::{BridgeError, CanPort, Received};
use golf_car_can::GolfCarMessage;

use crate::devices::cola_driver::{ColaDriverStats, ColaDriverThread};
use crate::devices::gps::{GpsError, GpsPort};
use crate::devices::laser::LaserProfile;
use crate::devices::map::{ControllerSite, GpsOutput, LaserSource};
use crate::faults::ProcessFault;
use crate::mode::Mode;
use firmware_bridge::cola::{ColaServer, DecodeOptions, ServerConfig};
use serde::Serialize;
use ugv_controller::trace::FixTiming;

use ugv_controller::config::ControllerConfig;
use ugv_controller::trace::Trace;

use crate::record::tap::SocketTap;
use crate::record::{RecordError, RecordMode, Recorder, Recording, RunInfo};
use crate::run::{Jitter, Outcome, Sim, SimError, Snapshot};
use crate::scenario::Scenario;
use crate::verdict::{Verdict, write_results};

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
    #[error("{0}")]
    Setup(String),
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
}

/// Where the wires are, for the user and for the controller.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WireMap {
    /// What the controller opens as its GPS: the pty's link, or the serial device.
    pub gps_link: PathBuf,
    pub gps_baud: u32,
    /// "pty" or "serial".
    pub gps_line: &'static str,
    pub laser_service: String,
    /// How the laser reaches the service: "iceoryx2", "cola <addr>", "physical <addr>".
    pub laser: String,
    /// The simulator's bus (the controller's, unless it is on a board).
    pub can: String,
    /// The gateways to physical buses: (physical interface, DBC nodes on it).
    pub gateways: Vec<(String, Vec<&'static str>)>,
    /// "local", or "board on <iface>".
    pub controller: String,
}

/// Where the simulated scans go.
enum LaserOut {
    /// Straight onto the run's iceoryx2 service (boxed: an iceoryx2 publisher is
    /// over a kilobyte).
    Iceoryx2(Box<LaserPublisher>),
    /// Served as a CoLa-A device over TCP (a driver puts them on the service).
    Cola(ColaServer),
    /// Nowhere: a physical laser is in the loop.
    Off,
}

/// The simulator's ends of the wires, the gateways to physical buses, and the laser
/// driver when the laser is a CoLa-A device.
pub struct Wires {
    pub map: WireMap,
    gps: GpsPort,
    laser: LaserOut,
    driver: Option<ColaDriverThread>,
    gateways: Vec<GatewayHandle>,
    /// Up to when the simulated ECUs' timed sockets hand out frames (set per tick).
    can_horizon: Horizon,
}

impl std::fmt::Debug for Wires {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Wires").field("map", &self.map).finish()
    }
}

impl Wires {
    /// Open the wires of the scenario's device map: the GPS pty behind `gps_link` (or
    /// the serial device), the laser service of `run_id` (directly, or behind a CoLa-A
    /// server and driver), and a gateway to each physical bus. `can_horizon` is the
    /// horizon of the ECUs' timed sockets, which the run sets at each tick.
    pub fn open<B: embedded_can::nb::Can>(
        sim: &Sim<B>,
        gps_link: &Path,
        run_id: &str,
        can_horizon: Horizon,
    ) -> Result<Wires, HilError> {
        let sc = &sim.scenario;
        let devices = &sc.devices;
        let (gps, gps_line) = match &devices.gps {
            GpsOutput::Pty {} => (GpsPort::open(Some(gps_link), sc.gps.baud)?, "pty"),
            GpsOutput::Serial { device, baud, .. } => (
                GpsPort::serial(device, baud.unwrap_or(sc.gps.baud))?,
                "serial",
            ),
        };
        let service = service_name(run_id);
        let laser_err = |message: String| HilError::Laser {
            service: service.clone(),
            message,
        };
        let (laser, driver, laser_text) = match &devices.laser {
            LaserSource::Iceoryx2 {} => (
                LaserOut::Iceoryx2(
                    LaserPublisher::new(&service)
                        .map(Box::new)
                        .map_err(|e| laser_err(e.to_string()))?,
                ),
                None,
                "iceoryx2".to_owned(),
            ),
            LaserSource::Cola { listen, driver } => {
                let spec = sc.laser.spec();
                let device = match sc.laser.profile {
                    LaserProfile::Lms111 => "LMS111",
                    LaserProfile::Lms291 => "LMS291",
                };
                let server = ColaServer::bind(
                    *listen,
                    ServerConfig {
                        device_name: device.to_owned(),
                        ..ServerConfig::lms111()
                    },
                )
                .map_err(|e| laser_err(format!("serving CoLa-A on {listen}: {e}")))?;
                let addr = server.local_addr();
                let driver = if *driver {
                    let decode = DecodeOptions {
                        range_min: spec.range_min as f32,
                        range_max: spec.range_max as f32,
                        ..DecodeOptions::default()
                    };
                    Some(
                        ColaDriverThread::spawn(addr, &service, decode)
                            .map_err(|e| laser_err(format!("CoLa-A driver to {addr}: {e}")))?,
                    )
                } else {
                    None
                };
                (LaserOut::Cola(server), driver, format!("cola {addr}"))
            }
            LaserSource::Physical { address } => (
                LaserOut::Off,
                Some(
                    ColaDriverThread::spawn(*address, &service, DecodeOptions::default())
                        .map_err(|e| laser_err(format!("CoLa-A driver to {address}: {e}")))?,
                ),
                format!("physical {address}"),
            ),
        };
        let buses = devices.physical_buses();
        let mut gateways = Vec::new();
        for (physical, nodes) in &buses {
            let config = GatewayConfig {
                sim_iface: sc.can.interface.clone(),
                physical_iface: physical.clone(),
                physical_nodes: nodes.iter().map(|n| (*n).to_owned()).collect(),
                ..GatewayConfig::default()
            };
            gateways.push(Gateway::spawn(config).map_err(|e| {
                HilError::Setup(format!("gateway {} <-> {physical}: {e}", sc.can.interface))
            })?);
        }
        Ok(Wires {
            map: WireMap {
                gps_link: match &devices.gps {
                    GpsOutput::Serial {
                        peer: Some(peer), ..
                    } => peer.clone(),
                    _ => gps.path().to_path_buf(),
                },
                gps_baud: match &devices.gps {
                    GpsOutput::Serial { baud: Some(b), .. } => *b,
                    _ => sc.gps.baud,
                },
                gps_line,
                laser_service: service,
                laser: laser_text,
                can: sc.can.interface.clone(),
                gateways: buses,
                controller: match &devices.controller {
                    ControllerSite::Local {} => "local".to_owned(),
                    ControllerSite::Board { can } => format!("board on {can}"),
                },
            },
            gps,
            laser,
            driver,
            gateways,
            can_horizon,
        })
    }

    /// Lines the controller wrote to the GPS port (GGA for NTRIP, configuration).
    pub fn gps_input(&self) -> (u64, Option<String>) {
        let log = self.gps.input();
        (log.count(), log.last().map(str::to_owned))
    }

    /// Put a scan on its way.
    fn publish(&mut self, frame: &LaserFrame) -> Result<(), HilError> {
        match &mut self.laser {
            LaserOut::Iceoryx2(p) => p.publish(frame).map(|_| ()).map_err(|e| HilError::Laser {
                service: self.map.laser_service.clone(),
                message: e.to_string(),
            }),
            // Never blocks: a client too slow for the scans loses them (counted).
            LaserOut::Cola(server) => {
                server
                    .publish(frame)
                    .map(|_| ())
                    .map_err(|e| HilError::Laser {
                        service: self.map.laser_service.clone(),
                        message: format!("CoLa-A server: {e}"),
                    })
            }
            LaserOut::Off => Ok(()),
        }
    }

    /// What the gateways and the laser driver did, for the verdict.
    pub fn stats(&self) -> WireStats {
        WireStats {
            gps_line: GpsLineStats {
                written_bytes: self.gps.written(),
                dropped_sentences: self.gps.dropped_sentences(),
                dropped_bytes: self.gps.dropped_bytes(),
            },
            gateways: self.gateways.iter().map(GatewayHandle::stats).collect(),
            laser_driver: self.driver.as_ref().map(ColaDriverThread::stats),
        }
    }
}

/// Statistics of the wires that carry more than the simulator's own ends.
#[derive(Clone, Debug, Serialize)]
pub struct WireStats {
    pub gps_line: GpsLineStats,
    pub gateways: Vec<GatewayStats>,
    pub laser_driver: Option<ColaDriverStats>,
}

/// The GPS line: what went out, and the whole sentences the receiver's transmit
/// buffer dropped because the reader did not keep up.
#[derive(Clone, Debug, Serialize)]
pub struct GpsLineStats {
    pub written_bytes: u64,
    pub dropped_sentences: u64,
    pub dropped_bytes: u64,
}

/// Block until a CONTROLLER_HEARTBEAT appears on `iface` (a controller started by
/// the user), at most `timeout`.
pub fn wait_for_controller(
    iface: &str,
    timeout: Duration,
    stop: &AtomicBool,
) -> Result<bool, HilError> {
    let mut port = CanPort::open(iface).map_err(|source| HilError::Wait {
        iface: iface.to_owned(),
        source,
    })?;
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline && !stop.load(Ordering::Relaxed) {
        if let Some(Received::Message(GolfCarMessage::ControllerHeartbeat(_))) = port
            .recv(Duration::from_millis(200))
            .map_err(|source| HilError::Wait {
                iface: iface.to_owned(),
                source,
            })?
        {
            return Ok(true);
        }
    }
    if stop.load(Ordering::Relaxed) {
        return Ok(false);
    }
    Err(HilError::NoController {
        iface: iface.to_owned(),
        seconds: timeout.as_secs(),
    })
}

/// A controller process started for the run.
#[derive(Debug)]
pub struct ControllerProcess {
    pub child: Child,
    pub trace: PathBuf,
}

/// Start `binary run --config CONFIG --gps LINK --baud BAUD --laser SERVICE --can IFACE
/// --trace TRACE [extra...]` (the controller contract, README).
pub fn spawn_controller(
    binary: &Path,
    config: &Path,
    wires: &WireMap,
    trace: &Path,
    extra: &[String],
) -> Result<ControllerProcess, HilError> {
    let child = Command::new(binary)
        .arg("run")
        .arg("--config")
        .arg(config)
        .arg("--gps")
        .arg(&wires.gps_link)
        .args([
            "--baud",
            &wires.gps_baud.to_string(),
            "--laser",
            &wires.laser_service,
            "--can",
            &wires.can,
        ])
        .arg("--trace")
        .arg(trace)
        .args(extra)
        .stdin(Stdio::null())
        .spawn()
        .map_err(|source| HilError::Spawn {
            binary: binary.display().to_string(),
            source,
        })?;
    Ok(ControllerProcess {
        child,
        trace: trace.to_path_buf(),
    })
}

impl ControllerProcess {
    /// Ask the controller to finish (SIGINT: it leaves the car safe and writes its
    /// trace), then kill it if it has not gone within `grace`.
    pub fn finish(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        if let Ok(Some(status)) = self.child.try_wait() {
            return Some(status);
        }
        // A process the fault plan stopped must run again to act on SIGINT.
        self.signal(nix::sys::signal::Signal::SIGCONT);
        self.signal(nix::sys::signal::Signal::SIGINT);
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        self.child.wait().ok()
    }

    /// Send `signal` to the controller's process (gone already: nothing to do).
    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), signal);
        }
    }
}

/// The HIL loop's latency: from the moment the simulator made a GPS fix to the
/// controller's first STEERING_CMD computed with it, split at the moment the
/// controller's reader completed the fix (which includes the line's transmission time
/// at the baud rate). Milliseconds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FixLatency {
    pub fix_to_read: Jitter,
    pub read_to_command: Jitter,
    pub fix_to_command: Jitter,
}

const DAY_S: f64 = 86_400.0;

/// Join the controller's fix timings with the run's clock: the run started (tick 0)
/// at `start_ns` on the monotonic clock, with UTC `epoch_unix_s` at t = 0. `None`
/// without timings (a controller that does not record them).
pub fn fix_latency(timings: &[FixTiming], epoch_unix_s: f64, start_ns: u64) -> Option<FixLatency> {
    if timings.is_empty() {
        return None;
    }
    let epoch_of_day = epoch_unix_s.rem_euclid(DAY_S);
    let mut to_read = Vec::new();
    let mut to_command = Vec::new();
    let mut read_to_command = Vec::new();
    for t in timings {
        // Sim time of the fix; a run may cross midnight UTC.
        let sim_t = (t.utc_s - epoch_of_day).rem_euclid(DAY_S);
        let fix_ns = start_ns as f64 + sim_t * 1e9;
        to_read.push((t.read_ns as f64 - fix_ns) * 1e-9);
        to_command.push((t.command_ns as f64 - fix_ns) * 1e-9);
        read_to_command.push(t.command_ns.saturating_sub(t.read_ns) as f64 * 1e-9);
    }
    Some(FixLatency {
        fix_to_read: Jitter::of(to_read),
        read_to_command: Jitter::of(read_to_command),
        fix_to_command: Jitter::of(to_command),
    })
}

/// Step in real time on absolute deadlines, the sensors' output on the wires, until
/// the run is over, `stop` is raised, or the controller exits. Returns the outcome
/// and the monotonic time of tick 0 (see [`fix_latency`]).
pub fn run_hil(
    sim: &mut Sim<TimedSocket>,
    wires: &mut Wires,
    mut controller: Option<&mut ControllerProcess>,
    stop: &AtomicBool,
    status_every: f64,
    status: &mut dyn FnMut(&Snapshot),
    mut recording: Option<&mut Recording<SocketTap>>,
) -> Result<(Outcome, u64), HilError> {
    let mut clock = WallClock::new(sim.dt());
    let started = clock.start_monotonic_ns();
    let every = ((status_every / sim.dt()).round() as u64).max(1);
    let mut process = ProcessFault::Running;
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok((
                Outcome::Stopped {
                    time: sim.time(),
                    reason: "stopped by signal".to_owned(),
                },
                started,
            ));
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
        let wanted = sim.process_fault();
        if wanted != process {
            let Some(c) = controller.as_deref_mut() else {
                return Err(HilError::Setup(
                    "the fault plan kills or stops the controller's process, which needs a \
                     controller started by ugv-sim (--controller)"
                        .to_owned(),
                ));
            };
            use nix::sys::signal::Signal;
            c.signal(match wanted {
                ProcessFault::Killed => Signal::SIGKILL,
                ProcessFault::Stopped => Signal::SIGSTOP,
                ProcessFault::Running => Signal::SIGCONT,
            });
            process = wanted;
        }
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
    /// SCHED_FIFO priority of the tick loop while it runs, 0 for none (see
    /// [`firmware_bridge::realtime`]).
    pub rt_priority: u8,
}

/// Run `scenario` in HIL with the controller configured by `config`: open the wires,
/// start or wait for the controller, step in real time until the outcome, collect
/// the controller's trace, judge and write the results. `log` gets a line for each
/// thing the user should know; `status` a snapshot every `status_every` seconds.
pub fn run_scenario(
    scenario: &Scenario,
    config: &ControllerConfig,
    options: &HilOptions,
    stop: &AtomicBool,
    log: &mut dyn FnMut(&str),
    status: &mut dyn FnMut(&Snapshot),
) -> Result<(Verdict, Outcome), HilError> {
    let sc = scenario;
    let board = match &sc.devices.controller {
        ControllerSite::Board { can } => Some(can.clone()),
        ControllerSite::Local {} => None,
    };
    if board.is_some() && options.controller.is_some() {
        return Err(HilError::Setup(
            "devices.controller is on a board: the simulator cannot start it (drop --controller)"
                .to_owned(),
        ));
    }
    if options.controller.is_some()
        && matches!(sc.devices.gps, GpsOutput::Serial { peer: None, .. })
    {
        return Err(HilError::Setup(
            "devices.gps.peer: the GPS goes out on a serial device; name the far end of its cable (peer) for the controller started here"
                .to_owned(),
        ));
    }
    // --isolate: this thread, its sockets and the controller it starts live in a
    // private network namespace from here to the end of the run (the guard's drop).
    let _isolated = match &options.isolate {
        Some(name) => {
            Some(crate::isolate::enter(sc, name, log).map_err(|e| HilError::Setup(e.to_string()))?)
        }
        None => None,
    };
    let iface = sc.can.interface.clone();
    let horizon = Horizon::new();
    let open = |what: &str| {
        CanPort::open_timed(&iface, horizon.clone()).map_err(|source| HilError::Can {
            iface: format!("{iface} ({what})"),
            source,
        })
    };
    let (steering, throttle) = (open("steering ECU")?, open("throttle ECU")?);
    let mut sim = Sim::new(sc.clone(), steering, throttle).with_sensors()?;
    let mut recording = match options.record {
        true => {
            let tap = SocketTap::open(&iface).map_err(|source| RecordError::Tap {
                iface: iface.clone(),
                source,
            })?;
            let toml = toml::to_string_pretty(config).unwrap_or_default();
            let info = RunInfo::of(RecordMode::Hil, sc, toml);
            Some(Recording::new(
                Recorder::create(&options.results, sc, info)?,
                tap,
            ))
        }
        false => None,
    };
    let gps_link = options
        .gps_link
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join(format!("ugv-hil-{}-gps", options.run_id)));
    let mut wires = Wires::open(&sim, &gps_link, &options.run_id, horizon)?;
    let m = &wires.map;
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
    for (physical, nodes) in &m.gateways {
        log(&format!(
            "gateway {iface} <-> {physical}: physical {}",
            nodes.join(", ")
        ));
    }
    let write = |name: &str, text: String| {
        let path = options.results.join(name);
        std::fs::write(&path, text).map_err(|source| {
            HilError::Results(crate::verdict::ResultsError::Write {
                path: path.display().to_string(),
                source,
            })
        })
    };
    write(
        "wires.json",
        serde_json::to_string_pretty(&wires.map).unwrap_or_default(),
    )?;
    // The controller's configuration: given to the binary started here, and left for
    // a controller started by the user or flashed to a board.
    let config_path = options.results.join("controller.toml");
    write(
        "controller.toml",
        toml::to_string_pretty(config)
            .map_err(|e| HilError::Setup(format!("encoding the controller configuration: {e}")))?,
    )?;
    let trace_path = options.results.join("controller-trace.jsonl");
    let _ = std::fs::remove_file(&trace_path);
    let mut controller = match &options.controller {
        Some(binary) => {
            log(&format!(
                "starting {} (configuration {})",
                binary.display(),
                config_path.display()
            ));
            Some(spawn_controller(
                binary,
                &config_path,
                &wires.map,
                &trace_path,
                &options.controller_args,
            )?)
        }
        None => None,
    };
    if controller.is_none() && (options.wait_for_controller || board.is_some()) {
        log(&format!(
            "waiting for a controller heartbeat on {iface} (configuration for it: {})",
            config_path.display()
        ));
        if !wait_for_controller(&iface, Duration::from_secs(60), stop)? {
            let outcome = Outcome::Stopped {
                time: 0.0,
                reason: "stopped by signal".to_owned(),
            };
            let verdict = Verdict::judge(Mode::Hil, sc, sim.report(outcome.clone()), None);
            return Ok((verdict, outcome));
        }
    }
    log(&format!(
        "physics {} Hz, time limit {} s",
        sc.sim.physics_hz, sc.sim.time_limit_s
    ));
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
    if let Some(r) = recording {
        log(&crate::record::describe(&r.finish()));
    }
    // Whatever happened, the controller is asked to finish and its trace collected.
    let trace = controller.as_mut().and_then(|c| {
        let exit = c.finish(Duration::from_secs(5));
        log(&format!("controller finished: {exit:?}"));
        // Written while the controller ran: there even when it was killed.
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
    });
    let (outcome, started_ns) = run?;
    let (lines, last) = wires.gps_input();
    if lines > 0 {
        log(&format!(
            "the controller wrote {lines} lines to the GPS port (last: {last:?})"
        ));
    }
    let mut verdict = Verdict::judge(Mode::Hil, sc, sim.report(outcome.clone()), trace.as_ref());
    verdict.fix_latency = trace.as_ref().and_then(|t| {
        let epoch = sc.sim.epoch.unix_s();
        fix_latency(&t.fix_timing, epoch, started_ns)
    });
    verdict.wires = Some(wires.stats());
    write_results(
        &options.results,
        sc,
        &verdict,
        &sim.trajectory,
        trace.as_ref(),
        config.perception.detection_radius,
    )?;
    Ok((verdict, outcome))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fix_latency_puts_both_sides_on_the_run_clock() {
        // Epoch 2026-05-04T23:59:59Z: the second fix is after midnight UTC.
        let epoch = 1_777_939_199.0;
        let start = 5_000_000_000;
        let timing = |sim_t: f64, read_ms: f64, cmd_ms: f64| FixTiming {
            utc_s: (epoch + sim_t).rem_euclid(DAY_S),
            read_ns: start + ((sim_t * 1e3 + read_ms) * 1e6) as u64,
            command_ns: start + ((sim_t * 1e3 + cmd_ms) * 1e6) as u64,
        };
        let l = fix_latency(
            &[timing(0.5, 20.0, 25.0), timing(1.5, 30.0, 40.0)],
            epoch,
            start,
        )
        .expect("timings");
        assert_eq!(l.fix_to_command.samples, 2);
        assert!((l.fix_to_read.max_ms - 30.0).abs() < 1e-3, "{l:?}");
        assert!((l.fix_to_command.max_ms - 40.0).abs() < 1e-3, "{l:?}");
        assert!(
            (l.read_to_command.p50_ms - 5.0).abs() < 1e-3
                || (l.read_to_command.p50_ms - 10.0).abs() < 1e-3,
            "{l:?}"
        );
        assert!(fix_latency(&[], epoch, start).is_none());
    }
}
