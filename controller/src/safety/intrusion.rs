//! Commands the controller did not send.
//!
//! E2E proves integrity, not origin: any local process that can open the CAN
//! interface can send a well-formed STEERING_CMD with the next counter. The
//! controller cannot stop that, but it can notice it, four ways, each enough to estop:
//!
//! - **Frames with its own IDs.** A raw CAN socket never receives what it sent itself
//!   (nor does an endpoint of the memory bus), so a CONTROLLER_HEARTBEAT,
//!   STEERING_CMD or THROTTLE_CMD, or a FAULT_REPORT from the controller, that
//!   arrives came from another sender (`second_sender`, the ID in the detail).
//! - **A second sender on a report stream** ([`golf_car_can::SenderWatch`] on the
//!   STEERING_REPORT and THROTTLE_REPORT counters): reports forged to hide a forged
//!   command (`second_sender`).
//! - **The ECUs' own findings**: a FAULT_REPORT `second_sender` from an ECU, or a
//!   report whose fault is `second_sender`.
//! - **Reports that disagree with the commands** beyond what the actuators' dynamics
//!   allow (`unexpected_actuation`):
//!   - an ECU reporting enabled although every command for [`ENABLE_GRACE`] said
//!     disable;
//!   - the road-wheel angle beyond every target commanded in the last [`STEER_WINDOW`]
//!     (by [`STEER_MARGIN`]) and still moving away from them (faster than
//!     [`STEER_RATE_NOISE`]). An actuator with lag, a rate limit and a dead time up
//!     to the window moves towards a target it was sent, never away from all of them.
//!     While the controller holds (commands the measured angle), the targets are
//!     frozen where the hold began (the recent targets and the angle then): an
//!     actuator chasing its own delayed angle stays within them, wheels turned under
//!     the hold leave them;
//!   - the wheel speed beyond every target speed of the last [`SPEED_WINDOW`] (by
//!     [`SPEED_MARGIN`]) and still accelerating away ([`SPEED_RISE`] over
//!     [`SPEED_SPAN`]).
//!
//!   Each must hold for [`PERSIST_REPORTS`] reports in a row spanning [`PERSIST_S`],
//!   so noise, one odd frame or a backlog of stale reports after a stall do not trip
//!   it.

use std::collections::{BTreeMap, VecDeque};

use firmware_bridge::Received;
use golf_car_can::{
    CanMessage, ControllerHeartbeat, CounterVerdict, E2eError, FaultReportCode, FaultReportSource,
    GolfCarMessage, SenderWatch, SteeringCmd, SteeringReport, SteeringReportFault, ThrottleCmd,
    ThrottleReport, ThrottleReportFault,
};
use serde::Serialize;

/// How long every command must have said disable before an enabled report counts.
pub const ENABLE_GRACE: f64 = 0.2;
/// Steering targets commanded this long ago still count (covers dead time and lag).
pub const STEER_WINDOW: f64 = 1.0;
/// How far beyond every recent target the angle must be, degrees (overshoot, noise).
pub const STEER_MARGIN: f64 = 1.0;
/// The rate away from the targets that counts as moving, deg/s.
pub const STEER_RATE_NOISE: f64 = 2.0;
/// Target speeds commanded this long ago still count.
pub const SPEED_WINDOW: f64 = 2.0;
/// How far beyond every recent target speed the wheel speed must be, m/s.
pub const SPEED_MARGIN: f64 = 0.3;
/// The speed gained away from the targets over [`SPEED_SPAN`] that counts, m/s.
pub const SPEED_RISE: f64 = 0.02;
/// The interval the speed gain is measured over, seconds.
pub const SPEED_SPAN: f64 = 0.1;
/// Reports in a row a disagreement must last.
pub const PERSIST_REPORTS: u32 = 5;
/// Time those reports must span, seconds.
pub const PERSIST_S: f64 = 0.04;

/// Something the controller did not command, found on the bus.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// The FAULT_REPORT code for it (`second_sender` or `unexpected_actuation`).
    #[serde(serialize_with = "code_label")]
    pub code: FaultReportCode,
    /// The CAN ID it concerns (FAULT_REPORT detail).
    pub detail: u16,
    pub reason: String,
}

fn code_label<S: serde::Serializer>(code: &FaultReportCode, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(code.label())
}

