//! A CAN endpoint speaking golf_car.dbc: typed messages out with the E2E counter and
//! CRC filled in, frames in checked for E2E and decoded.
//!
//! Generic over the ecosystem's non-blocking bus trait (`embedded_can::nb::Can`): a
//! SocketCAN socket on vcan0 (simulated devices) or can0 / a USB adapter (physical
//! ones) in HIL, or the in-memory bus of [`membus`] in SIL. The controller never knows
//! which.

pub mod arbiter;
pub mod gated;
pub mod membus;
pub mod paced;
pub mod timed;

use std::io;
use std::time::{Duration, Instant};

use embedded_can::{Frame, Id, StandardId};
use golf_car_can::{
    CanMessage, CodecError, E2eError, E2eRx, E2eStats, E2eTx, GolfCarMessage, NETWORK, Payload,
};
use socketcan::{CanSocket, Socket};

/// How long a send retries a full transmit queue before giving up.
const TX_RETRY: Duration = Duration::from_millis(20);

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
    #[error("CAN bus {iface}: {detail}")]
    Bus { iface: String, detail: String },
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
    /// An error reported by the bus (a CAN error frame, an overrun).
    BusError(String),
}

/// A golf_car.dbc endpoint on one bus.
#[derive(Debug)]
pub struct CanPort<B = CanSocket> {
    name: String,
    bus: B,
    tx: E2eTx,
    rx: E2eRx<'static>,
    undecodable: u64,
    bus_errors: u64,
    /// The standard IDs handed out, when not all ([`CanPort::hear_only`]).
    heard: Option<Vec<u16>>,
    /// Frames received but not handed out (not among `heard`).
    overheard: u64,
    /// Every frame handed out and sent, kept for a recorder ([`CanPort::keep_frames`]).
    kept: Option<Vec<TapFrame>>,
}

/// A CAN frame as a recorder logs it: a simulator's tap on the bus, or a
/// [`CanPort`] keeping what it handed out and sent.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TapFrame {
    pub id: u32,
    pub extended: bool,
    pub data: Vec<u8>,
    /// The kernel's receive time, when known (a tap's socket, in HIL).
    pub kernel: Option<std::time::SystemTime>,
    /// Whether the port that kept it sent it (`Some(true)`) or received it
    /// (`Some(false)`, whatever its ID: a second sender on the port's own IDs); `None`
    /// from a tap, which sees the bus and cannot tell.
    pub sent: Option<bool>,
}

impl TapFrame {
    pub fn of<F: Frame>(frame: &F, kernel: Option<std::time::SystemTime>) -> TapFrame {
        let (id, extended) = raw_id(frame.id());
        TapFrame {
            id,
            extended,
            data: frame.data().to_vec(),
            kernel,
            sent: None,
        }
    }

    /// A frame a port sent (`true`) or received (`false`).
    fn kept<F: Frame>(frame: &F, sent: bool) -> TapFrame {
        TapFrame {
            sent: Some(sent),
            ..TapFrame::of(frame, None)
        }
    }
}

/// The raw value of a CAN ID and whether it is an extended (29-bit) one.
fn raw_id(id: Id) -> (u32, bool) {
    match id {
        Id::Standard(id) => (u32::from(id.as_raw()), false),
        Id::Extended(id) => (id.as_raw(), true),
    }
}

