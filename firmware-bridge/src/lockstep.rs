//! The clock wire of lockstep HIL: the simulator's ticks to the controller, the
//! controller's acknowledgements back, over iceoryx2 next to the laser's service.
//!
//! In lockstep the controller binary runs on the simulator's time. After each physics
//! step that is a controller tick, the simulator (the leader) publishes a
//! [`ClockTick`] on `ugv-hil/<run id>/clock`: the tick's index and what it has put on
//! the wires since the start (NMEA bytes on the GPS line, CAN frames per ID). The
//! controller (the follower) takes the tick, reads its ports until it has all of that
//! (a pty and vcan hand bytes and frames on a little after the writer's call returned;
//! iceoryx2 hands a laser frame over within the publisher's call, so the laser needs
//! no count), runs its tick, sends its frames, and publishes a [`ClockAck`] on
//! `ugv-hil/<run id>/clock-ack` with the CAN frames it has sent per ID. The simulator
//! steps on only then, and its ECUs read until they have those frames (the gated
//! CAN endpoints of `can::gated`). So every input of a tick is in before the tick is taken,
//! by construction, and a run gives the same result however slow or loaded the
//! machine: docs/wire-contract.md, "Lockstep".
//!
//! Each direction is a publish-subscribe service and an event service of the same name
//! (the wake-up), both `ipc_threadsafe`, with the QoS of [`open_services`]; either side
//! may create them.

use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

type Svc = ipc_threadsafe::Service;

/// How often a leader waiting for an answer hands its last tick to receivers that
/// connected since it went out.
const REFRESH_EVERY: Duration = Duration::from_millis(20);

/// Distinct CAN IDs a [`CanCounts`] tells apart; frames of further IDs are counted
/// together ([`CanCounts::other`]).
pub const MAX_CAN_IDS: usize = 16;

/// CAN frames sent since the start, per ID (standard IDs as they are, extended ones
/// with bit 31 set: [`CanCounts::key`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("ugv_hil::CanCounts::v1")]
pub struct CanCounts {
    /// Frames of `ids[i]`, for `i < len`.
    pub counts: [u64; MAX_CAN_IDS],
    /// Frames of IDs beyond the table's [`MAX_CAN_IDS`].
    pub other: u64,
    pub ids: [u32; MAX_CAN_IDS],
    /// Entries in use.
    pub len: u32,
    /// Zero.
    pub reserved: u32,
}

impl CanCounts {
    /// The key of a frame's ID: standard IDs as they are, extended ones with bit 31 set.
    pub fn key(id: embedded_can::Id) -> u32 {
        match id {
            embedded_can::Id::Standard(s) => u32::from(s.as_raw()),
            embedded_can::Id::Extended(e) => e.as_raw() | 0x8000_0000,
        }
    }

    /// One more frame of `id` (a [`CanCounts::key`]).
    pub fn add(&mut self, id: u32) {
        let len = (self.len as usize).min(MAX_CAN_IDS);
        match self.ids[..len].iter().position(|&i| i == id) {
            Some(i) => self.counts[i] += 1,
            None if len < MAX_CAN_IDS => {
                self.ids[len] = id;
                self.counts[len] = 1;
                self.len += 1;
            }
            None => self.other += 1,
        }
    }

    /// Frames an endpoint whose acceptance filter lets `accept` through (`None`: all)
    /// receives of these.
    pub fn accepted(&self, accept: Option<&[u16]>) -> u64 {
        let len = (self.len as usize).min(MAX_CAN_IDS);
        let listed = self.ids[..len].iter().zip(&self.counts);
        match accept {
            None => listed.map(|(_, n)| n).sum::<u64>() + self.other,
            Some(ids) => listed
                .filter(|(id, _)| ids.iter().any(|&a| u32::from(a) == **id))
                .map(|(_, n)| n)
                .sum(),
        }
    }
}

/// The simulator's tick: the controller's tick `tick` (at `tick` x 10 ms) is due,
/// and this is what the wires have carried to it since the start.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("ugv_hil::ClockTick::v1")]
pub struct ClockTick {
    /// The controller's tick index (its time: `tick` x 10 ms).
    pub tick: u64,
    /// Bytes written to the GPS line since the start.
    pub nmea_bytes: u64,
    /// CAN frames the simulator sent since the start.
    pub can: CanCounts,
    /// [`PHASE_TICK`], [`PHASE_START`] or [`PHASE_END`].
    pub phase: u64,
}

