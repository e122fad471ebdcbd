//! The real `ugv-sim` binary's simulated ECUs on a real vcan interface, driven by
//! can-utils: canplayer replays a controller's frames (heartbeat, enable edge,
//! steering and throttle commands, all E2E protected), candump records the bus.
//!
//! Needs vcan (fails loudly without it); the README's test command runs it natively
//! or inside `vcan-setup vm`.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, ensure};
use golf_car_can::candump::{Compact, parse_line};
use golf_car_can::{
    CanMessage, ControllerHeartbeat, ControllerHeartbeatState, E2eRx, E2eTx, GolfCarMessage,
    NETWORK, SteeringCmd, SteeringReport, SteeringReportFault, ThrottleCmd, ThrottleCmdGear,
    ThrottleReport, ThrottleReportFault,
};
use ugv_e2e_tests::{TestVcan, workspace_bin};
use ugv_sim::ecu::{period_of, safety_timing};
use ugv_sim::scenario::CanConfig;

const TARGET_DEG: f64 = 20.0;
const COMMAND_SECONDS: f64 = 2.0;

/// The controller's frames as a candump log for canplayer: 10 ms steps, heartbeat every
/// 20 ms, enable low for the first 50 ms then high (the explicit enable edge).
fn controller_log(iface: &str) -> Result<(String, f64)> {
    let mut tx = E2eTx::new();
    let mut log = String::new();
    let t0 = 1_000.0;
    let mut line = |t: f64, id: u16, data: [u8; 8]| {
        let frame = Compact {
            id: u32::from(id),
            extended: false,
            data: &data,
        };
        log.push_str(&format!("({:.6}) {iface} {frame}\n", t0 + t));
    };
    let steps = (COMMAND_SECONDS / 0.01) as usize;
    for i in 0..steps {
        let t = i as f64 * 0.01;
        let enable = t >= 0.05;
        if i % 2 == 0 {
            let hb = ControllerHeartbeat {
                state: ControllerHeartbeatState::Auto,
            };
            line(t, ControllerHeartbeat::ID, tx.seal_message(&hb)?);
        }
        let steer = SteeringCmd {
            enable,
            target_angle: if enable { TARGET_DEG } else { 0.0 },
            max_rate: 0.0,
        };
        line(t, SteeringCmd::ID, tx.seal_message(&steer)?);
        let drive = ThrottleCmd {
            enable,
            gear: ThrottleCmdGear::Forward,
            brake: 0.0,
            target_speed: if enable { 1.0 } else { 0.0 },
            accel_limit: 0.0,
        };
        line(t, ThrottleCmd::ID, tx.seal_message(&drive)?);
    }
    Ok((log, (steps - 1) as f64 * 0.01))
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn cansent_commands_move_the_steering_at_its_rate_limit_and_silence_trips_the_safe_state()
-> Result<()> {
    let vcan = TestVcan::new("ecu")?;
    let dir = tempfile::tempdir()?;
    let (log, last_cmd_rel) = controller_log(&vcan.name)?;
    let log_path = dir.path().join("controller.log");
    std::fs::write(&log_path, log)?;
    let captured = capture(&vcan.name, dir.path(), &log_path)?;
    let frames = decode(&captured)?;
    let last_cmd = frames
        .iter()
        .filter(|(_, m)| matches!(m, GolfCarMessage::SteeringCmd(_)))
        .map(|(t, _)| *t)
        .fold(f64::MIN, f64::max);
    let first_cmd = frames
        .iter()
        .find(|(_, m)| matches!(m, GolfCarMessage::SteeringCmd(_)))
        .map(|(t, _)| *t)
        .context("no command seen")?;
    ensure!(
        (last_cmd - first_cmd - last_cmd_rel).abs() < 1.0,
        "canplayer kept the log's timing"
    );
    let steering: Vec<_> = frames
        .iter()
        .filter_map(|(t, m)| match m {
            GolfCarMessage::SteeringReport(r) => Some((*t, *r)),
            _ => None,
        })
        .collect();
    let throttle: Vec<_> = frames
        .iter()
        .filter_map(|(t, m)| match m {
            GolfCarMessage::ThrottleReport(r) => Some((*t, *r)),
            _ => None,
        })
        .collect();
    steering_ramps_at_its_rate_limit(&steering, last_cmd)?;
    both_ecus_go_safe_after_the_commands_stop(&steering, &throttle, last_cmd)?;
    let last_thr = throttle.last().context("no throttle reports")?.1;
    ensure!(
        last_thr.brake == 100.0 && last_thr.throttle == 0.0,
        "{last_thr:?}"
    );
    Ok(())
}

/// The bus on `iface` as candump shows it while the real `ugv-sim` runs its ECUs there
/// (results in `dir`) and canplayer replays `log_path`, until a few safe reports have
/// gone out after it.
fn capture(iface: &str, dir: &Path, log_path: &Path) -> Result<Vec<String>> {
    // candump first, then the simulator; its reports on candump show both are up.
    let mut candump = Kill(
        Command::new("candump")
            .args(["-L", iface])
            .stdout(Stdio::piped())
            .spawn()
            .context("candump (can-utils)")?,
    );
    let stdout = candump.0.stdout.take().context("candump stdout")?;
    let (lines_tx, lines) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for l in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            if lines_tx.send(l).is_err() {
                break;
            }
        }
    });
    let sim = Kill(
        Command::new(workspace_bin("ugv-sim")?)
            .args([
                "run",
                "--can",
                iface,
                "--time-limit",
                "120",
                "--status-every",
                "5",
            ])
            .arg("--results")
            .arg(dir.join("results"))
            .arg("--gps-link")
            .arg(dir.join("gps"))
            .stdout(Stdio::null())
            .spawn()
            .context("ugv-sim")?,
    );
    let mut captured = Vec::new();
    let first = lines
        .recv_timeout(Duration::from_secs(60))
        .context("no frame from ugv-sim on the bus within 60 s")?;
    captured.push(first);

    let player = Command::new("canplayer")
        .args(["-I", &log_path.to_string_lossy()])
        .status()
        .context("canplayer (can-utils)")?;
    ensure!(player.success(), "canplayer failed: {player}");
    // Let the watchdog trip and a few safe reports go out.
    let until = std::time::Instant::now() + Duration::from_secs(3);
    while let Ok(l) = lines.recv_timeout(until.saturating_duration_since(std::time::Instant::now()))
    {
        captured.push(l);
    }
    drop(sim);
    drop(candump);
    Ok(captured)
}

