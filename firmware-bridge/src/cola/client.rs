//! [`ColaClient`]: the driver of a SICK scanner (or of a [`ColaServer`](super::ColaServer))
//! over CoLa-A on TCP.
//!
//! [`ColaClient::connect`] opens the connection (with a timeout per address), logs in
//! as authorized client when [`ClientConfig::login`] is set, reads `DeviceIdent`,
//! optionally starts the measurement (`LMCstartmeas`, `Run`), and asks for scans
//! (`sEN LMDscandata 1`). [`ColaClient::next_frame`] then yields each streamed scan as
//! a [`LaserFrame`] (conventions in the [parent module](super)).
//!
//! # Connection loss
//!
//! The client never reconnects by itself: when the scanner closes the connection or a
//! socket call fails, `next_frame` returns [`ColaError::ConnectionLost`] or
//! [`ColaError::Io`] and every later call fails the same way until
//! [`ColaClient::reconnect`] succeeds (it re-runs the whole handshake on the same
//! address). The scan-counter unwrapping carries over, so sequence numbers stay
//! monotonic across a reconnect. `ugv-sick` retries `reconnect` once per second.
//!
//! A telegram that is malformed, or a scan that does not convert, is returned as its
//! error ([`ColaError::Parse`], [`ColaError::Frame`], [`ColaError::Convert`]) and
//! consumed: the next call goes on with the next telegram.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use super::convert::{DecodeOptions, frame_from_scan, stamp_of_device_time};
use super::framing::{DEFAULT_MAX_TELEGRAM, TelegramDecoder};
use super::message::Message;
use super::scandata::{ScanData, ScanKind};
use super::{AUTHORIZED_CLIENT_PASSWORD, ColaError, preview};
use crate::laser::LaserFrame;

/// Scans kept while waiting for the answer to a request.
const PENDING_SCANS: usize = 64;

/// How the driver talks to the scanner.
#[derive(Clone, Debug, PartialEq)]
pub struct ClientConfig {
    /// Time allowed for the TCP connection, per resolved address.
    pub connect_timeout: Duration,
    /// Time allowed for the answer to each request.
    pub reply_timeout: Duration,
    /// Log in as authorized client (`sMN SetAccessMode 03 F4724744`) first.
    pub login: bool,
    /// Send `sMN LMCstartmeas` and `sMN Run` before streaming (a scanner that was
    /// stopped; needs `login` on a real device).
    pub start_measurement: bool,
    /// Range limits and channels of the frames.
    pub decode: DecodeOptions,
    /// Stamp frames with the host clock even when the telegram has a time stamp (for
    /// scanners whose clock is not synchronised).
    pub host_stamps: bool,
    /// Longest telegram accepted, bytes.
    pub max_telegram: usize,
}

impl Default for ClientConfig {
    fn default() -> Self {
        ClientConfig {
            connect_timeout: Duration::from_secs(5),
            reply_timeout: Duration::from_secs(5),
            login: true,
            start_measurement: false,
            decode: DecodeOptions::default(),
            host_stamps: false,
            max_telegram: DEFAULT_MAX_TELEGRAM,
        }
    }
}

/// What the scanner says it is (`sRA DeviceIdent`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DeviceIdent {
    /// Device name, e.g. `LMS111` or `LMS10x_FieldEval`.
    pub name: String,
    /// Firmware version.
    pub version: String,
}

/// Counters of a client since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClientStats {
    /// Frames returned by `next_frame`/`poll_frame`.
    pub frames: u64,
    /// Telegrams received (any kind, well-formed or not).
    pub telegrams: u64,
    /// Scans missing between consecutive scan counters.
    pub lost_scans: u64,
    /// Telegrams that were badly framed, did not parse or did not convert.
    pub bad_telegrams: u64,
    /// Bytes received outside any telegram.
    pub garbage_bytes: u64,
    /// Telegrams received that were none of what the driver waits for.
    pub ignored: u64,
    /// Successful connections (the first and every reconnect).
    pub connects: u64,
}

