//! Reading and writing the fields of a CoLa-A telegram: numbers (hex, or signed
//! decimal), IEEE-754 floats in hex, flags, length-prefixed strings; and the typed
//! errors that name the field and its byte offset.

use std::fmt;

/// Why a telegram did not parse: which field, where, and what was wrong.
///
/// `offset` counts bytes from the start of the telegram's content (the byte after
/// STX), so `offset` 0 is the command type.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("field `{field}` at byte {offset}: {kind}")]
pub struct ParseError {
    /// The field, as SICK's telegram listing names it (e.g. `scan frequency`,
    /// `DIST1 data`).
    pub field: String,
    /// Byte offset of the field in the telegram (after STX).
    pub offset: usize,
    /// What was wrong.
    pub kind: ParseErrorKind,
}

/// What was wrong with a field.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ParseErrorKind {
    /// The telegram ended before this field.
    #[error("missing (the telegram ends here)")]
    Missing,
    /// Not a hexadecimal number (and not a signed decimal one either).
    #[error("{token:?} is not a hexadecimal number")]
    NotHex { token: String },
    /// A `+`/`-` number whose digits are not decimal.
    #[error("{token:?} is not a signed decimal number")]
    NotDecimal { token: String },
    /// A number that does not fit the field.
    #[error("{token:?} is outside {min}..={max}")]
    OutOfRange { token: String, min: i64, max: i64 },
    /// A presence flag that is neither 0 nor 1.
    #[error("{token:?} must be 0 or 1")]
    NotFlag { token: String },
    /// A channel declared more values than the telegram holds before the next block.
    #[error("declares {declared} values, the telegram has {found}")]
    CountMismatch { declared: usize, found: usize },
    /// A string longer than what is left of the telegram, or not followed by a space.
    #[error("string of {declared} bytes does not fit: {reason}")]
    BadString {
        declared: usize,
        reason: &'static str,
    },
    /// A name (channel content, event type, command) that is not a plain token.
    #[error("{token:?} is not a valid {what}")]
    BadName { token: String, what: &'static str },
    /// Bytes after the last field.
    #[error("{count} unexpected bytes after the last field: {text:?}")]
    Trailing { count: usize, text: String },
}

/// Why a value could not be written as CoLa-A.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("cannot encode `{field}`: {reason}")]
pub struct EncodeError {
    /// The field.
    pub field: String,
    /// What is wrong with its value.
    pub reason: String,
}

impl EncodeError {
    pub(crate) fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        EncodeError {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// A token as text for an error message (lossy, at most 40 characters).
pub(crate) fn token_text(token: &[u8]) -> String {
    crate::cola::preview(token)
}

/// Reads fields from a telegram's content.
#[derive(Debug)]
pub(crate) struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Cursor { buf, pos: 0 }
    }

    pub(crate) fn error(
        &self,
        field: impl fmt::Display,
        offset: usize,
        kind: ParseErrorKind,
    ) -> ParseError {
        ParseError {
            field: field.to_string(),
            offset,
            kind,
        }
    }

