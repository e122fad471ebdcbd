//! The verdict of a run: the simulator's report joined with the controller's trace,
//! judged against the scenario's success criteria, written with its figure.

use std::path::Path;

use serde::Serialize;
use ugv_controller::trace::Trace;

use crate::busload::BusLoadReport;
use crate::mode::Mode;
use crate::plot::{Figure, PlannedPath, render};
use crate::run::{Outcome, RunReport, SafeStateReport};
use crate::scenario::Scenario;
use crate::vehicle::VehicleState;

pub mod route;

/// Below this speed at the end, a stop counts as a stop, m/s.
const STOPPED: f64 = 0.05;

/// What the controller side contributes.
#[derive(Clone, Debug, Serialize)]
pub struct ControllerSummary {
    /// The controller's final mode (as it reported it).
    pub mode: serde_json::Value,
    pub tracking_error_rms: f64,
    /// RMS of the commanded steering rate, deg/s (the steering effort).
    pub steering_effort_deg_s: f64,
    pub replans: usize,
    pub infeasible_replans: usize,
    /// The reason of the controlled stop guidance held at the end, if it held one
    /// ("no forward path after 2 reversals").
    pub stop_reason: Option<String>,
    /// Reversals out of dead ends.
    pub reversals: u32,
}

/// The verdict of one run.
#[derive(Clone, Debug, Serialize)]
pub struct Verdict {
    /// "hil" or "sil".
    pub mode: Mode,
    pub passed: bool,
    /// Why it did not pass (empty when it did).
    pub failures: Vec<String>,
    pub goal_reached: bool,
    pub collision: bool,
    /// The outcome (with its time) and the rest of the simulator's report.
    #[serde(flatten)]
    pub report: RunReport,
    pub controller: Option<ControllerSummary>,
    /// HIL: from a GPS fix to the controller's first steering command with it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fix_latency: Option<crate::measure::FixLatency>,
    /// HIL: the gateways to physical buses and the laser driver, when in use.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wires: Option<crate::measure::WireStats>,
}

/// RMS of the commanded steering rate over the control samples, deg/s.
fn steering_effort(t: &Trace) -> f64 {
    let rates: Vec<f64> = t
        .samples
        .windows(2)
        .filter(|w| w[1].t > w[0].t)
        .map(|w| (w[1].steer_cmd - w[0].steer_cmd).to_degrees() / (w[1].t - w[0].t))
        .collect();
    if rates.is_empty() {
        0.0
    } else {
        (rates.iter().map(|r| r * r).sum::<f64>() / rates.len() as f64).sqrt()
    }
}

impl Verdict {
    /// When the run ended, simulated seconds.
    pub fn time(&self) -> f64 {
        match &self.report.outcome {
            Outcome::GoalReached { time }
            | Outcome::Collision { time, .. }
            | Outcome::TimeLimit { time }
            | Outcome::Stopped { time, .. } => *time,
        }
    }

    /// Judge a run: its outcome against the scenario's success criteria, the fault
    /// plan's expectations, the bus load and the ECUs' safe state; with the
    /// controller's summary when there is a trace.
    pub fn judge(
        mode: Mode,
        scenario: &Scenario,
        report: RunReport,
        trace: Option<&Trace>,
    ) -> Verdict {
        // With waypoints the goal counts only once the route was driven (every
        // waypoint passed in order): reaching its position by another way is no arrival.
        let route_driven = report.route.as_ref().is_none_or(route::RouteReport::driven);
        let goal_reached = route_driven && matches!(report.outcome, Outcome::GoalReached { .. });
        let collision = matches!(report.outcome, Outcome::Collision { .. });
        let mut failures = Vec::new();
        if collision {
            failures.push("collision".to_owned());
        }
        failures.extend(mission_failures(
            scenario,
            &report,
            goal_reached,
            route_driven,
        ));
        failures.extend(crate::faults::inject::unmet(
            &scenario.expect,
            &report.faults,
            report.safe_state.as_ref().map(|s| s.noticed_s),
        ));
        failures.extend(bus_load_failure(
            &report.bus_load,
            scenario.expect.bus_overloaded,
        ));
        if let Some(s) = &report.safe_state {
            failures.extend(safe_state_failures(s));
        }
        let controller = trace.map(ControllerSummary::of);
        Verdict {
            mode,
            passed: failures.is_empty(),
            failures,
            goal_reached,
            collision,
            report,
            controller,
            fix_latency: None,
            wires: None,
        }
    }
}

