//! The device seam: the wire formats and their endpoints, used by the simulator and
//! the controller alike, so a device can be simulated or physical without either
//! side knowing.
//!
//! - [`can`]: a SocketCAN endpoint that speaks golf_car.dbc with E2E protection.
//! - [`nmea`]: the GPS wire, NMEA 0183 writer and reader, serial and pty endpoints.
//! - [`laser`]: the laser scan frame and its iceoryx2 publisher/subscriber.
//! - [`cola`]: the physical SICK laser over Ethernet (CoLa-A): scan telegrams, a
//!   scanner emulation serving laser frames, and the driver behind `ugv-sick`.
//! - [`gateway`]: the CAN gateway (`ugv-bridge`) between the simulator's bus and a
//!   physical one, routed by the DBC's senders and receivers.
//! - [`geodesy`]: WGS-84 conversions between the world (ENU) frame and latitude/longitude.
//! - [`cli`]: bounded number parsers for the binaries' command lines.
//! - [`sync`]: the poison-tolerant lock of the threads' shared counters and lists.

pub mod can;
pub mod cli;
pub mod clock;
pub mod cola;
pub mod gateway;
pub mod geodesy;
pub mod laser;
pub mod lockstep;
pub mod nmea;
pub mod realtime;
pub mod sync;

pub use can::{BridgeError, CanPort, Received};
pub use geodesy::{Enu, Geodetic, LocalFrame};
pub use laser::{LaserError, LaserFrame, LaserPublisher, LaserSubscriber};
pub use nmea::{GpsFix, GpsReading, NmeaError, NmeaReader, NmeaWriter};
