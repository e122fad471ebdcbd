//! Following a manoeuvre segment by segment: forward segments with the steering law as
//! the polynomial's path is followed, backward ones with the same law driving a virtual
//! car that faces backwards (its heading the car's plus pi, its road-wheel angle the
//! car's negated: the kinematics at the rear axle are the same), every segment driven to
//! a stop at its end (a cusp), the next begun once the car stands.

use super::hybrid::SAMPLE;
use super::path::{Manoeuvre, PathPoint};
use crate::guidance::STANDING;
use crate::guidance::follower::{FollowInputs, SteeringLaw};
use crate::localisation::Pose;

/// A segment counts as driven this near its end (along the direction of travel),
/// metres.
const END_SLACK: f64 = 0.15;
/// The nearest point is looked for this many samples ahead of the last one.
const LOOK_AHEAD: usize = 40;
/// With the road wheels this far off the command (radians, where they will be when the
/// command acts) the car goes at its full pace; this far, it stands while they turn (a
/// driver in a tight place turns the wheels before moving off): at the start of a
/// segment the wheels may stand at the other lock, and driving on while they turn
/// carries the car off the manoeuvre towards what it was planned round.
const STEER_GAP_FULL: f64 = 4.0 * std::f64::consts::PI / 180.0;
const STEER_GAP_STAND: f64 = 12.0 * std::f64::consts::PI / 180.0;

/// What following asks of the actuators.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Command {
    /// Forward (else in gear R).
    pub forward: bool,
    /// Road-wheel angle, radians.
    pub steer: f64,
    /// Speed, a magnitude, m/s (0: brake to a stand).
    pub speed: f64,
    /// Left of the segment to its end, metres.
    pub room: f64,
    /// The deceleration the brake is asked to add to the speed loop's, m/s^2: what
    /// stops the car at the segment's end (see [`brake_to_stop`]).
    pub brake: f64,
    /// The law's inputs (the virtual car's on a backward segment).
    pub inputs: FollowInputs,
}

/// A partial manoeuvre is searched again (a complete one found then takes over) each
/// time this much more of it has been driven, metres: the laser has seen more.
const LOOK_AGAIN_M: f64 = 2.0;

/// A feasible polynomial path takes over from a forward segment after which at most this
/// much of the manoeuvre is left, metres: the search reaches its goal pose exactly, and
/// a turn into the way on may end in a short nudge back that the polynomial, driving on,
/// does not need.
const HAND_BACK_TAIL_M: f64 = 1.0;

/// A manoeuvre being followed.
#[derive(Clone, Debug, PartialEq)]
pub struct Following {
    pub manoeuvre: Manoeuvre,
    /// It reaches the search's goal (else it goes as far as was known).
    complete: bool,
    segments: Vec<std::ops::Range<usize>>,
    /// The segment being driven.
    segment: usize,
    /// The sample nearest the car, within that segment.
    at: usize,
    /// The sample nearest the car when it was last searched for (from).
    looked_at: usize,
    /// An escape: the narrower margin it was planned with (driven at a crawl).
    escape_margin: Option<f64>,
}

/// How following is tuned: speeds (magnitudes), the deceleration to stop at a segment's
/// end, the speed loop's dead time and time constant (seconds: the calibrated step
/// response), the full brake's deceleration, the wheelbase and the steering lock
/// (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pace {
    pub forward_speed: f64,
    pub reverse_speed: f64,
    pub decel: f64,
    pub dead_time: f64,
    pub time_constant: f64,
    pub brake_decel: f64,
    pub wheelbase: f64,
    pub max_steer: f64,
}

impl Following {
    /// Following `manoeuvre`, `complete` (to the search's goal) or partial.
    pub fn new(manoeuvre: Manoeuvre, complete: bool) -> Following {
        let segments = manoeuvre.segments();
        Following {
            manoeuvre,
            complete,
            segments,
            segment: 0,
            at: 0,
            looked_at: 0,
            escape_margin: None,
        }
    }

    /// This manoeuvre as an escape planned with `margin` (None: not an escape).
    pub fn escaping(self, margin: Option<f64>) -> Following {
        Following {
            escape_margin: margin,
            ..self
        }
    }

    /// An escape's margin, metres (None: not an escape).
    pub fn escape_margin(&self) -> Option<f64> {
        self.escape_margin
    }

    /// A partial manoeuvre driven [`LOOK_AGAIN_M`] further since it was searched for
    /// (or last searched again): worth a new search, which may now reach the goal.
    pub fn look_again(&self) -> bool {
        !self.complete && self.at.saturating_sub(self.looked_at) as f64 * SAMPLE >= LOOK_AGAIN_M
    }

