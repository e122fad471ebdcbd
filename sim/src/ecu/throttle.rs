//! The simulated throttle/brake ECU: a speed loop with dead time, first-order lag,
//! acceleration and deceleration limits and a brake; zero throttle and full brake in
//! the safe state.

use std::collections::VecDeque;

use golf_car_can::{
    ThrottleCmd, ThrottleCmdGear, ThrottleReport, ThrottleReportFault, ThrottleReportGear,
};

use super::safety::{Cause, Safety};
use crate::faults::EcuFaultCode;
use crate::scenario::ThrottleConfig;

/// Deceleration when coasting (rolling resistance), m/s^2.
const COAST_DECEL: f64 = 0.3;

/// The direction of travel: +1, -1, or 0 at rest (`f64::signum` is 1 at 0.0, which
/// made a brake at standstill push the car backwards).
fn direction(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The acceleration of a drive `drive` (m/s^2) against a brake (or rolling resistance)
/// of `decel`: while moving the brake acts against the motion; at rest it holds the
/// car against up to its own strength (static friction), so a brake alone never sets
/// the car moving.
fn braked(v: f64, drive: f64, decel: f64) -> f64 {
    if v != 0.0 {
        drive - decel * direction(v)
    } else {
        direction(drive) * (drive.abs() - decel).max(0.0)
    }
}

/// A throttle command after its dead time.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Demand {
    /// Signed target speed (negative in reverse), m/s.
    speed: f64,
    accel_limit: f64,
    brake_pct: f64,
    gear: ThrottleCmdGear,
}

/// The drive, the brake and their controller.
#[derive(Clone, Debug)]
pub struct ThrottleEcu {
    cfg: ThrottleConfig,
    max_speed: f64,
    pub safety: Safety,
    pending: VecDeque<(f64, Demand)>,
    demand: Demand,
    speed: f64,
    throttle_pct: f64,
    brake_pct: f64,
    /// Injected actuator faults (`[[faults]]`).
    pub faults: ThrottleFaults,
}

/// What injected faults do to the drive and the brake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThrottleFaults {
    /// The throttle holds the wheel speed it had (a stuck pedal or motor controller):
    /// commands no longer change it, only the safe state's brake does.
    pub stuck: bool,
    /// The brake gives this fraction of its deceleration.
    pub brake_factor: f64,
}

impl Default for ThrottleFaults {
    fn default() -> Self {
        ThrottleFaults {
            stuck: false,
            brake_factor: 1.0,
        }
    }
}

impl ThrottleEcu {
    pub fn new(cfg: ThrottleConfig, max_speed: f64, safety: Safety) -> ThrottleEcu {
        ThrottleEcu {
            cfg,
            max_speed,
            safety,
            pending: VecDeque::new(),
            demand: Demand {
                speed: 0.0,
                accel_limit: 0.0,
                brake_pct: 0.0,
                gear: ThrottleCmdGear::Neutral,
            },
            speed: 0.0,
            throttle_pct: 0.0,
            brake_pct: 0.0,
            faults: ThrottleFaults::default(),
        }
    }

    /// A THROTTLE_CMD arrived.
    pub fn on_command(&mut self, now: f64, cmd: &ThrottleCmd) {
        self.safety.on_command(now, cmd.enable);
        let magnitude = cmd.target_speed.clamp(0.0, self.max_speed);
        let speed = match cmd.gear {
            ThrottleCmdGear::Forward => magnitude,
            ThrottleCmdGear::Reverse => -magnitude,
            ThrottleCmdGear::Neutral => 0.0,
        };
        self.pending.push_back((
            now + self.cfg.dead_time_s,
            Demand {
                speed,
                accel_limit: cmd.accel_limit,
                brake_pct: cmd.brake,
                gear: cmd.gear,
            },
        ));
    }

