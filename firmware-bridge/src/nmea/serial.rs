//! Endpoints of the GPS wire: a serial device (or the simulator's pty) read through
//! an [`NmeaReader`], and the simulator's pseudo-terminal.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use serialport::{ClearBuffer, SerialPort};

use super::NmeaError;
use super::framing::{Framed, LineFramer};
use super::reader::{GpsReading, NmeaReader, ReadEvent, ReaderConfig, ReaderStats};

/// Open a serial device, or a pty slave or a symlink to one, at `baud` 8N1 without
/// flow control; reads block for at most `timeout`. Bytes received before the
/// open are discarded, as on a real line.
pub fn open_serial(
    path: &Path,
    baud: u32,
    timeout: Duration,
) -> Result<Box<dyn SerialPort>, NmeaError> {
    let path_str = path.to_str().ok_or_else(|| NmeaError::NonUtf8Path {
        path: path.to_owned(),
    })?;
    let serial_err = |source| NmeaError::Serial {
        path: path_str.to_owned(),
        source,
    };
    let port = serialport::new(path_str, baud)
        .timeout(timeout)
        .open()
        .map_err(serial_err)?;
    port.clear(ClearBuffer::Input).map_err(serial_err)?;
    Ok(port)
}

/// A byte port joined to an [`NmeaReader`]: the controller's GPS input. Writing goes
/// straight to the port (a GGA for NTRIP, receiver configuration).
#[derive(Debug)]
pub struct NmeaLink<P> {
    port: P,
    reader: NmeaReader,
    buf: Vec<u8>,
}

impl<P: Read + Write> NmeaLink<P> {
    pub fn new(port: P, config: ReaderConfig) -> Self {
        Self {
            port,
            reader: NmeaReader::new(config),
            buf: vec![0; 1024],
        }
    }

    /// One read from the port (blocking up to the port's timeout) fed to the reader;
    /// the events it completed. A timeout or `WouldBlock` yields no events.
    pub fn poll(&mut self) -> Result<Vec<ReadEvent>, NmeaError> {
        let n = loop {
            match self.port.read(&mut self.buf) {
                Ok(n) => break n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) =>
                {
                    return Ok(Vec::new());
                }
                Err(source) => {
                    return Err(NmeaError::Io {
                        context: "reading the GPS port".into(),
                        source,
                    });
                }
            }
        };
        let bytes = self.buf.get(..n).unwrap_or(&[]);
        Ok(self.reader.feed(bytes).collect())
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

/// The simulator's GPS port: a pseudo-terminal whose slave the controller opens like
/// /dev/ttyUSB0, optionally through a symlink with a stable name.
///
/// The slave is raw (no echo, no line editing) and held open by the endpoint, so the
/// master never sees a hang-up between controller runs. The master is non-blocking:
/// while nobody reads, the pty buffer (a few KiB) fills and [`Self::send`] drops what
/// does not fit, counting it, as a serial line with nobody listening loses it.
#[derive(Debug)]
pub struct PtyEndpoint {
    master: File,
    _slave: OwnedFd,
    slave_path: PathBuf,
    link: Option<PathBuf>,
    input: LineFramer,
    dropped_bytes: u64,
}

impl PtyEndpoint {
    /// Create the pty pair and, if `link` is given, a symlink there to the slave
    /// (replacing a stale symlink; refusing to replace anything else).
    pub fn open(link: Option<&Path>) -> Result<Self, NmeaError> {
        let pty = nix::pty::openpty(None, None).map_err(|source| NmeaError::Pty {
            op: "openpty",
            source,
        })?;
        let mut termios = tcgetattr(&pty.slave).map_err(|source| NmeaError::Pty {
            op: "tcgetattr",
            source,
        })?;
        cfmakeraw(&mut termios);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &termios).map_err(|source| NmeaError::Pty {
            op: "tcsetattr",
            source,
        })?;
        let flags = fcntl(&pty.master, FcntlArg::F_GETFL).map_err(|source| NmeaError::Pty {
            op: "fcntl(F_GETFL)",
            source,
        })?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(&pty.master, FcntlArg::F_SETFL(flags)).map_err(|source| NmeaError::Pty {
            op: "fcntl(F_SETFL)",
            source,
        })?;
        let slave_path = nix::unistd::ttyname(&pty.slave).map_err(|source| NmeaError::Pty {
            op: "ttyname",
            source,
        })?;
        if let Some(link) = link {
            make_link(&slave_path, link)?;
        }
        Ok(Self {
            master: File::from(pty.master),
            _slave: pty.slave,
            slave_path,
            link: link.map(Path::to_owned),
            input: LineFramer::default(),
            dropped_bytes: 0,
        })
    }

    /// The path the controller opens: the symlink if there is one, else the slave.
    pub fn path(&self) -> &Path {
        self.link.as_deref().unwrap_or(&self.slave_path)
    }

