//! [`ColaServer`]: a SICK scanner on TCP, serving the laser frames it is given.
//!
//! # Threads and queues
//!
//! An accept thread takes connections; each client gets a reader thread (parses its
//! requests and answers them) and a writer thread (the only one that writes to its
//! socket), fed by a bounded queue of [`ServerConfig::queue_len`] telegrams.
//!
//! [`ColaServer::publish`] never waits for a client: it encodes the scan once, then
//! offers it to every streaming client's queue with `try_send`; a client whose queue
//! is full (its socket does not drain fast enough) loses that scan, and the loss is
//! counted for the client and in total ([`ServerStats`]). The locks it takes are held
//! only to swap a pointer or walk the client list, never across I/O.
//!
//! # Device behaviour
//!
//! What the scanner answers is [`Device`]'s, the pure state machine in
//! [`device`](super::device): the user levels and the one controlling client, every
//! command's answer and `sFA` code. The server gives each connection a session of its
//! own, feeds it what the client sends, writes back the answers, turns the client's
//! stream on and off as the device says, closes the connection when the device drops
//! the session, and closes the session when the client goes away (which ends its
//! login and, for the controlling client, its control).
//!
//! Dropping the server closes every connection and joins every thread.

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::ColaError;
use super::convert::{EncodeOptions, RssiChannel, scan_from_frame};
use super::device::{Device, DeviceConfig, SessionId};
use super::framing::{ETX, STX};
use super::scandata::ScanKind;
use crate::laser::LaserFrame;
use crate::sync::lock;

/// What the emulated scanner is and how it behaves.
#[derive(Clone, Debug, PartialEq)]
pub struct ServerConfig {
    /// The name `sRN DeviceIdent` answers (`LMS111`, `LMS511`, ...).
    pub device_name: String,
    /// The version `sRN DeviceIdent` answers.
    pub firmware_version: String,
    /// How frames become scan telegrams: device and serial number, scale factor,
    /// RSSI channel, time stamp.
    pub encode: EncodeOptions,
    /// Telegrams queued per client before scans for it are dropped (at least 1).
    pub queue_len: usize,
    /// Clients served at once; further connections are closed at once.
    pub max_clients: usize,
    /// Longest request telegram accepted, bytes.
    pub max_telegram: usize,
    /// Bad telegrams in a row after which a client is disconnected.
    pub max_consecutive_errors: u32,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig::lms111()
    }
}

impl ServerConfig {
    /// An LMS111 (as the simulator's default laser): mm, 8-bit RSSI, time stamps.
    pub fn lms111() -> Self {
        ServerConfig {
            device_name: "LMS111".into(),
            firmware_version: format!("V{} ugv-hil", env!("CARGO_PKG_VERSION")),
            encode: EncodeOptions::default(),
            queue_len: 8,
            max_clients: 16,
            max_telegram: 4096,
            max_consecutive_errors: 64,
        }
    }

    /// An LMS511: 16-bit RSSI; mm (set `encode.scale_factor = 2.0` for ranges beyond
    /// 65.535 m, as the long-range LMS5xx configurations do).
    pub fn lms511() -> Self {
        ServerConfig {
            device_name: "LMS511".into(),
            encode: EncodeOptions {
                serial_number: 0x00C3_5A1B,
                rssi: RssiChannel::Bits16,
                ..EncodeOptions::default()
            },
            ..ServerConfig::lms111()
        }
    }

    /// Set the serial number (in the scan telegrams).
    pub fn with_serial_number(mut self, serial: u32) -> Self {
        self.encode.serial_number = serial;
        self
    }

    /// What the [`Device`] state machine takes of it.
    pub fn device_config(&self) -> DeviceConfig {
        DeviceConfig {
            device_name: self.device_name.clone(),
            firmware_version: self.firmware_version.clone(),
            max_telegram: self.max_telegram,
            max_consecutive_errors: self.max_consecutive_errors,
        }
    }
}

/// A client's share of the statistics.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClientInfo {
    /// The client's address.
    pub peer: SocketAddr,
    /// Whether it has scans streamed to it.
    pub streaming: bool,
    /// Scans written to it.
    pub frames_sent: u64,
    /// Scans dropped because its queue was full.
    pub frames_dropped: u64,
    /// Bad telegrams it sent.
    pub bad_telegrams: u64,
}

