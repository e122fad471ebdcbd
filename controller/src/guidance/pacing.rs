//! Moving obstacles: the pace (t_f) as the planner's second free parameter and its
//! score ([`Pacing`]), and each moving obstacle swept along its velocity over the
//! uncertainty of its timing and the car's ([`sweep`]).

use super::frame::clip_to_start;
use crate::planner;

/// The second free parameter around moving obstacles: the pace (t_f), and how moving
/// obstacles are swept for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Pacing {
    /// dx/dt to try, m/s, fastest first.
    pub speeds: Vec<f64>,
    /// The car's speed now, m/s.
    pub speed_now: f64,
    /// Acceleration and deceleration the car changes pace with, m/s^2.
    pub accel: f64,
    pub decel: f64,
    /// Moving obstacles are swept over +- this long along their velocity, seconds.
    pub time_margin: f64,
    /// Weight of the time lost by a slower pace against the path's deviation, m^3/s.
    pub time_weight: f64,
    /// How many local horizons the time lost counts for: 1, or behind traffic going
    /// the car's way the route left over the horizon (following lasts until the
    /// leader is passed, so passing it is weighed against following it to the goal).
    pub time_scale: f64,
    /// An obstacle near the line comes towards the car: give way to the side kept to
    /// (a deviation to the other side costs [`WRONG_SIDE_WEIGHT`] times as much).
    pub oncoming: bool,
    /// The side kept to: the right (else the left).
    pub keep_right: bool,
    /// The planning circle (the car's radius with the safety margin), metres. Moving
    /// obstacles keep its clearance in every tier: the passage tier's narrower circle
    /// is checked with the car's rectangle against the static obstacles, and a cart or
    /// a walker met in a passage must come no nearer the rear axle than this circle
    /// allows (the nose is 2 m ahead of it).
    pub circle: f64,
}

/// The nearest traffic ahead going the car's way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leader {
    /// The pace to follow it at, m/s.
    pub pace: f64,
    /// It keeps to its line: its speed across the line is at most [`ALONG_LINE`] of its
    /// speed along it (it can be passed; one crossing the line is only followed).
    pub along_line: bool,
}

/// See [`Leader::along_line`].
const ALONG_LINE: f64 = 0.3;

/// A pass lane clears the traffic it passes by this beyond the car's circle, metres.
const PASS_CLEARANCE: f64 = 0.3;

/// The lane to pass the traffic ahead going the car's way on, on `side` (+1 left, -1
/// right) of the line (planning frame, the car at (px, py), `r0` its circle with
/// margin): its offset from the line, beyond every such obstacle near the line by the
/// car's circle and [`PASS_CLEARANCE`].
pub fn pass_lane(obstacles: &[planner::Obstacle], px: f64, py: f64, r0: f64, side: f64) -> f64 {
    let reach = obstacles
        .iter()
        .filter(|o| near_line(o, px, py, r0) && o.vx > TRAFFIC_MIN_SPEED)
        .map(|o| side * o.y + o.radius)
        .fold(0.0, f64::max);
    side * (reach + r0 + PASS_CLEARANCE)
}

/// Whether `o` is ahead of the car at (px, py) within the traffic band of the line.
fn near_line(o: &planner::Obstacle, px: f64, py: f64, r0: f64) -> bool {
    o.x + o.radius > px && (o.y - py).abs() < r0 + o.radius + TRAFFIC_BAND
}

/// How much more a deviation to the side not kept to costs while giving way.
pub const WRONG_SIDE_WEIGHT: f64 = 4.0;
/// Slower than this along the line, an obstacle is no traffic to follow or meet, m/s.
const TRAFFIC_MIN_SPEED: f64 = 0.2;
/// Traffic is what moves within the car's circle plus this of the line, metres.
const TRAFFIC_BAND: f64 = 1.0;

