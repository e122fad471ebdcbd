//! The simulated throttle/brake ECU: a speed loop with dead time, first-order lag,
//! acceleration and deceleration limits and a brake; zero throttle and full brake in
//! the safe state.

use std::collections::VecDeque;

use golf_car_can::{
    ThrottleCmd, ThrottleCmdGear, ThrottleReport, ThrottleReportFault, ThrottleReportGear,
};

use super::safety::{Cause, Safety};
use crate::scenario::ThrottleConfig;

/// Deceleration when coasting (rolling resistance), m/s^2.
const COAST_DECEL: f64 = 0.3;

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
        let (accel, throttle, brake) = if !self.safety.enabled() {
            // Safe state: no drive, full brake.
            (-self.cfg.brake_decel * v.signum(), 0.0, 100.0)
        } else if self.demand.gear == ThrottleCmdGear::Neutral {
            let b = self.demand.brake_pct / 100.0 * self.cfg.brake_decel;
            (-(COAST_DECEL + b) * v.signum(), 0.0, self.demand.brake_pct)
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
            let brake_decel = self.demand.brake_pct / 100.0 * self.cfg.brake_decel;
            let a = a - brake_decel * v.signum();
            let decel_beyond_coast = (-a * v.signum() - COAST_DECEL).max(0.0);
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
            },
            wheel_speed: self.speed.clamp(-10.0, 10.0),
            throttle: self.throttle_pct,
            brake: self.brake_pct,
        }
    }
}