/// Counters of a server since it started.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ServerStats {
    /// The clients connected now.
    pub clients: Vec<ClientInfo>,
    /// Connections accepted.
    pub clients_accepted: u64,
    /// Connections closed at once because `max_clients` were connected.
    pub clients_refused: u64,
    /// Clients disconnected for sending too many bad telegrams.
    pub clients_dropped_for_errors: u64,
    /// Frames given to `publish` while measuring.
    pub frames_published: u64,
    /// Frames given to `publish` while measurement was stopped (ignored).
    pub frames_while_stopped: u64,
    /// Scans queued for a client (one per client per frame).
    pub frames_queued: u64,
    /// Scans written to clients.
    pub frames_sent: u64,
    /// Scans dropped because a client's queue was full.
    pub frames_dropped: u64,
    /// Requests answered.
    pub requests: u64,
    /// Telegrams that did not parse or were badly framed.
    pub bad_telegrams: u64,
    /// Bytes received outside any telegram.
    pub garbage_bytes: u64,
    /// Requests refused for a missing or too low login (`sFA 1`, `sFA A`).
    pub access_denied: u64,
    /// Logins refused: a wrong level or password, or another client in control.
    pub logins_refused: u64,
}

#[derive(Debug, Default)]
struct Counters {
    accepted: AtomicU64,
    refused: AtomicU64,
    published: AtomicU64,
    while_stopped: AtomicU64,
    queued: AtomicU64,
    sent: AtomicU64,
    dropped: AtomicU64,
    telegram_counter: AtomicU64,
}

fn add(c: &AtomicU64, n: u64) {
    c.fetch_add(n, Ordering::Relaxed);
}

fn get(c: &AtomicU64) -> u64 {
    c.load(Ordering::Relaxed)
}

/// What the writer thread of a client writes.
#[derive(Debug)]
enum Out {
    /// A streamed scan (`STX sSN LMDscandata ... ETX`), shared by all clients.
    Scan(Arc<Vec<u8>>),
    /// A framed answer.
    Reply(Vec<u8>),
    /// Start or stop streaming, then write the acknowledgement (framed).
    Stream(bool, Vec<u8>),
    /// The reader is done: close.
    Close,
}

#[derive(Debug)]
struct ClientShared {
    peer: SocketAddr,
    session: SessionId,
    streaming: AtomicBool,
    closed: AtomicBool,
    sent: AtomicU64,
    dropped: AtomicU64,
    bad: AtomicU64,
}

#[derive(Debug)]
struct ClientHandle {
    shared: Arc<ClientShared>,
    tx: SyncSender<Out>,
    stream: TcpStream,
    threads: Vec<JoinHandle<()>>,
}

#[derive(Debug)]
struct Shared {
    config: ServerConfig,
    start: Instant,
    shutdown: AtomicBool,
    counters: Counters,
    /// The scanner's state: sessions, logins, measuring, the latest scan. Held only to
    /// answer one piece of a client's stream or to swap the latest scan, never across
    /// I/O.
    device: Mutex<Device>,
    clients: Mutex<Vec<ClientHandle>>,
    /// Threads of clients that went away, joined later.
    retired: Mutex<Vec<JoinHandle<()>>>,
}

/// A SICK scanner on TCP; see the [module documentation](self).
#[derive(Debug)]
pub struct ColaServer {
    shared: Arc<Shared>,
    local_addr: SocketAddr,
    accept: Option<JoinHandle<()>>,
}

impl ColaServer {
    /// Listen on `address` and start serving: `127.0.0.1:2111` as a scanner for
    /// clients on this machine (`127.0.0.1:0` for a free port, see
    /// [`ColaServer::local_addr`]). Listen beyond loopback (an interface's own address)
    /// only on a network you trust: CoLa-A has no encryption, and SICK's passwords are
    /// public.
    pub fn bind(
        address: impl ToSocketAddrs,
        config: ServerConfig,
    ) -> Result<ColaServer, ColaError> {
        let name = address
            .to_socket_addrs()
            .map(|mut a| a.next().map(|a| a.to_string()).unwrap_or_default())
            .unwrap_or_default();
        let device = Device::new(config.device_config())?;
        // Fail early on options that would fail every frame.
        scan_from_frame(&probe_frame(), &config.encode)?;
        let listener = TcpListener::bind(address).map_err(|source| ColaError::Bind {
            address: name.clone(),
            source,
        })?;
        let local_addr = listener.local_addr().map_err(|source| ColaError::Bind {
            address: name,
            source,
        })?;
        let shared = Arc::new(Shared {
            config,
            start: Instant::now(),
            shutdown: AtomicBool::new(false),
            counters: Counters::default(),
            device: Mutex::new(device),
            clients: Mutex::new(Vec::new()),
            retired: Mutex::new(Vec::new()),
        });
        let accept_shared = Arc::clone(&shared);
        let accept = std::thread::Builder::new()
            .name("cola-accept".into())
            .spawn(move || accept_loop(&listener, &accept_shared))
            .map_err(ColaError::Thread)?;
        tracing::info!(%local_addr, device = %shared.config.device_name, "CoLa-A server listening");
        Ok(ColaServer {
            shared,
            local_addr,
            accept: Some(accept),
        })
    }

