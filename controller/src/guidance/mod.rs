//! Guidance: replanning every T_s with the Qu et al. planner towards a local goal on
//! the mission's route, in a frame whose x axis points from the car's place on the
//! route to that goal, within the steering limit, and following the planned path with
//! the paper's optimal law (feed-forward steering of the path plus feedback on the
//! lateral and heading errors) or an ANFIS model.
//!
//! # Beyond the paper
//!
//! - Routes and a receding horizon: the mission is a route (start, waypoints, goal,
//!   [`crate::route::Route`]). Each replanning plans one Qu et al. polynomial from the
//!   car to a local goal `horizon_m` further along the route (the goal itself once it
//!   is that near), arriving with the route's heading there; the frame's x axis runs
//!   from the car's place on the route (its progress) to the local goal, and the
//!   paper's L is that chord. A local goal with an inflated obstacle on it or on the
//!   5 m of route before it is moved on
//!   along the route (1 m at a time, up to the goal) or, failing that, back towards
//!   the car (down to `horizon_min_m`). A start-goal mission no longer than the
//!   horizon is planned exactly as before: one leg, the goal as the local goal.
//! - Detours: when the local goal has no feasible path, other local goals (shifted
//!   sideways, or at half the distance; [`Navigator::detours`]) are planned in the
//!   order of their stated cost, each its own Qu et al. polynomial, and the first
//!   feasible one is taken ([`solve`]).
//!
//! - Steering limit: among the feasible a6 the cheapest path within 85 % of the
//!   actuator's limit is taken (the method has no steering constraint).
//! - Margins: the vehicle radius grows by a safety margin; a static obstacle the car
//!   already stands within the margin of is planned as just clear of the car, so the
//!   new path leads away from it instead of every a6 being forbidden.
//! - Moving obstacles (the paper's planner is for static ones in practice: its time
//!   law is fixed by t_f, so it can only swerve, and it swerved ahead of a crossing
//!   obstacle in its direction of travel, into it). With a tracked obstacle moving,
//!   the pace is a second free parameter: t_f = t_k + (x_f - x_k) / pace for each of
//!   [`crate::config::PlannerConfig::pace_fractions`] of the cruise speed. Each pace is
//!   planned in space-time (the Qu et al. constraint with the obstacle's
//!   constant-velocity prediction at the instant the car is at each x), with every
//!   moving obstacle swept along its velocity over +- a time margin (its timing and
//!   the car's are uncertain) plus the slip of the car's schedule while it changes
//!   speed to that pace ([`sweep`], [`Pacing::schedule_slip`]). The feasible pace with
//!   the least deviation from the line plus a weighted time loss wins
//!   ([`Pacing::score`]): yielding by slowing down beats a wide swerve at full speed,
//!   and with no feasible pace the car stops. The follower then drives the plan's pace
//!   (x advancing at w1), so the car is where the plan assumed; the next replanning
//!   (T_s later) speeds up again once the obstacle has passed.
//! - Headings the polynomial cannot start from: beyond `align_enter_deg` from the
//!   line, the car first turns towards the goal on the planned steering limit at low
//!   speed, when the whole turning circle is clear ([`Align`]), until within
//!   `align_exit_deg`.
//! - Real actuators: the follower and the planner work from the pose propagated over
//!   the steering's calibrated dead time with the commands still on their way
//!   ([`Navigator::follow_ahead`]; `Controller::ahead`), while arrival, progress and
//!   the approach speed use the pose now; the localiser removes an estimated steering
//!   sensor bias and filters the fixes ([`crate::localisation`]).
//!
//! # Files
//!
//! `frame` (the world and planning frames), `search` (where a replanning aims: the
//! local goal and its detours), `pacing` (moving obstacles: the pace and the sweep),
//! `align` (turning towards the goal first), `solver` (solving a replanning),
//! `follower` (the steering laws) and `error`; this file keeps the navigator, which
//! builds the requests, takes the outcomes and follows the path.

