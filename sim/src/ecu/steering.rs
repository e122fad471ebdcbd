//! The simulated steering ECU: dead time, first-order lag, rate limit and angle limit
//! on the road-wheel angle; holds its angle in the safe state.

use std::collections::VecDeque;

use golf_car_can::{SteeringCmd, SteeringReport, SteeringReportFault};

use super::safety::{Cause, Safety};
use crate::scenario::SteeringConfig;

/// The steering actuator and its controller.
#[derive(Clone, Debug)]
pub struct SteeringEcu {
    cfg: SteeringConfig,
    /// Road-wheel angle limit, degrees.
    limit_deg: f64,
    pub safety: Safety,
    /// Commands waiting out the dead time: (time they act, target deg, max rate deg/s).
    pending: VecDeque<(f64, f64, f64)>,
    target_deg: f64,
    max_rate_deg_s: f64,
    angle_deg: f64,
    rate_deg_s: f64,
}

impl SteeringEcu {
    pub fn new(cfg: SteeringConfig, limit_deg: f64, safety: Safety) -> SteeringEcu {
        let max_rate = cfg.max_rate_deg_s;
        SteeringEcu {
            cfg,
            limit_deg,
            safety,
            pending: VecDeque::new(),
            target_deg: 0.0,
            max_rate_deg_s: max_rate,
            angle_deg: 0.0,
            rate_deg_s: 0.0,
        }
    }

    /// A STEERING_CMD arrived.
    pub fn on_command(&mut self, now: f64, cmd: &SteeringCmd) {
        self.safety.on_command(now, cmd.enable);
        let rate = if cmd.max_rate > 0.0 {
            cmd.max_rate.min(self.cfg.max_rate_deg_s)
        } else {
            self.cfg.max_rate_deg_s
        };
        let target = cmd.target_angle.clamp(-self.limit_deg, self.limit_deg);
        self.pending
            .push_back((now + self.cfg.dead_time_s, target, rate));
    }

    /// Advance the actuator by `dt` ending at `now`.
    pub fn step(&mut self, now: f64, dt: f64) {
        self.safety.update(now);
        // A command acts from the first step that starts after its dead time.
        while self.pending.front().is_some_and(|p| p.0 <= now - dt + 1e-9) {
            if let Some((_, target, rate)) = self.pending.pop_front() {
                self.target_deg = target;
                self.max_rate_deg_s = rate;
            }
        }
        if !self.safety.enabled() {
            // Safe state: the motor holds the angle.
            self.rate_deg_s = 0.0;
            return;
        }
        let wanted = (self.target_deg - self.angle_deg) / self.cfg.time_constant_s;
        let rate = wanted.clamp(-self.max_rate_deg_s, self.max_rate_deg_s);
        // Do not overshoot the target within one step.
        let step = rate * dt;
        let remaining = self.target_deg - self.angle_deg;
        let step = if step.abs() > remaining.abs() {
            remaining
        } else {
            step
        };
        let next = (self.angle_deg + step).clamp(-self.limit_deg, self.limit_deg);
        self.rate_deg_s = (next - self.angle_deg) / dt;
        self.angle_deg = next;
    }

    /// The actual road-wheel angle, radians.
    pub fn angle(&self) -> f64 {
        self.angle_deg.to_radians()
    }

    pub fn angle_deg(&self) -> f64 {
        self.angle_deg
    }

    pub fn rate_deg_s(&self) -> f64 {
        self.rate_deg_s
    }

    /// The STEERING_REPORT of this instant.
    pub fn report(&self) -> SteeringReport {
        SteeringReport {
            enabled: self.safety.enabled(),
            r#override: false,
            fault: match self.safety.fault() {
                None => SteeringReportFault::None,
                Some(Cause::CommandTimeout) => SteeringReportFault::CommandTimeout,
                Some(Cause::HeartbeatTimeout) => SteeringReportFault::HeartbeatTimeout,
                Some(Cause::Estop) => SteeringReportFault::Estop,
                Some(Cause::FaultReport) => SteeringReportFault::FaultReport,
            },
            angle: self.angle_deg.clamp(-45.0, 45.0),
            rate: self.rate_deg_s.clamp(-500.0, 500.0),
            motor_current: (self.cfg.idle_current_a
                + self.cfg.current_per_rate_a * self.rate_deg_s.abs())
            .clamp(0.0, 25.5),
        }
    }
}
