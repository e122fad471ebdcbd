//! A standing car's replanning reused (issue 37): a car held in a controlled stop
//! replans every period for the rest of the run, and with nothing changed finds no path
//! again, at the cost of every local goal, detour and passage planned in full (some
//! 3.4 ms a replanning in the cul-de-sac). [`Reuse::solve`] solves a replanning as
//! [`solve`] does, but takes the last one's outcome again when it found no path for a
//! car standing among static obstacles, and this one asks the same of the same world:
//! the car standing where it stood, the obstacles where they were, nothing but the
//! polynomial asked for (no manoeuvre search or check, no turn, no kept path).
//!
//! "The same" is within a tolerance: the localiser's pose of a standing car wanders by
//! millimetres with the GPS noise, and perception lays a wall's chain of circles afresh
//! from scan to scan (its spacing and ends move by up to some 0.35 m along the wall).
//! Only an outcome with no path is reused, so what it costs is never safety (the car
//! keeps standing) but at most [`MAX_AGE_S`] of a way opened by less than the
//! tolerance; a change beyond it, traffic, a search due or the car moving solves
//! anew. It is a pure function of the requests, so SIL stays deterministic, and
//! lives wherever replannings are solved (inline, or on the planning thread).

use super::STANDING;
use super::solver::{PlanOutcome, PlanRequest, solve};
use crate::localisation::Pose;
use crate::planner::Obstacle;

/// How far the car may stand from where the reused replanning saw it, metres.
const POSE_TOL_M: f64 = 0.05;
/// How far its heading and road-wheel angle may differ, radians.
const ANGLE_TOL: f64 = 0.01;
/// How far an obstacle's disc may reach beyond the other world's nearest disc
/// (distance between centres plus the difference in radius), metres: a wall's
/// circles laid afresh half their spacing along it, and a little more.
const OBSTACLE_TOL_M: f64 = 0.5;
/// A reused outcome is solved again at least this often, seconds.
pub const MAX_AGE_S: f64 = 5.0;

/// The world as a replanning of a standing car saw it.
#[derive(Clone, Debug, PartialEq)]
pub struct Standing {
    /// x, y, heading and road-wheel angle (world frame).
    pose: [f64; 4],
    /// Every obstacle reported, none moving.
    obstacles: Vec<Obstacle>,
}

impl Standing {
    /// The car at `pose` among `obstacles`; None while it moves or an obstacle does.
    pub fn new(pose: &Pose, obstacles: &[Obstacle]) -> Option<Standing> {
        let still = pose.v.abs() < STANDING && obstacles.iter().all(|o| o.vx == 0.0 && o.vy == 0.0);
        still.then(|| Standing {
            pose: [pose.x, pose.y, pose.theta, pose.phi],
            obstacles: obstacles.to_vec(),
        })
    }

    /// Whether `other` is the same world within the tolerances.
    fn same(&self, other: &Standing) -> bool {
        let [x, y, theta, phi] = self.pose;
        let [ox, oy, otheta, ophi] = other.pose;
        (x - ox).hypot(y - oy) <= POSE_TOL_M
            && super::wrap(theta - otheta).abs() <= ANGLE_TOL
            && (phi - ophi).abs() <= ANGLE_TOL
            && covered(&self.obstacles, &other.obstacles)
            && covered(&other.obstacles, &self.obstacles)
    }
}

/// Whether each disc of `a` lies within [`OBSTACLE_TOL_M`] of one of `b`'s.
fn covered(a: &[Obstacle], b: &[Obstacle]) -> bool {
    a.iter().all(|o| {
        b.iter().any(|q| {
            let reach = OBSTACLE_TOL_M + q.radius - o.radius;
            reach >= 0.0 && (o.x - q.x).powi(2) + (o.y - q.y).powi(2) <= reach * reach
        })
    })
}

/// A replanning that may be reused: its world and its outcome, solved at `time`.
#[derive(Clone, Debug)]
struct Solved {
    standing: Standing,
    goal_blocked: bool,
    outcome: PlanOutcome,
}

/// Solves replannings, reusing a standing car's last one while its world stays the
/// same (the module's text).
#[derive(Clone, Debug, Default)]
pub struct Reuse {
    last: Option<Solved>,
    /// Replannings answered with the last one's outcome.
    pub reused: u64,
}

impl Reuse {
    /// `req`'s outcome: the last one's again, at `req`'s time, where the module's text
    /// allows, else [`solve`]'s.
    pub fn solve(&mut self, req: &PlanRequest) -> PlanOutcome {
        if let Some(outcome) = self.reusable(req) {
            self.reused += 1;
            return outcome;
        }
        let outcome = solve(req);
        self.last = keep(req, &outcome).map(|standing| Solved {
            standing,
            goal_blocked: req.goal_blocked,
            outcome: outcome.clone(),
        });
        outcome
    }

    /// The last outcome at `req`'s time, if `req` asks the same of the same world
    /// within [`MAX_AGE_S`] of it.
    fn reusable(&self, req: &PlanRequest) -> Option<PlanOutcome> {
        let last = self.last.as_ref()?;
        let standing = polynomial_only(req)?;
        let fresh = req.time - last.outcome.time < MAX_AGE_S;
        let same = req.goal_blocked == last.goal_blocked && last.standing.same(standing);
        if !(fresh && same) {
            return None;
        }
        let mut outcome = last.outcome.clone();
        outcome.time = req.time;
        if let Ok((_, record)) = &mut outcome.result {
            record.time = req.time;
        }
        Some(outcome)
    }
}

