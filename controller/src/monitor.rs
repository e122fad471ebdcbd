//! The actuator monitor: the ECUs' reports checked against what was commanded, for
//! the faults an ECU does not report itself. A steering motor that no longer follows
//! (stuck, or a broken linkage), a drive that no longer slows when told to (a stuck
//! throttle), and a driver's hands on the wheel (the report's override bit) each
//! become a finding, which the safety check turns into an estop with FAULT_REPORT
//! actuator_fault. The intrusion watch (`intrusion.rs`) covers the opposite case:
//! actuation nobody commanded.

use std::collections::VecDeque;

use golf_car_can::{GolfCarMessage, SteeringReport, ThrottleCmd, ThrottleCmdGear, ThrottleReport};

/// The steering is judged over this window, seconds: if its angle moved less than
/// [`STEER_FROZEN_DEG`] over the window while a command older than [`RESPONSE_S`]
/// (dead time and lag) asked for an angle more than [`STEER_OFF_DEG`] away, it does
/// not follow. Replanning starts every path at the measured curvature, so a stuck
/// steering is re-planned around every T_s: only a frozen angle against commands
/// that keep asking for another shows it.
const STEER_WINDOW_S: f64 = 1.0;
const RESPONSE_S: f64 = 0.4;
const STEER_FROZEN_DEG: f64 = 0.3;
const STEER_OFF_DEG: f64 = 1.5;
/// The car runs faster than commanded (either way) by more than this, m/s...
const SPEED_OVER: f64 = 0.5;
/// ...and slows by less than this over [`SPEED_SPAN_S`], m/s...
const SPEED_FALL: f64 = 0.1;
const SPEED_SPAN_S: f64 = 0.5;
/// ...for this long, seconds: the drive does not follow.
const SPEED_STUCK_S: f64 = 1.0;
/// History kept, seconds: the checks' windows, and the longest steering dead time the
/// configuration allows (`vehicle.steer_dead_time_s`), over which the controller reads
/// back the steering commands still on their way ([`ActuatorMonitor::steer_command_as_of`]).
const HISTORY_S: f64 = 5.5;

/// What the monitor found.
#[derive(Clone, Debug, PartialEq)]
pub struct ActuatorFinding {
    pub at: f64,
    pub reason: String,
}

#[derive(Clone, Debug, Default)]
pub struct ActuatorMonitor {
    /// (time, enable, target angle deg)
    steer_cmds: VecDeque<(f64, bool, f64)>,
    /// (time, enable, signed target speed m/s)
    speed_cmds: VecDeque<(f64, bool, f64)>,
    /// (time, wheel speed m/s)
    speeds: VecDeque<(f64, f64)>,
    /// (time, reported angle deg) while enabled
    angles: VecDeque<(f64, f64)>,
    speed_over_since: Option<f64>,
    finding: Option<ActuatorFinding>,
}

/// The signed speed a THROTTLE_CMD asks for: its target speed (a magnitude) forwards
/// in gear F, backwards in gear R, none in neutral, m/s.
pub fn commanded_speed(c: &ThrottleCmd) -> f64 {
    match c.gear {
        ThrottleCmdGear::Forward => c.target_speed,
        ThrottleCmdGear::Reverse => -c.target_speed,
        ThrottleCmdGear::Neutral => 0.0,
    }
}

/// The newest entry at least `age` old.
fn as_of<T: Copy>(h: &VecDeque<(f64, bool, T)>, now: f64, age: f64) -> Option<(bool, T)> {
    h.iter()
        .rev()
        .find(|(t, _, _)| now - t >= age)
        .map(|(_, e, v)| (*e, *v))
}

fn trim<T>(h: &mut VecDeque<T>, now: f64, time: impl Fn(&T) -> f64) {
    while h.front().is_some_and(|x| now - time(x) > HISTORY_S) {
        h.pop_front();
    }
}

impl ActuatorMonitor {
    /// The messages the controller sent at `now`.
    pub fn commanded(&mut self, now: f64, sent: &[GolfCarMessage]) {
        for m in sent {
            match m {
                GolfCarMessage::SteeringCmd(c) => {
                    self.steer_cmds.push_back((now, c.enable, c.target_angle));
                }
                GolfCarMessage::ThrottleCmd(c) => {
                    self.speed_cmds
                        .push_back((now, c.enable, commanded_speed(c)));
                }
                _ => {}
            }
        }
        trim(&mut self.steer_cmds, now, |x| x.0);
        trim(&mut self.speed_cmds, now, |x| x.0);
    }

