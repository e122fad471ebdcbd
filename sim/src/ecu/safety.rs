//! The ECUs' common enable/disable state machine, watchdog and safe state (DESIGN.md):
//! an ECU whose commands or the heartbeat time out, or that sees an estop or any
//! FAULT_REPORT, disables; it re-enables only on an explicit enable (a 0 to 1 edge of
//! the command's enable bit) after the fault has cleared. So does one that sees a
//! second sender on a counter stream (golf_car_can::SenderWatch): someone other than
//! the controller is commanding it.

use golf_car_can::{ControllerHeartbeatState, FaultReportCode};

/// Why an ECU is in its safe state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Cause {
    CommandTimeout,
    HeartbeatTimeout,
    Estop,
    FaultReport,
    /// A second sender on a counter stream the ECU receives.
    SecondSender,
    /// The ECU's own hardware fault (overcurrent, sensor, internal; `Safety::actuator`).
    Actuator,
}

impl Cause {
    /// The FAULT_REPORT code for causes the ECU detects itself (it does not echo other
    /// nodes' reports, which would make two ECUs keep each other faulted).
    pub fn own_fault_code(self) -> Option<FaultReportCode> {
        match self {
            Cause::CommandTimeout => Some(FaultReportCode::CommandTimeout),
            Cause::HeartbeatTimeout => Some(FaultReportCode::HeartbeatTimeout),
            Cause::SecondSender => Some(FaultReportCode::SecondSender),
            // The code depends on the hardware fault: `EcuNode::due` picks it.
            Cause::Estop | Cause::FaultReport | Cause::Actuator => None,
        }
    }
}

/// Why an ECU did not enable when a command asked it to (Enable = 1 while disabled):
/// what the verdict names when a car stood (docs/wire-contract.md, "Enabling the ECUs").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct EnableRefusals {
    /// Whether the ECU was ever enabled.
    pub ever_enabled: bool,
    /// Enable 0 -> 1 edges refused: no heartbeat with State = auto within its timeout.
    pub no_auto_heartbeat: u64,
    /// Enable 0 -> 1 edges refused: a fault was latched.
    pub fault_latched: u64,
    /// Commands with Enable = 1 to the disabled ECU that were no 0 -> 1 edge (the
    /// enable bit held at 1 since an earlier command).
    pub without_edge: u64,
}

/// Timing of the watchdog, seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyTiming {
    pub command_timeout: f64,
    pub heartbeat_timeout: f64,
    /// How long without a FAULT_REPORT before another node's fault counts as cleared
    /// (and how long a second sender must have gone before its fault clears).
    pub fault_clear: f64,
}

/// The state machine.
#[derive(Clone, Debug)]
pub struct Safety {
    timing: SafetyTiming,
    last_command: Option<f64>,
    last_heartbeat: Option<(f64, ControllerHeartbeatState)>,
    last_fault_report: Option<f64>,
    last_second_sender: Option<f64>,
    enable_bit: bool,
    enabled: bool,
    latched: Option<Cause>,
    /// The ECU's own hardware fault while it lasts.
    actuator: Option<crate::faults::EcuFaultCode>,
    /// Times the safe state was entered, by cause order above.
    pub trips: [u64; 6],
    /// Commands that asked for an enable the ECU refused, by reason.
    pub refusals: EnableRefusals,
}

impl Safety {
    pub fn new(timing: SafetyTiming) -> Safety {
        Safety {
            timing,
            last_command: None,
            last_heartbeat: None,
            last_fault_report: None,
            last_second_sender: None,
            enable_bit: false,
            enabled: false,
            latched: None,
            actuator: None,
            trips: [0; 6],
            refusals: EnableRefusals::default(),
        }
    }

    /// A command arrived with this enable bit.
    pub fn on_command(&mut self, now: f64, enable: bool) {
        let edge = enable && !self.enable_bit;
        self.enable_bit = enable;
        self.last_command = Some(now);
        self.update(now);
        if !enable {
            self.enabled = false;
        } else if edge && self.latched.is_none() && self.heartbeat_auto(now) {
            self.enabled = true;
            self.refusals.ever_enabled = true;
        } else if !self.enabled {
            let r = &mut self.refusals;
            match (edge, self.latched.is_some()) {
                (false, _) => r.without_edge += 1,
                (true, true) => r.fault_latched += 1,
                (true, false) => r.no_auto_heartbeat += 1,
            }
        }
    }

    pub fn on_heartbeat(&mut self, now: f64, state: ControllerHeartbeatState) {
        self.last_heartbeat = Some((now, state));
        self.update(now);
    }

    /// A FAULT_REPORT from another node.
    pub fn on_fault_report(&mut self, now: f64) {
        self.last_fault_report = Some(now);
        self.update(now);
    }

    /// A counter stream shows a second sender now.
    pub fn on_second_sender(&mut self, now: f64) {
        self.last_second_sender = Some(now);
        self.update(now);
    }

    /// The ECU's own hardware fault starts (`Some`) or clears (`None`).
    pub fn set_actuator_fault(&mut self, now: f64, code: Option<crate::faults::EcuFaultCode>) {
        self.actuator = code;
        self.update(now);
    }

