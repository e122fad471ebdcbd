//! The controller's process in HIL: started here with the wire locations (the
//! controller contract), or waited for on the bus when the user starts it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::{CanPort, Received};
use golf_car_can::GolfCarMessage;

use super::HilError;
use super::wires::WireMap;

/// Block until a CONTROLLER_HEARTBEAT appears on `iface` (a controller started by
/// the user), at most `timeout`.
pub fn wait_for_controller(
    iface: &str,
    timeout: Duration,
    stop: &AtomicBool,
) -> Result<bool, HilError> {
    let mut port = CanPort::open(iface).map_err(|source| HilError::Wait {
        iface: iface.to_owned(),
        source,
    })?;
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline && !stop.load(Ordering::Relaxed) {
        if let Some(Received::Message(GolfCarMessage::ControllerHeartbeat(_))) = port
            .recv(Duration::from_millis(200))
            .map_err(|source| HilError::Wait {
                iface: iface.to_owned(),
                source,
            })?
        {
            return Ok(true);
        }
    }
    if stop.load(Ordering::Relaxed) {
        return Ok(false);
    }
    Err(HilError::NoController {
        iface: iface.to_owned(),
        seconds: timeout.as_secs(),
    })
}

/// A controller process started for the run.
#[derive(Debug)]
pub struct ControllerProcess {
    pub child: Child,
    pub trace: PathBuf,
}

/// Start `binary run --config CONFIG --gps LINK --baud BAUD --laser SERVICE --can IFACE
/// --trace TRACE [--log LOG] [extra...]` (the controller contract, README). `log` is
/// left out when `extra` names a `--log` of its own.
pub fn spawn_controller(
    binary: &Path,
    config: &Path,
    wires: &WireMap,
    trace: &Path,
    log: Option<&Path>,
    extra: &[String],
) -> Result<ControllerProcess, HilError> {
    let own_log = extra
        .iter()
        .any(|a| a == "--log" || a.starts_with("--log="));
    let log: Vec<&std::ffi::OsStr> = match log {
        Some(dir) if !own_log => vec!["--log".as_ref(), dir.as_os_str()],
        _ => Vec::new(),
    };
    let child = Command::new(binary)
        .arg("run")
        .arg("--config")
        .arg(config)
        .arg("--gps")
        .arg(&wires.gps_link)
        .args([
            "--baud",
            &wires.gps_baud.to_string(),
            "--laser",
            &wires.laser_service,
            "--can",
            &wires.can,
        ])
        .arg("--trace")
        .arg(trace)
        .args(log)
        .args(extra)
        .stdin(Stdio::null())
        .spawn()
        .map_err(|source| HilError::Spawn {
            binary: binary.display().to_string(),
            source,
        })?;
    Ok(ControllerProcess {
        child,
        trace: trace.to_path_buf(),
    })
}

impl ControllerProcess {
    /// Ask the controller to finish (SIGINT: it leaves the car safe and writes its
    /// trace), then kill it if it has not gone within `grace`.
    pub fn finish(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        if let Ok(Some(status)) = self.child.try_wait() {
            return Some(status);
        }
        // A process the fault plan stopped must run again to act on SIGINT.
        self.signal(nix::sys::signal::Signal::SIGCONT);
        self.signal(nix::sys::signal::Signal::SIGINT);
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        self.child.wait().ok()
    }

    /// Send `signal` to the controller's process (gone already: nothing to do).
    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), signal);
        }
    }
}
