//! The physical SICK laser over Ethernet: the CoLa-A (ASCII) protocol of the LMS1xx,
//! LMS5xx and TiM scanners on TCP port 2111, a scanner emulation that serves
//! [`LaserFrame`]s ([`ColaServer`]) and a driver that turns a scanner's telegrams back
//! into [`LaserFrame`]s ([`ColaClient`]).
//!
//! # Wire format
//!
//! Every telegram is ASCII between STX (0x02) and ETX (0x03): a command type (`sRN`
//! read, `sRA` read answer, `sMN` method, `sAN` method answer, `sEN` event
//! registration, `sEA` its answer, `sSN` an event, `sFA` an error answer), a command
//! name, then the arguments, all separated by one space. Numbers are hexadecimal
//! (upper case, no leading zeros) unless written with a sign (`+10`, `-5`), which
//! makes them decimal; signed fields in hexadecimal are two's complement of their
//! width (`FFF92230` is -450000 for a 32-bit start angle). Floats (scale factors,
//! positions) are the 8 hex digits of their IEEE-754 single-precision bits. Strings
//! are a hex length, a space and that many bytes (so they may contain spaces:
//! `B not defined`).
//!
//! - [`framing`]: STX/ETX framing and a stream decoder ([`TelegramDecoder`]) for TCP
//!   reads of any size, with garbage between telegrams and an oversize bound.
//! - [`scandata`]: the `LMDscandata` telegram, every field of SICK's telegram listing,
//!   parsed into [`ScanData`] and encoded from it.
//! - [`message`]: the commands and answers the server and the driver exchange
//!   ([`Message`]) and SICK's `sFA` error codes ([`SopasError`]).
//! - [`convert`]: [`ScanData`] to and from [`LaserFrame`], with the angle and range
//!   conventions below.
//! - [`device`]: [`Device`], the scanner's behaviour as a pure state machine (user
//!   levels, one controlling client, every command's answer), testable without TCP.
//! - [`server`]: [`ColaServer`], a scanner on TCP that serves published frames, the
//!   threads and sockets around a [`Device`].
//! - [`client`]: [`ColaClient`], the driver of a scanner (physical, or a
//!   [`ColaServer`]).
//! - [`driver`]: the driver loop, a [`ColaClient`]'s scans onto an iceoryx2 laser
//!   service ([`driver::drive`]), for `ugv-sick` and the simulator.
//!
//! # Angles
//!
//! SICK reports angles in 1/10000 degree in the scanner's own frame, in which 90° is
//! straight ahead: an LMS1xx or a TiM5xx/7xx (270° field) scans from -45° to 225°, an
//! LMS5xx (190°) from -5° to 185°, counter-clockwise seen from above with the scanner
//! upright. The laser frame counts radians counter-clockwise from the scanner's
//! forward axis (REP 103), so
//!
//! ```text
//! frame angle (rad) = (SICK angle (deg) - 90) * pi / 180
//! SICK start angle  = round((angle_min (deg) + 90) * 10000)
//! SICK angular step = round(angle_increment (deg) * 10000)
//! ```
//!
//! An LMS111's `FFF92230` (-45°) start angle and `1388` (0.5°) step with 541 values
//! become `angle_min = -135°`, `angle_increment = 0.5°`, `angle_max = +135°`, the
//! frame the simulator publishes. A scanner mounted upside down scans clockwise in the
//! vehicle frame; that is a mounting calibration, not something the wire says.
//!
//! # Ranges
//!
//! A distance value `d` of a channel with scale factor `s` and offset `o` is
//! `d * s + o` millimetres (`s = 1`: mm, as LMS1xx and TiM; LMS5xx may use `s = 2`;
//! LMS4000 uses 0.1). SICK reserves the raw values below 16:
//!
//! | raw | SICK | laser frame |
//! |---|---|---|
//! | 0 | no echo, or target out of the measurement range | `f32::INFINITY` (no return) |
//! | 1..=15 | invalid: dazzled, blinded, reserved | `f32::NAN` (dropout) |
//! | >= 16 | a measurement | `(d * s + o) / 1000` metres |
//!
//! Encoding a frame: `INFINITY` is 0, `NAN` is 1 (SICK's "dazzled" code, so the
//! dropout survives the trip), a finite range outside `[range_min, range_max]` is 0
//! (a SICK scanner reports such targets as no echo) and so is one whose raw value
//! would fall below 16 or above 65535; any other range is `round(r * 1000 / s)`.
//! Decoded ranges are therefore within half a unit (0.5 mm at `s = 1`) of what was
//! encoded. Intensities travel in an `RSSI1` channel (8 or 16 bit, rounded and
//! clamped to the channel's width) when the configuration asks for one.
//!
//! # Times and sequence numbers
//!
//! The telegram's 16-bit scan counter carries the frame's `sequence` (modulo 2^16);
//! the driver unwraps it into a monotonic 64-bit sequence. When the telegram has the
//! optional time-stamp block (the server writes it by default), the frame's stamp is
//! that UTC time (microsecond resolution); otherwise the driver stamps the frame with
//! the host's receive time minus the scanner's own delay between the start of the
//! scan and its transmission (`time of transmission - time since start-up`).
//! `scan_time` is `100 / scan frequency`, `time_increment` is
//! `1 / (measurement frequency * 100)`.
//!
//! # Example
//!
//! The simulator serves its laser as an LMS111; a driver (or `ugv-sick`) reads it:
//!
//! ```
//! use std::time::Duration;
//! use firmware_bridge::cola::{ClientConfig, ColaClient, ColaServer, ServerConfig};
//! use firmware_bridge::laser::LaserFrame;
//!
//! let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111()).unwrap();
//! let address = server.local_addr().to_string();
//! let mut driver = ColaClient::connect(&address, ClientConfig::default()).unwrap();
//! assert_eq!(driver.device_ident().name, "LMS111");
//!
//! let mut frame = LaserFrame {
//!     sequence: 7,
//!     angle_min: -135f32.to_radians(),
//!     angle_increment: 0.5f32.to_radians(),
//!     scan_time: 0.02,
//!     time_increment: 0.02 / 720.0,
//!     range_min: 0.5,
//!     range_max: 20.0,
//!     ..LaserFrame::default()
//! };
//! frame.set_beams(&[1.2345, f32::INFINITY, f32::NAN], &[10.0, 0.0, 0.0]).unwrap();
//! assert_eq!(server.publish(&frame).unwrap(), 1); // queued for one client, never waits
//!
//! let got = driver.next_frame(Duration::from_secs(10)).unwrap().unwrap();
//! assert_eq!(got.sequence, 7);
//! assert!((got.ranges[0] - 1.2345).abs() <= 0.0005); // millimetres on the wire
//! assert!(got.ranges[1].is_infinite() && got.ranges[2].is_nan());
//! ```

