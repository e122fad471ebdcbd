//! The Python example controller (examples/python/controller.py) in HIL: `ugv-sim run
//! --wait-for-controller` on the paper's scenario (a post of radius 3 m between start
//! and goal), and the example started as a foreign controller would be, reading
//! `wires.json` and `controller.toml` from the results directory and speaking NMEA
//! (pyserial), iceoryx2 (the Python binding) and CAN with E2E (python-can, cantools).
//! It must reach the goal without collision and without a frame the ECUs reject.
//!
//! Needs vcan (fails loudly without it) and the example's venv
//! (`scripts/install-deps.sh` makes examples/python/.venv); the test command runs it
//! natively or inside `vcan-setup vm`, with UGV_BIN_DIR pointing at the release
//! binaries.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Result, ensure};
use ugv_e2e_tests::foreign::{
    ForeignRun, drove_round_the_post_to_the_goal, example_lines, run_foreign_controller,
};

fn example_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/python")
}

/// The example in HIL (`ugv_e2e_tests::foreign`), in its venv's Python with `env` set.
fn run_example(tag: &str, sim_args: &[&str], env: &[(&str, &str)]) -> Result<ForeignRun> {
    let example = example_dir();
    let script = example.join("controller.py");
    let python = example.join(".venv/bin/python");
    ensure!(
        python.is_file(),
        "{} is missing: run scripts/install-deps.sh (it makes the example's venv)",
        python.display()
    );
    let lines = example_lines(&script)?;
    eprintln!("controller.py: {lines} lines");
    let mut controller = Command::new(&python);
    controller.arg(&script).envs(env.iter().copied());
    run_foreign_controller(tag, sim_args, controller)
}

#[test]
fn the_python_example_controller_drives_round_the_post_to_the_goal_in_hil() -> Result<()> {
    drove_round_the_post_to_the_goal(&run_example("pyex", &[], &[])?)
}

/// The mistake the contract warns of, made on purpose: Enable = 1 from the example's
/// first frame, before any heartbeat auto, and never a 0 after it. The ECUs stay
/// disabled with no fault, and the verdict says why the car stood.
#[test]
fn an_enable_from_the_first_frame_leaves_the_car_standing_and_the_verdict_says_why() -> Result<()> {
    let run = run_example(
        "pymis",
        &["--time-limit", "8"],
        &[("UGV_EXAMPLE_ENABLE_MISTAKE", "1")],
    )?;
    let v = &run.verdict;
    let failures = v["failures"].to_string();
    ensure!(
        run.sim.code() == Some(5),
        "ugv-sim exit {:?} (5: time limit)",
        run.sim
    );
    ensure!(v["goal_reached"] == false, "{failures}");
    for ecu in ["steering", "throttle"] {
        ensure!(
            failures.contains(&format!("the {ecu} ECU never enabled"))
                && failures.contains("without a CONTROLLER_HEARTBEAT auto")
                && failures.contains("no new 0 -> 1 edge"),
            "{ecu}: {failures}"
        );
        let enable = &v[format!("{ecu}_can")]["enable"];
        ensure!(enable["ever_enabled"] == false, "{enable}");
        ensure!(enable["no_auto_heartbeat"].as_u64() == Some(1), "{enable}");
        ensure!(
            enable["without_edge"].as_u64().unwrap_or(0) > 100,
            "{enable}"
        );
    }
    ensure!(
        run.ctl.contains("ECUs not enabled"),
        "the example's account:\n{}",
        run.ctl
    );
    Ok(())
}
