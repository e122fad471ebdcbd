//! The simulated ECUs as CAN nodes, in lockstep on the memory bus (the same bytes and
//! E2E checks as on vcan0): step responses, the watchdog and the safe state.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used, clippy::panic)]

use firmware_bridge::can::membus::{MemBus, MemEndpoint};
use firmware_bridge::{CanPort, Received};
use golf_car_can::{
    ControllerHeartbeat, ControllerHeartbeatState, GolfCarMessage, SteeringCmd, SteeringReport,
    SteeringReportFault, ThrottleCmd, ThrottleCmdGear, ThrottleReport, ThrottleReportFault,
};
use ugv_sim::scenario::Scenario;
use ugv_sim::{Outcome, Sim};

/// A scripted controller on the bus: what it sends at each 10 ms slot.
struct Bench {
    sim: Sim<MemEndpoint>,
    ctl: CanPort<MemEndpoint>,
    steering: Vec<(f64, SteeringReport)>,
    throttle: Vec<(f64, ThrottleReport)>,
}

fn empty_world() -> Scenario {
    let mut s = Scenario::default();
    s.sim.time_limit_s = 1000.0;
    s.success.reach_goal = false;
    s
}

impl Bench {
    fn new(scenario: Scenario) -> Bench {
        let bus = MemBus::new();
        let sim = Sim::new(
            scenario,
            CanPort::new(bus.endpoint(), "mem"),
            CanPort::new(bus.endpoint(), "mem"),
        );
        Bench {
            sim,
            ctl: CanPort::new(bus.endpoint(), "mem"),
            steering: Vec::new(),
            throttle: Vec::new(),
        }
    }

    /// Run until `until` seconds; every 10 ms `control(t)` says what the controller sends.
    fn run(&mut self, until: f64, mut control: impl FnMut(f64) -> Vec<GolfCarMessage>) {
        let dt = self.sim.dt();
        while self.sim.next_tick() as f64 * dt <= until + 1e-9 {
            let k = self.sim.next_tick();
            let t = k as f64 * dt;
            if k.is_multiple_of((0.01 / dt).round() as u64) {
                for m in control(t) {
                    self.ctl.send_message(&m).expect("send");
                }
            }
            let outcome = self.sim.step(t, 0.0).expect("step");
            assert!(outcome.is_none(), "unexpected end {outcome:?}");
            while let Some(r) = self.ctl.try_recv() {
                match r {
                    Received::Message(GolfCarMessage::SteeringReport(s)) => {
                        self.steering.push((t, s))
                    }
                    Received::Message(GolfCarMessage::ThrottleReport(s)) => {
                        self.throttle.push((t, s))
                    }
                    Received::Message(GolfCarMessage::FaultReport(_)) => {}
                    other => panic!("controller got {other:?}"),
                }
            }
        }
        assert_eq!(self.ctl.stats().rejected(), 0);
    }
}

fn heartbeat(state: ControllerHeartbeatState) -> GolfCarMessage {
    GolfCarMessage::ControllerHeartbeat(ControllerHeartbeat { state })
}

fn steer(enable: bool, angle: f64) -> GolfCarMessage {
    GolfCarMessage::SteeringCmd(SteeringCmd {
        enable,
        target_angle: angle,
        max_rate: 0.0,
    })
}

fn drive(enable: bool, speed: f64) -> GolfCarMessage {
    GolfCarMessage::ThrottleCmd(ThrottleCmd {
        enable,
        gear: ThrottleCmdGear::Forward,
        brake: 0.0,
        target_speed: speed,
        accel_limit: 0.0,
    })
}

/// Heartbeat in auto, the enable edge at 50 ms, then the given targets until `stop`.
fn script(stop: f64, angle: f64, speed: f64) -> impl FnMut(f64) -> Vec<GolfCarMessage> {
    move |t| {
        if t >= stop {
            return Vec::new();
        }
        let enable = t >= 0.05;
        vec![
            heartbeat(ControllerHeartbeatState::Auto),
            steer(enable, if enable { angle } else { 0.0 }),
            drive(enable, if enable { speed } else { 0.0 }),
        ]
    }
}

