//! iceoryx2 endpoints of the laser wire.
//!
//! Each endpoint owns a node (dead nodes of crashed runs are cleaned up when it starts),
//! the publish-subscribe service of frames and an event service of the same name. The
//! publisher notifies the event service after every frame; the subscriber blocks in
//! `Listener::timed_wait`, i.e. in the kernel on the event's file descriptor (a unix
//! datagram socket in iceoryx2 0.10's `ipc` services), and wakes when a frame is
//! announced or the timeout passes. There is no sleep or poll loop: a wake-up without
//! a frame (a notification whose frame was already taken) waits again for the rest of
//! the timeout.
//!
//! The services are `ipc_threadsafe`, so the endpoints are `Send` and can live in any
//! thread. Nodes leave signal handling to the application (`SignalHandlingMode::Disabled`):
//! the simulator and controller install their own Ctrl-C handling.

use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use super::{IpcOp, LaserError, LaserFrame};

type Svc = ipc_threadsafe::Service;

/// Frames a subscriber buffers before the oldest is overwritten (320 ms at 50 Hz).
pub const SUBSCRIBER_BUFFER: usize = 16;
/// Frames the service keeps for subscribers that connect late: the latest one.
const HISTORY: usize = 1;
/// Subscribers one laser service supports (controller, recorder, echo, ...).
const MAX_SUBSCRIBERS: usize = 8;

/// An iceoryx2 error of `op` on `service`, kept as the source.
fn ipc_err(
    service: &str,
    op: IpcOp,
    error: impl std::error::Error + Send + Sync + 'static,
) -> LaserError {
    LaserError::Ipc {
        service: service.to_owned(),
        op,
        source: Box::new(error),
    }
}

/// The node, the frame service and the event service of one endpoint.
struct Endpoint {
    node: Node<Svc>,
    frames: publish_subscribe::PortFactory<Svc, LaserFrame, ()>,
    events: event::PortFactory<Svc>,
}

/// How an endpoint comes by its services.
#[derive(Clone, Copy, PartialEq)]
enum Services {
    /// Open them, or create them with the wire's settings (the simulator, the tools).
    OpenOrCreate,
    /// Open them only, as a controller of one's own must (docs/wire-contract.md).
    Open,
}

/// Whether `error` is iceoryx2's "the service does not exist" of an [`Services::Open`].
fn service_missing(error: &LaserError) -> bool {
    let LaserError::Ipc { source, .. } = error else {
        return false;
    };
    matches!(
        source.downcast_ref(),
        Some(PublishSubscribeOpenError::DoesNotExist)
    ) || matches!(source.downcast_ref(), Some(EventOpenError::DoesNotExist))
}

fn open(service: &str, node_name: &str, how: Services) -> Result<Endpoint, LaserError> {
    let name = ServiceName::new(service).map_err(|source| LaserError::ServiceName {
        name: service.to_owned(),
        source,
    })?;
    let node_name = NodeName::new(node_name).map_err(|e| ipc_err(service, IpcOp::NameNode, e))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| ipc_err(service, IpcOp::CreateNode, e))?;
    // Resources of processes that died (a crashed earlier run) would block the service.
    let cleanup = node.try_cleanup_dead_nodes();
    if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 {
        tracing::info!(
            cleaned = cleanup.cleanups,
            failed = cleanup.failed_cleanups,
            "iceoryx2: removed resources of dead nodes"
        );
    }
    let frames = node
        .service_builder(&name)
        .publish_subscribe::<LaserFrame>()
        .history_size(HISTORY)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .max_subscribers(MAX_SUBSCRIBERS)
        .enable_safe_overflow(true);
    let frames = match how {
        Services::OpenOrCreate => frames
            .open_or_create()
            .map_err(|e| ipc_err(service, IpcOp::OpenFrameService, e)),
        Services::Open => frames
            .open()
            .map_err(|e| ipc_err(service, IpcOp::OpenFrameService, e)),
    }?;
    let events = node.service_builder(&name).event();
    let events = match how {
        Services::OpenOrCreate => events
            .open_or_create()
            .map_err(|e| ipc_err(service, IpcOp::OpenEventService, e)),
        Services::Open => events
            .open()
            .map_err(|e| ipc_err(service, IpcOp::OpenEventService, e)),
    }?;
    Ok(Endpoint {
        node,
        frames,
        events,
    })
}

/// Publishes laser frames on a service (the simulator's, or a physical scanner's driver).
pub struct LaserPublisher {
    service: String,
    publisher: Publisher<Svc, LaserFrame, ()>,
    notifier: Notifier<Svc>,
    endpoint: Endpoint,
}

impl std::fmt::Debug for LaserPublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LaserPublisher")
            .field("service", &self.service)
            .field("node", &self.endpoint.node.name())
            .finish()
    }
}

