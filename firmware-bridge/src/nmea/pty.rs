//! The simulator's GPS port as a pseudo-terminal: the slave is what the controller
//! opens like /dev/ttyUSB0, optionally through a symlink with a stable name.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

use super::NmeaError;
use super::line::LineEndpoint;

/// The simulator's GPS port: a [`LineEndpoint`] on a [`Pty`]'s master.
///
/// The slave is raw (no echo, no line editing) and held open by the endpoint, so the
/// master never sees a hang-up between controller runs. The master is non-blocking:
/// while nobody reads, the pty buffer (a few KiB) fills and [`LineEndpoint::send`]
/// drops what does not fit, counting it, as a serial line with nobody listening loses
/// it.
pub type PtyEndpoint = LineEndpoint<Pty>;

impl LineEndpoint<Pty> {
    /// Create the pty pair and, if `link` is given, a symlink there to the slave
    /// (replacing a stale symlink; refusing to replace anything else).
    pub fn open(link: Option<&Path>) -> Result<Self, NmeaError> {
        let pty = Pty::open(link)?;
        let device = pty.slave_path().to_owned();
        let path = pty.path().to_owned();
        Ok(LineEndpoint::new(pty, device, path))
    }

    /// The slave device (/dev/pts/N).
    pub fn slave_path(&self) -> &Path {
        self.device()
    }
}

/// A pseudo-terminal pair with a raw slave and a non-blocking master; reading and
/// writing go to the master. Dropping it removes its symlink.
#[derive(Debug)]
pub struct Pty {
    master: File,
    _slave: OwnedFd,
    slave_path: PathBuf,
    link: Option<PathBuf>,
}

impl Pty {
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
}

impl Read for Pty {
    /// Read from the master (non-blocking: nothing there gives `WouldBlock`).
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.master.read(buf)
    }
}

impl Write for Pty {
    /// Write to the master (non-blocking: a full pty gives `WouldBlock`).
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.master.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.master.flush()
    }
}

impl Drop for Pty {
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
