//! The simulator's ends of the HIL wires: the GPS line (a pty, or a serial device),
//! the laser (an iceoryx2 service, or a CoLa-A server and driver), and the gateways
//! to physical buses, as the scenario's device map places them.

use std::path::{Path, PathBuf};

use firmware_bridge::can::gated::Gate;
use firmware_bridge::can::timed::Horizon;
use firmware_bridge::cola::{ColaServer, DecodeOptions, ServerConfig};
use firmware_bridge::gateway::{Gateway, GatewayConfig, GatewayHandle};
use firmware_bridge::laser::{LaserFrame, LaserPublisher, service_name};
use firmware_bridge::lockstep::{ClockLeader, clock_service_name};

use super::{HilError, Lockstep};
use crate::devices::cola_driver::ColaDriverThread;
use crate::devices::gps::GpsPort;
use crate::devices::laser::LaserProfile;
use crate::devices::map::{ControllerSite, GpsOutput, LaserSource};
use crate::exit::Exit;
use crate::measure::{GpsLineStats, WireStats};
use crate::run::Outcome;
use crate::scenario::Scenario;
use crate::verdict::Verdict;

/// The version of `wires.json`'s layout ([`WireMap`], its first key): raised when a key
/// changes meaning or goes away (docs/wire-contract.md, "Finding the wires"); new keys
/// (`state` and `end`, issue 35) may appear without it.
pub const WIRES_VERSION: u32 = 1;

/// Where the run is: `wires.json`'s `state`, rewritten as the run goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// The wires are open; the simulator starts the controller or waits for its
    /// heartbeat.
    #[default]
    Waiting,
    /// The clock runs.
    Running,
    /// The run is over and judged (`end` says how, `verdict.json` is written); the
    /// wires close next.
    Ended,
}

/// How a run ended: `wires.json`'s `end` once `state` is `ended`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RunEnded {
    /// `goal_reached`, `collision`, `time_limit`, `stopped` (Ctrl-C, the controller
    /// exited), or `error` (the run could not start or go on; `reason` says why).
    pub outcome: String,
    /// The verdict's criteria met (false on an error).
    pub passed: bool,
    pub goal_reached: bool,
    /// Simulated seconds at the end; `null` on an error.
    pub time_s: Option<f64>,
    /// Why it did not pass (the verdict's failures, joined by "; ") or the error;
    /// `null` when it passed.
    pub reason: Option<String>,
    /// The code `ugv-sim run` exits with ([`crate::exit`]).
    pub exit_code: u8,
}

impl RunEnded {
    /// The end of a run that gave `result`.
    pub fn of(result: &Result<(Verdict, Outcome), HilError>) -> RunEnded {
        match result {
            Ok((verdict, outcome)) => RunEnded {
                outcome: serde_json::to_value(outcome)
                    .ok()
                    .and_then(|v| v["outcome"].as_str().map(str::to_owned))
                    .unwrap_or_default(),
                passed: verdict.passed,
                goal_reached: verdict.goal_reached,
                time_s: Some(verdict.time()),
                reason: (!verdict.passed).then(|| verdict.failures.join("; ")),
                exit_code: Exit::of_run(outcome, verdict.passed).code(),
            },
            Err(e) => RunEnded {
                outcome: "error".to_owned(),
                passed: false,
                goal_reached: false,
                time_s: None,
                reason: Some(e.to_string()),
                exit_code: Exit::Setup.code(),
            },
        }
    }
}

/// Where the wires are, for the user and for the controller (`wires.json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct WireMap {
    /// [`WIRES_VERSION`].
    pub version: u32,
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
    /// The clock wire in lockstep (`ugv-hil/<run id>/clock`), `null` in real time.
    pub clock_service: Option<String>,
    /// Where the run is.
    pub state: RunState,
    /// How it ended, once it has (`null` before).
    pub end: Option<RunEnded>,
}

impl WireMap {
    /// The file name in the run's results.
    pub const FILE: &str = "wires.json";

