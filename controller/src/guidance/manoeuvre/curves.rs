//! Reeds-Shepp curves (Reeds and Shepp 1990, "Optimal paths for a car that goes both
//! forwards and backwards": the shortest paths of a car that drives forward and backward
//! at a bounded curvature), for the car's turning radius, as arcs of signed length and
//! curvature, each verified: a curve whose integrated end misses the goal is dropped,
//! so a defect in a formula can cost a curve, never a wrong one.
//!
//! The analytic expansion takes the `reeds_shepp` crate's curves ([`curves`]): its 12
//! formulas in 4 symmetries give 48 candidates, some of them variants beyond the
//! canonical words, and the search tries the few shortest that its map clears. The
//! heuristic needs one number, the shortest length, at every node the search takes out
//! of its queue ([`shortest`]): through the crate that built all 48 candidates as
//! vectors, a quarter of a search. Ours solves the five families of the paper's
//! formulas (8.1-8.11: CSC, CCC, CCCC, CCSC, CCSCC) in their time-flip, reflection and
//! backwards symmetries as lengths on the stack, and makes a curve of the shortest
//! only, to verify it; a test checks the lengths against the crate's.

use super::path::{PathPoint, turned_arc};
use reeds_shepp_lib as rs;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

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
/// without obstacles, from our words (the same lengths as the crate's, a test says),
/// the shortest that verifies. Infinite when none does.
pub fn shortest(from: [f64; 3], to: [f64; 3], radius: f64) -> f64 {
    let mut words = Words::between(from, to, radius);
    std::iter::from_fn(move || words.take_shortest())
        .map(|w| w.curve(radius))
        .find(|c| reaches(c.end(from), to))
        .map_or(f64::INFINITY, |c| c.length)
}

fn reaches(end: [f64; 3], to: [f64; 3]) -> bool {
    let heading = super::super::frame::wrap(end[2] - to[2]).abs();
    (end[0] - to[0]).hypot(end[1] - to[1]) < END_TOLERANCE && heading < END_TOLERANCE
}

/// A segment's steering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Steer {
    Left,
    Straight,
    Right,
}

use Steer::{Left as L, Right as R, Straight as S};

/// A word: up to five segments, each a steering and a signed length in turning radii
/// (radians for a turn), negative backwards.
#[derive(Clone, Copy, Debug)]
struct Word {
    segments: [(Steer, f64); 5],
    n: usize,
    length: f64,
}

impl Word {
    fn new(steers: &[Steer], lengths: &[f64]) -> Word {
        let mut segments = [(S, 0.0); 5];
        for (k, (&steer, &l)) in steers.iter().zip(lengths).enumerate() {
            segments[k] = (steer, l);
        }
        Word {
            segments,
            n: steers.len(),
            length: lengths.iter().map(|l| l.abs()).sum(),
        }
    }

    /// The word as a curve for the turning radius `radius`, its segments of no length
    /// left out.
    fn curve(&self, radius: f64) -> Curve {
        let arcs: Vec<Arc> = self.segments[..self.n]
            .iter()
            .filter(|(_, l)| *l != 0.0)
            .map(|&(steer, l)| Arc {
                length: l.abs() * radius,
                curvature: match steer {
                    L => 1.0 / radius,
                    R => -1.0 / radius,
                    S => 0.0,
                },
                forward: l > 0.0,
            })
            .collect();
        Curve {
            length: self.length * radius,
            arcs,
        }
    }
}

/// Formulas' solutions within this of their bounds still count (rounding).
const ZERO: f64 = 1e-10;

/// `a` wrapped into [-pi, pi], unchanged when already in it (the guidance's `wrap`
/// shifts by pi and back, which rounds: the formulas' bounds at 0 would move).
fn wrap(a: f64) -> f64 {
    let v = a % TAU;
    if v < -PI {
        v + TAU
    } else if v > PI {
        v - TAU
    } else {
        v
    }
}

