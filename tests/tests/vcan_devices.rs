//! Device swapping, one device at a time: the paper's scenario in HIL with the real
//! controller binary, and each time one device physical instead of simulated — a
//! second vcan interface stands in for the physical bus, with a standalone ECU
//! (`ugv-sim ecu`) on it as the physical ECU; a null-modem pair of ptys stands in for
//! the USB-serial cable to the controller's board; the simulator's own CoLa-A server
//! stands in for the SICK on Ethernet. Every run must still reach the goal.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release binaries.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use golf_car_can::candump::parse_line;
use serde_json::Value;
use ugv_e2e_tests::{NullModem, TestVcan, mcap_summary, replay_hil_recording, workspace_bin};
use ugv_sim::hil::gateway_log;
use ugv_sim::record::{MCAP_FILE, topics};

/// A child process killed on drop (a standalone ECU, a controller on its "board").
struct Background(Child);

impl Drop for Background {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The run's directory, bench file and identity.
struct Bench {
    dir: tempfile::TempDir,
    run_id: String,
}

impl Bench {
    fn new(tag: &str, devices: &str) -> Result<Bench> {
        let dir = tempfile::tempdir()?;
        std::fs::write(
            dir.path().join("bench.toml"),
            format!("[devices]\n{devices}"),
        )?;
        Ok(Bench {
            dir,
            run_id: format!("dev-{tag}-{}", std::process::id()),
        })
    }

    fn results(&self) -> PathBuf {
        self.dir.path().join("results")
    }

