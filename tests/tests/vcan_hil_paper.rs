//! The main job as a test: the paper's scenario end to end in HIL — `ugv-sim` and the
//! real `ugv-controller` binary as separate processes on a pty (NMEA), iceoryx2 (laser
//! frames) and a real vcan interface (golf_car.dbc) — reaches the goal without
//! collision.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release binaries.

use std::process::Command;

use anyhow::{Context, Result, ensure};
use ugv_e2e_tests::{
    TestVcan, a_hil_run_that_passed, every_frame_passed_the_e2e_checks, workspace_bin,
};

#[test]
fn the_paper_scenario_reaches_its_goal_in_hil_with_the_real_controller_binary() -> Result<()> {
    let vcan = TestVcan::new("hil")?;
    let dir = tempfile::tempdir()?;
    let results = dir.path().join("results");
    let run_id = format!("test-{}", std::process::id());
    // can-utils' own bus-load meter on the same interface, for the verdict's figure
    // (line-buffered into a file: one line a second).
    let load_log = dir.path().join("canbusload.log");
    let mut canbusload = Command::new("stdbuf")
        .args(["-oL", "canbusload"])
        .arg(format!("{}@500000", vcan.name))
        .stdout(std::fs::File::create(&load_log)?)
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting canbusload (can-utils, scripts/install-deps.sh)")?;
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args([
            "run",
            "--can",
            &vcan.name,
            "--run-id",
            &run_id,
            "--status-every",
            "5",
        ])
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(&results)
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        .output()
        .context("running ugv-sim")?;
    // The last second's line is out once a second has passed.
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let _ = canbusload.kill();
    let _ = canbusload.wait();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let verdict: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict)?);
    ensure!(
        out.status.code() == Some(0),
        "ugv-sim exit {:?}; stderr:\n{stderr}",
        out.status
    );
    a_hil_run_that_passed(&verdict)?;
    // iceoryx2's start-up warning (no configuration file) is silenced in ugv-sim and in
    // the controller (whose stderr is ugv-sim's).
    ensure!(
        !stderr.contains("No config file was loaded"),
        "iceoryx2's warning on stderr:\n{stderr}"
    );
    let clearance = verdict["min_clearance"][0].as_f64().context("clearance")?;
    ensure!(clearance > 0.5, "min clearance {clearance}");
    every_frame_passed_the_e2e_checks(&verdict, 1000)?;
    // The controller's own account: it drove in auto, tracked its plans, and replanned.
    let controller = &verdict["controller"];
    ensure!(
        controller["replans"].as_u64().unwrap_or(0) > 10,
        "{controller}"
    );
    ensure!(
        controller["tracking_error_rms"]
            .as_f64()
            .unwrap_or(f64::MAX)
            < 0.3,
        "{controller}"
    );
    // The loop's latency was measured: every fix the controller read was answered by a
    // steering command, after the moment the simulator made it.
    let latency = &verdict["fix_latency"];
    let samples = latency["fix_to_command"]["samples"].as_u64().unwrap_or(0);
    ensure!(samples > 100, "{latency}");
    let p50 = latency["fix_to_command"]["p50_ms"].as_f64().unwrap_or(-1.0);
    let read = latency["fix_to_read"]["p50_ms"].as_f64().unwrap_or(-1.0);
    ensure!(p50 > 0.0 && read > 0.0 && p50 >= read, "{latency}");
    the_bus_load_agrees_with_canbusload(&verdict, &load_log, &vcan.name)?;
    for file in [
        "verdict.json",
        "trace.json",
        "figure.svg",
        "figure.png",
        "controller.toml",
        "wires.json",
    ] {
        ensure!(results.join(file).is_file(), "{file} missing");
    }
    Ok(())
}

/// The `verdict`'s bus load against canbusload's on `iface` (its log `load_log`; both
/// worst-case bit stuffing): the same bits per frame, and the frames canbusload counted
/// in the seconds it saw traffic are those of the run (it also sees the frames before
/// and after, and its seconds do not start with the run's).
fn the_bus_load_agrees_with_canbusload(
    verdict: &serde_json::Value,
    load_log: &std::path::Path,
    iface: &str,
) -> Result<()> {
    let load = &verdict["bus_load"];
    let frames = load["frames"].as_u64().context("bus_load.frames")?;
    let bits = load["bits"].as_u64().context("bus_load.bits")?;
    ensure!(bits == frames * 135, "{load}");
    let log = std::fs::read_to_string(load_log)?;
    let (mut their_frames, mut their_bits) = (0u64, 0u64);
    for line in log
        .lines()
        .filter(|l| l.contains(&format!("{iface}@500000")))
    {
        // " vcanX@500000   805   74491  36656  15%"
        let f: Vec<&str> = line.split_whitespace().collect();
        their_frames += f.get(1).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
        their_bits += f.get(2).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    }
    eprintln!(
        "bus load: ours {frames} frames, {bits} bits, mean {:.1} %, peak {:.1} %; canbusload {their_frames} frames, {their_bits} bits",
        load["mean_pct"].as_f64().unwrap_or(-1.0),
        load["peak_pct"].as_f64().unwrap_or(-1.0)
    );
    ensure!(their_frames > 0, "canbusload saw nothing:\n{log}");
    ensure!(
        their_bits == their_frames * 135,
        "canbusload's bits per frame:\n{log}"
    );
    let ratio = their_frames as f64 / frames as f64;
    ensure!(
        (0.97..=1.1).contains(&ratio),
        "canbusload counted {their_frames} frames, the verdict {frames}:\n{log}"
    );
    Ok(())
}