/// (x, y) as its length and angle.
fn polar((x, y): (f64, f64)) -> (f64, f64) {
    (x.hypot(y), y.atan2(x))
}

/// The words' solutions between two poses (44 at most: 11 formulas in 4 symmetries),
/// as lengths, on the stack.
struct Words {
    list: [Word; 44],
    n: usize,
}

/// The goal in the start's frame, radius 1: x, y, the heading phi and its sine and
/// cosine (computed once for the four symmetries: sin(-phi) = -sin(phi)).
#[derive(Clone, Copy)]
struct Rel {
    x: f64,
    y: f64,
    phi: f64,
    sin: f64,
    cos: f64,
}

impl Rel {
    /// The goal's offsets from the centres of the turns at its end: (x - sin phi,
    /// y - 1 + cos phi) for a left one, the formulas' (xi, eta).
    fn left(self) -> (f64, f64) {
        (self.x - self.sin, self.y - 1.0 + self.cos)
    }

    /// The same for a right turn: (x + sin phi, y - 1 - cos phi).
    fn right(self) -> (f64, f64) {
        (self.x + self.sin, self.y - 1.0 - self.cos)
    }
}

/// A base formula: the goal in the start's frame to the word's free lengths (t, u, v),
/// if it has a solution.
type Formula = fn(Rel) -> Option<(f64, f64, f64)>;
/// How a formula's (t, u, v) make its word's lengths.
type Make = fn(f64, f64, f64) -> [f64; 5];

impl Words {
    fn between(from: [f64; 3], to: [f64; 3], radius: f64) -> Words {
        let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
        let (s, c) = from[2].sin_cos();
        let x = (dx * c + dy * s) / radius;
        let y = (-dx * s + dy * c) / radius;
        let phi = wrap(to[2] - from[2]);
        // The goal as the backwards words see it: the start in the goal's frame.
        let (sin, cos) = phi.sin_cos();
        let ahead = Rel {
            x,
            y,
            phi,
            sin,
            cos,
        };
        let back = Rel {
            x: x * cos + y * sin,
            y: x * sin - y * cos,
            ..ahead
        };
        let mut w = Words {
            list: [Word::new(&[], &[]); 44],
            n: 0,
        };
        let tuv: Make = |t, u, v| [t, u, v, 0.0, 0.0];
        let vut: Make = |t, u, v| [v, u, t, 0.0, 0.0];
        let quarter: Make = |t, u, v| [t, -FRAC_PI_2, u, v, 0.0];
        let quarter_back: Make = |t, u, v| [v, u, -FRAC_PI_2, t, 0.0];
        // CSC (8.1, 8.2).
        w.symmetric(ahead, lsl, &[L, S, L], tuv);
        w.symmetric(ahead, lsr, &[L, S, R], tuv);
        // CCC (8.3, 8.4).
        w.symmetric(ahead, lrl, &[L, R, L], tuv);
        w.symmetric(back, lrl, &[L, R, L], vut);
        // CCCC (8.7, 8.8).
        w.symmetric(ahead, lrlr_same, &[L, R, L, R], |t, u, v| {
            [t, u, -u, v, 0.0]
        });
        w.symmetric(ahead, lrlr_opposite, &[L, R, L, R], |t, u, v| {
            [t, u, u, v, 0.0]
        });
        // CCSC (8.9, 8.10).
        w.symmetric(ahead, lrsl, &[L, R, S, L], quarter);
        w.symmetric(ahead, lrsr, &[L, R, S, R], quarter);
        w.symmetric(back, lrsl, &[L, S, R, L], quarter_back);
        w.symmetric(back, lrsr, &[R, S, R, L], quarter_back);
        // CCSCC (8.11).
        w.symmetric(ahead, lrslr, &[L, R, S, L, R], |t, u, v| {
            [t, -FRAC_PI_2, u, -FRAC_PI_2, v]
        });
        w
    }

