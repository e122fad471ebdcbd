//! An in-memory CAN bus for SIL runs: every endpoint implements
//! `embedded_can::nb::Can`, a frame sent by one endpoint reaches every other one in
//! order (like a raw CAN socket, not the sender itself), and frames are the same
//! bytes the wire would carry.
//!
//! A bus made with [`MemBus::timed`] also has the wire's time ([`super::arbiter`]): a
//! sent frame waits for the bus, the lowest identifier wins it, and the other nodes
//! receive it after its worst-case bit time. The run moves the bus's time on with
//! [`MemBus::advance_to`]; an overloaded schedule then shows up as frames that waited
//! ([`ArbitrationStats`]), as on a real bus.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use embedded_can::{ErrorKind, Frame, Id};

use super::arbiter::{Arbiter, ArbitrationStats, Release};

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

/// The wire's time of a timed bus: its arbitration, and the time it has reached
/// (frames sent from then on are ready then).
#[derive(Debug)]
struct Wire {
    now: f64,
    arbiter: Arbiter<MemFrame>,
}

/// A node's connection: the frames waiting for it, and its acceptance filter.
#[derive(Debug, Default)]
struct Inbox {
    frames: VecDeque<MemFrame>,
    /// The standard IDs it accepts; every frame when `None`.
    accepts: Option<Vec<u16>>,
}

impl Inbox {
    fn accepts(&self, frame: &MemFrame) -> bool {
        super::accepted(self.accepts.as_deref(), frame.id)
    }
}

#[derive(Debug, Default)]
struct Hub {
    inboxes: Vec<Inbox>,
    wire: Option<Wire>,
}

/// `frame` from node `from` into every other node's inbox that accepts it.
fn deliver(inboxes: &mut [Inbox], from: usize, frame: &MemFrame) {
    for (i, inbox) in inboxes.iter_mut().enumerate() {
        if i != from && inbox.accepts(frame) {
            inbox.frames.push_back(frame.clone());
        }
    }
}

impl Hub {
    /// Run the wire up to time `t`: the frames that finished by then reach the
    /// other nodes.
    fn advance_to(&mut self, t: f64) {
        let Hub { inboxes, wire } = self;
        if let Some(wire) = wire {
            wire.now = wire.now.max(t);
            wire.arbiter
                .advance_to(t, |from, frame| deliver(inboxes, from, &frame));
        }
    }
}

/// The bus: hands out endpoints.
#[derive(Clone, Debug, Default)]
pub struct MemBus {
    hub: Arc<Mutex<Hub>>,
}

impl MemBus {
    /// A bus without time: a frame reaches the others as it is sent.
    pub fn new() -> MemBus {
        MemBus::default()
    }

    /// A bus with the wire's time at `bit_rate` bit/s, from time 0 (see the module).
    pub fn timed(bit_rate: u32) -> MemBus {
        let bus = MemBus::default();
        lock(&bus.hub).wire = Some(Wire {
            now: 0.0,
            arbiter: Arbiter::new(bit_rate, Release::AtEnd),
        });
        bus
    }

    /// Move a timed bus's time on to `t` seconds: the frames that finished by then
    /// reach the other nodes; frames sent from now on are ready at `t`. Nothing on a
    /// bus without time.
    pub fn advance_to(&self, t: f64) {
        lock(&self.hub).advance_to(t);
    }

    /// What the arbitration of a timed bus did (none for a bus without time).
    pub fn arbitration(&self) -> Option<ArbitrationStats> {
        lock(&self.hub).wire.as_ref().map(|w| w.arbiter.stats())
    }

    /// A new node on the bus.
    pub fn endpoint(&self) -> MemEndpoint {
        let mut hub = lock(&self.hub);
        hub.inboxes.push(Inbox::default());
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
        match &mut hub.wire {
            Some(wire) => wire.arbiter.submit(wire.now, self.index, frame.clone()),
            None => deliver(&mut hub.inboxes, self.index, frame),
        }
        Ok(None)
    }

    fn receive(&mut self) -> nb::Result<MemFrame, MemBusError> {
        let mut hub = lock(&self.hub);
        hub.inboxes
            .get_mut(self.index)
            .and_then(|inbox| inbox.frames.pop_front())
            .ok_or(nb::Error::WouldBlock)
    }
}

/// An inbox grows as needed: nothing is lost.
impl super::QueueDrops for MemEndpoint {
    fn queue_drops(&self) -> Option<u32> {
        None
    }
}