pub mod client;
pub mod convert;
pub mod device;
pub mod driver;
pub mod framing;
pub mod message;
pub mod scandata;
pub mod server;

mod fields;

use std::time::Duration;

pub use client::{ClientConfig, ClientStats, ColaClient, DeviceIdent};
pub use convert::{
    ConvertError, DecodeOptions, EncodeOptions, RssiChannel, frame_from_scan, scan_from_frame,
};
pub use device::{Answer, Device, DeviceConfig, DeviceStats, SessionId, UserLevel};
pub use fields::{EncodeError, ParseError, ParseErrorKind};
pub use framing::{FrameError, TelegramDecoder, frame_telegram};
pub use message::{Message, SopasError};
pub use scandata::{Channel, DeviceTime, Encoder, Event, Position, ScanData, ScanKind};
pub use server::{ClientInfo, ColaServer, ServerConfig, ServerStats};

use crate::laser::LaserError;

/// The TCP port of CoLa-A on SICK scanners.
pub const DEFAULT_PORT: u16 = 2111;

/// Where an emulated scanner listens unless told otherwise: `127.0.0.1:2111`, loopback
/// only. CoLa-A has no encryption and SICK's passwords are public, so listening on
/// another interface is for a network you trust, and must be asked for.
pub const DEFAULT_LISTEN: std::net::SocketAddr = std::net::SocketAddr::V4(
    std::net::SocketAddrV4::new(std::net::Ipv4Addr::LOCALHOST, DEFAULT_PORT),
);

/// Password hash of the "authorized client" user level (level 3) of SICK scanners,
/// the one drivers log in with (`sMN SetAccessMode 03 F4724744`).
pub const AUTHORIZED_CLIENT_PASSWORD: u32 = 0xF472_4744;

/// Password hash of the "maintenance" user level (level 2).
pub const MAINTENANCE_PASSWORD: u32 = 0xB21A_CE26;

/// Password hash of the "service" user level (level 4).
pub const SERVICE_PASSWORD: u32 = 0x81BE_23AA;

/// Why a CoLa endpoint (server or driver) failed.
#[derive(Debug, thiserror::Error)]
pub enum ColaError {
    /// The address could not be resolved or names no socket address.
    #[error("CoLa address {address:?}: {reason}")]
    Address { address: String, reason: String },
    /// The server could not listen on its address.
    #[error("CoLa server: cannot listen on {address}: {source}")]
    Bind {
        address: String,
        source: std::io::Error,
    },
    /// No TCP connection to the scanner.
    #[error("cannot connect to the scanner at {address}: {source}")]
    Connect {
        address: String,
        source: std::io::Error,
    },
    /// A socket operation failed.
    #[error("scanner connection: {action}: {source}")]
    Io {
        action: &'static str,
        source: std::io::Error,
    },
    /// The scanner closed the connection.
    #[error("the scanner at {address} closed the connection")]
    ConnectionLost { address: String },
    /// No answer (or no scan) within the time allowed.
    #[error("no {waiting_for} from the scanner within {after:?}")]
    Timeout {
        waiting_for: String,
        after: Duration,
    },
    /// The scanner answered a request with `sFA`.
    #[error("the scanner refused {request:?}: {error}")]
    Device { request: String, error: SopasError },
    /// The scanner refused the login (`sAN SetAccessMode 0`): a wrong password, or
    /// (on the emulated scanner) another client in control.
    #[error(
        "the scanner refused the login as user level {level} (a wrong password, or another client is in control; a client that only reads needs no login)"
    )]
    AccessDenied { level: u8 },
    /// The scanner answered something else than the request called for.
    #[error("the scanner answered {answer:?} to {request:?}")]
    UnexpectedAnswer { request: String, answer: String },
    /// A telegram's framing was broken (too long, or cut off by a new STX).
    #[error("telegram framing: {0}")]
    Frame(#[from] FrameError),
    /// A telegram did not parse.
    #[error("telegram {command:?}: {error}")]
    Parse { command: String, error: ParseError },
    /// A message could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// A scan could not be converted to or from a laser frame.
    #[error(transparent)]
    Convert(#[from] ConvertError),
    /// A laser frame failed validation.
    #[error(transparent)]
    Laser(#[from] LaserError),
    /// A thread of the server could not be started.
    #[error("CoLa server: cannot start a thread: {0}")]
    Thread(std::io::Error),
}

/// The first bytes of a telegram as text, for error messages.
pub(crate) fn preview(payload: &[u8]) -> String {
    const MAX: usize = 40;
    let cut = payload.len().min(MAX);
    let mut s = String::from_utf8_lossy(&payload[..cut]).into_owned();
    if payload.len() > MAX {
        s.push_str("...");
    }
    s
}