/// Headway kept behind traffic going the car's way: this time at its speed, plus
/// [`FOLLOW_GAP`], beyond the car's circle and the obstacle's, seconds.
const FOLLOW_TIME_GAP: f64 = 1.5;
const FOLLOW_GAP: f64 = 1.0;
/// How fast the following pace closes a headway error, 1/s.
const FOLLOW_GAIN: f64 = 0.3;

/// What the moving obstacles near the line do (planning frame, the car at (px, py),
/// `r0` its circle with margin): the nearest going the car's way (ahead of it, and
/// more along the line than across it), with the pace to
/// follow it at (its speed along the line, plus [`FOLLOW_GAIN`] times the headway
/// error, so the pace changes with the gap instead of flipping between fixed fractions
/// above and below the leader's speed), and whether one comes towards the car.
pub fn traffic(
    obstacles: &[planner::Obstacle],
    px: f64,
    py: f64,
    r0: f64,
) -> (Option<Leader>, bool) {
    let mut leader: Option<(f64, &planner::Obstacle)> = None;
    let mut oncoming = false;
    for o in obstacles {
        if !near_line(o, px, py, r0) {
            continue;
        }
        if o.vx > TRAFFIC_MIN_SPEED && o.vx >= o.vy.abs() && o.x > px {
            let gap = (o.x - px).hypot(o.y - py) - o.radius - r0;
            if leader.is_none_or(|l| gap < l.0) {
                leader = Some((gap, o));
            }
        } else if o.vx < -TRAFFIC_MIN_SPEED {
            oncoming = true;
        }
    }
    let leader = leader.map(|(gap, o)| {
        let headway = FOLLOW_TIME_GAP * o.vx + FOLLOW_GAP;
        Leader {
            pace: o.vx + FOLLOW_GAIN * (gap - headway),
            along_line: o.vy.abs() <= ALONG_LINE * o.vx,
        }
    });
    (leader, oncoming)
}

impl Pacing {
    /// The score of a feasible path at `pace` (lower is better): its mean squared
    /// deviation from the start-goal line (J / span, m^2) plus `time_weight` times the
    /// time per metre lost against the fastest pace, `time_scale` times. Yielding to
    /// crossing traffic by slowing down beats a wide swerve at full pace; a slow
    /// leader with a long way to go is passed.
    pub fn score(&self, mean_sq_deviation: f64, pace: f64, fastest: f64) -> f64 {
        mean_sq_deviation + self.time_weight * self.time_scale * (1.0 / pace - 1.0 / fastest)
    }

    /// The weight of a deviation `y` from the line (positive: left): 1, or
    /// [`WRONG_SIDE_WEIGHT`] on the side not kept to while traffic comes towards the car.
    pub fn side_weight(&self, y: f64) -> f64 {
        let wrong = if self.keep_right { y > 0.0 } else { y < 0.0 };
        if self.oncoming && wrong {
            WRONG_SIDE_WEIGHT
        } else {
            1.0
        }
    }

    /// How far off the planned schedule the car ends up while changing from its
    /// current speed to `pace` (the plan assumes the pace from t_k on), as time at
    /// that pace, seconds.
    pub fn schedule_slip(&self, pace: f64) -> f64 {
        let dv = pace - self.speed_now;
        let a = if dv > 0.0 { self.accel } else { self.decel };
        if pace <= 0.0 || a <= 0.0 {
            return 0.0;
        }
        dv * dv / (2.0 * a * pace)
    }
}