    /// `ugv-sim run` of the paper's scenario on `sim_can` with this bench file,
    /// recorded when `record` says. The runs with a standalone ECU are not: in the
    /// emulated VM, the recorder's work on the tick thread beside a gateway, a
    /// standalone ECU and the controller on two vCPUs delayed laser scans past the
    /// controller's 250 ms laser watchdog at start-up.
    fn sim(&self, sim_can: &str, start_controller: bool, record: bool) -> Result<Command> {
        let mut cmd = Command::new(workspace_bin("ugv-sim")?);
        cmd.args(["run", "--can", sim_can, "--run-id", &self.run_id])
            .args(["--status-every", "5"]);
        if !record {
            cmd.arg("--no-record");
        }
        cmd.arg("--devices")
            .arg(self.dir.path().join("bench.toml"))
            .arg("--results")
            .arg(self.results())
            .arg("--gps-link")
            .arg(self.dir.path().join("gps"));
        if start_controller {
            cmd.arg("--controller")
                .arg(workspace_bin("ugv-controller")?);
        }
        Ok(cmd)
    }
}

/// A simulated ECU alone on `can`, as the physical one.
fn standalone_ecu(kind: &str, can: &str) -> Result<Background> {
    let child = Command::new(workspace_bin("ugv-sim")?)
        .args(["ecu", kind, "--can", can, "--status-every", "5"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .context("starting ugv-sim ecu")?;
    Ok(Background(child))
}

/// Run to the end and check the verdict: goal reached, no collision, every frame the
/// simulator's ECUs received passed E2E.
fn passes(mut cmd: Command) -> Result<Value> {
    let before = ugv_e2e_tests::softnet_drops();
    let out = cmd.output().context("running ugv-sim")?;
    let after = ugv_e2e_tests::softnet_drops();
    passed(out).with_context(|| {
        format!(
            "frames the kernel's input backlog dropped during the run: {:?}",
            after.zip(before).map(|(a, b)| a.saturating_sub(b))
        )
    })
}

/// The verdict of a finished `ugv-sim run`, checked as in [`passes`].
fn passed(out: std::process::Output) -> Result<Value> {
    let stderr = String::from_utf8_lossy(&out.stderr);
    let verdict: Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    ensure!(
        out.status.code() == Some(0) && verdict["passed"] == true,
        "ugv-sim exit {:?}, failures {}; verdict:\n{}\nstderr:\n{stderr}",
        out.status,
        verdict["failures"],
        serde_json::to_string_pretty(&verdict)?
    );
    ensure!(verdict["goal_reached"] == true && verdict["collision"] == false);
    for node in ["steering_can", "throttle_can"] {
        ensure!(
            verdict[node]["e2e"]["bad_crc"] == 0 && verdict[node]["e2e"]["skipped_counter"] == 0,
            "{node}: {} (frames the kernel dropped from its queue: {}; the first rejected: {}); \
             the gateways' losses: {}",
            verdict[node]["e2e"],
            verdict[node]["queue_drops"],
            verdict[node]["first_rejections"],
            gateway_losses(&verdict)
        );
    }
    Ok(verdict)
}

/// Where a gateway of the run can lose frames, per direction: its receive queue's
/// overflow, its receive errors and the frames it gave up sending.
fn gateway_losses(verdict: &Value) -> String {
    let mut out = Vec::new();
    for g in verdict["wires"]["gateways"]
        .as_array()
        .into_iter()
        .flatten()
    {
        for dir in ["to_physical", "to_sim"] {
            let d = &g[dir];
            out.push(format!(
                "{} -> {}: received {}, forwarded {}, rx_overflow {}, rx_errors {}, tx_dropped {}, tx_retries {}",
                d["from"], d["to"], d["received"], d["forwarded"], d["rx_overflow"],
                d["rx_errors"], d["tx_dropped"], d["tx_retries"]
            ));
        }
    }
    if out.is_empty() {
        "no gateway".into()
    } else {
        out.join("; ")
    }
}

/// The one gateway's forwarded count of message `name` in direction `dir`
/// ("to_physical" or "to_sim").
fn forwarded(verdict: &Value, dir: &str) -> u64 {
    verdict["wires"]["gateways"][0][dir]["forwarded"]
        .as_u64()
        .unwrap_or(0)
}

fn physical_ecu_run(kind: &str, node: &str) -> Result<()> {
    let sim_can = TestVcan::new(&format!("s{kind}"))?;
    let phys_can = TestVcan::new(&format!("p{kind}"))?;
    let _ecu = standalone_ecu(kind, &phys_can.name)?;
    let bench = Bench::new(
        kind,
        &format!(
            "{kind} = {{ mode = \"physical\", can = \"{}\" }}\n",
            phys_can.name
        ),
    )?;
    let verdict = passes(bench.sim(&sim_can.name, true, false)?)?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict["wires"])?);
    let station = &verdict[node];
    // The vehicle moved by the physical ECU's reports; its simulated twin said nothing.
    ensure!(
        station["physical_reports"].as_u64().unwrap_or(0) > 1000,
        "{node}: {station}"
    );
    ensure!(station["sent"] == 0, "the simulated twin sent: {station}");
    ensure!(
        forwarded(&verdict, "to_physical") > 1000 && forwarded(&verdict, "to_sim") > 1000,
        "gateway: {}",
        verdict["wires"]
    );
    Ok(())
}

#[test]
fn a_physical_steering_ecu_on_another_bus_drives_the_paper_scenario_to_its_goal() -> Result<()> {
    physical_ecu_run("steering", "steering_can")
}

#[test]
fn a_physical_throttle_ecu_on_another_bus_drives_the_paper_scenario_to_its_goal() -> Result<()> {
    physical_ecu_run("throttle", "throttle_can")
}

#[test]
fn the_gps_on_a_serial_device_feeds_the_controller() -> Result<()> {
    let sim_can = TestVcan::new("sgps")?;
    let cable = NullModem::new()?;
    let bench = Bench::new(
        "gps",
        &format!(
            "gps = {{ mode = \"serial\", device = \"{}\", peer = \"{}\", baud = 115200 }}\n",
            cable.a.display(),
            cable.b.display()
        ),
    )?;
    // The controller opens the far end of the cable (the peer), not a pty.
    let verdict = passes(bench.sim(&sim_can.name, true, false)?)?;
    let wires: Value = serde_json::from_str(&std::fs::read_to_string(
        bench.results().join("wires.json"),
    )?)?;
    ensure!(
        wires["gps_line"] == "serial" && wires["gps_link"] == cable.b.display().to_string(),
        "{wires}"
    );
    let latency = &verdict["fix_latency"]["fix_to_command"];
    ensure!(latency["samples"].as_u64().unwrap_or(0) > 50, "{latency}");
    Ok(())
}

#[test]
fn the_simulated_laser_served_over_cola_reaches_the_controller_through_the_driver() -> Result<()> {
    let sim_can = TestVcan::new("slas")?;
    let bench = Bench::new(
        "laser",
        "laser = { mode = \"cola\", listen = \"127.0.0.1:0\" }\n",
    )?;
    let verdict = passes(bench.sim(&sim_can.name, true, false)?)?;
    let driver = &verdict["wires"]["laser_driver"];
    ensure!(driver["frames"].as_u64().unwrap_or(0) > 100, "{driver}");
    // The controller saw the post through the CoLa-A path.
    ensure!(
        verdict["controller"]["replans"].as_u64().unwrap_or(0) > 10,
        "{}",
        verdict["controller"]
    );
    Ok(())
}

/// Wait for `path` to exist (the simulator writes the controller's configuration).
fn wait_for_file(path: &Path, timeout: Duration) -> Result<()> {
    let deadline = Instant::now() + timeout;
    while !path.is_file() {
        ensure!(
            Instant::now() < deadline,
            "{} did not appear",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}

#[test]
fn the_controller_on_its_own_board_reaches_the_goal_through_the_gateway() -> Result<()> {
    let sim_can = TestVcan::new("sbrd")?;
    let board_can = TestVcan::new("pbrd")?;
    let cable = NullModem::new()?;
    let bench = Bench::new(
        "board",
        &format!(
            "controller = {{ mode = \"board\", can = \"{}\" }}\ngps = {{ mode = \"serial\", device = \"{}\" }}\n",
            board_can.name,
            cable.a.display()
        ),
    )?;
    let sim = bench
        .sim(&sim_can.name, false, true)?
        .spawn_output_thread()?;
    // The "board": the controller binary on the physical bus, its GPS on the cable's
    // far end, given the configuration the simulator wrote for it.
    let config = bench.results().join("controller.toml");
    wait_for_file(&config, Duration::from_secs(120))?;
    let wires: Value = serde_json::from_str(&std::fs::read_to_string(
        bench.results().join("wires.json"),
    )?)?;
    let baud = wires["gps_baud"].as_u64().context("gps_baud")?.to_string();
    let laser = wires["laser_service"].as_str().context("laser_service")?;
    // Its log (each change of mode, with the reason of a stop) goes to a file, shown
    // when the run fails.
    let board_log = bench.dir.path().join("board.log");
    let _board = Background(
        Command::new(workspace_bin("ugv-controller")?)
            .arg("run")
            .arg("--config")
            .arg(&config)
            .arg("--gps")
            .arg(&cable.b)
            .args(["--baud", &baud, "--laser", laser])
            .args(["--can", &board_can.name, "--status-every", "0"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&board_log)?)
            .spawn()
            .context("starting the controller on its board")?,
    );
    let out = sim
        .join()
        .map_err(|_| anyhow::anyhow!("ugv-sim thread"))??;
    let verdict = passed(out).with_context(|| {
        format!(
            "the board controller's log:\n{}",
            std::fs::read_to_string(&board_log).unwrap_or_else(|e| e.to_string())
        )
    })?;
    ensure!(
        forwarded(&verdict, "to_sim") > 1000 && forwarded(&verdict, "to_physical") > 1000,
        "gateway: {}",
        verdict["wires"]
    );
    // The recording of a bench run with physical devices: the NMEA that went out on
    // the serial line, the frames on the simulator's bus, and the gateway's log of the
    // board's bus, which replays like any HIL recording.
    let results = bench.results();
    let summary = mcap_summary(&results.join(MCAP_FILE))?;
    ensure!(summary["complete"] == true, "{summary}");
    ensure!(
        summary["topics"][topics::NMEA]["count"].as_u64() > Some(100),
        "{summary}"
    );
    let log = std::fs::read_to_string(results.join(gateway_log(&board_can.name)))?;
    let mut sides = [0u64; 2];
    for line in log.lines() {
        let frame = parse_line(line).with_context(|| format!("gateway log line {line:?}"))?;
        let iface = frame.interface.as_deref();
        sides[usize::from(iface == Some(board_can.name.as_str()))] += 1;
    }
    // Each forwarded frame is logged on both buses, as received and as sent; the
    // verdict counted them while the board's controller still sent.
    let total = forwarded(&verdict, "to_sim") + forwarded(&verdict, "to_physical");
    ensure!(
        sides[0] == sides[1] && sides[0] >= total,
        "gateway log: {} lines on {}, {} on {}; {total} frames forwarded",
        sides[0],
        sim_can.name,
        sides[1],
        board_can.name
    );
    // The simulator started its clock once the board's heartbeat came (up to 60 s).
    replay_hil_recording(&results, -60.0..0.0)?;
    Ok(())
}

/// Run a command to completion on a thread, collecting its output.
trait SpawnOutput {
    fn spawn_output_thread(
        self,
    ) -> Result<std::thread::JoinHandle<std::io::Result<std::process::Output>>>;
}

impl SpawnOutput for Command {
    fn spawn_output_thread(
        mut self,
    ) -> Result<std::thread::JoinHandle<std::io::Result<std::process::Output>>> {
        Ok(std::thread::spawn(move || self.output()))
    }
}
