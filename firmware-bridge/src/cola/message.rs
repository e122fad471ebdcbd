//! The CoLa-A commands and answers the server and the driver exchange.
//!
//! | request | answer |
//! |---|---|
//! | `sRN LMDscandata` (poll one scan) | `sRA LMDscandata ...` |
//! | `sEN LMDscandata 1` / `0` (start/stop streaming) | `sEA LMDscandata 1` / `0`, then `sSN LMDscandata ...` per scan |
//! | `sMN SetAccessMode 03 F4724744` (log in as authorized client) | `sAN SetAccessMode 1` (0: refused) |
//! | `sRN DeviceIdent` | `sRA DeviceIdent 6 LMS111 10 V1.0 ugv-hil` (length-prefixed name and version) |
//! | `sMN LMCstartmeas` / `sMN LMCstopmeas` | `sAN LMCstartmeas 0` / `sAN LMCstopmeas 0` (0: done) |
//! | `sMN Run` (leave configuration mode) | `sAN Run 1` |
//! | `sRN SCdevicestate` | `sRA SCdevicestate 1` (0 busy, 1 ready, 2 error) |
//! | anything the device does not know | `sFA <code>` ([`SopasError`]) |

use std::fmt;

use super::fields::{
    Cursor, EncodeError, ParseError, ParseErrorKind, Writer, check_text, token_text,
};
use super::framing::frame_telegram;
use super::scandata::{ScanData, ScanKind, latin1};

/// A SOPAS error code, the argument of an `sFA` answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SopasError(pub u16);

impl SopasError {
    /// Wrong user level, access to the method not allowed.
    pub const METHOD_ACCESS_DENIED: SopasError = SopasError(0x1);
    /// Unknown method.
    pub const METHOD_UNKNOWN_INDEX: SopasError = SopasError(0x2);
    /// Unknown variable.
    pub const VARIABLE_UNKNOWN_INDEX: SopasError = SopasError(0x3);
    /// Local condition violated (e.g. no scan to answer with yet).
    pub const LOCAL_CONDITION_FAILED: SopasError = SopasError(0x4);
    /// Invalid data given.
    pub const INVALID_DATA: SopasError = SopasError(0x5);
    /// The telegram was larger than the device's buffer.
    pub const BUFFER_OVERFLOW: SopasError = SopasError(0x7);
    /// The telegram ended before its arguments.
    pub const BUFFER_UNDERFLOW: SopasError = SopasError(0x8);
    /// Wrong user level, writing the variable not allowed (no login, or too low).
    pub const VARIABLE_WRITE_ACCESS_DENIED: SopasError = SopasError(0xA);
    /// Unknown command type.
    pub const UNKNOWN_COLA_COMMAND: SopasError = SopasError(0xC);
    /// Unknown event.
    pub const EVENT_UNKNOWN_INDEX: SopasError = SopasError(0xF);
    /// A number too large for its argument.
    pub const COLA_A_VALUE_OVERFLOW: SopasError = SopasError(0x10);
    /// A character that does not belong in the argument.
    pub const COLA_A_INVALID_CHARACTER: SopasError = SopasError(0x11);

