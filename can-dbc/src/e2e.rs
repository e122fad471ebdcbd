//! End-to-end protection of every frame on the golf car bus (DESIGN.md):
//! a 4-bit rolling counter in byte 6 (low nibble) and a CRC-8/SAE-J1850
//! (poly 0x1D, init 0xFF, xor-out 0xFF) in byte 7 over the two bytes of the CAN ID
//! (big-endian) followed by data bytes 0-6.
//!
//! [`protect`] builds a protected frame and [`check`] checks one; [`E2eTx`] and
//! [`E2eRx`] keep the per-ID counter state and the receiver's rejection counts.
//!
//! E2E proves integrity, not origin: any process that can open the interface can send
//! a well-formed frame with the next counter. What it cannot do is keep the genuine
//! sender quiet, so a second sender shows on the counter stream: [`SenderWatch`]
//! looks for the counter patterns one sender with lost frames cannot produce, and
//! [`E2eRx`] runs one per stream ([`E2eRx::second_sender`], [`E2eStats::second_sender`]).

use std::collections::BTreeMap;

use embedded_can::{Frame, Id, StandardId};
use serde::Serialize;

use crate::codec::Payload;
use crate::spec::{FRAME_LEN, NetworkSpec};

/// The counter wraps after 15.
pub const COUNTER_MODULUS: u8 = 16;

/// Why a received frame was rejected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum E2eError {
    #[error("unknown CAN ID {id:#x}{}", if *.extended { " (extended)" } else { "" })]
    UnknownId { id: u32, extended: bool },
    #[error("CAN ID {id:#x}: remote frame; the golf car bus carries data frames only")]
    RemoteFrame { id: u16 },
    #[error("CAN ID {id:#x}: DLC {dlc}, expected 8")]
    WrongDlc { id: u16, dlc: usize },
    #[error("CAN ID {id:#x}: bad CRC {found:#04x}, expected {expected:#04x}")]
    BadCrc { id: u16, expected: u8, found: u8 },
    #[error("CAN ID {id:#x}: counter {counter} repeated")]
    RepeatedCounter { id: u16, counter: u8 },
    #[error("CAN ID {id:#x}: counter skipped from {last} to {found} (expected {expected})")]
    SkippedCounter {
        id: u16,
        last: u8,
        expected: u8,
        found: u8,
    },
}

impl E2eError {
    /// The standard ID of the rejected frame (`None` for an extended one).
    pub fn id(&self) -> Option<u16> {
        match *self {
            E2eError::UnknownId { extended: true, .. } => None,
            E2eError::UnknownId { id, .. } => u16::try_from(id).ok(),
            E2eError::RemoteFrame { id }
            | E2eError::WrongDlc { id, .. }
            | E2eError::BadCrc { id, .. }
            | E2eError::RepeatedCounter { id, .. }
            | E2eError::SkippedCounter { id, .. } => Some(id),
        }
    }
}

/// CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, xor-out 0xFF; a byte at a
/// time through [`CRC8_TABLE`].
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    bytes
        .iter()
        .fold(0xFF, |crc: u8, &b| CRC8_TABLE[usize::from(crc ^ b)])
        ^ 0xFF
}

/// The CRC register after shifting each byte value through the polynomial, eight bits.
const CRC8_TABLE: [u8; 256] = crc8_table();

