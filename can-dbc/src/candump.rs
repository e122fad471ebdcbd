//! can-utils text formats: the `candump -l` log line `(ts) iface ID#DATA`, the
//! `cansend` frame `ID#DATA`, and the plain `candump iface` line
//! `iface  ID   [len]  XX XX ...` (with or without a `-t` timestamp in front).

use std::fmt;

/// How much of a token an error message shows ([`excerpt`]).
pub const TOKEN_EXCERPT_CHARS: usize = 40;

/// `text` for a message: whole when it has at most `max_chars` characters, else its
/// first `max_chars` and a marker of how much was cut (`... (1234 more characters)`),
/// so an error never echoes a line or token of unbounded length.
pub fn excerpt(text: &str, max_chars: usize) -> String {
    match text.char_indices().nth(max_chars) {
        None => text.to_owned(),
        Some((cut, _)) => {
            let more = text[cut..].chars().count();
            format!("{}... ({more} more characters)", &text[..cut])
        }
    }
}

fn token(text: &str) -> String {
    excerpt(text, TOKEN_EXCERPT_CHARS)
}

/// One frame read from a text line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TextFrame {
    /// The timestamp as written (`1700000000.123456`, or a date for `-t a`).
    pub timestamp: Option<String>,
    pub interface: Option<String>,
    pub id: u32,
    pub extended: bool,
    pub remote: bool,
    pub data: Vec<u8>,
}

/// Why a line is not a frame.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CandumpError {
    #[error("empty line")]
    Empty,
    #[error("unterminated timestamp '(' ")]
    Timestamp,
    #[error(
        "timestamp {0:?} is neither seconds (1700000000.123456) nor a date and time (2024-01-31 12:00:00.123456)"
    )]
    BadTimestamp(String),
    #[error(
        "{0:?} after the frame: one frame per line (only candump -x's direction, R or T, may follow it)"
    )]
    Trailing(String),
    #[error("no frame after the interface name")]
    MissingFrame,
    #[error("CAN ID {0:?} is not hexadecimal")]
    BadId(String),
    #[error("CAN ID {0:?} is out of range (11-bit IDs take 3 hex digits, 29-bit IDs 8)")]
    IdRange(String),
    #[error("data {0:?} is not an even number of hex digits")]
    BadData(String),
    #[error("CAN FD frame ({0:?}); the golf car bus is classic CAN")]
    CanFd(String),
    #[error("data has {found} bytes but the length field says {declared}")]
    LengthMismatch { declared: usize, found: usize },
    #[error("more than 8 data bytes ({0})")]
    TooLong(usize),
    #[error("length field {0:?} is not [0]..[8]")]
    BadLength(String),
}

fn parse_id(text: &str) -> Result<(u32, bool), CandumpError> {
    if text.is_empty() || !text.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(CandumpError::BadId(token(text)));
    }
    let id = u32::from_str_radix(text, 16).map_err(|_| CandumpError::IdRange(token(text)))?;
    // can-utils writes 11-bit IDs with 3 digits and 29-bit IDs with 8.
    let extended = text.len() > 3;
    if (extended && id > 0x1FFF_FFFF) || (!extended && id > 0x7FF) {
        return Err(CandumpError::IdRange(token(text)));
    }
    Ok((id, extended))
}

fn parse_hex_bytes(text: &str) -> Result<Vec<u8>, CandumpError> {
    let clean: String = text.chars().filter(|c| *c != '.').collect();
    if !clean.len().is_multiple_of(2) || !clean.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(CandumpError::BadData(token(text)));
    }
    let bytes: Vec<u8> = (0..clean.len())
        .step_by(2)
        .filter_map(|i| u8::from_str_radix(&clean[i..i + 2], 16).ok())
        .collect();
    if bytes.len() > 8 {
        return Err(CandumpError::TooLong(bytes.len()));
    }
    Ok(bytes)
}

/// Parse `ID#DATA` (cansend and `candump -l` form).
pub fn parse_compact(frame: &str) -> Result<(u32, bool, bool, Vec<u8>), CandumpError> {
    let Some((id, data)) = frame.split_once('#') else {
        return Err(CandumpError::MissingFrame);
    };
    if data.starts_with('#') {
        return Err(CandumpError::CanFd(token(frame)));
    }
    let (id, extended) = parse_id(id)?;
    if data.starts_with(['R', 'r']) {
        // `R` or `R<dlc>`: a remote request.
        return Ok((id, extended, true, Vec::new()));
    }
    Ok((id, extended, false, parse_hex_bytes(data)?))
}