    /// SICK's name of the code (`Sopas_Error_METHODIN_ACCESSDENIED`, ...).
    pub fn name(self) -> &'static str {
        const NAMES: [&str; 27] = [
            "Sopas_Ok",
            "Sopas_Error_METHODIN_ACCESSDENIED",
            "Sopas_Error_METHODIN_UNKNOWNINDEX",
            "Sopas_Error_VARIABLE_UNKNOWNINDEX",
            "Sopas_Error_LOCALCONDITIONFAILED",
            "Sopas_Error_INVALID_DATA",
            "Sopas_Error_UNKNOWN_ERROR",
            "Sopas_Error_BUFFER_OVERFLOW",
            "Sopas_Error_BUFFER_UNDERFLOW",
            "Sopas_Error_ERROR_UNKNOWN_TYPE",
            "Sopas_Error_VARIABLE_WRITE_ACCESSDENIED",
            "Sopas_Error_UNKNOWN_CMD_FOR_NAMESERVER",
            "Sopas_Error_UNKNOWN_COLA_COMMAND",
            "Sopas_Error_METHODIN_SERVER_BUSY",
            "Sopas_Error_FLEX_OUT_OF_BOUNDS",
            "Sopas_Error_EVENTREG_UNKNOWNINDEX",
            "Sopas_Error_COLA_A_VALUE_OVERFLOW",
            "Sopas_Error_COLA_A_INVALID_CHARACTER",
            "Sopas_Error_OSAI_NO_MESSAGE",
            "Sopas_Error_OSAI_NO_ANSWER_MESSAGE",
            "Sopas_Error_INTERNAL",
            "Sopas_Error_HubAddressCorrupted",
            "Sopas_Error_HubAddressDecoding",
            "Sopas_Error_HubAddressAddressExceeded",
            "Sopas_Error_HubAddressBlankExpected",
            "Sopas_Error_AsyncMethodsAreSuppressed",
            "Sopas_Error_ComplexArraysNotSupported",
        ];
        NAMES
            .get(usize::from(self.0))
            .copied()
            .unwrap_or("unknown SOPAS error")
    }

    /// The code a device answers a telegram with that did not parse.
    pub fn for_parse_error(error: &ParseError) -> SopasError {
        match error.kind {
            ParseErrorKind::Missing => SopasError::BUFFER_UNDERFLOW,
            ParseErrorKind::OutOfRange { .. } | ParseErrorKind::NotFlag { .. } => {
                SopasError::COLA_A_VALUE_OVERFLOW
            }
            ParseErrorKind::NotHex { .. }
            | ParseErrorKind::NotDecimal { .. }
            | ParseErrorKind::BadName { .. }
            | ParseErrorKind::BadString { .. } => SopasError::COLA_A_INVALID_CHARACTER,
            ParseErrorKind::CountMismatch { .. } | ParseErrorKind::Trailing { .. } => {
                SopasError::INVALID_DATA
            }
        }
    }
}

impl fmt::Display for SopasError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "sFA {:X} ({})", self.0, self.name())
    }
}

/// A CoLa-A telegram, request or answer; see the [module documentation](self).
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// `sRN LMDscandata`: poll one scan.
    PollScan,
    /// `sRA LMDscandata ...` (polled) or `sSN LMDscandata ...` (streamed).
    Scan { kind: ScanKind, data: Box<ScanData> },
    /// `sEN LMDscandata 1|0`: start or stop streaming scans.
    StreamScans(bool),
    /// `sEA LMDscandata 1|0`: streaming started or stopped.
    StreamScansAck(bool),
    /// `sMN SetAccessMode <level> <password hash>`: log in (level 3, `F4724744`:
    /// authorized client).
    SetAccessMode { level: u8, password: u32 },
    /// `sAN SetAccessMode 1|0`: logged in, or refused.
    AccessModeAck(bool),
    /// `sRN DeviceIdent`.
    ReadDeviceIdent,
    /// `sRA DeviceIdent <len> <name> <len> <version>`.
    DeviceIdent { name: String, version: String },
    /// `sMN LMCstartmeas`: start measuring (laser and motor on).
    StartMeasurement,
    /// `sAN LMCstartmeas <status>`: 0 done, 1 error.
    StartMeasurementAck(u8),
    /// `sMN LMCstopmeas`: stop measuring.
    StopMeasurement,
    /// `sAN LMCstopmeas <status>`: 0 done, 1 error.
    StopMeasurementAck(u8),
    /// `sMN Run`: leave configuration mode.
    Run,
    /// `sAN Run 1|0`.
    RunAck(bool),
    /// `sRN SCdevicestate`.
    ReadDeviceState,
    /// `sRA SCdevicestate <state>`: 0 busy, 1 ready, 2 error.
    DeviceState(u8),
    /// `sFA <code>`: the device refused the last request.
    Error(SopasError),
    /// Any other well-formed telegram: its type (`sRN`, `sWN`, ...), name and raw
    /// arguments.
    Other {
        kind: String,
        name: String,
        args: Vec<u8>,
    },
}

/// Command types: `s` then two letters (sRN, sRA, sWN, sWA, sMN, sAN, sEN, sEA, sSN,
/// sFA).
fn is_command_type(token: &[u8]) -> bool {
    token.len() == 3 && token[0] == b's' && token[1..].iter().all(u8::is_ascii_alphabetic)
}

/// A command name: printable ASCII without spaces.
fn is_command_name(token: &[u8]) -> bool {
    !token.is_empty() && token.iter().all(|b| b.is_ascii_graphic())
}

