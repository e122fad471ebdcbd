//! The controller's mode machine and safety stops, driven with synthetic inputs: it
//! waits for its sensors, sends the enable edge, drives, and goes to estop (heartbeat
//! estop, ECUs disabled with full brake, FAULT_REPORT) on laser silence, a silent ECU
//! report, an actuator fault or a lost GPS fix; no command ever leaves its limits.
//! Facing a dead end it backs out in gear R without tripping its own watches.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used)]

use firmware_bridge::Received;
use firmware_bridge::geodesy::{Enu, LocalFrame, theta_to_course_deg};
use firmware_bridge::laser::LaserFrame;
use firmware_bridge::nmea::{FixQuality, GpsReading};
use golf_car_can::{
    ControllerHeartbeatState, FaultReportCode, GolfCarMessage, SteeringReport, SteeringReportFault,
    ThrottleCmdGear, ThrottleReport, ThrottleReportFault, ThrottleReportGear,
};
use ugv_controller::config::ControllerConfig;
use ugv_controller::control::{Controller, Mode};

struct Rig {
    cfg: ControllerConfig,
    ctl: Controller,
    frame: LocalFrame,
    ranges: Vec<f32>,
    out: Vec<GolfCarMessage>,
}

/// Which inputs keep coming.
#[derive(Clone, Copy)]
struct Feed {
    gps: bool,
    laser: bool,
    reports: bool,
    steering_fault: bool,
    /// Scans keep coming but perception refuses each (a NaN angle increment).
    refused_scans: bool,
}

const ALL: Feed = Feed {
    gps: true,
    laser: true,
    reports: true,
    steering_fault: false,
    refused_scans: false,
};

impl Rig {
    fn new() -> Rig {
        let cfg = ControllerConfig::default();
        Rig {
            ctl: Controller::new(&cfg).expect("controller"),
            frame: LocalFrame::new(cfg.mission.datum.geodetic()).expect("datum"),
            cfg,
            ranges: vec![f32::INFINITY; 541],
            out: Vec::new(),
        }
    }

    /// Tick every 10 ms from `from` to `to` with the given inputs.
    fn run(&mut self, from: f64, to: f64, feed: Feed) {
        let mut k = (from / 0.01).round() as u64;
        while (k as f64) * 0.01 < to - 1e-9 {
            let now = k as f64 * 0.01;
            let enabled = matches!(self.ctl.mode(), Mode::Enabling { .. } | Mode::Auto);
            if feed.reports {
                let steering = SteeringReport {
                    enabled,
                    fault: if feed.steering_fault {
                        SteeringReportFault::Overcurrent
                    } else {
                        SteeringReportFault::None
                    },
                    ..SteeringReport::default()
                };
                let throttle = ThrottleReport {
                    enabled,
                    gear: ThrottleReportGear::Forward,
                    fault: ThrottleReportFault::None,
                    ..ThrottleReport::default()
                };
                self.ctl.on_can(
                    now,
                    &Received::Message(GolfCarMessage::SteeringReport(steering)),
                );
                self.ctl.on_can(
                    now,
                    &Received::Message(GolfCarMessage::ThrottleReport(throttle)),
                );
            }
            if feed.gps && k.is_multiple_of(10) {
                let theta = 45f64.to_radians();
                let ax = self.cfg.vehicle.antenna_x;
                let g = self.frame.to_geodetic(Enu {
                    east_m: ax * theta.cos(),
                    north_m: ax * theta.sin(),
                    up_m: 0.0,
                });
                let reading = GpsReading {
                    quality: Some(FixQuality::RtkFixed),
                    lat_deg: Some(g.lat_deg),
                    lon_deg: Some(g.lon_deg),
                    altitude_msl_m: Some(g.height_m),
                    geoid_separation_m: Some(0.0),
                    heading_deg: Some(theta_to_course_deg(theta)),
                    speed_mps: Some(0.0),
                    course_deg: Some(0.0),
                    ..GpsReading::default()
                };
                self.ctl.on_gps(now, &reading);
            }
            if feed.laser && k.is_multiple_of(2) {
                // As the loop hands them over: the frame, checked as a scan once there.
                let mut frame = LaserFrame {
                    angle_min: -135f32.to_radians(),
                    angle_increment: if feed.refused_scans {
                        f32::NAN
                    } else {
                        0.5f32.to_radians()
                    },
                    range_min: 0.5,
                    range_max: 20.0,
                    ..LaserFrame::default()
                };
                frame.set_beams(&self.ranges, &[]).expect("541 beams");
                self.ctl.on_laser_frame(now, &frame);
            }
            let msgs = self.ctl.tick(now);
            self.out.extend(msgs);
            k += 1;
        }
    }

    fn drive(&mut self) {
        self.run(0.0, 1.0, ALL);
        assert_eq!(
            self.ctl.mode(),
            &Mode::Auto,
            "drives with every input present"
        );
    }

