//! The golf car's CAN contract.
//!
//! `golf_car.dbc` is the single source of truth: the build script checks it and
//! generates [`NETWORK`] (the tables) and one typed struct per message
//! ([`SteeringCmd`], [`ThrottleReport`], ...). [`e2e`] protects and checks frames;
//! [`candump`] reads can-utils' log formats.

pub mod candump;
pub mod codec;
pub mod e2e;
pub mod spec;

mod generated {
    #![allow(clippy::all, missing_docs)]
    include!(concat!(env!("OUT_DIR"), "/golf_car.rs"));
}

pub use codec::Payload;
pub use e2e::{CounterVerdict, E2eError, E2eRx, E2eStats, E2eTx, SenderWatch};
pub use generated::*;
pub use spec::{MessageSpec, NetworkSpec, SignalSpec, SpecError};

/// The DBC text the codecs were generated from.
pub const GOLF_CAR_DBC: &str = include_str!("../golf_car.dbc");

/// Errors of encoding and decoding signals.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CodecError {
    #[error("signal {signal}: {value} is outside its range [{min}, {max}]")]
    OutOfRange {
        signal: String,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("signal {signal}: raw value {raw} does not fit its bits [{min}, {max}]")]
    RawOutOfRange {
        signal: String,
        raw: i128,
        min: i128,
        max: i128,
    },
    #[error("message {message}: {len} data bytes, expected 8")]
    WrongLength { message: String, len: usize },
    #[error("message {message}, signal {signal}: raw value {raw} is not in its value table")]
    UndefinedValue {
        message: &'static str,
        signal: &'static str,
        raw: i128,
    },
    #[error("unknown CAN ID {0:#x}")]
    UnknownId(u32),
}

/// A message of the golf car network with its generated codec.
pub trait CanMessage: Sized {
    /// The 11-bit CAN ID.
    const ID: u16;
    /// The DBC name.
    const NAME: &'static str;
    /// The message's table entry.
    fn spec() -> &'static MessageSpec;
    /// The payload with every signal set (physical values rounded to the nearest
    /// raw step); the E2E counter and CRC are left zero for [`E2eTx::seal`].
    fn encode(&self) -> Result<Payload, CodecError>;
    /// The signals of an eight-byte payload (E2E is checked separately).
    fn decode(data: &[u8]) -> Result<Self, CodecError>;
}

impl E2eTx {
    /// Encode a typed message and protect it with the ID's next counter.
    pub fn seal_message<M: CanMessage>(&mut self, message: &M) -> Result<Payload, CodecError> {
        Ok(self.seal(M::ID, message.encode()?))
    }
}
