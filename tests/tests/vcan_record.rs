//! Recordings on a real bus: canplayer replays a recorded bus.log onto vcan and
//! candump sees the same frames in the same order; a HIL run records bus.log with
//! the kernel's receive timestamps and run.mcap with the wall clock alongside, and
//! `ugv-sim replay` finds its commands within the HIL tolerance (the figures it
//! prints are the ones the README's tolerance should be checked against), while the
//! controller's own recording of the same run (`ugv-controller run --record`) replays
//! byte for byte.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release binaries.

use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, ensure};
use golf_car_can::candump::{Compact, parse_line};
use ugv_controller::config::FollowerKind;
use ugv_e2e_tests::{TestVcan, can_utils, mcap_summary, replay_hil_recording, workspace_bin};
use ugv_sim::Scenario;
use ugv_sim::mission::controller_config;
use ugv_sim::record::{BUS_LOG, CONTROLLER_LOG_DIR, MCAP_FILE, topics};
use ugv_sim::sil::{Hook, run_sil_recorded};

/// `ID#DATA` of each candump line in `text`.
fn frames(text: &str) -> Result<Vec<String>> {
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f = parse_line(l).with_context(|| format!("candump line {l:?}"))?;
            Ok(Compact {
                id: f.id,
                extended: f.extended,
                data: &f.data,
            }
            .to_string())
        })
        .collect()
}

#[test]
fn canplayer_replays_a_recorded_bus_log_and_candump_sees_the_same_frames() -> Result<()> {
    let vcan = TestVcan::new("play")?;
    let dir = tempfile::tempdir()?;
    let mut sc = Scenario::paper()?;
    sc.sim.time_limit_s = 3.0;
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    run_sil_recorded(sc.clone(), &cfg, |_, _| Hook::Continue, Some(dir.path()))?;
    let log = std::fs::read_to_string(dir.path().join(BUS_LOG))?;
    let recorded = frames(&log)?;
    ensure!(recorded.len() > 1000, "{} frames recorded", recorded.len());
    let dump = dir.path().join("candump.log");
    let mut candump = Command::new("candump")
        .args(["-L", &vcan.name])
        .stdout(std::fs::File::create(&dump)?)
        .stderr(Stdio::null())
        .spawn()
        .context("running candump (Debian package can-utils)")?;
    std::thread::sleep(Duration::from_millis(500));
    // The log names the scenario's interface (vcan0): map it onto the test's.
    let bus_log = dir.path().join(BUS_LOG);
    let played = can_utils(
        "canplayer",
        &[
            "-I",
            bus_log.to_str().context("path")?,
            &format!("{}={}", vcan.name, sc.can.interface),
        ],
    )?;
    ensure!(
        played.status.success(),
        "canplayer: {}",
        String::from_utf8_lossy(&played.stderr)
    );
    std::thread::sleep(Duration::from_millis(500));
    candump.kill()?;
    candump.wait()?;
    let seen = frames(&std::fs::read_to_string(&dump)?)?;
    ensure!(
        seen == recorded,
        "candump saw {} frames, bus.log has {}; first difference at {:?}",
        seen.len(),
        recorded.len(),
        seen.iter().zip(&recorded).position(|(a, b)| a != b)
    );
    Ok(())
}

#[test]
fn a_hil_recording_has_kernel_timestamps_and_replays_from_the_controllers_start() -> Result<()> {
    let vcan = TestVcan::new("hrec")?;
    let dir = tempfile::tempdir()?;
    let results = dir.path().join("results");
    // The controller's own recording beside the simulator's.
    let own = results.join(CONTROLLER_LOG_DIR);
    let run_id = format!("rec-{}", std::process::id());
    let started = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?;
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--can", &vcan.name, "--run-id", &run_id])
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(&results)
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        .arg("--controller-log")
        .output()
        .context("running ugv-sim")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    ensure!(
        out.status.code() == Some(0),
        "ugv-sim {:?}: {stderr}",
        out.status
    );
    ensure!(stderr.contains("recorded"), "{stderr}");
    // bus.log: the kernel's receive times, on this run's wall clock.
    let log = std::fs::read_to_string(results.join(BUS_LOG))?;
    let first = parse_line(log.lines().next().context("empty bus.log")?)?;
    let t0: f64 = first.timestamp.as_deref().context("timestamp")?.parse()?;
    ensure!(
        (t0 - started.as_secs_f64()).abs() < 120.0,
        "first frame at {t0}, run started at {}",
        started.as_secs_f64()
    );
    // The run's interface (--can replaces the scenario's).
    ensure!(
        first.interface.as_deref() == Some(vcan.name.as_str()),
        "{first:?}"
    );
    let s = mcap_summary(&results.join(MCAP_FILE))?;
    ensure!(s["complete"] == true, "{s}");
    let lines = log.lines().count() as u64;
    ensure!(
        s["topics"][topics::CAN_RAW]["count"].as_u64() == Some(lines),
        "{s}"
    );
    ensure!(
        s["topics"][topics::LASER]["count"].as_u64() > Some(500),
        "{s}"
    );
    // The replay: the controller library fed the recording from the moment the
    // recorded controller started (its process, after the simulator's), to the end.
    replay_hil_recording(&results, 0.0..10.0)?;
    // The controller's own recording of the same run (`run --record`): every input at
    // the tick that took it, the ticks it skipped and took its paths at, so it
    // replays byte for byte however the guest stalled.
    let out = Command::new(workspace_bin("ugv-sim")?)
        .arg("replay")
        .arg(own.join(MCAP_FILE))
        .output()?;
    let text = String::from_utf8_lossy(&out.stdout);
    eprintln!(
        "{}\n{text}",
        String::from_utf8_lossy(&out.stderr).trim_end()
    );
    ensure!(out.status.code() == Some(0), "{:?}", out.status);
    let report: serde_json::Value = serde_json::from_str(&text)?;
    // Whole (a recorder that lost entries says so: `truncated`) and as recorded.
    ensure!(
        report["mode"] == "field"
            && report["truncated"].is_null()
            && report["divergence"].is_null(),
        "{report}"
    );
    for message in ["STEERING_CMD", "THROTTLE_CMD", "CONTROLLER_HEARTBEAT"] {
        let m = &report["messages"][message];
        ensure!(
            m["recorded"].as_u64() > Some(500) && m["matched"] == m["recorded"],
            "{message}: {m}"
        );
    }
    ensure!(
        std::fs::read_to_string(own.join(BUS_LOG))?.lines().count() > 3000,
        "the controller's bus.log"
    );
    Ok(())
}
