//! An in-memory CAN bus for SIL runs: every endpoint implements
//! `embedded_can::nb::Can`, a frame sent by one endpoint reaches every other one in
//! order (like a raw CAN socket, not the sender itself), and frames are the same
//! bytes the wire would carry.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use embedded_can::{ErrorKind, Frame, Id};

use crate::sync::lock;

/// A classic CAN data or remote frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemFrame {
    id: Id,
    remote: bool,
    dlc: usize,
    data: [u8; 8],
}

impl Frame for MemFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() > 8 {
            return None;
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Some(MemFrame {
            id: id.into(),
            remote: false,
            dlc: data.len(),
            data: buf,
        })
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        (dlc <= 8).then(|| MemFrame {
            id: id.into(),
            remote: true,
            dlc,
            data: [0; 8],
        })
    }

    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        self.dlc
    }

    fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..self.dlc]
        }
    }
}

/// The bus never fails; the error type exists for the trait.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemBusError;

impl embedded_can::Error for MemBusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

#[derive(Debug, Default)]
struct Hub {
    inboxes: Vec<VecDeque<MemFrame>>,
}

/// The bus: hands out endpoints.
#[derive(Clone, Debug, Default)]
pub struct MemBus {
    hub: Arc<Mutex<Hub>>,
}

impl MemBus {
    pub fn new() -> MemBus {
        MemBus::default()
    }

    /// A new node on the bus.
    pub fn endpoint(&self) -> MemEndpoint {
        let mut hub = lock(&self.hub);
        hub.inboxes.push(VecDeque::new());
        MemEndpoint {
            hub: Arc::clone(&self.hub),
            index: hub.inboxes.len() - 1,
        }
    }
}

/// One node's connection to a [`MemBus`].
#[derive(Debug)]
pub struct MemEndpoint {
    hub: Arc<Mutex<Hub>>,
    index: usize,
}

impl embedded_can::nb::Can for MemEndpoint {
    type Frame = MemFrame;
    type Error = MemBusError;

    fn transmit(&mut self, frame: &MemFrame) -> nb::Result<Option<MemFrame>, MemBusError> {
        let mut hub = lock(&self.hub);
        for (i, inbox) in hub.inboxes.iter_mut().enumerate() {
            if i != self.index {
                inbox.push_back(frame.clone());
            }
        }
        Ok(None)
    }

    fn receive(&mut self) -> nb::Result<MemFrame, MemBusError> {
        let mut hub = lock(&self.hub);
        hub.inboxes
            .get_mut(self.index)
            .and_then(VecDeque::pop_front)
            .ok_or(nb::Error::WouldBlock)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::{CanPort, Received};
    use golf_car_can::{CanMessage, GolfCarMessage, SteeringCmd};

    #[test]
    fn frames_reach_every_other_endpoint_in_order_through_e2e() {
        let bus = MemBus::new();
        let mut a = CanPort::new(bus.endpoint(), "mem");
        let mut b = CanPort::new(bus.endpoint(), "mem");
        let mut c = CanPort::new(bus.endpoint(), "mem");
        for i in 0..20 {
            a.send(&SteeringCmd {
                enable: true,
                target_angle: f64::from(i),
                max_rate: 10.0,
            })
            .expect("send");
        }
        assert!(a.try_recv().is_none(), "the sender does not hear itself");
        for port in [&mut b, &mut c] {
            for i in 0..20 {
                match port.try_recv() {
                    Some(Received::Message(GolfCarMessage::SteeringCmd(m))) => {
                        assert!((m.target_angle - f64::from(i)).abs() < 1e-9)
                    }
                    other => panic!("expected command {i}, got {other:?}"),
                }
            }
            assert!(port.try_recv().is_none());
            assert_eq!(port.stats().accepted, 20);
        }
    }

    #[test]
    fn replayed_payloads_are_rejected_on_the_memory_bus_too() {
        let bus = MemBus::new();
        let mut a = CanPort::new(bus.endpoint(), "mem");
        let mut b = CanPort::new(bus.endpoint(), "mem");
        let mut tx = golf_car_can::E2eTx::new();
        let data = tx.seal_message(&SteeringCmd::default()).expect("encode");
        a.send_payload(SteeringCmd::ID, &data).expect("send");
        a.send_payload(SteeringCmd::ID, &data).expect("send");
        assert!(matches!(b.try_recv(), Some(Received::Message(_))));
        assert!(matches!(b.try_recv(), Some(Received::Rejected(_))));
    }
}
