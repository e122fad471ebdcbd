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
    let gaps = Gaps::new(
        scan.angle_increment.abs(),
        lambda,
        cfg.max_dropout_beams,
        points.len(),
    );
    let mut clusters = Vec::new();
    let mut start = 0;
    for k in 1..=points.len() {
        let split = match (points.get(k - 1), points.get(k)) {
            (Some(a), Some(b)) => !joins(scan, a, b, &gaps, noise, cfg.max_dropout_beams),
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

/// The breakpoint's angular terms per number of beams between two hits (1 for
/// neighbours), computed once a scan: `dphi`, `sin(dphi)` and `sin(lambda - dphi)`,
/// the same values the threshold took per pair of hits.
struct Gaps {
    step: f64,
    lambda: f64,
    terms: Vec<(f64, f64, f64)>,
}

impl Gaps {
    fn new(step: f64, lambda: f64, max_dropouts: usize, points: usize) -> Gaps {
        let terms = (1..=max_dropouts.saturating_add(1).min(points))
            .map(|gap| gap_terms(gap, step, lambda))
            .collect();
        Gaps {
            step,
            lambda,
            terms,
        }
    }

    fn terms(&self, gap: usize) -> (f64, f64, f64) {
        self.terms
            .get(gap.wrapping_sub(1))
            .copied()
            .unwrap_or_else(|| gap_terms(gap, self.step, self.lambda))
    }
}

fn gap_terms(gap: usize, step: f64, lambda: f64) -> (f64, f64, f64) {
    let dphi = gap as f64 * step;
    (dphi, dphi.sin(), (lambda - dphi).sin())
}

fn joins(
    scan: &Scan<'_>,
    a: &ScanPoint,
    b: &ScanPoint,
    gaps: &Gaps,
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
    let (dphi, sin_dphi, sin_rest) = gaps.terms(b.beam - a.beam);
    if dphi >= gaps.lambda {
        return false;
    }
    let threshold = a.range.min(b.range) * sin_dphi / sin_rest + noise;
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

    #[test]
    fn the_gap_terms_are_those_of_the_pair_in_and_beyond_the_table() {
        let (step, lambda) = (0.5f64.to_radians(), 10f64.to_radians());
        let gaps = Gaps::new(step, lambda, 2, 100);
        for gap in [1, 2, 3, 7] {
            let dphi = gap as f64 * step;
            assert_eq!(gaps.terms(gap), (dphi, dphi.sin(), (lambda - dphi).sin()));
        }
        assert_eq!(gaps.terms.len(), 3);
    }
}
