//! A CAN endpoint in lockstep: it hands out frames until it has every frame the other
//! side says it sent, and counts what it sends, so that neither side takes a tick
//! before the other side's frames of the tick before are in.
//!
//! SocketCAN delivers a frame to the other sockets after `write` returned (vcan queues
//! it for the network stack's softirq), so "sent" is not yet "there". In lockstep
//! ([`crate::lockstep`]) each side tells the other, with every tick or
//! acknowledgement, how many frames it has sent per CAN ID since the start
//! ([`CanCounts`]); a [`Gated`] endpoint that has not yet received its share of them
//! (the IDs its acceptance filter lets through) waits for them in `receive`, bounded in
//! wall time. The endpoints of one side share a [`Gate`]: what the other side said, and
//! what this side has sent (a simulator's steering ECU also hears its throttle ECU).

use std::cell::RefCell;
use std::io;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use embedded_can::Frame;

use super::{Filtered, QueueDrops};
use crate::lockstep::CanCounts;

/// How long a gated endpoint waits for frames it was told of before it gives up on
/// them (counted in [`Gated::waived`]): far beyond the microseconds vcan takes, short
/// enough that a lost frame costs one stall, not a hung run.
pub const GATE_TIMEOUT: Duration = Duration::from_secs(2);

/// What the other side said it sent, and what this side sent, shared by this side's
/// endpoints.
#[derive(Clone, Debug, Default)]
pub struct Gate(Arc<Mutex<GateState>>);

#[derive(Debug, Default)]
struct GateState {
    peer: CanCounts,
    side: CanCounts,
}

impl Gate {
    pub fn new() -> Gate {
        Gate::default()
    }

    fn state(&self) -> MutexGuard<'_, GateState> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The other side has sent `peer` (cumulative, from its last tick or
    /// acknowledgement): this side's endpoints hand out frames until they have them.
    pub fn expect(&self, peer: CanCounts) {
        self.state().peer = peer;
    }

    /// What this side's endpoints have sent since the start.
    pub fn sent(&self) -> CanCounts {
        self.state().side
    }

    /// The frames an endpoint accepting `accept` (all: `None`) is owed in all: the
    /// other side's and this side's other endpoints' (all this side's, less `own`).
    fn owed(&self, accept: Option<&[u16]>, own: &CanCounts) -> u64 {
        let s = self.state();
        (s.peer.accepted(accept) + s.side.accepted(accept)).saturating_sub(own.accepted(accept))
    }
}

/// A raw SocketCAN socket, gated.
pub type GatedSocket = Gated<socketcan::CanSocket>;

/// An endpoint `B` that, given a [`Gate`], receives until it has what it is owed. Without
/// a gate it is `B` as it is.
#[derive(Debug)]
pub struct Gated<B> {
    inner: B,
    gate: Option<Gate>,
    /// The acceptance filter last set (`None`: every ID).
    accept: RefCell<Option<Vec<u16>>>,
    /// Frames handed out, in all.
    received: u64,
    /// Frames given up on after [`GATE_TIMEOUT`].
    waived: u64,
    /// Frames this endpoint sent, per ID.
    own: CanCounts,
}

impl<B> Gated<B> {
    pub fn new(inner: B, gate: Option<Gate>) -> Gated<B> {
        Gated {
            inner,
            gate,
            accept: RefCell::new(None),
            received: 0,
            waived: 0,
            own: CanCounts::default(),
        }
    }

    pub fn inner(&self) -> &B {
        &self.inner
    }

    /// Whether it is in lockstep.
    pub fn gated(&self) -> bool {
        self.gate.is_some()
    }

    /// Frames this endpoint was told of but that did not come within [`GATE_TIMEOUT`].
    pub fn waived(&self) -> u64 {
        self.waived
    }

    /// Frames still to come, by what the gate says.
    fn short(&self) -> u64 {
        let Some(gate) = &self.gate else {
            return 0;
        };
        let accept = self.accept.borrow();
        gate.owed(accept.as_deref(), &self.own)
            .saturating_sub(self.received + self.waived)
    }
}

impl<B: embedded_can::nb::Can> embedded_can::nb::Can for Gated<B> {
    type Frame = B::Frame;
    type Error = B::Error;