    /// Advance by `dt` ending at `now`.
    pub fn step(&mut self, now: f64, dt: f64) {
        self.safety.update(now);
        // A command acts from the first step that starts after its dead time.
        while self.pending.front().is_some_and(|p| p.0 <= now - dt + 1e-9) {
            if let Some((_, d)) = self.pending.pop_front() {
                self.demand = d;
            }
        }
        let v = self.speed;
        let brake_decel_max = self.cfg.brake_decel * self.faults.brake_factor;
        let (accel, throttle, brake) = if self.faults.stuck && self.safety.enabled() {
            // Stuck: the drive holds its speed whatever is commanded.
            (0.0, self.throttle_pct, 0.0)
        } else if !self.safety.enabled() {
            // Safe state: no drive, full brake.
            (braked(v, 0.0, brake_decel_max), 0.0, 100.0)
        } else if self.demand.gear == ThrottleCmdGear::Neutral {
            let b = self.demand.brake_pct / 100.0 * brake_decel_max;
            (braked(v, 0.0, COAST_DECEL + b), 0.0, self.demand.brake_pct)
        } else {
            let max_accel = if self.demand.accel_limit > 0.0 {
                self.demand.accel_limit.min(self.cfg.max_accel)
            } else {
                self.cfg.max_accel
            };
            // The loop accelerates towards the target (in the direction of travel).
            let wanted = (self.demand.speed - v) / self.cfg.time_constant_s;
            let speeding_up = wanted * v.signum() > 0.0 || v == 0.0;
            let a = if speeding_up {
                wanted.clamp(-max_accel, max_accel)
            } else {
                wanted.clamp(-self.cfg.max_decel, self.cfg.max_decel)
            };
            let brake_decel = self.demand.brake_pct / 100.0 * brake_decel_max;
            let a = braked(v, a, brake_decel);
            let decel_beyond_coast = (-a * direction(v) - COAST_DECEL).max(0.0);
            let brake =
                (decel_beyond_coast / self.cfg.brake_decel * 100.0).max(self.demand.brake_pct);
            let throttle = if a * v.signum() >= 0.0 || v == 0.0 {
                self.cfg.throttle_per_speed * v.abs() + 20.0 * a.abs()
            } else {
                0.0
            };
            (a, throttle, brake)
        };
        // Braking stops the car; it does not drive it backwards. Passing through zero
        // is allowed only when the demand lies on the other side.
        let next = v + accel * dt;
        let driving = self.safety.enabled() && self.demand.gear != ThrottleCmdGear::Neutral;
        let crossed = next * v < 0.0;
        self.speed =
            if (!driving && next * v <= 0.0) || (crossed && self.demand.speed * next <= 0.0) {
                0.0
            } else {
                next
            };
        self.throttle_pct = throttle.clamp(0.0, 100.0);
        self.brake_pct = brake.clamp(0.0, 100.0);
    }