mod align;
mod error;
mod follower;
mod frame;
mod pacing;
mod search;
mod solver;

pub use align::Align;
pub use error::{GuidanceError, ReplanError};
pub use follower::{FollowInputs, SteeringLaw};
pub use frame::{Circle, PathFrame};
pub use pacing::{Pacing, sweep};
pub use solver::{PlanOutcome, PlanRecord, PlanRequest, solve};

use crate::config::ControllerConfig;
use crate::localisation::Pose;
use crate::planner::{self, PlanProblem, Trajectory};
use crate::route::{Route, RoutePoint};
use frame::{clip_to_start, wrap};
use search::{MAX_GOAL_HEADING, MAX_LOCAL_HEADING};

/// What guidance asks of the actuators.
#[derive(Clone, Debug, PartialEq)]
pub enum Guidance {
    Drive {
        /// Road-wheel angle, radians.
        steer: f64,
        /// Speed, m/s.
        speed: f64,
        inputs: FollowInputs,
    },
    /// Stop with the steering held: no feasible path (or the planner failed).
    Stop { reason: String },
    /// Within the goal tolerance.
    Arrived,
}

/// How far back and ahead of its last progress the car's place on the route is looked
/// for (per call: progress is updated every control tick), metres.
const PROGRESS_BACK: f64 = 2.0;
const PROGRESS_AHEAD: f64 = 5.0;

/// Replanning and following.
#[derive(Debug)]
pub struct Navigator {
    cfg: ControllerConfig,
    route: Route,
    /// The car's progress along the route (arc length), metres.
    progress: f64,
    /// The frame of the active plan (or of the alignment turn).
    frame: PathFrame,
    /// The last leg, for "passed the goal".
    last_leg: PathFrame,
    law: SteeringLaw,
    active: Option<Trajectory>,
    /// The active path was planned around moving obstacles: drive its pace.
    paced: bool,
    /// Turning towards the goal on this road-wheel angle before planning, radians.
    aligning: Option<f64>,
    next_replan: f64,
    infeasible_since: Option<f64>,
    /// Why the last replanning was refused, if it was.
    planner_error: Option<ReplanError>,
    pub plans: Vec<PlanRecord>,
}

impl Navigator {
    pub fn new(cfg: &ControllerConfig) -> Result<Navigator, GuidanceError> {
        let law = SteeringLaw::from_config(cfg)?;
        let route = Route::new(&cfg.mission);
        let points = route.points();
        let last_leg = PathFrame::new(points[points.len() - 2], points[points.len() - 1]);
        Ok(Navigator {
            cfg: cfg.clone(),
            frame: PathFrame::new(points[0], points[1]),
            last_leg,
            route,
            progress: 0.0,
            law,
            active: None,
            paced: false,
            aligning: None,
            next_replan: 0.0,
            infeasible_since: None,
            planner_error: None,
            plans: Vec::new(),
        })
    }

    /// The car's progress along the route from `pose`.
    fn progress_at(&self, pose: &Pose) -> f64 {
        self.route
            .project(pose.x, pose.y, self.progress, PROGRESS_BACK, PROGRESS_AHEAD)
    }

    /// The local goal from progress `s`: `horizon_m` further along the route (the goal
    /// once that near), moved on along the route, or else back towards the car, until
    /// it lies outside every inflated static obstacle; the nominal one when none does
    /// (the planner then finds no path, and the car stops).
    pub fn local_goal(&self, s: f64, obstacles: &[Circle]) -> RoutePoint {
        let pc = &self.cfg.planner;
        let r0 = self.cfg.vehicle.radius + pc.safety_margin;
        search::local_goal(&self.route, pc, r0, s, obstacles)
    }

