//! Global maximisation of a smooth function of time on an interval: uniform sampling,
//! then golden-section refinement around the best discrete local maxima.
//!
//! Failure mode (documented, not hidden): two separate local maxima within one sampling
//! step may be merged and the lower one refined. With the default 2048 steps per window
//! this needs features shorter than 1/2048 of the window.

use serde::{Deserialize, Serialize};

/// Resolution of the time sampling.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Sampling {
    /// Uniform steps per sampled interval (collision window, or the whole step for the
    /// clearance diagnostic). At least 16.
    pub steps: usize,
    /// How many of the best discrete local extrema are refined by golden section.
    /// At least 1.
    pub refine_candidates: usize,
}

impl Default for Sampling {
    fn default() -> Self {
        Self {
            steps: 2048,
            refine_candidates: 8,
        }
    }
}

/// Inverse golden ratio.
const INV_PHI: f64 = 0.618_033_988_749_894_9;

/// Golden-section search for the maximum of `f` on [lo, hi]; returns the best point
/// evaluated. Stops when the bracket no longer shrinks in floating point (at most 120
/// iterations, i.e. a bracket 1e-25 of the start).
fn golden_max(f: &dyn Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> (f64, f64) {
    let mut x1 = hi - INV_PHI * (hi - lo);
    let mut x2 = lo + INV_PHI * (hi - lo);
    let mut f1 = f(x1);
    let mut f2 = f(x2);
    let mut best = if f1 >= f2 { (x1, f1) } else { (x2, f2) };
    for _ in 0..120 {
        if !(x1 > lo && x2 > x1 && hi > x2) {
            break;
        }
        if f1 < f2 {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + INV_PHI * (hi - lo);
            f2 = f(x2);
            if f2 > best.1 {
                best = (x2, f2);
            }
        } else {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - INV_PHI * (hi - lo);
            f1 = f(x1);
            if f1 > best.1 {
                best = (x1, f1);
            }
        }
    }
    best
}

/// The maximum of `f` over [a, b] (a <= b) as (argument, value). `f` returns -inf where
/// it is undefined. Samples `steps + 1` points (both ends included), then refines each
/// of the `refine_candidates` best discrete local maxima by golden section on the two
/// sampling steps around it.
pub fn maximise(f: &dyn Fn(f64) -> f64, a: f64, b: f64, sampling: &Sampling) -> (f64, f64) {
    let ts = sample_times(a, b, sampling);
    let vs: Vec<f64> = ts.iter().map(|&t| f(t)).collect();
    refine(f, &ts, &vs, sampling)
}

/// [`maximise`] of two functions over the same [a, b] whose values come from one
/// evaluation `g` at each sampled time (`g(t)` = (`f1(t)`, `f2(t)`)): the samples are
/// taken once for both, the golden-section refinements are each function's own. The
/// results are exactly those of `maximise(f1, ..)` and `maximise(f2, ..)`.
pub fn maximise_pair(
    g: &dyn Fn(f64) -> (f64, f64),
    f1: &dyn Fn(f64) -> f64,
    f2: &dyn Fn(f64) -> f64,
    a: f64,
    b: f64,
    sampling: &Sampling,
) -> ((f64, f64), (f64, f64)) {
    let ts = sample_times(a, b, sampling);
    let (vs1, vs2): (Vec<f64>, Vec<f64>) = ts.iter().map(|&t| g(t)).unzip();
    (
        refine(f1, &ts, &vs1, sampling),
        refine(f2, &ts, &vs2, sampling),
    )
}

/// The `steps + 1` sampled times of [a, b], both ends exact.
fn sample_times(a: f64, b: f64, sampling: &Sampling) -> Vec<f64> {
    let n = sampling.steps.max(2);
    (0..=n)
        .map(|j| {
            if j == n {
                b
            } else {
                a + (b - a) * (j as f64 / n as f64)
            }
        })
        .collect()
}

/// The best sample of `vs` (taken at `ts`), improved by golden section around the
/// `refine_candidates` best discrete local maxima.
fn refine(f: &dyn Fn(f64) -> f64, ts: &[f64], vs: &[f64], sampling: &Sampling) -> (f64, f64) {
    let n = ts.len() - 1;
    let mut best = (ts[0], f64::NEG_INFINITY);
    let mut peaks: Vec<usize> = Vec::new();
    for j in 0..=n {
        let v = vs[j];
        if v > best.1 {
            best = (ts[j], v);
        }
        let left = if j > 0 { vs[j - 1] } else { f64::NEG_INFINITY };
        let right = if j < n { vs[j + 1] } else { f64::NEG_INFINITY };
        if v > f64::NEG_INFINITY && v >= left && v >= right {
            peaks.push(j);
        }
    }
    peaks.sort_by(|&i, &j| vs[j].total_cmp(&vs[i]));
    for &j in peaks.iter().take(sampling.refine_candidates.max(1)) {
        let lo = ts[j.saturating_sub(1)];
        let hi = ts[(j + 1).min(n)];
        if hi > lo {
            let refined = golden_max(f, lo, hi);
            if refined.1 > best.1 {
                best = refined;
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_interior_maximum_beyond_sampling_resolution() {
        let peak = 0.123_456_789;
        let f = |t: f64| 1.0 - (t - peak) * (t - peak);
        let (t, v) = maximise(&f, 0.0, 1.0, &Sampling::default());
        assert!((t - peak).abs() < 1e-7);
        assert!((v - 1.0).abs() < 1e-14);
    }

    #[test]
    fn finds_maximum_at_an_end_and_skips_undefined_points() {
        let f = |t: f64| if t < 0.3 { f64::NEG_INFINITY } else { t };
        let (t, v) = maximise(&f, 0.0, 2.0, &Sampling::default());
        assert_eq!((t, v), (2.0, 2.0));
    }

    #[test]
    fn picks_the_global_of_several_local_maxima() {
        // Two bumps; the second is higher by 1e-3.
        let f = |t: f64| {
            (-(t - 0.2).powi(2) * 400.0).exp() + 1.001 * (-(t - 0.7).powi(2) * 400.0).exp()
        };
        let (t, _) = maximise(&f, 0.0, 1.0, &Sampling::default());
        assert!((t - 0.7).abs() < 1e-3);
    }

    #[test]
    fn sqrt_edge_maximum_is_refined() {
        // Infinite slope at the left end, maximum just inside (like a window edge).
        let f = |t: f64| t.max(0.0).sqrt() - 50.0 * t;
        let (t, v) = maximise(&f, 0.0, 1.0, &Sampling::default());
        let t_star = 1.0 / 10_000.0;
        assert!((t - t_star).abs() < 1e-7, "t = {t}");
        assert!((v - (t_star.sqrt() - 50.0 * t_star)).abs() < 1e-12);
    }
}
