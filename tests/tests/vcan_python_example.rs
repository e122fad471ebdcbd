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
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use ugv_e2e_tests::{TestVcan, every_frame_passed_the_e2e_checks, workspace_bin};

fn example_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/python")
}

/// What one run of the example in HIL left: ugv-sim's exit status, verdict and stderr,
/// the example's exit status (None: it did not end by itself) and stderr.
struct Run {
    sim: std::process::ExitStatus,
    verdict: serde_json::Value,
    stderr: String,
    controller: Option<std::process::ExitStatus>,
    ctl: String,
}

/// `ugv-sim run --wait-for-controller SIM_ARGS` on a vcan of its own, and the example
/// started once the simulator has written its files, with `env` set.
fn run_example(tag: &str, sim_args: &[&str], env: &[(&str, &str)]) -> Result<Run> {
    let example = example_dir();
    let script = example.join("controller.py");
    let python = example.join(".venv/bin/python");
    ensure!(
        python.is_file(),
        "{} is missing: run scripts/install-deps.sh (it makes the example's venv)",
        python.display()
    );
    let lines = std::fs::read_to_string(&script)?.lines().count();
    ensure!(
        lines < 300,
        "controller.py has {lines} lines, the example promises under 300"
    );

    let vcan = TestVcan::new(tag)?;
    let dir = tempfile::tempdir()?;
    let results = dir.path().join("results");
    std::fs::create_dir_all(&results)?;
    let run_id = format!("{tag}-{}", std::process::id());
    let sim_out = dir.path().join("sim.out");
    let sim_err = dir.path().join("sim.err");
    let mut sim = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--wait-for-controller", "--can", &vcan.name])
        .args(["--run-id", &run_id, "--status-every", "5"])
        .args(sim_args)
        .arg("--results")
        .arg(&results)
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        .stdout(std::fs::File::create(&sim_out)?)
        .stderr(std::fs::File::create(&sim_err)?)
        .spawn()
        .context("starting ugv-sim")?;
    // The simulator writes wires.json, mission.toml, then controller.toml, then waits
    // for a heartbeat.
    let deadline = Instant::now() + Duration::from_secs(60);
    while !results.join("controller.toml").is_file() && Instant::now() < deadline {
        if let Some(status) = sim.try_wait()? {
            anyhow::bail!(
                "ugv-sim exited ({status}) before waiting for the controller:\n{}",
                std::fs::read_to_string(&sim_err)?
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    ensure!(
        results.join("wires.json").is_file(),
        "no wires.json within 60 s"
    );
    let ctl_err = dir.path().join("controller.err");
    let started = Instant::now();
    let mut controller = Command::new(&python)
        .arg(&script)
        .arg(&results)
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&ctl_err)?)
        .spawn()
        .context("starting the Python example")?;
    let sim_status = sim.wait()?;
    let run_wall = started.elapsed();
    // The run is over: the example sees its GPS line close and ends by itself.
    let deadline = Instant::now() + Duration::from_secs(30);
    let controller_status = loop {
        if let Some(status) = controller.try_wait()? {
            break Some(status);
        }
        if Instant::now() > deadline {
            let _ = controller.kill();
            let _ = controller.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let stderr = std::fs::read_to_string(&sim_err)?;
    let ctl = std::fs::read_to_string(&ctl_err)?;
    eprintln!("--- ugv-sim stderr\n{stderr}--- controller.py stderr\n{ctl}");
    eprintln!(
        "controller.py: {lines} lines; the run took {:.1} s of wall time from the example's start",
        run_wall.as_secs_f64()
    );
    let verdict: serde_json::Value = serde_json::from_slice(&std::fs::read(&sim_out)?)
        .context("the verdict on ugv-sim's stdout")?;
    Ok(Run {
        sim: sim_status,
        verdict,
        stderr,
        controller: controller_status,
        ctl,
    })
}

#[test]
fn the_python_example_controller_drives_round_the_post_to_the_goal_in_hil() -> Result<()> {
    let Run {
        sim: sim_status,
        verdict,
        stderr,
        controller: controller_status,
        ctl,
    } = run_example("pyex", &[], &[])?;
    ensure!(
        sim_status.code() == Some(0),
        "ugv-sim exit {sim_status:?}, failures {}",
        verdict["failures"]
    );
    ensure!(
        verdict["passed"] == true,
        "failures: {}",
        verdict["failures"]
    );
    ensure!(verdict["goal_reached"] == true && verdict["collision"] == false);
    ensure!(verdict["mode"] == "hil");
    // iceoryx2's start-up warning (no configuration file) is silenced in ugv-sim.
    ensure!(
        !stderr.contains("No config file was loaded"),
        "iceoryx2's warning in ugv-sim's stderr:\n{stderr}"
    );
    let clearance = verdict["min_clearance"][0].as_f64().context("clearance")?;
    ensure!(
        clearance > 0.3,
        "the example passed the post {clearance} m off"
    );
    // The example's E2E is right: the ECUs accepted its frames and rejected none.
    every_frame_passed_the_e2e_checks(&verdict, 500)?;
    ensure!(
        controller_status.is_some_and(|s| s.success()),
        "the example did not end by itself with status 0 ({controller_status:?})"
    );
    // The run's end as docs/wire-contract.md says a controller sees it: the GPS line
    // closes, or (when the simulator takes its time writing the results, as in an
    // emulated VM) the ECUs' reports stop first.
    ensure!(
        ctl.contains("both ECUs enabled")
            && (ctl.contains("run over: the GPS line closed")
                || ctl.contains("run over: the ECUs' reports stopped")),
        "the example's account:\n{ctl}"
    );
    ensure!(
        ctl.contains("rejected 0"),
        "the example rejected reports:\n{ctl}"
    );
    Ok(())
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