impl LaserPublisher {
    /// Open (or create) the service `service_name` (see [`super::service_name`]) and
    /// a publisher on it.
    pub fn new(service_name: &str) -> Result<LaserPublisher, LaserError> {
        let endpoint = open(service_name, "ugv-laser-publisher", Services::OpenOrCreate)?;
        let publisher = endpoint
            .frames
            .publisher_builder()
            .create()
            .map_err(|e| ipc_err(service_name, IpcOp::CreatePublisher, e))?;
        let notifier = endpoint
            .events
            .notifier_builder()
            .create()
            .map_err(|e| ipc_err(service_name, IpcOp::CreateNotifier, e))?;
        Ok(LaserPublisher {
            service: service_name.to_owned(),
            publisher,
            notifier,
            endpoint,
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Validate and send a frame, then wake the subscribers. Returns how many
    /// subscribers it reached. The frame also becomes the history a late subscriber gets.
    pub fn publish(&self, frame: &LaserFrame) -> Result<usize, LaserError> {
        frame.validate()?;
        let reached = self
            .publisher
            .send_copy(*frame)
            .map_err(|e| ipc_err(&self.service, IpcOp::SendFrame, e))?;
        self.notifier
            .notify()
            .map_err(|e| ipc_err(&self.service, IpcOp::Notify, e))?;
        Ok(reached)
    }

    /// Connect subscribers that appeared since the last frame and hand them the latest
    /// frame (the history), then wake them. `publish` does this implicitly; call it when
    /// the publisher is idle and late subscribers should not wait for the next frame.
    pub fn update_connections(&self) -> Result<(), LaserError> {
        self.publisher
            .update_connections()
            .map_err(|e| ipc_err(&self.service, IpcOp::UpdateConnections, e))?;
        self.notifier
            .notify()
            .map_err(|e| ipc_err(&self.service, IpcOp::Notify, e))?;
        Ok(())
    }
}

/// Receives laser frames from a service (the controller, recorders, `ugv-laser-echo`).
pub struct LaserSubscriber {
    service: String,
    subscriber: Subscriber<Svc, LaserFrame, ()>,
    listener: Listener<Svc>,
    endpoint: Endpoint,
}

impl std::fmt::Debug for LaserSubscriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LaserSubscriber")
            .field("service", &self.service)
            .field("node", &self.endpoint.node.name())
            .finish()
    }
}

impl LaserSubscriber {
    /// Open (or create) the service `service_name` and a subscriber on it. It may start
    /// before the publisher; once connected it gets the latest frame (history) first.
    pub fn new(service_name: &str) -> Result<LaserSubscriber, LaserError> {
        Self::subscribe(service_name, Services::OpenOrCreate)
    }

    /// Open the publisher's service `service_name` and a subscriber on it, never
    /// creating it (a controller must not: docs/wire-contract.md); `Ok(None)` while the
    /// service does not exist.
    pub fn open_existing(service_name: &str) -> Result<Option<LaserSubscriber>, LaserError> {
        match Self::subscribe(service_name, Services::Open) {
            Err(e) if service_missing(&e) => Ok(None),
            opened => opened.map(Some),
        }
    }

    fn subscribe(service_name: &str, how: Services) -> Result<LaserSubscriber, LaserError> {
        let endpoint = open(service_name, "ugv-laser-subscriber", how)?;
        let subscriber = endpoint
            .frames
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| ipc_err(service_name, IpcOp::CreateSubscriber, e))?;
        let listener = endpoint
            .events
            .listener_builder()
            .create()
            .map_err(|e| ipc_err(service_name, IpcOp::CreateListener, e))?;
        Ok(LaserSubscriber {
            service: service_name.to_owned(),
            subscriber,
            listener,
            endpoint,
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The oldest buffered frame, validated, without blocking. A frame that fails
    /// validation is consumed and reported as the error; the next call goes on.
    pub fn try_recv(&self) -> Result<Option<LaserFrame>, LaserError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|e| ipc_err(&self.service, IpcOp::Receive, e))?;
        match sample {
            None => Ok(None),
            Some(sample) => {
                let frame = *sample.payload();
                drop(sample);
                frame.validate()?;
                Ok(Some(frame))
            }
        }
    }

    /// The newest frame, dropping older buffered ones, without blocking.
    pub fn try_recv_latest(&self) -> Result<Option<LaserFrame>, LaserError> {
        let mut latest = None;
        while let Some(f) = self.try_recv()? {
            latest = Some(f);
        }
        Ok(latest)
    }

    /// The oldest buffered frame, or wait for one until `timeout` has passed (`Ok(None)`).
    /// The wait is event-driven: the thread sleeps on the event service's listener and
    /// wakes when the publisher announces a frame.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<LaserFrame>, LaserError> {
        let deadline = Instant::now().checked_add(timeout);
        loop {
            if let Some(frame) = self.try_recv()? {
                return Ok(Some(frame));
            }
            let remaining = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => timeout,
            };
            if remaining.is_zero() {
                return Ok(None);
            }
            match self.listener.timed_wait(|_| {}, remaining) {
                Ok(_) => {}
                // A signal (Ctrl-C) interrupts the wait: give the caller its turn.
                Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {
                    return self.try_recv();
                }
                Err(e) => return Err(ipc_err(&self.service, IpcOp::WaitForFrame, e)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send<T: Send>() {}

    #[test]
    fn endpoints_can_move_to_other_threads() {
        assert_send::<LaserPublisher>();
        assert_send::<LaserSubscriber>();
    }

    #[test]
    fn an_ipc_error_names_the_operation_and_keeps_iceoryx2s_error() {
        use iceoryx2::port::listener::ListenerWaitError;
        let e = ipc_err(
            "svc",
            IpcOp::WaitForFrame,
            ListenerWaitError::InternalFailure,
        );
        assert_eq!(
            e.to_string(),
            "laser service svc: wait for a frame: InternalFailure"
        );
        let source = std::error::Error::source(&e).expect("a source");
        assert_eq!(
            source.downcast_ref::<ListenerWaitError>(),
            Some(&ListenerWaitError::InternalFailure)
        );
    }

    #[test]
    fn a_bad_service_name_keeps_iceoryx2s_error() {
        use iceoryx2::service::service_name::ServiceNameError;
        let e = LaserSubscriber::new("").expect_err("an empty service name");
        assert!(
            matches!(
                e,
                LaserError::ServiceName {
                    source: ServiceNameError::InvalidContent,
                    ..
                }
            ),
            "{e:?}"
        );
    }
}
