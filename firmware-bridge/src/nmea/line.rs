//! One end of a serial line over any byte port (`Read + Write`): the simulated
//! receiver's pty, or a serial device. Writing never blocks: what the port does not
//! take now is dropped and counted (or left to the caller); reading takes whatever
//! arrived and frames it into lines.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use super::NmeaError;
use super::framing::{Framed, LineFramer};

/// A byte port a [`LineEndpoint`] can run over, as a trait object:
/// `LineEndpoint<Box<dyn BytePort>>` holds a pty or a serial device alike.
pub trait BytePort: Read + Write + Send {}

impl<T: Read + Write + Send + ?Sized> BytePort for T {}

/// The receiver's end of a line over a byte port `P`: non-blocking writes with what
/// does not fit dropped and counted, and what the far end wrote back, framed into
/// lines (a GGA for NTRIP, receiver configuration). The port is expected not to block
/// (a non-blocking fd, or a zero read and write timeout); a timeout counts as "nothing
/// more now".
///
/// [`super::PtyEndpoint`] and [`super::SerialEndpoint`] are this over a pty and over
/// a serial device.
pub struct LineEndpoint<P> {
    port: P,
    /// The device (`/dev/pts/N`, `/dev/ttyUSB0`): named in errors.
    device: PathBuf,
    /// What the far end opens: the device, or a symlink to it.
    path: PathBuf,
    input: LineFramer,
    dropped_bytes: u64,
}

impl<P> std::fmt::Debug for LineEndpoint<P> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LineEndpoint")
            .field("device", &self.device)
            .field("path", &self.path)
            .field("dropped_bytes", &self.dropped_bytes)
            .finish_non_exhaustive()
    }
}

impl<P> LineEndpoint<P> {
    /// An endpoint on `port`, the device at `device`, which the far end opens at
    /// `path` (the device itself, or a symlink to it).
    pub fn new(port: P, device: PathBuf, path: PathBuf) -> Self {
        Self {
            port,
            device,
            path,
            input: LineFramer::default(),
            dropped_bytes: 0,
        }
    }

    /// The path the far end opens: a symlink if there is one, else the device.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The device itself (`/dev/pts/N`, `/dev/ttyUSB0`).
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// Bytes [`Self::send`] could not place.
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    pub fn port(&self) -> &P {
        &self.port
    }

    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// The same endpoint over a boxed port, so that endpoints over different devices
    /// have one type.
    pub fn boxed(self) -> LineEndpoint<Box<dyn BytePort>>
    where
        P: BytePort + 'static,
    {
        LineEndpoint {
            port: Box::new(self.port),
            device: self.device,
            path: self.path,
            input: self.input,
            dropped_bytes: self.dropped_bytes,
        }
    }
}

impl<P: Read + Write> LineEndpoint<P> {
    /// Write what fits now; the rest is dropped and counted. Returns the bytes
    /// written. Pacing at the baud rate is the caller's (see
    /// [`super::transmit_time`]): a pty enforces none.
    pub fn send(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        let written = self.send_some(bytes)?;
        self.dropped_bytes += (bytes.len() - written) as u64;
        Ok(written)
    }

    /// Write what fits now and return how much that was; the rest stays the caller's
    /// (a transmit buffer that drops whole sentences, not bytes).
    pub fn send_some(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        write_now(&mut self.port, bytes).map_err(|source| NmeaError::Io {
            context: format!("writing to {}", self.device.display()),
            source,
        })
    }

    /// Whatever the far end wrote since the last call, split into lines (logged);
    /// framing problems come as errors. Never blocks.
    pub fn read_input(&mut self) -> Result<Vec<Framed>, NmeaError> {
        let mut out = Vec::new();
        let mut buf = [0u8; 512];
        loop {
            let n = read_now(&mut self.port, &mut buf).map_err(|source| NmeaError::Io {
                context: format!("reading from {}", self.device.display()),
                source,
            })?;
            if n == 0 {
                break;
            }
            self.input.push(buf.get(..n).unwrap_or(&[]), &mut out);
        }
        for f in &out {
            match f {
                Framed::Line(line) => {
                    tracing::info!(line = %String::from_utf8_lossy(line), "GPS input from the controller");
                }
                Framed::Error(e) => tracing::info!(error = %e, "GPS input from the controller"),
            }
        }
        Ok(out)
    }
}

impl<P: Write> Write for LineEndpoint<P> {
    /// Raw write to the port (on a non-blocking port, a full buffer gives
    /// `WouldBlock`).
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.port.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.port.flush()
    }
}

/// Does this error mean "nothing more now" on a non-blocking or timed port?
fn is_idle(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
    )
}

/// One read, retried when interrupted; `WouldBlock` or a read timeout give 0 bytes.
pub(super) fn read_now(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    loop {
        match r.read(buf) {
            Ok(n) => return Ok(n),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if is_idle(&e) => return Ok(0),
            Err(e) => return Err(e),
        }
    }
}

/// Write what the port takes now (`WouldBlock` or a write timeout end it); the bytes
/// written.
fn write_now(w: &mut impl Write, bytes: &[u8]) -> io::Result<usize> {
    let mut written = 0;
    while written < bytes.len() {
        let rest = bytes.get(written..).unwrap_or(&[]);
        match w.write(rest) {
            Ok(0) => break,
            Ok(n) => written += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if is_idle(&e) => break,
            Err(e) => return Err(e),
        }
    }
    Ok(written)
}
