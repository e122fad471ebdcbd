//! Whatever ends the controller, the car ends safe, and the verdict says how fast: the
//! controller library's loop (the binary's) run in SIL with its ports failing under it
//! (issue 11, findings 2 and 4; issue 12: a SIL test drives the estop-on-exit path).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use firmware_bridge::laser::LaserFrame;
use ugv_controller::config::FollowerKind;
use ugv_controller::control::Mode;
use ugv_controller::runtime::Exit;
use ugv_sim::Outcome;
use ugv_sim::mission::controller_config;
use ugv_sim::run::SafeStateReport;
use ugv_sim::scenario::Scenario;
use ugv_sim::sil::{Hook, SilRun, run_sil_with};
use ugv_sim::verdict::Verdict;

fn paper() -> Scenario {
    Scenario::paper().expect("the paper scenario")
}

fn run(hook: impl FnMut(f64, &mut ugv_sim::sil::SilController) -> Hook) -> (SilRun, Verdict) {
    let sc = paper();
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    let run = run_sil_with(sc.clone(), &cfg, hook).expect("SIL run");
    let verdict = Verdict::judge(
        ugv_sim::Mode::Sil,
        &sc,
        run.sim.report(run.outcome.clone()),
        Some(&run.trace),
    );
    (run, verdict)
}

fn safe_state(v: &Verdict) -> &SafeStateReport {
    v.report
        .safe_state
        .as_ref()
        .unwrap_or_else(|| panic!("no safe-state report: {:#?}", v.report))
}

#[test]
fn a_lost_gps_port_estops_the_car_before_the_controller_exits() {
    // Today's binary exits with code 4 at once: no estop heartbeat, no FAULT_REPORT.
    let (run, v) = run(|now, rt| {
        if now >= 5.0 {
            rt.gps_mut().close("the serial device went away");
        }
        Hook::Continue
    });
    match &run.controller_exit {
        Some(Exit::PortLost { reason }) => assert!(reason.contains("GPS port lost"), "{reason}"),
        other => panic!("{other:?}"),
    }
    match &run.trace.mode {
        Mode::Estop { code, reason } => {
            assert_eq!(code, "gps_lost");
            assert!(reason.contains("serial device went away"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    let s = safe_state(&v);
    // Both ECUs saw the estop while the controller still ran: they reported their safe
    // state before its last (disabled) command, so the latency is negative.
    for e in [&s.steering, &s.throttle] {
        assert!(e.within_bound, "{s:#?}");
        let (safe, last) = (
            e.safe_report_s.expect("safe"),
            e.last_command_s.expect("cmd"),
        );
        assert!(safe < last && (5.0..5.1).contains(&safe), "{s:#?}");
    }
    // The estop (heartbeat estop, then FAULT_REPORT) put them there, not a timeout.
    let (steering, throttle) = (&v.report.steering_can, &v.report.throttle_can);
    assert!(steering.safe_state_trips[2] >= 1, "{steering:?}");
    assert!(throttle.safe_state_trips[2] >= 1, "{throttle:?}");
    assert!(s.stopped_s.is_some(), "{s:#?}");
    assert!(
        v.report.final_state.v.abs() < 0.05,
        "{:?}",
        v.report.final_state
    );
    assert!(matches!(v.report.outcome, Outcome::Stopped { .. }));
    assert!(!v.passed, "the mission was not completed");
    assert!(
        v.failures.iter().all(|f| !f.contains("ECU")),
        "{:?}",
        v.failures
    );
}

#[test]
fn a_killed_controller_leaves_both_ecus_safe_within_timeout_plus_one_period() {
    let (run, v) = run(|now, _| {
        if now >= 5.0 {
            Hook::Kill
        } else {
            Hook::Continue
        }
    });
    assert_eq!(run.controller_exit, None, "killed, not exited");
    let s = safe_state(&v);
    assert!(s.speed_then > 1.0, "the car was driving: {s:#?}");
    for e in [&s.steering, &s.throttle] {
        let l = e.latency_ms.expect("a latency");
        // The heartbeat's or the commands' timeout (100 ms each) has to pass: the
        // last heartbeat went out up to one heartbeat period (20 ms) before the last
        // command. Then the ECU trips within one physics step (5 ms at 200 Hz) and
        // reports it at once.
        assert!(l > 80.0 - 1e-6 && l <= e.bound_ms, "{s:#?}");
        assert!(e.within_bound, "{s:#?}");
        assert_eq!(e.bound_ms, 110.0);
    }
    // A timeout put them there (no estop was ever sent).
    for stats in [&v.report.steering_can, &v.report.throttle_can] {
        let t = stats.safe_state_trips;
        assert!(t[0] + t[1] >= 1 && t[2] == 0, "{stats:?}");
    }
    let stopped = s.stopped_s.expect("the car stopped");
    assert!(stopped > 5.0 && stopped < 8.0, "{s:#?}");
    assert!(v.report.final_state.v.abs() < 0.05);
    match &v.report.outcome {
        Outcome::Stopped { reason, time } => {
            assert!(reason.contains("killed"), "{reason}");
            assert!(*time >= stopped, "the run went on until the car was safe");
        }
        other => panic!("{other:?}"),
    }
    assert!(!v.collision);
}

#[test]
fn malformed_laser_frames_are_counted_and_skipped_and_the_mission_goes_on() {
    // A frame of another version on the shared-memory service ended today's loop.
    let (run, v) = run(|now, rt| {
        if (3.0..4.0).contains(&now) {
            rt.laser_mut().push(Box::new(LaserFrame {
                version: 99,
                ..LaserFrame::default()
            }));
        }
        Hook::Continue
    });
    assert!(v.goal_reached, "{:?}", v.failures);
    assert!(v.passed, "{:?}", v.failures);
    assert_eq!(run.controller_exit, None);
    assert!(v.report.safe_state.is_none());
    assert_eq!(run.inputs.laser_frames_refused, 100, "{:?}", run.inputs);
    let last = run.inputs.last_error.as_deref().unwrap_or_default();
    assert!(last.contains("version 99"), "{last}");
}
