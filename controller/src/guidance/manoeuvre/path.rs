//! A manoeuvre's path: poses sampled along arcs, each with its steering curvature and
//! direction of travel, split into segments at the cusps (forward/reverse changes), and
//! smoothed within each segment.

use super::field::Field;

/// One pose of a manoeuvre (the rear axle), world frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathPoint {
    pub x: f64,
    pub y: f64,
    /// Heading of the car (not of the motion), radians.
    pub theta: f64,
    /// Steering curvature, tan(road-wheel angle) / wheelbase, left positive, 1/m.
    pub curvature: f64,
    /// Driven forward (else in gear R) to this pose.
    pub forward: bool,
}

impl PathPoint {
    pub fn pose(&self) -> [f64; 3] {
        [self.x, self.y, self.theta]
    }
}

/// The pose after driving `d` metres (negative: backwards) from `at` on the steering
/// curvature `curvature`.
pub fn arc(at: [f64; 3], d: f64, curvature: f64) -> [f64; 3] {
    turned_arc(at, at[2].sin_cos(), d, curvature).0
}

/// [`arc`] from `at`, whose heading's sine and cosine are `turn` (the search takes
/// many arcs from one pose), with the sine and cosine of the heading it ends at (the
/// rectangle's check there needs them): the same values, computed once.
pub fn turned_arc(
    at: [f64; 3],
    turn: (f64, f64),
    d: f64,
    curvature: f64,
) -> ([f64; 3], (f64, f64)) {
    let [x, y, theta] = at;
    let (sin, cos) = turn;
    if curvature.abs() < 1e-9 {
        return ([x + d * cos, y + d * sin, theta], turn);
    }
    let t = theta + curvature * d;
    let end = t.sin_cos();
    let pose = [
        x + (end.0 - sin) / curvature,
        y + (cos - end.1) / curvature,
        t,
    ];
    (pose, end)
}

/// A planned manoeuvre: from the car's pose (not included) to the goal.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manoeuvre {
    pub points: Vec<PathPoint>,
}

/// Smoothing: passes, the pull towards the neighbours' mean, and the pull back to the
/// searched pose.
const SMOOTH_PASSES: usize = 30;
const SMOOTH_WEIGHT: f64 = 0.3;
const DATA_WEIGHT: f64 = 0.1;

impl Manoeuvre {
    /// Index ranges of the segments driven in one direction, in order.
    pub fn segments(&self) -> Vec<std::ops::Range<usize>> {
        let mut out = Vec::new();
        let mut start = 0;
        for j in 1..=self.points.len() {
            if j == self.points.len() || self.points[j].forward != self.points[start].forward {
                out.push(start..j);
                start = j;
            }
        }
        out
    }

    /// Direction changes.
    pub fn cusps(&self) -> usize {
        self.segments().len().saturating_sub(1)
    }

    /// Length driven, metres.
    pub fn length(&self, from: [f64; 3]) -> f64 {
        let mut last = from;
        let mut sum = 0.0;
        for p in &self.points {
            sum += (p.x - last[0]).hypot(p.y - last[1]);
            last = p.pose();
        }
        sum
    }

    /// The path smoothed within each segment (its ends, the cusps, held): positions
    /// pulled towards their neighbours' mean and back towards the searched ones, then
    /// headings and curvatures taken from the smoothed positions; a segment whose
    /// smoothed poses the car's rectangle no longer clears in `field` is kept as
    /// searched.
    pub fn smoothed(&self, from: [f64; 3], field: &Field) -> Manoeuvre {
        let mut points = self.points.clone();
        for range in self.segments() {
            let before = if range.start == 0 {
                from
            } else {
                points[range.start - 1].pose()
            };
            let mut xy: Vec<[f64; 2]> = std::iter::once([before[0], before[1]])
                .chain(points[range.clone()].iter().map(|p| [p.x, p.y]))
                .collect();
            let searched = xy.clone();
            for _ in 0..SMOOTH_PASSES {
                for j in 1..xy.len().saturating_sub(1) {
                    for k in 0..2 {
                        let mean = (xy[j - 1][k] + xy[j + 1][k]) / 2.0;
                        xy[j][k] += SMOOTH_WEIGHT * (mean - xy[j][k])
                            + DATA_WEIGHT * (searched[j][k] - xy[j][k]);
                    }
                }
            }
            let forward = points[range.start].forward;
            let smooth = headings(&xy, forward, before[2]);
            if smooth.iter().all(|p| field.passable(p)) {
                points.splice(range, smooth);
            }
        }
        Manoeuvre { points }
    }
}