    /// `f` for the goal `g` in the four symmetries: as it is, time-flipped (every
    /// length negated), reflected (left and right swapped) and both.
    fn symmetric(&mut self, g: Rel, f: Formula, steers: &[Steer], make: Make) {
        let n = steers.len();
        let mut reflected = [S; 5];
        for (r, s) in reflected.iter_mut().zip(steers) {
            *r = match s {
                L => R,
                R => L,
                S => S,
            };
        }
        let Rel {
            x,
            y,
            phi,
            sin,
            cos,
        } = g;
        let mirrored = |x, y, phi, sin| Rel {
            x,
            y,
            phi,
            sin,
            cos,
        };
        let cases = [
            (g, false, false),
            (mirrored(-x, y, -phi, -sin), true, false),
            (mirrored(x, -y, -phi, -sin), false, true),
            (mirrored(-x, -y, phi, sin), true, true),
        ];
        for (g, flip, reflect) in cases {
            if let Some((t, u, v)) = f(g) {
                let sign = if flip { -1.0 } else { 1.0 };
                let lengths = make(t, u, v).map(|l| sign * l);
                let steers = if reflect { &reflected[..n] } else { steers };
                self.list[self.n] = Word::new(steers, &lengths[..n]);
                self.n += 1;
            }
        }
    }

    /// The shortest word left (the earlier of equal ones), taken out.
    fn take_shortest(&mut self) -> Option<Word> {
        let mut best: Option<usize> = None;
        for (k, w) in self.list[..self.n].iter().enumerate() {
            if best.is_none_or(|b| w.length < self.list[b].length) {
                best = Some(k);
            }
        }
        let k = best?;
        let w = self.list[k];
        self.list.copy_within(k + 1..self.n, k);
        self.n -= 1;
        Some(w)
    }
}

/// L+ S+ L+ (8.1).
fn lsl(g: Rel) -> Option<(f64, f64, f64)> {
    let (u, t) = polar(g.left());
    let v = wrap(g.phi - t);
    (t >= -ZERO && v >= -ZERO).then_some((t, u, v))
}

/// L+ S+ R+ (8.2).
fn lsr(g: Rel) -> Option<(f64, f64, f64)> {
    let (r, t1) = polar(g.right());
    if r * r < 4.0 {
        return None;
    }
    let u = (r * r - 4.0).sqrt();
    let t = wrap(t1 + 2.0f64.atan2(u));
    let v = wrap(t - g.phi);
    (t >= -ZERO && v >= -ZERO).then_some((t, u, v))
}

/// L+ R- L (8.3, 8.4 read backwards).
fn lrl(g: Rel) -> Option<(f64, f64, f64)> {
    let (r, theta) = polar(g.left());
    if r > 4.0 {
        return None;
    }
    let u = -2.0 * (0.25 * r).asin();
    let t = wrap(theta + 0.5 * u + PI);
    let v = wrap(g.phi - t + u);
    (t >= -ZERO && u <= ZERO).then_some((t, u, v))
}

/// (t, v) of the CCCC words.
fn tau_omega(u: f64, v: f64, xi: f64, eta: f64, phi: f64) -> (f64, f64) {
    let delta = wrap(u - v);
    let a = u.sin() - delta.sin();
    let b = u.cos() - delta.cos() - 1.0;
    let t1 = (eta * a - xi * b).atan2(xi * a + eta * b);
    let t2 = 2.0 * (delta.cos() - v.cos() - u.cos()) + 3.0;
    let tau = if t2 < 0.0 { wrap(t1 + PI) } else { wrap(t1) };
    (tau, wrap(tau - u + v - phi))
}