    /// A new search from where the car is found no complete manoeuvre: this one goes on.
    pub fn looked(&mut self) {
        self.looked_at = self.at;
    }

    /// The rest of the manoeuvre, from the sample nearest the car.
    pub fn rest(&self) -> Manoeuvre {
        Manoeuvre {
            points: self.manoeuvre.points[self.at.min(self.manoeuvre.points.len())..].to_vec(),
        }
    }

    /// On a forward segment after which at most [`HAND_BACK_TAIL_M`] is left (the last
    /// segment, or a last short nudge to the search's goal pose): the polynomial may
    /// take over.
    pub fn may_hand_back(&self) -> bool {
        let Some(range) = self.segments.get(self.segment) else {
            return false;
        };
        let tail = self.manoeuvre.points.len().saturating_sub(range.end);
        self.manoeuvre.points[range.start].forward && tail as f64 * SAMPLE <= HAND_BACK_TAIL_M
    }

    /// Every segment driven.
    pub fn finished(&self) -> bool {
        self.segment >= self.segments.len()
    }

    /// The command from `pose` (where the car is: progress and the end of a segment) and
    /// `ahead` (where it will be when the command acts: steering); None once finished.
    pub fn command(
        &mut self,
        pose: &Pose,
        ahead: &Pose,
        law: &SteeringLaw,
        pace: &Pace,
    ) -> Option<Command> {
        loop {
            let range = self.segments.get(self.segment)?.clone();
            let points = &self.manoeuvre.points[range.clone()];
            let forward = points[0].forward;
            self.at = nearest(points, range.start, self.at.max(range.start), pose);
            let left = left_of(points, self.at - range.start, pose, forward);
            if left > END_SLACK {
                let j = nearest(points, range.start, self.at, ahead) - range.start;
                return Some(along_segment(&points[j], left, pose, ahead, law, pace));
            }
            // At the segment's end: stand, then the next.
            if pose.v.abs() >= STANDING {
                let inputs = inputs(&points[points.len() - 1], ahead, forward, pace.wheelbase);
                return Some(Command {
                    forward,
                    steer: if forward { 1.0 } else { -1.0 } * inputs.phi_ref,
                    speed: 0.0,
                    room: 0.0,
                    brake: pace.decel,
                    inputs,
                });
            }
            self.segment += 1;
            self.at = range.end;
        }
    }
}

/// The command on a segment with `left` metres of it to go, steering towards sample
/// `p` (the one nearest where the car will be, `ahead`).
fn along_segment(
    p: &PathPoint,
    left: f64,
    pose: &Pose,
    ahead: &Pose,
    law: &SteeringLaw,
    pace: &Pace,
) -> Command {
    let forward = p.forward;
    let inputs = inputs(p, ahead, forward, pace.wheelbase);
    let steer = if forward {
        law.steer(&inputs)
    } else {
        -law.steer(&inputs)
    };
    let cruise = if forward {
        pace.forward_speed
    } else {
        pace.reverse_speed
    };
    // Still rolling the other way (a manoeuvre found while moving): stop it on the
    // full brake, the nearer to where the search began.
    let along = if forward { pose.v } else { -pose.v };
    if along <= -STANDING {
        return Command {
            forward,
            steer,
            speed: 0.0,
            room: left,
            brake: pace.brake_decel,
            inputs,
        };
    }
    // Where the car is when a command given now acts.
    let reach = (left - along.max(0.0) * pace.dead_time).max(0.0);
    let stop = (2.0 * pace.decel * reach).sqrt();
    let target = steer.clamp(-pace.max_steer, pace.max_steer);
    // Standing, the wheels as they stand too: the prediction knows the steering's
    // lag, not its rate limit.
    let gap = if pose.v.abs() < STANDING {
        (target - ahead.phi).abs().max((target - pose.phi).abs())
    } else {
        target - ahead.phi
    };
    let speed = cruise.min(stop) * steer_ready(gap);
    Command {
        forward,
        steer,
        speed,
        room: left,
        brake: brake_to_stop(along.max(0.0), speed, reach, pace),
        inputs,
    }
}

/// The brake helps stop at a segment's end once stopping there needs this share of the
/// planned deceleration (before, the speed loop alone slows the car).
const BRAKE_FROM: f64 = 0.5;

