//! The device map: for each device of the golf car — the steering ECU, the throttle
//! ECU, the GPS, the laser and the controller — whether the simulator plays it or a
//! physical one is in the loop, and where the physical one is.
//!
//! It sits in the scenario's `[devices]` section, or in a bench file of its own
//! (`ugv-sim run --devices bench.toml`, the same `[devices]` section alone) so one
//! bench setup runs every scenario. Nothing of it reaches the controller: it sees the
//! same wires either way.
//!
//! ```toml
//! [devices]
//! steering = { mode = "physical", can = "can0" }        # the real steering ECU on can0
//! throttle = { mode = "simulated" }                     # the default
//! gps = { mode = "serial", device = "/dev/ttyUSB0", baud = 115200, peer = "/dev/ttyUSB1" }
//! laser = { mode = "cola", listen = "127.0.0.1:2111" }   # served as a SICK over TCP
//! controller = { mode = "board", can = "can0" }          # the controller on its own board
//! ```

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use ugv_fields::{FieldError, FieldPath, parse_toml, read_file};

use crate::ecu::EcuKind;
use crate::scenario::fields::ScenarioError;

/// An actuator ECU: played by the simulator on its bus, or a physical ECU on a
/// physical SocketCAN interface that the gateway joins to the simulator's bus. With a
/// physical ECU the simulated vehicle moves by that ECU's reports and the simulated
/// twin stays silent.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum EcuDevice {
    Simulated {},
    Physical {
        /// The physical bus the ECU is on (can0, a USB adapter, vcan1 on a bench).
        can: String,
    },
}

impl Default for EcuDevice {
    fn default() -> Self {
        EcuDevice::Simulated {}
    }
}

/// Where the controller runs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControllerSite {
    /// A process on this machine on the simulator's bus: started by the simulator
    /// (`--controller`) or by the user (`--wait-for-controller`).
    Local {},
    /// On its own board on a physical bus: the gateway joins that bus to the
    /// simulator's; the simulator waits for the board's heartbeat. The GPS must then
    /// go out on a serial port.
    Board { can: String },
}

impl Default for ControllerSite {
    fn default() -> Self {
        ControllerSite::Local {}
    }
}

/// The simulated GPS receiver's output line.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum GpsOutput {
    /// A pseudo-terminal behind a link path (`--gps-link`).
    Pty {},
    /// A physical serial device (a USB-serial adapter wired to the controller's board).
    Serial {
        device: PathBuf,
        /// Line rate; the scenario's `gps.baud` when absent.
        baud: Option<u32>,
        /// The device a controller on this machine opens: the far end of the cable
        /// (needed when the simulator starts the controller).
        peer: Option<PathBuf>,
    },
}

impl Default for GpsOutput {
    fn default() -> Self {
        GpsOutput::Pty {}
    }
}

/// The laser scanner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum LaserSource {
    /// The simulated scans go straight onto the run's iceoryx2 service.
    Iceoryx2 {},
    /// The simulated laser is served as a SICK CoLa-A device on TCP at `listen`
    /// (default `127.0.0.1:2111`, loopback only: give an interface's own address to
    /// serve a driver on another machine, on a network you trust); with `driver` (the
    /// default) the simulator also runs the CoLa-A driver that puts the scans on the
    /// run's iceoryx2 service, as `ugv-sick` does for a real scanner, and holds the
    /// scanner's one login. Without it, bring your own SICK driver.
    Cola {
        #[serde(default = "loopback_sick")]
        listen: SocketAddr,
        #[serde(default = "yes")]
        driver: bool,
    },
    /// A physical SICK LMS1xx/5xx at `address`: the simulator makes no scans and runs
    /// the CoLa-A driver against the scanner.
    Physical { address: SocketAddr },
}

impl Default for LaserSource {
    fn default() -> Self {
        LaserSource::Iceoryx2 {}
    }
}

fn yes() -> bool {
    true
}

fn loopback_sick() -> SocketAddr {
    firmware_bridge::cola::DEFAULT_LISTEN
}

/// The device map of a run.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DeviceMap {
    pub steering: EcuDevice,
    pub throttle: EcuDevice,
    pub gps: GpsOutput,
    pub laser: LaserSource,
    pub controller: ControllerSite,
}

fn interface_ok(name: &str) -> bool {
    !name.is_empty() && name.len() <= 15 && !name.contains(['/', ' ', '\0'])
}

