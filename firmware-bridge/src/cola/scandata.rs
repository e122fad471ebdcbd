//! The `LMDscandata` telegram: a polled scan (`sRA LMDscandata ...`, the answer to
//! `sRN LMDscandata`) or a streamed one (`sSN LMDscandata ...`, after
//! `sEN LMDscandata 1`).
//!
//! The fields, in order, as SICK's telegram listing (LMS1xx, LMS5xx, TiM) gives them:
//!
//! | field | type | example (LMS111) |
//! |---|---|---|
//! | version | u16 | `1` |
//! | device number | u16 | `1` |
//! | serial number | u32 | `89A27F` |
//! | device status | 2 x u8 | `0 0` |
//! | telegram counter | u16 | `343` |
//! | scan counter | u16 | `347` |
//! | time since start-up, µs | u32 | `27477BA9` |
//! | time of transmission, µs | u32 | `2747813B` |
//! | status of digital inputs | 2 x u8 | `0 0` |
//! | status of digital outputs | 2 x u8 | `7 0` |
//! | layer angle (LMS1xx: reserved) | i16 | `0` |
//! | scan frequency, 1/100 Hz | u32 | `1388` (50 Hz) |
//! | measurement frequency, 100 Hz | u32 | `168` (36 kHz) |
//! | encoders: count, then position (u32) and speed (i16) each | | `0` |
//! | 16-bit channels: count, then per channel | | `1` |
//! | - content (`DIST1`..`DIST5`, `RSSI1`.., `ANGL1`, `REFL1`) | name | `DIST1` |
//! | - scale factor | IEEE-754 hex | `3F800000` (1.0) |
//! | - scale factor offset | IEEE-754 hex | `00000000` |
//! | - start angle, 1/10000° | i32 | `FFF92230` (-45°) |
//! | - angular step, 1/10000° | u16 (read as u32) | `1388` (0.5°) |
//! | - number of values, then the values | u16, u16 each | `21D` (541) ... |
//! | 8-bit channels: count, then as above with u8 values | | `0` |
//! | position: flag, then x, y, z, x/y/z rotation (IEEE-754), rotation type (u8) | | `0` |
//! | name: flag, then a string | | `0` (TiM: `1 B not defined`) |
//! | comment: flag, then a string | | `0` |
//! | time stamp: flag, then year (u16), month, day, hour, minute, second (u8), µs (u32) | | `0` |
//! | event info: flag, then type (`FDIN`, `STIN`, `ENC1`..), encoder position (u32), time (u32, µs), angle (i32) | | `0` |
//!
//! Parsing is liberal where devices differ (lower-case hex, leading zeros, `+`/`-`
//! decimal numbers, several spaces between fields, any number of channels with any
//! names) and strict where data would be wrong: every field must be there and fit its
//! type, a channel's value count must match its values, flags are 0 or 1, nothing may
//! follow the last field. Encoding writes what SICK devices write (upper-case hex
//! without leading zeros, floats as 8 digits, one space), so `ScanData` survives
//! encode-then-parse exactly and a device's telegram survives parse-then-encode byte
//! for byte when it was written that way.

use super::fields::{
    Cursor, EncodeError, ParseError, ParseErrorKind, Writer, check_name, check_text, is_name,
    parse_int, token_text,
};

/// The command name of a scan telegram.
pub const LMD_SCANDATA: &str = "LMDscandata";

/// How a scan telegram was sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ScanKind {
    /// `sRA LMDscandata`: the answer to a poll (`sRN LMDscandata`).
    Polled,
    /// `sSN LMDscandata`: an event, streamed after `sEN LMDscandata 1`.
    Streamed,
}

impl ScanKind {
    /// The command type on the wire: `sRA` or `sSN`.
    pub fn command_type(self) -> &'static str {
        match self {
            ScanKind::Polled => "sRA",
            ScanKind::Streamed => "sSN",
        }
    }
}

/// One encoder block.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Encoder {
    /// Encoder position, ticks.
    pub position: u32,
    /// Encoder speed, ticks/mm.
    pub speed: i16,
}

