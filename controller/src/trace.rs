//! What a run leaves behind: the control samples, every replanning, the obstacles
//! last seen and the final mode (for the verdict and the plots), and the follower's
//! training data as CSV (for `anfis train`).
//!
//! The controller binary writes its trace while it drives, as JSON Lines
//! ([`TraceWriter`]): one record per line, flushed at least once a second and at
//! every change of mode, so a controller killed with SIGKILL leaves everything up to
//! its last second on disk. [`Trace::from_jsonl`] reads such a file back, a cut-off
//! last line included.

use std::io::Write;

use serde::Serialize;

use crate::control::{Controller, Mode, Sample};
use crate::guidance::PlanRecord;
use crate::planner::Obstacle;

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Trace {
    pub mode: Mode,
    pub duration: f64,
    /// Root mean square of the lateral error against the planned paths, metres.
    pub tracking_error_rms: f64,
    pub samples: Vec<Sample>,
    pub plans: Vec<PlanRecord>,
    pub obstacles: Vec<Obstacle>,
    /// When each GPS fix came in and when the first steering command computed with it
    /// went out (the binary on the wires; empty in SIL).
    #[serde(default)]
    pub fix_timing: Vec<FixTiming>,
    /// The reason of the controlled stop guidance held at the end, if it held one.
    #[serde(default)]
    pub stop_reason: Option<String>,
    /// Reversals out of dead ends.
    #[serde(default)]
    pub reversals: u32,
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

/// Root mean square of the lateral error of `samples`, metres.
fn tracking_error_rms(samples: &[Sample]) -> f64 {
    let n = samples.len().max(1) as f64;
    (samples.iter().map(|s| s.inputs.e_y.powi(2)).sum::<f64>() / n).sqrt()
}

/// The header row of the training CSV.
const CSV_HEADER: &str = "t,e_y,e_theta,phi_ref,v,steer_cmd\n";

/// One training CSV row.
fn csv_row(s: &Sample) -> String {
    format!(
        "{},{},{},{},{},{}\n",
        s.t, s.inputs.e_y, s.inputs.e_theta, s.inputs.phi_ref, s.inputs.v, s.steer_cmd
    )
}

/// The controller's state at a moment: written at every flush and change of mode, the
/// last one read back is the trace's final state.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct StateRecord {
    pub t: f64,
    pub mode: Mode,
    pub obstacles: Vec<Obstacle>,
    #[serde(default)]
    pub stop_reason: Option<String>,
    #[serde(default)]
    pub reversals: u32,
}

/// One line of a JSON Lines trace.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TraceRecord {
    Sample(Sample),
    Plan(PlanRecord),
    Fix(FixTiming),
    State(StateRecord),
}

/// Why a JSON Lines trace could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TraceReadError {
    #[error("trace line {line}: {source}")]
    Line {
        line: usize,
        #[source]
        source: serde_json::Error,
    },
    #[error("the trace has no state record")]
    NoState,
}

impl Trace {
    pub fn of(ctl: &Controller, duration: f64) -> Trace {
        Trace {
            mode: ctl.mode().clone(),
            duration,
            tracking_error_rms: tracking_error_rms(&ctl.samples),
            samples: ctl.samples.clone(),
            plans: ctl.nav.plans.clone(),
            obstacles: ctl.obstacles().to_vec(),
            fix_timing: Vec::new(),
            stop_reason: ctl.stop_reason().map(str::to_owned),
            reversals: ctl.nav.reversals(),
        }
    }

    /// A trace written by [`TraceWriter`]. A last line without its newline (the
    /// writer was killed while writing it) is ignored; any other bad line is an error.
    pub fn from_jsonl(text: &str) -> Result<Trace, TraceReadError> {
        let complete = text.ends_with('\n');
        let lines: Vec<&str> = text.lines().collect();
        let mut samples = Vec::new();
        let mut plans = Vec::new();
        let mut fix_timing = Vec::new();
        let mut state: Option<StateRecord> = None;
        for (i, line) in lines.iter().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let record = match serde_json::from_str::<TraceRecord>(line) {
                Ok(r) => r,
                Err(_) if i + 1 == lines.len() && !complete => break,
                Err(source) => {
                    return Err(TraceReadError::Line {
                        line: i + 1,
                        source,
                    });
                }
            };
            match record {
                TraceRecord::Sample(s) => samples.push(s),
                TraceRecord::Plan(p) => plans.push(p),
                TraceRecord::Fix(f) => fix_timing.push(f),
                TraceRecord::State(s) => state = Some(s),
            }
        }
        let state = state.ok_or(TraceReadError::NoState)?;
        Ok(Trace {
            mode: state.mode,
            duration: state.t,
            tracking_error_rms: tracking_error_rms(&samples),
            samples,
            plans,
            obstacles: state.obstacles,
            fix_timing,
            stop_reason: state.stop_reason,
            reversals: state.reversals,
        })
    }

    /// The follower's inputs and its steering command, one row per control tick.
    pub fn training_csv(&self) -> String {
        let mut out = String::from(CSV_HEADER);
        for s in &self.samples {
            out.push_str(&csv_row(s));
        }
        out
    }
}

/// How often at least the trace reaches the disk, seconds of controller time.
pub const TRACE_FLUSH_PERIOD: f64 = 1.0;