/// A condition that must persist over reports.
#[derive(Clone, Copy, Debug, Default)]
struct Persist {
    count: u32,
    since: f64,
}

impl Persist {
    fn update(&mut self, now: f64, holds: bool) -> bool {
        if !holds {
            self.count = 0;
            return false;
        }
        if self.count == 0 {
            self.since = now;
        }
        self.count = self.count.saturating_add(1);
        self.count >= PERSIST_REPORTS && now - self.since >= PERSIST_S
    }
}

/// What was commanded to one ECU recently.
#[derive(Clone, Debug, Default)]
struct Commands {
    /// (time, target): road-wheel angle in degrees or signed speed in m/s.
    targets: VecDeque<(f64, f64)>,
    first: Option<f64>,
    last_enable: Option<f64>,
    enabled: Persist,
    away: Persist,
}

impl Commands {
    fn push(&mut self, now: f64, enable: bool, target: f64, window: f64) {
        self.first.get_or_insert(now);
        if enable {
            self.last_enable = Some(now);
        }
        self.targets.push_back((now, target));
        while self.targets.front().is_some_and(|(t, _)| now - t > window) {
            self.targets.pop_front();
        }
    }

    /// The range of the targets commanded within `window` of `now`.
    fn hull(&self, now: f64, window: f64) -> Option<(f64, f64)> {
        self.targets
            .iter()
            .filter(|(t, _)| now - t <= window)
            .fold(None, |acc, (_, v)| match acc {
                None => Some((*v, *v)),
                Some((lo, hi)) => Some((lo.min(*v), hi.max(*v))),
            })
    }

    /// Whether an enabled report contradicts the commands (all disable for the grace).
    fn enabled_against_commands(&mut self, now: f64, enabled: bool) -> bool {
        let all_disable = self.first.is_some_and(|t| now - t >= ENABLE_GRACE)
            && self.last_enable.is_none_or(|t| now - t >= ENABLE_GRACE);
        self.enabled.update(now, enabled && all_disable)
    }
}

/// The controller's watch for commands it did not send (see the module).
#[derive(Clone, Debug, Default)]
pub struct ActuationWatch {
    steering: Commands,
    throttle: Commands,
    /// The steering targets frozen for the current hold (lowest, highest), degrees.
    hold: Option<(f64, f64)>,
    /// Whether the last STEERING_REPORT said enabled.
    steering_enabled: bool,
    /// Recent reported wheel speeds (time, m/s).
    speeds: VecDeque<(f64, f64)>,
    /// Counter streams of the ECUs' reports.
    streams: BTreeMap<u16, SenderWatch>,
    /// Frames with the controller's own IDs received (sent by someone else).
    pub foreign_frames: u64,
    /// Every finding, the first one first (an estop keeps the first).
    pub findings: Vec<Finding>,
}

/// The controller's own messages: their name when `id` is one.
fn own_message(id: u16) -> Option<&'static str> {
    match id {
        ControllerHeartbeat::ID => Some(ControllerHeartbeat::NAME),
        SteeringCmd::ID => Some(SteeringCmd::NAME),
        ThrottleCmd::ID => Some(ThrottleCmd::NAME),
        _ => None,
    }
}

/// The CAN ID, name and counter verdict of a frame whose CRC was good.
fn counted(received: &Received) -> Option<(u16, CounterVerdict)> {
    match received {
        Received::Message(m) => Some((m.id(), CounterVerdict::Next)),
        Received::Undecodable { id, .. } => Some((*id, CounterVerdict::Next)),
        Received::Rejected(E2eError::RepeatedCounter { id, .. }) => {
            Some((*id, CounterVerdict::Repeated))
        }
        Received::Rejected(E2eError::SkippedCounter { id, .. }) => {
            Some((*id, CounterVerdict::Skipped))
        }
        _ => None,
    }
}

impl ActuationWatch {
    pub fn new() -> ActuationWatch {
        ActuationWatch::default()
    }