/// Every candump line `captured`, E2E-checked per sender and decoded, with candump's
/// kernel timestamp.
fn decode(captured: &[String]) -> Result<Vec<(f64, GolfCarMessage)>> {
    let mut rx = E2eRx::new(&NETWORK);
    let mut frames = Vec::new();
    for l in captured {
        let f = parse_line(l).with_context(|| format!("candump line {l:?}"))?;
        let ts: f64 = f.timestamp.as_deref().unwrap_or("0").parse()?;
        let (id, payload) = rx
            .accept_parts(f.id, f.extended, f.remote, &f.data)
            .with_context(|| format!("E2E of {l:?}"))?;
        frames.push((ts, GolfCarMessage::decode(id, &payload)?));
    }
    Ok(frames)
}

/// While commanded (up to `last_cmd`): the angle the `steering` reports rises to the
/// target, never faster than the rate limit.
fn steering_ramps_at_its_rate_limit(
    steering: &[(f64, SteeringReport)],
    last_cmd: f64,
) -> Result<()> {
    let steer_period = period_of::<SteeringReport>();
    let limit = ugv_sim_limit();
    let during: Vec<_> = steering.iter().filter(|(t, _)| *t <= last_cmd).collect();
    ensure!(
        during.iter().any(|(_, r)| r.enabled),
        "the steering ECU never enabled"
    );
    for r in &during {
        ensure!(
            r.1.rate.abs() <= limit + 0.05,
            "reported rate {} > {limit}",
            r.1.rate
        );
    }
    let start = steering
        .iter()
        .position(|(_, r)| r.angle > 0.5)
        .context("the angle never moved")?;
    let end = steering
        .iter()
        .position(|(_, r)| r.angle >= TARGET_DEG - 0.1)
        .context("never reached the target")?;
    let min_time = (TARGET_DEG - 0.1 - steering[start].1.angle) / limit;
    // One period of slack: where in its report period the ramp started.
    let ramp = (end - start) as f64 * steer_period;
    ensure!(
        ramp >= min_time - steer_period,
        "ramp of {ramp:.3} s ({} reports) is faster than the rate limit allows ({min_time:.3} s)",
        end - start
    );
    Ok(())
}