    fn last_heartbeat(&self) -> Option<ControllerHeartbeatState> {
        self.out.iter().rev().find_map(|m| match m {
            GolfCarMessage::ControllerHeartbeat(h) => Some(h.state),
            _ => None,
        })
    }

    fn assert_safe_stop(&self, code: FaultReportCode) {
        assert!(
            matches!(self.ctl.mode(), Mode::Estop { .. }),
            "{:?}",
            self.ctl.mode()
        );
        assert_eq!(self.last_heartbeat(), Some(ControllerHeartbeatState::Estop));
        let (steer, throttle) = self.out.iter().rev().fold((None, None), |acc, m| match m {
            GolfCarMessage::SteeringCmd(c) if acc.0.is_none() => (Some(*c), acc.1),
            GolfCarMessage::ThrottleCmd(c) if acc.1.is_none() => (acc.0, Some(*c)),
            _ => acc,
        });
        let (steer, throttle) = (
            steer.expect("steering command"),
            throttle.expect("throttle command"),
        );
        assert!(!steer.enable && !throttle.enable);
        assert_eq!((throttle.target_speed, throttle.brake), (0.0, 100.0));
        assert!(
            self.out
                .iter()
                .any(|m| matches!(m, GolfCarMessage::FaultReport(f) if f.code == code)),
            "a FAULT_REPORT with {code:?}"
        );
    }

    /// Every command ever sent is within the DBC's and the vehicle's limits.
    fn assert_limits(&self) {
        let v = &self.cfg.vehicle;
        for m in &self.out {
            match m {
                GolfCarMessage::SteeringCmd(c) => {
                    assert!(
                        c.target_angle.abs() <= v.max_steer_deg && c.max_rate >= 0.0,
                        "{c:?}"
                    );
                }
                GolfCarMessage::ThrottleCmd(c) => {
                    assert!((0.0..=v.max_speed).contains(&c.target_speed), "{c:?}");
                    assert!(
                        (0.0..=100.0).contains(&c.brake) && (0.0..=5.0).contains(&c.accel_limit),
                        "{c:?}"
                    );
                }
                _ => {}
            }
            assert!(m.encode().is_ok(), "{m:?} encodes within the DBC's ranges");
        }
    }
}

#[test]
fn waits_for_sensors_then_enables_with_an_edge_and_drives() {
    let mut rig = Rig::new();
    rig.run(
        0.0,
        0.3,
        Feed {
            laser: false,
            ..ALL
        },
    );
    assert_eq!(rig.ctl.mode(), &Mode::WaitingForSensors, "no laser yet");
    assert_eq!(rig.last_heartbeat(), Some(ControllerHeartbeatState::Idle));
    rig.run(0.3, 1.5, ALL);
    assert_eq!(rig.ctl.mode(), &Mode::Auto);
    // The enable bit went low then high (the explicit enable edge).
    let bits: Vec<bool> = rig
        .out
        .iter()
        .filter_map(|m| match m {
            GolfCarMessage::SteeringCmd(c) => Some(c.enable),
            _ => None,
        })
        .collect();
    let edge = bits
        .windows(2)
        .position(|w| !w[0] && w[1])
        .expect("an enable edge");
    assert!(bits[edge + 1..].iter().all(|b| *b));
    assert_eq!(rig.last_heartbeat(), Some(ControllerHeartbeatState::Auto));
    rig.assert_limits();
}

/// A replay of the controller's own recording takes each replanning at the tick the
/// recorded loop took it from its planning thread, and none while one waits.
#[test]
fn replannings_are_taken_at_the_recorded_ticks() {
    let mut rig = Rig::new();
    rig.ctl = Controller::new(&rig.cfg)
        .expect("controller")
        .with_plans_taken_at(vec![0.25, 0.6]);
    rig.run(0.0, 0.24, ALL);
    assert!(rig.ctl.nav.plans.is_empty(), "the first waits for 0.25 s");
    rig.run(0.24, 0.59, ALL);
    assert_eq!((rig.ctl.nav.plans.len(), rig.ctl.nav.accepted()), (1, 1));
    rig.run(0.59, 1.5, ALL);
    // The third was asked for but the recording took no more.
    assert_eq!((rig.ctl.nav.plans.len(), rig.ctl.nav.accepted()), (2, 2));
    assert_eq!(
        rig.ctl.nav.plans[0].time, 0.0,
        "asked for at the first tick"
    );
}

