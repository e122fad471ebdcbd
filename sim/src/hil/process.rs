//! The controller's process in HIL: started here with the wire locations (the
//! controller contract), or waited for on the bus when the user starts it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_bridge::{CanPort, Received};
use golf_car_can::GolfCarMessage;

use ugv_controller::runtime::SIMULATOR_PID_ENV;

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

/// How long a run listens for another controller on its bus before it starts its
/// own: five heartbeat periods.
const BUS_LISTEN: Duration = Duration::from_millis(100);

/// Refuse to start a controller on `iface` while another controller's heartbeats are
/// on it (an orphan of an earlier run, a controller started by hand): two would fight
/// over the ECUs, and the ECUs would go to their safe state for a second sender. The
/// error says what was heard and which controller processes run on this machine.
pub fn ensure_no_controller(iface: &str) -> Result<(), HilError> {
    let can = |source| HilError::Can {
        iface: iface.to_owned(),
        source,
    };
    let mut port = CanPort::open(iface).map_err(can)?;
    let deadline = Instant::now() + BUS_LISTEN;
    let mut heard = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        if let Some(Received::Message(GolfCarMessage::ControllerHeartbeat(h))) =
            port.recv(left).map_err(can)?
        {
            heard.push(h.state);
        }
    }
    let Some(state) = heard.last() else {
        return Ok(());
    };
    let running = processes_named("ugv-controller");
    Err(HilError::BusTaken {
        iface: iface.to_owned(),
        heartbeats: heard.len(),
        listened_ms: BUS_LISTEN.as_millis(),
        state: format!("{state:?}").to_lowercase(),
        running: if running.is_empty() {
            "no ugv-controller process on this machine: another machine or a board sends them"
                .to_owned()
        } else {
            running.join("; ")
        },
    })
}

/// The processes whose name is `name`, as "pid N: command line".
fn processes_named(name: &str) -> Vec<String> {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let mut found: Vec<String> = dir
        .flatten()
        .filter_map(|entry| {
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let comm = std::fs::read_to_string(entry.path().join("comm")).ok()?;
            // comm holds at most 15 bytes of the name.
            if !name.starts_with(comm.trim_end()) || comm.trim_end().is_empty() {
                return None;
            }
            let cmdline = std::fs::read(entry.path().join("cmdline")).ok()?;
            let args: Vec<String> = cmdline
                .split(|b| *b == 0)
                .filter(|a| !a.is_empty())
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            Some(format!("pid {pid}: {}", args.join(" ")))
        })
        .collect();
    found.sort();
    found
}

/// A controller process started for the run.
#[derive(Debug)]
pub struct ControllerProcess {
    pub child: Child,
    pub trace: PathBuf,
}

/// Start `binary run --config CONFIG --gps LINK --baud BAUD --laser SERVICE --can IFACE
/// --trace TRACE [--record DIR] [--lockstep CLOCK] [extra...]` (the controller contract,
/// docs/wire-contract.md). `record` is left out when `extra` names a recording of its
/// own (`--record`, or its old name `--log`).
pub fn spawn_controller(
    binary: &Path,
    config: &Path,
    wires: &WireMap,
    trace: &Path,
    record: Option<&Path>,
    extra: &[String],
) -> Result<ControllerProcess, HilError> {
    let own_recording = extra.iter().any(|a| {
        ["--record", "--log"]
            .iter()
            .any(|flag| a == flag || a.starts_with(&format!("{flag}=")))
    });
    let record: Vec<&std::ffi::OsStr> = match record {
        Some(dir) if !own_recording => vec!["--record".as_ref(), dir.as_os_str()],
        _ => Vec::new(),
    };
    close_on_exec_all().map_err(|source| HilError::Spawn {
        binary: binary.display().to_string(),
        source,
    })?;
    let child = Command::new(binary)
        .env(SIMULATOR_PID_ENV, std::process::id().to_string())
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
        .args(record)
        .args(
            wires
                .clock_service
                .iter()
                .flat_map(|c| ["--lockstep", c.as_str()]),
        )
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

/// Marks every descriptor of this process beyond standard input, output and error
/// close-on-exec, so that a controller started next inherits none of the simulator's
/// wires: the GPS pty's master (holding it, the controller would never see its GPS
/// port close when the simulator dies), the CAN sockets, iceoryx2's files. Rust's own
/// files and sockets are close-on-exec already; those opened through C libraries and
/// crates that call `openpty`, `socket` or `open` directly are not. The wires are all
/// open before the controller starts, so none is opened between this and the fork.
#[allow(unsafe_code)] // fcntl on the descriptors /proc lists: nix needs a BorrowedFd, whose making from a number is unsafe too
fn close_on_exec_all() -> std::io::Result<()> {
    for entry in std::fs::read_dir("/proc/self/fd")? {
        let Some(fd) = entry?
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<i32>().ok())
        else {
            continue;
        };
        if fd <= 2 {
            continue;
        }
        // SAFETY: F_GETFD and F_SETFD read and set one descriptor's flags and touch no
        // memory; a descriptor closed since the listing (the listing's own) fails with
        // EBADF, which leaves nothing to do.
        let flags = unsafe { libc::fcntl(fd, libc::F_GETFD) };
        if flags >= 0 && flags & libc::FD_CLOEXEC == 0 {
            // SAFETY: as above.
            unsafe { libc::fcntl(fd, libc::F_SETFD, flags | libc::FD_CLOEXEC) };
        }
    }
    Ok(())
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

    /// CPU time the controller's process has used so far (user and system, all its
    /// threads), in clock ticks; None once it cannot be read (gone).
    pub fn cpu_ticks(&self) -> Option<u64> {
        cpu_ticks(self.child.id())
    }

    /// Send `signal` to the controller's process (gone already: nothing to do).
    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), signal);
        }
    }
}