#[test]
fn steering_step_response_respects_dead_time_lag_and_rate_limit() {
    let sc = empty_world();
    let limit = sc.steering.max_rate_deg_s;
    let mut b = Bench::new(sc.clone());
    b.run(3.0, script(10.0, 20.0, 0.0));
    let reports = &b.steering;
    assert!(
        reports.len() >= 290,
        "reports every 10 ms: {}",
        reports.len()
    );
    // Nothing moves before the enable edge plus the dead time.
    for (t, r) in reports {
        if *t <= 0.05 + sc.steering.dead_time_s {
            assert!(r.angle.abs() < 1e-9, "moved at {t}: {r:?}");
        }
    }
    // The rate never exceeds the motor's limit (reports are 10 ms apart).
    for w in reports.windows(2) {
        let rate = (w[1].1.angle - w[0].1.angle) / (w[1].0 - w[0].0);
        assert!(
            rate.abs() <= limit * 1.001 + 0.01 / 0.01,
            "rate {rate} deg/s > {limit}"
        );
        assert!(w[1].1.rate.abs() <= limit + 0.05);
    }
    // Rate-limited ramp: 20 degrees at 60 deg/s needs at least a third of a second.
    let reached = reports
        .iter()
        .find(|(_, r)| r.angle >= 19.9)
        .expect("reaches the target")
        .0;
    assert!(
        reached >= 0.05 + sc.steering.dead_time_s + 20.0 / limit,
        "{reached}"
    );
    assert!(reached <= 1.5, "{reached}");
    let last = reports.last().expect("reports").1;
    assert!(
        (last.angle - 20.0).abs() < 0.02 && last.enabled && last.fault == SteeringReportFault::None
    );
    // The vehicle model saw the actual angle.
    assert!((b.sim.vehicle.phi.to_degrees() - 20.0).abs() < 0.02);
}

#[test]
fn angle_commands_are_limited_to_the_vehicle_limit() {
    let sc = empty_world();
    let mut b = Bench::new(sc.clone());
    b.run(3.0, script(10.0, -44.0, 0.0));
    let last = b.steering.last().expect("reports").1;
    assert!(
        (last.angle + sc.vehicle.max_steer_deg).abs() < 0.02,
        "{last:?}"
    );
}

#[test]
fn throttle_step_response_respects_acceleration_limit() {
    let sc = empty_world();
    let mut b = Bench::new(sc.clone());
    b.run(12.0, script(100.0, 0.0, 3.0));
    let r = &b.throttle;
    for w in r.windows(2) {
        let accel = (w[1].1.wheel_speed - w[0].1.wheel_speed) / (w[1].0 - w[0].0);
        assert!(accel <= sc.throttle.max_accel + 1.0, "accel {accel}"); // 0.01 m/s quantisation
    }
    let last = r.last().expect("reports").1;
    assert!((last.wheel_speed - 3.0).abs() < 0.02, "{last:?}");
    assert!(last.throttle > 0.0 && last.enabled);
    // Mean acceleration over the first second of motion is within the limit.
    let start = r
        .iter()
        .find(|(_, x)| x.wheel_speed > 0.0)
        .expect("moves")
        .0;
    let after = r
        .iter()
        .find(|(t, _)| *t >= start + 1.0)
        .expect("later")
        .1
        .wheel_speed;
    assert!(
        after <= sc.throttle.max_accel * 1.0 + 0.02,
        "{after} m/s after 1 s"
    );
    // The vehicle drove: about 3 m/s for most of the run.
    assert!(b.sim.vehicle.odometer > 20.0, "{}", b.sim.vehicle.odometer);
}