    /// The read position.
    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    /// A cursor on the same telegram at another position.
    pub(crate) fn fork_at(&self, pos: usize) -> Cursor<'a> {
        Cursor {
            buf: self.buf,
            pos: pos.min(self.buf.len()),
        }
    }

    fn skip_spaces(&mut self) {
        while self.buf.get(self.pos) == Some(&b' ') {
            self.pos += 1;
        }
    }

    /// Whether only spaces are left.
    pub(crate) fn at_end(&self) -> bool {
        self.buf[self.pos.min(self.buf.len())..]
            .iter()
            .all(|&b| b == b' ')
    }

    /// The next space-delimited token and its offset, without consuming it.
    pub(crate) fn peek(&self) -> Option<(&'a [u8], usize)> {
        let mut start = self.pos;
        while self.buf.get(start) == Some(&b' ') {
            start += 1;
        }
        if start >= self.buf.len() {
            return None;
        }
        let len = self.buf[start..]
            .iter()
            .position(|&b| b == b' ')
            .unwrap_or(self.buf.len() - start);
        Some((&self.buf[start..start + len], start))
    }

    /// The next token (runs of spaces count as one separator).
    pub(crate) fn token(
        &mut self,
        field: impl fmt::Display,
    ) -> Result<(&'a [u8], usize), ParseError> {
        match self.peek() {
            Some((token, start)) => {
                self.pos = start + token.len();
                Ok((token, start))
            }
            None => {
                self.skip_spaces();
                Err(self.error(field, self.pos, ParseErrorKind::Missing))
            }
        }
    }

    /// An integer field of `bits` width, signed or not, as i64.
    pub(crate) fn int(
        &mut self,
        field: impl fmt::Display,
        bits: u32,
        signed: bool,
    ) -> Result<i64, ParseError> {
        let (token, at) = self.token(&field)?;
        parse_int(token, bits, signed).map_err(|kind| self.error(field, at, kind))
    }

    pub(crate) fn u8(&mut self, field: impl fmt::Display) -> Result<u8, ParseError> {
        Ok(self.int(field, 8, false)? as u8)
    }

    pub(crate) fn u16(&mut self, field: impl fmt::Display) -> Result<u16, ParseError> {
        Ok(self.int(field, 16, false)? as u16)
    }

    pub(crate) fn u32(&mut self, field: impl fmt::Display) -> Result<u32, ParseError> {
        Ok(self.int(field, 32, false)? as u32)
    }

    pub(crate) fn i16(&mut self, field: impl fmt::Display) -> Result<i16, ParseError> {
        Ok(self.int(field, 16, true)? as i16)
    }

    pub(crate) fn i32(&mut self, field: impl fmt::Display) -> Result<i32, ParseError> {
        Ok(self.int(field, 32, true)? as i32)
    }

    /// A block count (a u16) that must not exceed `max`.
    pub(crate) fn count(
        &mut self,
        field: impl fmt::Display,
        max: u16,
    ) -> Result<usize, ParseError> {
        let (token, at) = self.token(&field)?;
        let v = parse_int(token, 16, false).map_err(|kind| self.error(&field, at, kind))?;
        if v > i64::from(max) {
            return Err(self.error(
                field,
                at,
                ParseErrorKind::OutOfRange {
                    token: token_text(token),
                    min: 0,
                    max: i64::from(max),
                },
            ));
        }
        Ok(v as usize)
    }

    /// A presence flag: 0 or 1 (a u16 on the wire).
    pub(crate) fn flag(&mut self, field: impl fmt::Display) -> Result<bool, ParseError> {
        let (token, at) = self.token(&field)?;
        match parse_int(token, 16, false) {
            Ok(0) => Ok(false),
            Ok(1) => Ok(true),
            Ok(_) => Err(self.error(
                field,
                at,
                ParseErrorKind::NotFlag {
                    token: token_text(token),
                },
            )),
            Err(kind) => Err(self.error(field, at, kind)),
        }
    }

    /// An IEEE-754 single as (up to) 8 hex digits.
    pub(crate) fn f32(&mut self, field: impl fmt::Display) -> Result<f32, ParseError> {
        let (token, at) = self.token(&field)?;
        match parse_hex(token) {
            Some(bits) if bits <= u64::from(u32::MAX) => Ok(f32::from_bits(bits as u32)),
            Some(_) => Err(self.error(
                field,
                at,
                ParseErrorKind::OutOfRange {
                    token: token_text(token),
                    min: 0,
                    max: i64::from(u32::MAX),
                },
            )),
            None => Err(self.error(
                field,
                at,
                ParseErrorKind::NotHex {
                    token: token_text(token),
                },
            )),
        }
    }

    /// A name token: ASCII letters, digits and `_`, starting with a letter.
    pub(crate) fn name(
        &mut self,
        field: impl fmt::Display,
        what: &'static str,
    ) -> Result<String, ParseError> {
        let (token, at) = self.token(&field)?;
        if is_name(token) {
            Ok(String::from_utf8_lossy(token).into_owned())
        } else {
            Err(self.error(
                field,
                at,
                ParseErrorKind::BadName {
                    token: token_text(token),
                    what,
                },
            ))
        }
    }

    /// A length-prefixed string: a hex length (u16), one space, that many bytes, then a
    /// space or the end of the telegram.
    pub(crate) fn flex(&mut self, field: impl fmt::Display) -> Result<Vec<u8>, ParseError> {
        let len = usize::from(self.u16(format!("{field} length"))?);
        if len == 0 {
            return Ok(Vec::new());
        }
        let at = self.pos;
        let bad = |reason| ParseErrorKind::BadString {
            declared: len,
            reason,
        };
        if self.buf.get(self.pos) != Some(&b' ') {
            return Err(self.error(field, at, bad("no space after the length")));
        }
        let start = self.pos + 1;
        let end = start + len;
        if end > self.buf.len() {
            return Err(self.error(field, start, bad("the telegram ends first")));
        }
        if end < self.buf.len() && self.buf[end] != b' ' {
            return Err(self.error(field, start, bad("no space after the string")));
        }
        self.pos = end;
        Ok(self.buf[start..end].to_vec())
    }

    /// The rest after one separating space, raw (the arguments of an unknown command).
    pub(crate) fn rest(&mut self) -> &'a [u8] {
        if self.buf.get(self.pos) == Some(&b' ') {
            self.pos += 1;
        }
        let rest = &self.buf[self.pos.min(self.buf.len())..];
        self.pos = self.buf.len();
        rest
    }

    /// Fail unless only spaces are left.
    pub(crate) fn end(&mut self, after: &str) -> Result<(), ParseError> {
        if self.at_end() {
            self.pos = self.buf.len();
            return Ok(());
        }
        self.skip_spaces();
        let rest = &self.buf[self.pos..];
        Err(self.error(
            format!("end of telegram after {after}"),
            self.pos,
            ParseErrorKind::Trailing {
                count: rest.len(),
                text: token_text(rest),
            },
        ))
    }
}