    /// Write the map into `dir` whole or not at all: into a temporary file beside
    /// `wires.json`, renamed over it, so a reader sees the last state or the one
    /// before, never a part.
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        let partial = dir.join(".wires.json.partial");
        std::fs::write(&partial, text)?;
        std::fs::rename(&partial, dir.join(Self::FILE))
    }
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
    pub(super) gps: GpsPort,
    laser: LaserOut,
    driver: Option<ColaDriverThread>,
    gateways: Vec<GatewayHandle>,
    /// Up to when the simulated ECUs' timed sockets hand out frames (set per tick).
    pub(super) can_horizon: Horizon,
    /// The clock wire's simulator end and the ECUs' gate, in lockstep.
    pub(super) lockstep: Option<Lockstep>,
}

impl std::fmt::Debug for Wires {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Wires").field("map", &self.map).finish()
    }
}

/// The file name of the log a run's gateway to `physical` keeps in the results: each
/// frame it forwarded as received and as sent, with the kernel's times, as candump
/// would log the physical bus (see [`firmware_bridge::gateway`]'s log).
pub fn gateway_log(physical: &str) -> String {
    format!("gateway-{physical}.log")
}

/// The laser's end of the wires: where the simulated scans go, the CoLa-A driver
/// that puts a device's scans on the service (when there is one), and how the map
/// names it.
struct OpenLaser {
    out: LaserOut,
    driver: Option<ColaDriverThread>,
    text: String,
}

impl OpenLaser {
    /// The laser of the scenario's device map on `service`: the service itself, a
    /// CoLa-A server (with a driver, when the map asks), or a driver of the physical
    /// scanner.
    fn open(sc: &Scenario, service: &str) -> Result<OpenLaser, HilError> {
        Ok(match &sc.devices.laser {
            LaserSource::Iceoryx2 {} => OpenLaser {
                out: LaserOut::Iceoryx2(
                    LaserPublisher::new(service)
                        .map(Box::new)
                        .map_err(|e| laser_err(service, e.to_string()))?,
                ),
                driver: None,
                text: "iceoryx2".to_owned(),
            },
            LaserSource::Cola { listen, driver } => Self::cola(sc, service, *listen, *driver)?,
            LaserSource::Physical { address } => OpenLaser {
                out: LaserOut::Off,
                driver: Some(
                    ColaDriverThread::spawn(*address, service, DecodeOptions::default()).map_err(
                        |e| laser_err(service, format!("CoLa-A driver to {address}: {e}")),
                    )?,
                ),
                text: format!("physical {address}"),
            },
        })
    }

    /// The simulated scanner served as a CoLa-A device on `listen`, and with
    /// `driver` a driver that puts its scans on `service`.
    fn cola(
        sc: &Scenario,
        service: &str,
        listen: std::net::SocketAddr,
        driver: bool,
    ) -> Result<OpenLaser, HilError> {
        let spec = sc.laser.spec();
        let device = match sc.laser.profile {
            LaserProfile::Lms111 => "LMS111",
            LaserProfile::Lms291 => "LMS291",
        };
        let server = ColaServer::bind(
            listen,
            ServerConfig {
                device_name: device.to_owned(),
                ..ServerConfig::lms111()
            },
        )
        .map_err(|e| laser_err(service, format!("serving CoLa-A on {listen}: {e}")))?;
        let addr = server.local_addr();
        let driver = if driver {
            let decode = DecodeOptions {
                range_min: spec.range_min as f32,
                range_max: spec.range_max as f32,
                ..DecodeOptions::default()
            };
            Some(
                ColaDriverThread::spawn(addr, service, decode)
                    .map_err(|e| laser_err(service, format!("CoLa-A driver to {addr}: {e}")))?,
            )
        } else {
            None
        };
        Ok(OpenLaser {
            out: LaserOut::Cola(server),
            driver,
            text: format!("cola {addr}"),
        })
    }
}

/// An error of the laser service `service`.
fn laser_err(service: &str, message: String) -> HilError {
    HilError::Laser {
        service: service.to_owned(),
        message,
    }
}