/// A moving obstacle swept over [-margin, +margin] seconds along its velocity: a chain
/// of circles (each moving with it) spaced at most half the inflated radius (r + r0)
/// apart, so the inflated chain covers the inflated capsule to within 3 % of r + r0.
/// Circles the car at (px, py) already overlaps are shrunk as for static obstacles.
pub fn sweep(
    o: &planner::Obstacle,
    margin: f64,
    px: f64,
    py: f64,
    r0: f64,
) -> Vec<planner::Obstacle> {
    let speed = o.vx.hypot(o.vy);
    let reach = speed * margin;
    let spacing = (0.5 * (o.radius + r0)).max(0.05);
    let n = ((2.0 * reach / spacing).ceil() as usize).clamp(0, 64);
    (0..=n)
        .map(|j| {
            let s = if n == 0 {
                0.0
            } else {
                -margin + 2.0 * margin * j as f64 / n as f64
            };
            let (x, y) = (o.x + o.vx * s, o.y + o.vy * s);
            planner::Obstacle {
                x,
                y,
                radius: clip_to_start(o.radius, x, y, px, py, r0),
                vx: o.vx,
                vy: o.vy,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    /// Paces of 2 and 1 m/s from 2 m/s, 1 m/s^2 either way, no oncoming traffic.
    fn pacing() -> Pacing {
        Pacing {
            speeds: vec![2.0, 1.0],
            speed_now: 2.0,
            accel: 1.0,
            decel: 1.0,
            time_margin: 1.0,
            time_weight: 2.0,
            time_scale: 1.0,
            oncoming: false,
            keep_right: true,
            circle: 2.3,
        }
    }

    fn walker(x: f64, y: f64, vx: f64) -> planner::Obstacle {
        planner::Obstacle {
            x,
            y,
            radius: 0.3,
            vx,
            vy: 0.0,
        }
    }

    #[test]
    fn traffic_ahead_is_followed_on_the_gap_and_oncoming_traffic_is_flagged() {
        let r0 = 2.3;
        // A walker 10 m ahead at 0.7 m/s: the headway wanted is 1.5 * 0.7 + 1 m.
        let (follow, oncoming) = traffic(&[walker(10.0, 0.3, 0.7)], 0.0, 0.0, r0);
        let gap = 10.0f64.hypot(0.3) - 0.3 - r0;
        let want = 0.7 + 0.3 * (gap - (1.5 * 0.7 + 1.0));
        let leader = follow.expect("a leader");
        assert!((leader.pace - want).abs() < 1e-12 && leader.along_line && !oncoming);
        // Closer, slower: the pace drops below the walker's speed to open the gap.
        let (near, _) = traffic(&[walker(4.0, 0.0, 0.7)], 0.0, 0.0, r0);
        assert!(near.expect("a leader").pace < 0.7);
        // The nearest leader sets the pace.
        let (both, _) = traffic(
            &[walker(10.0, 0.0, 0.7), walker(4.0, 0.0, 0.7)],
            0.0,
            0.0,
            r0,
        );
        assert_eq!(both, near);
        // Crossing the line on the way: followed, not passed.
        let crossing = planner::Obstacle {
            vy: 0.5,
            ..walker(10.0, 0.0, 0.7)
        };
        let (leader, _) = traffic(&[crossing], 0.0, 0.0, r0);
        assert!(!leader.expect("a leader").along_line);
        // Coming towards the car, or far off the line, or behind: no leader.
        assert_eq!(
            traffic(&[walker(15.0, 1.0, -1.5)], 0.0, 0.0, r0),
            (None, true)
        );
        assert_eq!(
            traffic(&[walker(15.0, 6.0, -1.5)], 0.0, 0.0, r0),
            (None, false)
        );
        assert_eq!(
            traffic(&[walker(-5.0, 0.0, 0.7)], 0.0, 0.0, r0),
            (None, false)
        );
        // Crossing more than going along (steeper than 45 degrees), or level with the
        // car beside it (its centre not ahead): no leader to pace behind.
        let steep = planner::Obstacle {
            vy: 0.8,
            ..walker(10.0, 0.0, 0.34)
        };
        assert_eq!(traffic(&[steep], 0.0, 0.0, r0), (None, false));
        assert_eq!(
            traffic(&[walker(-0.1, -3.5, 0.7)], 0.0, 0.0, r0),
            (None, false)
        );
        // Standing still is no traffic.
        assert_eq!(
            traffic(&[walker(8.0, 0.0, 0.1)], 0.0, 0.0, r0),
            (None, false)
        );
    }

    #[test]
    fn the_pass_lane_clears_every_leader_near_the_line_on_its_side() {
        let r0 = 2.3;
        let side_by_side = [walker(6.0, 0.3, 0.7), walker(8.0, -0.5, 0.7)];
        let left = pass_lane(&side_by_side, 0.0, 0.0, r0, 1.0);
        assert!(
            (left - (0.3 + 0.3 + r0 + PASS_CLEARANCE)).abs() < 1e-12,
            "{left}"
        );
        let right = pass_lane(&side_by_side, 0.0, 0.0, r0, -1.0);
        assert!(
            (right + (0.5 + 0.3 + r0 + PASS_CLEARANCE)).abs() < 1e-12,
            "{right}"
        );
        // Behind the car, oncoming, or far off the line: not passed.
        let others = [
            walker(-5.0, 1.0, 0.7),
            walker(10.0, 1.0, -1.0),
            walker(10.0, 8.0, 0.7),
        ];
        let lane = pass_lane(&others, 0.0, 0.0, r0, 1.0);
        assert!((lane - (r0 + PASS_CLEARANCE)).abs() < 1e-12, "{lane}");
    }

    #[test]
    fn only_while_traffic_comes_towards_the_car_is_the_other_side_dearer() {
        let mut p = pacing();
        assert_eq!(p.side_weight(1.0), 1.0);
        p.oncoming = true;
        assert_eq!(p.side_weight(1.0), WRONG_SIDE_WEIGHT);
        assert_eq!(p.side_weight(-1.0), 1.0);
        p.keep_right = false;
        assert_eq!(p.side_weight(-1.0), WRONG_SIDE_WEIGHT);
        assert_eq!(p.side_weight(1.0), 1.0);
    }

    use super::*;

    #[test]
    fn a_moving_obstacle_is_swept_along_its_velocity_over_the_margin() {
        let o = planner::Obstacle {
            x: 10.0,
            y: -3.0,
            radius: 0.5,
            vx: 0.0,
            vy: 1.3,
        };
        let chain = sweep(&o, 1.0, 0.0, 0.0, 2.3);
        let first = chain.first().expect("circles");
        let last = chain.last().expect("circles");
        assert!((first.y - (-4.3)).abs() < 1e-12 && (last.y - (-1.7)).abs() < 1e-12);
        assert!(
            chain
                .iter()
                .all(|c| c.vy == 1.3 && c.x == 10.0 && c.radius == 0.5)
        );
        let spacing = chain
            .windows(2)
            .map(|w| w[1].y - w[0].y)
            .fold(0.0, f64::max);
        assert!(spacing <= 0.5 * (0.5 + 2.3) + 1e-12, "{spacing}");
        // A circle the car already overlaps is shrunk to just clear of it.
        let near = sweep(&o, 1.0, 10.0, -6.0, 2.3);
        assert!(near.iter().any(|c| c.radius < 0.5));
        assert!(
            near.iter()
                .all(|c| (c.x - 10.0).hypot(c.y + 6.0) >= c.radius + 2.3 - 1e-9 || c.radius == 0.0)
        );
        // A static obstacle is one circle.
        assert_eq!(
            sweep(&planner::Obstacle { vy: 0.0, ..o }, 1.0, 0.0, 0.0, 2.3).len(),
            1
        );
    }

    #[test]
    fn schedule_slip_and_pace_score() {
        let pacing = pacing();
        assert_eq!(pacing.schedule_slip(2.0), 0.0);
        // Slowing from 2 to 1 m/s at 1 m/s^2 takes 1 s and 1.5 m instead of 1 m.
        assert!((pacing.schedule_slip(1.0) - 0.5).abs() < 1e-12);
        // A straight path at half pace beats a 1.5 m swerve at full pace, not a 0.5 m one.
        assert!(pacing.score(0.0, 1.0, 2.0) < pacing.score(1.5, 2.0, 2.0));
        assert!(pacing.score(0.0, 1.0, 2.0) > pacing.score(0.5, 2.0, 2.0));
    }
}
