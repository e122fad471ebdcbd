//! SIL: the controller library in-process, in lockstep with the simulator, through
//! the same byte-level codecs as HIL: NMEA text through the NMEA reader, laser frames
//! as the `#[repr(C)]` frame, CAN frames with E2E on the memory bus. Deterministic for
//! a seed, far faster than real time.

use firmware_bridge::can::membus::{MemBus, MemEndpoint};
use firmware_bridge::nmea::ReaderConfig;
use firmware_bridge::{BridgeError, CanPort};
use ugv_controller::config::ControllerConfig;
use ugv_controller::control::{COMMAND_PERIOD, Controller, ControllerError};
use ugv_controller::runtime::{Exit, InputStats, MemGps, MemLaser, Runtime, accept_controller_ids};
use ugv_controller::trace::Trace;

use crate::ecu::EcuKind;
use crate::faults::ProcessFault;
use crate::record::{
    Outputs, RecordError, RecordMode, RecordSummary, Recorder, Recording, run_info,
};
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
    #[error("recording: {0}")]
    Record(#[from] RecordError),
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
    /// How the controller's loop ended, if it did before the run.
    pub controller_exit: Option<Exit>,
    /// What its ports delivered that it could not use.
    pub inputs: InputStats,
    /// The recording, when one was made ([`run_sil_recorded`]).
    pub recording: Option<RecordSummary>,
}

/// The controller as SIL runs it: the library's loop on memory ports.
pub type SilController = Runtime<MemGps, MemLaser, MemEndpoint>;

/// What a [`run_sil_with`] hook lets happen to the controller next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hook {
    Continue,
    /// The controller's process dies here (SIGKILL): it is never stepped again.
    Kill,
}

/// Run `scenario` with the controller configured by `cfg`, in lockstep.
pub fn run_sil(scenario: Scenario, cfg: &ControllerConfig) -> Result<SilRun, SilError> {
    run_sil_with(scenario, cfg, |_, _| Hook::Continue)
}

/// [`run_sil`] with `hook` called before every controller tick with its time and the
/// controller on its ports (to close a port, push bad input, or kill the controller).
pub fn run_sil_with(
    scenario: Scenario,
    cfg: &ControllerConfig,
    hook: impl FnMut(f64, &mut SilController) -> Hook,
) -> Result<SilRun, SilError> {
    run_sil_recorded(scenario, cfg, hook, None)
}

/// [`run_sil_with`], recorded into the directory `record` when given (see
/// [`crate::record`]).
pub fn run_sil_recorded(
    scenario: Scenario,
    cfg: &ControllerConfig,
    hook: impl FnMut(f64, &mut SilController) -> Hook,
    record: Option<&std::path::Path>,
) -> Result<SilRun, SilError> {
    let outputs = Outputs {
        dir: record,
        live: None,
    };
    run_sil_outputs(scenario, cfg, hook, outputs)
}

/// [`run_sil_with`], its topics recorded and/or served live as `outputs` says (see
/// [`crate::record`]). The loop runs as fast as it can: a hook paces it for a viewer.
pub fn run_sil_outputs(
    scenario: Scenario,
    cfg: &ControllerConfig,
    mut hook: impl FnMut(f64, &mut SilController) -> Hook,
    outputs: Outputs<'_>,
) -> Result<SilRun, SilError> {
    if !scenario.devices.all_simulated() {
        return Err(SilError::PhysicalDevice(format!("{:?}", scenario.devices)));
    }
    let bus = match scenario.can.bit_timing {
        true => MemBus::timed(golf_car_can::NETWORK.baudrate),
        false => MemBus::new(),
    };
    // As in HIL (crate::hil::Endpoints::open): the steering ECU's endpoint sees the
    // whole bus for the bus load; the throttle ECU and the controller take only their
    // nodes' IDs.
    let throttle = CanPort::new(bus.endpoint(), "sil");
    throttle.accept_only(&EcuKind::Throttle.accepts())?;
    let mut sim = Sim::new(
        scenario.clone(),
        CanPort::new(bus.endpoint(), "sil"),
        throttle,
    )
    .with_sensors()?;
    let gps = MemGps::new(ReaderConfig {
        complete_when: scenario.gps.sentence_set(),
        ..ReaderConfig::default()
    });
    // The controller on memory ports, run by the same loop as the binary's.
    let can = CanPort::new(bus.endpoint(), "sil");
    accept_controller_ids(&can)?;
    let mut rt = Runtime::new(Controller::new(cfg)?, gps, MemLaser::default(), can);
    let mut rec = match outputs.any() {
        true => {
            let toml = toml::to_string_pretty(cfg).unwrap_or_default();
            let info = run_info(RecordMode::Sil, &scenario, toml);
            Some(Recording::new(
                Recorder::create(outputs, &scenario, info)?,
                bus.endpoint(),
            ))
        }
        false => None,
    };
    let dt = sim.dt();
    let control_every = ((COMMAND_PERIOD / dt).round() as u64).max(1);
    let mut exit = None;
    let mut gone = false;
    let outcome = loop {
        let k = sim.next_tick();
        let now = k as f64 * dt;
        // The wire's time (a bus with bit timing): what finished by now arrives.
        bus.advance_to(now);
        let outcome = sim.step(now, 0.0)?;
        let out = sim.take_outputs();
        if let Some(r) = &mut rec {
            r.sensors(now, &out);
        }
        if let Some(epoch) = out.gps {
            rt.gps_mut().push(epoch.text.as_bytes());
        }
        if let Some(frame) = out.laser {
            rt.laser_mut().push(frame);
        }
        // Once the loop has ended the controller is gone, as its process would be.
        if !gone && k % control_every == 0 {
            let process = sim.process_fault();
            if process == ProcessFault::Killed || hook(now, &mut rt) == Hook::Kill {
                gone = true;
                sim.controller_gone("the controller was killed".to_owned());
            } else if process == ProcessFault::Stopped {
                // SIGSTOP: the process neither reads nor sends until SIGCONT.
            } else if let Some(e) = rt.step(now) {
                gone = true;
                sim.controller_gone(format!("the controller's loop ended ({})", e.describe()));
                exit = Some(e);
            }
            sim.reuse_frame(rt.laser_mut().take_spent());
        }
        if let Some(r) = &mut rec {
            r.after_step(now, &sim, Some(rt.controller()));
        }
        if let Some(o) = outcome {
            break o;
        }
    };
    if let Some(stats) = bus.arbitration() {
        sim.bus_arbitrated(stats);
    }
    let trace = rt.trace(sim.time());
    Ok(SilRun {
        sim,
        outcome,
        trace,
        controller_exit: exit,
        inputs: rt.stats.clone(),
        recording: rec.and_then(Recording::finish),
    })
}
