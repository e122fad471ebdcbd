//! Bus load against the DBC's bit rate. vcan has no notion of a bit rate, so a
//! schedule that would overload the car's 500 kbit/s bus runs there silently; the
//! simulator counts every frame on its bus (its own and everyone else's) and puts it
//! in bits, with the worst-case bit stuffing of a CAN 2.0A data frame, so the verdict
//! says how loaded the real bus would be.

use std::collections::VecDeque;

use firmware_bridge::can::arbiter::{ArbitrationStats, frame_bits_worst};
use serde::Serialize;

/// The window the peak load is taken over, seconds.
pub const PEAK_WINDOW_S: f64 = 0.1;

/// The load figures of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BusLoadReport {
    /// The bus's bit rate from the DBC, bit/s.
    pub bit_rate: u32,
    pub frames: u64,
    /// Worst-case bits of those frames.
    pub bits: u64,
    /// Over the whole run, percent of the bit rate.
    pub mean_pct: f64,
    /// The most loaded [`PEAK_WINDOW_S`] window, percent.
    pub peak_pct: f64,
    /// When that window ended, simulated seconds.
    pub peak_at_s: f64,
    /// The arbitration of a bus with the wire's time (`can.bit_timing`: SIL's memory
    /// bus, or the simulator's paced transmissions in HIL).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arbitration: Option<ArbitrationStats>,
}

/// The running count.
#[derive(Clone, Debug)]
pub struct BusLoad {
    bit_rate: u32,
    window: VecDeque<(f64, u64)>,
    in_window: u64,
    frames: u64,
    bits: u64,
    peak_bits: u64,
    peak_at_s: f64,
    last_s: f64,
    arbitration: Option<ArbitrationStats>,
}

impl BusLoad {
    pub fn new(bit_rate: u32) -> BusLoad {
        BusLoad {
            bit_rate,
            window: VecDeque::new(),
            in_window: 0,
            frames: 0,
            bits: 0,
            peak_bits: 0,
            peak_at_s: 0.0,
            last_s: 0.0,
            arbitration: None,
        }
    }

    /// `frames` eight-byte frames crossed the bus in the step ending at `now`.
    pub fn step(&mut self, now: f64, frames: u64) {
        let bits = frames * frame_bits_worst(false, 8);
        self.frames += frames;
        self.bits += bits;
        self.last_s = now;
        self.window.push_back((now, bits));
        self.in_window += bits;
        while self
            .window
            .front()
            .is_some_and(|(t, _)| now - t >= PEAK_WINDOW_S - 1e-9)
        {
            if let Some((_, b)) = self.window.pop_front() {
                self.in_window -= b;
            }
        }
        if self.in_window > self.peak_bits {
            self.peak_bits = self.in_window;
            self.peak_at_s = now;
        }
    }

    /// What the arbitration of a bus with the wire's time did, for the report.
    pub fn arbitrated(&mut self, stats: ArbitrationStats) {
        self.arbitration = Some(stats);
    }

    pub fn report(&self) -> BusLoadReport {
        let rate = f64::from(self.bit_rate.max(1));
        BusLoadReport {
            bit_rate: self.bit_rate,
            frames: self.frames,
            bits: self.bits,
            mean_pct: if self.last_s > 0.0 {
                self.bits as f64 / (self.last_s * rate) * 100.0
            } else {
                0.0
            },
            peak_pct: self.peak_bits as f64 / (PEAK_WINDOW_S * rate) * 100.0,
            peak_at_s: self.peak_at_s,
            arbitration: self.arbitration.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_schedule_loads_the_bus_evenly() {
        // 1000 frames per second at 500 kbit/s: 135 kbit/s, 27 %.
        let mut b = BusLoad::new(500_000);
        for k in 1..=2000u32 {
            b.step(f64::from(k) * 0.001, 1);
        }
        let r = b.report();
        assert_eq!(r.frames, 2000);
        assert!((r.mean_pct - 27.0).abs() < 0.01, "{r:?}");
        assert!((r.peak_pct - 27.0).abs() < 0.3, "{r:?}");
    }
}