/// CPU time of process `pid` so far, clock ticks (utime + stime of /proc/PID/stat).
fn cpu_ticks(pid: u32) -> Option<u64> {
    parse_cpu_ticks(&std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?)
}

/// utime + stime of a /proc/PID/stat line: its fields 14 and 15, counted from the
/// first after the command name's closing parenthesis (field 3; the name may hold
/// spaces and parentheses).
fn parse_cpu_ticks(stat: &str) -> Option<u64> {
    let mut fields = stat[stat.rfind(')')? + 1..].split_whitespace().skip(14 - 3);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

#[cfg(test)]
mod tests {
    use std::os::fd::AsRawFd;

    use super::*;

    /// The descriptors a child started now holds, as `ls` sees them in its shell's
    /// /proc entry.
    fn child_descriptors() -> Vec<i32> {
        let out = Command::new("sh")
            .args(["-c", "ls /proc/$$/fd"])
            .output()
            .expect("sh runs");
        String::from_utf8_lossy(&out.stdout)
            .split_whitespace()
            .filter_map(|n| n.parse().ok())
            .collect()
    }

    #[test]
    fn a_child_started_after_the_sweep_inherits_no_pty_of_the_simulator() {
        // openpty gives descriptors without close-on-exec, as the GPS device's are.
        let pty = nix::pty::openpty(None, None).expect("a pty");
        let (master, slave) = (pty.master.as_raw_fd(), pty.slave.as_raw_fd());
        let before = child_descriptors();
        assert!(
            before.contains(&master) && before.contains(&slave),
            "the child holds {before:?} (master {master}, slave {slave})"
        );
        close_on_exec_all().expect("the sweep");
        let after = child_descriptors();
        assert!(
            !after.contains(&master) && !after.contains(&slave),
            "the child still holds {after:?} (master {master}, slave {slave})"
        );
    }

    #[test]
    fn cpu_time_is_read_after_a_command_name_with_spaces_and_parentheses() {
        let stat = "4242 (ugv (ctl) x) R 1 4242 4242 0 -1 4194304 120 0 0 0 731 69 0 0 20 0 3 0";
        assert_eq!(parse_cpu_ticks(stat), Some(800));
        assert_eq!(parse_cpu_ticks("4242 (cut short) R 1 2"), None);
        assert_eq!(parse_cpu_ticks("no parenthesis"), None);
    }

    #[test]
    fn a_busy_process_uses_cpu_time_and_a_sleeping_one_does_not() {
        let mut busy = Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .spawn()
            .expect("sh runs");
        let mut idle = Command::new("sleep").arg("5").spawn().expect("sleep runs");
        let (b0, i0) = (cpu_ticks(busy.id()), cpu_ticks(idle.id()));
        std::thread::sleep(Duration::from_millis(500));
        let (b1, i1) = (cpu_ticks(busy.id()), cpu_ticks(idle.id()));
        for child in [&mut busy, &mut idle] {
            child.kill().expect("kill");
            child.wait().expect("wait");
        }
        assert!(b1 > b0, "{b0:?} -> {b1:?}");
        assert_eq!(i0, i1);
        assert!(i0.is_some());
        assert_eq!(cpu_ticks(busy.id()), None, "a reaped process has no stat");
    }
}
