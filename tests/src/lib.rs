//! Helpers shared by the end-to-end tests.

use std::path::PathBuf;
use std::process::{Command, Output};

pub mod foreign;

/// A vcan interface of the test's own, deleted on drop, so tests run in parallel.
///
/// Creating it fails loudly (with the reason and what to do) when this kernel has no
/// vcan or the process lacks CAP_NET_ADMIN: the README's test command runs these
/// tests on a host with vcan or inside `vcan-setup vm`.
#[derive(Debug)]
pub struct TestVcan {
    pub name: String,
}

impl TestVcan {
    /// `tag` (up to 6 characters) names the test; the process ID makes it unique.
    pub fn new(tag: &str) -> anyhow::Result<TestVcan> {
        let name = format!(
            "vt{}{}",
            &tag[..tag.len().min(6)],
            std::process::id() % 100_000
        );
        vcan_setup::up(&name).map_err(|e| {
            anyhow::anyhow!("this test needs a vcan interface and could not create {name}: {e}")
        })?;
        Ok(TestVcan { name })
    }
}

impl Drop for TestVcan {
    fn drop(&mut self) {
        let _ = vcan_setup::down(&self.name);
    }
}

/// Frames the kernel's per-CPU input backlog has dropped since boot, all CPUs
/// (`/proc/net/softnet_stat`, second column, hex): where a frame that vcan loops back
/// to local sockets is lost for every one of them when the softirqs that empty the
/// backlog fall behind. `None` when the file cannot be read.
pub fn softnet_drops() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/net/softnet_stat").ok()?;
    text.lines()
        .map(|l| u64::from_str_radix(l.split_whitespace().nth(1)?, 16).ok())
        .sum()
}

/// Run a can-utils tool and return its output, naming the package when it is missing.
pub fn can_utils(tool: &str, args: &[&str]) -> anyhow::Result<Output> {
    Command::new(tool).args(args).output().map_err(|e| {
        anyhow::anyhow!(
            "running {tool} (Debian package can-utils, see scripts/install-deps.sh): {e}"
        )
    })
}

/// A binary of the workspace: from `UGV_BIN_DIR` when set (the test command points
/// it at the release build for the real-time runs), else the one built by
/// `cargo build --workspace` beside this test (target/<profile>/NAME).
pub fn workspace_bin(name: &str) -> anyhow::Result<PathBuf> {
    let dir = match std::env::var_os("UGV_BIN_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => {
            // target/<profile>/deps/<test>-<hash>
            let exe = std::env::current_exe()?;
            exe.parent()
                .and_then(|deps| deps.parent())
                .map(std::path::Path::to_path_buf)
                .ok_or_else(|| {
                    anyhow::anyhow!("cannot locate the target directory from {}", exe.display())
                })?
        }
    };
    let bin = dir.join(name);
    anyhow::ensure!(
        bin.is_file(),
        "{} is missing: build the workspace first (cargo build --workspace, --release for UGV_BIN_DIR=target/release)",
        bin.display()
    );
    Ok(bin)
}

/// The pid of `parent`'s child process named `name` (from /proc).
pub fn child_named(parent: u32, name: &str) -> Option<i32> {
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<i32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        // pid (comm) state ppid ...
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let comm = &stat[open + 1..close];
        let ppid = stat[close + 1..].split_whitespace().nth(1);
        if name.starts_with(comm) && ppid == Some(&parent.to_string()) {
            return Some(pid);
        }
    }
    None
}

/// Whether process `pid` has ended (gone from /proc, or a zombie nobody reaped yet).
pub fn process_ended(pid: i32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        Ok(stat) => stat
            .rfind(')')
            .and_then(|close| stat[close + 1..].split_whitespace().next())
            .is_none_or(|state| state == "Z" || state == "X"),
    }
}

/// Control ticks a controller has driven, from the trace it writes as it goes.
pub fn samples_written(trace: &std::path::Path) -> usize {
    std::fs::read_to_string(trace)
        .map(|t| t.lines().filter(|l| l.starts_with("{\"sample\"")).count())
        .unwrap_or(0)
}