/// Whether `ts` is a timestamp candump writes: seconds (`-l`, `-t a`, `-t d`, `-t z`:
/// `1700000000.123456`) or a date and time (`-t A`: `2024-01-31 12:00:00.123456`).
fn valid_timestamp(ts: &str) -> bool {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let seconds = |s: &str| {
        let (whole, fraction) = s.split_once('.').unwrap_or((s, "0"));
        digits(whole) && digits(fraction)
    };
    let fields = |s: &str, sep: char| s.split(sep).filter(|f| digits(f)).count();
    match ts.split_once(' ') {
        None => seconds(ts),
        Some((date, time)) => {
            let (clock, fraction) = time.split_once('.').unwrap_or((time, "0"));
            date.split('-').count() == 3
                && fields(date, '-') == 3
                && clock.split(':').count() == 3
                && fields(clock, ':') == 3
                && digits(fraction)
        }
    }
}

/// What may follow a `candump -l` frame: nothing, or candump -x's direction.
fn check_trailing(rest: &[&str]) -> Result<(), CandumpError> {
    match rest {
        [] | ["R" | "T"] => Ok(()),
        [first, ..] => Err(CandumpError::Trailing(token(first))),
    }
}

/// Parse one line in any of the supported forms.
pub fn parse_line(line: &str) -> Result<TextFrame, CandumpError> {
    let mut rest = line.trim();
    if rest.is_empty() {
        return Err(CandumpError::Empty);
    }
    let mut timestamp = None;
    if let Some(after) = rest.strip_prefix('(') {
        let (ts, tail) = after.split_once(')').ok_or(CandumpError::Timestamp)?;
        let ts = ts.trim();
        if !valid_timestamp(ts) {
            return Err(CandumpError::BadTimestamp(token(ts)));
        }
        timestamp = Some(ts.to_owned());
        rest = tail.trim_start();
    }
    let fields: Vec<&str> = rest.split_whitespace().collect();
    match fields.as_slice() {
        [] => Err(CandumpError::MissingFrame),
        // A frame where the interface name goes: a second one follows it.
        [first, second, ..] if first.contains('#') => Err(CandumpError::Trailing(token(second))),
        // `ID#DATA` alone (cansend form).
        [frame] if frame.contains('#') => {
            let (id, extended, remote, data) = parse_compact(frame)?;
            Ok(TextFrame {
                timestamp,
                interface: None,
                id,
                extended,
                remote,
                data,
            })
        }
        // `iface ID#DATA [R|T]` (candump -l, with -x the direction).
        [iface, frame, flags @ ..] if frame.contains('#') => {
            check_trailing(flags)?;
            let (id, extended, remote, data) = parse_compact(frame)?;
            Ok(TextFrame {
                timestamp,
                interface: Some((*iface).to_owned()),
                id,
                extended,
                remote,
                data,
            })
        }
        // `iface ID [len] bytes...` (plain candump).
        [iface, id, len, bytes @ ..] => {
            let (id, extended) = parse_id(id)?;
            let declared = len
                .strip_prefix('[')
                .and_then(|l| l.strip_suffix(']'))
                .and_then(|l| l.parse::<usize>().ok())
                .filter(|l| *l <= 8)
                .ok_or_else(|| CandumpError::BadLength(token(len)))?;
            let remote = bytes.first().is_some_and(|b| *b == "remote");
            // `remote request`, and nothing after it.
            let after = match bytes {
                [_, "request", after @ ..] | [_, after @ ..] => after,
                [] => &[],
            };
            if remote && !after.is_empty() {
                return Err(CandumpError::Trailing(token(&after.join(" "))));
            }
            let data = if remote {
                Vec::new()
            } else {
                parse_hex_bytes(&bytes.concat())?
            };
            if !remote && data.len() != declared {
                return Err(CandumpError::LengthMismatch {
                    declared,
                    found: data.len(),
                });
            }
            Ok(TextFrame {
                timestamp,
                interface: Some((*iface).to_owned()),
                id,
                extended,
                remote,
                data,
            })
        }
        _ => Err(CandumpError::MissingFrame),
    }
}

/// `ID#DATA` as cansend takes it.
#[derive(Debug, Clone, Copy)]
pub struct Compact<'a> {
    pub id: u32,
    pub extended: bool,
    pub data: &'a [u8],
}

impl fmt::Display for Compact<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut text = Vec::with_capacity(9 + 2 * self.data.len());
        self.push_to(&mut text);
        f.write_str(std::str::from_utf8(&text).map_err(|_| fmt::Error)?)
    }
}