/// A gateway from the simulator's bus to each physical bus, logging into
/// `gateway_logs` when given, its threads at `rt_priority`.
fn open_gateways(
    sc: &Scenario,
    buses: &[(String, Vec<&'static str>)],
    gateway_logs: Option<&Path>,
    rt_priority: u8,
) -> Result<Vec<GatewayHandle>, HilError> {
    let mut gateways = Vec::new();
    for (physical, nodes) in buses {
        let config = GatewayConfig {
            sim_iface: sc.can.interface.clone(),
            physical_iface: physical.clone(),
            physical_nodes: nodes.iter().map(|n| (*n).to_owned()).collect(),
            log: gateway_logs.map(|dir| dir.join(gateway_log(physical))),
            rt_priority,
            ..GatewayConfig::default()
        };
        gateways.push(Gateway::spawn(config).map_err(|source| HilError::Gateway {
            sim: sc.can.interface.clone(),
            physical: physical.clone(),
            source,
        })?);
    }
    Ok(gateways)
}

impl Wires {
    /// Open the wires of the scenario's device map: the GPS pty behind `gps_link` (or
    /// the serial device), the laser service of `run_id` (directly, or behind a CoLa-A
    /// server and driver), and a gateway to each physical bus. `can_horizon` is the
    /// horizon of the ECUs' timed sockets, which the run sets at each tick. With
    /// `gateway_logs` (a recorded run's results), each gateway logs the frames it
    /// forwards there, in `candump -l -x` form ([`gateway_log`]). The gateways'
    /// threads run at the run's `rt_priority`, as its tick loop does.
    pub fn open(
        sc: &Scenario,
        gps_link: &Path,
        run_id: &str,
        can_horizon: Horizon,
        gateway_logs: Option<&Path>,
        rt_priority: u8,
        gate: Option<Gate>,
    ) -> Result<Wires, HilError> {
        let devices = &sc.devices;
        let lockstep = match gate {
            Some(gate) => Some(Lockstep {
                leader: ClockLeader::new(&clock_service_name(run_id))
                    .map_err(|e| HilError::Clock(e.to_string()))?,
                gate,
            }),
            None => None,
        };
        let (gps, gps_line) = match &devices.gps {
            GpsOutput::Pty {} => (GpsPort::open(Some(gps_link), sc.gps.baud)?, "pty"),
            GpsOutput::Serial { device, baud, .. } => (
                GpsPort::serial(device, baud.unwrap_or(sc.gps.baud))?,
                "serial",
            ),
        };
        let service = service_name(run_id);
        let laser = OpenLaser::open(sc, &service)?;
        let buses = devices.physical_buses();
        let gateways = open_gateways(sc, &buses, gateway_logs, rt_priority)?;
        Ok(Wires {
            map: WireMap {
                version: WIRES_VERSION,
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
                laser: laser.text,
                can: sc.can.interface.clone(),
                gateways: buses,
                controller: match &devices.controller {
                    ControllerSite::Local {} => "local".to_owned(),
                    ControllerSite::Board { can } => format!("board on {can}"),
                },
                clock_service: lockstep.as_ref().map(|l| l.leader.service().to_owned()),
                state: RunState::Waiting,
                end: None,
            },
            gps,
            laser: laser.out,
            driver: laser.driver,
            gateways,
            can_horizon,
            lockstep,
        })
    }

    /// Lines the controller wrote to the GPS port (GGA for NTRIP, configuration).
    pub fn gps_input(&self) -> (u64, Option<String>) {
        let log = self.gps.input();
        (log.count(), log.last().map(str::to_owned))
    }

    /// Put a scan on its way.
    pub(super) fn publish(&mut self, frame: &LaserFrame) -> Result<(), HilError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> WireMap {
        WireMap {
            version: WIRES_VERSION,
            gps_link: PathBuf::from("/tmp/ugv-hil-x-gps"),
            gps_baud: 115_200,
            gps_line: "pty",
            laser_service: "ugv-hil/x/laser".to_owned(),
            laser: "iceoryx2".to_owned(),
            can: "vcan0".to_owned(),
            gateways: vec![("can1".to_owned(), vec!["STEERING_ECU"])],
            controller: "local".to_owned(),
            clock_service: None,
            state: RunState::Waiting,
            end: None,
        }
    }

    #[test]
    fn wires_json_starts_with_its_version_and_has_the_documented_keys()
    -> Result<(), serde_json::Error> {
        let json = serde_json::to_string(&map())?;
        assert!(json.starts_with("{\"version\":1,"), "{json}");
        let value: serde_json::Value = serde_json::from_str(&json)?;
        let mut keys: Vec<&str> = value
            .as_object()
            .map(|o| o.keys().map(String::as_str).collect())
            .unwrap_or_default();
        keys.sort_unstable();
        // docs/wire-contract.md's table.
        let mut documented = vec![
            "version",
            "gps_link",
            "gps_baud",
            "gps_line",
            "laser_service",
            "laser",
            "can",
            "gateways",
            "controller",
            "clock_service",
            "state",
            "end",
        ];
        documented.sort_unstable();
        assert_eq!(keys, documented);
        assert_eq!(
            value["gateways"],
            serde_json::json!([["can1", ["STEERING_ECU"]]])
        );
        Ok(())
    }

    /// `dir/wires.json` as JSON.
    fn read(dir: &Path) -> Result<serde_json::Value, Box<dyn std::error::Error>> {
        Ok(serde_json::from_str(&std::fs::read_to_string(
            dir.join(WireMap::FILE),
        )?)?)
    }

    #[test]
    fn wires_json_is_rewritten_whole_and_ends_saying_how_the_run_ended()
    -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let mut map = map();
        map.write(dir.path())?;
        let v = read(dir.path())?;
        assert_eq!(
            (&v["state"], &v["end"]),
            (&"waiting".into(), &serde_json::Value::Null)
        );
        map.state = RunState::Running;
        map.write(dir.path())?;
        assert_eq!(read(dir.path())?["state"], "running");

        // A run that reached its time limit, as the HIL run judges it.
        let sc = Scenario::paper()?;
        let bus = firmware_bridge::can::membus::MemBus::new();
        let port = || firmware_bridge::CanPort::new(bus.endpoint(), "mem");
        let sim = crate::run::Sim::new(sc.clone(), port(), port());
        let outcome = Outcome::TimeLimit { time: 60.0 };
        let verdict = Verdict::judge(crate::Mode::Hil, &sc, sim.report(outcome.clone()), None);
        map.state = RunState::Ended;
        map.end = Some(RunEnded::of(&Ok((verdict, outcome))));
        map.write(dir.path())?;
        let v = read(dir.path())?;
        assert_eq!(v["state"], "ended");
        let end = &v["end"];
        assert_eq!(
            (&end["outcome"], &end["passed"], &end["goal_reached"]),
            (&"time_limit".into(), &false.into(), &false.into()),
            "{v}"
        );
        assert_eq!(
            (&end["time_s"], &end["exit_code"]),
            (&60.0.into(), &5.into())
        );
        assert!(
            end["reason"]
                .as_str()
                .is_some_and(|r| r.contains("goal not reached")),
            "{end}"
        );
        // Renamed into place: nothing else is left in the folder.
        let names: Vec<_> = std::fs::read_dir(dir.path())?
            .map(|e| e.map(|e| e.file_name()))
            .collect::<Result<_, _>>()?;
        assert_eq!(names, vec![std::ffi::OsString::from(WireMap::FILE)]);

        // A run that could not go on.
        let end = RunEnded::of(&Err(HilError::Clock("the clock wire broke".to_owned())));
        assert_eq!(
            (end.outcome.as_str(), end.passed, end.time_s, end.exit_code),
            ("error", false, None, 4)
        );
        assert!(
            end.reason
                .is_some_and(|r| r.contains("the clock wire broke"))
        );
        Ok(())
    }
}
