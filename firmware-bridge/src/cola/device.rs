//! [`Device`]: the emulated SICK scanner as a pure state machine, without sockets or
//! threads. It takes what each client (a session, named by a [`SessionId`]) sends and
//! returns what the device answers; [`ColaServer`](super::ColaServer) puts it on TCP.
//!
//! [`Device::handle`] is the whole device in one call: any bytes from a client (a
//! piece of its TCP stream: part of a telegram, several, garbage between them) in,
//! the framed answers out. It is total: no input makes it panic, and what it holds is
//! bounded by [`DeviceConfig::max_telegram`] per session.
//!
//! # User levels
//!
//! As on an LMS1xx, a client logs in with `sMN SetAccessMode <level> <hash>`, the
//! level and the hash of its password (SICK's defaults: 02 maintenance `B21ACE26`,
//! 03 authorized client `F4724744`, 04 service `81BE23AA`); any other pair answers
//! `sAN SetAccessMode 0` and leaves the session's level as it was. What needs which
//! level ([`required_level`]):
//!
//! | request | level | refused with |
//! |---|---|---|
//! | `sRN` (any read: `LMDscandata`, `DeviceIdent`, `SCdevicestate`), `sEN` (events: `LMDscandata`) | none | - |
//! | `sMN SetAccessMode` | none | - |
//! | `sMN Run` (log out) | any login (02 and up) | `sFA 1` |
//! | `sMN LMCstartmeas`, `LMCstopmeas`, `LMCstandby`, `mLMPsetscancfg`, `mEEwriteall`, `mSCreboot`, `mSCloadfacdef`, `mSCloadappdef` | authorized client (03) | `sFA 1` |
//! | `sMN SetPassword` | service (04) | `sFA 1` |
//! | `sWN` (any configuration write) | authorized client (03) | `sFA A` |
//!
//! `sMN Run` ends the session's login (its level drops to none), as it does on the
//! device.
//!
//! # One controlling client
//!
//! The first session that logs in is the device's controlling client until it
//! disconnects ([`Device::close`]); its `sMN Run` ends its login but not its control.
//! While it is connected, every other session's login is refused
//! (`sAN SetAccessMode 0`), so no second client can stop the measurement, change the
//! configuration or log in to do so. Reading clients (polls, streamed scans,
//! `DeviceIdent`) may be many. This is stricter than a real LMS1xx, which takes a
//! login on each of its connections.
//!
//! # Answers
//!
//! - `sEN LMDscandata 1|0` answers `sEA LMDscandata 1|0` and turns the session's
//!   stream on or off ([`Answer::stream`]); `sRN LMDscandata` answers the latest scan
//!   ([`Device::set_latest_scan`]) as `sRA`, or `sFA 4` before the first one.
//! - `sMN LMCstopmeas` (and `LMCstandby`) stop measuring for every session (it is one
//!   device) until `sMN LMCstartmeas`; [`Device::is_measuring`] says which.
//! - `sWN` of a variable an LMS1xx has (`LMDscandatacfg`, `LMPoutputRange`, ...)
//!   answers `sWA <name>`: accepted, not applied (the scans are the simulator's).
//!   `sMN mEEwriteall` answers `sAN mEEwriteall 1`. The methods of the table above
//!   that the emulation cannot carry out (`mLMPsetscancfg`: the scan configuration is
//!   the simulator's; `mSCreboot`, `mSCloadfacdef`, `mSCloadappdef`, `SetPassword`)
//!   answer `sFA 4` once the level is there.
//! - An unknown variable (`sRN`/`sWN`) is `sFA 3`, an unknown method (`sMN`) `sFA 2`,
//!   an unknown event (`sEN`) `sFA F`, any other command type (answers included)
//!   `sFA C`; a malformed telegram gets the code of its
//!   [`ParseError`](super::ParseError) kind ([`SopasError::for_parse_error`]), an
//!   oversize one `sFA 7`, one cut off by the next STX `sFA 8`. Bytes outside
//!   telegrams are ignored and counted. A session that sends
//!   [`DeviceConfig::max_consecutive_errors`] bad telegrams in a row is closed after
//!   the answer to the last one ([`Answer::disconnect`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use super::framing::{FrameError, TelegramDecoder};
use super::message::{Message, SopasError};
use super::scandata::ScanKind;
use super::{AUTHORIZED_CLIENT_PASSWORD, MAINTENANCE_PASSWORD, SERVICE_PASSWORD};

