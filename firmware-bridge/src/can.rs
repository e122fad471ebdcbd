//! A SocketCAN endpoint speaking golf_car.dbc: typed messages out with the E2E
//! counter and CRC filled in, frames in checked for E2E and decoded.
//!
//! The same endpoint serves vcan0 (simulated devices) and can0 or a USB adapter
//! (physical ones): the controller never knows which.

use std::io;
use std::time::Duration;

use embedded_can::{Frame, Id, StandardId};
use golf_car_can::{
    CanMessage, CodecError, E2eError, E2eRx, E2eStats, E2eTx, GolfCarMessage, NETWORK, Payload,
};
use socketcan::{CanFrame, CanSocket, Socket};

/// Errors of the CAN endpoint.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(
        "CAN interface {iface} does not exist; create it with `vcan-setup up {iface}` (see `vcan-setup status`)"
    )]
    NoInterface { iface: String },
    #[error("CAN interface {iface}: {source}")]
    Io {
        iface: String,
        #[source]
        source: io::Error,
    },
    #[error("encoding {message}: {source}")]
    Encode {
        message: &'static str,
        #[source]
        source: CodecError,
    },
    #[error("CAN ID {id:#x} is not an 11-bit ID")]
    BadId { id: u16 },
}

/// What arrived on the bus.
#[derive(Debug, Clone, PartialEq)]
pub enum Received {
    /// A frame that passed the E2E check and decoded.
    Message(GolfCarMessage),
    /// A frame the E2E check rejected (counted in [`CanPort::stats`]).
    Rejected(E2eError),
    /// A frame that passed E2E but whose signals do not decode (a value outside its table).
    Undecodable { id: u16, error: CodecError },
    /// A CAN error frame from the controller.
    ErrorFrame(String),
}

/// A SocketCAN endpoint on one interface.
#[derive(Debug)]
pub struct CanPort {
    iface: String,
    socket: CanSocket,
    tx: E2eTx,
    rx: E2eRx<'static>,
    undecodable: u64,
}

impl CanPort {
    /// Open a raw CAN socket on `iface` (vcan0, can0, ...).
    pub fn open(iface: &str) -> Result<Self, BridgeError> {
        let socket = CanSocket::open(iface).map_err(|source| match source.raw_os_error() {
            Some(libc::ENODEV) => BridgeError::NoInterface {
                iface: iface.to_owned(),
            },
            _ => BridgeError::Io {
                iface: iface.to_owned(),
                source,
            },
        })?;
        Ok(Self {
            iface: iface.to_owned(),
            socket,
            tx: E2eTx::new(),
            rx: E2eRx::new(&NETWORK),
            undecodable: 0,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    fn io(&self, source: io::Error) -> BridgeError {
        BridgeError::Io {
            iface: self.iface.clone(),
            source,
        }
    }

    /// Send a typed message, protected with the ID's next counter and the CRC.
    pub fn send<M: CanMessage>(&mut self, message: &M) -> Result<(), BridgeError> {
        let data = self
            .tx
            .seal_message(message)
            .map_err(|source| BridgeError::Encode {
                message: M::NAME,
                source,
            })?;
        self.send_payload(M::ID, &data)
    }

    /// Send a payload exactly as given (no E2E added): for gateways and fault injection.
    pub fn send_payload(&self, id: u16, data: &Payload) -> Result<(), BridgeError> {
        let sid = StandardId::new(id).ok_or(BridgeError::BadId { id })?;
        let frame = CanFrame::new(sid, data).ok_or(BridgeError::BadId { id })?;
        self.socket
            .write_frame_insist(&frame)
            .map_err(|e| self.io(e))
    }

    /// Wait up to `timeout` for a frame; `None` when none came.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, BridgeError> {
        let frame = match self.socket.read_frame_timeout(timeout) {
            Ok(frame) => frame,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(None);
            }
            Err(e) => return Err(self.io(e)),
        };
        if let CanFrame::Error(err) = &frame {
            return Ok(Some(Received::ErrorFrame(format!(
                "{:?}",
                err.into_error()
            ))));
        }
        let (id, extended) = match frame.id() {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        let checked = self
            .rx
            .accept_parts(id, extended, frame.is_remote_frame(), frame.data());
        Ok(Some(match checked {
            Err(e) => Received::Rejected(e),
            Ok((id, payload)) => match GolfCarMessage::decode(id, &payload) {
                Ok(m) => Received::Message(m),
                Err(error) => {
                    self.undecodable += 1;
                    Received::Undecodable { id, error }
                }
            },
        }))
    }

    /// The receiver's E2E statistics.
    pub fn stats(&self) -> E2eStats {
        self.rx.stats()
    }

    /// Frames that passed E2E but did not decode.
    pub fn undecodable(&self) -> u64 {
        self.undecodable
    }
}