    /// Local goals to try when the first has no feasible path (detours): the first
    /// local goal shifted sideways by 1.5, 3 and 4.5 m, and the route's point at half
    /// its distance, unshifted and shifted the same; each clear of every inflated
    /// static obstacle; at most `MAX_DETOURS`. The order is the stated cost, and the
    /// first with a feasible path wins: the least lateral shift, then the farther goal,
    /// then right before left.
    pub fn detours(&self, s: f64, first: &RoutePoint, obstacles: &[Circle]) -> Vec<RoutePoint> {
        let pc = &self.cfg.planner;
        let r0 = self.cfg.vehicle.radius + pc.safety_margin;
        search::detours(&self.route, pc, r0, s, first, obstacles)
    }

    /// The planning problem towards `goal` from `pose` at `now`, in the frame from the
    /// car's place on the route (`here`) to the goal; and whether an obstacle moves.
    fn problem(
        &self,
        now: f64,
        pose: &Pose,
        obstacles: &[Circle],
        here: &RoutePoint,
        goal: &RoutePoint,
    ) -> (PlanProblem, PathFrame, bool) {
        let frame = PathFrame::new((here.x, here.y), (goal.x, goal.y));
        let max_heading = if goal.s < self.route.length() {
            MAX_LOCAL_HEADING
        } else {
            MAX_GOAL_HEADING
        };
        let (px, py) = frame.to_path(pose.x, pose.y);
        let theta = wrap(pose.theta - frame.angle);
        let pc = &self.cfg.planner;
        let limit = (self.cfg.vehicle.max_steer_deg * pc.steer_usage).to_radians();
        let span = frame.length - px;
        let r0 = self.cfg.vehicle.radius + pc.safety_margin;
        let mut any_moving = false;
        let problem = PlanProblem {
            state: planner::VehicleState {
                x: px,
                y: py,
                theta: theta.clamp(-1.4, 1.4),
                phi: pose.phi.clamp(-limit, limit),
            },
            goal: planner::VehicleState {
                x: frame.length,
                y: 0.0,
                theta: wrap(goal.heading - frame.angle).clamp(-max_heading, max_heading),
                phi: 0.0,
            },
            line_start: planner::LineStart { x0: 0.0, y0: 0.0 },
            line_end: None,
            t_k: now,
            t_f: now + span / pc.cruise_speed,
            wheelbase: self.cfg.vehicle.wheelbase,
            vehicle_radius: r0,
            obstacles: obstacles
                .iter()
                .map(|o| {
                    let (x, y) = frame.to_path(o.x, o.y);
                    let (vx, vy) = frame.rotate_to_path(o.vx, o.vy);
                    if vx != 0.0 || vy != 0.0 {
                        // Moving: swept and clipped per pace in `solve`.
                        any_moving = true;
                        return planner::Obstacle {
                            x,
                            y,
                            radius: o.radius + pc.moving_margin,
                            vx,
                            vy,
                        };
                    }
                    // A path on the boundary of an inflated obstacle leaves the car on
                    // it; tracking errors then put the start inside, and every a6
                    // would be forbidden. Where the car already is within the margin,
                    // the obstacle is planned as just clear of where the car is, so
                    // the new path leads away from it, never closer.
                    planner::Obstacle {
                        x,
                        y,
                        radius: clip_to_start(o.radius, x, y, px, py, r0),
                        vx,
                        vy,
                    }
                })
                .collect(),
        };
        (problem, frame, any_moving)
    }