/// The deceleration the brake must add (m/s^2) for a car at speed `v` commanded to
/// `speed` to stop within `reach` metres: what stopping there needs beyond what the
/// speed loop gives on its own ((v - speed) / its time constant). A slow speed loop
/// (a heavy load, a soft throttle map) so stops at a cusp in about the time the
/// planned deceleration takes, instead of rolling on for seconds at a crawl.
fn brake_to_stop(v: f64, speed: f64, reach: f64, pace: &Pace) -> f64 {
    let needed = v * v / (2.0 * reach.max(0.01));
    if needed < BRAKE_FROM * pace.decel {
        return 0.0;
    }
    let from_loop = (v - speed).max(0.0) / pace.time_constant.max(0.01);
    (needed - from_loop).max(0.0)
}

/// The share of the pace allowed with the road wheels `gap` radians off the command:
/// all of it within [`STEER_GAP_FULL`], none beyond [`STEER_GAP_STAND`].
fn steer_ready(gap: f64) -> f64 {
    ((STEER_GAP_STAND - gap.abs()) / (STEER_GAP_STAND - STEER_GAP_FULL)).clamp(0.0, 1.0)
}

/// The index of the sample of `points` (the first at `offset` in the manoeuvre) nearest
/// `pose`, from `from` on, at most [`LOOK_AHEAD`] samples on.
fn nearest(points: &[PathPoint], offset: usize, from: usize, pose: &Pose) -> usize {
    let first = from - offset;
    let last = (first + LOOK_AHEAD).min(points.len() - 1);
    let d = |p: &PathPoint| (p.x - pose.x).hypot(p.y - pose.y);
    (first..=last)
        .min_by(|&a, &b| d(&points[a]).total_cmp(&d(&points[b])))
        .map_or(from, |j| j + offset)
}

/// What is left of the segment `points` from its sample `j`, the car at `pose`: the
/// samples' length, plus how far the car stands short of sample `j` along the direction
/// of travel (negative once past); 0 once past the end.
fn left_of(points: &[PathPoint], j: usize, pose: &Pose, forward: bool) -> f64 {
    let p = &points[j];
    let sign = if forward { 1.0 } else { -1.0 };
    let along = sign * ((p.x - pose.x) * p.theta.cos() + (p.y - pose.y) * p.theta.sin());
    let samples = (points.len() - 1 - j) as f64 * SAMPLE;
    (samples + along).max(0.0)
}