/// A client of the device (one TCP connection), as the caller numbers them.
pub type SessionId = u64;

/// SOPAS user levels, lowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum UserLevel {
    /// No login (SICK's "Run" level): reads and events only.
    Run = 0,
    /// Operator (1); an LMS1xx has no password for it.
    Operator = 1,
    /// Maintenance personnel (2, password `main`, hash `B21ACE26`).
    Maintenance = 2,
    /// Authorized client (3, password `client`, hash `F4724744`), the level drivers
    /// log in with.
    AuthorizedClient = 3,
    /// Service (4, password `servicelevel`, hash `81BE23AA`).
    Service = 4,
}

impl UserLevel {
    /// The level a `SetAccessMode` with `level` and `password` logs in to, if the pair
    /// is one of the device's.
    pub fn login(level: u8, password: u32) -> Option<UserLevel> {
        match (level, password) {
            (2, MAINTENANCE_PASSWORD) => Some(UserLevel::Maintenance),
            (3, AUTHORIZED_CLIENT_PASSWORD) => Some(UserLevel::AuthorizedClient),
            (4, SERVICE_PASSWORD) => Some(UserLevel::Service),
            _ => None,
        }
    }
}

/// Methods of an LMS1xx that need the authorized-client login.
const AUTHORIZED_METHODS: [&str; 8] = [
    "LMCstartmeas",
    "LMCstopmeas",
    "LMCstandby",
    "mLMPsetscancfg",
    "mEEwriteall",
    "mSCreboot",
    "mSCloadfacdef",
    "mSCloadappdef",
];

/// Methods of an LMS1xx that need the service login.
const SERVICE_METHODS: [&str; 1] = ["SetPassword"];

/// Variables of an LMS1xx a client may write (`sWN`) once logged in.
const WRITABLE_VARIABLES: [&str; 14] = [
    "LMDscandatacfg",
    "LMPoutputRange",
    "LCMcfg",
    "LFPmeanfilter",
    "LFPparticle",
    "FREchoFilter",
    "MMAlignmentMode",
    "EIHstCola",
    "EIIpAddr",
    "EIIpMask",
    "EIgate",
    "TSCRole",
    "TSCTCInterface",
    "TSCTCSrvAddr",
];

/// The user level a request needs, as on an LMS1xx (see the
/// [module documentation](self)).
pub fn required_level(msg: &Message) -> UserLevel {
    match msg {
        Message::StartMeasurement | Message::StopMeasurement => UserLevel::AuthorizedClient,
        Message::Run => UserLevel::Maintenance,
        Message::Other { kind, name, .. } => match kind.as_str() {
            "sWN" => UserLevel::AuthorizedClient,
            "sMN" if AUTHORIZED_METHODS.contains(&name.as_str()) => UserLevel::AuthorizedClient,
            "sMN" if SERVICE_METHODS.contains(&name.as_str()) => UserLevel::Service,
            _ => UserLevel::Run,
        },
        _ => UserLevel::Run,
    }
}

/// What the device is and how strict it is with its clients.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceConfig {
    /// The name `sRN DeviceIdent` answers (`LMS111`, `LMS511`, ...).
    pub device_name: String,
    /// The version `sRN DeviceIdent` answers.
    pub firmware_version: String,
    /// Longest request telegram accepted, bytes (at least 1).
    pub max_telegram: usize,
    /// Bad telegrams in a row after which a session is closed (at least 1).
    pub max_consecutive_errors: u32,
}

impl Default for DeviceConfig {
    fn default() -> Self {
        DeviceConfig {
            device_name: "LMS111".into(),
            firmware_version: format!("V{} ugv-hil", env!("CARGO_PKG_VERSION")),
            max_telegram: 4096,
            max_consecutive_errors: 64,
        }
    }
}

/// The device's answer to one telegram (or framing error) of a session.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Answer {
    /// The answer, framed (`STX ... ETX`), ready for the socket.
    pub telegram: Vec<u8>,
    /// The request was bad: it did not frame or parse.
    pub bad: bool,
    /// The request turned the session's scan stream on or off (`telegram` is its
    /// `sEA` acknowledgement, to be sent before any streamed scan).
    pub stream: Option<bool>,
    /// The session sent too many bad telegrams in a row: send `telegram`, then close
    /// the connection. The device has closed the session already.
    pub disconnect: bool,
}