/// The times reports `received` at these times were due at, `period` apart. The ECUs'
/// reports are judged in the ECUs' own time. A simulator that stalls catches up
/// afterwards, sending its late ticks' reports in a burst, so a report's receive time is
/// only a bound: never before it was due. While an ECU stays in one state its reports
/// are periodic (it also reports at once on entering or leaving its enabled state), so
/// within such a run report i is due at t0 + i periods, t0 the tightest bound the
/// reports sent on time give. The ticks take in the commands by their kernel receive
/// times, the ones candump shows: one clock for both.
fn due_times(received: &[f64], period: f64) -> Vec<f64> {
    let t0 = received
        .iter()
        .enumerate()
        .map(|(i, t)| t - i as f64 * period)
        .fold(f64::INFINITY, f64::min);
    (0..received.len())
        .map(|i| t0 + i as f64 * period)
        .collect()
}

/// After the commands stop (the last at `last_cmd`): both ECUs go to their safe state,
/// with at most one report period beyond the command timeout still enabled. Counted
/// over the ECU's enabled run, from a report period after it enabled (its on-change
/// report) to its safe report.
fn both_ecus_go_safe_after_the_commands_stop(
    steering: &[(f64, SteeringReport)],
    throttle: &[(f64, ThrottleReport)],
    last_cmd: f64,
) -> Result<()> {
    for (name, period, timeout, reports) in [
        (
            "steering",
            period_of::<SteeringReport>(),
            safety_timing(&CanConfig::default(), SteeringCmd::ID).command_timeout,
            steering
                .iter()
                .map(|(t, r)| (*t, r.enabled, r.fault != SteeringReportFault::None))
                .collect::<Vec<_>>(),
        ),
        (
            "throttle",
            period_of::<ThrottleReport>(),
            safety_timing(&CanConfig::default(), ThrottleCmd::ID).command_timeout,
            throttle
                .iter()
                .map(|(t, r)| (*t, r.enabled, r.fault != ThrottleReportFault::None))
                .collect(),
        ),
    ] {
        let enabled = reports
            .iter()
            .position(|(_, enabled, _)| *enabled)
            .with_context(|| format!("{name} never enabled"))?;
        let safe = enabled
            + reports[enabled..]
                .iter()
                .position(|(_, enabled, fault)| !enabled && *fault)
                .with_context(|| format!("{name} never reported its safe state"))?;
        let run = reports.get(enabled + 2..safe).unwrap_or_default();
        ensure!(
            run.len() > 10 && run.iter().all(|(_, enabled, _)| *enabled),
            "{name}: not a steady enabled run before the safe state: {} reports",
            run.len()
        );
        let received: Vec<f64> = run.iter().map(|(t, ..)| *t).collect();
        let due = due_times(&received, period);
        let still_enabled = due.iter().filter(|due| **due > last_cmd).count();
        let allowed = (timeout / period).round() as usize + 1;
        let last_due = due.last().copied().unwrap_or(last_cmd);
        let late = received
            .iter()
            .zip(&due)
            .map(|(r, d)| r - d)
            .fold(0.0, f64::max);
        eprintln!(
            "{name}: {still_enabled} enabled reports after the last command ({allowed} allowed), \
             the safe state {:.1}-{:.1} ms after it; reports received up to {:.1} ms after due",
            (last_due - last_cmd) * 1000.0,
            (last_due + period - last_cmd) * 1000.0,
            late * 1000.0
        );
        ensure!(
            still_enabled <= allowed,
            "{name}: {still_enabled} enabled reports after the last command, {allowed} allowed"
        );
    }
    Ok(())
}

fn ugv_sim_limit() -> f64 {
    ugv_sim::scenario::SteeringConfig::default().max_rate_deg_s
}
