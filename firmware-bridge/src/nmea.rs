//! The GPS wire: NMEA 0183 written by the simulator and read by the controller.
//!
//! - [`NmeaWriter`] (simulator side) turns a typed [`GpsFix`] and a UTC time into the
//!   sentences of one epoch (GGA, RMC, VTG, GST, HDT, THS, ZDA, chosen by a
//!   [`Schedule`]), with a configurable talker, and refuses a rate and sentence set
//!   that cannot fit the baud rate ([`link_budget`]).
//! - [`NmeaReader`] (controller side) takes bytes in any chunking, with garbage,
//!   partial lines, bad checksums and overlong lines, and yields typed
//!   [`GpsReading`]s, one per receiver epoch, and counted [`SentenceError`]s.
//! - [`NmeaLink`] joins a byte port (a serial device opened with [`open_serial`], or
//!   anything `Read + Write`) to a reader: the controller's end.
//! - [`LineEndpoint`] is the simulated receiver's end of the line over any byte port:
//!   non-blocking writes that drop what does not fit, and what the controller writes
//!   back, framed into lines. [`PtyEndpoint`] is one on a pseudo-terminal,
//!   [`SerialEndpoint`] one on a physical serial device.
//!
//! # Position resolution
//!
//! Latitude and longitude go out as degrees and decimal minutes with
//! [`WriterConfig::minute_decimals`] decimals, 7 by default: one arc-minute of
//! latitude is about 1852 m, so 1e-5 minutes is 1.85 cm (too coarse for RTK's 1 cm),
//! 1e-6 is 1.9 mm and 1e-7 is 0.19 mm, which keeps the quantisation (±0.09 mm) far
//! below RTK noise and lets a world-frame point survive the wire within 1 mm. Heights
//! and sigmas carry millimetres, speed 0.001 knot (0.5 mm/s), course 0.01° and
//! heading 0.001°. Such GGA sentences are up to ~90 characters, over NMEA's 82 (as
//! with u-blox high-precision mode or Trimble receivers); the reader accepts up to
//! [`MAX_SENTENCE_LEN`] (102, gpsd's limit) and the writer never
//! exceeds it.
//!
//! # Epochs
//!
//! See [`NmeaReader`] for the rule that groups one epoch's sentences into one reading.
//!
//! # Example
//!
//! ```
//! use std::time::Duration;
//! use firmware_bridge::nmea::{
//!     FixQuality, GpsFix, NmeaReader, NmeaWriter, ReadEvent, UtcClock, WriterConfig,
//! };
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut writer = NmeaWriter::new(WriterConfig::default())?; // GN talker, 10 Hz, 115200 baud
//! let clock = UtcClock::new(chrono::DateTime::UNIX_EPOCH);
//! let fix = GpsFix {
//!     lat_deg: 48.1173,
//!     lon_deg: 11.5167,
//!     ellipsoid_height_m: 592.3,
//!     geoid_separation_m: 46.9,
//!     quality: FixQuality::RtkFixed,
//!     satellites: 14,
//!     hdop: 0.7,
//!     ..GpsFix::default()
//! };
//! let mut text = String::new();
//! writer.write_epoch(&fix, clock.at(Duration::from_millis(100))?, &mut text)?;
//!
//! let mut reader = NmeaReader::default();
//! let events: Vec<ReadEvent> = reader.feed(text.as_bytes()).collect();
//! assert!(matches!(&events[..], [ReadEvent::Fix(f)] if f.quality == Some(FixQuality::RtkFixed)));
//! # Ok(())
//! # }
//! ```

mod decode;
mod framing;
mod line;
mod link;
mod pty;
mod reader;
mod serial;
mod types;
mod writer;

use std::io;
use std::path::PathBuf;

pub use framing::{Framed, LineFramer, MAX_SENTENCE_LEN, checksum, is_terminator};
pub use line::{BytePort, LineEndpoint};
pub use link::NmeaLink;
pub use pty::{Pty, PtyEndpoint};
pub use reader::{GpsReading, NmeaReader, ReadEvent, ReaderConfig, ReaderStats};
pub use serial::{SerialEndpoint, open_serial};
pub use types::{
    Accuracy, FixQuality, GpsFix, HeadingMode, NavStatus, PositioningMode, SentenceKind,
    SentenceSet, Talker,
};
pub use writer::{
    BITS_PER_BYTE_8N1, LinkBudget, NmeaWriter, Schedule, UtcClock, WriterConfig, byte_time,
    link_budget, max_sentence_len, transmit_time,
};

/// What was wrong with received bytes: each is counted by the reader
/// ([`ReaderStats`]) and handed to the caller; none stops the stream.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SentenceError {
    #[error("{bytes} bytes of garbage outside any sentence")]
    Garbage { bytes: usize },
    #[error("sentence cut off after {len} bytes (a new '$' or the end of the stream came first)")]
    Truncated { len: usize },
    #[error("line of {len} bytes exceeds the {max}-byte limit; discarded")]
    LineTooLong { len: usize, max: usize },
    #[error("invalid byte {byte:#04x} at position {position} of a sentence")]
    InvalidCharacter { position: usize, byte: u8 },
    #[error("sentence {sentence} has no '*hh' checksum")]
    MissingChecksum { sentence: String },
    #[error("sentence {sentence}: bad checksum, computed {computed:02X}, found {found}")]
    BadChecksum {
        sentence: String,
        computed: u8,
        found: String,
    },
    #[error("sentence address '{address}' is not a talker and a three-letter formatter")]
    BadAddress { address: String },
    #[error("unknown sentence {address}")]
    UnknownSentence { address: String },
    #[error("{sentence} field {field} malformed: '{text}' ({reason})")]
    MalformedField {
        sentence: String,
        field: usize,
        text: String,
        reason: String,
    },
}

/// Errors of the NMEA writer, configuration and endpoints.
#[derive(Debug, thiserror::Error)]
pub enum NmeaError {
    #[error("talker '{talker}' is not two upper-case letters or digits (e.g. GP, GN)")]
    InvalidTalker { talker: String },
    #[error("GPS fix {field} = {value} is outside {range}")]
    InvalidFix {
        field: &'static str,
        value: f64,
        range: &'static str,
    },
    #[error("NMEA configuration {field}: {reason}")]
    InvalidConfig { field: &'static str, reason: String },
    #[error(
        "{sentences:?} at {rate_hz} Hz does not fit {baud} baud: up to {bytes_per_epoch} bytes per epoch take {burst_ms:.1} ms at 8N1 but an epoch lasts {period_ms:.1} ms; needs at least {min_baud} baud"
    )]
    BaudTooLow {
        sentences: SentenceSet,
        rate_hz: f64,
        baud: u32,
        bytes_per_epoch: usize,
        burst_ms: f64,
        period_ms: f64,
        min_baud: u64,
    },
    #[error("UTC epoch plus sim time {sim_time_s} s is out of range")]
    TimeOutOfRange { sim_time_s: f64 },
    #[error(transparent)]
    Sentence(#[from] SentenceError),
    #[error("serial port {path}: {source}")]
    Serial {
        path: String,
        #[source]
        source: serialport::Error,
    },
    #[error("serial path {path:?} is not UTF-8")]
    NonUtf8Path { path: PathBuf },
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: io::Error,
    },
    #[error("pseudo-terminal {op}: {source}")]
    Pty {
        op: &'static str,
        #[source]
        source: nix::Error,
    },
    #[error("{path:?} exists and is not a symlink; refusing to replace it with the GPS pty link")]
    LinkOccupied { path: PathBuf },
}
