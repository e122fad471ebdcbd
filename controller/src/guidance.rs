//! Guidance: replanning every T_s with the Qu et al. planner in a frame whose x axis
//! points from the mission's start to its goal, within the steering limit, and
//! following the planned path with the paper's optimal law (feed-forward steering of
//! the path plus feedback on the lateral and heading errors) or an ANFIS model.

use crate::anfis::AnfisModel;
use crate::config::{ControllerConfig, FollowerKind};
use crate::localisation::Pose;
use crate::planner::{self, Interval, PlanOptions, PlanProblem, Trajectory};

/// An obstacle for the planner, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Circle {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
    pub vx: f64,
    pub vy: f64,
}

/// The planning frame: origin at the mission's start, x towards the goal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathFrame {
    pub ox: f64,
    pub oy: f64,
    pub angle: f64,
    pub length: f64,
}

impl PathFrame {
    pub fn new(start: (f64, f64), goal: (f64, f64)) -> PathFrame {
        let (dx, dy) = (goal.0 - start.0, goal.1 - start.1);
        PathFrame {
            ox: start.0,
            oy: start.1,
            angle: dy.atan2(dx),
            length: dx.hypot(dy),
        }
    }

    pub fn to_path(&self, x: f64, y: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        let (dx, dy) = (x - self.ox, y - self.oy);
        (c * dx + s * dy, -s * dx + c * dy)
    }

    pub fn to_world(&self, px: f64, py: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        (self.ox + c * px - s * py, self.oy + s * px + c * py)
    }

    pub fn rotate_to_path(&self, vx: f64, vy: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        (c * vx + s * vy, -s * vx + c * vy)
    }
}

/// How far outside an inflated obstacle the car must be for the obstacle to be
/// planned at its full size, metres.
const MARGIN_SLACK: f64 = 0.05;

fn wrap(a: f64) -> f64 {
    firmware_bridge::geodesy::normalize_rad_pi(a)
}

/// What the follower sees: errors against the path at the vehicle's position.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FollowInputs {
    /// Signed lateral error (left of the path positive), metres.
    pub e_y: f64,
    /// Heading error, radians.
    pub e_theta: f64,
    /// The path's steering angle at this point (the optimal law's feed-forward), radians.
    pub phi_ref: f64,
    /// Speed, m/s.
    pub v: f64,
}

impl FollowInputs {
    /// The inputs an ANFIS follower takes, in this order.
    pub const NAMES: [&'static str; 3] = ["e_y", "e_theta", "phi_ref"];
}

/// The steering law.
#[derive(Debug, Clone)]
pub enum SteeringLaw {
    /// phi = phi_ref - k_y e_y - k_theta e_theta, gains scheduled on speed so the
    /// lateral error has natural frequency omega and damping zeta.
    Optimal {
        omega: f64,
        zeta: f64,
        wheelbase: f64,
    },
    Anfis(Box<AnfisModel>),
}

impl SteeringLaw {
    /// The steering angle to command, radians (before the actuator limit).
    pub fn steer(&self, i: &FollowInputs) -> f64 {
        match self {
            SteeringLaw::Optimal {
                omega,
                zeta,
                wheelbase,
            } => {
                let v = i.v.abs().max(0.5);
                let k_y = omega * omega * wheelbase / (v * v);
                let k_theta = 2.0 * zeta * omega * wheelbase / v;
                i.phi_ref - k_y * i.e_y - k_theta * i.e_theta
            }
            // A model that cannot evaluate (it validated at load) falls back to the
            // feed-forward alone rather than to a wild command.
            SteeringLaw::Anfis(m) => m
                .predict(&[i.e_y, i.e_theta, i.phi_ref])
                .unwrap_or(i.phi_ref),
        }
    }
}

/// One replanning, kept for the run's figure and report.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PlanRecord {
    pub time: f64,
    pub feasible: bool,
    pub a6: Option<f64>,
    pub projected_to_boundary: bool,
    pub max_steer_deg: Option<f64>,
    /// The planned path in the world frame.
    pub path: Vec<[f64; 2]>,
}

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