/// One output channel: distances (`DIST1`..), remission (`RSSI1`..), angle offsets
/// (`ANGL1`) or reflectivity (`REFL1`), 16-bit (`u16`) or 8-bit (`u8`) values.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel<T> {
    /// What the channel holds, e.g. `DIST1` (first echo's distances) or `RSSI1`.
    pub content: String,
    /// Value = raw * scale_factor + scale_offset (mm for `DIST`).
    pub scale_factor: f32,
    /// See `scale_factor`.
    pub scale_offset: f32,
    /// Angle of the first value, 1/10000 degree, scanner frame (90° = straight ahead).
    pub start_angle: i32,
    /// Angle between values, 1/10000 degree.
    pub angular_step: u32,
    /// The raw values.
    pub data: Vec<T>,
}

/// The optional position block.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Position {
    pub x: f32,
    pub y: f32,
    pub z: f32,
    pub x_rotation: f32,
    pub y_rotation: f32,
    pub z_rotation: f32,
    /// 0 none, 1 pitch, 2 roll, 3 free.
    pub rotation_type: u8,
}

/// The optional time-stamp block: the device's clock when the scan started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeviceTime {
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub minute: u8,
    pub second: u8,
    pub microsecond: u32,
}

/// The optional event block.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Event {
    /// `FDIN` (fast digital input), `STIN` (static input), `ENC1`.., as the device says.
    pub kind: String,
    /// Encoder position at the event, ticks.
    pub encoder_position: u32,
    /// Time of the event, µs since start-up.
    pub time_us: u32,
    /// Angle of the event, 1/10000 degree.
    pub angle: i32,
}

/// An `LMDscandata` telegram's fields; see the [module documentation](self).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanData {
    /// Telegram format version (1).
    pub version: u16,
    /// Device number, set with SOPAS.
    pub device_number: u16,
    /// Serial number, set in the factory.
    pub serial_number: u32,
    /// `0 0` ok, `0 1` error, `0 2` pollution warning, `0 4` pollution error.
    pub device_status: [u8; 2],
    /// Telegrams finished and handed to the interface.
    pub telegram_counter: u16,
    /// Scans done by the device.
    pub scan_counter: u16,
    /// Time since start-up at the start of the scan, µs.
    pub time_since_startup_us: u32,
    /// Time since start-up when the scan was handed to the interface, µs.
    pub time_of_transmission_us: u32,
    /// Digital inputs (low byte first).
    pub inputs: [u8; 2],
    /// Digital outputs (low byte first).
    pub outputs: [u8; 2],
    /// Layer angle (MRS scanners); "reserved byte A", 0, on LMS1xx.
    pub layer_angle: i16,
    /// Scan frequency, 1/100 Hz (`1388` = 50 Hz).
    pub scan_frequency: u32,
    /// Measurement frequency, 100 Hz (`168` = 36 kHz).
    pub measurement_frequency: u32,
    /// Encoder blocks.
    pub encoders: Vec<Encoder>,
    /// 16-bit channels.
    pub channels16: Vec<Channel<u16>>,
    /// 8-bit channels.
    pub channels8: Vec<Channel<u8>>,
    /// Position block, if the device sends one.
    pub position: Option<Position>,
    /// Device name, if sent (raw bytes: SICK allows 0x20..0xFF).
    pub name: Option<Vec<u8>>,
    /// Comment, if sent.
    pub comment: Option<Vec<u8>>,
    /// Time stamp, if sent.
    pub time: Option<DeviceTime>,
    /// Event info, if sent.
    pub event: Option<Event>,
}

/// Block counts beyond these are taken as corrupt data.
const MAX_ENCODERS: u16 = 16;
const MAX_CHANNELS: u16 = 32;

