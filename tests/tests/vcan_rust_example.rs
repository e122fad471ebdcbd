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

use anyhow::Result;
use ugv_e2e_tests::foreign::{
    drove_round_the_post_to_the_goal, example_lines, run_foreign_controller,
    started_by_ugv_sim_reaches_the_goal,
};
use ugv_e2e_tests::workspace_bin;

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
    let example = workspace_bin("ugv-example-rust")?;
    started_by_ugv_sim_reaches_the_goal("rsctl", &example, "ugv-example-rust")
}
