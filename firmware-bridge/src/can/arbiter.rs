//! CAN's arbitration on a timeline: frames wait for the bus, the lowest identifier
//! among those waiting when the bus falls idle wins it (CAN's bitwise arbitration),
//! and each occupies the bus for its worst-case bit time ([`frame_bits_worst`]) at the
//! bit rate. An overloaded schedule shows up as frames that waited
//! ([`ArbitrationStats`]), as on a real bus.
//!
//! One timeline serves two buses: the SIL memory bus ([`super::membus`]), whose other
//! nodes receive a frame when its last bit is sent ([`Release::AtEnd`]), and the HIL
//! pacing of the simulator's transmissions on a SocketCAN interface
//! ([`super::paced`]), where a frame goes onto the real (virtual) wire when it wins the
//! bus ([`Release::AtStart`]) and the kernel carries it from there.

use embedded_can::{Frame, Id};

/// Bits on the wire of a CAN 2.0 data frame of `dlc` data bytes with the most stuff
/// bits it can need: SOF, the identifier field (11-bit: ID, RTR, IDE, r0; 29-bit: ID,
/// SRR, IDE, RTR, r1, r0), DLC, data and CRC can take a stuff bit after every four,
/// then the CRC delimiter, ACK, EOF and the interframe space (13 bits) are never
/// stuffed. 135 bits for 8 bytes with an 11-bit identifier.
pub fn frame_bits_worst(extended: bool, dlc: usize) -> u64 {
    let header = if extended { 54 } else { 34 };
    let stuffable = header + 8 * dlc.min(8) as u64;
    stuffable + (stuffable - 1) / 4 + 13
}

/// A frame waited for the bus longer than this, seconds: it counts as late. 5 ms is
/// eighteen 8-byte frames at 500 kbit/s, and one physics step of the simulator at its
/// default 200 Hz, whose nodes send the frames of a step together: a burst of one
/// step that the bus has not carried by the next means the schedule overloads it.
pub const LATE_WAIT_S: f64 = 0.005;

/// What an arbitrated bus did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ArbitrationStats {
    pub bit_rate: u32,
    /// Frames carried (to the other nodes, or onto the wire).
    pub delivered: u64,
    /// Of them, those that waited for the bus longer than [`LATE_WAIT_S`].
    pub late: u64,
    /// The longest wait from sending to winning the bus, milliseconds.
    pub max_wait_ms: f64,
    /// Frames still waiting for the bus (or on it) at the last advance.
    pub backlog: usize,
    /// Frames of nodes outside the timeline seen on the bus, whose bit time it
    /// accounted for (HIL: the controller's, a gateway's).
    #[serde(skip_serializing_if = "is_zero")]
    pub foreign: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// When a frame that won the bus leaves the timeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Release {
    /// When its last bit is sent: the other nodes receive it then (a bus simulated in
    /// memory).
    AtEnd,
    /// When it wins the bus: it is handed to a wire that carries it (pacing
    /// transmissions onto a SocketCAN interface).
    AtStart,
}

/// A frame waiting for the bus.
#[derive(Debug)]
struct Pending<F> {
    ready: f64,
    /// Arbitration key: the lower wins (an 11-bit identifier beats a 29-bit one with
    /// the same first 11 bits).
    key: (u32, bool, u32),
    order: u64,
    from: usize,
    frame: F,
}

fn arbitration_key(id: Id) -> (u32, bool, u32) {
    match id {
        Id::Standard(s) => (u32::from(s.as_raw()), false, 0),
        Id::Extended(e) => (e.as_raw() >> 18, true, e.as_raw() & 0x3_ffff),
    }
}

/// The bus's timeline: the frames waiting, the one on the bus, and when it ends.
/// Times are seconds on the caller's clock.
#[derive(Debug)]
pub struct Arbiter<F> {
    bit_rate: f64,
    release: Release,
    pending: Vec<Pending<F>>,
    on_bus: Option<(f64, Pending<F>)>,
    free_at: f64,
    order: u64,
    stats: ArbitrationStats,
}

impl<F: Frame> Arbiter<F> {
    /// An idle bus at `bit_rate` bit/s.
    pub fn new(bit_rate: u32, release: Release) -> Arbiter<F> {
        Arbiter {
            bit_rate: f64::from(bit_rate.max(1)),
            release,
            pending: Vec::new(),
            on_bus: None,
            free_at: f64::NEG_INFINITY,
            order: 0,
            stats: ArbitrationStats {
                bit_rate,
                ..ArbitrationStats::default()
            },
        }
    }

    /// Node `from` wants to send `frame` from time `ready` on.
    pub fn submit(&mut self, ready: f64, from: usize, frame: F) {
        self.order += 1;
        self.pending.push(Pending {
            ready,
            key: arbitration_key(frame.id()),
            order: self.order,
            from,
            frame,
        });
    }

    /// A frame of a node outside the timeline was on the bus, its last bit at `end`:
    /// the bus was busy for its bit time, after whatever this timeline had put on it.
    pub fn occupy(&mut self, end: f64, extended: bool, dlc: usize) {
        let busy = frame_bits_worst(extended, dlc) as f64 / self.bit_rate;
        self.free_at = (self.free_at + busy).max(end);
        self.stats.foreign += 1;
    }