const HEX_DIGITS: &[u8; 16] = b"0123456789ABCDEF";

/// Append `n` in hex, upper case, at least `width` digits (zero-padded).
fn push_hex(out: &mut Vec<u8>, n: u32, width: u32) {
    let digits = width.max((32 - n.leading_zeros()).div_ceil(4));
    for i in (0..digits).rev() {
        out.push(HEX_DIGITS[(n >> (4 * i) & 0xF) as usize]);
    }
}

/// Append `bytes` as hex, two upper-case digits each.
pub fn push_hex_bytes(out: &mut Vec<u8>, bytes: &[u8]) {
    for b in bytes {
        out.extend_from_slice(&[
            HEX_DIGITS[usize::from(b >> 4)],
            HEX_DIGITS[usize::from(b & 0xF)],
        ]);
    }
}

/// Append `n` in decimal, at least `width` digits (zero-padded).
pub fn push_decimal(out: &mut Vec<u8>, n: u64, width: usize) {
    let mut digits = [0u8; 20];
    let (mut n, mut len) = (n, 0);
    while n > 0 || len < width.max(1) {
        digits[len] = b'0' + (n % 10) as u8;
        n /= 10;
        len += 1;
    }
    out.extend(digits[..len].iter().rev());
}

impl Compact<'_> {
    /// Append what [`Display`](fmt::Display) writes, without the formatting machinery
    /// (a recorder writes one for every frame on the bus).
    pub fn push_to(&self, out: &mut Vec<u8>) {
        push_hex(out, self.id, if self.extended { 8 } else { 3 });
        out.push(b'#');
        push_hex_bytes(out, self.data);
    }

    /// Append the `candump -l` line of this frame received at `unix_ns` (ns since
    /// 1970) on `iface`: `(seconds.micros) IFACE ID#DATA` and its newline.
    pub fn push_log_line(&self, out: &mut Vec<u8>, unix_ns: u64, iface: &str) {
        out.push(b'(');
        push_decimal(out, unix_ns / 1_000_000_000, 1);
        out.push(b'.');
        push_decimal(out, (unix_ns % 1_000_000_000) / 1000, 6);
        out.extend_from_slice(b") ");
        out.extend_from_slice(iface.as_bytes());
        out.push(b' ');
        self.push_to(out);
        out.push(b'\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_cut_long_tokens_with_a_marker() {
        assert_eq!(excerpt("short", 40), "short");
        assert_eq!(excerpt("abcdef", 3), "abc... (3 more characters)");
        assert_eq!(excerpt("é€日本", 2), "é€... (2 more characters)");
        let huge = "Z".repeat(1 << 20);
        let e = parse_line(&format!("vcan0 {huge}#00"))
            .unwrap_err()
            .to_string();
        assert!(e.len() < 200, "{e}");
        assert!(e.contains("1048536 more characters"), "{e}");
    }

    #[test]
    fn log_form() {
        let f = parse_line("(1700000000.123456) vcan0 100#0102030405060708").unwrap();
        assert_eq!(f.timestamp.as_deref(), Some("1700000000.123456"));
        assert_eq!(f.interface.as_deref(), Some("vcan0"));
        assert_eq!((f.id, f.extended, f.remote), (0x100, false, false));
        assert_eq!(f.data, vec![1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn plain_form_with_and_without_timestamp() {
        let a = parse_line("  vcan0  101   [8]  01 02 03 04 05 06 07 08").unwrap();
        let b = parse_line(" (1700000000.5)  vcan0  101   [8]  01 02 03 04 05 06 07 08").unwrap();
        assert_eq!(a.id, 0x101);
        assert_eq!(a.data, b.data);
        assert_eq!(b.timestamp.as_deref(), Some("1700000000.5"));
    }

    #[test]
    fn extended_and_remote() {
        let f = parse_line("vcan0 12345678#R").unwrap();
        assert!(f.extended && f.remote);
        let g = parse_line("  vcan0  080   [8]  remote request").unwrap();
        assert!(g.remote && !g.extended);
    }

    #[test]
    fn cansend_form() {
        let f = parse_line("110#00112233445566").unwrap();
        assert_eq!(f.interface, None);
        assert_eq!(f.data.len(), 7);
    }

    #[test]
    fn malformed_lines_name_the_problem() {
        assert_eq!(parse_line("   "), Err(CandumpError::Empty));
        assert_eq!(
            parse_line("vcan0 1G0#00"),
            Err(CandumpError::BadId("1G0".into()))
        );
        assert_eq!(
            parse_line("vcan0 100#0"),
            Err(CandumpError::BadData("0".into()))
        );
        assert_eq!(
            parse_line("vcan0 800#00"),
            Err(CandumpError::IdRange("800".into()))
        );
        assert!(matches!(
            parse_line("vcan0 100##100"),
            Err(CandumpError::CanFd(_))
        ));
        assert_eq!(
            parse_line("vcan0 100 [8] 01 02"),
            Err(CandumpError::LengthMismatch {
                declared: 8,
                found: 2
            })
        );
        assert_eq!(parse_line("(123 vcan0"), Err(CandumpError::Timestamp));
        assert_eq!(
            parse_line("vcan0 100#001122334455667788"),
            Err(CandumpError::TooLong(9))
        );
    }

    #[test]
    fn timestamps_are_seconds_or_a_date_and_time() {
        for ts in [
            "1700000000.123456",
            "000.000123",
            "17",
            "2024-01-31 12:00:00.123456",
        ] {
            let f = parse_line(&format!("({ts}) vcan0 100#00")).unwrap();
            assert_eq!(f.timestamp.as_deref(), Some(ts));
        }
        for ts in [
            "nan",
            "",
            "inf",
            "-1.5",
            "1e9",
            "1.2.3",
            "0x10",
            "1.",
            ".5",
            "2024-01-31",
            "2024-01-31 12:00",
        ] {
            assert_eq!(
                parse_line(&format!("({ts}) vcan0 100#00")),
                Err(CandumpError::BadTimestamp(ts.into())),
                "{ts}"
            );
        }
        assert_eq!(
            parse_line("(nan) vcan0 100#00").unwrap_err().to_string(),
            "timestamp \"nan\" is neither seconds (1700000000.123456) nor a date and time (2024-01-31 12:00:00.123456)"
        );
    }

    #[test]
    fn one_frame_per_line() {
        for (line, extra) in [
            ("(1.0) vcan0 100#00 (2.0) vcan0 101#01", "(2.0)"),
            ("vcan0 100#00 vcan0 101#01", "vcan0"),
            ("vcan0 100#00 101#01", "101#01"),
            ("100#00 101#01", "101#01"),
            ("vcan0 100#00 R T", "R"),
            ("vcan0 080 [8] remote request vcan0 100#00", "vcan0 100#00"),
        ] {
            assert_eq!(
                parse_line(line),
                Err(CandumpError::Trailing(extra.into())),
                "{line}"
            );
        }
        assert_eq!(
            parse_line("vcan0 100#00 101#01").unwrap_err().to_string(),
            "\"101#01\" after the frame: one frame per line (only candump -x's direction, R or T, may follow it)"
        );
        // candump -l -x's direction is no frame.
        for line in ["vcan0 100#00 R", "(1.5) vcan0 100#00 T"] {
            assert_eq!(parse_line(line).unwrap().data, [0], "{line}");
        }
    }

    #[test]
    fn compact_round_trip() {
        let data = [0xDE, 0xAD, 0xBE, 0xEF];
        let text = Compact {
            id: 0x1F,
            extended: false,
            data: &data,
        }
        .to_string();
        assert_eq!(text, "01F#DEADBEEF");
        assert_eq!(
            parse_compact(&text).unwrap(),
            (0x1F, false, false, data.to_vec())
        );
    }

    #[test]
    fn log_lines_are_what_the_format_machinery_writes() {
        let data = [0x00, 0x0A, 0xF0, 0xFF, 0x7C];
        for (id, extended) in [
            (0, false),
            (0x1F, false),
            (0x7FF, false),
            (0x1ABC, false),
            (0, true),
            (0x1FFF_FFFF, true),
        ] {
            for ns in [0, 999, 1_700_000_000_123_456_789, u64::MAX] {
                for len in [0, 1, data.len()] {
                    let c = Compact {
                        id,
                        extended,
                        data: &data[..len],
                    };
                    let mut line = Vec::new();
                    c.push_log_line(&mut line, ns, "vcan0");
                    let hex: String = c.data.iter().map(|b| format!("{b:02X}")).collect();
                    let id_text = match extended {
                        true => format!("{id:08X}"),
                        false => format!("{id:03X}"),
                    };
                    let expected = format!(
                        "({}.{:06}) vcan0 {id_text}#{hex}\n",
                        ns / 1_000_000_000,
                        (ns % 1_000_000_000) / 1000
                    );
                    assert_eq!(String::from_utf8(line).unwrap(), expected);
                    assert_eq!(c.to_string(), format!("{id_text}#{hex}"));
                }
            }
        }
    }
}
