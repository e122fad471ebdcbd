//! The controller binary in lockstep with a simulator (`ugv-controller run --lockstep
//! SERVICE`): its loop runs on the simulator's ticks ([`SimClock`], through the loop's
//! clock abstraction), each tick's inputs are all in before the tick is taken (the GPS
//! line's bytes: [`GatedGps`]; the CAN frames: firmware-bridge's
//! [`Gated`](firmware_bridge::can::gated::Gated) endpoint), and each tick is
//! acknowledged once its frames are sent. The wire itself: [`firmware_bridge::lockstep`].
//!
//! The simulator ends the loop when it ends the run ([`Exit::RunOver`]
//! (crate::runtime::Exit::RunOver), after the same ticks as SIL's). One that stops
//! ticking (it died, or hangs) leaves the loop on the wall clock from there on, so that
//! it winds down as any controller that lost its simulator does (its ports close, it
//! estops and ends).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::can::gated::Gate;
use firmware_bridge::clock::Clock;
use firmware_bridge::lockstep::{
    ClockAck, ClockError, ClockFollower, ClockTick, PHASE_START, PHASE_TICK,
};
use firmware_bridge::nmea::ReadEvent;

use crate::control::COMMAND_PERIOD;
use crate::runtime::{GpsInput, InputError};

/// How long the loop waits for the simulator's next tick before it takes the
/// simulator for gone. Generous: a simulator in a software-emulated VM stalls for
/// seconds now and then.
pub const TICK_TIMEOUT: Duration = Duration::from_secs(30);

/// How long the loop waits for the first tick: the simulator may start its clock well
/// after the controller started (a controller started by hand).
pub const FIRST_TICK_TIMEOUT: Duration = Duration::from_secs(120);

/// How long a tick's GPS bytes may take to come through the line.
const BYTES_TIMEOUT: Duration = Duration::from_secs(2);

/// The simulator's ticks as the loop's clock.
pub struct SimClock {
    follower: ClockFollower,
    /// What the simulator said it sent on the CAN bus, for the CAN port.
    gate: Gate,
    /// What the simulator said it wrote to the GPS line, for the GPS port.
    nmea_bytes: Arc<AtomicU64>,
    /// The tick taken and not yet acknowledged.
    pending: Option<u64>,
    started: bool,
    now: f64,
    /// Since the simulator stopped ticking: the wall clock from (then, tick).
    lost: Option<(Instant, u64)>,
    /// The simulator ended the run.
    ended: bool,
}

impl std::fmt::Debug for SimClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimClock")
            .field("service", &self.follower.service())
            .field("now", &self.now)
            .finish()
    }
}

impl SimClock {
    /// Follow the simulator's clock service `service`.
    pub fn open(service: &str) -> Result<SimClock, ClockError> {
        Ok(SimClock {
            follower: ClockFollower::new(service)?,
            gate: Gate::new(),
            nmea_bytes: Arc::new(AtomicU64::new(0)),
            pending: None,
            started: false,
            now: 0.0,
            lost: None,
            ended: false,
        })
    }

    /// The gate of the CAN port (see firmware_bridge::can::gated).
    pub fn can_gate(&self) -> Gate {
        self.gate.clone()
    }

    /// The GPS port in lockstep with this clock.
    pub fn gate_gps<G: GpsInput>(&self, gps: G) -> GatedGps<G> {
        GatedGps::new(gps, Some(Arc::clone(&self.nmea_bytes)))
    }

    /// Acknowledge the tick taken: its frames are sent. The loop does it when it asks
    /// for the next tick.
    fn acknowledge(&mut self) {
        self.acknowledge_with(0);
    }

    /// Acknowledge the loop's last tick: it ended with exit code `code`.
    pub fn acknowledge_end(&mut self, code: u8) {
        self.acknowledge_with(u64::from(code) + 1);
    }

    fn acknowledge_with(&mut self, exit: u64) {
        if let Some(tick) = self.pending.take() {
            let ack = ClockAck {
                tick,
                can: self.gate.sent(),
                exit,
                start: 0,
            };
            if let Err(e) = self.follower.ack(ack) {
                eprintln!("ugv-controller: lockstep: {e}");
            }
        }
    }

    /// The wall clock's tick `k`, the simulator gone since tick `from` at `at`.
    fn wall_tick(at: Instant, from: u64, k: u64) -> f64 {
        let due = at + Duration::from_secs_f64(k.saturating_sub(from) as f64 * COMMAND_PERIOD);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        Instant::now().saturating_duration_since(due).as_secs_f64()
    }
}

impl Clock for SimClock {
    fn now(&self) -> f64 {
        self.now
    }

    fn ended(&self) -> bool {
        self.ended
    }

    /// The simulator's tick `k`, or a later one (a controller stopped meanwhile): then
    /// it is that many ticks late, and the loop skips them.
    fn wait_tick(&mut self, k: u64) -> f64 {
        self.acknowledge();
        loop {
            if let Some((at, from)) = self.lost {
                return SimClock::wall_tick(at, from, k);
            }
            let timeout = if self.started {
                TICK_TIMEOUT
            } else {
                FIRST_TICK_TIMEOUT
            };
            let tick = match self.follower.wait_tick(k, timeout) {
                Ok(Some(tick)) => tick,
                Ok(None) | Err(_) => {
                    self.lose(k, &format!("no tick {k} within {} s", timeout.as_secs()));
                    continue;
                }
            };
            match tick.phase {
                PHASE_TICK => return self.take(k, &tick),
                PHASE_START => self.answer_start(k),
                _ => {
                    self.ended = true;
                    return 0.0;
                }
            }
        }
    }
}