    /// The address the server listens on (with the actual port when bound to port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The configuration.
    pub fn config(&self) -> &ServerConfig {
        &self.shared.config
    }

    /// Serve a frame: it becomes the latest scan (for polls) and is queued for every
    /// streaming client. Never waits for a client; returns the number of clients the
    /// scan was queued for. Fails only on a frame that does not validate or convert
    /// (nothing is sent then).
    pub fn publish(&self, frame: &LaserFrame) -> Result<usize, ColaError> {
        let shared = &self.shared;
        if !lock(&shared.device).is_measuring() {
            add(&shared.counters.while_stopped, 1);
            return Ok(0);
        }
        let mut scan = scan_from_frame(frame, &shared.config.encode)?;
        scan.telegram_counter = shared
            .counters
            .telegram_counter
            .fetch_add(1, Ordering::Relaxed) as u16;
        // The device clock: µs since the server started, wrapping at 2^32 as SICK's does.
        let now_us = shared.start.elapsed().as_micros() as u32;
        let scan_us = (f64::from(frame.scan_time) * 1e6).round() as u32;
        scan.time_of_transmission_us = now_us;
        scan.time_since_startup_us = now_us.wrapping_sub(scan_us);
        let mut bytes = Vec::with_capacity(scan.encoded_len_hint() + 2);
        bytes.push(STX);
        scan.encode_into(ScanKind::Streamed, &mut bytes)?;
        bytes.push(ETX);
        let telegram = Arc::new(bytes);
        add(&shared.counters.published, 1);
        lock(&shared.device).set_latest_scan(Arc::clone(&telegram));

        let mut queued = 0;
        let mut clients = lock(&shared.clients);
        for c in clients.iter() {
            if !c.shared.streaming.load(Ordering::Acquire)
                || c.shared.closed.load(Ordering::Acquire)
            {
                continue;
            }
            match c.tx.try_send(Out::Scan(Arc::clone(&telegram))) {
                Ok(()) => queued += 1,
                Err(TrySendError::Full(_)) => {
                    add(&c.shared.dropped, 1);
                    add(&shared.counters.dropped, 1);
                }
                Err(TrySendError::Disconnected(_)) => {
                    c.shared.closed.store(true, Ordering::Release)
                }
            }
        }
        retire_closed(&mut clients, &shared.retired);
        drop(clients);
        add(&shared.counters.queued, queued as u64);
        Ok(queued)
    }

    /// Clients connected now.
    pub fn client_count(&self) -> usize {
        lock(&self.shared.clients)
            .iter()
            .filter(|c| !c.shared.closed.load(Ordering::Acquire))
            .count()
    }

    /// Clients with scans streamed to them now.
    pub fn streaming_clients(&self) -> usize {
        lock(&self.shared.clients)
            .iter()
            .filter(|c| {
                c.shared.streaming.load(Ordering::Acquire)
                    && !c.shared.closed.load(Ordering::Acquire)
            })
            .count()
    }

    /// Whether the device is measuring (not stopped with `sMN LMCstopmeas`).
    pub fn is_measuring(&self) -> bool {
        lock(&self.shared.device).is_measuring()
    }