/// L+ Ru+ Lu- R- (8.7): the middle turns of equal length, opposite directions.
fn lrlr_same(g: Rel) -> Option<(f64, f64, f64)> {
    let (xi, eta) = g.right();
    let rho = 0.25 * (2.0 + xi.hypot(eta));
    if rho > 1.0 {
        return None;
    }
    let u = rho.acos();
    let (t, v) = tau_omega(u, -u, xi, eta, g.phi);
    (t >= -ZERO && v <= ZERO).then_some((t, u, v))
}

/// L+ Ru- Lu- R+ (8.8): the middle turns of equal length, both backwards.
fn lrlr_opposite(g: Rel) -> Option<(f64, f64, f64)> {
    let (xi, eta) = g.right();
    let rho = (20.0 - xi * xi - eta * eta) / 16.0;
    if !(0.0..=1.0).contains(&rho) {
        return None;
    }
    let u = -rho.acos();
    if u < -FRAC_PI_2 {
        return None;
    }
    let (t, v) = tau_omega(u, u, xi, eta, g.phi);
    (t >= -ZERO && v >= -ZERO).then_some((t, u, v))
}

/// L+ R-(π/2) S- L- (8.9).
fn lrsl(g: Rel) -> Option<(f64, f64, f64)> {
    let (rho, theta) = polar(g.left());
    if rho < 2.0 {
        return None;
    }
    let r = (rho * rho - 4.0).sqrt();
    let u = 2.0 - r;
    let t = wrap(theta + r.atan2(-2.0));
    let v = wrap(g.phi - FRAC_PI_2 - t);
    (t >= -ZERO && u <= ZERO && v <= ZERO).then_some((t, u, v))
}

/// L+ R-(π/2) S- R- (8.10).
fn lrsr(g: Rel) -> Option<(f64, f64, f64)> {
    let (xi, eta) = g.right();
    let (rho, t) = polar((-eta, xi));
    if rho < 2.0 {
        return None;
    }
    let u = 2.0 - rho;
    let v = wrap(t + FRAC_PI_2 - g.phi);
    (t >= -ZERO && u <= ZERO && v <= ZERO).then_some((t, u, v))
}

/// L+ R-(π/2) S- L-(π/2) R+ (8.11).
fn lrslr(g: Rel) -> Option<(f64, f64, f64)> {
    let (xi, eta) = g.right();
    let rho = xi.hypot(eta);
    if rho < 2.0 {
        return None;
    }
    let u = 4.0 - (rho * rho - 4.0).sqrt();
    if u > ZERO {
        return None;
    }
    let t = wrap(((4.0 - u) * xi - 2.0 * eta).atan2(-2.0 * xi + (u - 4.0) * eta));
    let v = wrap(t - g.phi);
    (t >= -ZERO && v >= -ZERO).then_some((t, u, v))
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
    fn the_shortest_curve_is_as_long_as_the_reeds_shepp_crates_everywhere() {
        let r = 2.6;
        let mut compared = 0;
        for i in -6..=6 {
            for j in -6..=6 {
                for k in 0..16 {
                    let from = [0.3, -0.2, 0.4];
                    let to = [
                        1.1 * f64::from(i),
                        0.9 * f64::from(j),
                        f64::from(k) * 0.41 - 3.1,
                    ];
                    let ours = shortest(from, to, r);
                    // The crate's curves, shortest first.
                    let theirs = curves(from, to, r).next().map_or(f64::NAN, |c| c.length);
                    assert!(ours.is_finite(), "no curve to {to:?}");
                    assert!(
                        (ours - theirs).abs() < 1e-9,
                        "{to:?}: {ours} against {theirs}"
                    );
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, 13 * 13 * 16);
    }

    #[test]
    fn turning_round_on_the_spot_takes_cusps() {
        // The same place facing the other way: no curve without a change of direction.
        let c = &curves([0.0, 0.0, 0.0], [0.0, 0.0, PI], 2.4).collect::<Vec<_>>()[0];
        assert!(c.cusps() >= 1, "{c:?}");
        assert!(c.length > 2.4 && c.length < 4.0 * 2.4 * PI);
    }
}