    /// The actual wheel speed, m/s (negative backwards).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The THROTTLE_REPORT of this instant.
    pub fn report(&self) -> ThrottleReport {
        ThrottleReport {
            enabled: self.safety.enabled(),
            gear: match self.demand.gear {
                ThrottleCmdGear::Neutral => ThrottleReportGear::Neutral,
                ThrottleCmdGear::Forward => ThrottleReportGear::Forward,
                ThrottleCmdGear::Reverse => ThrottleReportGear::Reverse,
            },
            fault: match self.safety.fault() {
                None => ThrottleReportFault::None,
                Some(Cause::CommandTimeout) => ThrottleReportFault::CommandTimeout,
                Some(Cause::HeartbeatTimeout) => ThrottleReportFault::HeartbeatTimeout,
                Some(Cause::Estop) => ThrottleReportFault::Estop,
                Some(Cause::FaultReport) => ThrottleReportFault::FaultReport,
                Some(Cause::SecondSender) => ThrottleReportFault::SecondSender,
                Some(Cause::Actuator) => match self.safety.actuator_fault() {
                    Some(EcuFaultCode::Overcurrent) => ThrottleReportFault::Overcurrent,
                    Some(EcuFaultCode::Sensor) => ThrottleReportFault::SpeedSensor,
                    _ => ThrottleReportFault::Internal,
                },
            },
            wheel_speed: self.speed.clamp(-10.0, 10.0),
            throttle: self.throttle_pct,
            brake: self.brake_pct,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ecu::safety::SafetyTiming;
    use golf_car_can::ControllerHeartbeatState;

    fn ecu() -> ThrottleEcu {
        ThrottleEcu::new(
            ThrottleConfig::default(),
            6.7,
            Safety::new(SafetyTiming {
                command_timeout: 0.1,
                heartbeat_timeout: 0.1,
                fault_clear: 0.25,
            }),
        )
    }

    /// Drive `ecu` for `seconds` from its clock `now` with `cmd` every 10 ms (1 ms
    /// physics), the heartbeat in `state`; returns the distance driven (signed).
    fn drive(
        ecu: &mut ThrottleEcu,
        now: &mut f64,
        cmd: &ThrottleCmd,
        state: ControllerHeartbeatState,
        seconds: f64,
    ) -> f64 {
        let dt = 0.001;
        let mut distance = 0.0;
        for i in 1..=(seconds / dt).round() as u64 {
            *now += dt;
            if i % 10 == 0 {
                ecu.safety.on_heartbeat(*now, state);
                ecu.on_command(*now, cmd);
            }
            ecu.step(*now, dt);
            distance += ecu.speed() * dt;
        }
        distance
    }

    fn braking(enable: bool, gear: ThrottleCmdGear) -> ThrottleCmd {
        ThrottleCmd {
            enable,
            target_speed: 0.0,
            accel_limit: 1.0,
            brake: 40.0,
            gear,
        }
    }

    #[test]
    fn a_car_braked_at_standstill_does_not_creep() {
        for gear in [
            ThrottleCmdGear::Forward,
            ThrottleCmdGear::Reverse,
            ThrottleCmdGear::Neutral,
        ] {
            let mut e = ecu();
            let mut now = 0.0;
            // The enable edge: low first, then high.
            drive(
                &mut e,
                &mut now,
                &braking(false, gear),
                ControllerHeartbeatState::Auto,
                0.05,
            );
            let moved = drive(
                &mut e,
                &mut now,
                &braking(true, gear),
                ControllerHeartbeatState::Auto,
                60.0,
            );
            assert!(e.safety.enabled(), "{gear:?}: enabled");
            assert!(moved.abs() < 1e-3, "{gear:?}: moved {moved} m in 60 s");
        }
        // In the safe state (estop) too.
        let mut e = ecu();
        let mut now = 0.0;
        let moved = drive(
            &mut e,
            &mut now,
            &braking(false, ThrottleCmdGear::Forward),
            ControllerHeartbeatState::Estop,
            60.0,
        );
        assert!(moved.abs() < 1e-3, "safe state: moved {moved} m");
    }

    #[test]
    fn a_car_at_rest_drives_off_and_brakes_to_a_stop_without_reversing() {
        let mut e = ecu();
        let mut now = 0.0;
        drive(
            &mut e,
            &mut now,
            &braking(false, ThrottleCmdGear::Forward),
            ControllerHeartbeatState::Auto,
            0.05,
        );
        let go = ThrottleCmd {
            target_speed: 2.0,
            brake: 0.0,
            ..braking(true, ThrottleCmdGear::Forward)
        };
        let ahead = drive(&mut e, &mut now, &go, ControllerHeartbeatState::Auto, 5.0);
        assert!(
            ahead > 3.0 && (e.speed() - 2.0).abs() < 0.1,
            "{ahead} m, {} m/s",
            e.speed()
        );
        drive(
            &mut e,
            &mut now,
            &braking(true, ThrottleCmdGear::Forward),
            ControllerHeartbeatState::Auto,
            3.0,
        );
        assert_eq!(e.speed(), 0.0);
        let after = drive(
            &mut e,
            &mut now,
            &braking(true, ThrottleCmdGear::Forward),
            ControllerHeartbeatState::Auto,
            10.0,
        );
        assert!(after.abs() < 1e-3, "{after}");
    }
}
