//! Adjacent-beam clustering with Borges and Aldon's adaptive breakpoint.

use std::ops::Range;

use super::config::PerceptionConfig;
use super::frame::{Beam, Scan, ScanPoint};

/// Splits the hits of `scan` (as returned by [`super::scan_points`], beam order) into
/// clusters: index ranges into `points`, each with at least `min_points` hits.
///
/// Consecutive hits a, b join when no beam between them is a no-return, at most
/// `max_dropout_beams` dropouts lie between them, and their distance is below
/// `min(r_a, r_b) sin(dphi) / sin(lambda - dphi) + k sigma_r`, dphi the angle between
/// their beams (never when dphi >= lambda).
pub fn cluster_points(
    scan: &Scan<'_>,
    points: &[ScanPoint],
    cfg: &PerceptionConfig,
) -> Vec<Range<usize>> {
    let lambda = cfg.breakpoint_lambda_deg.to_radians();
    let noise = cfg.breakpoint_noise_factor * cfg.range_noise_sigma;
    let step = scan.angle_increment.abs();
    let mut clusters = Vec::new();
    let mut start = 0;
    for k in 1..=points.len() {
        let split = match (points.get(k - 1), points.get(k)) {
            (Some(a), Some(b)) => !joins(scan, a, b, step, lambda, noise, cfg.max_dropout_beams),
            _ => true,
        };
        if split {
            if k - start >= cfg.min_points {
                clusters.push(start..k);
            }
            start = k;
        }
    }
    clusters
}

fn joins(
    scan: &Scan<'_>,
    a: &ScanPoint,
    b: &ScanPoint,
    step: f64,
    lambda: f64,
    noise: f64,
    max_dropouts: usize,
) -> bool {
    let between = (a.beam + 1)..b.beam;
    if between.len() > max_dropouts {
        return false;
    }
    if between.clone().any(|i| scan.beam(i) == Beam::NoReturn) {
        return false;
    }
    let dphi = (b.beam - a.beam) as f64 * step;
    if dphi >= lambda {
        return false;
    }
    let threshold = a.range.min(b.range) * dphi.sin() / (lambda - dphi).sin() + noise;
    let (dx, dy) = (a.laser[0] - b.laser[0], a.laser[1] - b.laser[1]);
    (dx * dx + dy * dy).sqrt() <= threshold
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::{Pose2, scan_points};

    fn scan(ranges: &[f32]) -> Scan<'_> {
        Scan {
            stamp: 0.0,
            angle_min: -0.1,
            angle_increment: 0.5f64.to_radians(),
            range_min: 0.05,
            range_max: 20.0,
            ranges,
        }
    }

    #[test]
    fn range_jump_splits_and_no_return_splits_and_dropout_bridges() {
        let cfg = PerceptionConfig::default();
        let ranges = [
            5.0,
            5.0,
            5.0,
            7.0,
            7.0,
            7.0,
            f32::INFINITY,
            7.0,
            7.0,
            f32::NAN,
            7.0,
            7.0,
        ];
        let s = scan(&ranges);
        let p = Pose2::new(0.0, 0.0, 0.0);
        let pts = scan_points(&s.validate().expect("valid"), &p, &p).expect("finite");
        let c = cluster_points(&s, &pts, &cfg);
        assert_eq!(c, vec![0..3, 3..6, 6..10]);
    }
}