/// A tick to take.
pub const PHASE_TICK: u64 = 0;
/// Before tick 0: the controller answers once its ports are open (what the wires
/// carry from then on reaches it; a serial port drops what came before it opened).
pub const PHASE_START: u64 = 1;
/// The run is over, no tick follows: the controller goes on on the wall clock, to
/// wind down as one whose simulator is gone.
pub const PHASE_END: u64 = 2;

/// The controller's acknowledgement: tick `tick` is done, its frames sent.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("ugv_hil::ClockAck::v1")]
pub struct ClockAck {
    pub tick: u64,
    /// CAN frames the controller sent since the start.
    pub can: CanCounts,
    /// 0 while the loop runs; its exit code + 1 when this was its last tick.
    pub exit: u64,
    /// 1: the answer to [`PHASE_START`] (`tick` 0), 0 otherwise.
    pub start: u64,
}

/// The clock service of a run (`ugv-hil/<run id>/clock`); its acknowledgements go on
/// [`ack_service_name`].
pub fn clock_service_name(run_id: &str) -> String {
    format!("ugv-hil/{run_id}/clock")
}

/// The acknowledgement service that goes with the clock service `clock`.
pub fn ack_service_name(clock: &str) -> String {
    format!("{clock}-ack")
}

/// Why the clock wire failed: the service and what iceoryx2 said.
#[derive(Debug, thiserror::Error)]
#[error("clock service {service}: {op}: {message}")]
pub struct ClockError {
    pub service: String,
    pub op: &'static str,
    pub message: String,
}

fn err(service: &str, op: &'static str, e: impl std::fmt::Debug) -> ClockError {
    ClockError {
        service: service.to_owned(),
        op,
        message: format!("{e:?}"),
    }
}

/// The node and the two services (messages and their wake-up) of one end of one
/// direction of the clock wire.
struct Services<T: std::fmt::Debug + ZeroCopySend + 'static> {
    name: String,
    node: Node<Svc>,
    messages: publish_subscribe::PortFactory<Svc, T, ()>,
    events: event::PortFactory<Svc>,
}

/// Open (or create) the services `service` with the wire's QoS: history 1 (a receiver
/// that connects late gets the last message), a receiver's buffer of 4 with the oldest
/// overwritten, at most 2 receivers.
fn open_services<T: std::fmt::Debug + ZeroCopySend + 'static>(
    service: &str,
    node_name: &str,
) -> Result<Services<T>, ClockError> {
    let name = ServiceName::new(service).map_err(|e| err(service, "name the service", e))?;
    let node_name = NodeName::new(node_name).map_err(|e| err(service, "name the node", e))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| err(service, "create the node", e))?;
    node.try_cleanup_dead_nodes();
    let messages = node
        .service_builder(&name)
        .publish_subscribe::<T>()
        .history_size(1)
        .subscriber_max_buffer_size(RECEIVER_BUFFER)
        .max_subscribers(2)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err(service, "open the message service", e))?;
    let events = node
        .service_builder(&name)
        .event()
        .open_or_create()
        .map_err(|e| err(service, "open the event service", e))?;
    Ok(Services {
        name: service.to_owned(),
        node,
        messages,
        events,
    })
}

/// Messages a receiver keeps before the oldest is overwritten.
const RECEIVER_BUFFER: usize = 4;

/// The sending end of one direction.
struct Sender<T: std::fmt::Debug + ZeroCopySend + 'static> {
    name: String,
    publisher: Publisher<Svc, T, ()>,
    notifier: Notifier<Svc>,
    _node: Node<Svc>,
}

/// The receiving end of one direction.
struct Receiver<T: std::fmt::Debug + ZeroCopySend + 'static> {
    name: String,
    subscriber: Subscriber<Svc, T, ()>,
    listener: Listener<Svc>,
    _node: Node<Svc>,
}

