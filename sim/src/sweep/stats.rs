//! The statistics of a sweep: a success rate's 95 % Wilson score interval, and
//! percentiles of a distribution.

use serde::{Deserialize, Serialize};

/// The normal quantile of a two-sided 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// The 95 % Wilson score interval of `successes` in `n` trials (`None` for no trials).
/// Unlike the normal approximation it stays within [0, 1] and is not empty at 0 or n
/// successes.
pub fn wilson95(successes: usize, n: usize) -> Option<[f64; 2]> {
    if n == 0 {
        return None;
    }
    let n = n as f64;
    let p = successes as f64 / n;
    let z2 = Z95 * Z95;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z95 / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    Some([(centre - half).max(0.0), (centre + half).min(1.0)])
}

/// p5, p50 and p95 of a sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    pub p5: f64,
    pub p50: f64,
    pub p95: f64,
    /// How many values they are of.
    pub n: usize,
}

/// The `q` quantile (0..=1) of sorted `values`, interpolated linearly between the
/// closest ranks (numpy's default, Hyndman and Fan's type 7).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, frac) = (pos.floor() as usize, pos.fract());
    match sorted.get(lo + 1) {
        Some(next) => sorted[lo] + frac * (next - sorted[lo]),
        None => sorted[lo],
    }
}

impl Percentiles {
    /// Of the finite values among `values`; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Percentiles> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(Percentiles {
            p5: quantile(&v, 0.05),
            p50: quantile(&v, 0.5),
            p95: quantile(&v, 0.95),
            n: v.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).abs() < 5e-5 && (a[1] - b[1]).abs() < 5e-5
    }

    #[test]
    fn wilson_intervals_match_published_values() {
        // Newcombe (1998), table I: 81/263 -> 0.2553-0.3662; 15/148 -> 0.0624-0.1605.
        let a = wilson95(81, 263).unwrap();
        assert!(close(a, [0.2553, 0.3662]), "{a:?}");
        let b = wilson95(15, 148).unwrap();
        assert!(close(b, [0.0624, 0.1605]), "{b:?}");
        // All and none: the interval is not empty, and ends at 1 and 0.
        let all = wilson95(20, 20).unwrap();
        assert!(close(all, [0.8389, 1.0]), "{all:?}");
        let none = wilson95(0, 20).unwrap();
        assert!(close(none, [0.0, 0.1611]), "{none:?}");
        assert_eq!(wilson95(0, 0), None);
    }

    #[test]
    fn percentiles_interpolate_between_ranks_and_skip_non_finite_values() {
        let p = Percentiles::of((1..=21).map(f64::from).chain([f64::NAN])).unwrap();
        assert_eq!((p.p5, p.p50, p.p95, p.n), (2.0, 11.0, 20.0, 21));
        let p = Percentiles::of([4.0, 1.0]).unwrap();
        assert!((p.p5 - 1.15).abs() < 1e-12 && p.p50 == 2.5 && (p.p95 - 3.85).abs() < 1e-12);
        let one = Percentiles::of([7.0]).unwrap();
        assert_eq!((one.p5, one.p95), (7.0, 7.0));
        assert_eq!(Percentiles::of([f64::INFINITY]), None);
    }
}