/// Counters of a device since it started.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DeviceStats {
    /// Requests answered (good telegrams, refused ones included).
    pub requests: u64,
    /// Telegrams that did not parse or were badly framed.
    pub bad_telegrams: u64,
    /// Bytes received outside any telegram.
    pub garbage_bytes: u64,
    /// Sessions closed for sending too many bad telegrams.
    pub dropped_for_errors: u64,
    /// Requests refused for a missing or too low login (`sFA 1`, `sFA A`).
    pub access_denied: u64,
    /// Logins refused: a wrong level or password, or another session in control.
    pub logins_refused: u64,
}

/// One client's state.
#[derive(Debug)]
struct Session {
    level: UserLevel,
    streaming: bool,
    decoder: TelegramDecoder,
    garbage_seen: u64,
    errors_in_a_row: u32,
    /// A refused login was logged at warning level already.
    warned: bool,
}

impl Session {
    fn new(max_telegram: usize) -> Session {
        Session {
            level: UserLevel::Run,
            streaming: false,
            decoder: TelegramDecoder::new(max_telegram),
            garbage_seen: 0,
            errors_in_a_row: 0,
            warned: false,
        }
    }
}

/// The emulated scanner; see the [module documentation](self).
#[derive(Debug)]
pub struct Device {
    config: DeviceConfig,
    /// `sRA DeviceIdent ...`, framed.
    ident_reply: Vec<u8>,
    measuring: bool,
    /// The latest scan, framed as `sSN` (a poll answers it as `sRA`).
    latest: Option<Arc<Vec<u8>>>,
    /// The session in control (the first to log in, until it closes).
    controller: Option<SessionId>,
    sessions: BTreeMap<SessionId, Session>,
    next_id: SessionId,
    stats: DeviceStats,
}

/// `sFA 14` (internal error), framed: the answer when an answer cannot be encoded.
const INTERNAL_ERROR: &[u8] = b"\x02sFA 14\x03";

fn framed(msg: &Message) -> Vec<u8> {
    msg.to_telegram()
        .unwrap_or_else(|_| INTERNAL_ERROR.to_vec())
}

fn error(e: SopasError) -> Vec<u8> {
    framed(&Message::Error(e))
}

/// `<kind> <name> [args]`, framed, for answers without a variant of their own.
fn other(kind: &str, name: &str, args: &[u8]) -> Vec<u8> {
    framed(&Message::Other {
        kind: kind.into(),
        name: name.into(),
        args: args.to_vec(),
    })
}

