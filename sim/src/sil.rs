//! SIL: the controller library in-process, in lockstep with the simulator, through
//! the same byte-level codecs as HIL: NMEA text through the NMEA reader, laser frames
//! as the `#[repr(C)]` frame, CAN frames with E2E on the memory bus. Deterministic for
//! a seed, far faster than real time.

use firmware_bridge::can::membus::{MemBus, MemEndpoint};
use firmware_bridge::nmea::{NmeaReader, ReadEvent, ReaderConfig};
use firmware_bridge::{BridgeError, CanPort};
use ugv_controller::config::ControllerConfig;
use ugv_controller::core::{COMMAND_PERIOD, Controller, ControllerError, scan_of};
use ugv_controller::trace::Trace;

use crate::run::{Outcome, Sim, SimError};
use crate::scenario::Scenario;

/// Why a SIL run could not go on.
#[derive(Debug, thiserror::Error)]
pub enum SilError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("controller: {0}")]
    Controller(#[from] ControllerError),
    #[error("controller CAN: {0}")]
    Bus(#[from] BridgeError),
    #[error(
        "SIL plays every device in-process, but the device map puts {0} outside (run it in HIL, without --sil)"
    )]
    PhysicalDevice(String),
}

/// A finished SIL run.
#[derive(Debug)]
pub struct SilRun {
    pub sim: Sim<MemEndpoint>,
    pub outcome: Outcome,
    pub trace: Trace,
}

/// Run `scenario` with the controller configured by `cfg`, in lockstep.
pub fn run_sil(scenario: Scenario, cfg: &ControllerConfig) -> Result<SilRun, SilError> {
    if !scenario.devices.all_simulated() {
        return Err(SilError::PhysicalDevice(format!("{:?}", scenario.devices)));
    }
    let bus = MemBus::new();
    let mut sim = Sim::new(
        scenario.clone(),
        CanPort::new(bus.endpoint(), "sil"),
        CanPort::new(bus.endpoint(), "sil"),
    )
    .with_sensors()?;
    let mut ctl_port = CanPort::new(bus.endpoint(), "sil");
    let mut ctl = Controller::new(cfg)?;
    let mut reader = NmeaReader::new(ReaderConfig {
        complete_when: scenario.gps.sentence_set(),
        ..ReaderConfig::default()
    });
    let dt = sim.dt();
    let control_every = ((COMMAND_PERIOD / dt).round() as u64).max(1);
    let outcome = loop {
        let k = sim.next_tick();
        let now = k as f64 * dt;
        let outcome = sim.step(now, 0.0)?;
        let out = sim.take_outputs();
        if let Some(epoch) = out.gps {
            for event in reader.feed(epoch.text.as_bytes()) {
                if let ReadEvent::Fix(r) = event {
                    ctl.on_gps(now, &r);
                }
            }
        }
        if let Some(frame) = out.laser {
            ctl.on_scan(now, &scan_of(&frame, now));
        }
        if k % control_every == 0 {
            while let Some(r) = ctl_port.try_recv() {
                ctl.on_can(now, &r);
            }
            for m in ctl.tick(now) {
                ctl_port.send_message(&m)?;
            }
        }
        if let Some(o) = outcome {
            break o;
        }
    };
    let trace = Trace::of(&ctl, sim.time());
    Ok(SilRun {
        sim,
        outcome,
        trace,
    })
}
