//! Reeds-Shepp curves (Reeds and Shepp 1990: the shortest paths of a car that drives
//! forward and backward at a bounded curvature) from the `reeds_shepp` crate, which
//! computes the 12 base words in their 4 symmetries for a unit turning radius. Here
//! they are scaled to the car's turning radius, turned into arcs of signed length and
//! curvature, and verified: a word whose integrated end misses the goal is dropped, so
//! a defect in a formula can cost a curve, never a wrong one.

use super::path::{PathPoint, turned_arc};
use reeds_shepp_lib as rs;

/// A curve's integrated end may miss the goal by this much and still be taken, metres
/// and radians.
const END_TOLERANCE: f64 = 1e-3;

/// One arc of a curve: its length (a magnitude, metres), its steering curvature (left
/// positive, 1/m) and its direction of travel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arc {
    pub length: f64,
    pub curvature: f64,
    pub forward: bool,
}

/// A Reeds-Shepp curve between two poses.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    pub arcs: Vec<Arc>,
    pub length: f64,
}

impl Curve {
    /// Direction changes along the curve.
    pub fn cusps(&self) -> usize {
        self.arcs
            .windows(2)
            .filter(|w| w[0].forward != w[1].forward)
            .count()
    }

    /// The curve from `from` sampled every `step` metres or less (the start excluded,
    /// every arc's end included).
    pub fn sample(&self, from: [f64; 3], step: f64) -> Vec<PathPoint> {
        self.turned_points(from, step).map(|(p, _)| p).collect()
    }

    /// The samples of [`Curve::sample`], one by one, each with its heading's sine and
    /// cosine (what integrating the arcs computes, and the rectangle's checks need).
    pub fn turned_points(
        &self,
        from: [f64; 3],
        step: f64,
    ) -> impl Iterator<Item = (PathPoint, (f64, f64))> + '_ {
        let mut at = (from, from[2].sin_cos());
        self.arcs
            .iter()
            .flat_map(move |a| {
                let n = (a.length / step).ceil().max(1.0) as usize;
                let d = if a.forward { a.length } else { -a.length } / n as f64;
                (0..n).map(move |_| (d, a))
            })
            .map(move |(d, a)| {
                at = turned_arc(at.0, at.1, d, a.curvature);
                let [x, y, theta] = at.0;
                let p = PathPoint {
                    x,
                    y,
                    theta,
                    curvature: a.curvature,
                    forward: a.forward,
                };
                (p, at.1)
            })
    }

    /// Where the curve ends from `from`.
    fn end(&self, from: [f64; 3]) -> [f64; 3] {
        let start = (from, from[2].sin_cos());
        let (end, _) = self.arcs.iter().fold(start, |(at, turn), a| {
            let d = if a.forward { a.length } else { -a.length };
            turned_arc(at, turn, d, a.curvature)
        });
        end
    }
}

/// Every verified Reeds-Shepp curve from `from` to `to` (x, y, heading) for the turning
/// radius `radius`, shortest first; each verified as it is taken (the search's
/// heuristic takes one).
pub fn curves(from: [f64; 3], to: [f64; 3], radius: f64) -> impl Iterator<Item = Curve> {
    // The crate works in units of the turning radius, with headings in degrees.
    let pose = |p: [f64; 3]| rs::Pose {
        x: p[0] / radius,
        y: p[1] / radius,
        theta_degree: p[2].to_degrees(),
    };
    let words = rs::get_all_paths(pose(from), pose(to));
    // Only the lengths at first: the heuristic takes the first curve that verifies, the
    // analytic expansion a few, so each is made a curve when its turn comes (the
    // shortest left, the earlier word of equal ones, as a stable sort would order them).
    let mut left: Vec<(f64, usize)> = words
        .iter()
        .map(|w| w.iter().map(|e| arc_of(e, radius).length).sum())
        .enumerate()
        .filter(|&(_, length): &(usize, f64)| length.is_finite())
        .map(|(k, length)| (length, k))
        .collect();
    std::iter::from_fn(move || {
        let (next, _) = left
            .iter()
            .enumerate()
            .min_by(|(_, a), (_, b)| a.0.total_cmp(&b.0))?;
        let (length, k) = left.remove(next);
        Some(Curve {
            arcs: words[k].iter().map(|e| arc_of(e, radius)).collect(),
            length,
        })
    })
    .filter(move |c| reaches(c.end(from), to))
}

/// One of the crate's words as an arc for the turning radius `radius`.
fn arc_of(w: &rs::PathElement, radius: f64) -> Arc {
    Arc {
        length: w.param.abs() * radius,
        curvature: match w.steering {
            rs::Steering::Left => 1.0 / radius,
            rs::Steering::Right => -1.0 / radius,
            rs::Steering::Straight => 0.0,
        },
        forward: w.gear == rs::Gear::Forward,
    }
}

/// The shortest curve's length from `from` to `to`: the non-holonomic heuristic
/// without obstacles. Infinite when no curve verifies.
pub fn shortest(from: [f64; 3], to: [f64; 3], radius: f64) -> f64 {
    curves(from, to, radius)
        .next()
        .map_or(f64::INFINITY, |c| c.length)
}

fn reaches(end: [f64; 3], to: [f64; 3]) -> bool {
    let heading = super::super::frame::wrap(end[2] - to[2]).abs();
    (end[0] - to[0]).hypot(end[1] - to[1]) < END_TOLERANCE && heading < END_TOLERANCE
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn every_curve_ends_at_the_goal_and_the_shortest_is_no_longer_than_a_straight_run() {
        let r = 2.4;
        let goals = [
            [10.0, 0.0, 0.0],
            [0.0, 5.0, PI],
            [-3.0, 0.0, 0.0],
            [2.0, -4.0, -PI / 2.0],
            [0.5, 0.5, 2.5],
        ];
        for to in goals {
            let all: Vec<Curve> = curves([0.0, 0.0, 0.0], to, r).collect();
            assert!(!all.is_empty(), "no curve to {to:?}");
            for c in &all {
                let end = c.sample([0.0, 0.0, 0.0], 0.05).last().copied();
                let end = end.map(|p| [p.x, p.y, p.theta]).unwrap_or([0.0; 3]);
                assert!((end[0] - to[0]).hypot(end[1] - to[1]) < 1e-6, "{c:?}");
            }
            assert!(all.windows(2).all(|w| w[0].length <= w[1].length));
        }
        // Straight ahead: the curve is the straight line.
        assert!((shortest([0.0, 0.0, 0.0], [10.0, 0.0, 0.0], r) - 10.0).abs() < 1e-9);
        // Straight back: the same, in reverse.
        let back = &curves([0.0, 0.0, 0.0], [-3.0, 0.0, 0.0], r).collect::<Vec<_>>()[0];
        assert!((back.length - 3.0).abs() < 1e-9 && !back.arcs[0].forward);
    }

    #[test]
    fn turning_round_on_the_spot_takes_cusps() {
        // The same place facing the other way: no curve without a change of direction.
        let c = &curves([0.0, 0.0, 0.0], [0.0, 0.0, PI], 2.4).collect::<Vec<_>>()[0];
        assert!(c.cusps() >= 1, "{c:?}");
        assert!(c.length > 2.4 && c.length < 4.0 * 2.4 * PI);
    }
}