/// A bench file: the `[devices]` section alone.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BenchFile {
    devices: DeviceMap,
}

impl DeviceMap {
    /// Check the map against itself and the simulator's bus `sim_can`; the error's
    /// path is below `devices`.
    pub fn validate(&self, sim_can: &str) -> Result<(), FieldError> {
        let err = |device, field, message: String| {
            FieldError::new(FieldPath::of(&[device, field]), message)
        };
        for (device, can) in self.physical_can() {
            if !interface_ok(can) {
                return Err(err(
                    device,
                    "can",
                    format!("{can:?} is not an interface name (1 to 15 characters, no '/')"),
                ));
            }
            if can == sim_can {
                return Err(err(
                    device,
                    "can",
                    format!(
                        "{can} is the simulator's own bus (can.interface): a physical device needs a bus of its own that the gateway joins to it"
                    ),
                ));
            }
        }
        if let GpsOutput::Serial { device, baud, .. } = &self.gps {
            if device.as_os_str().is_empty() {
                return Err(err("gps", "device", "must name a serial device".to_owned()));
            }
            if let Some(b) = baud
                && !(300..=4_000_000).contains(b)
            {
                return Err(err("gps", "baud", format!("{b} is outside 300..4000000")));
            }
        }
        if matches!(self.controller, ControllerSite::Board { .. })
            && matches!(self.gps, GpsOutput::Pty {})
        {
            return Err(err(
                "gps",
                "mode",
                "the controller on its own board cannot open this machine's pty: put the GPS on a serial port (mode = \"serial\")".to_owned(),
            ));
        }
        Ok(())
    }

    /// The devices on physical buses: (device name, interface).
    pub fn physical_can(&self) -> Vec<(&'static str, &str)> {
        let mut out = Vec::new();
        if let EcuDevice::Physical { can } = &self.steering {
            out.push(("steering", can.as_str()));
        }
        if let EcuDevice::Physical { can } = &self.throttle {
            out.push(("throttle", can.as_str()));
        }
        if let ControllerSite::Board { can } = &self.controller {
            out.push(("controller", can.as_str()));
        }
        out
    }