/// The (type, name) pairs that have their own [`Message`] variant.
fn is_known(kind: &[u8], name: &[u8]) -> bool {
    matches!(
        (kind, name),
        (b"sRN" | b"sRA" | b"sSN" | b"sEN" | b"sEA", b"LMDscandata")
            | (b"sMN" | b"sAN", b"SetAccessMode")
            | (b"sRN" | b"sRA", b"DeviceIdent")
            | (b"sMN" | b"sAN", b"LMCstartmeas")
            | (b"sMN" | b"sAN", b"LMCstopmeas")
            | (b"sMN" | b"sAN", b"Run")
            | (b"sRN" | b"sRA", b"SCdevicestate")
    )
}

impl Message {
    /// Parse a telegram's content (without STX and ETX).
    pub fn parse(payload: &[u8]) -> Result<Message, ParseError> {
        let mut c = Cursor::new(payload);
        let (kind, at) = c.token("command type")?;
        if !is_command_type(kind) {
            return Err(c.error(
                "command type",
                at,
                ParseErrorKind::BadName {
                    token: token_text(kind),
                    what: "command type (such as sRN)",
                },
            ));
        }
        if kind == b"sFA" {
            let code = c.u16("error code")?;
            c.end("error code")?;
            return Ok(Message::Error(SopasError(code)));
        }
        let (name, at) = c.token("command name")?;
        if !is_command_name(name) {
            return Err(c.error(
                "command name",
                at,
                ParseErrorKind::BadName {
                    token: token_text(name),
                    what: "command name",
                },
            ));
        }
        let msg = match (kind, name) {
            (b"sRN", b"LMDscandata") => Message::PollScan,
            (b"sRA" | b"sSN", b"LMDscandata") => {
                let kind = if kind == b"sRA" {
                    ScanKind::Polled
                } else {
                    ScanKind::Streamed
                };
                let data = ScanData::parse_fields(&mut c)?;
                Message::Scan {
                    kind,
                    data: Box::new(data),
                }
            }
            (b"sEN", b"LMDscandata") => Message::StreamScans(c.flag("start/stop")?),
            (b"sEA", b"LMDscandata") => Message::StreamScansAck(c.flag("start/stop")?),
            (b"sMN", b"SetAccessMode") => Message::SetAccessMode {
                level: c.u8("user level")?,
                password: c.u32("password hash")?,
            },
            (b"sAN", b"SetAccessMode") => Message::AccessModeAck(c.flag("success")?),
            (b"sRN", b"DeviceIdent") => Message::ReadDeviceIdent,
            (b"sRA", b"DeviceIdent") => Message::DeviceIdent {
                name: latin1(&c.flex("device name")?),
                version: latin1(&c.flex("device version")?),
            },
            (b"sMN", b"LMCstartmeas") => Message::StartMeasurement,
            (b"sAN", b"LMCstartmeas") => Message::StartMeasurementAck(c.u8("status")?),
            (b"sMN", b"LMCstopmeas") => Message::StopMeasurement,
            (b"sAN", b"LMCstopmeas") => Message::StopMeasurementAck(c.u8("status")?),
            (b"sMN", b"Run") => Message::Run,
            (b"sAN", b"Run") => Message::RunAck(c.flag("success")?),
            (b"sRN", b"SCdevicestate") => Message::ReadDeviceState,
            (b"sRA", b"SCdevicestate") => Message::DeviceState(c.u8("device state")?),
            _ => Message::Other {
                kind: String::from_utf8_lossy(kind).into_owned(),
                name: String::from_utf8_lossy(name).into_owned(),
                args: c.rest().to_vec(),
            },
        };
        c.end(&String::from_utf8_lossy(name))?;
        Ok(msg)
    }

