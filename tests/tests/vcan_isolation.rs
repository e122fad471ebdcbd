//! Issue 11, item 5: any local user can open a raw CAN socket, and E2E proves
//! integrity, not origin. `ugv-forge` plays the attack of the report: it answers each
//! STEERING_CMD with a forged one carrying the next counter and 35 degrees.
//!
//! - On a shared vcan, the forger running as `nobody` is detected: the steering ECU
//!   sees a second sender on its command stream and goes to its safe state with a
//!   FAULT_REPORT, the controller estops, and the wheels never get near 35 degrees.
//! - With `ugv-sim run --isolate` the run's interface exists only in the run's own
//!   network namespace: the forger cannot open it (as `nobody` or as root from the root
//!   namespace) nor join the namespace (as `nobody`), and the run passes.
//!
//! Needs vcan and root (the README's test command runs it inside `vcan-setup vm`),
//! with UGV_BIN_DIR pointing at the release binaries.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use serde_json::Value;
use ugv_e2e_tests::{TestVcan, workspace_bin};

/// A forger process, killed on drop if still running.
struct Forger(Option<Child>);

impl Forger {
    fn spawn(args: &[&str]) -> Result<Forger> {
        let child = Command::new(workspace_bin("ugv-forge")?)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .context("starting ugv-forge")?;
        Ok(Forger(Some(child)))
    }

