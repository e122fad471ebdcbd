//! Byte stream to sentence lines: any chunking, garbage between sentences, partial
//! lines cut by a new `$`, CR, LF or CRLF terminators, and overlong lines.

use super::SentenceError;

/// Longest sentence accepted, from `$` to the checksum, without CR/LF: NMEA 0183's
/// 82 characters plus 20, gpsd's limit and the one the nmea crate (0.8) applied
/// before this crate decoded its own fields. Some receivers exceed 82 characters; RTK
/// receivers with 7-decimal minutes do, like this crate's writer.
pub const MAX_SENTENCE_LEN: usize = 82 + 20;

/// Whether `b` ends a line: a sentence ends at its first CR or LF (the LF after a CR
/// ends an empty line).
pub fn is_terminator(b: u8) -> bool {
    b == b'\r' || b == b'\n'
}

/// The NMEA checksum: XOR of the bytes between `$` and `*`.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |c, b| c ^ b)
}

/// What the framer produced from a byte.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Framed {
    /// A complete line starting with `$`, terminator stripped.
    Line(Vec<u8>),
    /// Something to count and report.
    Error(SentenceError),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between sentences.
    Idle,
    /// Inside a sentence.
    InLine,
    /// Inside an overlong sentence, skipping to its end.
    Discarding,
}

/// Splits a byte stream into sentence lines.
#[derive(Debug, Clone)]
pub struct LineFramer {
    buf: Vec<u8>,
    max_len: usize,
    state: State,
    garbage: usize,
    discarded: usize,
}

impl Default for LineFramer {
    fn default() -> Self {
        Self::new(MAX_SENTENCE_LEN)
    }
}

impl LineFramer {
    /// A framer for lines up to `max_len` bytes (from `$` through the checksum).
    pub fn new(max_len: usize) -> Self {
        Self {
            buf: Vec::with_capacity(max_len + 1),
            max_len,
            state: State::Idle,
            garbage: 0,
            discarded: 0,
        }
    }

    /// Feed bytes; complete lines and framing errors are pushed to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Framed>) {
        for &b in bytes {
            self.push_byte(b, out);
        }
    }

    /// Bytes held for a line not yet terminated.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Give up on a partial line and pending garbage (end of stream), reporting them.
    pub fn finish(&mut self, out: &mut Vec<Framed>) {
        self.end_garbage(out);
        match self.state {
            State::InLine => out.push(Framed::Error(SentenceError::Truncated {
                len: self.buf.len(),
            })),
            State::Discarding => self.end_discard(out),
            State::Idle => {}
        }
        self.buf.clear();
        self.state = State::Idle;
    }

    fn push_byte(&mut self, b: u8, out: &mut Vec<Framed>) {
        let terminator = is_terminator(b);
        match self.state {
            State::Idle => {
                if b == b'$' {
                    self.end_garbage(out);
                    self.start(b);
                } else if terminator {
                    self.end_garbage(out);
                } else {
                    self.garbage += 1;
                }
            }
            State::InLine => {
                if terminator {
                    let line =
                        std::mem::replace(&mut self.buf, Vec::with_capacity(self.max_len + 1));
                    out.push(Framed::Line(line));
                    self.state = State::Idle;
                } else if b == b'$' {
                    out.push(Framed::Error(SentenceError::Truncated {
                        len: self.buf.len(),
                    }));
                    self.start(b);
                } else if self.buf.len() >= self.max_len {
                    self.discarded = self.buf.len() + 1;
                    self.buf.clear();
                    self.state = State::Discarding;
                } else {
                    self.buf.push(b);
                }
            }
            State::Discarding => {
                if terminator {
                    self.end_discard(out);
                    self.state = State::Idle;
                } else if b == b'$' {
                    self.end_discard(out);
                    self.start(b);
                } else {
                    self.discarded += 1;
                }
            }
        }
    }

    fn start(&mut self, b: u8) {
        self.buf.clear();
        self.buf.push(b);
        self.state = State::InLine;
    }

    fn end_garbage(&mut self, out: &mut Vec<Framed>) {
        if self.garbage > 0 {
            out.push(Framed::Error(SentenceError::Garbage {
                bytes: self.garbage,
            }));
            self.garbage = 0;
        }
    }

    fn end_discard(&mut self, out: &mut Vec<Framed>) {
        out.push(Framed::Error(SentenceError::LineTooLong {
            len: self.discarded,
            max: self.max_len,
        }));
        self.discarded = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(input: &[u8]) -> Vec<Framed> {
        let mut f = LineFramer::new(20);
        let mut out = Vec::new();
        f.push(input, &mut out);
        out
    }

    #[test]
    fn crlf_lf_and_cr_terminate() {
        let out = frame(b"$A*00\r\n$B*00\n$C*00\r");
        assert_eq!(
            out,
            vec![
                Framed::Line(b"$A*00".to_vec()),
                Framed::Line(b"$B*00".to_vec()),
                Framed::Line(b"$C*00".to_vec()),
            ]
        );
    }

    #[test]
    fn garbage_and_cut_lines_are_reported() {
        let out = frame(b"xyz$GPG$B*00\r\n");
        assert_eq!(
            out,
            vec![
                Framed::Error(SentenceError::Garbage { bytes: 3 }),
                Framed::Error(SentenceError::Truncated { len: 4 }),
                Framed::Line(b"$B*00".to_vec()),
            ]
        );
    }

    #[test]
    fn overlong_lines_are_discarded_once() {
        let out = frame(b"$0123456789012345678901234567890\r\n$B*00\n");
        assert_eq!(
            out,
            vec![
                Framed::Error(SentenceError::LineTooLong { len: 32, max: 20 }),
                Framed::Line(b"$B*00".to_vec()),
            ]
        );
    }
}
