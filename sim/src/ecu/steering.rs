//! The simulated steering ECU: dead time, first-order lag, rate limit and angle limit
//! on the road-wheel angle; holds its angle in the safe state. A disturbance: a bias
//! of the angle sensor (`bias_deg`), so the wheels stand off the reported angle.

use std::collections::VecDeque;

use golf_car_can::{SteeringCmd, SteeringReport, SteeringReportFault};

use super::safety::{Cause, Safety};
use crate::faults::EcuFaultCode;
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
    /// Injected actuator faults (`[[faults]]`).
    pub faults: SteeringFaults,
}

/// What injected faults do to the steering actuator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteeringFaults {
    /// The motor no longer moves the wheels.
    pub stuck: bool,
    /// The motor's rate is cut to this fraction.
    pub rate_factor: f64,
    /// The wheels sit this far from where the position sensor says, degrees.
    pub offset_deg: f64,
    /// A driver holds the wheel at this angle, against the motor (degrees).
    pub driver_deg: Option<f64>,
}

impl Default for SteeringFaults {
    fn default() -> Self {
        SteeringFaults {
            stuck: false,
            rate_factor: 1.0,
            offset_deg: 0.0,
            driver_deg: None,
        }
    }
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
            faults: SteeringFaults::default(),
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
        if let Some(driver) = self.faults.driver_deg {
            // The driver's hands win: the wheel goes where they turn it, at the
            // motor's full rate.
            let step = (driver - self.angle_deg)
                .clamp(-self.cfg.max_rate_deg_s * dt, self.cfg.max_rate_deg_s * dt);
            self.rate_deg_s = step / dt;
            self.angle_deg = (self.angle_deg + step).clamp(-self.limit_deg, self.limit_deg);
            return;
        }
        if !self.safety.enabled() || self.faults.stuck {
            // Safe state (or a stuck motor): the angle holds.
            self.rate_deg_s = 0.0;
            return;
        }
        let max_rate = self.max_rate_deg_s * self.faults.rate_factor;
        let wanted = (self.target_deg - self.angle_deg) / self.cfg.time_constant_s;
        let rate = wanted.clamp(-max_rate, max_rate);
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

    /// The actual road-wheel angle, radians: the servoed (reported) angle plus the
    /// sensor bias, within the mechanical limit.
    pub fn angle(&self) -> f64 {
        self.angle_deg().to_radians()
    }

    /// The actual road-wheel angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        (self.angle_deg + self.cfg.bias_deg + self.faults.offset_deg)
            .clamp(-self.limit_deg, self.limit_deg)
    }

    pub fn rate_deg_s(&self) -> f64 {
        self.rate_deg_s
    }

    /// The STEERING_REPORT of this instant.
    pub fn report(&self) -> SteeringReport {
        SteeringReport {
            enabled: self.safety.enabled(),
            r#override: self.faults.driver_deg.is_some(),
            fault: match self.safety.fault() {
                None => SteeringReportFault::None,
                Some(Cause::CommandTimeout) => SteeringReportFault::CommandTimeout,
                Some(Cause::HeartbeatTimeout) => SteeringReportFault::HeartbeatTimeout,
                Some(Cause::Estop) => SteeringReportFault::Estop,
                Some(Cause::FaultReport) => SteeringReportFault::FaultReport,
                Some(Cause::SecondSender) => SteeringReportFault::SecondSender,
                Some(Cause::Actuator) => match self.safety.actuator_fault() {
                    Some(EcuFaultCode::Overcurrent) => SteeringReportFault::Overcurrent,
                    Some(EcuFaultCode::Sensor) => SteeringReportFault::PositionSensor,
                    _ => SteeringReportFault::Internal,
                },
            },
            angle: self.angle_deg.clamp(-45.0, 45.0),
            rate: self.rate_deg_s.clamp(-500.0, 500.0),
            motor_current: (self.cfg.idle_current_a
                + self.cfg.current_per_rate_a * self.rate_deg_s.abs())
            .clamp(0.0, 25.5),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ecu::safety::{Safety, SafetyTiming};
    use golf_car_can::ControllerHeartbeatState;

    fn safety() -> Safety {
        Safety::new(SafetyTiming {
            command_timeout: 1.0,
            heartbeat_timeout: 1.0,
            fault_clear: 0.25,
        })
    }

    fn settled(bias_deg: f64) -> SteeringEcu {
        let cfg = SteeringConfig {
            bias_deg,
            ..SteeringConfig::default()
        };
        let mut ecu = SteeringEcu::new(cfg, 35.0, safety());
        let dt = 0.005;
        for k in 0..400 {
            let now = f64::from(k) * dt;
            if k % 2 == 0 {
                ecu.on_command(
                    now,
                    &SteeringCmd {
                        enable: k > 10,
                        target_angle: 10.0,
                        max_rate: 0.0,
                    },
                );
                ecu.safety.on_heartbeat(now, ControllerHeartbeatState::Auto);
            }
            ecu.step(now, dt);
        }
        ecu
    }

    #[test]
    fn a_sensor_bias_offsets_the_wheels_but_not_the_report() {
        let nominal = settled(0.0);
        assert!(
            (nominal.angle_deg() - 10.0).abs() < 1e-6,
            "{}",
            nominal.angle_deg()
        );
        let biased = settled(2.0);
        assert!(
            (biased.angle_deg() - 12.0).abs() < 1e-6,
            "{}",
            biased.angle_deg()
        );
        assert!((biased.angle() - 12f64.to_radians()).abs() < 1e-9);
        assert!(
            (biased.report().angle - 10.0).abs() < 1e-6,
            "the ECU reports its sensor"
        );
        // The mechanical limit still holds.
        let mut ecu = settled(5.0);
        ecu.on_command(
            2.0,
            &SteeringCmd {
                enable: true,
                target_angle: 35.0,
                max_rate: 0.0,
            },
        );
        for k in 0..400 {
            ecu.safety
                .on_heartbeat(2.0 + f64::from(k) * 0.005, ControllerHeartbeatState::Auto);
            ecu.step(2.0 + f64::from(k) * 0.005, 0.005);
        }
        assert_eq!(ecu.angle_deg(), 35.0);
    }

    #[test]
    fn a_bias_is_validated_and_defaults_to_none() {
        use crate::scenario::Scenario;
        assert_eq!(SteeringConfig::default().bias_deg, 0.0);
        let ok = Scenario::from_toml("[steering]\nbias_deg = -2.5\n", "ok.toml");
        assert_eq!(ok.map(|s| s.steering.bias_deg).ok(), Some(-2.5));
        let err = Scenario::from_toml("[steering]\nbias_deg = 12.0\n", "bad.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("bad.toml:2: steering.bias_deg"), "{err}");
    }
}
