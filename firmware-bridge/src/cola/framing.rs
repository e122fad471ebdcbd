//! STX/ETX framing of CoLa-A telegrams, and a decoder for a TCP byte stream.
//!
//! TCP hands over bytes in arbitrary pieces: half a telegram, several telegrams, or
//! bytes that belong to no telegram (a scanner that was mid-telegram when we
//! connected, a client sending garbage). [`TelegramDecoder`] takes the pieces as they
//! come and yields each complete telegram's content (the bytes between STX and ETX):
//!
//! - bytes outside STX..ETX are discarded and counted ([`TelegramDecoder::garbage_bytes`]);
//! - an STX inside a telegram means the telegram was cut off (CoLa-A content never
//!   holds STX): it is reported as [`FrameError::Unterminated`] and the new telegram
//!   starts at that STX, so the telegram after a broken one is not lost;
//! - a telegram longer than the bound is reported as [`FrameError::TooLong`] as soon
//!   as it exceeds it, its bytes are dropped up to its ETX (or the next STX) and the
//!   decoder goes on with the next telegram. Memory stays bounded by the limit.

use std::collections::VecDeque;

/// Start of a telegram.
pub const STX: u8 = 0x02;
/// End of a telegram.
pub const ETX: u8 = 0x03;

/// Default bound on a telegram's content: 256 KiB, far above the largest scan telegram
/// (an LMS5xx's five echoes with RSSI at 0.1667° are about 60 KiB).
pub const DEFAULT_MAX_TELEGRAM: usize = 256 * 1024;

/// Why the stream did not hold a well-framed telegram.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The telegram grew beyond the limit; the rest of it up to ETX is discarded.
    #[error("telegram longer than {limit} bytes, discarded")]
    TooLong { limit: usize },
    /// An STX arrived before the telegram's ETX: the telegram was cut off after
    /// `length` bytes.
    #[error("telegram cut off after {length} bytes by the next STX")]
    Unterminated { length: usize },
}

/// Append `STX payload ETX` to `out`.
pub fn frame_telegram(payload: &[u8], out: &mut Vec<u8>) {
    out.reserve(payload.len() + 2);
    out.push(STX);
    out.extend_from_slice(payload);
    out.push(ETX);
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Between telegrams.
    Idle,
    /// Inside a telegram, its bytes so far in `current`.
    Inside,
    /// Inside a telegram that was too long, dropping bytes up to its end.
    Discarding,
}

/// Splits a byte stream into telegram contents; see the [module documentation](self).
#[derive(Debug)]
pub struct TelegramDecoder {
    max_len: usize,
    state: State,
    current: Vec<u8>,
    ready: VecDeque<Result<Vec<u8>, FrameError>>,
    garbage: u64,
}

impl Default for TelegramDecoder {
    fn default() -> Self {
        TelegramDecoder::new(DEFAULT_MAX_TELEGRAM)
    }
}

impl TelegramDecoder {
    /// A decoder that refuses telegrams with more than `max_len` bytes of content
    /// (at least 1).
    pub fn new(max_len: usize) -> Self {
        TelegramDecoder {
            max_len: max_len.max(1),
            state: State::Idle,
            current: Vec::new(),
            ready: VecDeque::new(),
            garbage: 0,
        }
    }

    /// The bound on a telegram's content.
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    /// Bytes received outside any telegram so far.
    pub fn garbage_bytes(&self) -> u64 {
        self.garbage
    }

    /// Bytes of an unfinished telegram held so far.
    pub fn partial_len(&self) -> usize {
        self.current.len()
    }