const fn crc8_table() -> [u8; 256] {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = i as u8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x1D
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// The CRC of a frame: over the ID (two bytes, big-endian) and data bytes 0-6.
pub fn frame_crc(id: u16, data: &Payload) -> u8 {
    let mut bytes = [0u8; 2 + FRAME_LEN - 1];
    bytes[..2].copy_from_slice(&id.to_be_bytes());
    bytes[2..].copy_from_slice(&data[..FRAME_LEN - 1]);
    crc8_sae_j1850(&bytes)
}

/// The rolling counter of a payload.
pub fn counter_of(data: &Payload) -> u8 {
    data[6] & 0x0F
}

/// Build a protected frame: write `counter` (mod 16) into byte 6's low nibble and the
/// CRC into byte 7. Bytes 0-5 and byte 6's high nibble are the message's signals.
pub fn protect(id: u16, data: &mut Payload, counter: u8) {
    data[6] = (data[6] & 0xF0) | (counter % COUNTER_MODULUS);
    data[7] = frame_crc(id, data);
}

/// Check a received frame: known 11-bit ID, data frame, eight bytes, CRC, and the
/// counter against the last accepted one (`None` for the first frame of an ID).
pub fn check(
    network: &NetworkSpec,
    id: u32,
    extended: bool,
    remote: bool,
    data: &[u8],
    last_counter: Option<u8>,
) -> Result<(u16, Payload), E2eError> {
    let known = (!extended)
        .then(|| u16::try_from(id).ok())
        .flatten()
        .filter(|id| network.message(*id).is_some());
    let Some(id) = known else {
        return Err(E2eError::UnknownId { id, extended });
    };
    if remote {
        return Err(E2eError::RemoteFrame { id });
    }
    let data = Payload::try_from(data).map_err(|_| E2eError::WrongDlc {
        id,
        dlc: data.len(),
    })?;
    let expected = frame_crc(id, &data);
    if data[7] != expected {
        return Err(E2eError::BadCrc {
            id,
            expected,
            found: data[7],
        });
    }
    let counter = counter_of(&data);
    if let Some(last) = last_counter {
        let next = (last + 1) % COUNTER_MODULUS;
        if counter == last {
            return Err(E2eError::RepeatedCounter { id, counter });
        }
        if counter != next {
            return Err(E2eError::SkippedCounter {
                id,
                last,
                expected: next,
                found: counter,
            });
        }
    }
    Ok((id, data))
}

/// The sender side: one rolling counter per CAN ID.
#[derive(Debug, Default, Clone)]
pub struct E2eTx {
    next: BTreeMap<u16, u8>,
}

impl E2eTx {
    pub fn new() -> Self {
        Self::default()
    }

    /// Protect a payload with the ID's next counter value.
    pub fn seal(&mut self, id: u16, mut data: Payload) -> Payload {
        let counter = self.next.entry(id).or_insert(0);
        protect(id, &mut data, *counter);
        *counter = (*counter + 1) % COUNTER_MODULUS;
        data
    }

    /// Protect a payload and wrap it as a frame of any `embedded_can` implementation.
    pub fn seal_frame<F: Frame>(&mut self, id: u16, data: Payload) -> Option<F> {
        let sid = StandardId::new(id)?;
        F::new(sid, &self.seal(id, data))
    }
}

/// What the counter check made of one frame of a stream (a frame with a good CRC).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CounterVerdict {
    /// The next counter (or the first frame of the stream): accepted.
    Next,
    /// The last accepted counter again.
    Repeated,
    /// Neither: one or more frames missing, or another sequence.
    Skipped,
}

/// The frames of one stream [`SenderWatch`] looks back over.
pub const SENDER_WINDOW: u32 = 32;
/// Repeated counters within the window that reveal a second sender.
pub const SENDER_REPEATS: u32 = 3;
/// Counter anomalies (repeated or skipped) within the window that reveal one.
pub const SENDER_ANOMALIES: u32 = 8;
// The window is the bits of the watch's masks.
const _: () = assert!(SENDER_WINDOW == u32::BITS);

/// Second-sender detection on one counter stream (one ID, or one `Source` of a
/// message with several senders).
///
/// One sender never repeats its counter: a lost frame makes a skip, and since the
/// receiver re-synchronises on a skip, a burst of lost frames costs one skip, not one
/// per frame. A second sender on the stream does what loss cannot: one that answers
/// each genuine frame with a forged one carrying the next counter makes every genuine
/// frame a repeat; one with a sequence of its own makes nearly every frame a skip. So
/// within the last [`SENDER_WINDOW`] frames, [`SENDER_REPEATS`] repeated counters or
/// [`SENDER_ANOMALIES`] anomalies of either kind flag the stream; it stays flagged
/// until they have left the window. An occasional lost frame (or a rare double
/// reception) never gets there: it takes a quarter of the frames lost, in separate
/// bursts, to reach eight skips.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SenderWatch {
    /// One bit per frame, newest lowest: anomalies, and the repeats among them.
    anomalies: u32,
    repeats: u32,
    flagged: bool,
}