/// Replanning and following.
#[derive(Debug)]
pub struct Navigator {
    cfg: ControllerConfig,
    pub frame: PathFrame,
    law: SteeringLaw,
    active: Option<Trajectory>,
    next_replan: f64,
    infeasible_since: Option<f64>,
    /// Why the last replanning was refused, if it was.
    planner_error: Option<String>,
    pub plans: Vec<PlanRecord>,
}

/// Why guidance could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum GuidanceError {
    #[error("loading the ANFIS model {path}: {source}")]
    Anfis {
        path: String,
        #[source]
        source: crate::anfis::AnfisError,
    },
    #[error(
        "the ANFIS model {path} takes {found} inputs; the follower gives 3 (e_y, e_theta, phi_ref)"
    )]
    AnfisInputs { path: String, found: usize },
}

impl Navigator {
    pub fn new(cfg: &ControllerConfig) -> Result<Navigator, GuidanceError> {
        let law = match (&cfg.follower.kind, &cfg.follower.anfis_model) {
            (FollowerKind::Anfis, Some(path)) => {
                let model = AnfisModel::load(path).map_err(|source| GuidanceError::Anfis {
                    path: path.display().to_string(),
                    source,
                })?;
                if model.n_inputs() != 3 {
                    return Err(GuidanceError::AnfisInputs {
                        path: path.display().to_string(),
                        found: model.n_inputs(),
                    });
                }
                SteeringLaw::Anfis(Box::new(model))
            }
            _ => SteeringLaw::Optimal {
                omega: cfg.follower.omega,
                zeta: cfg.follower.zeta,
                wheelbase: cfg.vehicle.wheelbase,
            },
        };
        let m = &cfg.mission;
        Ok(Navigator {
            cfg: cfg.clone(),
            frame: PathFrame::new((m.start_x, m.start_y), (m.goal_x, m.goal_y)),
            law,
            active: None,
            next_replan: 0.0,
            infeasible_since: None,
            planner_error: None,
            plans: Vec::new(),
        })
    }

    fn goal_heading_in_frame(&self) -> f64 {
        self.cfg
            .mission
            .goal_heading_deg
            .map_or(0.0, |h| wrap(h.to_radians() - self.frame.angle))
    }

    /// The planning problem for a replanning from `pose` at `now`.
    pub fn request(&self, now: f64, pose: &Pose, obstacles: &[Circle]) -> PlanRequest {
        let (px, py) = self.frame.to_path(pose.x, pose.y);
        let theta = wrap(pose.theta - self.frame.angle);
        let limit = (self.cfg.vehicle.max_steer_deg * self.cfg.planner.steer_usage).to_radians();
        let span = self.frame.length - px;
        let r0 = self.cfg.vehicle.radius + self.cfg.planner.safety_margin;
        let problem = PlanProblem {
            state: planner::VehicleState {
                x: px,
                y: py,
                theta: theta.clamp(-1.4, 1.4),
                phi: pose.phi.clamp(-limit, limit),
            },
            goal: planner::VehicleState {
                x: self.frame.length,
                y: 0.0,
                theta: self.goal_heading_in_frame(),
                phi: 0.0,
            },
            line_start: planner::LineStart { x0: 0.0, y0: 0.0 },
            line_end: None,
            t_k: now,
            t_f: now + span / self.cfg.planner.cruise_speed,
            wheelbase: self.cfg.vehicle.wheelbase,
            vehicle_radius: r0,
            obstacles: obstacles
                .iter()
                .map(|o| {
                    let (x, y) = self.frame.to_path(o.x, o.y);
                    let (vx, vy) = self.frame.rotate_to_path(o.vx, o.vy);
                    // A path on the boundary of an inflated obstacle leaves the car on
                    // it; tracking errors then put the start inside, and every a6
                    // would be forbidden. Where the car already is within the margin,
                    // the obstacle is planned as just clear of where the car is, so
                    // the new path leads away from it, never closer.
                    let gap = (px - x).hypot(py - y) - r0 - MARGIN_SLACK;
                    planner::Obstacle {
                        x,
                        y,
                        radius: o.radius.min(gap.max(0.0)),
                        vx,
                        vy,
                    }
                })
                .collect(),
        };
        PlanRequest {
            time: now,
            problem,
            steer_limit: limit,
            frame: self.frame,
        }
    }