    /// The hardware fault in force, if any.
    pub fn actuator_fault(&self) -> Option<crate::faults::EcuFaultCode> {
        self.actuator
    }

    fn fresh(last: Option<f64>, now: f64, timeout: f64) -> bool {
        last.is_some_and(|t| now - t <= timeout)
    }

    fn heartbeat_auto(&self, now: f64) -> bool {
        self.last_heartbeat.is_some_and(|(t, s)| {
            now - t <= self.timing.heartbeat_timeout && s == ControllerHeartbeatState::Auto
        })
    }

    /// Whether a fault condition holds at `now`.
    fn holds(&self, cause: Cause, now: f64) -> bool {
        let heartbeat_fresh = Self::fresh(
            self.last_heartbeat.map(|h| h.0),
            now,
            self.timing.heartbeat_timeout,
        );
        // Timeouts count against an ECU that is (or was) being driven.
        let driven = self.enabled || self.latched.is_some();
        match cause {
            Cause::Estop => {
                heartbeat_fresh
                    && self
                        .last_heartbeat
                        .is_some_and(|(_, s)| s == ControllerHeartbeatState::Estop)
            }
            Cause::FaultReport => Self::fresh(self.last_fault_report, now, self.timing.fault_clear),
            Cause::SecondSender => {
                Self::fresh(self.last_second_sender, now, self.timing.fault_clear)
            }
            Cause::Actuator => self.actuator.is_some(),
            Cause::HeartbeatTimeout => driven && !heartbeat_fresh,
            Cause::CommandTimeout => {
                driven && !Self::fresh(self.last_command, now, self.timing.command_timeout)
            }
        }
    }

