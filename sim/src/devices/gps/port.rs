//! The GPS's serial port in HIL: a pseudo-terminal at a user-named link path, or a
//! physical serial device, fed at the configured baud rate by a [`Pacer`], and a log
//! of what the controller writes back.

use std::collections::VecDeque;
use std::path::Path;

use firmware_bridge::nmea::{BytePort, Framed, LineEndpoint, PtyEndpoint, SerialEndpoint};

use super::pacer::Pacer;
use super::{GpsDevice, GpsEpoch, GpsError};
use crate::vehicle::VehicleState;

/// Lines kept by default in the input log.
pub const INPUT_LOG_LINES: usize = 32;

/// The receiver's transmit buffer, bytes: what the UART has released but the line has
/// not taken yet (a reader that stalls). A sentence that would not fit whole is
/// dropped whole, as a receiver's buffer does, never cut: the reader then misses
/// sentences, but never gets one spliced from two.
pub const TX_BUFFER: usize = 1024;

/// The longest NMEA 0183 sentence, with its CR LF.
const SENTENCE_MAX: usize = 82;

/// What the controller wrote to the receiver (a GGA for NTRIP, configuration
/// commands): the last lines, and counts.
#[derive(Debug, Clone)]
pub struct InputLog {
    lines: VecDeque<String>,
    capacity: usize,
    count: u64,
    errors: u64,
    last_error: Option<String>,
}

impl InputLog {
    pub fn new(capacity: usize) -> InputLog {
        InputLog {
            lines: VecDeque::with_capacity(capacity),
            capacity,
            count: 0,
            errors: 0,
            last_error: None,
        }
    }

    fn push(&mut self, framed: Framed) {
        match framed {
            Framed::Line(bytes) => {
                self.count += 1;
                if self.capacity > 0 {
                    if self.lines.len() == self.capacity {
                        self.lines.pop_front();
                    }
                    self.lines
                        .push_back(String::from_utf8_lossy(&bytes).into_owned());
                }
            }
            Framed::Error(e) => {
                self.errors += 1;
                self.last_error = Some(e.to_string());
            }
        }
    }

    /// The last lines received, oldest first, without their CR LF.
    pub fn lines(&self) -> impl Iterator<Item = &str> {
        self.lines.iter().map(String::as_str)
    }

    /// The most recent line.
    pub fn last(&self) -> Option<&str> {
        self.lines.back().map(String::as_str)
    }

    /// Lines received in all.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Framing problems (garbage, overlong or cut-off lines) in all.
    pub fn errors(&self) -> u64 {
        self.errors
    }

    pub fn last_error(&self) -> Option<&str> {
        self.last_error.as_deref()
    }
}

/// The simulated receiver's serial port: owns the pty (and the symlink the controller
/// opens), paces the NMEA at the baud rate on sim time, and logs the controller's
/// input. Call [`GpsPort::tick`] (or [`GpsPort::enqueue`] and [`GpsPort::pace`]) from
/// the simulator's tick loop: bytes leave in the tick at or after their time, so at
/// 200 Hz a byte is at most 5 ms late and the line never runs faster than the baud.
#[derive(Debug)]
pub struct GpsPort {
    /// The receiver's end of the line: a pty or a serial device.
    line: LineEndpoint<Box<dyn BytePort>>,
    pacer: Pacer,
    input: InputLog,
    out: Vec<u8>,
    /// Released by the pacer, not yet taken by the line (at most [`TX_BUFFER`]).
    unsent: VecDeque<u8>,
    /// Dropping the rest of a sentence that did not fit.
    dropping: bool,
    written: u64,
    dropped_sentences: u64,
    dropped_bytes: u64,
}

impl GpsPort {
    fn on(line: LineEndpoint<Box<dyn BytePort>>, baud: u32) -> GpsPort {
        GpsPort {
            line,
            pacer: Pacer::new(baud),
            input: InputLog::new(INPUT_LOG_LINES),
            out: Vec::new(),
            unsent: VecDeque::new(),
            dropping: false,
            written: 0,
            dropped_sentences: 0,
            dropped_bytes: 0,
        }
    }

    /// A pty, with a symlink at `link` if given (a stale symlink there is replaced,
    /// anything else refused), paced at `baud`.
    pub fn open(link: Option<&Path>, baud: u32) -> Result<GpsPort, GpsError> {
        Ok(GpsPort::on(PtyEndpoint::open(link)?.boxed(), baud))
    }

    /// A physical serial device (a USB-serial adapter wired to the controller's
    /// board) set to `baud` and paced at it.
    pub fn serial(device: &Path, baud: u32) -> Result<GpsPort, GpsError> {
        Ok(GpsPort::on(
            SerialEndpoint::open(device, baud)?.boxed(),
            baud,
        ))
    }

    /// The path the controller opens: the pty's symlink, else its slave; or the
    /// serial device.
    pub fn path(&self) -> &Path {
        self.line.path()
    }

    /// The pty slave device (/dev/pts/N), or the serial device.
    pub fn slave_path(&self) -> &Path {
        self.line.device()
    }

    /// Queue an epoch's sentences to go out from its epoch time on.
    pub fn enqueue(&mut self, epoch: &GpsEpoch) -> f64 {
        self.pacer.enqueue(epoch.time_s, epoch.text.as_bytes())
    }

    /// Write the bytes whose time has come by `now` (sim seconds) and log whatever the
    /// controller wrote; returns the bytes handed to the pty.
    pub fn pace(&mut self, now: f64) -> Result<usize, GpsError> {
        self.out.clear();
        self.pacer.release(now, &mut self.out);
        for &b in &self.out {
            // A sentence starts after a LF (or on an empty buffer's first byte); one
            // that would not fit whole is dropped to its LF.
            let at_start = self.unsent.back().is_none_or(|&last| last == b'\n');
            if !self.dropping && at_start && self.unsent.len() + SENTENCE_MAX > TX_BUFFER {
                self.dropping = true;
            }
            if self.dropping {
                self.dropped_bytes += 1;
                if b == b'\n' {
                    self.dropping = false;
                    self.dropped_sentences += 1;
                }
            } else {
                self.unsent.push_back(b);
            }
        }
        let n = if self.unsent.is_empty() {
            0
        } else {
            let (head, _) = self.unsent.as_slices();
            let n = self.line.send_some(head)?;
            self.unsent.drain(..n);
            n
        };
        self.written += n as u64;
        for f in self.line.read_input()? {
            self.input.push(f);
        }
        Ok(n)
    }

    /// One simulator tick: the device's epoch if one is due (queued), then
    /// [`Self::pace`]. Returns the epoch produced, for logs and recordings.
    pub fn tick(
        &mut self,
        device: &mut GpsDevice,
        now: f64,
        vehicle: &VehicleState,
    ) -> Result<Option<GpsEpoch>, GpsError> {
        let epoch = device.poll(now, vehicle)?;
        if let Some(e) = &epoch {
            self.enqueue(e);
        }
        self.pace(now)?;
        Ok(epoch)
    }

    /// What the controller wrote.
    pub fn input(&self) -> &InputLog {
        &self.input
    }

    pub fn pacer(&self) -> &Pacer {
        &self.pacer
    }

    /// Bytes written to the line.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Bytes of the sentences dropped because the line was full (nobody reading).
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// Whole sentences dropped because the reader did not keep up.
    pub fn dropped_sentences(&self) -> u64 {
        self.dropped_sentences
    }
}