    /// The counters.
    pub fn stats(&self) -> ServerStats {
        let c = &self.shared.counters;
        let device = lock(&self.shared.device).stats().clone();
        let clients = lock(&self.shared.clients)
            .iter()
            .filter(|h| !h.shared.closed.load(Ordering::Acquire))
            .map(|h| ClientInfo {
                peer: h.shared.peer,
                streaming: h.shared.streaming.load(Ordering::Acquire),
                frames_sent: get(&h.shared.sent),
                frames_dropped: get(&h.shared.dropped),
                bad_telegrams: get(&h.shared.bad),
            })
            .collect();
        ServerStats {
            clients,
            clients_accepted: get(&c.accepted),
            clients_refused: get(&c.refused),
            clients_dropped_for_errors: device.dropped_for_errors,
            frames_published: get(&c.published),
            frames_while_stopped: get(&c.while_stopped),
            frames_queued: get(&c.queued),
            frames_sent: get(&c.sent),
            frames_dropped: get(&c.dropped),
            requests: device.requests,
            bad_telegrams: device.bad_telegrams,
            garbage_bytes: device.garbage_bytes,
            access_denied: device.access_denied,
            logins_refused: device.logins_refused,
        }
    }
}

impl Drop for ColaServer {
    fn drop(&mut self) {
        let shared = &self.shared;
        shared.shutdown.store(true, Ordering::Release);
        // Wake the accept thread with a connection of our own.
        let mut wake = self.local_addr;
        if wake.ip().is_unspecified() {
            wake.set_ip(match wake {
                SocketAddr::V4(_) => std::net::Ipv4Addr::LOCALHOST.into(),
                SocketAddr::V6(_) => std::net::Ipv6Addr::LOCALHOST.into(),
            });
        }
        match TcpStream::connect_timeout(&wake, Duration::from_secs(2)) {
            Ok(_) => {
                if let Some(t) = self.accept.take() {
                    let _ = t.join();
                }
            }
            Err(e) => {
                // The thread exits on the next connection; it holds nothing else.
                tracing::warn!(error = %e, "CoLa server: could not wake the accept thread");
            }
        }
        let clients = std::mem::take(&mut *lock(&shared.clients));
        for c in &clients {
            let _ = c.stream.shutdown(Shutdown::Both);
        }
        for c in clients {
            let ClientHandle { tx, threads, .. } = c;
            drop(tx);
            for t in threads {
                let _ = t.join();
            }
        }
        for t in std::mem::take(&mut *lock(&shared.retired)) {
            let _ = t.join();
        }
        tracing::debug!(addr = %self.local_addr, "CoLa-A server stopped");
    }
}

/// A frame that every sane encoding accepts, to check the options at bind time.
fn probe_frame() -> LaserFrame {
    let mut f = LaserFrame {
        count: 1,
        angle_increment: 0.01,
        range_min: 0.5,
        range_max: 20.0,
        ..LaserFrame::default()
    };
    f.ranges[0] = 1.0;
    f
}

/// Move closed clients' threads to `retired`, join the retired ones that finished.
fn retire_closed(clients: &mut Vec<ClientHandle>, retired: &Mutex<Vec<JoinHandle<()>>>) {
    if !clients
        .iter()
        .any(|c| c.shared.closed.load(Ordering::Acquire))
    {
        return;
    }
    let mut retired = lock(retired);
    let mut i = 0;
    while i < clients.len() {
        if clients[i].shared.closed.load(Ordering::Acquire) {
            let c = clients.swap_remove(i);
            let _ = c.stream.shutdown(Shutdown::Both);
            retired.extend(c.threads);
        } else {
            i += 1;
        }
    }
}

fn join_finished(retired: &Mutex<Vec<JoinHandle<()>>>) {
    let mut retired = lock(retired);
    let (done, running): (Vec<_>, Vec<_>) = retired.drain(..).partition(|t| t.is_finished());
    *retired = running;
    drop(retired);
    for t in done {
        let _ = t.join();
    }
}

fn accept_loop(listener: &TcpListener, shared: &Arc<Shared>) {
    loop {
        let accepted = listener.accept();
        if shared.shutdown.load(Ordering::Acquire) {
            return;
        }
        let (stream, peer) = match accepted {
            Ok(s) => s,
            Err(e) => {
                // Out of file descriptors and the like: say so, and keep serving.
                tracing::warn!(error = %e, "CoLa server: accept failed");
                std::thread::sleep(Duration::from_millis(50));
                continue;
            }
        };
        join_finished(&shared.retired);
        let connected = {
            let mut clients = lock(&shared.clients);
            retire_closed(&mut clients, &shared.retired);
            clients.len()
        };
        if connected >= shared.config.max_clients {
            add(&shared.counters.refused, 1);
            tracing::warn!(%peer, max = shared.config.max_clients, "CoLa server: too many clients, closing");
            let _ = stream.shutdown(Shutdown::Both);
            continue;
        }
        // Threads start outside the lock, so `publish` never waits for them.
        match start_client(stream, peer, shared) {
            Ok(handle) => {
                add(&shared.counters.accepted, 1);
                tracing::info!(%peer, "CoLa client connected");
                lock(&shared.clients).push(handle);
            }
            Err(e) => tracing::warn!(%peer, error = %e, "CoLa server: cannot serve client"),
        }
    }
}