impl Device {
    /// A device with no session, measuring, with no scan yet.
    ///
    /// Fails only when the device name or version cannot be written as CoLa-A
    /// (not Latin-1).
    pub fn new(config: DeviceConfig) -> Result<Device, super::EncodeError> {
        let ident_reply = Message::DeviceIdent {
            name: config.device_name.clone(),
            version: config.firmware_version.clone(),
        }
        .to_telegram()?;
        Ok(Device {
            config,
            ident_reply,
            measuring: true,
            latest: None,
            controller: None,
            sessions: BTreeMap::new(),
            next_id: 0,
            stats: DeviceStats::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DeviceConfig {
        &self.config
    }

    /// Open a session for a new client and return its id.
    pub fn open(&mut self) -> SessionId {
        while self.sessions.contains_key(&self.next_id) {
            self.next_id = self.next_id.wrapping_add(1);
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let session = Session::new(self.config.max_telegram);
        self.sessions.insert(id, session);
        id
    }

    /// Close a session (its client went away): its login and its control end. Closing
    /// a session that is not open does nothing.
    pub fn close(&mut self, id: SessionId) {
        self.sessions.remove(&id);
        if self.controller == Some(id) {
            self.controller = None;
            tracing::info!(session = id, "CoLa device: the controlling client left");
        }
    }

    fn session(&mut self, id: SessionId) -> &mut Session {
        let max_telegram = self.config.max_telegram;
        self.sessions
            .entry(id)
            .or_insert_with(|| Session::new(max_telegram))
    }

    /// Sessions open now.
    pub fn session_count(&self) -> usize {
        self.sessions.len()
    }

    /// A session's user level (`None`: not open).
    pub fn level(&self, id: SessionId) -> Option<UserLevel> {
        self.sessions.get(&id).map(|s| s.level)
    }

    /// Whether a session has asked for streamed scans (`None`: not open).
    pub fn is_streaming(&self, id: SessionId) -> Option<bool> {
        self.sessions.get(&id).map(|s| s.streaming)
    }

    /// The session in control, if any.
    pub fn controller(&self) -> Option<SessionId> {
        self.controller
    }

    /// Whether the device is measuring (not stopped with `sMN LMCstopmeas`).
    pub fn is_measuring(&self) -> bool {
        self.measuring
    }

    /// The scan a poll answers from now on: a whole `STX sSN LMDscandata ... ETX`
    /// telegram, as streamed.
    pub fn set_latest_scan(&mut self, telegram: Arc<Vec<u8>>) {
        self.latest = Some(telegram);
    }

    /// The counters.
    pub fn stats(&self) -> &DeviceStats {
        &self.stats
    }

    /// Take bytes a session sent (any piece of its stream) and return the answers to
    /// the telegrams they complete, in order. After an answer with
    /// [`Answer::disconnect`] the session is closed and the rest is ignored. A session
    /// that is not open is opened.
    pub fn receive(&mut self, id: SessionId, bytes: &[u8]) -> Vec<Answer> {
        let session = self.session(id);
        session.decoder.push(bytes);
        let garbage = session.decoder.garbage_bytes();
        let new_garbage = garbage.saturating_sub(session.garbage_seen);
        session.garbage_seen = garbage;
        self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(new_garbage);
        let mut answers = Vec::new();
        while let Some(item) = self
            .sessions
            .get_mut(&id)
            .and_then(|s| s.decoder.next_telegram())
        {
            let answer = self.answer_item(id, item);
            let done = answer.disconnect;
            answers.push(answer);
            if done {
                break;
            }
        }
        answers
    }

    /// [`Device::receive`] with the answers' bytes joined: what the device writes back
    /// to a client for `bytes`. Total: never panics, whatever the bytes.
    pub fn handle(&mut self, id: SessionId, bytes: &[u8]) -> Vec<u8> {
        self.receive(id, bytes)
            .into_iter()
            .flat_map(|a| a.telegram)
            .collect()
    }

    /// The answer to one telegram's content (the bytes between STX and ETX) from a
    /// session. A session that is not open is opened.
    pub fn request(&mut self, id: SessionId, payload: &[u8]) -> Answer {
        self.session(id);
        self.answer_item(id, Ok(payload.to_vec()))
    }

    fn answer_item(&mut self, id: SessionId, item: Result<Vec<u8>, FrameError>) -> Answer {
        let parsed = match item {
            Ok(payload) => Message::parse(&payload).map_err(|e| {
                tracing::debug!(session = id, error = %e, telegram = %super::preview(&payload), "CoLa device: bad telegram");
                if e.field == "command type" {
                    SopasError::UNKNOWN_COLA_COMMAND
                } else {
                    SopasError::for_parse_error(&e)
                }
            }),
            Err(FrameError::TooLong { .. }) => Err(SopasError::BUFFER_OVERFLOW),
            Err(FrameError::Unterminated { .. }) => Err(SopasError::BUFFER_UNDERFLOW),
        };
        match parsed {
            Ok(msg) => {
                self.stats.requests = self.stats.requests.saturating_add(1);
                if let Some(s) = self.sessions.get_mut(&id) {
                    s.errors_in_a_row = 0;
                }
                let (telegram, stream) = self.answer(id, msg);
                Answer {
                    telegram,
                    bad: false,
                    stream,
                    disconnect: false,
                }
            }
            Err(code) => {
                self.stats.bad_telegrams = self.stats.bad_telegrams.saturating_add(1);
                let limit = self.config.max_consecutive_errors.max(1);
                let errors = self.sessions.get_mut(&id).map_or(limit, |s| {
                    s.errors_in_a_row = s.errors_in_a_row.saturating_add(1);
                    s.errors_in_a_row
                });
                let disconnect = errors >= limit;
                if disconnect {
                    self.stats.dropped_for_errors = self.stats.dropped_for_errors.saturating_add(1);
                    tracing::debug!(
                        session = id,
                        errors,
                        "CoLa device: closing a session that sends only bad telegrams"
                    );
                    self.close(id);
                }
                Answer {
                    telegram: error(code),
                    bad: true,
                    stream: None,
                    disconnect,
                }
            }
        }
    }

    fn denied(&mut self, id: SessionId, msg: &Message, code: SopasError) -> Vec<u8> {
        self.stats.access_denied = self.stats.access_denied.saturating_add(1);
        tracing::debug!(session = id, request = %msg.command(), "CoLa device: refused, no login for it");
        error(code)
    }

    fn log_in(&mut self, id: SessionId, level: u8, password: u32) -> Vec<u8> {
        let refused = match UserLevel::login(level, password) {
            None => Some("wrong user level or password"),
            Some(_) if self.controller.is_some_and(|c| c != id) => {
                Some("another client is in control")
            }
            Some(l) => {
                self.session(id).level = l;
                if self.controller.is_none() {
                    tracing::info!(session = id, level = ?l, "CoLa device: a client took control");
                }
                self.controller = Some(id);
                None
            }
        };
        if let Some(reason) = refused {
            self.stats.logins_refused = self.stats.logins_refused.saturating_add(1);
            let session = self.session(id);
            if session.warned {
                tracing::debug!(session = id, level, reason, "CoLa device: login refused");
            } else {
                session.warned = true;
                tracing::warn!(session = id, level, reason, "CoLa device: login refused");
            }
        }
        framed(&Message::AccessModeAck(refused.is_none()))
    }

    /// The answer to a request that parsed, and the stream change it makes.
    fn answer(&mut self, id: SessionId, msg: Message) -> (Vec<u8>, Option<bool>) {
        let level = self.session(id).level;
        let needed = required_level(&msg);
        if level < needed {
            let code = match &msg {
                Message::Other { kind, .. } if kind == "sWN" => {
                    SopasError::VARIABLE_WRITE_ACCESS_DENIED
                }
                _ => SopasError::METHOD_ACCESS_DENIED,
            };
            return (self.denied(id, &msg, code), None);
        }
        let telegram = match msg {
            Message::PollScan => match &self.latest {
                Some(t) => {
                    let mut bytes = t.as_ref().clone();
                    if let Some(kind) = bytes.get_mut(1..4) {
                        kind.copy_from_slice(ScanKind::Polled.command_type().as_bytes());
                    }
                    bytes
                }
                None => error(SopasError::LOCAL_CONDITION_FAILED),
            },
            Message::StreamScans(on) => {
                self.session(id).streaming = on;
                return (framed(&Message::StreamScansAck(on)), Some(on));
            }
            Message::SetAccessMode { level, password } => self.log_in(id, level, password),
            Message::ReadDeviceIdent => self.ident_reply.clone(),
            Message::StartMeasurement => {
                self.measuring = true;
                framed(&Message::StartMeasurementAck(0))
            }
            Message::StopMeasurement => {
                self.measuring = false;
                tracing::info!(session = id, "CoLa device: measurement stopped");
                framed(&Message::StopMeasurementAck(0))
            }
            Message::Run => {
                self.session(id).level = UserLevel::Run;
                framed(&Message::RunAck(true))
            }
            Message::ReadDeviceState => framed(&Message::DeviceState(1)),
            Message::Other { kind, name, .. } => match (kind.as_str(), name.as_str()) {
                ("sWN", n) if WRITABLE_VARIABLES.contains(&n) => other("sWA", n, b""),
                ("sMN", "LMCstandby") => {
                    self.measuring = false;
                    other("sAN", "LMCstandby", b"0")
                }
                ("sMN", "mEEwriteall") => other("sAN", "mEEwriteall", b"1"),
                ("sMN", n) if AUTHORIZED_METHODS.contains(&n) || SERVICE_METHODS.contains(&n) => {
                    error(SopasError::LOCAL_CONDITION_FAILED)
                }
                ("sRN" | "sWN", _) => error(SopasError::VARIABLE_UNKNOWN_INDEX),
                ("sMN", _) => error(SopasError::METHOD_UNKNOWN_INDEX),
                ("sEN", _) => error(SopasError::EVENT_UNKNOWN_INDEX),
                _ => error(SopasError::UNKNOWN_COLA_COMMAND),
            },
            // Answers and events are what a device sends, not what it is sent.
            Message::Scan { .. }
            | Message::StreamScansAck(_)
            | Message::AccessModeAck(_)
            | Message::DeviceIdent { .. }
            | Message::StartMeasurementAck(_)
            | Message::StopMeasurementAck(_)
            | Message::RunAck(_)
            | Message::DeviceState(_)
            | Message::Error(_) => error(SopasError::UNKNOWN_COLA_COMMAND),
        };
        (telegram, None)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;
    use crate::cola::framing::{ETX, STX};
    use proptest::prelude::*;

    fn device() -> Device {
        Device::new(DeviceConfig::default()).unwrap()
    }

    /// The answer to one request, as text without STX and ETX.
    fn ask(d: &mut Device, id: SessionId, text: &str) -> String {
        let a = d.request(id, text.as_bytes());
        assert!(!a.bad, "{text}: {a:?}");
        let t = &a.telegram;
        assert_eq!((t.first(), t.last()), (Some(&STX), Some(&ETX)), "{text}");
        String::from_utf8(t[1..t.len() - 1].to_vec()).unwrap()
    }

    const LOGIN: &str = "sMN SetAccessMode 03 F4724744";

    /// A streamed scan telegram as the server keeps it.
    fn scan() -> Arc<Vec<u8>> {
        Arc::new(b"\x02sSN LMDscandata 1 0 89A27F 0 0 7 7\x03".to_vec())
    }

    #[test]
    fn unauthenticated_stop_measurement_is_refused_and_the_device_keeps_measuring() {
        let mut d = device();
        let id = d.open();
        assert_eq!(ask(&mut d, id, "sMN LMCstopmeas"), "sFA 1");
        assert!(d.is_measuring());
        assert_eq!(ask(&mut d, id, "sMN LMCstandby"), "sFA 1");
        assert_eq!(ask(&mut d, id, "sMN LMCstartmeas"), "sFA 1");
        assert_eq!(ask(&mut d, id, "sMN Run"), "sFA 1");
        assert!(d.is_measuring());
        assert_eq!(d.stats().access_denied, 4);

        assert_eq!(ask(&mut d, id, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(ask(&mut d, id, "sMN LMCstopmeas"), "sAN LMCstopmeas 0");
        assert!(!d.is_measuring());
        assert_eq!(ask(&mut d, id, "sMN LMCstartmeas"), "sAN LMCstartmeas 0");
        assert!(d.is_measuring());
        assert_eq!(ask(&mut d, id, "sMN LMCstandby"), "sAN LMCstandby 0");
        assert!(!d.is_measuring());
    }

    #[test]
    fn configuration_writes_and_setscancfg_need_the_authorized_client_login() {
        let mut d = device();
        let id = d.open();
        assert_eq!(
            ask(
                &mut d,
                id,
                "sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1"
            ),
            "sFA A"
        );
        assert_eq!(ask(&mut d, id, "sWN NoSuchVariable 1"), "sFA A");
        assert_eq!(
            ask(
                &mut d,
                id,
                "sMN mLMPsetscancfg +5000 +1 +5000 -450000 +2250000"
            ),
            "sFA 1"
        );
        assert_eq!(ask(&mut d, id, "sMN mEEwriteall"), "sFA 1");
        assert_eq!(ask(&mut d, id, "sMN SetPassword 03 12345678"), "sFA 1");

        assert_eq!(ask(&mut d, id, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(
            ask(
                &mut d,
                id,
                "sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1"
            ),
            "sWA LMDscandatacfg"
        );
        assert_eq!(ask(&mut d, id, "sWN NoSuchVariable 1"), "sFA 3");
        // The scan configuration is the simulator's: refused as a local condition.
        assert_eq!(
            ask(
                &mut d,
                id,
                "sMN mLMPsetscancfg +5000 +1 +5000 -450000 +2250000"
            ),
            "sFA 4"
        );
        assert_eq!(ask(&mut d, id, "sMN mEEwriteall"), "sAN mEEwriteall 1");
        // Changing a password needs the service level.
        assert_eq!(ask(&mut d, id, "sMN SetPassword 03 12345678"), "sFA 1");
        assert_eq!(
            ask(&mut d, id, "sMN SetAccessMode 04 81BE23AA"),
            "sAN SetAccessMode 1"
        );
        assert_eq!(ask(&mut d, id, "sMN SetPassword 03 12345678"), "sFA 4");
        assert_eq!(ask(&mut d, id, "sMN NoSuchMethod"), "sFA 2");
    }

    #[test]
    fn reads_and_scan_events_need_no_login() {
        let mut d = device();
        let id = d.open();
        assert_eq!(ask(&mut d, id, "sRN LMDscandata"), "sFA 4", "no scan yet");
        d.set_latest_scan(scan());
        assert_eq!(
            ask(&mut d, id, "sRN LMDscandata"),
            "sRA LMDscandata 1 0 89A27F 0 0 7 7"
        );
        let a = d.request(id, b"sEN LMDscandata 1");
        assert_eq!(a.telegram, b"\x02sEA LMDscandata 1\x03");
        assert_eq!((a.stream, d.is_streaming(id)), (Some(true), Some(true)));
        let a = d.request(id, b"sEN LMDscandata 0");
        assert_eq!((a.stream, d.is_streaming(id)), (Some(false), Some(false)));
        assert!(ask(&mut d, id, "sRN DeviceIdent").starts_with("sRA DeviceIdent 6 LMS111 "));
        assert_eq!(ask(&mut d, id, "sRN SCdevicestate"), "sRA SCdevicestate 1");
        assert_eq!(ask(&mut d, id, "sRN LMPscancfg"), "sFA 3");
        assert_eq!(ask(&mut d, id, "sEN LIDoutputstate 1"), "sFA F");
        assert_eq!(d.stats().access_denied, 0);
        assert_eq!(d.level(id), Some(UserLevel::Run));
    }

    #[test]
    fn logins_take_only_the_lms1xx_level_and_hash_pairs() {
        let mut d = device();
        let id = d.open();
        for refused in [
            "sMN SetAccessMode 03 12345678",
            "sMN SetAccessMode 02 F4724744",
            "sMN SetAccessMode 01 00000000",
            "sMN SetAccessMode 00 00000000",
            "sMN SetAccessMode 05 81BE23AA",
        ] {
            assert_eq!(ask(&mut d, id, refused), "sAN SetAccessMode 0", "{refused}");
            assert_eq!(d.level(id), Some(UserLevel::Run));
        }
        assert_eq!(d.controller(), None, "a refused login takes no control");
        assert_eq!(
            ask(&mut d, id, "sMN SetAccessMode 02 B21ACE26"),
            "sAN SetAccessMode 1"
        );
        assert_eq!(d.level(id), Some(UserLevel::Maintenance));
        // Maintenance is not enough to stop the measurement; it may log out.
        assert_eq!(ask(&mut d, id, "sMN LMCstopmeas"), "sFA 1");
        assert_eq!(ask(&mut d, id, "sMN Run"), "sAN Run 1");
        assert_eq!(d.level(id), Some(UserLevel::Run));
        // A wrong password keeps the level the session has.
        assert_eq!(ask(&mut d, id, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(
            ask(&mut d, id, "sMN SetAccessMode 03 00000000"),
            "sAN SetAccessMode 0"
        );
        assert_eq!(d.level(id), Some(UserLevel::AuthorizedClient));
        assert_eq!(d.stats().logins_refused, 6);
    }

    #[test]
    fn run_ends_the_login_but_not_the_control() {
        let mut d = device();
        let (a, b) = (d.open(), d.open());
        assert_eq!(ask(&mut d, a, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(ask(&mut d, a, "sMN Run"), "sAN Run 1");
        assert_eq!(ask(&mut d, a, "sMN LMCstopmeas"), "sFA 1");
        assert_eq!(d.controller(), Some(a));
        assert_eq!(ask(&mut d, b, LOGIN), "sAN SetAccessMode 0");
        assert_eq!(ask(&mut d, a, LOGIN), "sAN SetAccessMode 1");
    }

    #[test]
    fn a_second_controlling_client_is_refused_until_the_first_leaves() {
        let mut d = device();
        let (first, second) = (d.open(), d.open());
        assert_eq!(ask(&mut d, first, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(d.controller(), Some(first));
        for level in [
            LOGIN,
            "sMN SetAccessMode 04 81BE23AA",
            "sMN SetAccessMode 02 B21ACE26",
        ] {
            assert_eq!(ask(&mut d, second, level), "sAN SetAccessMode 0");
        }
        assert_eq!(ask(&mut d, second, "sMN LMCstopmeas"), "sFA 1");
        assert!(d.is_measuring());
        // Readers are served as before.
        assert_eq!(d.request(second, b"sEN LMDscandata 1").stream, Some(true));
        assert_eq!(
            ask(&mut d, second, "sRN SCdevicestate"),
            "sRA SCdevicestate 1"
        );
        // The controller goes on; once it leaves, another client may take control.
        assert_eq!(ask(&mut d, first, "sMN LMCstopmeas"), "sAN LMCstopmeas 0");
        d.close(first);
        assert_eq!(d.controller(), None);
        assert_eq!(ask(&mut d, second, LOGIN), "sAN SetAccessMode 1");
        assert_eq!(d.controller(), Some(second));
        assert_eq!(
            ask(&mut d, second, "sMN LMCstartmeas"),
            "sAN LMCstartmeas 0"
        );
    }

    #[test]
    fn handle_frames_the_stream_and_answers_in_order() {
        let mut d = device();
        let id = d.open();
        // Garbage, a telegram split over two pieces, two in one piece.
        assert_eq!(d.handle(id, b"junk\x02sRN SCdev"), b"");
        assert_eq!(
            d.handle(id, b"icestate\x03\x02sMN LMCstopmeas\x03\x02sXX x\x03"),
            b"\x02sRA SCdevicestate 1\x03\x02sFA 1\x03\x02sFA C\x03"
        );
        let mut big = vec![STX];
        big.extend(std::iter::repeat_n(b'A', 5000));
        big.extend_from_slice(b"\x03\x02sRN LMD\x02sMN Run\x03");
        assert_eq!(
            d.handle(id, &big),
            b"\x02sFA 7\x03\x02sFA 8\x03\x02sFA 1\x03"
        );
        let s = d.stats();
        assert_eq!(
            (s.garbage_bytes, s.bad_telegrams, s.requests),
            (4, 2, 4),
            "{s:?}"
        );
    }

    #[test]
    fn a_run_of_bad_telegrams_closes_the_session_and_ends_its_control() {
        let mut d = Device::new(DeviceConfig {
            max_consecutive_errors: 3,
            ..DeviceConfig::default()
        })
        .unwrap();
        let id = d.open();
        assert_eq!(ask(&mut d, id, LOGIN), "sAN SetAccessMode 1");
        let answers = d.receive(
            id,
            b"\x02?\x03\x02?\x03\x02sRN SCdevicestate\x03\x02?\x03\x02?\x03\x02?\x03\x02?\x03",
        );
        let closed: Vec<bool> = answers.iter().map(|a| a.disconnect).collect();
        assert_eq!(
            closed,
            [false, false, false, false, false, true],
            "a good one resets the count"
        );
        assert_eq!((d.controller(), d.level(id)), (None, None));
        assert_eq!(d.stats().dropped_for_errors, 1);
    }

    #[test]
    fn closing_a_session_that_is_not_open_does_nothing() {
        let mut d = device();
        let id = d.open();
        d.close(id + 1000);
        assert_eq!(d.session_count(), 1);
        // An id never opened is opened by its first request.
        assert_eq!(ask(&mut d, 77, "sRN SCdevicestate"), "sRA SCdevicestate 1");
        assert_eq!(d.session_count(), 2);
        assert_ne!(d.open(), 77);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// Any bytes from any sessions: no panic, and what comes back is whole telegrams.
        #[test]
        fn handle_is_total_and_answers_whole_telegrams(
            pieces in proptest::collection::vec(
                (0u64..4, proptest::collection::vec(
                    prop_oneof![
                        3 => any::<u8>(),
                        1 => Just(STX),
                        1 => Just(ETX),
                        1 => Just(b' '),
                    ],
                    0..300,
                )),
                0..20,
            ),
            prefix in prop_oneof![
                Just(&b""[..]),
                Just(&b"\x02sMN SetAccessMode 03 F4724744\x03"[..]),
                Just(&b"\x02sMN "[..]),
                Just(&b"\x02sWN "[..]),
                Just(&b"\x02sEN LMDscandata "[..]),
            ],
        ) {
            let mut d = Device::new(DeviceConfig { max_telegram: 64, ..DeviceConfig::default() }).unwrap();
            d.set_latest_scan(scan());
            for (id, bytes) in pieces {
                let mut input = prefix.to_vec();
                input.extend_from_slice(&bytes);
                let out = d.handle(id, &input);
                let mut decoder = TelegramDecoder::new(usize::MAX);
                decoder.push(&out);
                prop_assert_eq!(decoder.garbage_bytes(), 0);
                prop_assert_eq!(decoder.partial_len(), 0);
                while let Some(t) = decoder.next_telegram() {
                    prop_assert!(t.is_ok());
                }
                if id % 2 == 1 {
                    d.close(id);
                }
            }
            prop_assert!(d.controller().is_none_or(|c| d.level(c).is_some()));
        }
    }
}
