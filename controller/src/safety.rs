//! The controller's safety (docs/design.md): every reason to stop the car, each with
//! the FAULT_REPORT code it sends.
//!
//! - The watchdogs on the inputs ([`check`]): a GPS fix that is missing, older than
//!   `safety.gps_timeout_s`, below RTK (a float counts with `safety.accept_rtk_float`)
//!   or that jumped against dead reckoning; laser scans silent for
//!   `safety.laser_timeout_s` (a scan of mostly dropouts is no scan:
//!   [`shows_the_laser_sees`]); a STEERING_REPORT or THROTTLE_REPORT silent for
//!   `safety.report_timeout_s`; an ECU's own fault.
//! - The actuator monitor ([`monitor`]): the reports against the commands, for what an
//!   ECU does not report itself (a stuck steering or throttle, a driver's hands).
//! - The intrusion watch ([`intrusion`]): actuation nobody commanded, a second sender
//!   on the bus.
//!
//! The controller (`control.rs`) runs [`check`] at every tick while it enables
//! and drives, and the intrusion watch on every frame, and estops on the first
//! finding: estop heartbeat, FAULT_REPORT, both ECUs commanded disabled.

pub mod intrusion;
pub mod monitor;

use firmware_bridge::nmea::FixQuality;
use golf_car_can::FaultReportCode;

use crate::config::SafetyConfig;
use crate::localisation::Localiser;
use crate::perception::{Beam, Scan};
use monitor::ActuatorMonitor;

/// A scan with fewer usable beams (returns or free space) than this fraction is
/// blindness, not a scan: the laser-silence watchdog is not refreshed by it.
pub const MIN_USABLE_BEAMS: f64 = 0.5;

/// A reason to stop: the code FAULT_REPORT carries, and what happened.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    pub code: FaultReportCode,
    pub reason: String,
}

impl Fault {
    fn new(code: FaultReportCode, reason: String) -> Fault {
        Fault { code, reason }
    }
}

/// What the watchdogs read at a tick.
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a> {
    /// The GPS fixes (the last one's time and quality, a jump).
    pub localiser: &'a Localiser,
    /// When the last scan that showed the laser sees came, controller seconds.
    pub last_scan: Option<f64>,
    /// When the last STEERING_REPORT came, controller seconds.
    pub steering_report: Option<f64>,
    /// When the last THROTTLE_REPORT came, controller seconds.
    pub throttle_report: Option<f64>,
    /// An ECU's own fault while driving (its report's fault field, a FAULT_REPORT).
    pub ecu_fault: Option<&'a str>,
    pub monitor: &'a ActuatorMonitor,
}

/// Whether a scan (one perception took, or whose beams are to be judged) shows the
/// laser sees: at least [`MIN_USABLE_BEAMS`] of its beams are returns or free space,
/// not dropouts (a NaN or zero-range storm shows nothing).
pub fn shows_the_laser_sees(scan: &Scan<'_>) -> bool {
    let usable = (0..scan.ranges.len())
        .filter(|&i| scan.beam(i) != Beam::Dropout)
        .count();
    (usable as f64) >= MIN_USABLE_BEAMS * scan.ranges.len() as f64
}

/// Every reason to stop at `now` (sensors, reports, ECU faults, the actuator
/// monitor), the first one found.
pub fn check(cfg: &SafetyConfig, now: f64, inputs: &Inputs<'_>) -> Result<(), Fault> {
    fix_ok(cfg, inputs.localiser, now)?;
    match inputs.last_scan {
        Some(t) if now - t <= cfg.laser_timeout_s => {}
        Some(t) => {
            return Err(Fault::new(
                FaultReportCode::LaserSilent,
                format!("no laser scan for {:.2} s", now - t),
            ));
        }
        None => {
            return Err(Fault::new(
                FaultReportCode::LaserSilent,
                "no laser scan".to_owned(),
            ));
        }
    }
    for (name, last) in [
        ("STEERING_REPORT", inputs.steering_report),
        ("THROTTLE_REPORT", inputs.throttle_report),
    ] {
        match last {
            Some(t) if now - t <= cfg.report_timeout_s => {}
            _ => {
                return Err(Fault::new(
                    FaultReportCode::ReportTimeout,
                    format!("{name} silent"),
                ));
            }
        }
    }
    if let Some(f) = inputs.ecu_fault {
        return Err(Fault::new(FaultReportCode::ActuatorFault, f.to_owned()));
    }
    if let Some(f) = inputs.monitor.finding() {
        return Err(Fault::new(FaultReportCode::ActuatorFault, f.reason.clone()));
    }
    Ok(())
}

/// The GPS at `now`: a fix within the timeout, of RTK quality, that did not jump.
fn fix_ok(cfg: &SafetyConfig, localiser: &Localiser, now: f64) -> Result<(), Fault> {
    if let Some(jump) = &localiser.jump {
        return Err(Fault::new(
            FaultReportCode::GpsDegraded,
            format!(
                "the GPS position jumped {:.2} m from the dead-reckoned one at {:.2} s",
                jump.metres, jump.at
            ),
        ));
    }
    match localiser.last_fix {
        None => Err(Fault::new(
            FaultReportCode::GpsLost,
            "no GPS fix".to_owned(),
        )),
        Some((t, _)) if now - t > cfg.gps_timeout() => Err(Fault::new(
            FaultReportCode::GpsLost,
            format!("no GPS fix for {:.2} s", now - t),
        )),
        Some((_, q)) => {
            let good =
                q == FixQuality::RtkFixed || (cfg.accept_rtk_float && q == FixQuality::RtkFloat);
            if good {
                Ok(())
            } else {
                Err(Fault::new(
                    FaultReportCode::GpsDegraded,
                    format!("GPS fix quality {q:?} is below RTK"),
                ))
            }
        }
    }
}
