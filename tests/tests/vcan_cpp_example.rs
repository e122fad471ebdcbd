//! The C++ example controller (examples/cpp, binary `ugv-example-cpp`) in HIL: `ugv-sim
//! run --wait-for-controller` on the paper's scenario (a post of radius 3 m between
//! start and goal), and the example started as a user would start it, with the results
//! directory as its argument, speaking NMEA (termios), iceoryx2 (through the shim
//! examples/cpp/laser-c) and CAN with E2E (SocketCAN raw sockets, signals, counter and
//! CRC by hand); and started by `ugv-sim run --controller`. It must reach the goal
//! without collision and without a frame the ECUs reject.
//!
//! Needs vcan (fails loudly without it) and the example's binary, which `make -C
//! examples/cpp` builds into target/cpp-example/ on the host before the VM boots
//! (scripts/test.sh does, after the workspace's release build); the test command runs
//! it natively or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release
//! binaries.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Result, ensure};
use ugv_e2e_tests::foreign::{
    drove_round_the_post_to_the_goal, example_lines, run_foreign_controller,
    started_by_ugv_sim_reaches_the_goal,
};

fn example_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cpp")
}

/// The binary `make -C examples/cpp` built; none is built here (a VM would take minutes).
fn example_bin() -> Result<PathBuf> {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/cpp-example/ugv-example-cpp");
    ensure!(
        bin.is_file(),
        "{} is missing: build it with `make -C examples/cpp` (after `cargo build --workspace \
         --release`; scripts/test.sh does both)",
        bin.display()
    );
    Ok(bin)
}

#[test]
fn the_cpp_example_controller_drives_round_the_post_to_the_goal_in_hil() -> Result<()> {
    let lines = example_lines(&example_dir().join("controller.cpp"))?;
    eprintln!("examples/cpp/controller.cpp: {lines} lines");
    let controller = Command::new(example_bin()?);
    drove_round_the_post_to_the_goal(&run_foreign_controller("cppex", &[], controller)?)
}

/// The other way the README gives: `ugv-sim run --controller ugv-example-cpp`, which
/// starts the example with the project's controller command line (`run --config
/// DIR/controller.toml --gps ...`) and ends it with SIGINT after the run.
#[test]
fn started_by_ugv_sim_run_controller_the_cpp_example_reaches_the_goal_too() -> Result<()> {
    started_by_ugv_sim_reaches_the_goal("cppctl", &example_bin()?, "ugv-example-cpp")
}