    /// Run the bus up to time `t`: whenever it falls idle the waiting frames
    /// arbitrate, and each frame leaves through `out(from, frame)` as [`Release`] says.
    pub fn advance_to(&mut self, t: f64, mut out: impl FnMut(usize, F)) {
        loop {
            if let Some((end, _)) = &self.on_bus {
                if *end > t {
                    break;
                }
                if let Some((end, p)) = self.on_bus.take() {
                    self.free_at = end;
                    self.stats.delivered += 1;
                    out(p.from, p.frame);
                }
            }
            let Some(first) = self.pending.iter().map(|p| p.ready).reduce(f64::min) else {
                break;
            };
            let start = self.free_at.max(first);
            if start > t {
                break;
            }
            // The earliest frame is ready by `start`, so there is a winner.
            let Some(winner) = self
                .pending
                .iter()
                .enumerate()
                .filter(|(_, p)| p.ready <= start)
                .min_by_key(|(_, p)| (p.key, p.order))
                .map(|(i, _)| i)
            else {
                break;
            };
            let p = self.pending.swap_remove(winner);
            let wait = start - p.ready;
            self.stats.max_wait_ms = self.stats.max_wait_ms.max(wait * 1e3);
            if wait > LATE_WAIT_S {
                self.stats.late += 1;
            }
            let bits = frame_bits_worst(p.frame.is_extended(), p.frame.dlc());
            let end = start + bits as f64 / self.bit_rate;
            match self.release {
                Release::AtEnd => self.on_bus = Some((end, p)),
                Release::AtStart => {
                    self.free_at = end;
                    self.stats.delivered += 1;
                    out(p.from, p.frame);
                }
            }
        }
        self.stats.backlog = self.pending.len() + usize::from(self.on_bus.is_some());
    }

    /// What the bus did so far.
    pub fn stats(&self) -> ArbitrationStats {
        self.stats.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::membus::MemFrame;

    fn frame(id: u16) -> MemFrame {
        MemFrame::new(embedded_can::StandardId::new(id).expect("11-bit"), &[0; 8]).expect("frame")
    }

    fn run(a: &mut Arbiter<MemFrame>, t: f64) -> Vec<(usize, u16)> {
        let mut out = Vec::new();
        a.advance_to(t, |from, f| {
            if let Id::Standard(s) = f.id() {
                out.push((from, s.as_raw()));
            }
        });
        out
    }

    #[test]
    fn worst_case_bits_of_a_frame() {
        assert_eq!(frame_bits_worst(false, 8), 135);
        assert_eq!(frame_bits_worst(false, 0), 55);
        assert_eq!(frame_bits_worst(true, 8), 160);
    }

    #[test]
    fn released_at_start_a_frame_leaves_when_it_wins_and_holds_the_bus_for_its_bits() {
        let mut a = Arbiter::new(500_000, Release::AtStart);
        a.submit(0.0, 0, frame(0x300));
        a.submit(0.0, 1, frame(0x100));
        // The lower ID wins at once; the other waits the 270 us of an 8-byte frame.
        assert_eq!(run(&mut a, 0.000_1), vec![(1, 0x100)]);
        assert_eq!(run(&mut a, 0.000_269), vec![]);
        assert_eq!(run(&mut a, 0.000_270), vec![(0, 0x300)]);
        let s = a.stats();
        assert_eq!((s.delivered, s.late, s.backlog), (2, 0, 0));
        assert!((s.max_wait_ms - 0.27).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn a_foreign_frame_delays_the_next_one() {
        let mut a = Arbiter::new(500_000, Release::AtStart);
        // Someone else's frame ended at 1 ms; ours, ready at 0.9 ms, starts after it.
        a.occupy(0.001, false, 8);
        a.submit(0.000_9, 0, frame(0x10));
        assert_eq!(run(&mut a, 0.000_95), vec![]);
        assert_eq!(run(&mut a, 0.001), vec![(0, 0x10)]);
        // Two foreign frames back to back while the bus was busy with ours: the bus
        // carried them after it, one after the other.
        a.occupy(0.001_1, false, 8);
        a.occupy(0.001_1, false, 8);
        a.submit(0.001_1, 0, frame(0x10));
        assert_eq!(run(&mut a, 0.001_80), vec![]);
        assert_eq!(run(&mut a, 0.001_811), vec![(0, 0x10)]);
        assert_eq!(a.stats().foreign, 3);
    }

    #[test]
    fn a_flood_of_a_lower_id_makes_the_others_late() {
        let mut a = Arbiter::new(500_000, Release::AtStart);
        let mut got = Vec::new();
        // 10 ms steps; each the babbler sends 50 frames of ID 0 (13.5 ms of bus time).
        for k in 0..20 {
            let t = f64::from(k) * 0.01;
            for _ in 0..50 {
                a.submit(t, 0, frame(0));
            }
            a.submit(t, 1, frame(0x200));
            got.extend(run(&mut a, t));
        }
        got.extend(run(&mut a, 0.2));
        assert!(!got.contains(&(1, 0x200)), "ID 0x200 never wins");
        let s = a.stats();
        assert!(
            s.backlog > 20 && s.late > 0 && s.max_wait_ms > 10.0,
            "{s:?}"
        );
    }
}
