//! The controller's GPS input: a byte port joined to an [`NmeaReader`].

use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use super::NmeaError;
use super::line::read_now;
use super::reader::{GpsReading, NmeaReader, ReadEvent, ReaderConfig, ReaderStats};

/// A byte port joined to an [`NmeaReader`]: the controller's GPS input. Writing goes
/// straight to the port (a GGA for NTRIP, receiver configuration).
#[derive(Debug)]
pub struct NmeaLink<P> {
    port: P,
    reader: NmeaReader,
    buf: Vec<u8>,
    /// Bytes the last poll read (the start of `buf`).
    last: usize,
}

impl<P: Read + Write> NmeaLink<P> {
    pub fn new(port: P, config: ReaderConfig) -> Self {
        Self {
            port,
            reader: NmeaReader::new(config),
            buf: vec![0; 1024],
            last: 0,
        }
    }

    /// One read from the port (blocking up to the port's timeout) fed to the reader;
    /// the events it completed. A timeout or `WouldBlock` yields no events.
    pub fn poll(&mut self) -> Result<Vec<ReadEvent>, NmeaError> {
        self.last = 0;
        let n = read_now(&mut self.port, &mut self.buf).map_err(|source| NmeaError::Io {
            context: "reading the GPS port".into(),
            source,
        })?;
        self.last = n;
        let bytes = self.buf.get(..n).unwrap_or(&[]);
        Ok(self.reader.feed(bytes).collect())
    }

    /// The bytes the last [`NmeaLink::poll`] read, as they came off the line (for a
    /// recorder).
    pub fn last_read(&self) -> &[u8] {
        self.buf.get(..self.last).unwrap_or(&[])
    }

    /// Poll until a reading arrives or `timeout` has passed (wall clock: for HIL
    /// endpoints, not for SIL logic). Errors met on the way are counted in
    /// [`Self::stats`] and skipped.
    pub fn next_fix(&mut self, timeout: Duration) -> Result<Option<GpsReading>, NmeaError> {
        let deadline = Instant::now() + timeout;
        loop {
            let fix = self.poll()?.into_iter().find_map(|e| match e {
                ReadEvent::Fix(f) => Some(f),
                ReadEvent::Error(_) => None,
            });
            if fix.is_some() {
                return Ok(fix);
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    pub fn reader_mut(&mut self) -> &mut NmeaReader {
        &mut self.reader
    }

    pub fn stats(&self) -> &ReaderStats {
        self.reader.stats()
    }

    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    pub fn into_port(self) -> P {
        self.port
    }
}

impl<P: Write> Write for NmeaLink<P> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.port.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.port.flush()
    }
}