fn start_client(
    stream: TcpStream,
    peer: SocketAddr,
    shared: &Arc<Shared>,
) -> std::io::Result<ClientHandle> {
    let _ = stream.set_nodelay(true);
    let reader_stream = stream.try_clone()?;
    let writer_stream = stream.try_clone()?;
    let session = lock(&shared.device).open();
    let client = Arc::new(ClientShared {
        peer,
        session,
        streaming: AtomicBool::new(false),
        closed: AtomicBool::new(false),
        sent: AtomicU64::new(0),
        dropped: AtomicU64::new(0),
        bad: AtomicU64::new(0),
    });
    let (tx, rx) = sync_channel(shared.config.queue_len.max(1));
    let writer = {
        let client = Arc::clone(&client);
        let shared = Arc::clone(shared);
        std::thread::Builder::new()
            .name(format!("cola-wr-{peer}"))
            .spawn(move || writer_loop(writer_stream, &rx, &client, &shared))?
    };
    let reader = {
        let reader_client = Arc::clone(&client);
        let reader_shared = Arc::clone(shared);
        let reader_tx = tx.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("cola-rd-{peer}"))
            .spawn(move || reader_loop(reader_stream, &reader_tx, &reader_client, &reader_shared));
        match spawned {
            Ok(t) => t,
            Err(e) => {
                client.closed.store(true, Ordering::Release);
                lock(&shared.device).close(session);
                let _ = stream.shutdown(Shutdown::Both);
                drop(tx);
                let _ = writer.join();
                return Err(e);
            }
        }
    };
    Ok(ClientHandle {
        shared: client,
        tx,
        stream,
        threads: vec![reader, writer],
    })
}

fn writer_loop(mut stream: TcpStream, rx: &Receiver<Out>, client: &ClientShared, shared: &Shared) {
    let mut streaming = false;
    while let Ok(out) = rx.recv() {
        let result = match out {
            Out::Scan(telegram) => {
                if !streaming {
                    continue;
                }
                let r = stream.write_all(&telegram);
                if r.is_ok() {
                    add(&client.sent, 1);
                    add(&shared.counters.sent, 1);
                }
                r
            }
            Out::Reply(bytes) => stream.write_all(&bytes),
            Out::Stream(on, ack) => {
                streaming = on;
                client.streaming.store(on, Ordering::Release);
                stream.write_all(&ack)
            }
            Out::Close => break,
        };
        if let Err(e) = result {
            tracing::debug!(peer = %client.peer, error = %e, "CoLa client: write failed, closing");
            break;
        }
    }
    client.streaming.store(false, Ordering::Release);
    client.closed.store(true, Ordering::Release);
    let _ = stream.shutdown(Shutdown::Both);
}

fn reader_loop(
    mut stream: TcpStream,
    tx: &SyncSender<Out>,
    client: &ClientShared,
    shared: &Shared,
) {
    let mut buf = vec![0u8; 4096];
    'read: loop {
        let n = match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) => break,
        };
        // The device answers under its lock; the answers are queued after it is freed.
        let answers = lock(&shared.device).receive(client.session, &buf[..n]);
        for answer in answers {
            if answer.bad {
                add(&client.bad, 1);
            }
            let out = match answer.stream {
                Some(on) => Out::Stream(on, answer.telegram),
                None => Out::Reply(answer.telegram),
            };
            if tx.send(out).is_err() {
                break 'read;
            }
            if answer.disconnect {
                tracing::warn!(peer = %client.peer, "CoLa client sends only bad telegrams, disconnecting");
                break 'read;
            }
        }
    }
    lock(&shared.device).close(client.session);
    client.closed.store(true, Ordering::Release);
    let _ = tx.send(Out::Close);
    tracing::info!(peer = %client.peer, "CoLa client disconnected");
}
