//! The simulator killed mid-run (SIGKILL) in HIL (issue 31, item 2): the controller it
//! started must not outlive it. It inherits none of the simulator's descriptors (the
//! GPS pty's master among them), gets SIGTERM from the kernel when the simulator dies
//! (the parent-death signal) and ends; the bus is quiet afterwards. A run that finds
//! another controller's heartbeats on its bus refuses to start and says so. Needs
//! vcan (fails loudly without it).

use std::process::{Child, Command};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use firmware_bridge::CanPort;
use golf_car_can::{ControllerHeartbeat, ControllerHeartbeatState};
use ugv_e2e_tests::{TestVcan, child_named, process_ended, samples_written, workspace_bin};

/// The longest a controller may live on after its simulator was killed: the kernel's
/// signal, the loop's estop heartbeats (0.1 s) and its exit, with room for an
/// emulated VM's stalls.
const EXIT_BOUND: Duration = Duration::from_secs(3);

/// `ugv-sim run` in HIL with the controller it starts, output to files in `dir`.
fn start_run(vcan: &TestVcan, dir: &std::path::Path, tag: &str) -> Result<Child> {
    Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--can", &vcan.name, "--status-every", "5"])
        .arg("--run-id")
        .arg(format!("{tag}-{}", std::process::id()))
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(dir.join("results"))
        .arg("--gps-link")
        .arg(dir.join("gps"))
        .stdout(std::fs::File::create(dir.join("stdout"))?)
        .stderr(std::fs::File::create(dir.join("stderr"))?)
        .spawn()
        .context("starting ugv-sim")
}

/// The controller `sim` started, once it has driven `ticks` control ticks.
fn controller_driving(sim: &mut Child, dir: &std::path::Path, ticks: usize) -> Result<i32> {
    let trace = dir.join("results/controller-trace.jsonl");
    let started = Instant::now();
    let mut controller = None;
    loop {
        if controller.is_none() {
            controller = child_named(sim.id(), "ugv-controller");
        }
        if let Some(pid) = controller
            && samples_written(&trace) >= ticks
        {
            return Ok(pid);
        }
        if let Some(status) = sim.try_wait()? {
            bail!(
                "ugv-sim ended ({status}) before the controller drove:\n{}",
                std::fs::read_to_string(dir.join("stderr")).unwrap_or_default()
            );
        }
        ensure!(
            started.elapsed() < Duration::from_secs(90),
            "the controller did not drive {ticks} ticks within 90 s"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Frames heard on `iface` over `span`.
fn frames_heard(iface: &str, span: Duration) -> Result<Vec<String>> {
    let mut port = CanPort::open(iface)?;
    let deadline = Instant::now() + span;
    let mut heard = Vec::new();
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        if let Some(r) = port.recv(left)? {
            heard.push(format!("{r:?}"));
        }
    }
    Ok(heard)
}

#[test]
fn killing_the_simulator_ends_its_controller_and_leaves_the_bus_quiet() -> Result<()> {
    let vcan = TestVcan::new("simkil")?;
    let dir = tempfile::tempdir()?;
    let mut sim = start_run(&vcan, dir.path(), "simkill")?;
    let controller = controller_driving(&mut sim, dir.path(), 300)?;
    sim.kill().context("SIGKILL to ugv-sim")?;
    let killed = Instant::now();
    sim.wait()?;
    while !process_ended(controller) {
        ensure!(
            killed.elapsed() <= EXIT_BOUND,
            "the controller (pid {controller}) still runs {:?} after its simulator was killed",
            killed.elapsed()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let lived = killed.elapsed();
    eprintln!("the controller ended {lived:?} after its simulator was killed");
    // Nothing is left to talk: no controller, and the simulated ECUs died with the
    // simulator.
    let heard = frames_heard(&vcan.name, Duration::from_millis(500))?;
    ensure!(
        heard.is_empty(),
        "{} frames on {} after the run ended, first {:?}",
        heard.len(),
        vcan.name,
        heard.first()
    );
    let stderr = std::fs::read_to_string(dir.path().join("stderr"))?;
    // Through its loop's end (SIGTERM, or its GPS port closing): estop, then exit.
    ensure!(
        stderr.contains("ugv-controller: Stopped") || stderr.contains("ugv-controller: PortLost"),
        "the controller did not stop through its loop:\n{stderr}"
    );
    Ok(())
}

#[test]
fn a_run_refuses_a_bus_where_another_controller_sends_heartbeats() -> Result<()> {
    let vcan = TestVcan::new("taken")?;
    let dir = tempfile::tempdir()?;
    // Another controller, as an orphan of an earlier run would be: its heartbeats
    // every 20 ms while the run starts.
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stop = std::sync::Arc::clone(&done);
    let mut port = CanPort::open(&vcan.name)?;
    let other = std::thread::spawn(move || -> Result<()> {
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            port.send(&ControllerHeartbeat {
                state: ControllerHeartbeatState::Auto,
            })?;
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    });
    let status = start_run(&vcan, dir.path(), "taken")?.wait()?;
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    other
        .join()
        .map_err(|_| anyhow::anyhow!("the sender panicked"))??;
    let stderr = std::fs::read_to_string(dir.path().join("stderr"))?;
    ensure!(
        status.code() == Some(4),
        "ugv-sim exit {status:?}:\n{stderr}"
    );
    ensure!(
        stderr.contains("another controller is on the bus") && stderr.contains("state auto"),
        "{stderr}"
    );
    ensure!(
        !dir.path().join("results/controller-trace.jsonl").exists(),
        "a controller was started:\n{stderr}"
    );
    // Nothing was started: the heartbeats stopped, the bus is quiet.
    ensure!(frames_heard(&vcan.name, Duration::from_millis(200))?.is_empty());
    Ok(())
}
