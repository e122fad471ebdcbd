//! Lockstep HIL (`ugv-sim run --lockstep`): the real controller binary on the real wires
//! (pty, iceoryx2, vcan), on the simulator's clock. The paper's scenario run twice
//! gives byte-identical results and recordings, the controller's trace is SIL's byte
//! for byte, its recording replays exactly, and a controller killed mid-run is a
//! fault judged on simulated time.
//!
//! These judge outcomes, not real-time behaviour, so they need no retries
//! (.config/nextest.toml): a stall of the VM only makes a run slower.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release binaries.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, ensure};
use ugv_e2e_tests::{TestVcan, a_hil_run_that_passed, workspace_bin};

/// The paper's scenario file.
fn paper() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios/paper.toml")
}

/// `ugv-sim run SCENARIO --lockstep` on `vcan` with the controller binary, results
/// into `results`, the run named `tag` (its services and GPS link); its verdict.
fn lockstep_run(
    vcan: &TestVcan,
    scenario: &Path,
    results: &Path,
    tag: &str,
) -> Result<serde_json::Value> {
    let run_id = format!("lockstep-{tag}-{}", std::process::id());
    let gps_link = std::env::temp_dir().join(&run_id);
    let out = Command::new(workspace_bin("ugv-sim")?)
        .arg("run")
        .arg(scenario)
        .args(["--lockstep", "--can", &vcan.name, "--run-id", &run_id])
        .args(["--status-every", "5"])
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(results)
        .arg("--gps-link")
        .arg(gps_link)
        .output()
        .context("running ugv-sim")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    let verdict: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    ensure!(
        stderr.contains("lockstep on ugv-hil/"),
        "not a lockstep run; stderr:\n{stderr}"
    );
    Ok(verdict)
}

/// The same file in two folders, byte for byte.
fn same_bytes(a: &Path, b: &Path, file: &str) -> Result<()> {
    let (x, y) = (std::fs::read(a.join(file))?, std::fs::read(b.join(file))?);
    ensure!(
        x == y,
        "{file} differs between {} and {} ({} and {} bytes)",
        a.display(),
        b.display(),
        x.len(),
        y.len()
    );
    Ok(())
}

#[test]
fn the_paper_scenario_in_lockstep_is_sil_on_the_wires_and_repeats_byte_for_byte() -> Result<()> {
    let vcan = TestVcan::new("lstep")?;
    let dir = tempfile::tempdir()?;
    let sil = dir.path().join("sil");
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--sil", "--no-record"])
        .arg(paper())
        .arg("--results")
        .arg(&sil)
        .output()?;
    ensure!(out.status.success(), "SIL run: {:?}", out.status);
    let sil_verdict: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    let runs = [dir.path().join("first"), dir.path().join("second")];
    for results in &runs {
        // The same command twice (the run's name is in its recording).
        let verdict = lockstep_run(&vcan, &paper(), results, "paper")?;
        a_hil_run_that_passed(&verdict)?;
        // The run is SIL's: the same outcome at the same time, the same path.
        for key in [
            "outcome",
            "time",
            "final_state",
            "path_length",
            "min_clearance",
        ] {
            ensure!(
                verdict[key] == sil_verdict[key],
                "{key}: lockstep {} against SIL {}",
                verdict[key],
                sil_verdict[key]
            );
        }
        // The controller took the same inputs at the same ticks: its trace is SIL's.
        same_bytes(&sil, results, "trace.json")?;
    }
    // Two runs of one seed: the same results and the same recording, byte for byte.
    for file in ["verdict.json", "run.mcap", "bus.log", "gps.nmea"] {
        same_bytes(&runs[0], &runs[1], file)?;
    }
    // The recording replays exactly: no divergence at all.
    let replay = Command::new(workspace_bin("ugv-sim")?)
        .arg("replay")
        .arg(runs[0].join("run.mcap"))
        .output()?;
    let report: serde_json::Value = serde_json::from_slice(&replay.stdout).with_context(|| {
        format!(
            "replay report; stderr:\n{}",
            String::from_utf8_lossy(&replay.stderr)
        )
    })?;
    ensure!(
        replay.status.code() == Some(0) && report["divergence"].is_null(),
        "the lockstep recording did not replay exactly: {report}"
    );
    let steering = &report["messages"]["STEERING_CMD"];
    ensure!(
        steering["matched"].as_u64() > Some(1000) && steering["matched"] == steering["recorded"],
        "{steering}"
    );
    Ok(())
}

#[test]
fn a_controller_killed_in_lockstep_is_a_fault_judged_on_simulated_time() -> Result<()> {
    let vcan = TestVcan::new("lskill")?;
    let dir = tempfile::tempdir()?;
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../sim/scenarios/faults/40-controller-kill.toml");
    let results = dir.path().join("kill");
    let verdict = lockstep_run(&vcan, &scenario, &results, "kill")?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict)?);
    // The fault plan's expectations hold (the car safe in time), as in SIL.
    ensure!(verdict["passed"] == true, "{}", verdict["failures"]);
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--sil", "--no-record"])
        .arg(&scenario)
        .arg("--results")
        .arg(dir.path().join("sil"))
        .output()?;
    let sil: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    for key in ["outcome", "time", "final_state", "safe_state"] {
        ensure!(
            verdict[key] == sil[key],
            "{key}: lockstep {} against SIL {}",
            verdict[key],
            sil[key]
        );
    }
    Ok(())
}
