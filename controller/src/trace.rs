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