impl ScanData {
    /// Parse a whole telegram's content: `sRA LMDscandata ...` or `sSN LMDscandata ...`.
    pub fn parse(payload: &[u8]) -> Result<(ScanKind, ScanData), ParseError> {
        let mut c = Cursor::new(payload);
        let (kind, at) = c.token("command type")?;
        let kind = match kind {
            b"sRA" => ScanKind::Polled,
            b"sSN" => ScanKind::Streamed,
            other => {
                return Err(c.error(
                    "command type",
                    at,
                    ParseErrorKind::BadName {
                        token: token_text(other),
                        what: "scan command type (sRA or sSN)",
                    },
                ));
            }
        };
        let (name, at) = c.token("command name")?;
        if name != LMD_SCANDATA.as_bytes() {
            return Err(c.error(
                "command name",
                at,
                ParseErrorKind::BadName {
                    token: token_text(name),
                    what: "scan command name (LMDscandata)",
                },
            ));
        }
        let scan = Self::parse_fields(&mut c)?;
        Ok((kind, scan))
    }

    /// The fields after `LMDscandata`, up to the end of the telegram.
    pub(crate) fn parse_fields(c: &mut Cursor<'_>) -> Result<ScanData, ParseError> {
        let version = c.u16("version")?;
        let device_number = c.u16("device number")?;
        let serial_number = c.u32("serial number")?;
        let device_status = [c.u8("device status")?, c.u8("device status (2nd byte)")?];
        let telegram_counter = c.u16("telegram counter")?;
        let scan_counter = c.u16("scan counter")?;
        let time_since_startup_us = c.u32("time since start-up")?;
        let time_of_transmission_us = c.u32("time of transmission")?;
        let inputs = [c.u8("digital inputs")?, c.u8("digital inputs (2nd byte)")?];
        let outputs = [
            c.u8("digital outputs")?,
            c.u8("digital outputs (2nd byte)")?,
        ];
        let layer_angle = c.i16("layer angle")?;
        let scan_frequency = c.u32("scan frequency")?;
        let measurement_frequency = c.u32("measurement frequency")?;

        let n = c.count("number of encoders", MAX_ENCODERS)?;
        let mut encoders = Vec::with_capacity(n);
        for i in 1..=n {
            encoders.push(Encoder {
                position: c.u32(format_args!("encoder {i} position"))?,
                speed: c.i16(format_args!("encoder {i} speed"))?,
            });
        }

        let n = c.count("number of 16-bit channels", MAX_CHANNELS)?;
        let mut channels16 = Vec::with_capacity(n);
        let mut last_block = None;
        for i in 1..=n {
            let (channel, mark) = parse_channel(c, 16, i, |v| v as u16)?;
            channels16.push(channel);
            last_block = Some(mark);
        }
        // What follows the last 16-bit channel; a failure there may be that channel's
        // count being wrong, which `recount` finds out.
        let (channels8, tail) = match parse_after_channels16(c) {
            Ok(rest) => rest,
            Err(e) => {
                return Err(match last_block {
                    Some(mark) => recount(c, &mark, e, |c| parse_after_channels16(c).map(|_| ())),
                    None => e,
                });
            }
        };
        let Tail {
            position,
            name,
            comment,
            time,
            event,
        } = tail;
        Ok(ScanData {
            version,
            device_number,
            serial_number,
            device_status,
            telegram_counter,
            scan_counter,
            time_since_startup_us,
            time_of_transmission_us,
            inputs,
            outputs,
            layer_angle,
            scan_frequency,
            measurement_frequency,
            encoders,
            channels16,
            channels8,
            position,
            name,
            comment,
            time,
            event,
        })
    }