impl SenderWatch {
    /// Take one frame's verdict; true when it made the stream flagged (the moment a
    /// second sender is found, counted once per episode).
    pub fn observe(&mut self, verdict: CounterVerdict) -> bool {
        let (anomaly, repeat) = match verdict {
            CounterVerdict::Next => (0, 0),
            CounterVerdict::Repeated => (1, 1),
            CounterVerdict::Skipped => (1, 0),
        };
        self.anomalies = (self.anomalies << 1) | anomaly;
        self.repeats = (self.repeats << 1) | repeat;
        let was = self.flagged;
        self.flagged = self.repeats.count_ones() >= SENDER_REPEATS
            || self.anomalies.count_ones() >= SENDER_ANOMALIES;
        self.flagged && !was
    }

    /// Whether the stream shows a second sender now.
    pub fn flagged(&self) -> bool {
        self.flagged
    }
}

/// What a receiver accepted and rejected, by cause.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct E2eStats {
    pub accepted: u64,
    pub unknown_id: u64,
    pub remote: u64,
    pub wrong_dlc: u64,
    pub bad_crc: u64,
    pub repeated_counter: u64,
    pub skipped_counter: u64,
    /// Times a stream was found to have a second sender ([`SenderWatch`]); not a
    /// rejection count (the frames are counted above).
    pub second_sender: u64,
}

impl E2eStats {
    /// All rejected frames.
    pub fn rejected(&self) -> u64 {
        self.unknown_id
            + self.remote
            + self.wrong_dlc
            + self.bad_crc
            + self.repeated_counter
            + self.skipped_counter
    }

    fn count(&mut self, result: &Result<(u16, Payload), E2eError>) {
        let slot = match result {
            Ok(_) => &mut self.accepted,
            Err(E2eError::UnknownId { .. }) => &mut self.unknown_id,
            Err(E2eError::RemoteFrame { .. }) => &mut self.remote,
            Err(E2eError::WrongDlc { .. }) => &mut self.wrong_dlc,
            Err(E2eError::BadCrc { .. }) => &mut self.bad_crc,
            Err(E2eError::RepeatedCounter { .. }) => &mut self.repeated_counter,
            Err(E2eError::SkippedCounter { .. }) => &mut self.skipped_counter,
        };
        *slot += 1;
    }
}

/// The receiver side: the last accepted counter per sender of each ID and the
/// rejection counts.
///
/// A message that several nodes send (FAULT_REPORT) carries its sender in a `Source`
/// signal, and each sender keeps its own counter, so the receiver tracks one counter
/// per (ID, Source). A skipped counter is rejected and counted, and the receiver
/// re-synchronises on it, so the frame after it is accepted again; a repeated counter
/// or a bad CRC leaves the state as it was. Each stream has a [`SenderWatch`].
#[derive(Debug, Clone)]
pub struct E2eRx<'n> {
    network: &'n NetworkSpec,
    last: BTreeMap<(u16, i128), u8>,
    watch: BTreeMap<(u16, i128), SenderWatch>,
    stats: E2eStats,
}

/// Which sender's counter a frame continues: the `Source` signal of a message with
/// several senders, 0 otherwise.
fn sender_key(network: &NetworkSpec, id: u16, data: &[u8]) -> i128 {
    network
        .message(id)
        .filter(|m| m.senders.len() > 1)
        .and_then(|m| m.signal("Source"))
        .zip(Payload::try_from(data).ok())
        .map_or(0, |(s, p)| s.get_raw(&p))
}