    /// The messages the controller sent at `now`; `hold_deg` is the measured angle it
    /// commands when it holds the steering.
    pub fn commanded(&mut self, now: f64, sent: &[GolfCarMessage], hold_deg: f64) {
        for m in sent {
            match m {
                GolfCarMessage::SteeringCmd(c) => {
                    let t = c.target_angle;
                    if (t - hold_deg).abs() < 1e-6 {
                        let recent = self.steering.hull(now, STEER_WINDOW);
                        let (lo, hi) = match self.hold {
                            // A disabled ECU cannot be moved by commands: the hold
                            // follows what it measures until it is enabled.
                            Some((lo, hi)) if !self.steering_enabled => (lo.min(t), hi.max(t)),
                            Some(frozen) => frozen,
                            None => recent.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t))),
                        };
                        self.hold = Some((lo, hi));
                    } else {
                        self.hold = None;
                    }
                    self.steering.push(now, c.enable, t, STEER_WINDOW);
                }
                GolfCarMessage::ThrottleCmd(c) => {
                    let speed = super::monitor::commanded_speed(c);
                    self.throttle.push(now, c.enable, speed, SPEED_WINDOW);
                }
                _ => {}
            }
        }
    }

    /// A frame from the bus at `now`: a finding when it reveals a command the
    /// controller did not send.
    pub fn on_can(&mut self, now: f64, received: &Received) -> Option<Finding> {
        let finding = self.examine(now, received);
        if let Some(f) = &finding {
            self.findings.push(f.clone());
        }
        finding
    }

    fn examine(&mut self, now: f64, received: &Received) -> Option<Finding> {
        let (id, verdict) = counted(received)?;
        if let Some(name) = own_message(id).or_else(|| match received {
            Received::Message(GolfCarMessage::FaultReport(f))
                if f.source == FaultReportSource::Controller =>
            {
                Some("FAULT_REPORT (source controller)")
            }
            _ => None,
        }) {
            self.foreign_frames += 1;
            return Some(Finding {
                code: FaultReportCode::SecondSender,
                detail: id,
                reason: format!(
                    "{name} ({id:#05x}) from another sender on the bus: someone else is commanding the car"
                ),
            });
        }
        if id == SteeringReport::ID || id == ThrottleReport::ID {
            let watch = self.streams.entry(id).or_default();
            watch.observe(verdict);
            if watch.flagged() {
                let name = if id == SteeringReport::ID {
                    SteeringReport::NAME
                } else {
                    ThrottleReport::NAME
                };
                return Some(Finding {
                    code: FaultReportCode::SecondSender,
                    detail: id,
                    reason: format!(
                        "a second sender of {name} ({id:#05x}): its counter stream has repeated or interleaved counters"
                    ),
                });
            }
        }
        let Received::Message(m) = received else {
            return None;
        };
        match m {
            GolfCarMessage::FaultReport(f)
                if f.source != FaultReportSource::Controller
                    && f.code == FaultReportCode::SecondSender =>
            {
                Some(Finding {
                    code: FaultReportCode::SecondSender,
                    detail: f.detail,
                    reason: format!(
                        "the {} found a second sender on {:#05x} (FAULT_REPORT)",
                        f.source, f.detail
                    ),
                })
            }
            GolfCarMessage::SteeringReport(r) => self.steering_report(now, r),
            GolfCarMessage::ThrottleReport(r) => self.throttle_report(now, r),
            _ => None,
        }
    }

    fn steering_report(&mut self, now: f64, r: &SteeringReport) -> Option<Finding> {
        if r.fault == SteeringReportFault::SecondSender {
            return Some(Finding {
                code: FaultReportCode::SecondSender,
                detail: SteeringCmd::ID,
                reason: "the steering ECU reports a second sender".to_owned(),
            });
        }
        let unexpected = |reason: String| Finding {
            code: FaultReportCode::UnexpectedActuation,
            detail: SteeringReport::ID,
            reason,
        };
        if self.steering.enabled_against_commands(now, r.enabled) {
            return Some(unexpected(format!(
                "the steering ECU reports enabled although every command for {ENABLE_GRACE} s said disable"
            )));
        }
        self.steering_enabled = r.enabled;
        // Only a moving, enabled steering can move away: the targets' hull (a pass
        // over a second of commands) is needed only then.
        let moving = !(-STEER_RATE_NOISE..=STEER_RATE_NOISE).contains(&r.rate);
        let hull = (r.enabled && !r.r#override && moving)
            .then(|| self.hold.or_else(|| self.steering.hull(now, STEER_WINDOW)))
            .flatten();
        let away = r.enabled
            && !r.r#override
            && hull.is_some_and(|(lo, hi)| {
                (r.angle > hi + STEER_MARGIN && r.rate > STEER_RATE_NOISE)
                    || (r.angle < lo - STEER_MARGIN && r.rate < -STEER_RATE_NOISE)
            });
        if self.steering.away.update(now, away) {
            let (lo, hi) = hull.unwrap_or_default();
            return Some(unexpected(format!(
                "the steering angle {:.1} deg moves away ({:.1} deg/s) from every target it was commanded ({lo:.1} to {hi:.1} deg)",
                r.angle, r.rate
            )));
        }
        None
    }

    fn throttle_report(&mut self, now: f64, r: &ThrottleReport) -> Option<Finding> {
        if r.fault == ThrottleReportFault::SecondSender {
            return Some(Finding {
                code: FaultReportCode::SecondSender,
                detail: ThrottleCmd::ID,
                reason: "the throttle ECU reports a second sender".to_owned(),
            });
        }
        let unexpected = |reason: String| Finding {
            code: FaultReportCode::UnexpectedActuation,
            detail: ThrottleReport::ID,
            reason,
        };
        if self.throttle.enabled_against_commands(now, r.enabled) {
            return Some(unexpected(format!(
                "the throttle ECU reports enabled although every command for {ENABLE_GRACE} s said disable"
            )));
        }
        let v = r.wheel_speed;
        // The gain since the newest report at least SPEED_SPAN old.
        let gain = self
            .speeds
            .iter()
            .rev()
            .find(|(t, _)| now - t >= SPEED_SPAN)
            .map(|(_, old)| v - old);
        self.speeds.push_back((now, v));
        while self
            .speeds
            .get(1)
            .is_some_and(|(t, _)| now - t >= SPEED_SPAN)
        {
            self.speeds.pop_front();
        }
        // Only a speed gaining or losing more than SPEED_RISE can move away: the
        // targets' hull (a pass over two seconds of commands) is needed only then.
        let moving = gain.is_some_and(|g| !(-SPEED_RISE..=SPEED_RISE).contains(&g));
        let hull = (r.enabled && moving)
            .then(|| self.throttle.hull(now, SPEED_WINDOW))
            .flatten();
        let away = r.enabled
            && hull.zip(gain).is_some_and(|((lo, hi), gain)| {
                (v > hi + SPEED_MARGIN && gain > SPEED_RISE)
                    || (v < lo.min(0.0) - SPEED_MARGIN && gain < -SPEED_RISE)
            });
        if self.throttle.away.update(now, away) {
            let (lo, hi) = hull.unwrap_or_default();
            return Some(unexpected(format!(
                "the wheel speed {v:.2} m/s moves away from every target speed commanded in the last {SPEED_WINDOW} s ({lo:.2} to {hi:.2} m/s)"
            )));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use golf_car_can::ThrottleCmdGear;

    /// A first-order actuator with dead time and a rate limit, as a healthy ECU is
    /// (the simulator's ECUs, and the disturbance scenarios' slow ones).
    struct Plant {
        dead: f64,
        tau: f64,
        max_rate: f64,
        pending: VecDeque<(f64, bool, f64)>,
        enabled: bool,
        target: f64,
        value: f64,
        rate: f64,
    }

    impl Plant {
        fn new(dead: f64, tau: f64, max_rate: f64) -> Plant {
            Plant {
                dead,
                tau,
                max_rate,
                pending: VecDeque::new(),
                enabled: false,
                target: 0.0,
                value: 0.0,
                rate: 0.0,
            }
        }

        fn command(&mut self, now: f64, enable: bool, target: f64) {
            self.pending.push_back((now + self.dead, enable, target));
        }

        fn step(&mut self, now: f64, dt: f64) {
            while self.pending.front().is_some_and(|p| p.0 <= now) {
                if let Some((_, enable, target)) = self.pending.pop_front() {
                    self.enabled = enable;
                    self.target = target;
                }
            }
            self.rate = if self.enabled {
                ((self.target - self.value) / self.tau).clamp(-self.max_rate, self.max_rate)
            } else {
                0.0
            };
            self.value += self.rate * dt;
        }
    }

    fn q(x: f64, step: f64) -> f64 {
        (x / step).round() * step
    }

    fn steering_report(p: &Plant) -> Received {
        Received::Message(GolfCarMessage::SteeringReport(SteeringReport {
            enabled: p.enabled,
            angle: q(p.value, 0.01),
            rate: q(p.rate, 0.1),
            ..SteeringReport::default()
        }))
    }

    fn throttle_report(p: &Plant) -> Received {
        Received::Message(GolfCarMessage::ThrottleReport(ThrottleReport {
            enabled: p.enabled,
            wheel_speed: q(p.value, 0.01),
            ..ThrottleReport::default()
        }))
    }

    fn steer_cmd(enable: bool, target: f64) -> GolfCarMessage {
        GolfCarMessage::SteeringCmd(SteeringCmd {
            enable,
            target_angle: target,
            max_rate: 0.0,
        })
    }

    fn throttle_cmd(enable: bool, speed: f64) -> GolfCarMessage {
        GolfCarMessage::ThrottleCmd(ThrottleCmd {
            enable,
            gear: ThrottleCmdGear::Forward,
            target_speed: speed,
            ..ThrottleCmd::default()
        })
    }

    /// What the controller wants at `t`: None holds (the measured angle).
    type Profile = dyn Fn(f64) -> Option<f64>;

    /// Drive the steering plant for `seconds` at 1 ms steps, commands and reports every
    /// 10 ms. `plant_target` overrides what reaches the plant (a forger's command).
    /// Returns the first finding and its time.
    fn run_steering(
        plant: &mut Plant,
        seconds: f64,
        wanted: &Profile,
        plant_target: &dyn Fn(f64, f64) -> f64,
    ) -> Option<(f64, Finding)> {
        let mut watch = ActuationWatch::new();
        let mut measured = 0.0;
        for k in 0..(seconds * 1000.0) as u64 {
            let now = k as f64 * 0.001;
            plant.step(now, 0.001);
            if k % 10 == 0 {
                let enable = now > 0.1;
                let target = wanted(now).unwrap_or(measured);
                watch.commanded(now, &[steer_cmd(enable, target)], measured);
                plant.command(now, enable, plant_target(now, target));
            }
            if k % 10 == 5 {
                let r = steering_report(plant);
                if let Received::Message(GolfCarMessage::SteeringReport(s)) = &r {
                    measured = s.angle;
                }
                if let Some(f) = watch.on_can(now, &r) {
                    return Some((now, f));
                }
            }
        }
        None
    }

    /// A zig-zag of drives and holds across the whole steering range.
    fn busy_profile(t: f64) -> Option<f64> {
        let phase = t % 6.0;
        if phase < 4.0 {
            Some(30.0 * (t * 2.3).sin() + 5.0 * (t * 11.0).sin())
        } else {
            None
        }
    }

    #[test]
    fn a_healthy_steering_ecu_with_lag_and_dead_time_is_never_flagged() {
        // The simulator's ECU, and the comparison study's slow one (250 ms dead time).
        for (dead, tau, rate) in [(0.02, 0.08, 60.0), (0.25, 0.08, 60.0), (0.1, 0.3, 20.0)] {
            let mut plant = Plant::new(dead, tau, rate);
            let found = run_steering(&mut plant, 120.0, &busy_profile, &|_, t| t);
            assert!(found.is_none(), "dead {dead} tau {tau}: {found:?}");
        }
    }

    #[test]
    fn a_forged_steering_target_is_found_within_half_a_second() {
        let mut plant = Plant::new(0.02, 0.08, 60.0);
        // Driving at a few degrees; from t = 2 s a forger's 35 deg reaches the ECU.
        let found = run_steering(
            &mut plant,
            5.0,
            &|t| Some(3.0 * (t * 0.7).sin()),
            &|now, t| if now >= 2.0 { 35.0 } else { t },
        );
        let (t, f) = found.expect("found");
        eprintln!(
            "forged steering target from 2.0 s found at {t:.3} s, wheels at {:.1} deg",
            plant.value
        );
        assert_eq!(f.code, FaultReportCode::UnexpectedActuation);
        assert!((2.0..2.5).contains(&t), "found at {t}: {f:?}");
        assert!(plant.value < 15.0, "the wheels got to {}", plant.value);
    }

    #[test]
    fn wheels_turned_under_a_hold_are_found() {
        let mut plant = Plant::new(0.02, 0.08, 60.0);
        // Holding from t = 1 s (the controller commands the measured angle); a forger
        // walks the target away at 20 deg/s from t = 3 s.
        let found = run_steering(&mut plant, 6.0, &|t| (t < 1.0).then_some(5.0), &|now, t| {
            if now >= 3.0 {
                5.0 + 20.0 * (now - 3.0)
            } else {
                t
            }
        });
        let (t, f) = found.expect("found");
        eprintln!(
            "wheels turned under a hold from 3.0 s found at {t:.3} s, at {:.1} deg",
            plant.value
        );
        assert_eq!(f.code, FaultReportCode::UnexpectedActuation);
        assert!((3.0..3.5).contains(&t), "found at {t}: {f:?}");
    }

    #[test]
    fn an_ecu_enabled_while_every_command_says_disable_is_found() {
        let mut watch = ActuationWatch::new();
        let mut found = None;
        for k in 0..100u32 {
            let now = f64::from(k) * 0.01;
            watch.commanded(now, &[steer_cmd(false, 0.0), throttle_cmd(false, 0.0)], 0.0);
            // The steering ECU says enabled from 0.5 s (someone else enabled it).
            let r = Received::Message(GolfCarMessage::SteeringReport(SteeringReport {
                enabled: now >= 0.5,
                ..SteeringReport::default()
            }));
            if let Some(f) = watch.on_can(now + 0.005, &r) {
                found = Some((now, f));
                break;
            }
        }
        let (t, f) = found.expect("found");
        assert_eq!(f.code, FaultReportCode::UnexpectedActuation);
        assert!((0.5..0.6).contains(&t), "{t}: {f:?}");
        assert!(f.reason.contains("enabled"), "{}", f.reason);
    }

    #[test]
    fn an_enabled_report_just_after_the_commands_switch_to_disable_is_not_a_finding() {
        let mut watch = ActuationWatch::new();
        for k in 0..300u32 {
            let now = f64::from(k) * 0.01;
            let enable = now < 2.0;
            watch.commanded(now, &[steer_cmd(enable, 0.0)], 0.0);
            // The ECU follows 150 ms late (a slow bus, a stall).
            let r = Received::Message(GolfCarMessage::SteeringReport(SteeringReport {
                enabled: now > 0.2 && now < 2.15,
                ..SteeringReport::default()
            }));
            assert_eq!(watch.on_can(now + 0.005, &r), None, "t = {now}");
        }
    }

    /// The throttle plant driven by a speed profile; `forged` overrides the target
    /// reaching it.
    fn run_throttle(
        plant: &mut Plant,
        seconds: f64,
        wanted: &dyn Fn(f64) -> f64,
        forged: &dyn Fn(f64, f64) -> f64,
    ) -> Option<(f64, Finding)> {
        let mut watch = ActuationWatch::new();
        for k in 0..(seconds * 1000.0) as u64 {
            let now = k as f64 * 0.001;
            plant.step(now, 0.001);
            if k % 10 == 0 {
                let enable = now > 0.1;
                let speed = wanted(now);
                watch.commanded(now, &[throttle_cmd(enable, speed)], 0.0);
                plant.command(now, enable, forged(now, speed));
            }
            if k % 10 == 5
                && let Some(f) = watch.on_can(now, &throttle_report(plant))
            {
                return Some((now, f));
            }
        }
        None
    }

    fn speed_profile(t: f64) -> f64 {
        match t % 20.0 {
            p if p < 6.0 => 2.0,
            p if p < 9.0 => 0.5,
            p if p < 14.0 => 3.0,
            p if p < 15.0 => 0.0,
            _ => 1.5,
        }
    }

    #[test]
    fn a_healthy_throttle_ecu_is_never_flagged() {
        // The simulator's drive, and the comparison study's slow speed loop.
        for (dead, tau, accel) in [(0.05, 0.4, 1.5), (0.3, 1.5, 1.5)] {
            let mut plant = Plant::new(dead, tau, accel);
            // (max_rate limits the speed's rate of change: the acceleration limit.)
            let found = run_throttle(&mut plant, 120.0, &speed_profile, &|_, s| s);
            assert!(found.is_none(), "dead {dead} tau {tau}: {found:?}");
        }
    }

    #[test]
    fn a_forged_target_speed_is_found() {
        let mut plant = Plant::new(0.05, 0.4, 1.5);
        let found = run_throttle(&mut plant, 10.0, &|_| 1.5, &|now, s| {
            if now >= 5.0 { 6.0 } else { s }
        });
        let (t, f) = found.expect("found");
        eprintln!(
            "forged target speed from 5.0 s found at {t:.3} s, at {:.2} m/s",
            plant.value
        );
        assert_eq!(f.code, FaultReportCode::UnexpectedActuation);
        assert!((5.0..6.0).contains(&t), "found at {t}: {f:?}");
        assert!(plant.value < 2.5, "the car got to {} m/s", plant.value);
    }

    #[test]
    fn frames_with_the_controllers_own_ids_are_found_at_once() {
        let mut watch = ActuationWatch::new();
        let forged = Received::Message(steer_cmd(true, 35.0));
        let f = watch.on_can(0.0, &forged).expect("found");
        assert_eq!(f.code, FaultReportCode::SecondSender);
        assert_eq!(f.detail, SteeringCmd::ID);
        assert!(f.reason.contains("STEERING_CMD"), "{}", f.reason);
        // Rejected for its counter, it still came from someone else.
        let rejected = Received::Rejected(E2eError::RepeatedCounter {
            id: ThrottleCmd::ID,
            counter: 3,
        });
        assert_eq!(
            watch.on_can(0.01, &rejected).map(|f| f.detail),
            Some(ThrottleCmd::ID)
        );
        assert_eq!(watch.foreign_frames, 2);
        // The ECUs' frames are not.
        let report = Received::Message(GolfCarMessage::SteeringReport(SteeringReport::default()));
        assert_eq!(watch.on_can(0.02, &report), None);
    }

    #[test]
    fn forged_reports_show_as_a_second_sender_on_the_report_stream() {
        let mut watch = ActuationWatch::new();
        let report = Received::Message(GolfCarMessage::SteeringReport(SteeringReport::default()));
        let repeated = Received::Rejected(E2eError::RepeatedCounter {
            id: SteeringReport::ID,
            counter: 0,
        });
        let mut found = None;
        for k in 0..20u32 {
            let now = f64::from(k) * 0.01;
            for r in [&report, &repeated] {
                if let Some(f) = watch.on_can(now, r) {
                    found.get_or_insert(f);
                }
            }
        }
        let f = found.expect("found");
        assert_eq!(
            (f.code, f.detail),
            (FaultReportCode::SecondSender, SteeringReport::ID)
        );
        // One lost report now and then is not.
        let mut watch = ActuationWatch::new();
        let skipped = Received::Rejected(E2eError::SkippedCounter {
            id: SteeringReport::ID,
            last: 0,
            expected: 1,
            found: 2,
        });
        for k in 0..1000u32 {
            let r = if k % 10 == 0 { &skipped } else { &report };
            assert_eq!(watch.on_can(f64::from(k) * 0.01, r), None);
        }
    }

    #[test]
    fn an_ecu_reporting_a_second_sender_is_a_finding() {
        let mut watch = ActuationWatch::new();
        let fault = Received::Message(GolfCarMessage::FaultReport(golf_car_can::FaultReport {
            source: FaultReportSource::SteeringEcu,
            code: FaultReportCode::SecondSender,
            detail: SteeringCmd::ID,
        }));
        let f = watch.on_can(0.0, &fault).expect("found");
        assert_eq!(f.code, FaultReportCode::SecondSender);
        assert_eq!(f.detail, SteeringCmd::ID);
        // Another fault code from an ECU is the safety check's business, not this one's.
        let timeout = Received::Message(GolfCarMessage::FaultReport(golf_car_can::FaultReport {
            source: FaultReportSource::SteeringEcu,
            code: FaultReportCode::CommandTimeout,
            detail: SteeringCmd::ID,
        }));
        assert_eq!(watch.on_can(0.1, &timeout), None);
    }

    #[test]
    fn a_burst_of_stale_reports_after_a_stall_is_not_a_finding() {
        let mut watch = ActuationWatch::new();
        for k in 0..100u32 {
            watch.commanded(f64::from(k) * 0.01, &[steer_cmd(true, 0.0)], 5.0);
        }
        // Twenty reports of a moving angle, all read at one instant.
        for k in 0..20u32 {
            let r = Received::Message(GolfCarMessage::SteeringReport(SteeringReport {
                enabled: true,
                angle: 2.0 + f64::from(k) * 0.1,
                rate: 10.0,
                ..SteeringReport::default()
            }));
            assert_eq!(watch.on_can(1.0, &r), None);
        }
    }
}
