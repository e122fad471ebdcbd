//! The run's measurements of time and of the wires: timing distributions (report
//! jitter, tick lateness), the HIL loop's fix-to-command latency, and the statistics
//! of the GPS line, the gateways and the laser driver. The verdict carries them; the
//! runs (HIL, SIL) produce them.

use firmware_bridge::gateway::GatewayStats;
use serde::Serialize;
use ugv_controller::trace::FixTiming;

use crate::devices::cola_driver::ColaDriverStats;

/// Percentiles of a timing distribution, milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Jitter {
    pub samples: usize,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl Jitter {
    /// From absolute deviations in seconds.
    pub fn of(mut deviations: Vec<f64>) -> Jitter {
        if deviations.is_empty() {
            return Jitter::default();
        }
        deviations.sort_by(f64::total_cmp);
        let pick =
            |q: f64| deviations[((deviations.len() - 1) as f64 * q).round() as usize] * 1000.0;
        Jitter {
            samples: deviations.len(),
            p50_ms: pick(0.5),
            p99_ms: pick(0.99),
            max_ms: pick(1.0),
        }
    }
}

/// Statistics of the wires that carry more than the simulator's own ends.
#[derive(Clone, Debug, Serialize)]
pub struct WireStats {
    pub gps_line: GpsLineStats,
    pub gateways: Vec<GatewayStats>,
    pub laser_driver: Option<ColaDriverStats>,
}

/// The GPS line: what went out, and the whole sentences the receiver's transmit
/// buffer dropped because the reader did not keep up.
#[derive(Clone, Debug, Serialize)]
pub struct GpsLineStats {
    pub written_bytes: u64,
    pub dropped_sentences: u64,
    pub dropped_bytes: u64,
}

/// The HIL loop's latency: from the moment the simulator made a GPS fix to the
/// controller's first STEERING_CMD computed with it, split at the moment the
/// controller's reader completed the fix (which includes the line's transmission time
/// at the baud rate). Milliseconds. Fixes made before the controller's first read
/// waited in the line's buffer for the process to start: they are counted in
/// `backlog_at_start` and left out of the distributions, which describe the running
/// loop.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FixLatency {
    pub backlog_at_start: usize,
    pub fix_to_read: Jitter,
    pub read_to_command: Jitter,
    pub fix_to_command: Jitter,
}

const DAY_S: f64 = 86_400.0;

/// Join the controller's fix timings with the run's clock: the run started (tick 0)
/// at `start_ns` on the monotonic clock, with UTC `epoch_unix_s` at t = 0. `None`
/// without timings (a controller that does not record them).
pub fn fix_latency(timings: &[FixTiming], epoch_unix_s: f64, start_ns: u64) -> Option<FixLatency> {
    let epoch_of_day = epoch_unix_s.rem_euclid(DAY_S);
    let first_read_ns = timings.iter().map(|t| t.read_ns).min()? as f64;
    let mut backlog_at_start = 0;
    let mut to_read = Vec::new();
    let mut to_command = Vec::new();
    let mut read_to_command = Vec::new();
    for t in timings {
        // Sim time of the fix; a run may cross midnight UTC.
        let sim_t = (t.utc_s - epoch_of_day).rem_euclid(DAY_S);
        let fix_ns = start_ns as f64 + sim_t * 1e9;
        if fix_ns < first_read_ns {
            backlog_at_start += 1;
            continue;
        }
        to_read.push((t.read_ns as f64 - fix_ns) * 1e-9);
        to_command.push((t.command_ns as f64 - fix_ns) * 1e-9);
        read_to_command.push(t.command_ns.saturating_sub(t.read_ns) as f64 * 1e-9);
    }
    Some(FixLatency {
        backlog_at_start,
        fix_to_read: Jitter::of(to_read),
        read_to_command: Jitter::of(read_to_command),
        fix_to_command: Jitter::of(to_command),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fix_latency_puts_both_sides_on_the_run_clock() {
        // Epoch 2026-05-04T23:59:59Z: the second fix is after midnight UTC.
        let epoch = 1_777_939_199.0;
        let start = 5_000_000_000;
        let timing = |sim_t: f64, read_ms: f64, cmd_ms: f64| FixTiming {
            utc_s: (epoch + sim_t).rem_euclid(DAY_S),
            read_ns: start + ((sim_t * 1e3 + read_ms) * 1e6) as u64,
            command_ns: start + ((sim_t * 1e3 + cmd_ms) * 1e6) as u64,
        };
        // The first two waited for the controller to start reading at 0.32 s.
        let l = fix_latency(
            &[
                timing(0.0, 320.0, 330.0),
                timing(0.1, 221.0, 230.0),
                timing(0.5, 20.0, 25.0),
                timing(1.5, 30.0, 40.0),
            ],
            epoch,
            start,
        )
        .expect("timings");
        assert_eq!(l.backlog_at_start, 2, "{l:?}");
        assert_eq!(l.fix_to_command.samples, 2);
        assert!((l.fix_to_read.max_ms - 30.0).abs() < 1e-3, "{l:?}");
        assert!((l.fix_to_command.max_ms - 40.0).abs() < 1e-3, "{l:?}");
        assert!(
            (l.read_to_command.p50_ms - 5.0).abs() < 1e-3
                || (l.read_to_command.p50_ms - 10.0).abs() < 1e-3,
            "{l:?}"
        );
        assert!(fix_latency(&[], epoch, start).is_none());
    }
}