#[test]
fn both_ecus_report_the_safe_state_within_timeout_plus_one_period_when_commands_stop() {
    let sc = empty_world();
    let mut b = Bench::new(sc);
    let stop = 2.0;
    b.run(3.0, script(stop, 10.0, 2.0));
    let last_cmd = stop - 0.01;
    let bound = last_cmd + 0.1 + 0.01 + 1e-9;
    let first_safe_steer = b
        .steering
        .iter()
        .find(|(t, r)| *t > last_cmd && !r.enabled)
        .expect("steering safe");
    assert!(
        first_safe_steer.0 <= bound,
        "steering safe at {}",
        first_safe_steer.0
    );
    assert_eq!(
        first_safe_steer.1.fault,
        SteeringReportFault::HeartbeatTimeout
    );
    let first_safe_thr = b
        .throttle
        .iter()
        .find(|(t, r)| *t > last_cmd && !r.enabled)
        .expect("throttle safe");
    assert!(
        first_safe_thr.0 <= bound,
        "throttle safe at {}",
        first_safe_thr.0
    );
    // The throttle ECU timed out too, or already saw the steering ECU's FAULT_REPORT
    // (the more severe cause is reported).
    assert!(
        matches!(
            first_safe_thr.1.fault,
            ThrottleReportFault::HeartbeatTimeout | ThrottleReportFault::FaultReport
        ),
        "{:?}",
        first_safe_thr.1
    );
    // Safe state: steering holds its angle, throttle zero with full brake, car stops.
    let held = first_safe_steer.1.angle;
    for (_, r) in b.steering.iter().filter(|(t, _)| *t > first_safe_steer.0) {
        assert!((r.angle - held).abs() < 1e-9 && !r.enabled);
    }
    let last = b.throttle.last().expect("reports").1;
    assert_eq!((last.throttle, last.brake), (0.0, 100.0));
    assert!(last.wheel_speed.abs() < 1e-9, "{last:?}");
}

#[test]
fn estop_and_fault_reports_force_the_safe_state_and_need_an_enable_edge() {
    let sc = empty_world();
    let mut b = Bench::new(sc);
    b.run(1.0, script(100.0, 5.0, 1.0));
    assert!(b.steering.last().expect("r").1.enabled);
    // Estop heartbeat.
    b.run(1.3, |_| {
        vec![
            heartbeat(ControllerHeartbeatState::Estop),
            steer(true, 5.0),
            drive(true, 1.0),
        ]
    });
    let r = b.steering.last().expect("r").1;
    assert!(!r.enabled && r.fault == SteeringReportFault::Estop);
    // Back in auto with enable held at 1: fault clears, but it stays disabled.
    b.run(1.6, |_| {
        vec![
            heartbeat(ControllerHeartbeatState::Auto),
            steer(true, 5.0),
            drive(true, 1.0),
        ]
    });
    let r = b.steering.last().expect("r").1;
    assert!(!r.enabled && r.fault == SteeringReportFault::None, "{r:?}");
    // The explicit enable (0 then 1) re-enables.
    b.run(1.7, |_| {
        vec![
            heartbeat(ControllerHeartbeatState::Auto),
            steer(false, 5.0),
            drive(false, 1.0),
        ]
    });
    b.run(1.9, |_| {
        vec![
            heartbeat(ControllerHeartbeatState::Auto),
            steer(true, 5.0),
            drive(true, 1.0),
        ]
    });
    assert!(b.steering.last().expect("r").1.enabled);
    assert!(b.throttle.last().expect("r").1.enabled);
    // A FAULT_REPORT from the controller puts both in the safe state.
    b.run(2.0, |_| {
        vec![
            heartbeat(ControllerHeartbeatState::Auto),
            steer(true, 5.0),
            drive(true, 1.0),
            GolfCarMessage::FaultReport(golf_car_can::FaultReport {
                source: golf_car_can::FaultReportSource::Controller,
                code: golf_car_can::FaultReportCode::GpsLost,
                detail: 0,
            }),
        ]
    });
    let (s, t) = (
        b.steering.last().expect("r").1,
        b.throttle.last().expect("r").1,
    );
    assert!(!s.enabled && s.fault == SteeringReportFault::FaultReport);
    assert!(!t.enabled && t.fault == ThrottleReportFault::FaultReport);
}

#[test]
fn a_run_ends_with_the_time_limit_and_a_report() {
    let mut sc = empty_world();
    sc.sim.time_limit_s = 0.5;
    let bus = MemBus::new();
    let mut sim = Sim::new(
        sc,
        CanPort::new(bus.endpoint(), "mem"),
        CanPort::new(bus.endpoint(), "mem"),
    );
    let outcome = loop {
        let t = sim.next_tick() as f64 * sim.dt();
        if let Some(o) = sim.step(t, 0.0).expect("step") {
            break o;
        }
    };
    assert!(matches!(outcome, Outcome::TimeLimit { time } if (time - 0.5).abs() < 1e-9));
    let report = sim.report(outcome);
    // Both ECUs sent a report every 10 ms and nothing was rejected.
    assert_eq!(report.steering_can.sent, 51);
    assert_eq!(report.throttle_can.sent, 51);
    assert_eq!(report.steering_can.e2e.rejected(), 0);
}