impl ControllerSummary {
    /// The summary of the controller's trace.
    fn of(t: &Trace) -> ControllerSummary {
        ControllerSummary {
            mode: serde_json::to_value(&t.mode).unwrap_or_default(),
            tracking_error_rms: t.tracking_error_rms,
            steering_effort_deg_s: steering_effort(t),
            replans: t.plans.len(),
            infeasible_replans: t.plans.iter().filter(|p| !p.feasible).count(),
            stop_reason: t.stop_reason.clone(),
            reversals: t.reversals,
        }
    }
}

/// How the run missed its mission, beyond a collision: the goal (and its route) not
/// reached, not stopped at the end, too little clearance, stopped by anything but
/// the fault plan or a mission ended at the goal.
fn mission_failures(
    scenario: &Scenario,
    report: &RunReport,
    goal_reached: bool,
    route_driven: bool,
) -> Vec<String> {
    let mut failures = Vec::new();
    if scenario.success.reach_goal && !goal_reached {
        failures.push(format!(
            "goal not reached ({:.2} m away)",
            report.distance_to_goal
        ));
    }
    if scenario.success.reach_goal && !goal_reached {
        // A car that stood: say why an ECU never enabled (docs/wire-contract.md).
        for (name, stats) in [
            ("steering", &report.steering_can),
            ("throttle", &report.throttle_can),
        ] {
            if stats.physical_reports.is_none()
                && let Some(why) = never_enabled(&stats.enable)
            {
                failures.push(format!("the {name} ECU never enabled: {why}"));
            }
        }
    }
    if scenario.success.reach_goal
        && let Some(failure) = report.route.as_ref().and_then(route::RouteReport::failure)
    {
        failures.push(failure);
    }
    if !scenario.success.reach_goal && report.final_state.v.abs() > STOPPED {
        failures.push(format!(
            "not stopped at the end ({:.2} m/s)",
            report.final_state.v
        ));
    }
    let closest = report
        .min_clearance
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    if closest < scenario.success.min_clearance {
        failures.push(format!(
            "clearance {closest:.2} m below the required {:.2} m",
            scenario.success.min_clearance
        ));
    }
    // A stop the fault plan caused (the controller killed) is what it tests, and a
    // controller that ended its mission at the goal (where the run does not end at
    // the goal) arrived.
    let planned_stop = !scenario.success.reach_goal
        && (report
            .faults
            .iter()
            .any(|f| f.fault.kind == crate::faults::FaultKind::ControllerKill)
            || (route_driven && report.distance_to_goal <= scenario.goal.tolerance));
    if let Outcome::Stopped { reason, .. } = &report.outcome
        && !planned_stop
    {
        failures.push(format!("stopped: {reason}"));
    }
    failures
}

/// The bus load against the expectation (`expect.bus_overloaded`), if it fails it.
fn bus_load_failure(load: &BusLoadReport, expect_overloaded: bool) -> Option<String> {
    // With the wire's time (can.bit_timing: SIL's memory bus, HIL's paced sends)
    // the bus carries no more than its bit rate: an overload shows as frames that
    // waited for it.
    let late = load.arbitration.as_ref().filter(|a| a.late > 0);
    let overloaded = load.peak_pct > 100.0 || late.is_some();
    if overloaded == expect_overloaded {
        return None;
    }
    Some(if let Some(a) = late {
        format!(
            "the bus could not carry the schedule: {} frames waited over {:.0} ms for it (longest {:.1} ms), {} still waiting at the end",
            a.late,
            firmware_bridge::can::arbiter::LATE_WAIT_S * 1e3,
            a.max_wait_ms,
            a.backlog
        )
    } else if overloaded {
        format!(
            "the bus would be overloaded: {:.0} % of {} kbit/s over the {:.0} ms to {:.2} s",
            load.peak_pct,
            load.bit_rate / 1000,
            crate::busload::PEAK_WINDOW_S * 1e3,
            load.peak_at_s
        )
    } else {
        format!(
            "expected an overloaded bus, its peak load is {:.0} % of {} kbit/s",
            load.peak_pct,
            load.bit_rate / 1000
        )
    })
}

/// The ECUs' safe state after the controller went away: each reported within its
/// bound, and the car stopped.
fn safe_state_failures(s: &SafeStateReport) -> Vec<String> {
    let mut failures = Vec::new();
    for (name, e) in [("steering", &s.steering), ("throttle", &s.throttle)] {
        if !e.within_bound {
            failures.push(match e.latency_ms {
                Some(l) => format!(
                    "the {name} ECU reported its safe state {l:.1} ms after its last command, beyond its {:.0} ms",
                    e.bound_ms
                ),
                None => format!("the {name} ECU never reported its safe state"),
            });
        }
    }
    if s.stopped_s.is_none() {
        failures.push("the car did not stop after the controller went away".to_owned());
    }
    failures
}

