//! Serial-line pacing on simulated time: a pty sends at memory speed, a UART at its
//! baud rate; the pacer hands out each byte when a UART would start sending it.

use std::collections::VecDeque;

use firmware_bridge::nmea::BITS_PER_BYTE_8N1;

/// Slack for comparing float times, seconds (far below a byte time: 0.26 µs at 4 Mbaud).
const EPS_S: f64 = 1e-9;

#[derive(Debug, Clone)]
struct Segment {
    /// When byte 0 leaves, sim seconds.
    start: f64,
    bytes: Vec<u8>,
    /// Bytes already released.
    sent: usize,
}

/// A queue of byte bursts, each released at the baud rate from its start time:
/// byte `k` of a burst queued at `t` leaves at `t + k * byte_time` (8N1: 10 bits per
/// byte). A burst queued while the line is still busy starts when the previous one
/// ends, as on a UART. Time is the caller's (sim seconds), never the wall clock.
#[derive(Debug, Clone)]
pub struct Pacer {
    byte_time_s: f64,
    segments: VecDeque<Segment>,
    /// When the last queued byte has left the line.
    line_free_at: f64,
    queued: u64,
    released: u64,
}

impl Pacer {
    /// A pacer for an 8N1 line at `baud` (zero baud: everything leaves at once).
    pub fn new(baud: u32) -> Pacer {
        Pacer {
            byte_time_s: if baud == 0 {
                0.0
            } else {
                f64::from(BITS_PER_BYTE_8N1) / f64::from(baud)
            },
            segments: VecDeque::new(),
            line_free_at: f64::NEG_INFINITY,
            queued: 0,
            released: 0,
        }
    }

    /// Seconds one byte occupies the line.
    pub fn byte_time_s(&self) -> f64 {
        self.byte_time_s
    }

    /// Queue `bytes` to go out from time `t` on; returns when the first of them
    /// leaves (`t`, or later while the line is busy with earlier bytes).
    pub fn enqueue(&mut self, t: f64, bytes: &[u8]) -> f64 {
        if bytes.is_empty() {
            return t;
        }
        let start = t.max(self.line_free_at);
        self.line_free_at = start + bytes.len() as f64 * self.byte_time_s;
        self.queued += bytes.len() as u64;
        self.segments.push_back(Segment {
            start,
            bytes: bytes.to_vec(),
            sent: 0,
        });
        start
    }

    /// Append to `out` every byte whose time is at or before `now`; returns how many.
    pub fn release(&mut self, now: f64, out: &mut Vec<u8>) -> usize {
        let before = out.len();
        while let Some(seg) = self.segments.front_mut() {
            if now + EPS_S < seg.start {
                break;
            }
            let due = if self.byte_time_s > 0.0 {
                let k = ((now - seg.start + EPS_S) / self.byte_time_s).floor();
                // k is >= 0 here; saturate the conversion for absurd times.
                (k as usize).saturating_add(1).min(seg.bytes.len())
            } else {
                seg.bytes.len()
            };
            if due > seg.sent {
                out.extend_from_slice(seg.bytes.get(seg.sent..due).unwrap_or(&[]));
                seg.sent = due;
            }
            if seg.sent < seg.bytes.len() {
                break;
            }
            self.segments.pop_front();
        }
        let n = out.len() - before;
        self.released += n as u64;
        n
    }

    /// When the next unreleased byte leaves, if any is queued.
    pub fn next_release(&self) -> Option<f64> {
        self.segments
            .front()
            .map(|s| s.start + s.sent as f64 * self.byte_time_s)
    }

    /// Bytes queued and not yet released.
    pub fn pending(&self) -> usize {
        self.segments.iter().map(|s| s.bytes.len() - s.sent).sum()
    }

    /// Bytes ever queued.
    pub fn queued(&self) -> u64 {
        self.queued
    }

    /// Bytes ever released.
    pub fn released(&self) -> u64 {
        self.released
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_leave_one_byte_time_apart() {
        let mut p = Pacer::new(10_000); // 1 ms per byte
        assert_eq!(p.enqueue(1.0, b"abcde"), 1.0);
        let mut out = Vec::new();
        assert_eq!(p.release(0.999, &mut out), 0);
        assert_eq!(p.release(1.0, &mut out), 1);
        assert_eq!(p.release(1.0025, &mut out), 2);
        assert_eq!(p.next_release(), Some(1.003));
        assert_eq!(p.release(5.0, &mut out), 2);
        assert_eq!(out, b"abcde");
        assert_eq!(p.pending(), 0);
    }

    #[test]
    fn a_burst_on_a_busy_line_waits_for_it() {
        let mut p = Pacer::new(10_000);
        p.enqueue(0.0, b"0123456789");
        let start = p.enqueue(0.005, b"xy");
        assert!((start - 0.010).abs() < 1e-12);
        let mut out = Vec::new();
        p.release(0.0095, &mut out);
        assert_eq!(out, b"0123456789");
        p.release(0.0100, &mut out);
        assert_eq!(out, b"0123456789x");
    }
}
