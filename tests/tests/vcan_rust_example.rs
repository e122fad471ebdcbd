//! The Rust example controller (examples/rust, binary `ugv-example-rust`) in HIL:
//! `ugv-sim run --wait-for-controller` on the paper's scenario (a post of radius 3 m
//! between start and goal), and the example started as a user would start it, with the
//! results directory as its argument, speaking NMEA, iceoryx2 and CAN with E2E through
//! firmware-bridge's endpoints and golf-car-can's codecs. It must reach the goal
//! without collision and without a frame the ECUs reject.
//!
//! Needs vcan (fails loudly without it) and the workspace's release build (the example
//! is a workspace member); the test command runs it natively or inside `vcan-setup vm`,
//! with UGV_BIN_DIR pointing at the release binaries.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, ensure};
use ugv_e2e_tests::foreign::{
    drove_round_the_post_to_the_goal, example_lines, run_foreign_controller,
};
use ugv_e2e_tests::{
    TestVcan, a_hil_run_that_passed, every_frame_passed_the_e2e_checks, workspace_bin,
};

#[test]
fn the_rust_example_controller_drives_round_the_post_to_the_goal_in_hil() -> Result<()> {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/rust/src/main.rs");
    let lines = example_lines(&source)?;
    eprintln!("examples/rust/src/main.rs: {lines} lines");
    let controller = Command::new(workspace_bin("ugv-example-rust")?);
    drove_round_the_post_to_the_goal(&run_foreign_controller("rsex", &[], controller)?)
}

/// The other way the README gives: `ugv-sim run --controller ugv-example-rust`, which
/// starts the example with the project's controller command line (`run --config
/// DIR/controller.toml --gps ...`) and ends it with SIGINT after the run.
#[test]
fn started_by_ugv_sim_run_controller_the_rust_example_reaches_the_goal_too() -> Result<()> {
    let vcan = TestVcan::new("rsctl")?;
    let dir = tempfile::tempdir()?;
    let run_id = format!("rsctl-{}", std::process::id());
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--can", &vcan.name, "--run-id", &run_id])
        .arg("--controller")
        .arg(workspace_bin("ugv-example-rust")?)
        .arg("--results")
        .arg(dir.path().join("results"))
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        .output()
        .context("running ugv-sim")?;
    // The example's stderr is ugv-sim's.
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("--- ugv-sim stderr\n{stderr}");
    let verdict: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("the verdict on ugv-sim's stdout")?;
    ensure!(
        out.status.code() == Some(0),
        "ugv-sim exit {:?}",
        out.status
    );
    a_hil_run_that_passed(&verdict)?;
    every_frame_passed_the_e2e_checks(&verdict, 500)?;
    for line in [
        "ugv-example-rust: both ECUs enabled",
        "ugv-example-rust: run over: ",
        "rejected 0",
        "controller finished: Some(ExitStatus(unix_wait_status(0)))",
    ] {
        ensure!(stderr.contains(line), "no {line:?} in ugv-sim's stderr");
    }
    Ok(())
}
