//! Serial devices: opening one (the controller's GPS input, or a pty slave), and the
//! simulated receiver's line on a physical serial device.

use std::path::Path;
use std::time::Duration;

use serialport::{ClearBuffer, SerialPort};

use super::NmeaError;
use super::line::LineEndpoint;

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

/// The simulated receiver's line on a physical serial device (a USB-serial adapter
/// wired to the controller's board): a [`LineEndpoint`] on the device opened through
/// serialport at the baud rate, 8N1, and used without blocking, like
/// [`super::PtyEndpoint`]: what the UART buffer does not take is dropped and counted.
pub type SerialEndpoint = LineEndpoint<Box<dyn SerialPort>>;

impl LineEndpoint<Box<dyn SerialPort>> {
    /// Open `path` at `baud`.
    pub fn open(path: &Path, baud: u32) -> Result<Self, NmeaError> {
        let port = open_serial(path, baud, Duration::ZERO)?;
        Ok(LineEndpoint::new(port, path.to_owned(), path.to_owned()))
    }
}