    /// The planning problem for a replanning from `pose` at `now`: towards the local
    /// goal, with the detours to try if it has no feasible path.
    pub fn request(&self, now: f64, pose: &Pose, obstacles: &[Circle]) -> PlanRequest {
        let s = self.progress_at(pose);
        let here = self.route.at(s);
        let goal = self.local_goal(s, obstacles);
        let (problem, frame, any_moving) = self.problem(now, pose, obstacles, &here, &goal);
        let detours = self
            .detours(s, &goal, obstacles)
            .iter()
            .map(|g| {
                let (p, f, _) = self.problem(now, pose, obstacles, &here, g);
                (p, f)
            })
            .collect();
        let theta = wrap(pose.theta - frame.angle);
        let pc = &self.cfg.planner;
        let limit = (self.cfg.vehicle.max_steer_deg * pc.steer_usage).to_radians();
        let pacing = any_moving.then(|| Pacing {
            speeds: pc
                .pace_fractions
                .iter()
                .map(|f| f * pc.cruise_speed)
                .collect(),
            speed_now: pose.v.max(0.0),
            accel: self.cfg.follower.accel_limit,
            decel: self.cfg.follower.decel,
            time_margin: pc.moving_time_margin_s,
            time_weight: pc.pace_time_weight,
        });
        let threshold = if self.aligning.is_some() {
            pc.align_exit_deg
        } else {
            pc.align_enter_deg
        };
        let align = (theta.abs() > threshold.to_radians()).then(|| Align {
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            // Turn the short way round first.
            prefer_left: theta < 0.0,
            turn_radius: self.cfg.vehicle.wheelbase / limit.tan(),
            obstacles: obstacles.to_vec(),
        });
        PlanRequest {
            time: now,
            problem,
            steer_limit: limit,
            frame,
            detours,
            pacing,
            align,
        }
    }

    /// Whether a replanning is due at `now` from `pose`.
    pub fn replan_due(&self, now: f64, pose: &Pose) -> bool {
        now >= self.next_replan
            && self.route.length() - self.progress_at(pose) > self.cfg.planner.final_approach
    }

    /// A replanning was issued at `now`: the next is due one T_s later.
    pub fn issued(&mut self, now: f64) {
        self.next_replan = now + self.cfg.planner.replan_period_s;
    }

    /// Take a finished replanning: its path is followed from now on.
    pub fn accept(&mut self, outcome: PlanOutcome) {
        self.frame = outcome.frame;
        match outcome.result {
            Ok((trajectory, record)) => {
                if trajectory.is_some() {
                    self.infeasible_since = None;
                } else {
                    self.infeasible_since.get_or_insert(outcome.time);
                }
                self.active = trajectory;
                self.paced = record.moving;
                self.aligning = record.align;
                self.planner_error = None;
                self.plans.push(record);
            }
            Err(e) => {
                self.active = None;
                self.aligning = None;
                self.planner_error = Some(e);
            }
        }
    }

    /// Follow the current path from `pose` (no planning).
    pub fn follow(&mut self, pose: &Pose) -> Guidance {
        self.follow_ahead(pose, pose)
    }