impl<'n> E2eRx<'n> {
    pub fn new(network: &'n NetworkSpec) -> Self {
        Self {
            network,
            last: BTreeMap::new(),
            watch: BTreeMap::new(),
            stats: E2eStats::default(),
        }
    }

    /// Check a frame given as its parts.
    pub fn accept_parts(
        &mut self,
        id: u32,
        extended: bool,
        remote: bool,
        data: &[u8],
    ) -> Result<(u16, Payload), E2eError> {
        let key = u16::try_from(id)
            .ok()
            .filter(|_| !extended)
            .map(|id| (id, sender_key(self.network, id, data)));
        let last = key.and_then(|k| self.last.get(&k).copied());
        let result = check(self.network, id, extended, remote, data, last);
        match (&result, key) {
            (Ok((_, payload)), Some(k)) => {
                self.last.insert(k, counter_of(payload));
            }
            (Err(E2eError::SkippedCounter { found, .. }), Some(k)) => {
                self.last.insert(k, *found);
            }
            _ => {}
        }
        let verdict = match &result {
            Ok(_) => Some(CounterVerdict::Next),
            Err(E2eError::RepeatedCounter { .. }) => Some(CounterVerdict::Repeated),
            Err(E2eError::SkippedCounter { .. }) => Some(CounterVerdict::Skipped),
            Err(_) => None,
        };
        if let (Some(verdict), Some(k)) = (verdict, key)
            && self.watch.entry(k).or_default().observe(verdict)
        {
            self.stats.second_sender += 1;
        }
        self.stats.count(&result);
        result
    }

    /// The CAN ID of a stream that shows a second sender now (the lowest, when
    /// several do), see [`SenderWatch`].
    pub fn second_sender(&self) -> Option<u16> {
        self.watch
            .iter()
            .find(|(_, w)| w.flagged())
            .map(|((id, _), _)| *id)
    }