    /// The whole telegram's content (`sRA LMDscandata ...` or `sSN LMDscandata ...`),
    /// without STX and ETX.
    pub fn encode(&self, kind: ScanKind) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::with_capacity(self.encoded_len_hint());
        self.encode_into(kind, &mut out)?;
        Ok(out)
    }

    /// Append the telegram's content to `out`; on error `out` may hold part of it.
    pub fn encode_into(&self, kind: ScanKind, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        let mut w = Writer { out };
        w.raw(kind.command_type().as_bytes());
        w.token(LMD_SCANDATA.as_bytes());
        self.encode_fields(&mut w)
    }

    /// A capacity guess for the encoded telegram.
    pub fn encoded_len_hint(&self) -> usize {
        let values: usize = self
            .channels16
            .iter()
            .map(|c| c.data.len() * 5)
            .sum::<usize>()
            + self
                .channels8
                .iter()
                .map(|c| c.data.len() * 3)
                .sum::<usize>();
        160 + values
    }

    fn encode_fields(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        w.hex(self.version.into());
        w.hex(self.device_number.into());
        w.hex(self.serial_number.into());
        w.hex(self.device_status[0].into());
        w.hex(self.device_status[1].into());
        w.hex(self.telegram_counter.into());
        w.hex(self.scan_counter.into());
        w.hex(self.time_since_startup_us.into());
        w.hex(self.time_of_transmission_us.into());
        w.hex(self.inputs[0].into());
        w.hex(self.inputs[1].into());
        w.hex(self.outputs[0].into());
        w.hex(self.outputs[1].into());
        w.hex_signed(self.layer_angle.into(), 16);
        w.hex(self.scan_frequency.into());
        w.hex(self.measurement_frequency.into());

        check_count("encoders", self.encoders.len(), MAX_ENCODERS)?;
        w.hex(self.encoders.len() as u64);
        for e in &self.encoders {
            w.hex(e.position.into());
            w.hex_signed(e.speed.into(), 16);
        }
        check_count("16-bit channels", self.channels16.len(), MAX_CHANNELS)?;
        w.hex(self.channels16.len() as u64);
        for ch in &self.channels16 {
            encode_channel(w, ch, |v| u64::from(*v))?;
        }
        check_count("8-bit channels", self.channels8.len(), MAX_CHANNELS)?;
        w.hex(self.channels8.len() as u64);
        for ch in &self.channels8 {
            encode_channel(w, ch, |v| u64::from(*v))?;
        }

        match &self.position {
            None => w.hex(0),
            Some(p) => {
                w.hex(1);
                for v in [p.x, p.y, p.z, p.x_rotation, p.y_rotation, p.z_rotation] {
                    w.f32(v);
                }
                w.hex(p.rotation_type.into());
            }
        }
        for (field, text) in [("device name", &self.name), ("comment", &self.comment)] {
            match text {
                None => w.hex(0),
                Some(bytes) => {
                    w.hex(1);
                    w.flex(field, bytes)?;
                }
            }
        }
        match &self.time {
            None => w.hex(0),
            Some(t) => {
                w.hex(1);
                w.hex(t.year.into());
                for v in [t.month, t.day, t.hour, t.minute, t.second] {
                    w.hex(v.into());
                }
                w.hex(t.microsecond.into());
            }
        }
        match &self.event {
            None => w.hex(0),
            Some(e) => {
                w.hex(1);
                check_name("event type", &e.kind)?;
                w.token(e.kind.as_bytes());
                w.hex(e.encoder_position.into());
                w.hex(e.time_us.into());
                w.hex_signed(e.angle.into(), 32);
            }
        }
        Ok(())
    }

    /// The first 16-bit channel whose content starts with `prefix` (e.g. `DIST1`).
    pub fn channel16(&self, content: &str) -> Option<&Channel<u16>> {
        self.channels16.iter().find(|c| c.content == content)
    }

    /// The first 8-bit channel named `content`.
    pub fn channel8(&self, content: &str) -> Option<&Channel<u8>> {
        self.channels8.iter().find(|c| c.content == content)
    }

    /// The device name as text (bytes above 0x7F as Latin-1).
    pub fn name_text(&self) -> Option<String> {
        self.name.as_deref().map(latin1)
    }
}

/// The blocks after the channels.
struct Tail {
    position: Option<Position>,
    name: Option<Vec<u8>>,
    comment: Option<Vec<u8>>,
    time: Option<DeviceTime>,
    event: Option<Event>,
}

/// Where a channel's values are, to re-check its count when what follows fails.
struct BlockMark {
    content: String,
    declared: usize,
    count_at: usize,
    data_start: usize,
}

