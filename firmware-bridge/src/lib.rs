//! The device seam: the wire formats and their endpoints, used by the simulator and
//! the controller alike, so a device can be simulated or physical without either
//! side knowing.
//!
//! - [`can`]: a SocketCAN endpoint that speaks golf_car.dbc with E2E protection.

pub mod can;

pub use can::{BridgeError, CanPort, Received};