/// ASCII letters, digits and `_`, starting with a letter.
pub(crate) fn is_name(token: &[u8]) -> bool {
    token.first().is_some_and(u8::is_ascii_alphabetic)
        && token
            .iter()
            .all(|b| b.is_ascii_alphanumeric() || *b == b'_')
}

/// Upper- or lower-case hex digits, at most 16 of them after leading zeros.
pub(crate) fn parse_hex(token: &[u8]) -> Option<u64> {
    if token.is_empty() {
        return None;
    }
    let mut v: u64 = 0;
    for &b in token {
        let d = match b {
            b'0'..=b'9' => b - b'0',
            b'A'..=b'F' => b - b'A' + 10,
            b'a'..=b'f' => b - b'a' + 10,
            _ => return None,
        };
        if v >> 60 != 0 {
            // More than 16 significant digits: report as out of range.
            return Some(u64::MAX);
        }
        v = (v << 4) | u64::from(d);
    }
    Some(v)
}

/// An integer of `bits` width (8, 16 or 32): hex (two's complement when signed), or
/// decimal with a leading `+` or `-`.
pub(crate) fn parse_int(token: &[u8], bits: u32, signed: bool) -> Result<i64, ParseErrorKind> {
    let (min, max) = if signed {
        (-(1i64 << (bits - 1)), (1i64 << (bits - 1)) - 1)
    } else {
        (0, (1i64 << bits) - 1)
    };
    let out_of_range = || ParseErrorKind::OutOfRange {
        token: token_text(token),
        min,
        max,
    };
    match token.first() {
        Some(&sign @ (b'+' | b'-')) => {
            let digits = &token[1..];
            if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
                return Err(ParseErrorKind::NotDecimal {
                    token: token_text(token),
                });
            }
            let mut v: i64 = 0;
            for &d in digits {
                v = v
                    .checked_mul(10)
                    .and_then(|v| v.checked_add(i64::from(d - b'0')))
                    .ok_or_else(out_of_range)?;
            }
            let v = if sign == b'-' { -v } else { v };
            if v < min || v > max {
                return Err(out_of_range());
            }
            Ok(v)
        }
        _ => {
            let raw = parse_hex(token).ok_or_else(|| ParseErrorKind::NotHex {
                token: token_text(token),
            })?;
            let unsigned_max = (1u64 << bits) - 1;
            if raw > unsigned_max {
                return Err(ParseErrorKind::OutOfRange {
                    token: token_text(token),
                    min: if signed { min } else { 0 },
                    max: unsigned_max as i64,
                });
            }
            if signed && raw > max as u64 {
                // Two's complement of `bits` width.
                Ok(raw as i64 - (1i64 << bits))
            } else {
                Ok(raw as i64)
            }
        }
    }
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// Writes CoLa-A fields: hex without leading zeros, upper case, one space before
/// every field but the first.
pub(crate) struct Writer<'a> {
    pub(crate) out: &'a mut Vec<u8>,
}