    /// Append the telegram's content (without STX and ETX) to `out`.
    pub fn encode_into(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        if let Message::Scan { kind, data } = self {
            return data.encode_into(*kind, out);
        }
        let mut w = Writer { out };
        match self {
            Message::Scan { .. } => {}
            Message::PollScan => w.raw(b"sRN LMDscandata"),
            Message::StreamScans(on) => {
                w.raw(b"sEN LMDscandata");
                w.hex(u64::from(*on));
            }
            Message::StreamScansAck(on) => {
                w.raw(b"sEA LMDscandata");
                w.hex(u64::from(*on));
            }
            Message::SetAccessMode { level, password } => {
                // As SICK writes it: the level with two digits, the hash with eight.
                w.raw(format!("sMN SetAccessMode {level:02X} {password:08X}").as_bytes());
            }
            Message::AccessModeAck(ok) => {
                w.raw(b"sAN SetAccessMode");
                w.hex(u64::from(*ok));
            }
            Message::ReadDeviceIdent => w.raw(b"sRN DeviceIdent"),
            Message::DeviceIdent { name, version } => {
                w.raw(b"sRA DeviceIdent");
                w.flex("device name", &to_latin1("device name", name)?)?;
                w.flex("device version", &to_latin1("device version", version)?)?;
            }
            Message::StartMeasurement => w.raw(b"sMN LMCstartmeas"),
            Message::StartMeasurementAck(s) => {
                w.raw(b"sAN LMCstartmeas");
                w.hex(u64::from(*s));
            }
            Message::StopMeasurement => w.raw(b"sMN LMCstopmeas"),
            Message::StopMeasurementAck(s) => {
                w.raw(b"sAN LMCstopmeas");
                w.hex(u64::from(*s));
            }
            Message::Run => w.raw(b"sMN Run"),
            Message::RunAck(ok) => {
                w.raw(b"sAN Run");
                w.hex(u64::from(*ok));
            }
            Message::ReadDeviceState => w.raw(b"sRN SCdevicestate"),
            Message::DeviceState(s) => {
                w.raw(b"sRA SCdevicestate");
                w.hex(u64::from(*s));
            }
            Message::Error(e) => {
                w.raw(b"sFA");
                w.hex(u64::from(e.0));
            }
            Message::Other { kind, name, args } => {
                if !is_command_type(kind.as_bytes()) || kind == "sFA" {
                    return Err(EncodeError::new(
                        "command type",
                        format!("{kind:?} is not a command type such as sRN"),
                    ));
                }
                if !is_command_name(name.as_bytes()) {
                    return Err(EncodeError::new(
                        "command name",
                        format!("{name:?} is not a command name (printable ASCII, no spaces)"),
                    ));
                }
                if is_known(kind.as_bytes(), name.as_bytes()) {
                    return Err(EncodeError::new(
                        "command name",
                        format!("{kind} {name} is a known command: use its own variant"),
                    ));
                }
                check_text("arguments", args)?;
                w.raw(kind.as_bytes());
                w.token(name.as_bytes());
                if !args.is_empty() {
                    w.token(args);
                }
            }
        }
        Ok(())
    }

    /// The telegram's content (without STX and ETX).
    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::new();
        self.encode_into(&mut out)?;
        Ok(out)
    }

    /// The whole telegram, STX and ETX included, ready for the socket.
    pub fn to_telegram(&self) -> Result<Vec<u8>, EncodeError> {
        let payload = self.encode()?;
        let mut out = Vec::with_capacity(payload.len() + 2);
        frame_telegram(&payload, &mut out);
        Ok(out)
    }

    /// The command type and name (`sRN LMDscandata`, `sFA`), for logs and errors.
    pub fn command(&self) -> String {
        match self {
            Message::PollScan => "sRN LMDscandata".into(),
            Message::Scan { kind, .. } => format!("{} LMDscandata", kind.command_type()),
            Message::StreamScans(_) => "sEN LMDscandata".into(),
            Message::StreamScansAck(_) => "sEA LMDscandata".into(),
            Message::SetAccessMode { .. } => "sMN SetAccessMode".into(),
            Message::AccessModeAck(_) => "sAN SetAccessMode".into(),
            Message::ReadDeviceIdent => "sRN DeviceIdent".into(),
            Message::DeviceIdent { .. } => "sRA DeviceIdent".into(),
            Message::StartMeasurement => "sMN LMCstartmeas".into(),
            Message::StartMeasurementAck(_) => "sAN LMCstartmeas".into(),
            Message::StopMeasurement => "sMN LMCstopmeas".into(),
            Message::StopMeasurementAck(_) => "sAN LMCstopmeas".into(),
            Message::Run => "sMN Run".into(),
            Message::RunAck(_) => "sAN Run".into(),
            Message::ReadDeviceState => "sRN SCdevicestate".into(),
            Message::DeviceState(_) => "sRA SCdevicestate".into(),
            Message::Error(_) => "sFA".into(),
            Message::Other { kind, name, .. } => format!("{kind} {name}"),
        }
    }
}