    /// Stop it (its standard input closes) and take its JSON line and exit code.
    fn finish(mut self) -> Result<(Value, Option<i32>)> {
        let mut child = self.0.take().context("forger gone")?;
        drop(child.stdin.take());
        let out = child.wait_with_output()?;
        let line = String::from_utf8_lossy(&out.stdout);
        let value = serde_json::from_str(line.trim()).with_context(|| {
            format!(
                "ugv-forge said {line:?}; stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            )
        })?;
        Ok((value, out.status.code()))
    }
}

impl Drop for Forger {
    fn drop(&mut self) {
        if let Some(c) = &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// `ugv-sim run` of the paper's scenario with the real controller.
fn sim_command(dir: &Path, extra: &[&str]) -> Result<Command> {
    let mut cmd = Command::new(workspace_bin("ugv-sim")?);
    cmd.arg("run")
        .args(extra)
        .args(["--status-every", "5"])
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(dir.join("results"))
        .arg("--gps-link")
        .arg(dir.join("gps"));
    Ok(cmd)
}

fn verdict_of(out: &Output) -> Result<Value> {
    let stderr = String::from_utf8_lossy(&out.stderr);
    let verdict: Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict)?);
    Ok(verdict)
}

#[test]
fn a_forger_as_nobody_on_a_shared_bus_is_detected_and_the_car_stays_safe() -> Result<()> {
    let vcan = TestVcan::new("forge")?;
    let dir = tempfile::tempdir()?;
    let forger = Forger::spawn(&[
        "--can",
        &vcan.name,
        "--as-user",
        "nobody",
        "--angle",
        "35",
        "--seconds",
        "600",
    ])?;
    let out = sim_command(dir.path(), &["--can", &vcan.name, "--time-limit", "8"])?
        .args(["--run-id", &format!("forge-{}", std::process::id())])
        .output()
        .context("running ugv-sim")?;
    let verdict = verdict_of(&out)?;
    let (forged, _) = forger.finish()?;
    eprintln!("forger: {forged}");
    ensure!(
        forged["uid"] == 65534,
        "the forger ran as {}",
        forged["uid"]
    );
    ensure!(
        forged["forged"].as_u64().unwrap_or(0) > 0,
        "the forger sent nothing: {forged}"
    );
    // The steering ECU found the second sender on its command stream and went safe.
    let steering = &verdict["steering_can"];
    ensure!(
        steering["e2e"]["second_sender"].as_u64().unwrap_or(0) >= 1,
        "steering ECU: {steering}"
    );
    ensure!(
        steering["safe_state_trips"][4].as_u64().unwrap_or(0) >= 1,
        "steering ECU safe-state trips: {}",
        steering["safe_state_trips"]
    );
    // The controller estopped, naming it.
    let mode = &verdict["controller"]["mode"];
    ensure!(mode["mode"] == "estop", "controller mode {mode}");
    let code = mode["code"].as_str().unwrap_or_default();
    ensure!(
        code == "second_sender" || code == "unexpected_actuation",
        "estop code {code}: {mode}"
    );
    // The car never went, and the wheels stayed far from the forged 35 degrees.
    let steer = verdict["max_steer_deg"].as_f64().context("max_steer_deg")?;
    ensure!(steer < 10.0, "the wheels got to {steer} deg");
    ensure!(verdict["goal_reached"] == false && verdict["collision"] == false);
    Ok(())
}

fn wait_for(path: &Path, timeout: Duration) -> Result<()> {
    let start = Instant::now();
    while !path.exists() {
        ensure!(
            start.elapsed() < timeout,
            "{} did not appear within {timeout:?}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

#[test]
fn an_isolated_run_refuses_a_forger_outside_its_namespace_and_passes() -> Result<()> {
    let iface = format!("vtiso{}", std::process::id() % 100_000);
    let run_id = format!("iso-{}", std::process::id());
    let netns = PathBuf::from("/run/netns").join(format!("ugv-{run_id}"));
    let dir = tempfile::tempdir()?;
    let stderr_path = dir.path().join("sim.stderr");
    let sim = sim_command(
        dir.path(),
        &["--isolate", "--can", &iface, "--run-id", &run_id],
    )?
    .stdout(Stdio::piped())
    .stderr(std::fs::File::create(&stderr_path)?)
    .spawn()
    .context("running ugv-sim --isolate")?;
    let waited = wait_for(&netns, Duration::from_secs(60));
    // Whatever happens, the run is collected.
    let attempts = waited.and_then(|()| {
        let mut results = Vec::new();
        for args in [
            // As nobody, the interface from the root namespace.
            vec!["--can", &iface, "--as-user", "nobody", "--seconds", "1"],
            // As nobody, joining the run's namespace.
            vec![
                "--can",
                &iface,
                "--as-user",
                "nobody",
                "--seconds",
                "1",
                "--netns",
                netns.to_str().unwrap_or_default(),
            ],
            // As root, from the root namespace: not there either.
            vec!["--can", &iface, "--seconds", "1"],
        ] {
            results.push(Forger::spawn(&args)?.finish()?);
        }
        Ok(results)
    });
    let out = sim.wait_with_output()?;
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    let verdict = serde_json::from_slice::<Value>(&out.stdout)
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    eprintln!("{}", serde_json::to_string_pretty(&verdict)?);
    let attempts = attempts?;
    for (i, (said, code)) in attempts.iter().enumerate() {
        eprintln!("forger {i}: {said} (exit {code:?})");
        ensure!(*code == Some(3), "forger {i} was not refused: {said}");
    }
    ensure!(attempts[0].0["refused"] == "interface", "{}", attempts[0].0);
    ensure!(attempts[1].0["refused"] == "netns", "{}", attempts[1].0);
    ensure!(
        attempts[2].0["refused"] == "interface" && attempts[2].0["uid"] == 0,
        "{}",
        attempts[2].0
    );
    ensure!(
        out.status.code() == Some(0) && verdict["passed"] == true,
        "ugv-sim exit {:?}, failures {}; stderr:\n{stderr}",
        out.status,
        verdict["failures"]
    );
    for node in ["steering_can", "throttle_can"] {
        let e2e = &verdict[node]["e2e"];
        for key in ["second_sender", "repeated_counter", "skipped_counter"] {
            ensure!(e2e[key] == 0, "{node}: {key} = {}", e2e[key]);
        }
    }
    // Users were told how to look in; the namespace and its interface are gone.
    let hint = format!("ip netns exec ugv-{run_id} candump {iface}");
    ensure!(stderr.contains(&hint), "no {hint:?} in:\n{stderr}");
    ensure!(!netns.exists(), "{} left behind", netns.display());
    ensure!(
        !vcan_setup::can_links().iter().any(|l| l.name == iface),
        "{iface} in the root namespace"
    );
    Ok(())
}
