//! Lockstep HIL (`ugv-sim run --lockstep`): the real controller binary on the real
//! wires, on the simulator's time. After each physics step that is a controller tick
//! the simulator publishes the tick on the clock wire and waits for the controller's
//! acknowledgement; its ECUs then read until they have the controller's frames of
//! that tick ([`firmware_bridge::lockstep`], [`firmware_bridge::can::gated`]). The
//! controller takes the same inputs at the same ticks as in SIL, so a run is
//! deterministic and as fast as the two processes go.
//!
//! A controller that stops acknowledging is a fault like any other: once its process
//! has exited, or after [`ACK_TIMEOUT`] of wall time without using the CPU (one that
//! works, a long search in an emulated VM, is waited for longer: [`BUSY_BOUNDS`]; one
//! started separately, of which the simulator knows no process, for [`ACK_TIMEOUT`]),
//! the run goes on in simulated time without it, and the ECUs' watchdogs (on simulated
//! time) take the car to its safe state; the verdict's times are simulated ones.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::can::gated::Gate;
use firmware_bridge::clock::monotonic_ns;
use firmware_bridge::lockstep::{
    ClockAck, ClockError, ClockLeader, ClockTick, PHASE_END, PHASE_START, PHASE_TICK,
};
use ugv_controller::control::COMMAND_PERIOD;

use super::process::ControllerProcess;
use super::{EcuSocket, HilError, Wires, signal_process_fault, stopped_by_signal};
use crate::faults::ProcessFault;
use crate::record::Recording;
use crate::record::tap::SocketTap;
use crate::run::{Outcome, Sim, Snapshot};

/// How long the simulator waits for a tick's acknowledgement before it takes the
/// controller for gone: long, since a controller in a software-emulated VM may take
/// seconds for a search that takes a tenth of that natively.
pub const ACK_TIMEOUT: Duration = Duration::from_secs(60);

/// A controller that has not acknowledged within its bound but used CPU time over it (a
/// long search in an emulated VM, its loop waiting for the plan as in SIL) is waited
/// for over one more bound, this many times at most; one that used none (hung, stopped)
/// is taken for gone.
pub const BUSY_BOUNDS: u32 = 5;

/// How long the simulator waits for the first acknowledgement (a controller started by
/// hand, or one that loads a model first).
pub const FIRST_ACK_TIMEOUT: Duration = Duration::from_secs(120);

/// What came back for a tick.
enum Answer {
    Ack(Box<ClockAck>),
    /// The controller is gone, for this reason.
    Gone(String),
}

/// The clock wire's simulator end, and the ECUs' gate: what the controller said it
/// sent.
#[derive(Debug)]
pub struct Lockstep {
    pub leader: ClockLeader,
    pub gate: Gate,
}

impl Lockstep {
    /// Publish controller tick `tick` with what the wires carried so far, and wait for
    /// its answer.
    fn tick(
        &self,
        tick: u64,
        wires: &Wires,
        controller: Option<&mut ControllerProcess>,
    ) -> Result<Answer, HilError> {
        let message = ClockTick {
            tick,
            nmea_bytes: wires.gps.written(),
            can: self.gate.sent(),
            phase: PHASE_TICK,
        };
        self.leader.publish(message).map_err(clock_err)?;
        let what = format!("tick {tick}");
        self.answer(ACK_TIMEOUT, controller, &what, |l, slice| {
            l.wait_ack(tick, slice)
        })
    }

    /// Ask the controller whether its ports are open, and wait for its answer: what the
    /// wires carry from then on reaches it.
    fn start(&self, controller: Option<&mut ControllerProcess>) -> Result<Answer, HilError> {
        let message = ClockTick {
            phase: PHASE_START,
            ..ClockTick::default()
        };
        self.leader.publish(message).map_err(clock_err)?;
        self.answer(FIRST_ACK_TIMEOUT, controller, "the start", |l, slice| {
            l.wait_start(slice)
        })
    }

    /// The answer `wait` waits for, in slices, while the controller's process lives,
    /// for at most `bound` (more while it works: [`BUSY_BOUNDS`]); `what` names what is
    /// answered.
    fn answer(
        &self,
        bound: Duration,
        mut controller: Option<&mut ControllerProcess>,
        what: &str,
        wait: impl Fn(&ClockLeader, Duration) -> Result<Option<ClockAck>, ClockError>,
    ) -> Result<Answer, HilError> {
        let mut deadline = Instant::now() + bound;
        // The controller's CPU time once the answer is slow to come (read then, not at
        // every tick): whether it works while the simulator waits.
        let mut cpu = None;
        let mut extended = 0;
        loop {
            let slice = Duration::from_millis(50);
            if let Some(ack) = wait(&self.leader, slice).map_err(clock_err)? {
                return Ok(Answer::Ack(Box::new(ack)));
            }
            if let Some(c) = controller.as_deref_mut()
                && let Ok(Some(status)) = c.child.try_wait()
            {
                return Ok(Answer::Gone(format!("the controller exited ({status})")));
            }
            let cpu_now = || controller.as_deref().and_then(ControllerProcess::cpu_ticks);
            let before = *cpu.get_or_insert_with(cpu_now);
            if Instant::now() >= deadline {
                let used = cpu_now();
                let busy = used.is_some() && used > before;
                if busy && extended < BUSY_BOUNDS {
                    (cpu, extended, deadline) = (Some(used), extended + 1, deadline + bound);
                    continue;
                }
                let waited = bound.as_secs() * u64::from(extended + 1);
                return Ok(Answer::Gone(if busy {
                    format!(
                        "the controller did not acknowledge {what} within {waited} s of wall \
                         time, though busy all along (lockstep)"
                    )
                } else {
                    format!(
                        "the controller did not acknowledge {what} within {waited} s of wall \
                         time (lockstep)"
                    )
                }));
            }
        }
    }