/// `req`'s world, if it is a standing car's that asks for nothing but the polynomial:
/// no manoeuvre searched or followed, no turn first, no path that may be kept, no
/// traffic to pace, pass or yield to.
fn polynomial_only(req: &PlanRequest) -> Option<&Standing> {
    let only = req.manoeuvre.is_none()
        && req.align.is_none()
        && !req.current_holds
        && !req.hand_back
        && req.pacing.is_none()
        && req.pass.is_none()
        && req.yields.is_empty();
    req.standing.as_ref().filter(|_| only)
}

/// The world to keep with `outcome` of `req`: where it found no path at all (none kept,
/// no manoeuvre) for a request [`polynomial_only`] allows.
fn keep(req: &PlanRequest, outcome: &PlanOutcome) -> Option<Standing> {
    let no_path = matches!(&outcome.result, Ok((None, r))
        if !r.feasible && !r.kept && r.manoeuvre.is_none() && r.align.is_none());
    polynomial_only(req).filter(|_| no_path).cloned()
}

#[cfg(test)]
mod tests {
    use super::super::tests::{car_at, east_to, post};
    use super::*;

    fn standing(x: f64, obstacles: &[Obstacle]) -> Standing {
        Standing::new(&car_at(x, 0.0, 0.0, 0.0), obstacles).expect("standing")
    }

    /// A navigator east to (40, 0), and a wall of posts across the route at x = 6.
    fn blocked() -> (super::super::Navigator, Vec<Obstacle>) {
        let wall = (-50..=50)
            .map(|k| post(6.0, f64::from(k) * 0.4, 0.3))
            .collect();
        let nav = super::super::Navigator::new(&east_to(40.0)).expect("navigator");
        (nav, wall)
    }

    fn car(x: f64, v: f64) -> Pose {
        car_at(x, 0.0, 0.0, v)
    }

    fn no_path(outcome: &PlanOutcome) -> &super::super::PlanRecord {
        match &outcome.result {
            Ok((None, record)) if !record.feasible => record,
            other => panic!("a path or a refusal: {other:?}"),
        }
    }

    #[test]
    fn a_standing_car_before_a_wall_solves_once_while_nothing_changes() {
        let (nav, wall) = blocked();
        let mut reuse = Reuse::default();
        let first = reuse.solve(&nav.request(0.0, &car(0.0, 0.0), &wall));
        let first = no_path(&first).clone();
        // The same world half a second later, the pose wandering by GPS noise.
        let again = reuse.solve(&nav.request(0.5, &car(0.004, 0.0), &wall));
        assert_eq!(reuse.reused, 1);
        let record = no_path(&again);
        assert_eq!(again.time, 0.5);
        assert_eq!(record.time, 0.5);
        let expected = super::super::PlanRecord { time: 0.5, ..first };
        assert_eq!(format!("{record:?}"), format!("{expected:?}"));
        // A post more, the car moved, the car rolling, or too long since: solved anew.
        let mut more = wall.clone();
        more.push(post(3.0, 2.0, 0.2));
        for (now, pose, obstacles) in [
            (1.0, car(0.0, 0.0), &more),
            (1.0, car(0.3, 0.0), &wall),
            (1.0, car(0.0, 0.5), &wall),
            (MAX_AGE_S + 0.1, car(0.0, 0.0), &wall),
        ] {
            no_path(&reuse.solve(&nav.request(now, &pose, obstacles)));
            assert_eq!(reuse.reused, 1, "{now} {pose:?}");
        }
        // Each solved one is reused in turn.
        no_path(&reuse.solve(&nav.request(MAX_AGE_S + 0.6, &car(0.0, 0.0), &wall)));
        assert_eq!(reuse.reused, 2);
    }

    #[test]
    fn a_moving_car_or_obstacle_is_no_standing_world() {
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.5,
            phi: 0.0,
        };
        assert!(Standing::new(&pose, &[]).is_none());
        let still = Pose { v: 0.0, ..pose };
        assert!(Standing::new(&still, &[]).is_some());
        let walker = Obstacle {
            vx: 0.3,
            ..post(3.0, 0.0, 0.3)
        };
        assert!(Standing::new(&still, &[walker]).is_none());
    }

    #[test]
    fn the_same_world_is_within_the_tolerances_both_ways() {
        let wall: Vec<Obstacle> = (0..10)
            .map(|k| post(5.0, f64::from(k) * 0.7, 0.25))
            .collect();
        // The wall's chain laid afresh half its spacing along.
        let relaid: Vec<Obstacle> = wall
            .iter()
            .map(|o| post(o.x, o.y + 0.35, o.radius))
            .collect();
        assert!(standing(0.0, &wall).same(&standing(0.01, &relaid)));
        // The car moved.
        assert!(!standing(0.0, &wall).same(&standing(0.2, &wall)));
        // A post more, or one less.
        let mut more = wall.clone();
        more.push(post(2.0, 0.0, 0.1));
        assert!(!standing(0.0, &wall).same(&standing(0.0, &more)));
        assert!(!standing(0.0, &more).same(&standing(0.0, &wall)));
        // A disc grown past the tolerance.
        let mut grown = wall.clone();
        grown[3].radius = 0.9;
        assert!(!standing(0.0, &wall).same(&standing(0.0, &grown)));
    }
}