/// How far off a channel's count `recount` looks.
const RECOUNT_RANGE: usize = 64;

/// When the fields after a channel block fail to parse, try whether they parse with
/// the block holding a few values more or fewer than declared: if so, the count was
/// wrong and that is the error to report ([`ParseErrorKind::CountMismatch`]).
/// Otherwise the original error stands. Only runs on the error path.
fn recount<'a>(
    c: &Cursor<'a>,
    mark: &BlockMark,
    original: ParseError,
    rest: impl Fn(&mut Cursor<'a>) -> Result<(), ParseError>,
) -> ParseError {
    let mut probe = c.fork_at(mark.data_start);
    // ends[k]: the position after k value tokens.
    let mut ends = vec![mark.data_start];
    for _ in 0..mark.declared + RECOUNT_RANGE {
        if probe.token("value").is_err() {
            break;
        }
        ends.push(probe.pos());
    }
    let parses_with = |k: usize| {
        ends.get(k).is_some_and(|&at| {
            let mut t = c.fork_at(at);
            rest(&mut t).is_ok()
        })
    };
    for delta in 1..=RECOUNT_RANGE {
        let candidates = [
            mark.declared.checked_sub(delta),
            Some(mark.declared + delta),
        ];
        for found in candidates.into_iter().flatten() {
            if parses_with(found) {
                return c.error(
                    format_args!("{} values", mark.content),
                    mark.count_at,
                    ParseErrorKind::CountMismatch {
                        declared: mark.declared,
                        found,
                    },
                );
            }
        }
    }
    original
}

/// The 8-bit channels and the rest, up to the end of the telegram.
fn parse_after_channels16(c: &mut Cursor<'_>) -> Result<(Vec<Channel<u8>>, Tail), ParseError> {
    let n = c.count("number of 8-bit channels", MAX_CHANNELS)?;
    let mut channels8 = Vec::with_capacity(n);
    let mut last_block = None;
    for i in 1..=n {
        let (channel, mark) = parse_channel(c, 8, i, |v| v as u8)?;
        channels8.push(channel);
        last_block = Some(mark);
    }
    match parse_tail(c) {
        Ok(tail) => Ok((channels8, tail)),
        Err(e) => Err(match last_block {
            Some(mark) => recount(c, &mark, e, |c| parse_tail(c).map(|_| ())),
            None => e,
        }),
    }
}

/// Position, name, comment, time stamp and event blocks, then the end.
fn parse_tail(c: &mut Cursor<'_>) -> Result<Tail, ParseError> {
    let position = if c.flag("position flag")? {
        Some(Position {
            x: c.f32("x position")?,
            y: c.f32("y position")?,
            z: c.f32("z position")?,
            x_rotation: c.f32("x rotation")?,
            y_rotation: c.f32("y rotation")?,
            z_rotation: c.f32("z rotation")?,
            rotation_type: c.u8("rotation type")?,
        })
    } else {
        None
    };
    let name = if c.flag("name flag")? {
        Some(c.flex("device name")?)
    } else {
        None
    };
    let comment = if c.flag("comment flag")? {
        Some(c.flex("comment")?)
    } else {
        None
    };
    let time = if c.flag("time stamp flag")? {
        Some(DeviceTime {
            year: c.u16("year")?,
            month: c.u8("month")?,
            day: c.u8("day")?,
            hour: c.u8("hour")?,
            minute: c.u8("minute")?,
            second: c.u8("second")?,
            microsecond: c.u32("microsecond")?,
        })
    } else {
        None
    };
    let event = if c.flag("event flag")? {
        Some(Event {
            kind: c.name("event type", "event type (such as FDIN)")?,
            encoder_position: c.u32("event encoder position")?,
            time_us: c.u32("event time")?,
            angle: c.i32("event angle")?,
        })
    } else {
        None
    };
    c.end("event flag")?;
    Ok(Tail {
        position,
        name,
        comment,
        time,
        event,
    })
}

/// Bytes as Latin-1 text.
pub(crate) fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

