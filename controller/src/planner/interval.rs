//! Intervals of a6 with possibly infinite ends, the feasible set, and the choice of a6.
//!
//! Forbidden intervals are open (a6 on a boundary only touches the obstacle: the
//! clearance is exactly r_i + r_0 at one instant), so the feasible set, their complement,
//! is a sorted list of disjoint closed pieces, whose outer ends may be infinite.
//!
//! In JSON an interval is the array `[lo, hi]`; an infinite end is the string `"inf"` or
//! `"-inf"` (JSON has no infinity).

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// An interval [lo, hi] of a6 (lo <= hi); lo may be -inf and hi +inf.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Lower end (may be -inf).
    pub lo: f64,
    /// Upper end (may be +inf).
    pub hi: f64,
}

impl Interval {
    /// The whole real line.
    pub const ALL: Self = Self {
        lo: f64::NEG_INFINITY,
        hi: f64::INFINITY,
    };

    /// Whether v lies in the closed interval.
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }

    /// Whether v lies in the open interval (lo, hi).
    pub fn contains_open(&self, v: f64) -> bool {
        self.lo < v && v < self.hi
    }

    /// The point of the closed interval nearest to v.
    pub fn clamp(&self, v: f64) -> f64 {
        v.max(self.lo).min(self.hi)
    }

    /// Both ends infinite.
    pub fn is_all(&self) -> bool {
        self.lo == f64::NEG_INFINITY && self.hi == f64::INFINITY
    }
}

/// A real number or an infinity, as JSON sees it.
#[derive(Deserialize)]
#[serde(untagged)]
enum ExtendedReal {
    Number(f64),
    Text(String),
}

fn encode(v: f64) -> Result<serde_json::Value, String> {
    if v == f64::INFINITY {
        Ok(serde_json::Value::from("inf"))
    } else if v == f64::NEG_INFINITY {
        Ok(serde_json::Value::from("-inf"))
    } else if v.is_finite() {
        Ok(serde_json::Value::from(v))
    } else {
        Err(format!("interval end {v} is not a number"))
    }
}

fn decode(v: ExtendedReal) -> Result<f64, String> {
    match v {
        ExtendedReal::Number(n) => Ok(n),
        ExtendedReal::Text(s) => match s.as_str() {
            "inf" | "+inf" => Ok(f64::INFINITY),
            "-inf" => Ok(f64::NEG_INFINITY),
            other => Err(format!(
                "interval end {other:?}: expected a number, \"inf\" or \"-inf\""
            )),
        },
    }
}

impl Serialize for Interval {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::Error as _;
        let lo = encode(self.lo).map_err(S::Error::custom)?;
        let hi = encode(self.hi).map_err(S::Error::custom)?;
        [lo, hi].serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Interval {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let [lo, hi] = <[ExtendedReal; 2]>::deserialize(deserializer)?;
        let lo = decode(lo).map_err(D::Error::custom)?;
        let hi = decode(hi).map_err(D::Error::custom)?;
        if lo > hi {
            return Err(D::Error::custom(format!(
                "interval [{lo}, {hi}] is reversed"
            )));
        }
        Ok(Self { lo, hi })
    }
}

/// The complement of the union of open forbidden intervals: sorted, disjoint, closed
/// pieces (a piece can be a single point where two forbidden intervals just touch).
/// Empty when the forbidden intervals cover the whole line.
pub fn feasible_set(forbidden: &[Interval]) -> Vec<Interval> {
    let mut sorted: Vec<Interval> = forbidden.iter().copied().filter(|f| f.lo < f.hi).collect();
    sorted.sort_by(|a, b| a.lo.total_cmp(&b.lo));
    let mut pieces = Vec::new();
    // Start of the next feasible piece: everything below the first forbidden interval.
    let mut free_from = f64::NEG_INFINITY;
    let mut covered_to_inf = false;
    for f in sorted {
        if f.lo >= free_from && !(f.lo == f64::NEG_INFINITY && free_from == f64::NEG_INFINITY) {
            pieces.push(Interval {
                lo: free_from,
                hi: f.lo,
            });
        }
        if f.hi == f64::INFINITY {
            covered_to_inf = true;
            break;
        }
        free_from = free_from.max(f.hi);
    }
    if !covered_to_inf {
        pieces.push(Interval {
            lo: free_from,
            hi: f64::INFINITY,
        });
    }
    pieces
}

