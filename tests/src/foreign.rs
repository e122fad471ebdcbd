//! A controller of one's own (examples/) in HIL: `ugv-sim run --wait-for-controller` on
//! a vcan of the test's own, and the controller started as a user would start it, with
//! the results directory (`wires.json`, `mission.toml`, `controller.toml`) as its last
//! argument; what the run left, and the checks every example's test makes of it. And the
//! other way: `ugv-sim run --controller BINARY`, which starts it itself.

use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};

use crate::{TestVcan, a_hil_run_that_passed, every_frame_passed_the_e2e_checks, workspace_bin};

/// What one run of a controller in HIL left: ugv-sim's exit status, verdict, last
/// `wires.json` and stderr, the controller's exit status (None: it did not end by
/// itself) and stderr.
#[derive(Debug)]
pub struct ForeignRun {
    pub sim: ExitStatus,
    pub verdict: serde_json::Value,
    pub wires: serde_json::Value,
    pub stderr: String,
    pub controller: Option<ExitStatus>,
    pub ctl: String,
}

/// The lines of an example's source, which must be under 300 (the examples promise it).
pub fn example_lines(source: &Path) -> Result<usize> {
    let text =
        std::fs::read_to_string(source).with_context(|| format!("reading {}", source.display()))?;
    let lines = text.lines().count();
    ensure!(
        lines < 300,
        "{} has {lines} lines, the example promises under 300",
        source.display()
    );
    Ok(lines)
}

/// `ugv-sim run --wait-for-controller SIM_ARGS` on a vcan of its own (`tag` names it),
/// and `controller` with the results directory as its last argument, started once the
/// simulator has written its files.
pub fn run_foreign_controller(
    tag: &str,
    sim_args: &[&str],
    mut controller: Command,
) -> Result<ForeignRun> {
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
    let name = Path::new(controller.get_program())
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ctl_err = dir.path().join("controller.err");
    let started = Instant::now();
    let mut controller = controller
        .arg(&results)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&ctl_err)?)
        .spawn()
        .with_context(|| format!("starting the example ({name})"))?;
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
    eprintln!("--- ugv-sim stderr\n{stderr}--- {name} stderr\n{ctl}");
    eprintln!(
        "{name}: the run took {:.1} s of wall time from the example's start",
        run_wall.as_secs_f64()
    );
    let verdict: serde_json::Value = serde_json::from_slice(&std::fs::read(&sim_out)?)
        .context("the verdict on ugv-sim's stdout")?;
    let wires: serde_json::Value =
        serde_json::from_slice(&std::fs::read(results.join("wires.json"))?)
            .context("wires.json after the run")?;
    ended_on_the_wires(sim_status, &verdict, &wires)?;
    Ok(ForeignRun {
        sim: sim_status,
        verdict,
        wires,
        stderr,
        controller: controller_status,
        ctl,
    })
}

/// The end of the run as docs/wire-contract.md promises it on the wires: the last
/// `wires.json` (written before the wires closed) says `ended`, with the verdict's
/// outcome and the simulator's exit code.
fn ended_on_the_wires(
    sim: ExitStatus,
    verdict: &serde_json::Value,
    wires: &serde_json::Value,
) -> Result<()> {
    let end = &wires["end"];
    ensure!(
        wires["state"] == "ended",
        "wires.json after the run: {wires}"
    );
    for key in ["outcome", "passed", "goal_reached"] {
        ensure!(
            end[key] == verdict[key],
            "wires.json's end.{key} {} but the verdict's {}",
            end[key],
            verdict[key]
        );
    }
    ensure!(
        end["time_s"] == verdict["time"] && end["exit_code"].as_i64() == sim.code().map(i64::from),
        "wires.json's end {end}, the verdict's time {}, ugv-sim's exit {sim:?}",
        verdict["time"]
    );
    Ok(())
}

/// The run every example promises: the goal reached round the post without collision,
/// every frame through the ECUs' E2E checks and none of the ECUs' reports rejected by
/// the example, which saw the run end on its wires and ended by itself.
pub fn drove_round_the_post_to_the_goal(run: &ForeignRun) -> Result<()> {
    let ForeignRun {
        sim,
        verdict,
        wires: _,
        stderr,
        controller,
        ctl,
    } = run;
    ensure!(
        sim.code() == Some(0),
        "ugv-sim exit {sim:?}, failures {}",
        verdict["failures"]
    );
    a_hil_run_that_passed(verdict)?;
    // iceoryx2's start-up warning (no configuration file) is silenced in ugv-sim and in
    // the example.
    for (who, text) in [("ugv-sim", stderr), ("the example", ctl)] {
        ensure!(
            !text.contains("No config file was loaded"),
            "iceoryx2's warning in {who}'s stderr:\n{text}"
        );
    }
    let clearance = verdict["min_clearance"][0].as_f64().context("clearance")?;
    let accepted = |ecu: &str| verdict[ecu]["e2e"]["accepted"].clone();
    eprintln!(
        "verdict: {} at t = {} s, footprint at least {clearance:.2} m from the post, frames accepted {} (steering) and {} (throttle)",
        verdict["outcome"],
        verdict["time"],
        accepted("steering_can"),
        accepted("throttle_can")
    );
    ensure!(
        clearance > 0.3,
        "the example passed the post {clearance} m off"
    );
    // The example's E2E is right: the ECUs accepted its frames and rejected none.
    every_frame_passed_the_e2e_checks(verdict, 500)?;
    ensure!(
        controller.is_some_and(|s| s.success()),
        "the example did not end by itself with status 0 ({controller:?})"
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

/// The other way an example runs: `ugv-sim run --controller BINARY` on a vcan of its own
/// (`tag` names it), which starts the example with the project's controller command
/// line (`run --config DIR/controller.toml --gps ...`) and ends it with SIGINT after the
/// run. The run must pass with every frame through the ECUs' E2E checks, and the
/// example (whose stderr is ugv-sim's, each line starting `name: `) must have enabled
/// the ECUs, seen the run end, rejected no report and exited with status 0.
pub fn started_by_ugv_sim_reaches_the_goal(tag: &str, binary: &Path, name: &str) -> Result<()> {
    let vcan = TestVcan::new(tag)?;
    let dir = tempfile::tempdir()?;
    let run_id = format!("{tag}-{}", std::process::id());
    let out = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--can", &vcan.name, "--run-id", &run_id])
        .arg("--controller")
        .arg(binary)
        .arg("--results")
        .arg(dir.path().join("results"))
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        .output()
        .context("running ugv-sim")?;
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
        format!("{name}: both ECUs enabled"),
        format!("{name}: run over: "),
        "rejected 0".to_owned(),
        "controller finished: Some(ExitStatus(unix_wait_status(0)))".to_owned(),
    ] {
        ensure!(stderr.contains(&line), "no {line:?} in ugv-sim's stderr");
    }
    Ok(())
}