fn check_count(what: &str, n: usize, max: u16) -> Result<(), EncodeError> {
    if n > usize::from(max) {
        return Err(EncodeError::new(
            format!("number of {what}"),
            format!("{n}, at most {max}"),
        ));
    }
    Ok(())
}

/// A token that cannot be a value but looks like the next block's channel name:
/// the declared count was larger than the values present.
fn looks_like_next_block(token: &[u8]) -> bool {
    is_name(token)
        && token
            .iter()
            .any(|b| b.is_ascii_alphabetic() && !b.is_ascii_hexdigit())
}

fn parse_channel<T>(
    c: &mut Cursor<'_>,
    bits: u32,
    index: usize,
    cast: impl Fn(i64) -> T,
) -> Result<(Channel<T>, BlockMark), ParseError> {
    let block = format!("{bits}-bit channel {index}");
    let content = c.name(
        format_args!("{block} content"),
        "channel content (such as DIST1)",
    )?;
    let scale_factor = c.f32(format_args!("{content} scale factor"))?;
    let scale_offset = c.f32(format_args!("{content} scale factor offset"))?;
    let start_angle = c.i32(format_args!("{content} start angle"))?;
    let angular_step = c.u32(format_args!("{content} angular step"))?;
    let (count_token, count_at) = c.token(format_args!("{content} number of values"))?;
    let declared = parse_int(count_token, 16, false)
        .map_err(|kind| c.error(format_args!("{content} number of values"), count_at, kind))?
        as usize;
    let mark = BlockMark {
        content: content.clone(),
        declared,
        count_at,
        data_start: c.pos(),
    };
    let mut data = Vec::with_capacity(declared);
    for found in 0..declared {
        match c.peek() {
            None => {
                return Err(c.error(
                    format_args!("{content} values"),
                    count_at,
                    ParseErrorKind::CountMismatch { declared, found },
                ));
            }
            Some((token, _)) if looks_like_next_block(token) => {
                return Err(c.error(
                    format_args!("{content} values"),
                    count_at,
                    ParseErrorKind::CountMismatch { declared, found },
                ));
            }
            Some(_) => {
                let v = c.int(format_args!("{content} value {}", found + 1), bits, false)?;
                data.push(cast(v));
            }
        }
    }
    let channel = Channel {
        content,
        scale_factor,
        scale_offset,
        start_angle,
        angular_step,
        data,
    };
    Ok((channel, mark))
}

fn encode_channel<T>(
    w: &mut Writer<'_>,
    ch: &Channel<T>,
    raw: impl Fn(&T) -> u64,
) -> Result<(), EncodeError> {
    check_name("channel content", &ch.content)?;
    if ch.data.len() > usize::from(u16::MAX) {
        return Err(EncodeError::new(
            format!("{} number of values", ch.content),
            format!("{}, at most {}", ch.data.len(), u16::MAX),
        ));
    }
    w.token(ch.content.as_bytes());
    w.f32(ch.scale_factor);
    w.f32(ch.scale_offset);
    w.hex_signed(ch.start_angle.into(), 32);
    w.hex(ch.angular_step.into());
    w.hex(ch.data.len() as u64);
    for v in &ch.data {
        w.hex(raw(v));
    }
    Ok(())
}