/// The feasible a6 nearest to `target` (J is a convex quadratic in a6 with its minimum
/// at `target`, so this is the constrained minimiser of J). Returns the value and
/// whether it was projected onto a boundary; None when the feasible set is empty.
/// Ties (two boundaries equally far) go to the smaller |a6|.
pub fn nearest_feasible(target: f64, feasible: &[Interval]) -> Option<(f64, bool)> {
    if feasible.iter().any(|piece| piece.contains(target)) {
        return Some((target, false));
    }
    let mut best: Option<f64> = None;
    for piece in feasible {
        let candidate = piece.clamp(target);
        if !candidate.is_finite() {
            continue;
        }
        best = match best {
            None => Some(candidate),
            Some(b) => {
                let (db, dc) = ((b - target).abs(), (candidate - target).abs());
                if dc < db || (dc == db && candidate.abs() < b.abs()) {
                    Some(candidate)
                } else {
                    Some(b)
                }
            }
        };
    }
    best.map(|b| (b, true))
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f64 = f64::INFINITY;

    fn iv(lo: f64, hi: f64) -> Interval {
        Interval { lo, hi }
    }

    #[test]
    fn no_forbidden_interval_leaves_everything_feasible() {
        assert_eq!(feasible_set(&[]), vec![Interval::ALL]);
    }

    #[test]
    fn overlapping_and_nested_intervals_merge() {
        let set = feasible_set(&[iv(3.0, 5.0), iv(-1.0, 1.0), iv(0.5, 2.0), iv(3.5, 4.0)]);
        assert_eq!(
            set,
            vec![iv(-INF, -1.0), iv(2.0, 3.0), iv(5.0, INF)],
            "pieces sorted and disjoint"
        );
    }

    #[test]
    fn half_lines_and_full_cover() {
        assert_eq!(
            feasible_set(&[iv(-INF, 1.0), iv(4.0, INF)]),
            vec![iv(1.0, 4.0)]
        );
        assert!(feasible_set(&[iv(-INF, 1.0), iv(0.0, INF)]).is_empty());
        assert!(feasible_set(&[Interval::ALL, iv(0.0, 1.0)]).is_empty());
        assert_eq!(feasible_set(&[iv(-INF, 2.0)]), vec![iv(2.0, INF)]);
    }

    #[test]
    fn touching_open_intervals_leave_a_point() {
        assert_eq!(
            feasible_set(&[iv(0.0, 1.0), iv(1.0, 2.0)]),
            vec![iv(-INF, 0.0), iv(1.0, 1.0), iv(2.0, INF)]
        );
    }

    #[test]
    fn nearest_feasible_projects_and_breaks_ties_towards_zero() {
        let set = vec![iv(-INF, -1.0), iv(1.0, INF)];
        // Equally far: the first piece's boundary is kept (|-1| == |1|).
        assert_eq!(nearest_feasible(0.0, &set), Some((-1.0, true)));
        assert_eq!(nearest_feasible(0.2, &set), Some((1.0, true)));
        assert_eq!(nearest_feasible(-0.2, &set), Some((-1.0, true)));
        assert_eq!(nearest_feasible(5.0, &set), Some((5.0, false)));
        assert_eq!(nearest_feasible(0.0, &[]), None);
        // Equal distance, different magnitudes: the smaller |a6| wins.
        let uneven = vec![iv(-INF, -2.0), iv(4.0, INF)];
        assert_eq!(nearest_feasible(1.0, &uneven), Some((-2.0, true)));
    }
}
