//! The simulator's transmissions on a SocketCAN interface paced at the bus's bit rate.
//!
//! vcan has no bit rate: every frame arrives the instant it is sent, so a schedule
//! that would overload a 500 kbit/s bus passes silently. A [`Pacer`] shared by the
//! simulator's sockets (see [`super::timed::TimedSocket::paced`]) puts each frame they
//! send on the timeline of [`super::arbiter`] first: it goes onto the interface when it
//! wins the bus (the lowest identifier among those waiting), and holds the bus for its
//! worst-case bit time; the frames of other nodes seen on the interface (the
//! controller's, a gateway's) hold it for theirs. An overloaded schedule then shows up
//! as frames that waited ([`ArbitrationStats`]), as the memory bus shows it in SIL.
//!
//! The simulator sends in ticks: a frame whose turn comes before the next tick
//! (`lookahead`) goes at once, so a bus that keeps up adds no delay; the frames the
//! bus cannot carry by then wait for a later tick.

use std::collections::{HashSet, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::SystemTime;

use embedded_can::Frame;
use socketcan::CanFrame;

use super::arbiter::{Arbiter, ArbitrationStats, Release};
use crate::clock::unix_ns;
use crate::sync::lock;

#[derive(Debug)]
struct Timeline {
    arbiter: Arbiter<CanFrame>,
    /// The real-time clock at time 0 of the timeline, ns.
    origin_ns: u64,
    lookahead: f64,
    /// Per node: frames that won the bus and wait for their socket to send them.
    outboxes: Vec<VecDeque<CanFrame>>,
    /// Identifiers the paced nodes send: seen on the interface, they are not foreign.
    own_ids: HashSet<u32>,
}

impl Timeline {
    fn time(&self, unix: u64) -> f64 {
        unix.saturating_sub(self.origin_ns) as f64 * 1e-9
    }

    fn advance(&mut self, t: f64) {
        let Timeline {
            arbiter, outboxes, ..
        } = self;
        arbiter.advance_to(t + self.lookahead, |from, frame| {
            if let Some(outbox) = outboxes.get_mut(from) {
                outbox.push_back(frame);
            }
        });
    }
}

fn raw_id(frame: &CanFrame) -> u32 {
    match frame.id() {
        embedded_can::Id::Standard(s) => u32::from(s.as_raw()),
        embedded_can::Id::Extended(e) => e.as_raw() | 0x8000_0000,
    }
}

/// The bus time shared by the simulator's paced sockets on one interface.
#[derive(Clone, Debug)]
pub struct Pacer(Arc<Mutex<Timeline>>);

impl Pacer {
    /// A bus at `bit_rate` bit/s whose senders come back every `lookahead` seconds.
    pub fn new(bit_rate: u32, lookahead: f64) -> Pacer {
        Pacer(Arc::new(Mutex::new(Timeline {
            arbiter: Arbiter::new(bit_rate, Release::AtStart),
            origin_ns: unix_ns(SystemTime::now()),
            lookahead: lookahead.max(0.0),
            outboxes: Vec::new(),
            own_ids: HashSet::new(),
        })))
    }

    /// A new sending node; its number goes with its frames.
    pub(super) fn node(&self) -> usize {
        let mut t = lock(&self.0);
        t.outboxes.push(VecDeque::new());
        t.outboxes.len() - 1
    }

    /// Node `node` sends `frame` now.
    pub(super) fn submit(&self, node: usize, frame: CanFrame) {
        let mut t = lock(&self.0);
        let now = t.time(unix_ns(SystemTime::now()));
        t.own_ids.insert(raw_id(&frame));
        t.arbiter.submit(now, node, frame);
        t.advance(now);
    }

    /// The frames of `node` whose turn has come, oldest first.
    pub(super) fn take(&self, node: usize) -> Vec<CanFrame> {
        let mut t = lock(&self.0);
        let now = t.time(unix_ns(SystemTime::now()));
        t.advance(now);
        t.outboxes
            .get_mut(node)
            .map(|o| o.drain(..).collect())
            .unwrap_or_default()
    }

    /// A frame that could not be sent yet goes back to the front of its node's queue.
    pub(super) fn put_back(&self, node: usize, frames: impl DoubleEndedIterator<Item = CanFrame>) {
        let mut t = lock(&self.0);
        if let Some(outbox) = t.outboxes.get_mut(node) {
            for f in frames.rev() {
                outbox.push_front(f);
            }
        }
    }

    /// A frame received from the interface at `unix` ns (the kernel's time): if no
    /// paced node sends its identifier, it held the bus for its bits.
    pub(super) fn seen(&self, frame: &CanFrame, unix: u64) {
        let mut t = lock(&self.0);
        if !t.own_ids.contains(&raw_id(frame)) {
            let end = t.time(unix);
            t.arbiter.occupy(end, frame.is_extended(), frame.dlc());
        }
    }

    /// What the bus did so far.
    pub fn stats(&self) -> ArbitrationStats {
        lock(&self.0).arbiter.stats()
    }
}
