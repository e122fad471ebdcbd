//! `--isolate`: a run's vcan interface, the simulator's CAN sockets and the controller
//! it starts in a private network namespace of their own (`vcan_setup::netns`), so no
//! other process on the machine can open the run's bus, let alone send on it. E2E
//! proves integrity, not origin; isolation takes the other local users off the bus.
//!
//! The namespace is named after the run (`ugv-<run id>`), so one can look in with
//! `sudo ip netns exec NAME candump IFACE`; it is entered by the thread that runs the
//! scenario, before any socket is opened or process started, and left (and its name
//! removed) when the run ends. Needs root. Devices outside the machine's own wires
//! (a physical bus behind a gateway, a laser on Ethernet, a controller on a board)
//! live outside the namespace, so they and isolation exclude each other.

use vcan_setup::netns::NetNs;

use crate::devices::map::{ControllerSite, LaserSource};
use crate::scenario::Scenario;

/// The namespace name for a run.
pub fn netns_name(run_id: &str) -> String {
    vcan_setup::netns::name_for(&format!("ugv-{run_id}"))
}

/// Why a run cannot be isolated, or isolating it failed.
#[derive(Debug, thiserror::Error)]
pub enum IsolateError {
    #[error(
        "--isolate: {what} lives outside the run's private network namespace; isolate only runs whose CAN devices are all simulated"
    )]
    OutsideDevice { what: String },
    #[error("--isolate: {0}")]
    Netns(#[from] vcan_setup::VcanError),
}

/// Refuse device maps that reach outside the machine's own wires.
pub fn check_devices(scenario: &Scenario) -> Result<(), IsolateError> {
    let devices = &scenario.devices;
    let outside = if let Some((bus, nodes)) = devices.physical_buses().first() {
        Some(format!("the physical bus {bus} ({})", nodes.join(", ")))
    } else if let LaserSource::Physical { address } = &devices.laser {
        Some(format!("the physical laser at {address}"))
    } else if let ControllerSite::Board { can } = &devices.controller {
        Some(format!("the controller on its board ({can})"))
    } else {
        None
    };
    match outside {
        Some(what) => Err(IsolateError::OutsideDevice { what }),
        None => Ok(()),
    }
}

/// Move the calling thread into a new network namespace `name` and create the
/// scenario's CAN interface there; the run stays isolated while the returned value
/// lives. `log` is told how to look in.
pub fn enter(
    scenario: &Scenario,
    name: &str,
    log: &mut dyn FnMut(&str),
) -> Result<NetNs, IsolateError> {
    check_devices(scenario)?;
    let ns = NetNs::enter(name)?;
    let iface = &scenario.can.interface;
    ns.add_vcan(iface)?;
    log(&format!(
        "isolated: {iface} exists only in network namespace {name}, with the simulator and the controller; look in with: {} (a controller you start yourself joins the same way)",
        ns.exec_line(&format!("candump {iface}"))
    ));
    Ok(ns)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::map::EcuDevice;

    #[test]
    fn devices_outside_the_machine_exclude_isolation() {
        let mut sc = Scenario::default();
        assert!(check_devices(&sc).is_ok());
        sc.devices.steering = EcuDevice::Physical {
            can: "can0".to_owned(),
        };
        let err = check_devices(&sc).err().map(|e| e.to_string());
        assert!(
            err.as_deref()
                .is_some_and(|e| e.contains("physical bus can0")),
            "{err:?}"
        );
        let mut sc = Scenario::default();
        sc.devices.controller = ControllerSite::Board {
            can: "can1".to_owned(),
        };
        assert!(check_devices(&sc).is_err());
        assert_eq!(netns_name("paper-42"), "ugv-paper-42");
        assert_eq!(netns_name("suite/a b"), "ugv-suite-a-b");
    }
}