/// The driver of one scanner; see the [module documentation](self).
#[derive(Debug)]
pub struct ColaClient {
    address: String,
    config: ClientConfig,
    stream: Option<TcpStream>,
    peer: Option<SocketAddr>,
    decoder: TelegramDecoder,
    /// Garbage bytes of earlier connections' decoders.
    garbage_before: u64,
    pending: VecDeque<(Box<ScanData>, u64)>,
    ident: DeviceIdent,
    /// (last raw scan counter, its unwrapped sequence).
    last_counter: Option<(u16, u64)>,
    stats: ClientStats,
    buf: Vec<u8>,
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

fn io_err(action: &'static str) -> impl FnOnce(std::io::Error) -> ColaError {
    move |source| ColaError::Io { action, source }
}

/// The answer type of a request type: sRN→sRA, sWN→sWA, sMN→sAN, sEN→sEA.
fn answer_command(request: &str) -> Option<String> {
    let (kind, name) = request.split_once(' ')?;
    let kind = match kind {
        "sRN" => "sRA",
        "sWN" => "sWA",
        "sMN" => "sAN",
        "sEN" => "sEA",
        _ => return None,
    };
    Some(format!("{kind} {name}"))
}

impl ColaClient {
    /// Connect to the scanner at `address` (`host:port`; port 2111 on a SICK) and
    /// start streaming; see the [module documentation](self).
    pub fn connect(address: &str, config: ClientConfig) -> Result<ColaClient, ColaError> {
        let mut client = ColaClient {
            address: address.to_owned(),
            decoder: TelegramDecoder::new(config.max_telegram),
            config,
            stream: None,
            peer: None,
            garbage_before: 0,
            pending: VecDeque::new(),
            ident: DeviceIdent::default(),
            last_counter: None,
            stats: ClientStats::default(),
            buf: vec![0; 64 * 1024],
        };
        client.reconnect()?;
        Ok(client)
    }

    /// Drop the connection (if any) and connect again: login, `DeviceIdent`, start of
    /// streaming, as [`ColaClient::connect`].
    pub fn reconnect(&mut self) -> Result<(), ColaError> {
        self.disconnect();
        let addrs: Vec<SocketAddr> = self
            .address
            .to_socket_addrs()
            .map_err(|e| ColaError::Address {
                address: self.address.clone(),
                reason: e.to_string(),
            })?
            .collect();
        if addrs.is_empty() {
            return Err(ColaError::Address {
                address: self.address.clone(),
                reason: "resolves to no address".into(),
            });
        }
        let mut last_error = None;
        for addr in &addrs {
            match TcpStream::connect_timeout(addr, self.config.connect_timeout) {
                Ok(stream) => {
                    let _ = stream.set_nodelay(true);
                    stream
                        .set_write_timeout(Some(self.config.reply_timeout))
                        .map_err(io_err("set the write timeout"))?;
                    self.stream = Some(stream);
                    self.peer = Some(*addr);
                    break;
                }
                Err(e) => last_error = Some(e),
            }
        }
        if self.stream.is_none() {
            return Err(ColaError::Connect {
                address: self.address.clone(),
                source: last_error.unwrap_or_else(|| std::io::Error::other("no address")),
            });
        }
        match self.handshake() {
            Ok(()) => {
                self.stats.connects += 1;
                tracing::info!(
                    address = %self.address,
                    device = %self.ident.name,
                    version = %self.ident.version,
                    "connected to the scanner, scans streaming"
                );
                Ok(())
            }
            Err(e) => {
                self.disconnect();
                Err(e)
            }
        }
    }

    fn handshake(&mut self) -> Result<(), ColaError> {
        if self.config.login {
            let request = Message::SetAccessMode {
                level: 3,
                password: AUTHORIZED_CLIENT_PASSWORD,
            };
            match self.request(&request)? {
                Message::AccessModeAck(true) => {}
                Message::AccessModeAck(false) => return Err(ColaError::AccessDenied { level: 3 }),
                other => return Err(unexpected(&request, &other)),
            }
        }
        let request = Message::ReadDeviceIdent;
        match self.request(&request)? {
            Message::DeviceIdent { name, version } => self.ident = DeviceIdent { name, version },
            other => return Err(unexpected(&request, &other)),
        }
        if self.config.start_measurement {
            let request = Message::StartMeasurement;
            match self.request(&request)? {
                Message::StartMeasurementAck(0) => {}
                other => return Err(unexpected(&request, &other)),
            }
            let request = Message::Run;
            match self.request(&request)? {
                Message::RunAck(true) => {}
                other => return Err(unexpected(&request, &other)),
            }
        }
        let request = Message::StreamScans(true);
        match self.request(&request)? {
            Message::StreamScansAck(true) => Ok(()),
            other => Err(unexpected(&request, &other)),
        }
    }

