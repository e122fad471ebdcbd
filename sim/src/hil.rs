//! HIL: the simulator on the real wires in real time — NMEA on a pty paced at the
//! baud rate, laser frames over iceoryx2, the simulated ECUs on SocketCAN — with the
//! controller as a separate process: started here (`--controller BINARY`) or by the
//! user.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::clock::{Clock, WallClock};
use firmware_bridge::laser::{LaserPublisher, service_name};
use firmware_bridge::{BridgeError, CanPort, Received};
use golf_car_can::GolfCarMessage;
use socketcan::CanSocket;

use crate::devices::gps::{GpsError, GpsPort};
use crate::run::{Outcome, Sim, SimError, Snapshot};

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
}

/// Where the wires are, for the user and for the controller.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WireMap {
    pub gps_link: PathBuf,
    pub gps_baud: u32,
    pub laser_service: String,
    pub can: String,
}

/// The simulator's ends of the sensor wires.
pub struct Wires {
    pub map: WireMap,
    gps: GpsPort,
    laser: LaserPublisher,
}

impl std::fmt::Debug for Wires {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Wires").field("map", &self.map).finish()
    }
}

impl Wires {
    /// Open the GPS pty behind `gps_link` and the laser service of `run_id`.
    pub fn open(sim: &Sim<CanSocket>, gps_link: &Path, run_id: &str) -> Result<Wires, HilError> {
        let baud = sim.scenario.gps.baud;
        let gps = GpsPort::open(Some(gps_link), baud)?;
        let service = service_name(run_id);
        let laser = LaserPublisher::new(&service).map_err(|e| HilError::Laser {
            service: service.clone(),
            message: e.to_string(),
        })?;
        Ok(Wires {
            map: WireMap {
                gps_link: gps.path().to_path_buf(),
                gps_baud: baud,
                laser_service: service,
                can: sim.scenario.can.interface.clone(),
            },
            gps,
            laser,
        })
    }

    /// Lines the controller wrote to the GPS port (GGA for NTRIP, configuration).
    pub fn gps_input(&self) -> (u64, Option<String>) {
        let log = self.gps.input();
        (log.count(), log.last().map(str::to_owned))
    }
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
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid),
                nix::sys::signal::Signal::SIGINT,
            );
        }
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
}

/// Step in real time on absolute deadlines, the sensors' output on the wires, until
/// the run is over, `stop` is raised, or the controller exits.
pub fn run_hil(
    sim: &mut Sim<CanSocket>,
    wires: &mut Wires,
    mut controller: Option<&mut ControllerProcess>,
    stop: &AtomicBool,
    status_every: f64,
    status: &mut dyn FnMut(&Snapshot),
) -> Result<Outcome, HilError> {
    let mut clock = WallClock::new(sim.dt());
    let every = ((status_every / sim.dt()).round() as u64).max(1);
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(Outcome::Stopped {
                time: sim.time(),
                reason: "stopped by signal".to_owned(),
            });
        }
        let k = sim.next_tick();
        let late = clock.wait_tick(k);
        let now = k as f64 * sim.dt();
        let outcome = sim.step(clock.now(), late)?;
        let out = sim.take_outputs();
        if let Some(epoch) = &out.gps {
            wires.gps.enqueue(epoch);
        }
        wires.gps.pace(now)?;
        if let Some(frame) = &out.laser {
            wires.laser.publish(frame).map_err(|e| HilError::Laser {
                service: wires.map.laser_service.clone(),
                message: e.to_string(),
            })?;
        }
        if k % every == 0 {
            status(&sim.snapshot());
        }
        if let Some(o) = outcome {
            return Ok(o);
        }
        if k % 20 == 0 {
            if let Some(c) = controller.as_deref_mut() {
                if let Ok(Some(exit)) = c.child.try_wait() {
                    return Ok(Outcome::Stopped {
                        time: sim.time(),
                        reason: format!("the controller exited ({exit})"),
                    });
                }
            }
        }
    }
}