    /// Take the next piece of the stream.
    pub fn push(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            match self.state {
                State::Idle => match bytes.iter().position(|&b| b == STX) {
                    Some(i) => {
                        self.garbage += i as u64;
                        self.state = State::Inside;
                        self.current.clear();
                        bytes = &bytes[i + 1..];
                    }
                    None => {
                        self.garbage += bytes.len() as u64;
                        bytes = &[];
                    }
                },
                State::Inside => {
                    let end = bytes.iter().position(|&b| b == STX || b == ETX);
                    let take = end.unwrap_or(bytes.len());
                    if self.current.len() + take > self.max_len {
                        self.current = Vec::new();
                        self.ready.push_back(Err(FrameError::TooLong {
                            limit: self.max_len,
                        }));
                        self.state = State::Discarding;
                        // Re-examine from the delimiter (if any) in Discarding state.
                        bytes = &bytes[take..];
                        continue;
                    }
                    self.current.extend_from_slice(&bytes[..take]);
                    match end {
                        Some(i) if bytes[i] == ETX => {
                            let telegram = std::mem::take(&mut self.current);
                            self.ready.push_back(Ok(telegram));
                            self.state = State::Idle;
                        }
                        Some(_) => {
                            // STX: the telegram so far was cut off; a new one starts.
                            self.ready.push_back(Err(FrameError::Unterminated {
                                length: self.current.len(),
                            }));
                            self.current.clear();
                        }
                        None => {}
                    }
                    bytes = &bytes[(take + 1).min(bytes.len())..];
                }
                State::Discarding => match bytes.iter().position(|&b| b == STX || b == ETX) {
                    Some(i) => {
                        if bytes[i] == STX {
                            self.state = State::Inside;
                            self.current.clear();
                        } else {
                            self.state = State::Idle;
                        }
                        bytes = &bytes[i + 1..];
                    }
                    None => bytes = &[],
                },
            }
        }
    }

    /// The next complete telegram's content (without STX and ETX), or a framing error,
    /// in stream order; `None` until more bytes are pushed.
    pub fn next_telegram(&mut self) -> Option<Result<Vec<u8>, FrameError>> {
        self.ready.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(d: &mut TelegramDecoder) -> Vec<Result<Vec<u8>, FrameError>> {
        std::iter::from_fn(|| d.next_telegram()).collect()
    }

    #[test]
    fn telegrams_split_and_joined_across_reads() {
        let mut d = TelegramDecoder::new(100);
        d.push(b"junk\x02sRN Dev");
        assert!(d.next_telegram().is_none());
        d.push(b"iceIdent\x03\x02sMN Run\x03\x02s");
        assert_eq!(
            all(&mut d),
            vec![Ok(b"sRN DeviceIdent".to_vec()), Ok(b"sMN Run".to_vec())]
        );
        assert_eq!(d.garbage_bytes(), 4);
        assert_eq!(d.partial_len(), 1);
    }

    #[test]
    fn too_long_is_reported_once_and_the_next_telegram_survives() {
        let mut d = TelegramDecoder::new(8);
        d.push(b"\x02123456789");
        d.push(b"abcdef\x03\x02ok\x03");
        assert_eq!(
            all(&mut d),
            vec![Err(FrameError::TooLong { limit: 8 }), Ok(b"ok".to_vec())]
        );
        // Exactly at the limit is fine.
        d.push(b"\x0212345678\x03");
        assert_eq!(all(&mut d), vec![Ok(b"12345678".to_vec())]);
        // An oversize telegram cut off by an STX: the next one is kept.
        d.push(b"\x02123456789\x02ok\x03");
        assert_eq!(
            all(&mut d),
            vec![Err(FrameError::TooLong { limit: 8 }), Ok(b"ok".to_vec())]
        );
    }

    #[test]
    fn stx_inside_a_telegram_starts_a_new_one() {
        let mut d = TelegramDecoder::new(100);
        d.push(b"\x02sRN LMD\x02sRN DeviceIdent\x03\x03");
        assert_eq!(
            all(&mut d),
            vec![
                Err(FrameError::Unterminated { length: 7 }),
                Ok(b"sRN DeviceIdent".to_vec())
            ]
        );
        assert_eq!(d.garbage_bytes(), 1);
    }
}
