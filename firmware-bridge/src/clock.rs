//! Time for both sides of the wire: fixed-step ticks on absolute deadlines (a long run does not drift), and a
//! lockstep clock that advances only when told (faster than real time, deterministic).

use std::time::{Duration, Instant};

/// Where ticks come from.
pub trait Clock {
    /// Simulated seconds since the start.
    fn now(&self) -> f64;
    /// Wait until tick `k` is due (k * dt after the start); returns how late it is, s.
    fn wait_tick(&mut self, k: u64) -> f64;
    /// No tick follows: the simulator whose time this is has ended the run (lockstep).
    fn ended(&self) -> bool {
        false
    }
}

/// Wall-clock ticks at `start + k * dt`: each deadline is computed from the start, not
/// from the previous tick, so lateness never accumulates.
#[derive(Debug)]
pub struct WallClock {
    start: Instant,
    start_ns: u64,
    dt: f64,
}

/// CLOCK_MONOTONIC in nanoseconds: one time base for every process on the machine, so
/// the simulator and the controller can put their events on one axis (latencies
/// across the wires).
pub fn monotonic_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).map_or(0, |t| {
        u64::try_from(t.tv_sec()).unwrap_or(0) * 1_000_000_000
            + u64::try_from(t.tv_nsec()).unwrap_or(0)
    })
}

/// A time on the real-time clock in nanoseconds since the Unix epoch (0 before it):
/// the base of the kernel's receive timestamps and of the recordings' wall clock.
pub fn unix_ns(t: std::time::SystemTime) -> u64 {
    t.duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

impl WallClock {
    pub fn new(dt: f64) -> WallClock {
        WallClock {
            start: Instant::now(),
            start_ns: monotonic_ns(),
            dt,
        }
    }

    /// [`monotonic_ns`] at the start (tick 0).
    pub fn start_monotonic_ns(&self) -> u64 {
        self.start_ns
    }

    /// The instant tick `k` is due.
    pub fn deadline(&self, k: u64) -> Instant {
        self.start + Duration::from_secs_f64(k as f64 * self.dt)
    }
}

impl Clock for WallClock {
    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    fn wait_tick(&mut self, k: u64) -> f64 {
        let deadline = self.deadline(k);
        let now = Instant::now();
        if deadline > now {
            std::thread::sleep(deadline - now);
        }
        Instant::now()
            .saturating_duration_since(deadline)
            .as_secs_f64()
    }
}

/// Lockstep: tick `k` happens the moment it is asked for.
#[derive(Debug, Default)]
pub struct LockstepClock {
    now: f64,
    dt: f64,
}

impl LockstepClock {
    pub fn new(dt: f64) -> LockstepClock {
        LockstepClock { now: 0.0, dt }
    }
}

impl Clock for LockstepClock {
    fn now(&self) -> f64 {
        self.now
    }

    fn wait_tick(&mut self, k: u64) -> f64 {
        self.now = k as f64 * self.dt;
        0.0
    }
}

/// The slot after `due` of a periodic schedule on absolute times (`due + k * period`),
/// skipping the slots a late caller missed.
pub fn next_slot(due: f64, now: f64, period: f64) -> f64 {
    due + period * ((now - due) / period).floor().max(0.0) + period
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn next_slot_keeps_the_grid_and_skips_missed_slots() {
        assert!((next_slot(0.10, 0.10, 0.01) - 0.11).abs() < 1e-12);
        assert!((next_slot(0.10, 0.1349, 0.01) - 0.14).abs() < 1e-12);
        assert!(
            (next_slot(0.10, 0.05, 0.01) - 0.11).abs() < 1e-12,
            "early: the next slot"
        );
    }

    #[test]
    fn lockstep_ticks_are_exact() {
        let mut c = LockstepClock::new(0.005);
        c.wait_tick(200);
        assert!((c.now() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn wall_deadlines_are_absolute() {
        let c = WallClock::new(0.005);
        let d = c.deadline(1_000_000) - c.deadline(0);
        assert_eq!(d, Duration::from_secs(5000));
    }
}