impl<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> Sender<T> {
    fn open(service: &str) -> Result<Sender<T>, ClockError> {
        let s = open_services::<T>(service, "ugv-clock-sender")?;
        Ok(Sender {
            publisher: s
                .messages
                .publisher_builder()
                .create()
                .map_err(|e| err(service, "create the publisher", e))?,
            notifier: s
                .events
                .notifier_builder()
                .create()
                .map_err(|e| err(service, "create the notifier", e))?,
            name: s.name,
            _node: s.node,
        })
    }

    fn send(&self, message: T) -> Result<(), ClockError> {
        self.publisher
            .send_copy(message)
            .map_err(|e| err(&self.name, "send", e))?;
        self.notifier
            .notify()
            .map_err(|e| err(&self.name, "notify", e))?;
        Ok(())
    }

    /// Connect receivers that appeared since the last message and hand them the last
    /// one (the history), then wake them.
    fn refresh(&self) -> Result<(), ClockError> {
        self.publisher
            .update_connections()
            .map_err(|e| err(&self.name, "update connections", e))?;
        self.notifier
            .notify()
            .map_err(|e| err(&self.name, "notify", e))?;
        Ok(())
    }
}

impl<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> Receiver<T> {
    fn open(service: &str) -> Result<Receiver<T>, ClockError> {
        let s = open_services::<T>(service, "ugv-clock-receiver")?;
        Ok(Receiver {
            subscriber: s
                .messages
                .subscriber_builder()
                .buffer_size(RECEIVER_BUFFER)
                .create()
                .map_err(|e| err(service, "create the subscriber", e))?,
            listener: s
                .events
                .listener_builder()
                .create()
                .map_err(|e| err(service, "create the listener", e))?,
            name: s.name,
            _node: s.node,
        })
    }

    /// The newest message there is, without waiting.
    fn newest(&self) -> Result<Option<T>, ClockError> {
        let mut newest = None;
        while let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| err(&self.name, "receive", e))?
        {
            newest = Some(*sample.payload());
        }
        Ok(newest)
    }

    /// The newest message for which `wanted` holds, waiting up to `timeout` for one.
    fn wait(
        &self,
        timeout: Duration,
        wanted: impl Fn(&T) -> bool,
    ) -> Result<Option<T>, ClockError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(m) = self.newest()?.filter(|m| wanted(m)) {
                return Ok(Some(m));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            match self.listener.timed_wait(|_| {}, left) {
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(e) => return Err(err(&self.name, "wait", e)),
            }
        }
    }
}

/// The simulator's end: publishes ticks, waits for their acknowledgements.
pub struct ClockLeader {
    ticks: Sender<ClockTick>,
    acks: Receiver<ClockAck>,
}

impl std::fmt::Debug for ClockLeader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClockLeader")
            .field("service", &self.ticks.name)
            .finish()
    }
}

impl ClockLeader {
    /// Open the clock service `service` (see [`clock_service_name`]) and its
    /// acknowledgements.
    pub fn new(service: &str) -> Result<ClockLeader, ClockError> {
        Ok(ClockLeader {
            ticks: Sender::open(service)?,
            acks: Receiver::open(&ack_service_name(service))?,
        })
    }

    pub fn service(&self) -> &str {
        &self.ticks.name
    }

    pub fn publish(&self, tick: ClockTick) -> Result<(), ClockError> {
        self.ticks.send(tick)
    }

    /// The acknowledgement of tick `tick` (or a later one), waiting up to `timeout`.
    /// A controller that connected since the tick went out gets it first.
    pub fn wait_ack(&self, tick: u64, timeout: Duration) -> Result<Option<ClockAck>, ClockError> {
        self.answer(timeout, |a| a.start == 0 && a.tick >= tick)
    }

    /// The answer to [`PHASE_START`], waiting up to `timeout`.
    pub fn wait_start(&self, timeout: Duration) -> Result<Option<ClockAck>, ClockError> {
        self.answer(timeout, |a| a.start == 1)
    }

    fn answer(
        &self,
        timeout: Duration,
        wanted: impl Fn(&ClockAck) -> bool,
    ) -> Result<Option<ClockAck>, ClockError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(ack) = self.acks.wait(Duration::ZERO, &wanted)? {
                return Ok(Some(ack));
            }
            // A controller that connected meanwhile gets the last tick.
            self.ticks.refresh()?;
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            if let Some(ack) = self.acks.wait(left.min(REFRESH_EVERY), &wanted)? {
                return Ok(Some(ack));
            }
        }
    }
}