    /// Follow the current path: arrival, progress, passing the goal and the approach
    /// speed from `pose` (where the car is), steering from `ahead` (where it will be when
    /// the command acts: the pose propagated over the steering dead time).
    pub fn follow_ahead(&mut self, pose: &Pose, ahead: &Pose) -> Guidance {
        let goal = (self.cfg.mission.goal_x, self.cfg.mission.goal_y);
        let to_goal = (pose.x - goal.0).hypot(pose.y - goal.1);
        if to_goal <= self.cfg.mission.goal_tolerance {
            return Guidance::Arrived;
        }
        self.progress = self.progress_at(pose);
        if self.last_leg.length - self.last_leg.to_path(pose.x, pose.y).0 <= 0.0 {
            // Past the goal's x without reaching it: the polynomial cannot go back.
            return Guidance::Stop {
                reason: format!("passed the goal {to_goal:.2} m beside it"),
            };
        }
        if let Some(e) = &self.planner_error {
            return Guidance::Stop {
                reason: format!("planner: {e}"),
            };
        }
        let pose = ahead;
        let (px, py) = self.frame.to_path(pose.x, pose.y);
        if let Some(steer) = self.aligning {
            let theta = wrap(pose.theta - self.frame.angle);
            return Guidance::Drive {
                steer,
                speed: self.cfg.planner.align_speed.min(self.cfg.vehicle.max_speed),
                inputs: FollowInputs {
                    e_y: 0.0,
                    e_theta: theta,
                    phi_ref: steer,
                    v: pose.v,
                },
            };
        }
        let Some(t) = &self.active else {
            return Guidance::Stop {
                reason: "no collision-free path".to_owned(),
            };
        };
        let path = t.path();
        let x = px.clamp(path.x_k(), path.x_f());
        let theta_ref = path.heading(x);
        let theta = wrap(pose.theta - self.frame.angle);
        let inputs = FollowInputs {
            e_y: (py - path.y(x)) * theta_ref.cos(),
            e_theta: wrap(theta - theta_ref),
            phi_ref: path.steering_angle(x),
            v: pose.v,
        };
        let steer = self.law.steer(&inputs);
        // Speed: the plan's pace, slower in curves and towards the goal. Around moving
        // obstacles the plan's timing matters: x must advance at the planned w1, so the
        // speed along the path is w1 sqrt(1 + y'^2).
        let f = &self.cfg.follower;
        let curvature = path.curvature(x).abs().max(1e-6);
        let pace = if self.paced {
            t.w1() * path.dy_dx(x).hypot(1.0)
        } else {
            self.cfg.planner.cruise_speed
        };
        let speed = pace
            .min(
                self.route
                    .speed_limit(self.progress)
                    .unwrap_or(f64::INFINITY),
            )
            .min((f.max_lateral_accel / curvature).sqrt())
            .min((2.0 * f.decel * to_goal).sqrt())
            .min(self.cfg.vehicle.max_speed);
        Guidance::Drive {
            steer,
            speed,
            inputs,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::search::{MAX_DETOURS, clear_of};
    use super::*;

    fn replan_and_follow(nav: &mut Navigator, pose: &Pose, obstacles: &[Circle]) -> Guidance {
        assert!(nav.replan_due(0.0, pose));
        nav.issued(0.0);
        nav.accept(solve(&nav.request(0.0, pose, obstacles)));
        nav.follow(pose)
    }

    #[test]
    fn the_paper_scenario_plans_around_the_post_within_the_steering_limit() {
        let cfg = ControllerConfig::default();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 45f64.to_radians(),
            v: 0.0,
            phi: 0.0,
        };
        let post = Circle {
            x: 19.0,
            y: 8.0,
            radius: 3.0,
            vx: 0.0,
            vy: 0.0,
        };
        match replan_and_follow(&mut nav, &pose, &[post]) {
            Guidance::Drive { steer, speed, .. } => {
                assert!(steer.abs() <= 35f64.to_radians() && speed > 0.0);
            }
            other => panic!("expected to drive, got {other:?}"),
        }
        let plan = nav.plans.last().expect("a plan");
        assert!(plan.feasible);
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        let clearance = plan
            .path
            .iter()
            .map(|p| (p[0] - post.x).hypot(p[1] - post.y) - post.radius - r0)
            .fold(f64::INFINITY, f64::min);
        assert!(
            clearance > -0.05,
            "the sampled plan clears the post: {clearance}"
        );
        assert!(
            plan.max_steer_deg.expect("steer")
                <= cfg.vehicle.max_steer_deg * cfg.planner.steer_usage + 1e-9
        );
    }

    #[test]
    fn an_obstacle_on_the_goal_means_stop() {
        let cfg = ControllerConfig::default();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.4,
            v: 0.0,
            phi: 0.0,
        };
        let blocker = Circle {
            x: 30.0,
            y: 15.0,
            radius: 1.0,
            vx: 0.0,
            vy: 0.0,
        };
        // Farther than the horizon, the car drives towards a local goal before it.
        assert!(matches!(
            replan_and_follow(&mut nav, &pose, &[blocker]),
            Guidance::Drive { .. }
        ));
        // A blocked goal: local goals stop short of it, outside the inflated blocker,
        // and once the car is there no path is left: a controlled stop beside it.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let heading = 15f64.atan2(30.0);
        let along = |d: f64| Pose {
            x: d * heading.cos(),
            y: d * heading.sin(),
            theta: heading,
            ..pose
        };
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        // Progress along the route follows the car tick by tick.
        for d in 0..=29 {
            nav.follow(&along(f64::from(d)));
            let g = nav.local_goal(f64::from(d), &[blocker]);
            assert!(
                (g.x - 30.0).hypot(g.y - 15.0) > blocker.radius + r0,
                "{d}: {g:?}"
            );
        }
        assert!(matches!(
            replan_and_follow(&mut nav, &along(29.8), &[blocker]),
            Guidance::Stop { .. }
        ));
    }