impl Writer<'_> {
    /// Append raw bytes (no separator).
    pub(crate) fn raw(&mut self, bytes: &[u8]) {
        self.out.extend_from_slice(bytes);
    }

    /// A space, then a token.
    pub(crate) fn token(&mut self, token: &[u8]) {
        self.out.push(b' ');
        self.out.extend_from_slice(token);
    }

    /// A space, then `v` in hex.
    pub(crate) fn hex(&mut self, v: u64) {
        self.out.push(b' ');
        if v == 0 {
            self.out.push(b'0');
            return;
        }
        let digits = (64 - v.leading_zeros()).div_ceil(4);
        for i in (0..digits).rev() {
            self.out.push(HEX[((v >> (i * 4)) & 0xF) as usize]);
        }
    }

    /// A space, then a signed value as two's complement hex of `bits` width.
    pub(crate) fn hex_signed(&mut self, v: i64, bits: u32) {
        let mask = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        self.hex(v as u64 & mask);
    }

    /// A space, then the 8 hex digits of an IEEE-754 single.
    pub(crate) fn f32(&mut self, v: f32) {
        self.out.push(b' ');
        let bits = v.to_bits();
        for i in (0..8).rev() {
            self.out.push(HEX[((bits >> (i * 4)) & 0xF) as usize]);
        }
    }

    /// A space, the hex length, and (when not empty) a space and the bytes.
    pub(crate) fn flex(&mut self, field: &str, bytes: &[u8]) -> Result<(), EncodeError> {
        if bytes.len() > usize::from(u16::MAX) {
            return Err(EncodeError::new(
                field,
                format!("{} bytes, at most {}", bytes.len(), u16::MAX),
            ));
        }
        check_text(field, bytes)?;
        self.hex(bytes.len() as u64);
        if !bytes.is_empty() {
            self.token(bytes);
        }
        Ok(())
    }
}

/// Text inside a telegram must not contain STX or ETX.
pub(crate) fn check_text(field: &str, bytes: &[u8]) -> Result<(), EncodeError> {
    if let Some(i) = bytes.iter().position(|&b| b == 0x02 || b == 0x03) {
        return Err(EncodeError::new(
            field,
            format!("byte {i} is STX or ETX, which would break the framing"),
        ));
    }
    Ok(())
}

/// A name token for the wire (channel content, event type, command).
pub(crate) fn check_name(field: &str, name: &str) -> Result<(), EncodeError> {
    if is_name(name.as_bytes()) {
        Ok(())
    } else {
        Err(EncodeError::new(
            field,
            format!("{name:?} is not a name (ASCII letters, digits, _; a letter first)"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_and_signed_decimal_numbers() {
        assert_eq!(parse_int(b"FFF92230", 32, true), Ok(-450_000));
        assert_eq!(parse_int(b"186A0", 32, true), Ok(100_000));
        assert_eq!(parse_int(b"+10", 16, false), Ok(10));
        assert_eq!(parse_int(b"-5", 16, true), Ok(-5));
        assert_eq!(parse_int(b"ff", 8, false), Ok(255));
        assert_eq!(parse_int(b"0000000A", 8, false), Ok(10));
        assert!(matches!(
            parse_int(b"-5", 16, false),
            Err(ParseErrorKind::OutOfRange {
                min: 0,
                max: 65535,
                ..
            })
        ));
        assert!(matches!(
            parse_int(b"100", 8, false),
            Err(ParseErrorKind::OutOfRange { .. })
        ));
        assert!(matches!(
            parse_int(b"12G", 16, false),
            Err(ParseErrorKind::NotHex { .. })
        ));
        assert!(matches!(
            parse_int(b"+1A", 16, false),
            Err(ParseErrorKind::NotDecimal { .. })
        ));
        assert!(matches!(
            parse_int(b"FFFFFFFFFFFFFFFFFFFF", 32, false),
            Err(ParseErrorKind::OutOfRange { .. })
        ));
    }

    #[test]
    fn writer_writes_minimal_upper_case_hex() {
        let mut out = Vec::new();
        let mut w = Writer { out: &mut out };
        w.raw(b"x");
        w.hex(0);
        w.hex(0x21D);
        w.hex_signed(-450_000, 32);
        w.f32(1.0);
        w.f32(0.0);
        w.flex("name", b"not defined").unwrap();
        w.flex("empty", b"").unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "x 0 21D FFF92230 3F800000 00000000 B not defined 0"
        );
    }

    #[test]
    fn flex_strings_may_hold_spaces() {
        let mut c = Cursor::new(b"1 B not defined 0");
        assert!(c.flag("name").unwrap());
        assert_eq!(c.flex("name").unwrap(), b"not defined");
        assert!(!c.flag("comment").unwrap());
        c.end("comment").unwrap();
        let mut c = Cursor::new(b"C short");
        let e = c.flex("name").unwrap_err();
        assert!(matches!(
            e.kind,
            ParseErrorKind::BadString { declared: 12, .. }
        ));
        assert_eq!(e.offset, 2);
    }

    #[test]
    fn trailing_bytes_are_an_error() {
        let mut c = Cursor::new(b"1 2 ");
        c.u8("a").unwrap();
        let e = c.end("a").unwrap_err();
        assert_eq!(e.offset, 2);
        assert!(matches!(e.kind, ParseErrorKind::Trailing { count: 2, .. }));
    }
}