/// The controller's end: takes ticks, acknowledges them.
pub struct ClockFollower {
    ticks: Receiver<ClockTick>,
    acks: Sender<ClockAck>,
}

impl std::fmt::Debug for ClockFollower {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClockFollower")
            .field("service", &self.ticks.name)
            .finish()
    }
}

impl ClockFollower {
    /// Open the clock service `service` and its acknowledgements.
    pub fn new(service: &str) -> Result<ClockFollower, ClockError> {
        Ok(ClockFollower {
            ticks: Receiver::open(service)?,
            acks: Sender::open(&ack_service_name(service))?,
        })
    }

    pub fn service(&self) -> &str {
        &self.ticks.name
    }

    /// The newest tick at or after `tick`, waiting up to `timeout`.
    pub fn wait_tick(&self, tick: u64, timeout: Duration) -> Result<Option<ClockTick>, ClockError> {
        self.ticks.wait(timeout, |t| t.tick >= tick)
    }

    pub fn ack(&self, ack: ClockAck) -> Result<(), ClockError> {
        self.acks.send(ack)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_wire_has_the_documented_layout() {
        // docs/wire-contract.md, "Lockstep": no padding anywhere.
        assert_eq!(std::mem::size_of::<CanCounts>(), 208);
        assert_eq!(std::mem::size_of::<ClockTick>(), 232);
        assert_eq!(std::mem::size_of::<ClockAck>(), 232);
        assert_eq!(std::mem::align_of::<ClockTick>(), 8);
    }

    #[test]
    fn can_counts_count_per_id_and_by_acceptance() {
        let mut c = CanCounts::default();
        for id in [0x100, 0x100, 0x200, 0x8000_0300] {
            c.add(id);
        }
        assert_eq!(c.accepted(None), 4);
        assert_eq!(c.accepted(Some(&[0x100])), 2);
        assert_eq!(c.accepted(Some(&[0x100, 0x200, 0x300])), 3);
        assert_eq!(c.accepted(Some(&[])), 0);
        // Beyond the table, frames are counted together and only an open filter
        // takes them.
        for id in 0..40 {
            c.add(0x400 + id);
        }
        assert_eq!(c.len as usize, MAX_CAN_IDS);
        assert_eq!(c.other, 40 - (MAX_CAN_IDS as u64 - 3));
        assert_eq!(c.accepted(None), 44);
    }

    #[test]
    fn a_controller_that_connects_late_gets_the_tick_out_already() -> Result<(), ClockError> {
        let service = clock_service_name(&format!("late-{}", std::process::id()));
        let leader = ClockLeader::new(&service)?;
        leader.publish(ClockTick::default())?;
        let follower = ClockFollower::new(&service)?;
        // Waiting for the acknowledgement hands the tick to the newcomer.
        assert_eq!(leader.wait_ack(0, Duration::from_millis(10))?, None);
        assert_eq!(
            follower.wait_tick(0, Duration::from_secs(5))?,
            Some(ClockTick::default())
        );
        Ok(())
    }

    #[test]
    fn a_tick_goes_out_and_its_acknowledgement_comes_back() -> Result<(), ClockError> {
        let service = clock_service_name(&format!("test-{}", std::process::id()));
        let leader = ClockLeader::new(&service)?;
        let follower = ClockFollower::new(&service)?;
        assert_eq!(follower.wait_tick(0, Duration::from_millis(10))?, None);
        let mut tick = ClockTick {
            tick: 3,
            nmea_bytes: 120,
            ..ClockTick::default()
        };
        tick.can.add(0x101);
        leader.publish(tick)?;
        assert_eq!(follower.wait_tick(3, Duration::from_secs(5))?, Some(tick));
        // An old acknowledgement does not answer a newer tick.
        follower.ack(ClockAck {
            tick: 2,
            ..ClockAck::default()
        })?;
        assert_eq!(leader.wait_ack(3, Duration::from_millis(10))?, None);
        follower.ack(ClockAck {
            tick: 3,
            ..ClockAck::default()
        })?;
        assert_eq!(
            leader.wait_ack(3, Duration::from_secs(5))?.map(|a| a.tick),
            Some(3)
        );
        Ok(())
    }
}