/// Writes a run's trace as JSON Lines (and optionally the training CSV) while the
/// controller drives: what the controller added since the last call goes out at every
/// [`TraceWriter::update`], and reaches the file (a `write` to the kernel, which keeps
/// it when the process is killed) at least every [`TRACE_FLUSH_PERIOD`] and at every
/// change of mode.
#[derive(Debug)]
pub struct TraceWriter<W: Write = std::fs::File> {
    trace: Option<std::io::BufWriter<W>>,
    csv: Option<std::io::BufWriter<W>>,
    samples: usize,
    plans: usize,
    fixes: usize,
    mode: Option<Mode>,
    last_flush: f64,
    /// Every update reaches the file ([`TraceWriter::flushing_every_update`]).
    every_update: bool,
}

impl<W: Write> TraceWriter<W> {
    /// A writer of the trace to `trace` and the training CSV to `csv`, each when given.
    pub fn new(trace: Option<W>, csv: Option<W>) -> std::io::Result<TraceWriter<W>> {
        let mut csv = csv.map(std::io::BufWriter::new);
        if let Some(c) = &mut csv {
            c.write_all(CSV_HEADER.as_bytes())?;
        }
        Ok(TraceWriter {
            trace: trace.map(std::io::BufWriter::new),
            csv,
            samples: 0,
            plans: 0,
            fixes: 0,
            mode: None,
            last_flush: f64::NEG_INFINITY,
            every_update: false,
        })
    }

    /// The writer with every update written through to the file, as a lockstep
    /// controller needs: a tick acknowledged is then in the file, so that a controller
    /// killed between ticks leaves the trace SIL's in-memory one is (up to the last
    /// tick taken), not one short of the buffer it had not written yet.
    pub fn flushing_every_update(mut self) -> Self {
        self.every_update = true;
        self
    }

    fn record(&mut self, r: &TraceRecord) -> std::io::Result<()> {
        match &mut self.trace {
            Some(t) => {
                serde_json::to_writer(&mut *t, r)?;
                t.write_all(b"\n")
            }
            None => Ok(()),
        }
    }

    /// Write what is new in `ctl` (and `fixes`, the fix timings so far) at `now`.
    pub fn update(
        &mut self,
        now: f64,
        ctl: &Controller,
        fixes: &[FixTiming],
    ) -> std::io::Result<()> {
        for s in ctl.samples.get(self.samples..).unwrap_or(&[]) {
            self.record(&TraceRecord::Sample(*s))?;
            if let Some(c) = &mut self.csv {
                c.write_all(csv_row(s).as_bytes())?;
            }
        }
        self.samples = ctl.samples.len();
        for p in ctl.nav.plans.get(self.plans..).unwrap_or(&[]) {
            self.record(&TraceRecord::Plan(p.clone()))?;
        }
        self.plans = ctl.nav.plans.len();
        for f in fixes.get(self.fixes..).unwrap_or(&[]) {
            self.record(&TraceRecord::Fix(*f))?;
        }
        self.fixes = fixes.len();
        let changed = self.mode.as_ref() != Some(ctl.mode());
        if changed || now - self.last_flush >= TRACE_FLUSH_PERIOD {
            self.mode = Some(ctl.mode().clone());
            self.record(&TraceRecord::State(StateRecord {
                t: now,
                mode: ctl.mode().clone(),
                obstacles: ctl.obstacles().to_vec(),
                stop_reason: ctl.stop_reason().map(str::to_owned),
                reversals: ctl.nav.reversals(),
            }))?;
            self.flush()?;
            self.last_flush = now;
        } else if self.every_update {
            self.flush()?;
        }
        Ok(())
    }

    /// Everything written so far, to the file.
    pub fn flush(&mut self) -> std::io::Result<()> {
        if let Some(t) = &mut self.trace {
            t.flush()?;
        }
        if let Some(c) = &mut self.csv {
            c.flush()?;
        }
        Ok(())
    }

    /// The last records (the final state at `now`), flushed.
    pub fn finish(
        &mut self,
        now: f64,
        ctl: &Controller,
        fixes: &[FixTiming],
    ) -> std::io::Result<()> {
        self.last_flush = f64::NEG_INFINITY;
        self.update(now, ctl, fixes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ControllerConfig;
    use crate::guidance::follower::FollowInputs;
    use crate::localisation::Pose;
    use std::sync::{Arc, Mutex};

    /// A file whose bytes the test can look at while the writer holds it.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The samples in the file after a first update and one more sample 10 ms later.
    fn samples_in_file(flushing: bool) -> usize {
        let file = Shared::default();
        let mut w = TraceWriter::new(Some(file.clone()), None).unwrap();
        if flushing {
            w = w.flushing_every_update();
        }
        let mut ctl = Controller::new(&ControllerConfig::default()).unwrap();
        w.update(0.0, &ctl, &[]).unwrap();
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.0,
            phi: 0.0,
        };
        let inputs = FollowInputs {
            e_y: 0.01,
            e_theta: 0.0,
            phi_ref: 0.0,
            v: 0.0,
        };
        ctl.samples.push(Sample {
            t: 0.01,
            pose,
            inputs,
            steer_cmd: 0.0,
            speed_cmd: 0.0,
        });
        w.update(0.01, &ctl, &[]).unwrap();
        let text = String::from_utf8(file.0.lock().unwrap().clone()).unwrap();
        Trace::from_jsonl(&text).unwrap().samples.len()
    }

    #[test]
    fn a_lockstep_trace_has_every_update_in_its_file_at_once() {
        // Within the second between flushes, the sample waits in the buffer...
        assert_eq!(samples_in_file(false), 0);
        // ... unless every update is written through (lockstep).
        assert_eq!(samples_in_file(true), 1);
    }
}
