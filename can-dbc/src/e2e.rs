//! End-to-end protection of every frame on the golf car bus (DESIGN.md):
//! a 4-bit rolling counter in byte 6 (low nibble) and a CRC-8/SAE-J1850
//! (poly 0x1D, init 0xFF, xor-out 0xFF) in byte 7 over the two bytes of the CAN ID
//! (big-endian) followed by data bytes 0-6.
//!
//! [`protect`] builds a protected frame and [`check`] checks one; [`E2eTx`] and
//! [`E2eRx`] keep the per-ID counter state and the receiver's rejection counts.

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

/// CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, xor-out 0xFF.
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    let mut crc: u8 = 0xFF;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x1D
            } else {
                crc << 1
            };
        }
    }
    crc ^ 0xFF
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
/// or a bad CRC leaves the state as it was.
#[derive(Debug, Clone)]
pub struct E2eRx<'n> {
    network: &'n NetworkSpec,
    last: BTreeMap<(u16, i128), u8>,
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
        self.stats.count(&result);
        result
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
    }
}