/// A software null-modem cable: two pseudo-terminals whose masters are joined, so a
/// program that opens `a` (say, the simulator writing its NMEA to a "physical" serial
/// device) talks to one that opens `b` (the controller), both through real tty
/// devices, as over a USB-serial adapter and its cable. The relay stops on drop.
#[derive(Debug)]
pub struct NullModem {
    pub a: PathBuf,
    pub b: PathBuf,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    relay: Option<std::thread::JoinHandle<()>>,
}

impl NullModem {
    pub fn new() -> anyhow::Result<NullModem> {
        use nix::fcntl::{FcntlArg, OFlag, fcntl};
        use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
        use std::io::{ErrorKind, Read, Write};
        use std::sync::atomic::Ordering;

        let end = || -> anyhow::Result<(std::fs::File, std::os::fd::OwnedFd, PathBuf)> {
            let pty = nix::pty::openpty(None, None)?;
            let mut t = tcgetattr(&pty.slave)?;
            cfmakeraw(&mut t);
            tcsetattr(&pty.slave, SetArg::TCSANOW, &t)?;
            let flags = OFlag::from_bits_truncate(fcntl(&pty.master, FcntlArg::F_GETFL)?);
            fcntl(&pty.master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
            let path = nix::unistd::ttyname(&pty.slave)?;
            Ok((std::fs::File::from(pty.master), pty.slave, path))
        };
        let (ma, slave_a, a) = end()?;
        let (mb, slave_b, b) = end()?;
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = std::sync::Arc::clone(&stop);
        let relay = std::thread::spawn(move || {
            // The slaves stay open here so neither side sees a hang-up between opens.
            let _slaves = (slave_a, slave_b);
            let mut buf = [0u8; 4096];
            // Bytes read from one master and not yet taken by the other.
            let mut pending: [Vec<u8>; 2] = [Vec::new(), Vec::new()];
            while !flag.load(Ordering::Relaxed) {
                let mut moved = false;
                for (mut from, mut to, queue) in [(&ma, &mb, 0usize), (&mb, &ma, 1usize)] {
                    if let Ok(n) = from.read(&mut buf) {
                        pending[queue].extend_from_slice(&buf[..n]);
                        moved |= n > 0;
                    }
                    if !pending[queue].is_empty() {
                        match to.write(&pending[queue]) {
                            Ok(n) => {
                                pending[queue].drain(..n);
                                moved |= n > 0;
                            }
                            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                            // The far end is gone: what was in flight is lost, as on a cable.
                            Err(_) => pending[queue].clear(),
                        }
                    }
                }
                if !moved {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
            }
        });
        Ok(NullModem {
            a,
            b,
            stop,
            relay: Some(relay),
        })
    }
}

impl Drop for NullModem {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(relay) = self.relay.take() {
            let _ = relay.join();
        }
    }
}

/// The Python `mcap` package's summary of an MCAP file (tests/record_common/
/// mcap_summary.py: per topic its schema, encodings, message count, first and last log
/// time; whether the file was complete), read independently of ugv-sim. `PYTHON`
/// chooses the interpreter.
pub fn mcap_summary(path: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    python_on_mcap("mcap_summary.py", path)
}

/// What Foxglove's 3D and map panels would find in an MCAP file, read with the Python
/// `mcap` package and the protobuf schemas in the file (tests/record_common/
/// foxglove_panels.py: per topic its schema and encodings, every transform parent ->
/// child with its first and last translation, the frames of the messages and those
/// with no chain of transforms to `world`, the fixes' ranges). `PYTHON` chooses the
/// interpreter.
pub fn foxglove_panels(path: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    python_on_mcap("foxglove_panels.py", path)
}

/// tests/record_common/`script` run on `path`: the JSON it prints.
fn python_on_mcap(script: &str, path: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/record_common")
        .join(script);
    let out = Command::new(&python)
        .arg(&script)
        .arg(path)
        .output()
        .map_err(|e| anyhow::anyhow!("running {python} (set PYTHON to choose another): {e}"))?;
    anyhow::ensure!(
        out.status.success(),
        "{} (needs the Python packages of scripts/install-deps.sh: mcap, mcap-protobuf-support): {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(serde_json::from_slice(&out.stdout)?)
}

/// `ugv-sim replay` of the recording a finished HIL run left in `results` (run.mcap and
/// verdict.json), checked as far as an open-loop replay of a HIL run can be: it reads
/// the whole file, starts at the recorded controller's first frame, `start_s` seconds
/// of simulated time (a controller the simulator starts comes after the simulator
/// began recording; one on its own board before, as the simulator waits for its
/// heartbeat), replays to the run's end, and replays and finds recorded more than 100
/// of each of the controller's messages. Its agreement within the HIL tolerance is
/// printed, not judged: a HIL recording made in the emulated VM replays within it only
/// some of the time (README, "Replay"; the tolerance itself is tested on SIL
/// recordings). Returns the replay's report.
pub fn replay_hil_recording(
    results: &std::path::Path,
    start_s: std::ops::Range<f64>,
) -> anyhow::Result<serde_json::Value> {
    use anyhow::{Context, ensure};
    let replay = Command::new(workspace_bin("ugv-sim")?)
        .arg("replay")
        .arg(results.join(ugv_sim::record::MCAP_FILE))
        .output()?;
    let text = String::from_utf8_lossy(&replay.stdout);
    eprintln!(
        "{}\n{text}",
        String::from_utf8_lossy(&replay.stderr).trim_end()
    );
    ensure!(
        matches!(replay.status.code(), Some(0 | 1)),
        "the replay failed: {:?}",
        replay.status
    );
    let report: serde_json::Value = serde_json::from_str(&text)?;
    let verdict: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(results.join("verdict.json"))?)?;
    let start = report["controller_start_s"]
        .as_f64()
        .context("controller_start_s")?;
    let replayed = report["replayed_s"].as_f64().context("replayed_s")?;
    let time = verdict["time"].as_f64().context("verdict time")?;
    ensure!(
        start_s.contains(&start),
        "controller start {start} s, expected in {start_s:?}"
    );
    ensure!(
        start + replayed > time - 0.5,
        "replayed {start} + {replayed} s of a {time} s run"
    );
    for message in ["STEERING_CMD", "THROTTLE_CMD", "CONTROLLER_HEARTBEAT"] {
        let m = &report["messages"][message];
        ensure!(
            m["recorded"].as_u64() > Some(100) && m["replayed"].as_u64() > Some(100),
            "{message}: {m}"
        );
    }
    Ok(report)
}

/// A HIL `verdict` that passed its criteria: the goal reached, no collision.
pub fn a_hil_run_that_passed(verdict: &serde_json::Value) -> anyhow::Result<()> {
    use anyhow::ensure;
    ensure!(
        verdict["passed"] == true,
        "failures: {}",
        verdict["failures"]
    );
    ensure!(verdict["goal_reached"] == true && verdict["collision"] == false);
    ensure!(verdict["mode"] == "hil");
    Ok(())
}

/// Every frame on the bus passed the ECUs' E2E checks, both ways, by a HIL `verdict`'s
/// counts, with more than `min_accepted` accepted by each ECU.
pub fn every_frame_passed_the_e2e_checks(
    verdict: &serde_json::Value,
    min_accepted: u64,
) -> anyhow::Result<()> {
    use anyhow::{Context, ensure};
    for node in ["steering_can", "throttle_can"] {
        let e2e = &verdict[node]["e2e"];
        let accepted = e2e["accepted"].as_u64().context("accepted")?;
        ensure!(accepted > min_accepted, "{node}: only {accepted} frames");
        for key in [
            "bad_crc",
            "repeated_counter",
            "skipped_counter",
            "wrong_dlc",
            "unknown_id",
            "second_sender",
        ] {
            ensure!(e2e[key] == 0, "{node}: {key} = {}", e2e[key]);
        }
    }
    Ok(())
}