impl SimClock {
    /// The simulator asks whether the ports are open: they are (the loop asks for its
    /// first tick only then).
    fn answer_start(&mut self, k: u64) {
        let ack = ClockAck {
            start: 1,
            ..ClockAck::default()
        };
        match self.follower.ack(ack) {
            Ok(()) => self.started = true,
            Err(e) => self.lose(k, &e.to_string()),
        }
    }

    /// Tick `tick` taken as the loop's tick `k`: what it carried is expected at the
    /// ports; returns how late it is.
    fn take(&mut self, k: u64, tick: &ClockTick) -> f64 {
        self.started = true;
        self.gate.expect(tick.can);
        self.nmea_bytes.store(tick.nmea_bytes, Ordering::Relaxed);
        self.pending = Some(tick.tick);
        self.now = tick.tick as f64 * COMMAND_PERIOD;
        // Half a period more, so the loop's floor counts the ticks skipped.
        match tick.tick > k {
            true => ((tick.tick - k) as f64 + 0.5) * COMMAND_PERIOD,
            false => 0.0,
        }
    }

    /// The simulator's clock is gone (`why`): the wall clock from tick `k` on.
    fn lose(&mut self, k: u64, why: &str) {
        eprintln!(
            "ugv-controller: lockstep on {}: {why}: the wall clock from here on",
            self.follower.service()
        );
        self.lost = Some((Instant::now(), k));
    }
}

/// A GPS port that, in lockstep, reads until it has every byte the simulator said it
/// wrote (bounded in wall time); without, the port as it is.
#[derive(Debug)]
pub struct GatedGps<G> {
    inner: G,
    expected: Option<Arc<AtomicU64>>,
    /// Bytes read since the start, and given up on.
    got: u64,
    waived: u64,
    /// What the last poll read, all of it.
    last: Vec<u8>,
}

impl<G: GpsInput> GatedGps<G> {
    pub fn new(inner: G, expected: Option<Arc<AtomicU64>>) -> GatedGps<G> {
        GatedGps {
            inner,
            expected,
            got: 0,
            waived: 0,
            last: Vec::new(),
        }
    }

    /// One poll of the port, its bytes kept.
    fn take(&mut self, events: &mut Vec<ReadEvent>) -> Result<(), InputError> {
        events.extend(self.inner.poll()?);
        let read = self.inner.last_read();
        self.got += read.len() as u64;
        self.last.extend_from_slice(read);
        Ok(())
    }

    /// Bytes still to come.
    fn short(&self) -> u64 {
        self.expected.as_ref().map_or(0, |e| {
            e.load(Ordering::Relaxed)
                .saturating_sub(self.got + self.waived)
        })
    }
}

impl<G: GpsInput> GpsInput for GatedGps<G> {
    fn poll(&mut self) -> Result<Vec<ReadEvent>, InputError> {
        self.last.clear();
        let mut events = Vec::new();
        self.take(&mut events)?;
        let deadline = Instant::now() + BYTES_TIMEOUT;
        while self.short() > 0 {
            if Instant::now() >= deadline {
                self.waived += self.short();
                break;
            }
            std::thread::sleep(Duration::from_micros(20));
            if let Err(e) = self.take(&mut events) {
                // What came before the error is not lost; the error is, if any came.
                return if events.is_empty() {
                    Err(e)
                } else {
                    Ok(events)
                };
            }
        }
        Ok(events)
    }

    fn last_read(&self) -> &[u8] {
        &self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::MemGps;
    use firmware_bridge::nmea::ReaderConfig;

    /// A line that hands out its bytes a few at a time, as a pty may.
    struct Trickle {
        gps: MemGps,
        left: Vec<u8>,
    }

    impl GpsInput for Trickle {
        fn poll(&mut self) -> Result<Vec<ReadEvent>, InputError> {
            let n = self.left.len().min(7);
            let chunk: Vec<u8> = self.left.drain(..n).collect();
            self.gps.push(&chunk);
            self.gps.poll()
        }

        fn last_read(&self) -> &[u8] {
            self.gps.last_read()
        }
    }

    #[test]
    fn a_gated_gps_port_reads_until_it_has_the_bytes_it_was_told_of() {
        let text = b"$GPZDA,120000.00,01,01,2026,00,00*6A\r\n".to_vec();
        let expected = Arc::new(AtomicU64::new(text.len() as u64));
        let mut gps = GatedGps::new(
            Trickle {
                gps: MemGps::new(ReaderConfig::default()),
                left: text.clone(),
            },
            Some(Arc::clone(&expected)),
        );
        gps.poll().expect("a poll");
        assert_eq!(gps.last_read(), &text[..]);
        assert_eq!(gps.short(), 0);
        // Told of more than ever comes: it gives up after the bound, once.
        expected.store(text.len() as u64 + 5, Ordering::Relaxed);
        let t = Instant::now();
        gps.poll().expect("a poll");
        assert!(t.elapsed() >= BYTES_TIMEOUT);
        assert_eq!(gps.waived, 5);
        assert_eq!(gps.short(), 0);
    }
}