    fn transmit(&mut self, frame: &B::Frame) -> nb::Result<Option<B::Frame>, B::Error> {
        let r = self.inner.transmit(frame)?;
        if let Some(gate) = &self.gate {
            let id = CanCounts::key(frame.id());
            self.own.add(id);
            gate.state().side.add(id);
        }
        Ok(r)
    }

    fn receive(&mut self) -> nb::Result<B::Frame, B::Error> {
        let mut deadline = None;
        loop {
            match self.inner.receive() {
                Ok(frame) => {
                    self.received += 1;
                    return Ok(frame);
                }
                Err(nb::Error::WouldBlock) => {
                    let short = self.short();
                    if short == 0 {
                        return Err(nb::Error::WouldBlock);
                    }
                    let until = *deadline.get_or_insert_with(|| Instant::now() + GATE_TIMEOUT);
                    if Instant::now() >= until {
                        self.waived += short;
                        return Err(nb::Error::WouldBlock);
                    }
                    std::thread::sleep(Duration::from_micros(20));
                }
                Err(e) => return Err(e),
            }
        }
    }
}

impl<B: Filtered> Filtered for Gated<B> {
    fn set_acceptance(&self, ids: &[u16]) -> io::Result<()> {
        self.inner.set_acceptance(ids)?;
        *self.accept.borrow_mut() = Some(ids.to_vec());
        Ok(())
    }
}

impl<B: QueueDrops> QueueDrops for Gated<B> {
    fn queue_drops(&self) -> Option<u32> {
        self.inner.queue_drops()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::membus::{MemBus, MemFrame};
    use embedded_can::StandardId;
    use embedded_can::nb::Can;

    fn frame(id: u16) -> MemFrame {
        let id = StandardId::new(id).expect("a standard id");
        MemFrame::new(id, &[1, 2]).expect("a frame")
    }

    #[test]
    fn a_gated_endpoint_waits_for_what_it_is_owed_and_no_more() {
        let bus = MemBus::new();
        let gate = Gate::new();
        let mut sender = bus.endpoint();
        let mut rx = Gated::new(bus.endpoint(), Some(gate.clone()));
        rx.set_acceptance(&[0x100]).expect("a filter");
        // Nothing owed: an empty bus answers at once.
        assert!(matches!(rx.receive(), Err(nb::Error::WouldBlock)));
        // The other side says it sent two 0x100 and one 0x200 (not accepted): one
        // is there, the other never comes and is waived after the timeout.
        let mut peer = CanCounts::default();
        for id in [0x100, 0x100, 0x200] {
            peer.add(id);
        }
        gate.expect(peer);
        sender.transmit(&frame(0x100)).expect("sent");
        assert!(rx.receive().is_ok());
        let t = Instant::now();
        assert!(matches!(rx.receive(), Err(nb::Error::WouldBlock)));
        assert!(t.elapsed() >= GATE_TIMEOUT, "{:?}", t.elapsed());
        assert_eq!(rx.waived(), 1);
        // Waived frames are not waited for again.
        assert!(matches!(rx.receive(), Err(nb::Error::WouldBlock)));
        assert_eq!(rx.waived(), 1);
    }

    #[test]
    fn endpoints_of_one_side_owe_each_other_what_they_sent() {
        let bus = MemBus::new();
        let gate = Gate::new();
        let mut a = Gated::new(bus.endpoint(), Some(gate.clone()));
        let mut b = Gated::new(bus.endpoint(), Some(gate.clone()));
        a.transmit(&frame(0x10)).expect("sent");
        a.transmit(&frame(0x11)).expect("sent");
        assert_eq!(gate.sent().accepted(None), 2);
        // b is owed a's two frames, a nothing of its own.
        assert_eq!(b.short(), 2);
        assert_eq!(a.short(), 0);
        assert!(b.receive().is_ok() && b.receive().is_ok());
        assert_eq!(b.short(), 0);
        assert!(matches!(b.receive(), Err(nb::Error::WouldBlock)));
    }

    #[test]
    fn without_a_gate_an_endpoint_is_its_bus() {
        let bus = MemBus::new();
        let mut tx = bus.endpoint();
        let mut rx = Gated::new(bus.endpoint(), None);
        assert!(matches!(rx.receive(), Err(nb::Error::WouldBlock)));
        tx.transmit(&frame(0x10)).expect("sent");
        assert!(rx.receive().is_ok());
        assert_eq!(rx.short(), 0);
    }
}