    #[test]
    fn a_crossing_obstacle_timed_to_meet_the_car_is_yielded_to() {
        let mut cfg = ControllerConfig::default();
        cfg.mission.goal_x = 35.0;
        cfg.mission.goal_y = 0.0;
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = Pose {
            x: 8.0,
            y: 0.0,
            theta: 0.0,
            v: 2.0,
            phi: 0.0,
        };
        // At 2 m/s the car is at x = 16 in 4 s, when the obstacle crosses y = 0.
        let crossing = Circle {
            x: 16.0,
            y: -5.2,
            radius: 0.5,
            vx: 0.0,
            vy: 1.3,
        };
        let req = nav.request(0.0, &pose, &[crossing]);
        assert!(req.pacing.is_some() && req.align.is_none());
        let outcome = solve(&req);
        let (trajectory, record) = outcome.result.clone().expect("planned");
        let t = trajectory.expect("a feasible pace");
        assert!(record.moving);
        let pace = record.pace.expect("pace");
        assert!(pace < cfg.planner.cruise_speed, "it slows down: {pace}");
        // In space-time the path clears the obstacle's predicted track.
        let obstacle = planner::Obstacle {
            x: crossing.x,
            y: crossing.y,
            radius: crossing.radius,
            vx: 0.0,
            vy: 1.3,
        };
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        let clearance = planner::min_clearance(&t, &obstacle, r0, &planner::Sampling::default());
        assert!(clearance > 0.0, "{clearance}");
        // The same obstacle taken as static at its position (the paper's planner)
        // gives no reason to slow down.
        let still = Circle {
            vy: 0.0,
            ..crossing
        };
        let (_, static_record) = solve(&nav.request(0.0, &pose, &[still]))
            .result
            .expect("planned");
        assert!(!static_record.moving);
        nav.accept(outcome);
        match nav.follow(&pose) {
            Guidance::Drive { speed, .. } => assert!(speed < cfg.planner.cruise_speed),
            other => panic!("expected to drive, got {other:?}"),
        }
    }