    /// Controller tick `tick` out and its answer taken: the ECUs expect the frames it
    /// names. Whether the controller goes on answering.
    fn take_answer(
        &self,
        sim: &mut Sim<EcuSocket>,
        tick: u64,
        wires: &Wires,
        controller: Option<&mut ControllerProcess>,
    ) -> Result<bool, HilError> {
        match self.tick(tick, wires, controller)? {
            Answer::Ack(ack) => {
                self.gate.expect(ack.can);
                if ack.exit == 0 {
                    return Ok(true);
                }
                sim.controller_gone(format!(
                    "the controller's loop ended (exit code {})",
                    ack.exit - 1
                ));
                Ok(false)
            }
            Answer::Gone(why) => {
                sim.controller_gone(why);
                Ok(false)
            }
        }
    }

    /// The run is over: the controller's loop ends.
    fn end(&self, tick: u64) {
        let _ = self.leader.publish(ClockTick {
            tick,
            phase: PHASE_END,
            ..ClockTick::default()
        });
    }
}

fn clock_err(e: ClockError) -> HilError {
    HilError::Clock(e.to_string())
}

/// Step in lockstep with the controller until the run is over, `stop` is raised, or
/// the controller is gone and the car safe. Returns the outcome and the monotonic time
/// of tick 0.
#[allow(clippy::too_many_arguments)] // run_hil's, and the clock wire
pub fn run_lockstep(
    sim: &mut Sim<EcuSocket>,
    wires: &mut Wires,
    lockstep: &Lockstep,
    mut controller: Option<&mut ControllerProcess>,
    stop: &AtomicBool,
    status_every: f64,
    status: &mut dyn FnMut(&Snapshot),
    mut recording: Option<&mut Recording<SocketTap>>,
) -> Result<(Outcome, u64), HilError> {
    let started = monotonic_ns();
    let every = ((status_every / sim.dt()).round() as u64).max(1);
    let control_every = ((COMMAND_PERIOD / sim.dt()).round() as u64).max(1);
    let mut process = ProcessFault::Running;
    let mut answering = match lockstep.start(controller.as_deref_mut())? {
        Answer::Ack(_) => true,
        Answer::Gone(why) => {
            sim.controller_gone(why);
            false
        }
    };
    let outcome = loop {
        if stop.load(Ordering::Relaxed) {
            break stopped_by_signal(sim.time());
        }
        let k = sim.next_tick();
        let now = k as f64 * sim.dt();
        let outcome = sim.step(now, 0.0)?;
        let out = sim.take_outputs();
        if let Some(r) = recording.as_deref_mut() {
            r.sensors(now, &out);
        }
        // The whole epoch at once, as SIL hands it over: the controller reads the
        // bytes the tick says.
        if let Some(epoch) = &out.gps {
            wires.gps.enqueue(epoch);
        }
        wires.gps.pace(f64::MAX)?;
        if let Some(frame) = &out.laser {
            wires.publish(frame)?;
        }
        if k.is_multiple_of(every) {
            status(&sim.snapshot());
        }
        // As in SIL, the controller takes the tick the run ends at.
        // The controller's ticks, and the fault plan's signals at them, as in SIL.
        if answering && k.is_multiple_of(control_every) {
            signal_process_fault(sim, controller.as_deref_mut(), &mut process)?;
            answering = match process {
                ProcessFault::Killed => {
                    sim.controller_gone("the controller was killed".to_owned());
                    false
                }
                // SIGSTOP: it neither reads nor sends until SIGCONT.
                ProcessFault::Stopped => true,
                ProcessFault::Running => lockstep.take_answer(
                    sim,
                    k / control_every,
                    wires,
                    controller.as_deref_mut(),
                )?,
            };
        }
        // The bus after the controller's tick, as SIL records it: the ECUs' frames of
        // this step and the controller's of this tick.
        if let Some(r) = recording.as_deref_mut() {
            r.after_step(now, sim, None);
        }
        if let Some(o) = outcome {
            break o;
        }
    };
    lockstep.end(sim.next_tick() / control_every + 1);
    Ok((outcome, started))
}