/// Check that a device name or comment can be encoded (no STX/ETX, at most 65535 bytes).
pub fn check_flex_text(field: &str, bytes: &[u8]) -> Result<(), EncodeError> {
    if bytes.len() > usize::from(u16::MAX) {
        return Err(EncodeError::new(field, "longer than 65535 bytes"));
    }
    check_text(field, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lms111_like() -> ScanData {
        ScanData {
            version: 1,
            device_number: 1,
            serial_number: 0x89A27F,
            telegram_counter: 0x343,
            scan_counter: 0x347,
            time_since_startup_us: 0x2747_7BA9,
            time_of_transmission_us: 0x2747_813B,
            outputs: [7, 0],
            scan_frequency: 5000,
            measurement_frequency: 360,
            channels16: vec![Channel {
                content: "DIST1".into(),
                scale_factor: 1.0,
                scale_offset: 0.0,
                start_angle: -450_000,
                angular_step: 5000,
                data: vec![0x8A1, 0, 3, 0xFFFF],
            }],
            ..ScanData::default()
        }
    }

    #[test]
    fn encodes_as_an_lms111_does() {
        let text = lms111_like().encode(ScanKind::Streamed).unwrap();
        assert_eq!(
            String::from_utf8(text).unwrap(),
            "sSN LMDscandata 1 1 89A27F 0 0 343 347 27477BA9 2747813B 0 0 7 0 0 1388 168 0 1 \
             DIST1 3F800000 00000000 FFF92230 1388 4 8A1 0 3 FFFF 0 0 0 0 0 0"
        );
    }

    #[test]
    fn every_optional_block_round_trips() {
        let mut s = lms111_like();
        s.encoders = vec![Encoder {
            position: 0xDEAD_BEEF,
            speed: -3,
        }];
        s.channels8 = vec![Channel {
            content: "RSSI1".into(),
            scale_factor: 1.0,
            scale_offset: 0.0,
            start_angle: -450_000,
            angular_step: 5000,
            data: vec![0, 255, 17, 1],
        }];
        s.position = Some(Position {
            x: 1.5,
            y: -2.0,
            z: 0.25,
            x_rotation: 0.0,
            y_rotation: 0.1,
            z_rotation: -3.0,
            rotation_type: 3,
        });
        s.name = Some(b"not defined".to_vec());
        s.comment = Some(Vec::new());
        s.time = Some(DeviceTime {
            year: 2026,
            month: 5,
            day: 4,
            hour: 13,
            minute: 59,
            second: 7,
            microsecond: 999_999,
        });
        s.event = Some(Event {
            kind: "FDIN".into(),
            encoder_position: 7,
            time_us: 0x1234_5678,
            angle: -900_000,
        });
        for kind in [ScanKind::Polled, ScanKind::Streamed] {
            let text = s.encode(kind).unwrap();
            assert_eq!(ScanData::parse(&text).unwrap(), (kind, s.clone()));
        }
    }

    #[test]
    fn too_few_values_is_a_count_mismatch_naming_the_channel() {
        let text = b"sSN LMDscandata 1 1 1 0 0 1 1 0 0 0 0 0 0 0 1388 168 0 2 \
DIST1 3F800000 00000000 FFF92230 1388 3 10 20 \
RSSI1 3F800000 00000000 FFF92230 1388 3 1 2 3 0 0 0 0 0 0";
        let e = ScanData::parse(text).unwrap_err();
        assert_eq!(e.field, "DIST1 values");
        assert_eq!(
            e.kind,
            ParseErrorKind::CountMismatch {
                declared: 3,
                found: 2
            }
        );
        let at = text.windows(8).position(|w| w == b"1388 3 1").unwrap() + 5;
        assert_eq!(e.offset, at);
    }

    #[test]
    fn a_wrong_count_on_the_last_channel_is_found_by_recounting() {
        let good = lms111_like().encode(ScanKind::Streamed).unwrap();
        let text = String::from_utf8(good).unwrap();
        // Declare 5 values where there are 4, then 3.
        for (declared, found) in [("5", 4), ("3", 4)] {
            let bad = text.replace("1388 4 8A1", &format!("1388 {declared} 8A1"));
            let e = ScanData::parse(bad.as_bytes()).unwrap_err();
            assert_eq!(e.field, "DIST1 values", "{bad}");
            assert_eq!(
                e.kind,
                ParseErrorKind::CountMismatch {
                    declared: declared.parse().unwrap(),
                    found
                }
            );
            assert_eq!(e.offset, bad.find(&format!("{declared} 8A1")).unwrap());
        }
    }

    #[test]
    fn wrong_command_is_refused() {
        let e = ScanData::parse(b"sRA DeviceIdent 1").unwrap_err();
        assert_eq!(e.field, "command name");
        assert_eq!(e.offset, 4);
    }
}