    /// Close the connection (after a best-effort `sEN LMDscandata 0`).
    pub fn disconnect(&mut self) {
        if let Some(mut stream) = self.stream.take() {
            if let Ok(bytes) = Message::StreamScans(false).to_telegram() {
                let _ = stream.write_all(&bytes);
            }
            let _ = stream.shutdown(Shutdown::Both);
        }
        self.garbage_before += self.decoder.garbage_bytes();
        self.decoder = TelegramDecoder::new(self.config.max_telegram);
        self.pending.clear();
    }

    /// Whether a connection is open.
    pub fn is_connected(&self) -> bool {
        self.stream.is_some()
    }

    /// The address given to `connect`.
    pub fn address(&self) -> &str {
        &self.address
    }

    /// The socket address of the scanner, once connected.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }

    /// What the scanner said it is.
    pub fn device_ident(&self) -> &DeviceIdent {
        &self.ident
    }

    /// The counters.
    pub fn stats(&self) -> ClientStats {
        ClientStats {
            garbage_bytes: self.garbage_before + self.decoder.garbage_bytes(),
            ..self.stats
        }
    }

    /// Send a request and wait for its answer (`sFA` is [`ColaError::Device`]).
    /// Scans streamed meanwhile are kept for `next_frame` (up to 64).
    pub fn request(&mut self, request: &Message) -> Result<Message, ColaError> {
        let command = request.command();
        let expected = match request {
            Message::PollScan => "sRA LMDscandata".to_owned(),
            _ => answer_command(&command).unwrap_or_default(),
        };
        let bytes = request.to_telegram()?;
        self.stream()?
            .write_all(&bytes)
            .map_err(io_err("send a request"))?;
        let timeout = self.config.reply_timeout;
        let deadline = Instant::now() + timeout;
        loop {
            let Some(item) = self.next_message(deadline)? else {
                return Err(ColaError::Timeout {
                    waiting_for: format!("answer to {command}"),
                    after: timeout,
                });
            };
            let msg = match item {
                Ok(msg) => msg,
                Err(e) => {
                    tracing::warn!(error = %e, "scanner sent a bad telegram");
                    continue;
                }
            };
            match msg {
                Message::Error(error) => {
                    return Err(ColaError::Device {
                        request: command,
                        error,
                    });
                }
                Message::Scan {
                    kind: ScanKind::Streamed,
                    data,
                } => {
                    if self.pending.len() >= PENDING_SCANS {
                        self.pending.pop_front();
                    }
                    self.pending.push_back((data, now_ns()));
                }
                m if m.command() == expected => return Ok(m),
                m => {
                    self.stats.ignored += 1;
                    tracing::debug!(command = %m.command(), "ignored a telegram");
                }
            }
        }
    }

    /// Poll one scan (`sRN LMDscandata`) and return it as a frame.
    pub fn poll_frame(&mut self) -> Result<LaserFrame, ColaError> {
        match self.request(&Message::PollScan)? {
            Message::Scan { data, .. } => self.frame_of(&data, now_ns()),
            other => Err(unexpected(&Message::PollScan, &other)),
        }
    }

    /// The next streamed scan as a frame, waiting up to `timeout`; `Ok(None)` when none
    /// came. See the [module documentation](self) for errors.
    pub fn next_frame(&mut self, timeout: Duration) -> Result<Option<LaserFrame>, ColaError> {
        if let Some((data, received)) = self.pending.pop_front() {
            return self.frame_of(&data, received).map(Some);
        }
        let deadline = Instant::now() + timeout;
        loop {
            let Some(item) = self.next_message(deadline)? else {
                return Ok(None);
            };
            match item? {
                Message::Scan { data, .. } => return self.frame_of(&data, now_ns()).map(Some),
                Message::Error(error) => {
                    self.stats.ignored += 1;
                    tracing::warn!(%error, "scanner sent an error answer nobody asked for");
                }
                m => {
                    self.stats.ignored += 1;
                    tracing::debug!(command = %m.command(), "ignored a telegram");
                }
            }
        }
    }

