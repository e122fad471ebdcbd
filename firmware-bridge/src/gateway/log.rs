//! The log of forwarded frames, in can-utils' `candump -l -x` format.
//!
//! Each forwarded frame is two lines, exactly what `candump -l -x` on the gateway's
//! two sockets would record: the frame as received (`R`, the kernel's receive time, on
//! the interface it came from), then as transmitted (`T`, the time the transmit call
//! returned, on the interface it went to):
//!
//! ```text
//! (1700000000.123456) vcan0 100#0102030405060708 R
//! (1700000000.123471) can0 100#0102030405060708 T
//! ```
//!
//! The direction is the pair of interfaces; the difference of the two times is the
//! frame's latency in the gateway. can-utils (canplayer, log2asc) and
//! `golf_car_can::candump::parse_line` read these lines.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use golf_car_can::candump::Compact;

use super::routing::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_SFF_MASK};
use super::socket::RawFrame;

/// How often the log is flushed while frames flow.
const FLUSH_EVERY: Duration = Duration::from_millis(500);

/// The candump-format log of forwarded frames.
#[derive(Debug)]
pub struct ForwardLog {
    path: PathBuf,
    out: BufWriter<File>,
    last_flush: Instant,
}

/// `(seconds.micros)` as candump writes it.
fn stamp(t: SystemTime) -> String {
    let d = t.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    format!("({:010}.{:06})", d.as_secs(), d.subsec_micros())
}

impl ForwardLog {
    /// Create (truncate) the log file.
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(ForwardLog {
            path: path.to_owned(),
            out: BufWriter::with_capacity(64 * 1024, File::create(path)?),
            last_flush: Instant::now(),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The two lines of one forwarded frame.
    pub fn format(
        frame: &RawFrame,
        from: &str,
        to: &str,
        rx: SystemTime,
        tx: SystemTime,
    ) -> String {
        let can_id = frame.can_id();
        let extended = can_id & CAN_EFF_FLAG != 0;
        let compact = Compact {
            id: can_id & if extended { CAN_EFF_MASK } else { CAN_SFF_MASK },
            extended,
            data: frame.data(),
        };
        let mut s = String::with_capacity(96);
        let _ = writeln!(s, "{} {from} {compact} R", stamp(rx));
        let _ = writeln!(s, "{} {to} {compact} T", stamp(tx));
        s
    }

    /// Append one forwarded frame.
    pub fn write(
        &mut self,
        frame: &RawFrame,
        from: &str,
        to: &str,
        rx: SystemTime,
        tx: SystemTime,
    ) -> io::Result<()> {
        self.out
            .write_all(Self::format(frame, from, to, rx, tx).as_bytes())?;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    /// Write what is buffered to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.last_flush = Instant::now();
        self.out.flush()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use golf_car_can::candump::parse_line;

    #[test]
    fn lines_are_candump_log_lines_with_direction() {
        let mut bytes = [0u8; 16];
        bytes[..4].copy_from_slice(&0x101u32.to_ne_bytes());
        bytes[4] = 8;
        bytes[8..].copy_from_slice(&[0xDE, 0xAD, 0xBE, 0xEF, 0, 1, 2, 0xFF]);
        let frame = RawFrame { bytes, stamp: None };
        let rx = SystemTime::UNIX_EPOCH + Duration::new(1_700_000_000, 123_456_789);
        let tx = rx + Duration::from_micros(15);
        let text = ForwardLog::format(&frame, "can0", "vcan0", rx, tx);
        assert_eq!(
            text,
            "(1700000000.123456) can0 101#DEADBEEF000102FF R\n(1700000000.123471) vcan0 101#DEADBEEF000102FF T\n"
        );
        for (line, iface) in text.lines().zip(["can0", "vcan0"]) {
            let f = parse_line(line).unwrap();
            assert_eq!(f.interface.as_deref(), Some(iface));
            assert_eq!((f.id, f.extended, f.remote), (0x101, false, false));
            assert_eq!(f.data, [0xDE, 0xAD, 0xBE, 0xEF, 0, 1, 2, 0xFF]);
        }
    }

    #[test]
    fn the_file_holds_what_was_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fwd.log");
        let mut log = ForwardLog::create(&path).unwrap();
        let mut bytes = [0u8; 16];
        bytes[4] = 8;
        let frame = RawFrame { bytes, stamp: None };
        for _ in 0..3 {
            log.write(&frame, "a", "b", SystemTime::now(), SystemTime::now())
                .unwrap();
        }
        log.flush().unwrap();
        let text = std::fs::read_to_string(log.path()).unwrap();
        assert_eq!(text.lines().count(), 6);
        assert!(text.lines().all(|l| parse_line(l).is_ok()), "{text}");
    }
}
