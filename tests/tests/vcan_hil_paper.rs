//! The main job as a test: the paper's scenario end to end in HIL — `ugv-sim` and the
//! real `ugv-controller` binary as separate processes on a pty (NMEA), iceoryx2 (laser
//! frames) and a real vcan interface (golf_car.dbc) — reaches the goal without
//! collision.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release binaries.

use std::process::Command;

use anyhow::{Context, Result, ensure};
use ugv_e2e_tests::{TestVcan, workspace_bin};

#[test]
fn the_paper_scenario_reaches_its_goal_in_hil_with_the_real_controller_binary() -> Result<()> {
    let vcan = TestVcan::new("hil")?;
    let dir = tempfile::tempdir()?;
    let results = dir.path().join("results");
    let run_id = format!("test-{}", std::process::id());
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
    let stderr = String::from_utf8_lossy(&out.stderr);
    let verdict: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict)?);
    ensure!(
        out.status.code() == Some(0),
        "ugv-sim exit {:?}; stderr:\n{stderr}",
        out.status
    );
    ensure!(
        verdict["passed"] == true,
        "failures: {}",
        verdict["failures"]
    );
    ensure!(verdict["goal_reached"] == true && verdict["collision"] == false);
    ensure!(verdict["mode"] == "hil");
    let clearance = verdict["min_clearance"][0].as_f64().context("clearance")?;
    ensure!(clearance > 0.5, "min clearance {clearance}");
    // Every frame on the bus passed the E2E checks, both ways.
    for node in ["steering_can", "throttle_can"] {
        let e2e = &verdict[node]["e2e"];
        let accepted = e2e["accepted"].as_u64().context("accepted")?;
        ensure!(accepted > 1000, "{node}: only {accepted} frames");
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