    fn stream(&mut self) -> Result<&mut TcpStream, ColaError> {
        self.stream
            .as_mut()
            .ok_or_else(|| ColaError::ConnectionLost {
                address: self.address.clone(),
            })
    }

    fn frame_of(&mut self, scan: &ScanData, received_ns: u64) -> Result<LaserFrame, ColaError> {
        let mut frame = match frame_from_scan(scan, &self.config.decode) {
            Ok(f) => f,
            Err(e) => {
                self.stats.bad_telegrams += 1;
                return Err(e.into());
            }
        };
        let device_stamp = scan.time.as_ref().and_then(stamp_of_device_time);
        frame.stamp_ns = match device_stamp {
            Some(stamp) if !self.config.host_stamps => stamp,
            _ => {
                // The scan began (transmission - start) µs before it was sent.
                let delay_us = scan
                    .time_of_transmission_us
                    .wrapping_sub(scan.time_since_startup_us);
                let delay_ns = if delay_us < 1_000_000 {
                    u64::from(delay_us) * 1000
                } else {
                    0
                };
                received_ns.saturating_sub(delay_ns)
            }
        };
        frame.sequence = self.unwrap_counter(scan.scan_counter);
        self.stats.frames += 1;
        Ok(frame)
    }

    /// The 16-bit scan counter as a monotonic 64-bit sequence.
    fn unwrap_counter(&mut self, counter: u16) -> u64 {
        let seq = match self.last_counter {
            None => u64::from(counter),
            Some((last, last_seq)) => {
                let ahead = counter.wrapping_sub(last);
                if ahead < 0x8000 {
                    if ahead > 1 {
                        self.stats.lost_scans += u64::from(ahead - 1);
                    }
                    last_seq + u64::from(ahead)
                } else {
                    // The counter went back: the scanner restarted. Keep counting up.
                    tracing::warn!(last, counter, "scan counter went back (scanner restarted?)");
                    last_seq + 1
                }
            }
        };
        self.last_counter = Some((counter, seq));
        seq
    }

    /// The next telegram, parsed (inner error: a bad telegram, consumed), or `None` at
    /// the deadline. The outer error is the connection's.
    fn next_message(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<Result<Message, ColaError>>, ColaError> {
        loop {
            if let Some(item) = self.decoder.next_telegram() {
                self.stats.telegrams += 1;
                let parsed = match item {
                    Ok(payload) => Message::parse(&payload).map_err(|error| ColaError::Parse {
                        command: preview(&payload),
                        error,
                    }),
                    Err(e) => Err(ColaError::Frame(e)),
                };
                if parsed.is_err() {
                    self.stats.bad_telegrams += 1;
                }
                return Ok(Some(parsed));
            }
            let remaining = deadline.saturating_duration_since(Instant::now());
            if remaining.is_zero() {
                return Ok(None);
            }
            let address = self.address.clone();
            let Some(stream) = self.stream.as_mut() else {
                return Err(ColaError::ConnectionLost { address });
            };
            stream
                .set_read_timeout(Some(remaining))
                .map_err(io_err("set the read timeout"))?;
            match stream.read(&mut self.buf) {
                Ok(0) => {
                    self.disconnect();
                    return Err(ColaError::ConnectionLost { address });
                }
                Ok(n) => self.decoder.push(&self.buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None);
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(source) => {
                    self.disconnect();
                    return Err(ColaError::Io {
                        action: "read from the scanner",
                        source,
                    });
                }
            }
        }
    }
}

impl Drop for ColaClient {
    fn drop(&mut self) {
        self.disconnect();
    }
}

fn unexpected(request: &Message, answer: &Message) -> ColaError {
    ColaError::UnexpectedAnswer {
        request: request.command(),
        answer: answer.command(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answer_types() {
        assert_eq!(
            answer_command("sRN DeviceIdent").as_deref(),
            Some("sRA DeviceIdent")
        );
        assert_eq!(answer_command("sMN Run").as_deref(), Some("sAN Run"));
        assert_eq!(
            answer_command("sEN LMDscandata").as_deref(),
            Some("sEA LMDscandata")
        );
        assert_eq!(answer_command("sFA"), None);
    }
}