#[test]
fn start_up_gaps_pass_while_disabled_and_the_first_path_is_planned_before_enabling() {
    let mut rig = Rig::new();
    let settle = rig.cfg.safety.settle_s;
    assert!(settle >= 0.3, "{settle}");
    rig.run(0.0, 0.2, ALL);
    // A stall at start-up: the reports stop for longer than their timeout.
    rig.run(
        0.2,
        0.7,
        Feed {
            reports: false,
            ..ALL
        },
    );
    assert_eq!(rig.ctl.mode(), &Mode::WaitingForSensors, "no estop yet");
    // Steady again from 0.7 s: still waiting until the inputs have been steady for
    // settle_s, with the first path already planned.
    rig.run(0.7, 0.7 + settle - 0.02, ALL);
    assert_eq!(rig.ctl.mode(), &Mode::WaitingForSensors);
    assert!(!rig.ctl.nav.plans.is_empty(), "planned while waiting");
    rig.run(0.7 + settle - 0.02, 0.7 + settle + 0.03, ALL);
    assert!(
        matches!(rig.ctl.mode(), Mode::Enabling { .. } | Mode::Auto),
        "{:?}",
        rig.ctl.mode()
    );
    rig.run(0.7 + settle + 0.03, 0.7 + settle + 0.5, ALL);
    assert_eq!(rig.ctl.mode(), &Mode::Auto);
    // No fault was reported while the reports were missing.
    assert!(
        !rig.out
            .iter()
            .any(|m| matches!(m, GolfCarMessage::FaultReport(_))),
        "no fault reported"
    );
    rig.assert_limits();
}

#[test]
fn a_car_in_a_dead_end_commands_gear_reverse_and_stays_in_auto() {
    let mut rig = Rig::new();
    // Returns 3 m from the laser over the whole front half: a cup round the nose.
    for (i, r) in rig.ranges.iter_mut().enumerate() {
        let angle = -135.0 + 0.5 * i as f64;
        if angle.abs() <= 90.0 {
            *r = 3.0;
        }
    }
    rig.drive();
    let throttle = |out: &[GolfCarMessage]| {
        out.iter()
            .filter_map(|m| match m {
                GolfCarMessage::ThrottleCmd(c) => Some(*c),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
    rig.run(1.0, 1.0 + rig.cfg.planner.recover_after_s + 1.0, ALL);
    let pc = &rig.cfg.planner;
    // It backs out at once, by a manoeuvre into the space behind it its operator checked
    // (no waiting for recovery): gear R, enabled, no brake, at most the reverse speed.
    let cmds = throttle(&rig.out);
    let reversing: Vec<_> = cmds
        .iter()
        .filter(|c| c.gear == ThrottleCmdGear::Reverse)
        .collect();
    assert!(!reversing.is_empty(), "{:?}", rig.ctl.stop_reason());
    assert!(
        reversing
            .iter()
            .all(|c| c.enable && c.brake == 0.0 && c.target_speed <= pc.reverse_speed + 1e-9),
        "{reversing:?}"
    );
    assert!(reversing.iter().any(|c| c.target_speed > 0.0));
    assert_eq!(rig.ctl.mode(), &Mode::Auto, "no watch took it for a fault");
    assert_eq!(rig.ctl.stop_reason(), None);
    // A manoeuvre, not recovery's straight reversal.
    assert_eq!(rig.ctl.nav.reversals(), 0);
    rig.assert_limits();
}

#[test]
fn laser_silence_stops_the_car() {
    let mut rig = Rig::new();
    rig.drive();
    rig.run(
        1.0,
        1.5,
        Feed {
            laser: false,
            ..ALL
        },
    );
    rig.assert_safe_stop(FaultReportCode::LaserSilent);
    rig.assert_limits();
}

/// Issue 11, finding 1: a NaN laser mounting made perception drop every scan while
/// the watchdog was refreshed anyway, and the car drove blind into the post.
#[test]
fn scans_perception_refuses_count_as_laser_silence() {
    let mut rig = Rig::new();
    rig.drive();
    let bad_before = rig.ctl.bad_scans;
    rig.run(
        1.0,
        1.5,
        Feed {
            refused_scans: true,
            ..ALL
        },
    );
    assert!(rig.ctl.bad_scans > bad_before + 10, "{}", rig.ctl.bad_scans);
    rig.assert_safe_stop(FaultReportCode::LaserSilent);
    match rig.ctl.mode() {
        Mode::Estop { reason, .. } => assert!(reason.contains("no laser scan"), "{reason}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_silent_ecu_report_stops_the_car() {
    let mut rig = Rig::new();
    rig.drive();
    rig.run(
        1.0,
        1.5,
        Feed {
            reports: false,
            ..ALL
        },
    );
    rig.assert_safe_stop(FaultReportCode::ReportTimeout);
}

#[test]
fn an_actuator_fault_stops_the_car() {
    let mut rig = Rig::new();
    rig.drive();
    rig.run(
        1.0,
        1.2,
        Feed {
            steering_fault: true,
            ..ALL
        },
    );
    rig.assert_safe_stop(FaultReportCode::ActuatorFault);
}

#[test]
fn gps_loss_stops_the_car_and_estop_is_latched() {
    let mut rig = Rig::new();
    rig.drive();
    rig.run(1.0, 2.0, Feed { gps: false, ..ALL });
    rig.assert_safe_stop(FaultReportCode::GpsLost);
    // The fix comes back: the estop stays until the controller is restarted.
    rig.run(2.0, 3.0, ALL);
    assert!(matches!(rig.ctl.mode(), Mode::Estop { .. }));
    rig.assert_limits();
}