    /// The slave device (/dev/pts/N).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// Write what fits in the pty now; the rest is dropped and counted. Returns the
    /// bytes written. Pacing at the baud rate is the caller's (see
    /// [`super::transmit_time`]): a pty enforces none.
    pub fn send(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        let written = self.send_some(bytes)?;
        self.dropped_bytes += (bytes.len() - written) as u64;
        Ok(written)
    }

    /// Write what fits in the pty now and return how much that was; the rest stays
    /// the caller's (a transmit buffer that drops whole sentences, not bytes).
    pub fn send_some(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        write_what_fits(&mut self.master, bytes, &self.slave_path)
    }

    /// Bytes [`Self::send`] could not place.
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// Whatever the controller wrote since the last call (a GGA for NTRIP, receiver
    /// configuration), split into lines; framing problems come as errors. Never blocks.
    pub fn read_input(&mut self) -> Result<Vec<Framed>, NmeaError> {
        read_lines(&mut self.master, &mut self.input, &self.slave_path)
    }
}

/// Write what the line takes now (`WouldBlock` or a write timeout end it); the bytes
/// written.
fn write_what_fits(w: &mut impl Write, bytes: &[u8], path: &Path) -> Result<usize, NmeaError> {
    let mut written = 0;
    while written < bytes.len() {
        let rest = bytes.get(written..).unwrap_or(&[]);
        match w.write(rest) {
            Ok(0) => break,
            Ok(n) => written += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                break;
            }
            Err(source) => {
                return Err(NmeaError::Io {
                    context: format!("writing to {}", path.display()),
                    source,
                });
            }
        }
    }
    Ok(written)
}

/// Whatever came in on the line so far, framed into lines (logged); never blocks on a
/// non-blocking or zero-timeout port.
fn read_lines(
    r: &mut impl Read,
    framer: &mut LineFramer,
    path: &Path,
) -> Result<Vec<Framed>, NmeaError> {
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    loop {
        match r.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => framer.push(buf.get(..n).unwrap_or(&[]), &mut out),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                break;
            }
            Err(source) => {
                return Err(NmeaError::Io {
                    context: format!("reading from {}", path.display()),
                    source,
                });
            }
        }
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

/// The simulated receiver's line on a physical serial device (a USB-serial adapter
/// wired to the controller's board): opened through serialport at the baud rate, 8N1,
/// and used without blocking, like [`PtyEndpoint`]: what the UART buffer does not take
/// is dropped and counted.
pub struct SerialEndpoint {
    port: Box<dyn SerialPort>,
    path: PathBuf,
    input: LineFramer,
    dropped_bytes: u64,
}

impl std::fmt::Debug for SerialEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialEndpoint")
            .field("path", &self.path)
            .field("dropped_bytes", &self.dropped_bytes)
            .finish_non_exhaustive()
    }
}

impl SerialEndpoint {
    /// Open `path` at `baud`.
    pub fn open(path: &Path, baud: u32) -> Result<Self, NmeaError> {
        Ok(SerialEndpoint {
            port: open_serial(path, baud, Duration::ZERO)?,
            path: path.to_owned(),
            input: LineFramer::default(),
            dropped_bytes: 0,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Write what the device takes now; the rest is dropped and counted.
    pub fn send(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        let written = self.send_some(bytes)?;
        self.dropped_bytes += (bytes.len() - written) as u64;
        Ok(written)
    }

    /// Write what the device takes now and return how much that was; the rest stays
    /// the caller's.
    pub fn send_some(&mut self, bytes: &[u8]) -> Result<usize, NmeaError> {
        write_what_fits(&mut self.port, bytes, &self.path)
    }

    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// What the controller wrote back, in lines. Never blocks.
    pub fn read_input(&mut self) -> Result<Vec<Framed>, NmeaError> {
        read_lines(&mut self.port, &mut self.input, &self.path)
    }
}

impl Write for PtyEndpoint {
    /// Raw write to the master (non-blocking: a full pty gives `WouldBlock`).
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.master.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.master.flush()
    }
}

impl Drop for PtyEndpoint {
    fn drop(&mut self) {
        if let Some(link) = &self.link
            && std::fs::read_link(link).is_ok_and(|target| target == self.slave_path)
        {
            let _ = std::fs::remove_file(link);
        }
    }
}

fn make_link(target: &Path, link: &Path) -> Result<(), NmeaError> {
    let io_err = |context: String| move |source| NmeaError::Io { context, source };
    match std::fs::symlink_metadata(link) {
        Ok(meta) if !meta.file_type().is_symlink() => {
            return Err(NmeaError::LinkOccupied {
                path: link.to_owned(),
            });
        }
        Ok(_) => std::fs::remove_file(link).map_err(io_err(format!(
            "removing stale GPS link {}",
            link.display()
        )))?,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(source) => {
            return Err(NmeaError::Io {
                context: format!("checking GPS link {}", link.display()),
                source,
            });
        }
    }
    std::os::unix::fs::symlink(target, link).map_err(io_err(format!(
        "linking {} to {}",
        link.display(),
        target.display()
    )))
}