    fn found(&mut self, now: f64, reason: String) {
        self.finding
            .get_or_insert(ActuatorFinding { at: now, reason });
    }

    pub fn on_steering(&mut self, now: f64, r: &SteeringReport) {
        if r.r#override {
            self.found(
                now,
                "a driver overrides the steering (STEERING_REPORT override)".to_owned(),
            );
            return;
        }
        if !r.enabled {
            self.angles.clear();
            return;
        }
        self.angles.push_back((now, r.angle));
        trim(&mut self.angles, now, |x| x.0);
        let Some(&(first, _)) = self.angles.front() else {
            return;
        };
        if now - first < STEER_WINDOW_S {
            return;
        }
        let (lo, hi) = self
            .angles
            .iter()
            .filter(|(t, _)| now - t <= STEER_WINDOW_S)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, a)| {
                (lo.min(*a), hi.max(*a))
            });
        if hi - lo >= STEER_FROZEN_DEG {
            return;
        }
        let asked: Vec<(bool, f64)> = self
            .steer_cmds
            .iter()
            .filter(|(t, _, _)| now - t <= STEER_WINDOW_S && now - t >= RESPONSE_S)
            .map(|(_, e, a)| (*e, *a))
            .collect();
        if asked.is_empty() || asked.iter().any(|(e, _)| !e) {
            return;
        }
        let farthest = asked.iter().map(|(_, a)| *a).fold(r.angle, |f, a| {
            if (a - r.angle).abs() > (f - r.angle).abs() {
                a
            } else {
                f
            }
        });
        if (farthest - r.angle).abs() > STEER_OFF_DEG {
            self.found(
                now,
                format!(
                    "the steering does not follow: at {:.1} deg (within {:.1} deg for {STEER_WINDOW_S} s) while commanded up to {farthest:.1} deg",
                    r.angle,
                    hi - lo
                ),
            );
        }
    }

    pub fn on_throttle(&mut self, now: f64, r: &ThrottleReport) {
        let v = r.wheel_speed;
        self.speeds.push_back((now, v));
        trim(&mut self.speeds, now, |x| x.0);
        let commanded = as_of(&self.speed_cmds, now, RESPONSE_S);
        let fall = self
            .speeds
            .iter()
            .rev()
            .find(|(t, _)| now - t >= SPEED_SPAN_S)
            .map(|(_, old)| old.abs() - v.abs());
        let over = match (commanded, fall) {
            (Some((true, target)), Some(fall)) if r.enabled => {
                v.abs() > target.abs() + SPEED_OVER && fall < SPEED_FALL
            }
            _ => false,
        };
        match (over, self.speed_over_since) {
            (false, _) => self.speed_over_since = None,
            (true, None) => self.speed_over_since = Some(now),
            (true, Some(since)) if now - since >= SPEED_STUCK_S => {
                let target = commanded.map_or(0.0, |c| c.1);
                self.found(
                    now,
                    format!(
                        "the drive does not follow: {v:.2} m/s for {:.1} s, commanded {target:.2} m/s",
                        now - since
                    ),
                );
            }
            (true, Some(_)) => {}
        }
    }

    /// The steering command in force `age` seconds before `now` (the newest sent at
    /// least that long ago): whether it enabled the ECU, and its angle in degrees.
    pub fn steer_command_as_of(&self, now: f64, age: f64) -> Option<(bool, f64)> {
        as_of(&self.steer_cmds, now, age)
    }

    /// The first finding, kept.
    pub fn finding(&self) -> Option<&ActuatorFinding> {
        self.finding.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use golf_car_can::{SteeringCmd, SteeringReportFault, ThrottleCmd, ThrottleCmdGear};

    fn steer_cmd(angle: f64) -> GolfCarMessage {
        GolfCarMessage::SteeringCmd(SteeringCmd {
            enable: true,
            target_angle: angle,
            max_rate: 0.0,
        })
    }

    fn steer_report(angle: f64, rate: f64) -> SteeringReport {
        SteeringReport {
            enabled: true,
            r#override: false,
            fault: SteeringReportFault::None,
            angle,
            rate,
            motor_current: 1.0,
        }
    }

    /// An enabled THROTTLE_CMD in `gear` at `speed`, no brake.
    fn drive(gear: ThrottleCmdGear, speed: f64) -> GolfCarMessage {
        GolfCarMessage::ThrottleCmd(ThrottleCmd {
            enable: true,
            gear,
            brake: 0.0,
            target_speed: speed,
            accel_limit: 0.0,
        })
    }

    /// An enabled THROTTLE_REPORT with the wheels at `v`.
    fn wheels(v: f64) -> ThrottleReport {
        ThrottleReport {
            enabled: true,
            wheel_speed: v,
            ..ThrottleReport::default()
        }
    }
    #[test]
    fn a_steering_that_follows_with_lag_is_no_finding_and_a_stuck_one_is() {
        let mut m = ActuatorMonitor::default();
        // A target stepping to 10 deg, followed at 20 deg/s after 0.2 s of dead time.
        let mut angle: f64 = 0.0;
        for k in 0..300 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[steer_cmd(10.0)]);
            let rate = if now > 0.2 && angle < 10.0 { 20.0 } else { 0.0 };
            angle = (angle + rate * 0.01).min(10.0);
            m.on_steering(now, &steer_report(angle, rate));
        }
        assert!(m.finding().is_none(), "{:?}", m.finding());
        // Now commanded to -10 deg, and the wheels stay at 10.
        for k in 300..500 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[steer_cmd(-10.0)]);
            m.on_steering(now, &steer_report(10.0, 0.0));
        }
        let f = m.finding().expect("a stuck steering is found");
        assert!(f.reason.contains("does not follow"), "{}", f.reason);
        // Found within the response time and the stuck time of the new command.
        assert!(f.at <= 3.0 + RESPONSE_S + STEER_WINDOW_S + 0.02, "{}", f.at);
    }

    #[test]
    fn a_driver_override_is_a_finding_at_once() {
        let mut m = ActuatorMonitor::default();
        let mut r = steer_report(0.0, 0.0);
        r.r#override = true;
        m.on_steering(1.0, &r);
        assert!(m.finding().is_some_and(|f| f.reason.contains("driver")));
    }

    #[test]
    fn a_drive_that_does_not_slow_is_found_and_braking_is_not() {
        let throttle = |speed| drive(ThrottleCmdGear::Forward, speed);
        // Commanded to stop from 2 m/s, slowing at 1 m/s^2 after 0.2 s: fine.
        let mut m = ActuatorMonitor::default();
        let mut v: f64 = 2.0;
        for k in 0..400 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[throttle(0.0)]);
            if now > 0.2 {
                v = (v - 0.01).max(0.0);
            }
            m.on_throttle(now, &wheels(v));
        }
        assert!(m.finding().is_none(), "{:?}", m.finding());
        // The same with the speed held at 2 m/s: found.
        let mut m = ActuatorMonitor::default();
        for k in 0..400 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[throttle(0.0)]);
            m.on_throttle(now, &wheels(2.0));
        }
        let f = m.finding().expect("a stuck drive is found");
        assert!(f.reason.contains("does not follow"), "{}", f.reason);
    }

    #[test]
    fn reversing_at_the_commanded_speed_is_no_finding_and_running_away_backwards_is() {
        let reverse = |speed| drive(ThrottleCmdGear::Reverse, speed);
        // Backing at the commanded 0.5 m/s.
        let mut m = ActuatorMonitor::default();
        for k in 0..400 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[reverse(0.5)]);
            m.on_throttle(now, &wheels(-0.5));
        }
        assert!(m.finding().is_none(), "{:?}", m.finding());
        // Backing at 1.5 m/s against a command of 0.5: found.
        let mut m = ActuatorMonitor::default();
        for k in 0..400 {
            let now = f64::from(k) * 0.01;
            m.commanded(now, &[reverse(0.5)]);
            m.on_throttle(now, &wheels(-1.5));
        }
        let f = m
            .finding()
            .expect("a drive running away backwards is found");
        assert!(f.reason.contains("does not follow"), "{}", f.reason);
    }
}