/// The steering law's inputs at sample `p` from `pose`; backwards, the virtual car's
/// (facing backwards, its road-wheel angle negated).
fn inputs(p: &PathPoint, pose: &Pose, forward: bool, wheelbase: f64) -> FollowInputs {
    let left = -(pose.x - p.x) * p.theta.sin() + (pose.y - p.y) * p.theta.cos();
    let phi = (wheelbase * p.curvature).atan();
    let sign = if forward { 1.0 } else { -1.0 };
    FollowInputs {
        e_y: sign * left,
        e_theta: super::super::frame::wrap(pose.theta - p.theta),
        phi_ref: sign * phi,
        v: pose.v.abs(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guidance::manoeuvre::path::arc;

    const LAW: SteeringLaw = SteeringLaw::Optimal {
        omega: 0.9,
        zeta: 0.9,
        wheelbase: 1.65,
    };
    const PACE: Pace = Pace {
        forward_speed: 1.0,
        reverse_speed: 0.5,
        decel: 1.0,
        dead_time: 0.0,
        time_constant: 0.3,
        brake_decel: 4.0,
        wheelbase: 1.65,
        max_steer: 0.61,
    };

    /// Drive the car (kinematic bicycle, commands acting at once) along `m` until it
    /// finishes or `limit` steps pass; the poses driven.
    fn drive(m: Manoeuvre, limit: usize) -> (Following, Vec<Pose>) {
        drive_steering(m, limit, 0.0, f64::INFINITY)
    }

    /// As [`drive`], the road wheels starting at `phi` and turning at most `rate`
    /// radians per second.
    fn drive_steering(m: Manoeuvre, limit: usize, phi: f64, rate: f64) -> (Following, Vec<Pose>) {
        let start = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.0,
            phi,
        };
        drive_with(m, limit, start, rate, &PACE, true)
    }

    /// As [`drive`] from `start` with `pace` (its time constant the speed loop's too),
    /// the brake applied as asked if `brakes`.
    fn drive_with(
        m: Manoeuvre,
        limit: usize,
        start: Pose,
        rate: f64,
        pace: &Pace,
        brakes: bool,
    ) -> (Following, Vec<Pose>) {
        let mut f = Following::new(m, true);
        let mut pose = start;
        let mut poses = Vec::new();
        let dt = 0.01;
        for _ in 0..limit {
            let Some(c) = f.command(&pose, &pose, &LAW, pace) else {
                break;
            };
            let target = if c.forward { c.speed } else { -c.speed };
            // First-order speed, instant steering within the lock.
            pose.v += (target - pose.v) * (dt / pace.time_constant);
            if brakes {
                pose.v -= (c.brake * dt).min(pose.v.abs()) * pose.v.signum();
            }
            if c.speed == 0.0 && pose.v.abs() < 0.02 {
                pose.v = 0.0;
            }
            let turn = c.steer.clamp(-0.61, 0.61) - pose.phi;
            pose.phi += turn.clamp(-rate * dt, rate * dt);
            let p = arc(
                [pose.x, pose.y, pose.theta],
                pose.v * dt,
                pose.phi.tan() / 1.65,
            );
            (pose.x, pose.y, pose.theta) = (p[0], p[1], p[2]);
            poses.push(pose);
        }
        (f, poses)
    }

    fn sampled(start: [f64; 3], arcs: &[(f64, f64)]) -> Manoeuvre {
        let mut at = start;
        let mut points = Vec::new();
        for &(d, curvature) in arcs {
            let n = (d.abs() / SAMPLE).round() as usize;
            for _ in 0..n {
                at = arc(at, d / n as f64, curvature);
                points.push(PathPoint {
                    x: at[0],
                    y: at[1],
                    theta: at[2],
                    curvature,
                    forward: d > 0.0,
                });
            }
        }
        Manoeuvre { points }
    }

    #[test]
    fn a_three_point_turn_is_driven_to_its_end_stopping_at_each_cusp() {
        // Forward left, back right, forward left: the car turns round.
        let m = sampled([0.0; 3], &[(3.0, 0.4), (-2.5, -0.4), (3.0, 0.4)]);
        let end = m.points[m.points.len() - 1];
        let (f, poses) = drive(m, 20_000);
        assert!(f.finished(), "not finished");
        let last = poses[poses.len() - 1];
        assert!(
            (last.x - end.x).hypot(last.y - end.y) < 0.3,
            "{last:?} vs {end:?}"
        );
        // It went backwards, and stood between the segments.
        assert!(poses.iter().any(|p| p.v < -0.3));
        let cusps: Vec<f64> = poses
            .windows(2)
            .filter(|w| w[0].v * w[1].v < 0.0)
            .map(|w| w[0].v.abs())
            .collect();
        assert_eq!(cusps.len(), 2, "{cusps:?}");
        assert!(cusps.iter().all(|v| *v < 0.06), "{cusps:?}");
    }

    #[test]
    fn a_slow_speed_loop_is_helped_to_a_stand_at_each_cusp_by_the_brake() {
        // A speed loop of 1.5 s (a heavy load) alone creeps into each cusp for seconds.
        let m = sampled([0.0; 3], &[(3.0, 0.4), (-2.5, -0.4), (3.0, 0.4)]);
        let end = m.points[m.points.len() - 1];
        let slow = Pace {
            time_constant: 1.5,
            dead_time: 0.0,
            ..PACE
        };
        let start = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.0,
            phi: 0.0,
        };
        let (f, braked) = drive_with(m.clone(), 20_000, start, f64::INFINITY, &slow, true);
        let (g, coasted) = drive_with(m, 20_000, start, f64::INFINITY, &slow, false);
        assert!(f.finished() && g.finished(), "not finished");
        let last = braked[braked.len() - 1];
        assert!(
            (last.x - end.x).hypot(last.y - end.y) < 0.3,
            "{last:?} vs {end:?}"
        );
        // Two cusps and the end, each reached a second or more sooner.
        assert!(
            braked.len() + 300 < coasted.len(),
            "{} steps braked, {} coasting",
            braked.len(),
            coasted.len()
        );
    }

    #[test]
    fn a_car_still_rolling_against_the_first_segment_is_stopped_on_the_full_brake() {
        // Found while the car rolls forward at 0.8 m/s: the manoeuvre begins backwards.
        let m = sampled([0.0; 3], &[(-2.0, 0.0), (3.0, 0.4)]);
        let rolling = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.8,
            phi: 0.0,
        };
        let mut f = Following::new(m.clone(), true);
        let c = f
            .command(&rolling, &rolling, &LAW, &PACE)
            .expect("a command");
        assert!(!c.forward && c.speed == 0.0, "{c:?}");
        assert_eq!(c.brake, PACE.brake_decel);
        let (f, poses) = drive_with(m, 20_000, rolling, f64::INFINITY, &PACE, true);
        assert!(f.finished(), "not finished");
        // 0.8 m/s on the full 4 m/s^2 and the loop: stopped within 0.08 m.
        let furthest = poses
            .iter()
            .take_while(|p| p.v >= 0.0)
            .map(|p| p.x)
            .fold(f64::MIN, f64::max);
        assert!(furthest < 0.08, "rolled on to {furthest:.3} m");
    }

    #[test]
    fn a_backward_arc_is_tracked_from_an_offset_start() {
        // Straight back with the car 0.3 m off to the left: the error shrinks.
        let mut m = sampled([0.0, -0.3, 0.0], &[(-6.0, 0.0)]);
        m.points.iter_mut().for_each(|p| p.y = -0.3);
        let (_, poses) = drive(m, 20_000);
        let last = poses[poses.len() - 1];
        assert!(last.x < -5.0, "{last:?}");
        assert!((last.y + 0.3).abs() < 0.1, "{last:?}");
    }

    #[test]
    fn the_wheels_are_turned_before_the_car_moves_off_along_a_tight_arc() {
        // A left arc near the planned lock, the wheels at the right lock when it begins
        // and turning at 60 deg/s: driving off at once would carry the car 0.3 m outside
        // the arc before they are round (as a car ran 0.05 m from a wall's corner).
        let m = sampled([0.0, 0.0, 0.0], &[(3.0, 0.32)]);
        let (f, poses) = drive_steering(m.clone(), 2000, -0.55, 60f64.to_radians());
        assert!(f.finished());
        let off = poses
            .iter()
            .map(|p| {
                std::iter::once((0.0, 0.0))
                    .chain(m.points.iter().map(|q| (q.x, q.y)))
                    .map(|(x, y)| (x - p.x).hypot(y - p.y))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max);
        assert!(off < 0.08, "{off}");
        // It stood while the wheels turned.
        let moved_at = poses.iter().position(|p| p.v.abs() > 0.01).expect("moves");
        assert!(
            poses[moved_at].phi > 0.3 - 12f64.to_radians(),
            "{:?}",
            poses[moved_at]
        );
    }

    #[test]
    fn a_partial_manoeuvre_is_looked_at_again_every_two_metres_driven() {
        let m = sampled([0.0; 3], &[(8.0, 0.0)]);
        let mut partial = Following::new(m.clone(), false);
        let complete = Following::new(m, true);
        assert!(!partial.look_again());
        let at = |x: f64| Pose {
            x,
            y: 0.0,
            theta: 0.0,
            v: 1.0,
            phi: 0.0,
        };
        for x in [0.5, 1.0, 1.5] {
            partial.command(&at(x), &at(x), &LAW, &PACE);
        }
        assert!(!partial.look_again(), "{}", partial.at);
        partial.command(&at(2.1), &at(2.1), &LAW, &PACE);
        assert!(partial.look_again());
        // Looked at again: two metres more before the next.
        partial.looked();
        assert!(!partial.look_again());
        for x in [2.5, 3.0, 3.5, 4.0, 4.2] {
            partial.command(&at(x), &at(x), &LAW, &PACE);
        }
        assert!(partial.look_again());
        // A complete manoeuvre is driven to its end as it is.
        assert!(!complete.look_again());
    }

    #[test]
    fn the_polynomial_may_take_over_on_a_forward_segment_with_at_most_a_short_nudge_after_it() {
        let at = |x: f64| Pose {
            x,
            y: 0.0,
            theta: 0.0,
            v: 1.0,
            phi: 0.0,
        };
        // Forward 6 m, then back 0.5 m: on the forward segment already.
        let mut nudge = Following::new(sampled([0.0; 3], &[(6.0, 0.0), (-0.5, 0.0)]), true);
        assert!(nudge.may_hand_back());
        // Forward, then back 3 m: not before the last segment, and that one backward.
        let mut back = Following::new(sampled([0.0; 3], &[(3.0, 0.0), (-3.0, 0.0)]), true);
        assert!(!back.may_hand_back());
        let end = Pose { v: 0.0, ..at(3.0) };
        back.command(&end, &end, &LAW, &PACE);
        assert!(!back.finished() && !back.may_hand_back());
        // Back, then forward: on the forward one.
        let mut turn = Following::new(sampled([0.0; 3], &[(-1.0, 0.0), (4.0, 0.0)]), true);
        assert!(!turn.may_hand_back());
        let stand = Pose {
            v: 0.0,
            ..at(-0.95)
        };
        turn.command(&stand, &stand, &LAW, &PACE);
        assert!(turn.may_hand_back());
        // Every segment driven: nothing to hand back.
        for x in [3.0, 6.0, 5.5] {
            let p = Pose { v: 0.0, ..at(x) };
            nudge.command(&p, &p, &LAW, &PACE);
        }
        assert!(nudge.finished() && !nudge.may_hand_back());
    }
}