/// Poses along the smoothed positions `xy` (the segment's start first): the heading of
/// the chord (reversed when driven backwards) and the curvature from the heading change
/// per metre travelled.
fn headings(xy: &[[f64; 2]], forward: bool, start: f64) -> Vec<PathPoint> {
    let sign = if forward { 1.0 } else { -1.0 };
    let mut last = start;
    let mut out = Vec::with_capacity(xy.len());
    for j in 1..xy.len() {
        let (dx, dy) = (xy[j][0] - xy[j - 1][0], xy[j][1] - xy[j - 1][1]);
        let step = dx.hypot(dy).max(1e-9);
        let theta = if j + 1 == xy.len() {
            // The last: the chord from the one before.
            dy.atan2(dx) + if forward { 0.0 } else { std::f64::consts::PI }
        } else {
            let ahead = (xy[j + 1][0] - xy[j - 1][0], xy[j + 1][1] - xy[j - 1][1]);
            let chord = ahead.1.atan2(ahead.0);
            if forward {
                chord
            } else {
                chord + std::f64::consts::PI
            }
        };
        let turn = super::super::frame::wrap(theta - last);
        out.push(PathPoint {
            x: xy[j][0],
            y: xy[j][1],
            theta: last + turn,
            curvature: sign * turn / step,
            forward,
        });
        last += turn;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f64, forward: bool) -> PathPoint {
        PathPoint {
            x,
            y: 0.0,
            theta: 0.0,
            curvature: 0.0,
            forward,
        }
    }

    #[test]
    fn segments_split_at_each_change_of_direction() {
        let m = Manoeuvre {
            points: vec![
                point(1.0, true),
                point(2.0, true),
                point(1.5, false),
                point(1.0, false),
                point(2.0, true),
            ],
        };
        assert_eq!(m.segments(), vec![0..2, 2..4, 4..5]);
        assert_eq!(m.cusps(), 2);
        assert!((m.length([0.0, 0.0, 0.0]) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn a_turned_arc_is_the_arc_and_its_end_heading_turned() {
        let from = [1.0, -2.0, 0.7];
        for (d, curvature) in [(0.4, 0.0), (-0.3, 0.38), (0.1, -0.19), (2.0, 1e-10)] {
            let (end, (sin, cos)) = turned_arc(from, from[2].sin_cos(), d, curvature);
            assert_eq!(end, arc(from, d, curvature));
            assert_eq!((sin.to_bits(), cos.to_bits()), {
                let (s, c) = end[2].sin_cos();
                (s.to_bits(), c.to_bits())
            });
        }
    }

    #[test]
    fn an_arc_of_a_quarter_circle_ends_a_radius_ahead_and_aside() {
        let r = 2.0;
        let end = arc([0.0, 0.0, 0.0], r * std::f64::consts::FRAC_PI_2, 1.0 / r);
        assert!((end[0] - r).abs() < 1e-12 && (end[1] - r).abs() < 1e-12);
        // Backwards on the same steering the car turns the other way.
        let back = arc([0.0, 0.0, 0.0], -1.0, 1.0 / r);
        assert!(back[0] < 0.0 && back[1] > 0.0 && back[2] < 0.0);
    }
}