/// Text as Latin-1 bytes (SICK strings are single bytes).
fn to_latin1(field: &str, text: &str) -> Result<Vec<u8>, EncodeError> {
    text.chars()
        .map(|ch| {
            u8::try_from(u32::from(ch))
                .map_err(|_| EncodeError::new(field, format!("{ch:?} is not a Latin-1 character")))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_and_answers_as_sick_writes_them() {
        let cases: Vec<(&[u8], Message)> = vec![
            (b"sRN LMDscandata", Message::PollScan),
            (b"sEN LMDscandata 1", Message::StreamScans(true)),
            (b"sEA LMDscandata 0", Message::StreamScansAck(false)),
            (
                b"sMN SetAccessMode 03 F4724744",
                Message::SetAccessMode {
                    level: 3,
                    password: 0xF472_4744,
                },
            ),
            (b"sAN SetAccessMode 1", Message::AccessModeAck(true)),
            (b"sRN DeviceIdent", Message::ReadDeviceIdent),
            (
                b"sRA DeviceIdent 10 LMS10x_FieldEval 10 V1.36-21.10.2010",
                Message::DeviceIdent {
                    name: "LMS10x_FieldEval".into(),
                    version: "V1.36-21.10.2010".into(),
                },
            ),
            (b"sMN LMCstartmeas", Message::StartMeasurement),
            (b"sAN LMCstartmeas 0", Message::StartMeasurementAck(0)),
            (b"sMN LMCstopmeas", Message::StopMeasurement),
            (b"sAN LMCstopmeas 0", Message::StopMeasurementAck(0)),
            (b"sMN Run", Message::Run),
            (b"sAN Run 1", Message::RunAck(true)),
            (b"sRN SCdevicestate", Message::ReadDeviceState),
            (b"sRA SCdevicestate 1", Message::DeviceState(1)),
            (b"sFA 11", Message::Error(SopasError(0x11))),
            (
                b"sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1",
                Message::Other {
                    kind: "sWN".into(),
                    name: "LMDscandatacfg".into(),
                    args: b"01 00 1 1 0 00 00 0 0 0 0 +1".to_vec(),
                },
            ),
        ];
        for (text, msg) in cases {
            assert_eq!(
                Message::parse(text).unwrap(),
                msg,
                "{}",
                String::from_utf8_lossy(text)
            );
            assert_eq!(msg.encode().unwrap(), text, "{msg:?}");
        }
    }

    #[test]
    fn error_codes_have_sick_names() {
        assert_eq!(SopasError(1).name(), "Sopas_Error_METHODIN_ACCESSDENIED");
        assert_eq!(
            SopasError(0x11).name(),
            "Sopas_Error_COLA_A_INVALID_CHARACTER"
        );
        assert_eq!(
            SopasError(0x1A).name(),
            "Sopas_Error_ComplexArraysNotSupported"
        );
        assert_eq!(SopasError(0x1B).name(), "unknown SOPAS error");
        assert_eq!(
            SopasError(2).to_string(),
            "sFA 2 (Sopas_Error_METHODIN_UNKNOWNINDEX)"
        );
    }

    #[test]
    fn malformed_requests_name_the_field() {
        let e = Message::parse(b"sEN LMDscandata 2").unwrap_err();
        assert_eq!((e.field.as_str(), e.offset), ("start/stop", 16));
        let e = Message::parse(b"sMN SetAccessMode 03").unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.kind),
            ("password hash", ParseErrorKind::Missing)
        );
        let e = Message::parse(b"hello world").unwrap_err();
        assert_eq!(e.field, "command type");
        let e = Message::parse(b"sRN LMDscandata 1").unwrap_err();
        assert!(matches!(e.kind, ParseErrorKind::Trailing { .. }));
        assert!(Message::parse(b"").is_err());
    }

    #[test]
    fn known_commands_cannot_hide_in_other() {
        let m = Message::Other {
            kind: "sRN".into(),
            name: "LMDscandata".into(),
            args: Vec::new(),
        };
        assert!(m.encode().is_err());
        let m = Message::Other {
            kind: "sRN".into(),
            name: "LMPscancfg".into(),
            args: Vec::new(),
        };
        assert_eq!(m.encode().unwrap(), b"sRN LMPscancfg");
    }
}