    /// The DBC nodes on each physical bus, one entry per bus (one gateway each).
    pub fn physical_buses(&self) -> Vec<(String, Vec<&'static str>)> {
        let mut buses: Vec<(String, Vec<&'static str>)> = Vec::new();
        for (device, can) in self.physical_can() {
            let node = match device {
                "steering" => EcuKind::Steering.node(),
                "throttle" => EcuKind::Throttle.node(),
                _ => ugv_controller::runtime::NODE,
            };
            match buses.iter_mut().find(|(bus, _)| bus == can) {
                Some((_, nodes)) => nodes.push(node),
                None => buses.push((can.to_owned(), vec![node])),
            }
        }
        buses
    }

    /// Whether every device is played by the simulator (the only map SIL accepts,
    /// the controller aside).
    pub fn all_simulated(&self) -> bool {
        self.steering == EcuDevice::Simulated {}
            && self.throttle == EcuDevice::Simulated {}
            && self.gps == GpsOutput::Pty {}
            && self.laser == LaserSource::Iceoryx2 {}
            && self.controller == ControllerSite::Local {}
    }

    /// Read a bench file (`[devices]` alone), checked against the simulator's bus.
    pub fn load(path: &Path, sim_can: &str) -> Result<DeviceMap, ScenarioError> {
        let file = path.display().to_string();
        let text = read_file(path)?;
        let bench: BenchFile = parse_toml(&text, &file)?;
        bench
            .devices
            .validate(sim_can)
            .map_err(|e| e.under(&FieldPath::of(&["devices"])).located(&text, &file))?;
        Ok(bench.devices)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DeviceMap, String> {
        toml::from_str::<BenchFile>(text)
            .map(|b| b.devices)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn an_empty_section_simulates_everything() {
        let map = parse("[devices]\n").unwrap();
        assert!(map.all_simulated());
        assert!(map.physical_buses().is_empty());
        assert_eq!(map.validate("vcan0"), Ok(()));
    }

    #[test]
    fn every_mode_parses() {
        let map = parse(
            r#"[devices]
steering = { mode = "physical", can = "can0" }
throttle = { mode = "physical", can = "can1" }
gps = { mode = "serial", device = "/dev/ttyUSB0", baud = 115200 }
laser = { mode = "cola", listen = "127.0.0.1:2111" }
controller = { mode = "board", can = "can0" }
"#,
        )
        .unwrap();
        assert_eq!(map.steering, EcuDevice::Physical { can: "can0".into() });
        assert_eq!(
            map.laser,
            LaserSource::Cola {
                listen: "127.0.0.1:2111".parse().unwrap(),
                driver: true
            }
        );
        assert_eq!(map.validate("vcan0"), Ok(()));
        assert!(!map.all_simulated());
        assert_eq!(
            map.physical_buses(),
            vec![
                ("can0".to_owned(), vec!["STEERING_ECU", "CONTROLLER"]),
                ("can1".to_owned(), vec!["THROTTLE_ECU"]),
            ]
        );
        let physical =
            parse("[devices]\nlaser = { mode = \"physical\", address = \"192.168.0.1:2111\" }\n")
                .unwrap();
        assert!(matches!(physical.laser, LaserSource::Physical { .. }));
    }

    #[test]
    fn the_cola_laser_listens_on_loopback_by_default() {
        let map = parse("[devices]\nlaser = { mode = \"cola\" }\n").unwrap();
        assert_eq!(
            map.laser,
            LaserSource::Cola {
                listen: "127.0.0.1:2111".parse().unwrap(),
                driver: true
            }
        );
    }

    #[test]
    fn mistakes_are_named() {
        let unknown_mode = parse("[devices]\nsteering = { mode = \"real\" }\n").unwrap_err();
        assert!(unknown_mode.contains("real"), "{unknown_mode}");
        let missing = parse("[devices]\nsteering = { mode = \"physical\" }\n").unwrap_err();
        assert!(missing.contains("can"), "{missing}");
        let extra =
            parse("[devices]\nthrottle = { mode = \"simulated\", can = \"can0\" }\n").unwrap_err();
        assert!(extra.contains("can"), "{extra}");
        let address =
            parse("[devices]\nlaser = { mode = \"cola\", listen = \"localhost\" }\n").unwrap_err();
        assert!(
            address.contains("listen") || address.contains("address"),
            "{address}"
        );
    }

    #[test]
    fn inconsistent_maps_are_refused() {
        let own_bus = DeviceMap {
            steering: EcuDevice::Physical {
                can: "vcan0".into(),
            },
            ..DeviceMap::default()
        };
        let e = own_bus.validate("vcan0").unwrap_err();
        assert_eq!(e.path.to_string(), "steering.can");
        assert!(e.message.contains("own bus"), "{}", e.message);

        let long = DeviceMap {
            throttle: EcuDevice::Physical {
                can: "a-very-long-interface".into(),
            },
            ..DeviceMap::default()
        };
        assert_eq!(
            long.validate("vcan0").unwrap_err().path.to_string(),
            "throttle.can"
        );

        let board_on_pty = DeviceMap {
            controller: ControllerSite::Board { can: "can0".into() },
            ..DeviceMap::default()
        };
        let e = board_on_pty.validate("vcan0").unwrap_err();
        assert_eq!(e.path.to_string(), "gps.mode");

        let slow = DeviceMap {
            gps: GpsOutput::Serial {
                device: "/dev/ttyUSB0".into(),
                baud: Some(12),
                peer: None,
            },
            ..DeviceMap::default()
        };
        assert_eq!(
            slow.validate("vcan0").unwrap_err().path.to_string(),
            "gps.baud"
        );
    }

    #[test]
    fn a_bench_file_error_names_file_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bench.toml");
        std::fs::write(
            &path,
            "# bench\n[devices]\nthrottle = { mode = \"simulated\" }\nsteering = { mode = \"physical\", can = \"vcan0\" }\n",
        )
        .unwrap();
        let e = DeviceMap::load(&path, "vcan0").unwrap_err().to_string();
        assert!(e.contains("bench.toml:4: devices.steering.can"), "{e}");
        std::fs::write(&path, "[devices]\nsteering = 3\n").unwrap();
        let e = DeviceMap::load(&path, "vcan0").unwrap_err().to_string();
        assert!(e.contains("bench.toml") && e.contains("steering"), "{e}");
        let missing = DeviceMap::load(&dir.path().join("none.toml"), "vcan0").unwrap_err();
        assert!(missing.to_string().contains("none.toml"));
    }
}
