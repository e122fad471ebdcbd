//! The GPS's serial port in HIL: a pseudo-terminal at a user-named link path, or a
//! physical serial device, fed at the configured baud rate by a [`Pacer`], and a log
//! of what the controller writes back.

use std::collections::VecDeque;
use std::path::Path;

use firmware_bridge::nmea::{Framed, NmeaError, PtyEndpoint, SerialEndpoint};

use super::pacer::Pacer;
use super::{GpsDevice, GpsEpoch, GpsError};
use crate::vehicle::VehicleState;

/// Lines kept by default in the input log.
pub const INPUT_LOG_LINES: usize = 32;

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
    line: Line,
    pacer: Pacer,
    input: InputLog,
    out: Vec<u8>,
    written: u64,
}

/// The receiver's end of the line.
#[derive(Debug)]
enum Line {
    Pty(PtyEndpoint),
    Serial(SerialEndpoint),
}

impl Line {
    fn send(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        match self {
            Line::Pty(p) => p.send(bytes),
            Line::Serial(s) => s.send(bytes),
        }
    }

    fn read_input(&mut self) -> Result<Vec<Framed>, NmeaError> {
        match self {
            Line::Pty(p) => p.read_input(),
            Line::Serial(s) => s.read_input(),
        }
    }
}

impl GpsPort {
    fn on(line: Line, baud: u32) -> GpsPort {
        GpsPort {
            line,
            pacer: Pacer::new(baud),
            input: InputLog::new(INPUT_LOG_LINES),
            out: Vec::new(),
            written: 0,
        }
    }

    /// A pty, with a symlink at `link` if given (a stale symlink there is replaced,
    /// anything else refused), paced at `baud`.
    pub fn open(link: Option<&Path>, baud: u32) -> Result<GpsPort, GpsError> {
        Ok(GpsPort::on(Line::Pty(PtyEndpoint::open(link)?), baud))
    }

    /// A physical serial device (a USB-serial adapter wired to the controller's
    /// board) set to `baud` and paced at it.
    pub fn serial(device: &Path, baud: u32) -> Result<GpsPort, GpsError> {
        Ok(GpsPort::on(
            Line::Serial(SerialEndpoint::open(device, baud)?),
            baud,
        ))
    }

    /// The path the controller opens: the pty's symlink, else its slave; or the
    /// serial device.
    pub fn path(&self) -> &Path {
        match &self.line {
            Line::Pty(p) => p.path(),
            Line::Serial(s) => s.path(),
        }
    }

    /// The pty slave device (/dev/pts/N), or the serial device.
    pub fn slave_path(&self) -> &Path {
        match &self.line {
            Line::Pty(p) => p.slave_path(),
            Line::Serial(s) => s.path(),
        }
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
        let n = if self.out.is_empty() {
            0
        } else {
            // What does not fit (nobody reading) is dropped and counted by the line.
            self.line.send(&self.out)?
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

    /// Bytes lost because the line was full (nobody reading).
    pub fn dropped_bytes(&self) -> u64 {
        match &self.line {
            Line::Pty(p) => p.dropped_bytes(),
            Line::Serial(s) => s.dropped_bytes(),
        }
    }
}