    /// Check a frame of any `embedded_can` implementation.
    pub fn accept<F: Frame>(&mut self, frame: &F) -> Result<(u16, Payload), E2eError> {
        let (id, extended) = match frame.id() {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        self.accept_parts(id, extended, frame.is_remote_frame(), frame.data())
    }

    pub fn stats(&self) -> E2eStats {
        self.stats
    }

    /// Forget the counter history (after a bus-off or a deliberate restart).
    pub fn reset(&mut self) {
        self.last.clear();
        self.watch.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CanMessage, NETWORK, SteeringCmd};

    /// splitmix64, so a failure reproduces.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn chance(&mut self, p: f64) -> bool {
            ((self.next() >> 11) as f64 / (1u64 << 53) as f64) < p
        }
    }

    fn frame(counter: u8, target: f64) -> Payload {
        let mut data = SteeringCmd {
            enable: true,
            target_angle: target,
            max_rate: 50.0,
        }
        .encode()
        .unwrap_or_default();
        protect(SteeringCmd::ID, &mut data, counter);
        data
    }

    fn feed(rx: &mut E2eRx<'_>, data: &Payload) -> Result<(u16, Payload), E2eError> {
        rx.accept_parts(u32::from(SteeringCmd::ID), false, false, data)
    }

    #[test]
    fn a_forger_answering_each_frame_with_the_next_counter_is_found_within_eight_frames() {
        let mut rx = E2eRx::new(&NETWORK);
        let mut found_after = None;
        for k in 0..100u8 {
            // The genuine frame, then the forged one with the next counter.
            let _ = feed(&mut rx, &frame(k % 16, 1.0));
            let _ = feed(&mut rx, &frame((k + 1) % 16, 35.0));
            if found_after.is_none() && rx.second_sender().is_some() {
                found_after = Some(2 * (usize::from(k) + 1));
            }
        }
        let frames = found_after.unwrap_or(usize::MAX);
        eprintln!("second sender found after {frames} frames");
        assert!(frames <= 8, "found after {frames} frames");
        assert_eq!(rx.second_sender(), Some(SteeringCmd::ID));
        let s = rx.stats();
        assert_eq!(s.second_sender, 1, "one episode, counted once: {s:?}");
        assert!(s.repeated_counter >= 95, "{s:?}");
    }

    #[test]
    fn an_interleaved_sequence_of_its_own_is_found() {
        let mut rx = E2eRx::new(&NETWORK);
        for k in 0..20u8 {
            let _ = feed(&mut rx, &frame(k % 16, 1.0));
            let _ = feed(&mut rx, &frame((k + 7) % 16, 35.0));
        }
        assert_eq!(rx.second_sender(), Some(SteeringCmd::ID));
        assert!(rx.stats().skipped_counter >= 30, "{:?}", rx.stats());
    }

    #[test]
    fn a_flag_clears_once_the_second_sender_has_gone() {
        let mut rx = E2eRx::new(&NETWORK);
        let mut c = 0u8;
        for _ in 0..10 {
            let _ = feed(&mut rx, &frame(c, 1.0));
            c = (c + 1) % 16;
            let _ = feed(&mut rx, &frame(c, 35.0));
        }
        assert!(rx.second_sender().is_some());
        // The genuine sender alone, resynchronised: the anomalies leave the window.
        for _ in 0..SENDER_WINDOW {
            c = (c + 1) % 16;
            let _ = feed(&mut rx, &frame(c, 1.0));
        }
        assert_eq!(rx.second_sender(), None);
        assert_eq!(rx.stats().second_sender, 1);
    }

    #[test]
    fn one_sender_with_occasional_loss_bursts_and_a_double_reception_is_never_flagged() {
        let mut rx = E2eRx::new(&NETWORK);
        let mut rng = Rng(0x5EED_E2E5);
        let mut counter = 0u8;
        let mut delivered = 0u64;
        // 200 000 frames (over half an hour at 100 Hz): 2 % lost singly, bursts of up
        // to 20 lost now and then, and a double reception (CAN's EOF case) now and then.
        for _ in 0..200_000 {
            let data = frame(counter, 1.0);
            counter = (counter + 1) % 16;
            if rng.chance(0.02) {
                continue;
            }
            if rng.chance(0.001) {
                for _ in 0..(rng.next() % 20) {
                    counter = (counter + 1) % 16;
                }
            }
            let _ = feed(&mut rx, &data);
            delivered += 1;
            if rng.chance(0.0005) {
                let _ = feed(&mut rx, &data);
            }
            assert_eq!(
                rx.second_sender(),
                None,
                "after {delivered} frames: {:?}",
                rx.stats()
            );
        }
        let s = rx.stats();
        assert_eq!(s.second_sender, 0, "{s:?}");
        assert!(
            s.skipped_counter > 2_000 && s.repeated_counter > 20,
            "{s:?}"
        );
    }

    #[test]
    fn the_watch_counts_patterns_not_single_events() {
        let mut w = SenderWatch::default();
        // Two repeats in a window: not yet (a double reception twice is possible).
        assert!(!w.observe(CounterVerdict::Repeated));
        assert!(!w.observe(CounterVerdict::Next));
        assert!(!w.observe(CounterVerdict::Repeated));
        assert!(!w.flagged());
        assert!(
            w.observe(CounterVerdict::Repeated),
            "the third repeat flags"
        );
        assert!(
            !w.observe(CounterVerdict::Repeated),
            "flagged once per episode"
        );
        assert!(w.flagged());
        // Seven skips in a window do not flag; the eighth does.
        let mut w = SenderWatch::default();
        for _ in 0..SENDER_ANOMALIES - 1 {
            assert!(!w.observe(CounterVerdict::Skipped));
            assert!(!w.observe(CounterVerdict::Next));
        }
        assert!(w.observe(CounterVerdict::Skipped));
        // Skips spread wider than the window never flag.
        let mut w = SenderWatch::default();
        for _ in 0..1000 {
            assert!(!w.observe(CounterVerdict::Skipped));
            for _ in 0..4 {
                assert!(!w.observe(CounterVerdict::Next));
            }
        }
    }
}