    /// Re-evaluate at time `now`: latch a fault (the first cause is kept while it
    /// holds, so the report says why the ECU tripped), clear it when no condition is
    /// left, disable when the controller leaves auto.
    pub fn update(&mut self, now: f64) {
        const ORDER: [Cause; 6] = [
            Cause::SecondSender,
            Cause::Actuator,
            Cause::Estop,
            Cause::FaultReport,
            Cause::HeartbeatTimeout,
            Cause::CommandTimeout,
        ];
        let kept = self.latched.filter(|c| self.holds(*c, now));
        // A second sender overrides whatever else the ECU is safe for, so its report
        // and FAULT_REPORT name the intruder.
        let current = if self.holds(Cause::SecondSender, now) {
            Some(Cause::SecondSender)
        } else {
            kept.or_else(|| ORDER.into_iter().find(|c| self.holds(*c, now)))
        };
        if let Some(cause) = current {
            let entered = self.latched.is_none()
                || (cause == Cause::SecondSender && self.latched != Some(cause));
            if entered {
                self.enabled = false;
                self.trips[cause as usize] += 1;
            }
        }
        self.latched = current;
        if self.enabled && !self.heartbeat_auto(now) {
            self.enabled = false;
        }
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// When the last command arrived.
    pub fn last_command(&self) -> Option<f64> {
        self.last_command
    }

    /// The fault being reported (latched until its condition clears).
    pub fn fault(&self) -> Option<Cause> {
        self.latched
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ControllerHeartbeatState::{Auto, Estop, Idle};

    fn timing() -> SafetyTiming {
        SafetyTiming {
            command_timeout: 0.1,
            heartbeat_timeout: 0.1,
            fault_clear: 0.25,
        }
    }

    /// Drive with commands and heartbeats every 10 ms from `from` to `to`.
    fn drive(s: &mut Safety, from: f64, to: f64, enable: bool) {
        let mut t = from;
        while t < to {
            s.on_heartbeat(t, Auto);
            s.on_command(t, enable);
            t += 0.01;
        }
    }

    #[test]
    fn enables_on_an_edge_with_the_heartbeat_in_auto() {
        let mut s = Safety::new(timing());
        s.on_command(0.0, true);
        assert!(!s.enabled(), "no heartbeat yet");
        s.on_heartbeat(0.01, Idle);
        s.on_command(0.01, true);
        assert!(!s.enabled(), "no edge, not auto");
        s.on_heartbeat(0.02, Auto);
        s.on_command(0.02, false);
        s.on_command(0.03, true);
        assert!(s.enabled());
        s.on_heartbeat(0.04, Idle);
        assert!(!s.enabled(), "leaving auto disables");
        assert_eq!(s.fault(), None);
    }

    #[test]
    fn enable_from_the_first_frame_before_an_auto_heartbeat_is_refused_and_counted() {
        let mut s = Safety::new(timing());
        // The mistake: Enable = 1 from the first command, the heartbeat auto after it.
        s.on_command(0.0, true);
        let mut t = 0.01;
        while t < 0.5 {
            s.on_heartbeat(t, Auto);
            s.on_command(t, true);
            t += 0.01;
        }
        assert!(!s.enabled());
        assert_eq!(s.fault(), None, "disabled without a fault");
        let r = s.refusals;
        assert!(!r.ever_enabled);
        assert_eq!(r.no_auto_heartbeat, 1, "{r:?}");
        assert!(r.without_edge >= 45, "{r:?}");
        // Done right: a 0, then the edge.
        s.on_command(0.5, false);
        s.on_command(0.51, true);
        assert!(s.enabled() && s.refusals.ever_enabled);
        // An edge while a fault is latched is counted as such.
        s.on_heartbeat(0.52, Estop);
        s.on_command(0.53, false);
        s.on_command(0.54, true);
        assert_eq!(s.refusals.fault_latched, 1, "{:?}", s.refusals);
    }

    #[test]
    fn command_timeout_latches_until_commands_return_and_an_edge() {
        let mut s = Safety::new(timing());
        drive(&mut s, 0.0, 0.05, false);
        drive(&mut s, 0.05, 1.0, true);
        assert!(s.enabled());
        // Commands stop, heartbeats go on.
        let mut t = 1.0;
        while t < 1.3 {
            s.on_heartbeat(t, Auto);
            s.update(t);
            t += 0.01;
        }
        assert!(!s.enabled());
        assert_eq!(s.fault(), Some(Cause::CommandTimeout));
        // Commands come back with enable held at 1: fault clears, but no re-enable.
        drive(&mut s, 1.3, 1.5, true);
        assert_eq!(s.fault(), None);
        assert!(!s.enabled());
        drive(&mut s, 1.5, 1.52, false);
        drive(&mut s, 1.52, 1.6, true);
        assert!(s.enabled());
        assert_eq!(s.trips[Cause::CommandTimeout as usize], 1);
    }

    #[test]
    fn timeout_trips_within_the_timeout_after_the_last_command() {
        let mut s = Safety::new(timing());
        drive(&mut s, 0.0, 0.02, false);
        drive(&mut s, 0.02, 0.5, true);
        let last = 0.49;
        s.update(last + 0.099);
        assert!(s.enabled());
        s.update(last + 0.101);
        assert!(!s.enabled());
        assert_eq!(
            s.fault(),
            Some(Cause::HeartbeatTimeout),
            "both stopped: heartbeat first"
        );
    }

    #[test]
    fn a_second_sender_trips_the_safe_state_until_it_has_gone() {
        let mut s = Safety::new(timing());
        drive(&mut s, 0.0, 0.02, false);
        drive(&mut s, 0.02, 0.2, true);
        assert!(s.enabled());
        s.on_second_sender(0.2);
        assert!(!s.enabled());
        assert_eq!(s.fault(), Some(Cause::SecondSender));
        assert_eq!(
            Cause::SecondSender.own_fault_code(),
            Some(FaultReportCode::SecondSender)
        );
        // While the stream is flagged, even enable edges with a heartbeat in auto (a
        // forger can send both) do not re-enable.
        let mut t = 0.21;
        let mut enable = false;
        while t < 0.6 {
            s.on_second_sender(t);
            s.on_heartbeat(t, Auto);
            s.on_command(t, enable);
            enable = !enable;
            assert!(!s.enabled(), "t = {t}");
            t += 0.01;
        }
        // Gone for longer than fault_clear: the fault clears, and an edge re-enables.
        drive(&mut s, 0.6, 0.9, false);
        assert_eq!(s.fault(), None);
        drive(&mut s, 0.9, 0.95, true);
        assert!(s.enabled());
        assert_eq!(s.trips[Cause::SecondSender as usize], 1);
    }

    #[test]
    fn a_second_sender_overrides_the_cause_an_ecu_was_already_safe_for() {
        let mut s = Safety::new(timing());
        drive(&mut s, 0.0, 0.02, false);
        drive(&mut s, 0.02, 0.2, true);
        s.on_heartbeat(0.2, Estop);
        assert_eq!(s.fault(), Some(Cause::Estop));
        s.on_second_sender(0.21);
        assert_eq!(s.fault(), Some(Cause::SecondSender));
        assert_eq!(s.trips[Cause::Estop as usize], 1);
        assert_eq!(s.trips[Cause::SecondSender as usize], 1);
        s.on_second_sender(0.22);
        assert_eq!(s.trips[Cause::SecondSender as usize], 1, "counted once");
    }

    #[test]
    fn estop_and_fault_reports_disable() {
        let mut s = Safety::new(timing());
        drive(&mut s, 0.0, 0.02, false);
        drive(&mut s, 0.02, 0.2, true);
        s.on_heartbeat(0.2, Estop);
        assert!(!s.enabled());
        assert_eq!(s.fault(), Some(Cause::Estop));
        drive(&mut s, 0.21, 0.3, false);
        drive(&mut s, 0.3, 0.4, true);
        assert!(s.enabled());
        s.on_fault_report(0.4);
        assert_eq!(s.fault(), Some(Cause::FaultReport));
        // Still faulted 0.2 s later (fault_clear 0.25), cleared after.
        drive(&mut s, 0.41, 0.6, false);
        assert_eq!(s.fault(), Some(Cause::FaultReport));
        drive(&mut s, 0.6, 0.7, false);
        assert_eq!(s.fault(), None);
        drive(&mut s, 0.7, 0.72, true);
        assert!(s.enabled());
    }
}
