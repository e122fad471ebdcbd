//! What a run leaves behind: the control samples, every replanning, the obstacles
//! last seen and the final mode, as JSON (for the verdict and the plots) and the
//! follower's training data as CSV (for `anfis train`).

use serde::Serialize;

use crate::core::{Controller, Mode, Sample};
use crate::guidance::{Circle, PlanRecord};

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Trace {
    pub mode: Mode,
    pub duration: f64,
    /// Root mean square of the lateral error against the planned paths, metres.
    pub tracking_error_rms: f64,
    pub samples: Vec<Sample>,
    pub plans: Vec<PlanRecord>,
    pub obstacles: Vec<Circle>,
    /// When each GPS fix came in and when the first steering command computed with it
    /// went out (the binary on the wires; empty in SIL).
    #[serde(default)]
    pub fix_timing: Vec<FixTiming>,
}

/// One GPS fix through the controller, on the machine's monotonic clock
/// (`firmware_bridge::clock::monotonic_ns`), so the simulator can put it beside the
/// moment it made the fix.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct FixTiming {
    /// The fix's UTC time of day, seconds.
    pub utc_s: f64,
    /// When the reader completed the fix.
    pub read_ns: u64,
    /// When the first STEERING_CMD after it was sent.
    pub command_ns: u64,
}

impl Trace {
    pub fn of(ctl: &Controller, duration: f64) -> Trace {
        let n = ctl.samples.len().max(1) as f64;
        Trace {
            mode: ctl.mode().clone(),
            duration,
            tracking_error_rms: (ctl
                .samples
                .iter()
                .map(|s| s.inputs.e_y.powi(2))
                .sum::<f64>()
                / n)
                .sqrt(),
            samples: ctl.samples.clone(),
            plans: ctl.nav.plans.clone(),
            obstacles: ctl.obstacles().to_vec(),
            fix_timing: Vec::new(),
        }
    }

    /// The follower's inputs and its steering command, one row per control tick.
    pub fn training_csv(&self) -> String {
        let mut out = String::from("t,e_y,e_theta,phi_ref,v,steer_cmd\n");
        for s in &self.samples {
            out.push_str(&format!(
                "{},{},{},{},{},{}\n",
                s.t, s.inputs.e_y, s.inputs.e_theta, s.inputs.phi_ref, s.inputs.v, s.steer_cmd
            ));
        }
        out
    }
}
