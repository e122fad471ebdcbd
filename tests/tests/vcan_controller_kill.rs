//! The controller killed mid-run (SIGKILL) in HIL: the simulator goes on until both
//! ECUs report their safe state and the car has stopped, and the verdict says how
//! long each ECU took from its last command (issue 11, finding 4: the run ended 25-70
//! ms after the kill, with the car still at 2 m/s and no timing). The controller's
//! trace, written while it drove, is still read (finding 3).
//!
//! `UGV_KILL_TRIALS` (default 1, as the README's test command runs it; the
//! measurement in the closing note used 20) trials, the kill moving through the run;
//! the distribution is printed. Needs vcan (fails loudly without it).

use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use ugv_e2e_tests::{TestVcan, child_named, samples_written, workspace_bin};

struct Trial {
    kill_at_s: f64,
    steering_ms: f64,
    throttle_ms: f64,
    bound_ms: f64,
    stop_after_s: f64,
}

/// A file of the trial's folder, as text (empty when missing).
fn read(dir: &tempfile::TempDir, name: &str) -> String {
    std::fs::read_to_string(dir.path().join(name)).unwrap_or_default()
}

fn trial(vcan: &TestVcan, i: usize, kill_after_samples: usize) -> Result<Trial> {
    let dir = tempfile::tempdir()?;
    let results = dir.path().join("results");
    let mut sim = Command::new(workspace_bin("ugv-sim")?)
        .args(["run", "--can", &vcan.name, "--status-every", "5"])
        .arg("--run-id")
        .arg(format!("kill-{}-{i}", std::process::id()))
        .arg("--controller")
        .arg(workspace_bin("ugv-controller")?)
        .arg("--results")
        .arg(&results)
        .arg("--gps-link")
        .arg(dir.path().join("gps"))
        // Files, not pipes: nobody reads a pipe while the run goes, and the status
        // lines of ugv-sim and its controller would fill it and block them.
        .stdout(std::fs::File::create(dir.path().join("stdout"))?)
        .stderr(std::fs::File::create(dir.path().join("stderr"))?)
        .spawn()
        .context("starting ugv-sim")?;
    // Kill the controller once it has driven for a while (its trace, written as it
    // drives, says how long).
    // Polled gently: in an emulated VM a /proc scan and a re-read of the growing trace
    // every 10 ms took enough of the two vCPUs to starve the real-time run itself.
    let started = Instant::now();
    let trace = results.join("controller-trace.jsonl");
    let mut controller = None;
    let controller = loop {
        if controller.is_none() {
            controller = child_named(sim.id(), "ugv-controller");
        }
        if let Some(pid) = controller
            && samples_written(&trace) >= kill_after_samples
        {
            break pid;
        }
        if let Some(status) = sim.try_wait()? {
            bail!(
                "ugv-sim ended ({status}) before the controller drove {kill_after_samples} ticks:\n{}\nverdict:\n{}",
                read(&dir, "stderr"),
                read(&dir, "stdout")
            );
        }
        if started.elapsed() > Duration::from_secs(90) {
            let _ = sim.kill();
            let _ = sim.wait();
            bail!(
                "the controller did not drive {kill_after_samples} ticks within 90 s ({} written):\n{}",
                samples_written(&trace),
                read(&dir, "stderr")
            );
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(controller),
        nix::sys::signal::Signal::SIGKILL,
    )
    .context("SIGKILL to the controller")?;
    let status = sim.wait().context("waiting for ugv-sim")?;
    let stderr = read(&dir, "stderr");
    let verdict: serde_json::Value = serde_json::from_str(&read(&dir, "stdout"))
        .with_context(|| format!("verdict on stdout; stderr:\n{stderr}"))?;
    ensure!(
        status.code() == Some(3),
        "ugv-sim exit {status:?} (3: stopped); stderr:\n{stderr}"
    );
    let s = &verdict["safe_state"];
    ensure!(s.is_object(), "no safe_state in the verdict:\n{verdict:#}");
    ensure!(
        s["reason"]
            .as_str()
            .unwrap_or("")
            .contains("the controller exited"),
        "{s}"
    );
    ensure!(verdict["collision"] == false, "{verdict:#}");
    let speed_then = s["speed_then"].as_f64().context("speed_then")?;
    ensure!(speed_then > 0.5, "the car was driving when killed: {s}");
    let stopped = s["stopped_s"].as_f64().context("the car stopped")?;
    let final_speed = verdict["final_state"]["v"]
        .as_f64()
        .context("final speed")?;
    ensure!(final_speed.abs() < 0.05, "final speed {final_speed}");
    let ecu = |name: &str| -> Result<(f64, f64)> {
        let e = &s[name];
        ensure!(e["within_bound"] == true, "{name}: {e}");
        Ok((
            e["latency_ms"].as_f64().context("latency")?,
            e["bound_ms"].as_f64().context("bound")?,
        ))
    };
    let (steering_ms, bound_ms) = ecu("steering")?;
    let (throttle_ms, _) = ecu("throttle")?;
    // The trace the controller wrote before it was killed reached the verdict.
    let replans = verdict["controller"]["replans"].as_u64().unwrap_or(0);
    ensure!(
        replans > 0,
        "no controller trace after the kill: {}",
        verdict["controller"]
    );
    let noticed = s["noticed_s"].as_f64().context("noticed_s")?;
    Ok(Trial {
        kill_at_s: noticed,
        steering_ms,
        throttle_ms,
        bound_ms,
        stop_after_s: stopped - noticed,
    })
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn a_controller_killed_mid_run_leaves_both_ecus_safe_within_timeout_plus_one_period() -> Result<()>
{
    let trials: usize = std::env::var("UGV_KILL_TRIALS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
        .clamp(1, 100);
    let vcan = TestVcan::new("kill")?;
    let mut all = Vec::new();
    for i in 0..trials {
        // Kill after 3 to 9 s of driving (the trace reaches the disk once a second):
        // at different points of the path and of the command schedule.
        let after = 300 + (i * 137) % 600;
        let t = trial(&vcan, i, after).with_context(|| format!("trial {i}"))?;
        eprintln!(
            "trial {i}: killed (noticed) at {:.2} s, steering safe {:.1} ms, throttle {:.1} ms after the last command (bound {:.0} ms), stopped {:.2} s later",
            t.kill_at_s, t.steering_ms, t.throttle_ms, t.bound_ms, t.stop_after_s
        );
        all.push(t);
    }
    let mut ms: Vec<f64> = all
        .iter()
        .flat_map(|t| [t.steering_ms, t.throttle_ms])
        .collect();
    let (p50, max) = (percentile(&mut ms, 0.5), percentile(&mut ms, 1.0));
    eprintln!(
        "{trials} trials: time from the last command to each ECU's safe-state report p50 {p50:.1} ms, max {max:.1} ms (bound {:.0} ms)",
        all[0].bound_ms
    );
    ensure!(max <= all[0].bound_ms, "max {max} ms beyond the bound");
    Ok(())
}
