//! The recorder's ear on the bus: a node of its own that only listens, so it sees
//! every frame the simulator's ECUs send and every frame they receive, in bus order.
//! In SIL a memory-bus endpoint; in HIL a CAN socket on the interface with kernel
//! receive timestamps (`SO_TIMESTAMPNS`), as candump takes them.

use firmware_bridge::can::QueueDrops;
pub use firmware_bridge::can::TapFrame;
use firmware_bridge::can::gated::{Gate, Gated};
use socketcan::{CanSocket, Socket, SocketOptions};

/// Takes what arrived since the last call, never blocking; its queue drops are the
/// frames the recording lacks.
pub trait BusTap: QueueDrops {
    fn drain(&mut self, into: &mut Vec<TapFrame>) -> std::io::Result<()>;
}

impl BusTap for firmware_bridge::can::membus::MemEndpoint {
    fn drain(&mut self, into: &mut Vec<TapFrame>) -> std::io::Result<()> {
        use embedded_can::nb::Can;
        while let Ok(f) = self.receive() {
            into.push(TapFrame::of(&f, None));
        }
        Ok(())
    }
}

/// A listening CAN socket with kernel timestamps; in lockstep, gated (see
/// firmware_bridge::can::gated) and stamped with the simulator's time, so that a
/// recording takes the same frames at the same steps in every run.
#[derive(Debug)]
pub struct SocketTap {
    socket: Gated<CanSocket>,
}

impl SocketTap {
    /// Listen on `iface`, with a deep receive queue so that a stalled recorder loses
    /// no frame ([`firmware_bridge::can::DEEP_QUEUE_BYTES`]); in lockstep through
    /// `gate`.
    pub fn open(iface: &str, gate: Option<Gate>) -> std::io::Result<SocketTap> {
        let socket = CanSocket::open(iface)?;
        socket.set_nonblocking(true)?;
        socket.set_recv_timestamp(true)?;
        firmware_bridge::can::set_receive_queue(&socket, firmware_bridge::can::DEEP_QUEUE_BYTES)?;
        Ok(SocketTap {
            socket: Gated::new(socket, gate),
        })
    }
}

impl BusTap for SocketTap {
    fn drain(&mut self, into: &mut Vec<TapFrame>) -> std::io::Result<()> {
        if self.socket.gated() {
            use embedded_can::nb::Can;
            return loop {
                match self.socket.receive() {
                    Ok(f) => into.push(TapFrame::of(&f, None)),
                    Err(nb::Error::WouldBlock) => break Ok(()),
                    Err(nb::Error::Other(e)) => break Err(std::io::Error::other(e)),
                }
            };
        }
        loop {
            match self.socket.inner().read_frame_with_timestamp() {
                Ok((f, at)) => into.push(TapFrame::of(&f, Some(at))),
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(()),
                Err(e) => return Err(e),
            }
        }
    }
}

impl QueueDrops for SocketTap {
    fn queue_drops(&self) -> Option<u32> {
        self.socket.inner().queue_drops()
    }
}