impl<B> CanPort<B>
where
    B: embedded_can::nb::Can,
{
    /// Wrap a bus; `name` names it in errors (the interface name).
    pub fn new(bus: B, name: &str) -> Self {
        CanPort {
            name: name.to_owned(),
            bus,
            tx: E2eTx::new(),
            rx: E2eRx::new(&NETWORK),
            undecodable: 0,
            bus_errors: 0,
            heard: None,
            overheard: 0,
            kept: None,
        }
    }

    /// Keep every frame handed out by [`CanPort::try_recv`] and every frame sent, in
    /// bus order, until [`CanPort::take_frames`] takes them: the controller's recorder.
    pub fn keep_frames(&mut self) {
        self.kept.get_or_insert_with(Vec::new);
    }

    /// The frames kept since the last call (none unless [`CanPort::keep_frames`]).
    pub fn take_frames(&mut self) -> Vec<TapFrame> {
        self.kept.as_mut().map(std::mem::take).unwrap_or_default()
    }

    /// Hand out only frames with these standard IDs (error frames still come) and
    /// count the rest ([`CanPort::overheard`]): for a port that must see the whole bus
    /// (to count its load, to pace its sends) while its node takes only its own
    /// messages, as a real node's acceptance filter has it. The software twin of
    /// [`CanPort::accept_only`].
    pub fn hear_only(&mut self, ids: &[u16]) {
        self.heard = Some(ids.to_vec());
    }

    /// Frames received but not handed out ([`CanPort::hear_only`]).
    pub fn overheard(&self) -> u64 {
        self.overheard
    }

    /// Whether `frame` is handed out; counts it as overheard when not.
    fn hears(&mut self, frame: &B::Frame) -> bool {
        let heard = accepted(self.heard.as_deref(), frame.id());
        if !heard {
            self.overheard += 1;
        }
        heard
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.name
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

    /// Send any message of the network.
    pub fn send_message(&mut self, message: &GolfCarMessage) -> Result<(), BridgeError> {
        let (id, sealed) = self.seal_message(message)?;
        self.send_payload(id, &sealed)
    }

    /// Encode `message` and protect it with its ID's next counter and the CRC, without
    /// sending it (fault injection alters the payload, or leaves a counter out).
    pub fn seal_message(
        &mut self,
        message: &GolfCarMessage,
    ) -> Result<(u16, Payload), BridgeError> {
        let id = message.id();
        let data = message.encode().map_err(|source| BridgeError::Encode {
            message: message.name(),
            source,
        })?;
        Ok((id, self.tx.seal(id, data)))
    }

    /// Send a payload exactly as given (no E2E added): for gateways and fault injection.
    pub fn send_payload(&mut self, id: u16, data: &Payload) -> Result<(), BridgeError> {
        self.send_bytes(id, data)
    }

    /// Send 0 to 8 bytes exactly as given (a wrong DLC, for fault injection).
    pub fn send_bytes(&mut self, id: u16, data: &[u8]) -> Result<(), BridgeError> {
        let sid = StandardId::new(id).ok_or(BridgeError::BadId { id })?;
        let frame = B::Frame::new(sid, data).ok_or(BridgeError::BadId { id })?;
        let started = Instant::now();
        loop {
            match self.bus.transmit(&frame) {
                Ok(_) => {
                    if let Some(kept) = &mut self.kept {
                        kept.push(TapFrame::kept(&frame, true));
                    }
                    return Ok(());
                }
                Err(nb::Error::WouldBlock) if started.elapsed() < TX_RETRY => {
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(nb::Error::WouldBlock) => {
                    return Err(BridgeError::Bus {
                        iface: self.name.clone(),
                        detail: format!("transmit queue full for {TX_RETRY:?}"),
                    });
                }
                Err(nb::Error::Other(e)) => {
                    return Err(BridgeError::Bus {
                        iface: self.name.clone(),
                        detail: format!("{e:?}"),
                    });
                }
            }
        }
    }

    /// The next frame if one is waiting (never blocks).
    pub fn try_recv(&mut self) -> Option<Received> {
        loop {
            return match self.bus.receive() {
                Ok(frame) if !self.hears(&frame) => continue,
                Ok(frame) => Some(self.classify(&frame)),
                Err(nb::Error::WouldBlock) => None,
                Err(nb::Error::Other(e)) => {
                    self.bus_errors += 1;
                    Some(Received::BusError(format!("{e:?}")))
                }
            };
        }
    }

    fn classify(&mut self, frame: &B::Frame) -> Received {
        let (id, extended) = raw_id(frame.id());
        if let Some(kept) = &mut self.kept {
            kept.push(TapFrame::kept(frame, false));
        }
        match self
            .rx
            .accept_parts(id, extended, frame.is_remote_frame(), frame.data())
        {
            Err(e) => Received::Rejected(e),
            Ok((id, payload)) => match GolfCarMessage::decode(id, &payload) {
                Ok(m) => Received::Message(m),
                Err(error) => {
                    self.undecodable += 1;
                    Received::Undecodable { id, error }
                }
            },
        }
    }

    /// The receiver's E2E statistics.
    pub fn stats(&self) -> E2eStats {
        self.rx.stats()
    }

    /// The CAN ID of a counter stream that shows a second sender now
    /// (`golf_car_can::SenderWatch`), if any.
    pub fn second_sender(&self) -> Option<u16> {
        self.rx.second_sender()
    }

    /// Frames that passed E2E but did not decode.
    pub fn undecodable(&self) -> u64 {
        self.undecodable
    }

    /// Errors the bus reported.
    pub fn bus_errors(&self) -> u64 {
        self.bus_errors
    }
}

/// An error opening `iface`, named as one.
fn open_error(iface: &str, source: io::Error) -> BridgeError {
    match source.raw_os_error() {
        Some(libc::ENODEV) => BridgeError::NoInterface {
            iface: iface.to_owned(),
        },
        _ => BridgeError::Io {
            iface: iface.to_owned(),
            source,
        },
    }
}

/// The receive queue the simulator's sockets ask for, bytes: a CAN frame takes
/// about 1 KiB of it in the kernel (its buffer's true size), so the default
/// (`net.core.rmem_default`, 208 KiB) holds some 200 frames, a quarter of a second of
/// a loaded bus, and a reader stalled longer than that (a busy host, an emulated
/// guest) loses frames. 16 MiB holds over ten seconds of a saturated 500 kbit/s bus.
pub const DEEP_QUEUE_BYTES: usize = 16 << 20;

/// SO_MEMINFO (asm-generic/socket.h; x86 and arm share it) and its DROPS slot.
const SO_MEMINFO: libc::c_int = 55;
const SK_MEMINFO_DROPS: usize = 8;

/// Ask for a receive queue of `bytes` on `socket`: `SO_RCVBUFFORCE` with
/// CAP_NET_ADMIN, else `SO_RCVBUF`, which the kernel caps at `net.core.rmem_max`.
pub fn set_receive_queue(socket: &CanSocket, bytes: usize) -> nix::Result<()> {
    use nix::sys::socket::{setsockopt, sockopt};
    if setsockopt(socket, sockopt::RcvBufForce, &bytes).is_err() {
        setsockopt(socket, sockopt::RcvBuf, &bytes)?;
    }
    Ok(())
}

/// A bus endpoint that tells how many frames it lost before it read them.
pub trait QueueDrops {
    /// The frames dropped because the receive queue was full, at any time (`None`: it
    /// cannot tell, or cannot lose any).
    fn queue_drops(&self) -> Option<u32>;
}

/// The kernel's count (SO_MEMINFO).
impl QueueDrops for CanSocket {
    fn queue_drops(&self) -> Option<u32> {
        let mut buf = [0u8; 4 * (SK_MEMINFO_DROPS + 1)];
        let n = socketcan::SocketOptions::get_socket_option_bytes(
            self,
            libc::SOL_SOCKET,
            SO_MEMINFO,
            &mut buf,
        )
        .ok()?;
        let at = 4 * SK_MEMINFO_DROPS;
        (n >= at + 4).then(|| u32::from_ne_bytes([buf[at], buf[at + 1], buf[at + 2], buf[at + 3]]))
    }
}

/// Whether a frame with `id` passes an acceptance filter of standard IDs (`None`:
/// every frame passes).
fn accepted(ids: Option<&[u16]>, id: Id) -> bool {
    match (ids, id) {
        (None, _) => true,
        (Some(ids), Id::Standard(id)) => ids.contains(&id.as_raw()),
        (Some(_), Id::Extended(_)) => false,
    }
}

/// A bus endpoint with an acceptance filter: a SocketCAN socket (the kernel's
/// filter), a timed one (see [`timed`]), or a memory bus endpoint (see [`membus`]).
pub trait Filtered {
    /// Hand this endpoint only data and remote frames with these standard IDs (error
    /// frames still come).
    fn set_acceptance(&self, ids: &[u16]) -> io::Result<()>;
}

impl Filtered for CanSocket {
    fn set_acceptance(&self, ids: &[u16]) -> io::Result<()> {
        let mask = libc::CAN_SFF_MASK | libc::CAN_EFF_FLAG;
        let filters: Vec<socketcan::CanFilter> = ids
            .iter()
            .map(|&id| socketcan::CanFilter::new(u32::from(id), mask))
            .collect();
        socketcan::SocketOptions::set_filters(self, &filters)
    }
}

impl<B: QueueDrops> CanPort<B> {
    /// The frames its endpoint lost before it read them ([`QueueDrops`]).
    pub fn queue_drops(&self) -> Option<u32> {
        self.bus.queue_drops()
    }
}

impl<B: embedded_can::nb::Can + Filtered> CanPort<B> {
    /// Let this port receive only frames with these standard IDs (and error frames):
    /// a node's acceptance filter, so that traffic meant for others (a babbling node
    /// flooding another ID) costs it nothing. Frames with those IDs are still checked
    /// and counted as before.
    pub fn accept_only(&self, ids: &[u16]) -> Result<(), BridgeError> {
        self.bus
            .set_acceptance(ids)
            .map_err(|source| BridgeError::Io {
                iface: self.name.clone(),
                source,
            })
    }
}

impl CanPort<gated::Gated<timed::TimedSocket>> {
    /// Open a raw CAN socket on `iface` whose frames are handed out by `horizon`
    /// (see [`timed`]), sending through `pacer` when given (see [`paced`]), and in
    /// lockstep through `gate` (see [`gated`]).
    pub fn open_timed(
        iface: &str,
        horizon: timed::Horizon,
        pacer: Option<&paced::Pacer>,
        gate: Option<gated::Gate>,
    ) -> Result<Self, BridgeError> {
        let socket = timed::TimedSocket::open(iface, horizon).map_err(|e| open_error(iface, e))?;
        let socket = match pacer {
            Some(p) => socket.paced(p),
            None => socket,
        };
        Ok(CanPort::new(gated::Gated::new(socket, gate), iface))
    }
}

/// A raw CAN socket on `iface`, non-blocking.
fn open_socket(iface: &str) -> Result<CanSocket, BridgeError> {
    let io = |source: io::Error| open_error(iface, source);
    let socket = CanSocket::open(iface).map_err(io)?;
    socket.set_nonblocking(true).map_err(io)?;
    Ok(socket)
}

impl CanPort<gated::Gated<CanSocket>> {
    /// Open a raw CAN socket on `iface`, in lockstep through `gate` (see [`gated`]).
    pub fn open_gated(iface: &str, gate: Option<gated::Gate>) -> Result<Self, BridgeError> {
        Ok(CanPort::new(
            gated::Gated::new(open_socket(iface)?, gate),
            iface,
        ))
    }
}

impl CanPort<CanSocket> {
    /// Open a raw CAN socket on `iface` (vcan0, can0, ...).
    pub fn open(iface: &str) -> Result<Self, BridgeError> {
        Ok(CanPort::new(open_socket(iface)?, iface))
    }

    /// Wait up to `timeout` for a frame (woken by the socket, not polling); `None`
    /// when none came.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, BridgeError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(r) = self.try_recv() {
                return Ok(Some(r));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            match self.bus.read_frame_timeout(left) {
                Ok(socketcan::CanFrame::Error(e)) => {
                    self.bus_errors += 1;
                    return Ok(Some(Received::BusError(format!("{:?}", e.into_error()))));
                }
                Ok(frame) if !self.hears(&frame) => {}
                Ok(frame) => return Ok(Some(self.classify(&frame))),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) => {}
                Err(source) => {
                    return Err(BridgeError::Io {
                        iface: self.name.clone(),
                        source,
                    });
                }
            }
        }
    }
}