    /// Whether a replanning is due at `now` from `pose`.
    pub fn replan_due(&self, now: f64, pose: &Pose) -> bool {
        let (px, _) = self.frame.to_path(pose.x, pose.y);
        now >= self.next_replan && self.frame.length - px > self.cfg.planner.final_approach
    }

    /// A replanning was issued at `now`: the next is due one T_s later.
    pub fn issued(&mut self, now: f64) {
        self.next_replan = now + self.cfg.planner.replan_period_s;
    }

    /// Take a finished replanning: its path is followed from now on.
    pub fn accept(&mut self, outcome: PlanOutcome) {
        match outcome.result {
            Ok((trajectory, record)) => {
                if trajectory.is_some() {
                    self.infeasible_since = None;
                } else {
                    self.infeasible_since.get_or_insert(outcome.time);
                }
                self.active = trajectory;
                self.planner_error = None;
                self.plans.push(record);
            }
            Err(e) => {
                self.active = None;
                self.planner_error = Some(e);
            }
        }
    }

    /// Follow the current path from `pose` (no planning).
    pub fn follow(&mut self, pose: &Pose) -> Guidance {
        let goal = (self.cfg.mission.goal_x, self.cfg.mission.goal_y);
        let to_goal = (pose.x - goal.0).hypot(pose.y - goal.1);
        if to_goal <= self.cfg.mission.goal_tolerance {
            return Guidance::Arrived;
        }
        let (px, py) = self.frame.to_path(pose.x, pose.y);
        if self.frame.length - px <= 0.0 {
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
        // Speed: the plan's pace, slower in curves and towards the goal.
        let f = &self.cfg.follower;
        let curvature = path.curvature(x).abs().max(1e-6);
        let speed = self
            .cfg
            .planner
            .cruise_speed
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

/// One replanning to do: the problem in the planning frame and the steering limit.
#[derive(Clone, Debug)]
pub struct PlanRequest {
    pub time: f64,
    pub problem: PlanProblem,
    /// Road-wheel angle a planned path may use, radians.
    pub steer_limit: f64,
    frame: PathFrame,
}

/// A finished replanning: the path (None when no feasible path exists) and its
/// record, or why the planner refused the problem.
#[derive(Clone, Debug)]
pub struct PlanOutcome {
    pub time: f64,
    pub result: Result<(Option<Trajectory>, PlanRecord), String>,
}

/// Solve a replanning (pure: runs inline or on a planning thread). Among the feasible
/// a6 it takes the cheapest whose path stays within the steering limit, since the
/// method itself has none.
pub fn solve(req: &PlanRequest) -> PlanOutcome {
    let run = || -> Result<(Option<Trajectory>, PlanRecord), String> {
        let problem = &req.problem;
        let step =
            planner::plan_with(problem, &PlanOptions::default()).map_err(|e| e.to_string())?;
        let mut chosen = step.trajectory.clone();
        let mut a6 = step.result.a6_chosen;
        if step
            .result
            .max_abs_steering
            .is_some_and(|s| s > req.steer_limit)
        {
            chosen = None;
            a6 = None;
            let line = planner::ReferenceLine::new(0.0, 0.0, problem.goal.x, 0.0)
                .map_err(|e| e.to_string())?;
            let mut best: Option<(f64, f64, Trajectory)> = None;
            for candidate in candidates(step.result.a6_unconstrained, &step.result.feasible_set) {
                let Ok(t) = problem.trajectory(candidate) else {
                    continue;
                };
                if max_steer(&t) > req.steer_limit {
                    continue;
                }
                let cost = t.path().reference_cost(&line);
                if best.as_ref().is_none_or(|b| cost < b.0) {
                    best = Some((cost, candidate, t));
                }
            }
            if let Some((_, c, t)) = best {
                a6 = Some(c);
                chosen = Some(t);
            }
        }
        let record = PlanRecord {
            time: req.time,
            feasible: chosen.is_some(),
            a6,
            projected_to_boundary: step.result.projected_to_boundary,
            max_steer_deg: chosen.as_ref().map(|t| max_steer(t).to_degrees()),
            path: chosen.as_ref().map_or_else(Vec::new, |t| {
                let p = t.path();
                (0..=40)
                    .map(|j| {
                        let x = p.x_k() + p.span() * f64::from(j) / 40.0;
                        let (wx, wy) = req.frame.to_world(x, p.y(x));
                        [wx, wy]
                    })
                    .collect()
            }),
        };
        Ok((chosen, record))
    };
    PlanOutcome {
        time: req.time,
        result: run(),
    }
}

/// Maximum steering angle along a path, radians.
fn max_steer(t: &Trajectory) -> f64 {
    let p = t.path();
    (0..=200)
        .map(|j| {
            p.steering_angle(p.x_k() + p.span() * f64::from(j) / 200.0)
                .abs()
        })
        .fold(0.0, f64::max)
}

/// a6 values to try inside the feasible set: its finite boundaries, the unconstrained
/// optimum clamped into each piece, and a spread through each piece.
fn candidates(a6_star: f64, feasible: &[Interval]) -> Vec<f64> {
    let mut out = Vec::new();
    let scale = feasible
        .iter()
        .flat_map(|i| [i.lo, i.hi])
        .chain([a6_star])
        .filter(|v| v.is_finite())
        .map(f64::abs)
        .fold(0.0, f64::max)
        .max(1e-12);
    for i in feasible {
        let lo = if i.lo.is_finite() {
            i.lo
        } else {
            i.hi.min(a6_star) - 4.0 * scale
        };
        let hi = if i.hi.is_finite() {
            i.hi
        } else {
            i.lo.max(a6_star) + 4.0 * scale
        };
        out.push(i.clamp(a6_star));
        for j in 0..=64 {
            out.push(lo + (hi - lo) * f64::from(j) / 64.0);
        }
    }
    out.retain(|v| v.is_finite() && feasible.iter().any(|i| i.contains(*v)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn replan_and_follow(nav: &mut Navigator, pose: &Pose, obstacles: &[Circle]) -> Guidance {
        assert!(nav.replan_due(0.0, pose));
        nav.issued(0.0);
        nav.accept(solve(&nav.request(0.0, pose, obstacles)));
        nav.follow(pose)
    }

    #[test]
    fn path_frame_round_trips_and_points_at_the_goal() {
        let f = PathFrame::new((0.0, 0.0), (30.0, 15.0));
        let (px, py) = f.to_path(30.0, 15.0);
        assert!((px - f.length).abs() < 1e-12 && py.abs() < 1e-12);
        let (x, y) = f.to_world(3.0, -2.0);
        let (bx, by) = f.to_path(x, y);
        assert!((bx - 3.0).abs() < 1e-12 && (by + 2.0).abs() < 1e-12);
    }

    #[test]
    fn optimal_law_corrects_towards_the_path() {
        let law = SteeringLaw::Optimal {
            omega: 0.9,
            zeta: 0.8,
            wheelbase: 1.65,
        };
        let base = FollowInputs {
            e_y: 0.0,
            e_theta: 0.0,
            phi_ref: 0.1,
            v: 2.0,
        };
        assert_eq!(law.steer(&base), 0.1, "on the path: the feed-forward alone");
        assert!(
            law.steer(&FollowInputs { e_y: 0.5, ..base }) < 0.1,
            "left of the path: steer right"
        );
        assert!(
            law.steer(&FollowInputs {
                e_theta: -0.1,
                ..base
            }) > 0.1
        );
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
        assert!(matches!(
            replan_and_follow(&mut nav, &pose, &[blocker]),
            Guidance::Stop { .. }
        ));
    }
}