    #[test]
    fn a_car_facing_away_turns_towards_the_goal_where_the_circle_is_clear() {
        let cfg = ControllerConfig::default();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        // The line points at 26.6 degrees; the car at 170 degrees (143 off, to the
        // left): the short way round is a right turn.
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 170f64.to_radians(),
            v: 0.0,
            phi: 0.0,
        };
        let req = nav.request(0.0, &pose, &[]);
        let align = req.align.clone().expect("align");
        assert!(!align.prefer_left);
        nav.accept(solve(&req));
        let limit = (cfg.vehicle.max_steer_deg * cfg.planner.steer_usage).to_radians();
        match nav.follow(&pose) {
            Guidance::Drive { steer, speed, .. } => {
                assert!((steer + limit).abs() < 1e-12, "{steer}");
                assert_eq!(speed, cfg.planner.align_speed);
            }
            other => panic!("expected to turn, got {other:?}"),
        }
        // A post on the right turning circle: the long way round (left).
        let r = cfg.vehicle.wheelbase / limit.tan();
        let (cx, cy) = (r * pose.theta.sin(), -r * pose.theta.cos());
        let post = Circle {
            x: cx + r,
            y: cy,
            radius: 0.5,
            vx: 0.0,
            vy: 0.0,
        };
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        let blocked = Align {
            obstacles: vec![post],
            ..align.clone()
        };
        assert!(!blocked.clear(false, r0));
        assert_eq!(blocked.steer(r0, limit), Some(limit));
        // Posts on both circles: stop.
        let other = Circle {
            x: -r * pose.theta.sin() - r,
            y: r * pose.theta.cos(),
            ..post
        };
        let boxed_in = Align {
            obstacles: vec![post, other],
            ..align
        };
        assert_eq!(boxed_in.steer(r0, limit), None);
        // Within the exit angle, planning resumes.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let aligned = Pose {
            theta: 40f64.to_radians(),
            ..pose
        };
        assert!(nav.request(0.0, &aligned, &[]).align.is_none());
        nav.accept(solve(&nav.request(0.0, &aligned, &[])));
        assert!(matches!(nav.follow(&aligned), Guidance::Drive { .. }));
    }

    fn long_route() -> ControllerConfig {
        let mut cfg = ControllerConfig::default();
        cfg.mission.waypoints = vec![crate::route::Waypoint {
            x: 50.0,
            y: 0.0,
            tolerance: 2.0,
            heading_deg: None,
            speed_limit: None,
        }];
        cfg.mission.goal_x = 50.0;
        cfg.mission.goal_y = 60.0;
        cfg
    }

    #[test]
    fn a_long_route_is_planned_towards_a_local_goal_on_it() {
        let cfg = long_route();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 0.0,
            phi: 0.0,
        };
        let req = nav.request(0.0, &pose, &[]);
        assert!((req.problem.goal.x - cfg.planner.horizon_m).abs() < 1e-9);
        assert_eq!(req.problem.goal.theta, 0.0, "the route's heading there");
        assert!(matches!(
            replan_and_follow(&mut nav, &pose, &[]),
            Guidance::Drive { .. }
        ));
        let end = nav
            .plans
            .last()
            .and_then(|p| p.path.last().copied())
            .expect("path");
        assert!(
            (end[0] - 20.0).abs() < 1e-6 && end[1].abs() < 1e-6,
            "{end:?}"
        );
        // Nearer the corner than the horizon: the local goal is round it, on the
        // second leg, arriving within MAX_LOCAL_HEADING of its chord.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        for x in 0..=40 {
            nav.follow(&Pose {
                x: f64::from(x),
                ..pose
            });
        }
        let at = Pose { x: 40.0, ..pose };
        let g = nav.local_goal(40.0, &[]);
        assert!(
            (g.x - 50.0).abs() < 1e-9 && (g.y - 10.0).abs() < 1e-9,
            "{g:?}"
        );
        let req = nav.request(0.0, &at, &[]);
        assert!(req.problem.goal.theta.abs() <= MAX_LOCAL_HEADING + 1e-12);
        // A post on the local goal moves it on along the route, 5 m of approach clear.
        let post = Circle {
            x: 50.0,
            y: 10.0,
            radius: 0.5,
            vx: 0.0,
            vy: 0.0,
        };
        let moved = nav.local_goal(40.0, &[post]);
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        assert!(
            moved.y - 5.0 > post.y + post.radius + r0 - 1e-9,
            "{moved:?}"
        );
    }

    #[test]
    fn detours_are_clear_and_ordered_by_shift_then_distance() {
        let cfg = long_route();
        let nav = Navigator::new(&cfg).expect("navigator");
        let first = nav.local_goal(0.0, &[]);
        let post = Circle {
            x: 20.0,
            y: -1.5,
            radius: 0.5,
            vx: 0.0,
            vy: 0.0,
        };
        let d = nav.detours(0.0, &first, &[post]);
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        assert!(!d.is_empty() && d.len() <= MAX_DETOURS);
        assert!(d.iter().all(|g| clear_of(g, &[post], r0)));
        // The route's point at half the distance, unshifted, comes first.
        assert!(
            (d[0].x - 10.0).abs() < 1e-9 && d[0].y.abs() < 1e-9,
            "{:?}",
            d[0]
        );
        let shifts: Vec<f64> = d
            .iter()
            .map(|g| nav.route.at(g.s).y.hypot(0.0) + g.y.abs())
            .collect();
        assert!(shifts.windows(2).all(|w| w[0] <= w[1] + 1e-9), "{shifts:?}");
    }
}