impl super::Filtered for MemEndpoint {
    fn set_acceptance(&self, ids: &[u16]) -> std::io::Result<()> {
        if let Some(inbox) = lock(&self.hub).inboxes.get_mut(self.index) {
            inbox.accepts = Some(ids.to_vec());
        }
        Ok(())
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
    fn an_acceptance_filter_keeps_other_ids_from_an_endpoint_only() {
        let bus = MemBus::new();
        let mut a = CanPort::new(bus.endpoint(), "mem");
        let mut filtered = CanPort::new(bus.endpoint(), "mem");
        let mut open = CanPort::new(bus.endpoint(), "mem");
        filtered.accept_only(&[SteeringCmd::ID]).expect("filter");
        a.send_payload(0x000, &[0xff; 8]).expect("send");
        a.send(&SteeringCmd::default()).expect("send");
        a.send_payload(0x555, &[0xff; 8]).expect("send");
        assert!(matches!(
            filtered.try_recv(),
            Some(Received::Message(GolfCarMessage::SteeringCmd(_)))
        ));
        assert!(filtered.try_recv().is_none());
        assert_eq!(filtered.stats().unknown_id, 0);
        let mut heard = 0;
        while open.try_recv().is_some() {
            heard += 1;
        }
        assert_eq!(heard, 3, "an endpoint without a filter hears every frame");
        assert_eq!(open.stats().unknown_id, 2);
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

    fn frame(id: u16) -> MemFrame {
        MemFrame::new(embedded_can::StandardId::new(id).expect("11-bit"), &[0; 8]).expect("frame")
    }

    fn ids(e: &mut MemEndpoint) -> Vec<u16> {
        use embedded_can::nb::Can;
        let mut out = Vec::new();
        while let Ok(f) = e.receive() {
            if let Id::Standard(s) = f.id() {
                out.push(s.as_raw());
            }
        }
        out
    }

    #[test]
    fn a_timed_bus_delivers_after_the_bit_time_and_the_lowest_id_wins() {
        use embedded_can::nb::Can;
        let bus = MemBus::timed(500_000);
        let (mut a, mut b, mut rx) = (bus.endpoint(), bus.endpoint(), bus.endpoint());
        // At t = 0 two frames wait: 0x300 from a, then 0x100 from b.
        a.transmit(&frame(0x300)).expect("send");
        b.transmit(&frame(0x100)).expect("send");
        assert!(
            ids(&mut rx).is_empty(),
            "nothing arrives before the bus moves"
        );
        // One 8-byte frame takes 135 bits = 270 us at 500 kbit/s.
        bus.advance_to(0.000_269);
        assert!(
            ids(&mut rx).is_empty(),
            "the first frame is still on the bus"
        );
        bus.advance_to(0.000_270);
        assert_eq!(
            ids(&mut rx),
            vec![0x100],
            "the lower ID won the arbitration"
        );
        assert_eq!(ids(&mut a), vec![0x100], "the loser hears the winner");
        assert!(ids(&mut b).is_empty(), "the sender does not hear itself");
        bus.advance_to(0.000_541);
        assert_eq!(ids(&mut rx), vec![0x300]);
        let s = bus.arbitration().expect("timed");
        assert_eq!((s.delivered, s.late, s.backlog), (2, 0, 0));
        assert!((s.max_wait_ms - 0.27).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn an_overloaded_timed_bus_makes_the_low_priority_frames_late() {
        use embedded_can::nb::Can;
        let bus = MemBus::timed(500_000);
        let (mut babbler, mut node, mut rx) = (bus.endpoint(), bus.endpoint(), bus.endpoint());
        // 10 ms steps; each step the babbler sends 50 frames of ID 0 (13.5 ms of bus
        // time), the node one of ID 0x200.
        for k in 0..20 {
            bus.advance_to(f64::from(k) * 0.01);
            for _ in 0..50 {
                babbler.transmit(&frame(0)).expect("send");
            }
            node.transmit(&frame(0x200)).expect("send");
        }
        bus.advance_to(0.2);
        let got = ids(&mut rx);
        assert!(
            !got.contains(&0x200),
            "ID 0x200 never wins against the flood"
        );
        let s = bus.arbitration().expect("timed");
        assert!(s.backlog > 20, "the bus falls behind: {s:?}");
        assert!(s.late > 0 && s.max_wait_ms > 10.0, "{s:?}");
    }

    #[test]
    fn a_bus_without_time_delivers_at_once() {
        use embedded_can::nb::Can;
        let bus = MemBus::new();
        let (mut a, mut rx) = (bus.endpoint(), bus.endpoint());
        a.transmit(&frame(0x123)).expect("send");
        assert_eq!(ids(&mut rx), vec![0x123]);
        bus.advance_to(1.0);
        assert_eq!(bus.arbitration(), None);
    }
}