/// Why results could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    #[error("writing {path}: {source}")]
    Write {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("encoding the verdict: {0}")]
    Json(#[from] serde_json::Error),
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
}

fn write(path: &Path, text: &str) -> Result<(), ResultsError> {
    std::fs::write(path, text).map_err(|source| ResultsError::Write {
        path: path.display().to_string(),
        source,
    })
}

/// How a run ended, for [`judge_and_write`]: its mode, the simulator's report, the
/// driven path, and the controller's trace when there is one.
#[derive(Debug)]
pub struct RunEnd<'a> {
    pub mode: Mode,
    pub report: RunReport,
    pub driven: &'a [(f64, VehicleState)],
    pub trace: Option<&'a Trace>,
}

/// Why an ECU that never enabled did not, from what its commands asked
/// ([`crate::ecu::safety::EnableRefusals`]); `None` when it was enabled at some time, or
/// when no command asked it to.
pub fn never_enabled(r: &crate::ecu::safety::EnableRefusals) -> Option<String> {
    if r.ever_enabled {
        return None;
    }
    let mut why = Vec::new();
    if r.no_auto_heartbeat > 0 {
        why.push(format!(
            "{} Enable 0 -> 1 edge(s) without a CONTROLLER_HEARTBEAT auto in the last 100 ms",
            r.no_auto_heartbeat
        ));
    }
    if r.fault_latched > 0 {
        why.push(format!(
            "{} edge(s) while a fault was latched",
            r.fault_latched
        ));
    }
    if r.without_edge > 0 {
        why.push(format!(
            "{} command(s) with Enable = 1 that were no new 0 -> 1 edge (send 0, then 1, after a heartbeat auto)",
            r.without_edge
        ));
    }
    // No command asked it to enable: the controller never tried (or there was none),
    // which the other failures describe.
    (!why.is_empty()).then(|| why.join("; "))
}

/// Judge a finished run of `scenario` (HIL or SIL alike), let `measured` add what
/// only the mode knows (the HIL latency figures and wire statistics), and write the
/// results into `dir` (see [`write_results`]; the figure when `figures`).
pub fn judge_and_write(
    scenario: &Scenario,
    end: RunEnd<'_>,
    detection_radius: f64,
    dir: &Path,
    figures: bool,
    measured: impl FnOnce(&mut Verdict),
) -> Result<Verdict, ResultsError> {
    let mut verdict = Verdict::judge(end.mode, scenario, end.report, end.trace);
    measured(&mut verdict);
    write_results(
        dir,
        scenario,
        &verdict,
        end.driven,
        end.trace,
        figures.then_some(detection_radius),
    )?;
    Ok(verdict)
}

/// Write `verdict.json`, `trace.json` and `training.csv` (when there is a trace)
/// into `dir`, and `figure.svg` and `figure.png` when given the controller's
/// detection radius to draw (`None`: `--no-figures`).
pub fn write_results(
    dir: &Path,
    scenario: &Scenario,
    verdict: &Verdict,
    driven: &[(f64, VehicleState)],
    trace: Option<&Trace>,
    figure_detection_radius: Option<f64>,
) -> Result<(), ResultsError> {
    std::fs::create_dir_all(dir).map_err(|source| ResultsError::Write {
        path: dir.display().to_string(),
        source,
    })?;
    write(
        &dir.join("verdict.json"),
        &serde_json::to_string_pretty(verdict)?,
    )?;
    if let Some(t) = trace {
        write(&dir.join("trace.json"), &serde_json::to_string(t)?)?;
        // The follower's inputs and commands, for `ugv-controller anfis train`.
        write(&dir.join("training.csv"), &t.training_csv())?;
    }
    let Some(detection_radius) = figure_detection_radius else {
        return Ok(());
    };
    let plans: Vec<PlannedPath> = trace
        .map(|t| {
            t.plans
                .iter()
                .filter(|p| p.feasible)
                .map(|p| PlannedPath {
                    time: p.time,
                    points: p.path.clone(),
                    manoeuvre: p.manoeuvre.clone(),
                })
                .collect()
        })
        .unwrap_or_default();
    let title = format!(
        "{} ({}): {}",
        scenario.name,
        verdict.mode.as_str().to_uppercase(),
        if verdict.passed {
            "passed".to_owned()
        } else {
            verdict.failures.join(", ")
        }
    );
    render(
        &Figure {
            title,
            scenario,
            driven,
            plans: &plans,
            detection_radius,
            footprint_every: 2.0,
        },
        &dir.join("figure.svg"),
        &dir.join("figure.png"),
    )?;
    Ok(())
}
