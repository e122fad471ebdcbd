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

use crate::anfis::AnfisModel;
use crate::config::{ControllerConfig, FollowerKind};
use crate::localisation::Pose;
use crate::planner::{self, Interval, PlanOptions, PlanProblem, Trajectory};
use crate::route::{Route, RoutePoint};

/// An obstacle for the planner, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Circle {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
    pub vx: f64,
    pub vy: f64,
}

/// A planning frame: origin on the route, x towards the local goal.
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
    /// The pace planned, dx/dt along the start-goal line, m/s (None when infeasible).
    #[serde(default)]
    pub pace: Option<f64>,
    /// Whether moving obstacles were planned in space-time (the pace was searched).
    #[serde(default)]
    pub moving: bool,
    /// Set when the car heads too far from the line to plan: turn on this road-wheel
    /// angle (radians) towards the goal first.
    #[serde(default)]
    pub align: Option<f64>,
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

/// How far back and ahead of its last progress the car's place on the route is looked
/// for (per call: progress is updated every control tick), metres.
const PROGRESS_BACK: f64 = 2.0;
const PROGRESS_AHEAD: f64 = 5.0;
/// Step of the search for a clear local goal along the route, metres.
const LOCAL_GOAL_STEP: f64 = 1.0;
/// Sideways shifts of a detour's local goal, metres (negative: right).
const DETOUR_SHIFTS: [f64; 7] = [0.0, -1.5, 1.5, -3.0, 3.0, -4.5, 4.5];
/// Most detours tried per replanning.
const MAX_DETOURS: usize = 8;

/// Whether `p` lies outside every static obstacle grown by `r0`.
fn clear_of(p: &RoutePoint, obstacles: &[Circle], r0: f64) -> bool {
    obstacles
        .iter()
        .filter(|o| o.vx == 0.0 && o.vy == 0.0)
        .all(|o| (o.x - p.x).hypot(o.y - p.y) > o.radius + r0)
}

/// The stretch of route before a local goal that must be clear of obstacles, metres.
const LOCAL_GOAL_APPROACH: f64 = 5.0;
/// A local goal's heading in its frame is kept within this (y(x) cannot arrive
/// steeper), radians.
const MAX_GOAL_HEADING: f64 = 1.2;
/// A local goal before the goal arrives within this of its chord, so that round a
/// corner the car turns over several replannings instead of at once, radians.
const MAX_LOCAL_HEADING: f64 = 0.5;

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
        let end = self.route.length();
        let nominal = (s + pc.horizon_m).min(end);
        // The route's last LOCAL_GOAL_APPROACH before the goal is clear too, so a plan
        // can arrive on it with its heading.
        let clear = |g: &RoutePoint| {
            let n = (LOCAL_GOAL_APPROACH / LOCAL_GOAL_STEP) as usize;
            (0..=n)
                .map(|k| self.route.at((g.s - k as f64 * LOCAL_GOAL_STEP).max(s)))
                .all(|p| clear_of(&p, obstacles, r0))
        };
        let steps = ((end - nominal) / LOCAL_GOAL_STEP).ceil() as usize;
        let back = ((pc.horizon_m - pc.horizon_min_m).max(0.0) / LOCAL_GOAL_STEP) as usize;
        let on = (0..=steps).map(|i| (nominal + i as f64 * LOCAL_GOAL_STEP).min(end));
        let nearer = (1..=back).map(|i| nominal - i as f64 * LOCAL_GOAL_STEP);
        on.chain(nearer.filter(|&g| g > s))
            .map(|g| self.route.local_goal(g))
            .find(clear)
            .unwrap_or_else(|| self.route.local_goal(nominal))
    }

    /// Local goals to try when the first has no feasible path (detours): the first
    /// local goal shifted sideways by 1.5, 3 and 4.5 m, and the route's point at half
    /// its distance, unshifted and shifted the same; each clear of every inflated
    /// static obstacle; at most `MAX_DETOURS`. The order is the stated cost, and the
    /// first with a feasible path wins: the least lateral shift, then the farther
    /// goal, then right before left.
    pub fn detours(&self, s: f64, first: &RoutePoint, obstacles: &[Circle]) -> Vec<RoutePoint> {
        let r0 = self.cfg.vehicle.radius + self.cfg.planner.safety_margin;
        let half = self.route.at(s + (first.s - s) / 2.0);
        let mut tries: Vec<(f64, RoutePoint)> = Vec::new();
        for (i, base) in [*first, half].into_iter().enumerate() {
            if base.s - s < self.cfg.planner.horizon_min_m / 2.0 {
                continue;
            }
            let (nx, ny) = (-base.heading.sin(), base.heading.cos());
            for shift in DETOUR_SHIFTS {
                if i == 0 && shift == 0.0 {
                    continue;
                }
                let g = RoutePoint {
                    x: base.x + shift * nx,
                    y: base.y + shift * ny,
                    ..base
                };
                if clear_of(&g, obstacles, r0) {
                    tries.push((shift, g));
                }
            }
        }
        // Stable: right before left stays from DETOUR_SHIFTS.
        tries.sort_by(|a, b| {
            a.0.abs()
                .total_cmp(&b.0.abs())
                .then(b.1.s.total_cmp(&a.1.s))
        });
        tries.into_iter().take(MAX_DETOURS).map(|t| t.1).collect()
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
        let goal = (self.cfg.mission.goal_x, self.cfg.mission.goal_y);
        let to_goal = (pose.x - goal.0).hypot(pose.y - goal.1);
        if to_goal <= self.cfg.mission.goal_tolerance {
            return Guidance::Arrived;
        }
        self.progress = self.progress_at(pose);
        let (px, py) = self.frame.to_path(pose.x, pose.y);
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

/// One replanning to do: the problem in the planning frame and the steering limit.
#[derive(Clone, Debug)]
pub struct PlanRequest {
    pub time: f64,
    pub problem: PlanProblem,
    /// Road-wheel angle a planned path may use, radians.
    pub steer_limit: f64,
    frame: PathFrame,
    /// Problems towards other local goals (with their frames), tried in order when
    /// `problem` has no feasible path.
    pub detours: Vec<(PlanProblem, PathFrame)>,
    /// Set when moving obstacles are in view: the paces to try.
    pub pacing: Option<Pacing>,
    /// Set when the car heads too far from the line: turn towards the goal first.
    pub align: Option<Align>,
}

/// A car's nearest thing to turning on the spot: full planned lock at low speed, until
/// the heading is within reach of a y(x) path. Taken only when the whole turning
/// circle (grown by the planner's vehicle radius) is clear of every obstacle.
#[derive(Clone, Debug, PartialEq)]
pub struct Align {
    /// The rear axle's pose, world frame.
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Turning left is the short way round.
    pub prefer_left: bool,
    /// Turning radius of the rear axle at the planned steering limit, metres.
    pub turn_radius: f64,
    /// Obstacles in the world frame.
    pub obstacles: Vec<Circle>,
}

impl Align {
    /// Whether the full turning circle to the left (or right) is clear: every obstacle
    /// is farther than its radius plus `r0` from the circle the rear axle drives.
    pub fn clear(&self, left: bool, r0: f64) -> bool {
        let s = if left { 1.0 } else { -1.0 };
        let r = self.turn_radius;
        let (cx, cy) = (
            self.x - s * r * self.theta.sin(),
            self.y + s * r * self.theta.cos(),
        );
        self.obstacles
            .iter()
            .all(|o| ((o.x - cx).hypot(o.y - cy) - r).abs() > o.radius + r0)
    }

    /// The road-wheel angle to turn with (the short way if clear, else the long way),
    /// or None when neither turning circle is clear.
    pub fn steer(&self, r0: f64, steer_limit: f64) -> Option<f64> {
        [self.prefer_left, !self.prefer_left]
            .into_iter()
            .find(|left| self.clear(*left, r0))
            .map(|left| if left { steer_limit } else { -steer_limit })
    }
}

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
}

impl Pacing {
    /// The score of a feasible path at `pace` (lower is better): its mean squared
    /// deviation from the start-goal line (J / span, m^2) plus `time_weight` times the
    /// time per metre lost against the fastest pace. Yielding by slowing down beats a
    /// wide swerve at full pace.
    pub fn score(&self, mean_sq_deviation: f64, pace: f64, fastest: f64) -> f64 {
        mean_sq_deviation + self.time_weight * (1.0 / pace - 1.0 / fastest)
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

/// The radius to plan a static obstacle with: its own, or less where the car at
/// (px, py) is already within the inflated radius r0 (plus a slack).
fn clip_to_start(radius: f64, x: f64, y: f64, px: f64, py: f64, r0: f64) -> f64 {
    let gap = (px - x).hypot(py - y) - r0 - MARGIN_SLACK;
    radius.min(gap.max(0.0))
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

/// A finished replanning: the path (None when no feasible path exists) and its
/// record, or why the planner refused the problem.
#[derive(Clone, Debug)]
pub struct PlanOutcome {
    pub time: f64,
    /// The frame it was planned in.
    pub frame: PathFrame,
    pub result: Result<(Option<Trajectory>, PlanRecord), String>,
}

/// Solve a replanning (pure: runs inline or on a planning thread). Among the feasible
/// a6 it takes the cheapest whose path stays within the steering limit, since the
/// method itself has none.
///
/// With moving obstacles in view ([`PlanRequest::pacing`]) the pace is a second free
/// parameter: each pace sets t_f, every moving obstacle is swept over the time margin
/// plus the schedule slip of that pace ([`sweep`], [`Pacing::schedule_slip`]), and the
/// fastest pace with a feasible path is taken. The Qu et al. constraint is then a
/// space-time one: the obstacle's predicted position at the instant the car is at each
/// x. With no pace feasible the car stops (it yields).
///
/// The local goal's problem is solved first; when it has no feasible path, the
/// detours' problems in their order ([`PlanRequest::detours`]), and the first with
/// one is taken, in its own frame ([`PlanOutcome::frame`]).
pub fn solve(req: &PlanRequest) -> PlanOutcome {
    if let Some(align) = &req.align {
        let (_, mut record) = record(req.time, &req.frame, None, false);
        record.align = align.steer(req.problem.vehicle_radius, req.steer_limit);
        record.feasible = record.align.is_some();
        return PlanOutcome {
            time: req.time,
            frame: req.frame,
            result: Ok((None, record)),
        };
    }
    // The local goal, then the detours in order: the first with a feasible path.
    let mut nominal = None;
    let tries =
        std::iter::once((&req.problem, req.frame)).chain(req.detours.iter().map(|(p, f)| (p, *f)));
    for (problem, frame) in tries {
        let result = solve_towards(req, problem, &frame);
        let outcome = PlanOutcome {
            time: req.time,
            frame,
            result,
        };
        match &outcome.result {
            Ok((None, _)) => {
                nominal.get_or_insert(outcome);
            }
            _ => return outcome,
        }
    }
    nominal.unwrap_or(PlanOutcome {
        time: req.time,
        frame: req.frame,
        result: Err("no planning problem".to_owned()),
    })
}

/// One local goal's planning problem solved (see [`solve`]).
fn solve_towards(
    req: &PlanRequest,
    p: &PlanProblem,
    frame: &PathFrame,
) -> Result<(Option<Trajectory>, PlanRecord), String> {
    let Some(pacing) = &req.pacing else {
        let chosen = solve_one(p, req.steer_limit)?;
        return Ok(record(req.time, frame, chosen, false));
    };
    let span = p.goal.x - p.state.x;
    let line = p.reference_line().map_err(|e| e.to_string())?;
    let fastest = pacing.speeds.iter().copied().fold(0.0, f64::max);
    let mut best: Option<(f64, Chosen)> = None;
    for &pace in &pacing.speeds {
        let margin = pacing.time_margin + pacing.schedule_slip(pace);
        let mut problem = p.clone();
        problem.t_f = p.t_k + span / pace;
        problem.obstacles = p
            .obstacles
            .iter()
            .flat_map(|o| {
                if o.vx == 0.0 && o.vy == 0.0 {
                    vec![*o]
                } else {
                    sweep(o, margin, p.state.x, p.state.y, p.vehicle_radius)
                }
            })
            .collect();
        if let Some(c) = solve_one(&problem, req.steer_limit)? {
            let score = pacing.score(
                c.trajectory.path().reference_cost(&line) / span.abs(),
                pace,
                fastest,
            );
            if best.as_ref().is_none_or(|b| score < b.0) {
                best = Some((score, c));
            }
        }
    }
    Ok(record(req.time, frame, best.map(|b| b.1), true))
}

/// The chosen path of one planning problem: the planner's a6 when its path is within
/// the steering limit, else the cheapest feasible a6 whose path is; None when none.
fn solve_one(problem: &PlanProblem, steer_limit: f64) -> Result<Option<Chosen>, String> {
    let step = planner::plan_with(problem, &PlanOptions::default()).map_err(|e| e.to_string())?;
    let projected = step.result.projected_to_boundary;
    let within = !step
        .result
        .max_abs_steering
        .is_some_and(|s| s > steer_limit);
    if within {
        return Ok(step
            .trajectory
            .zip(step.result.a6_chosen)
            .map(|(trajectory, a6)| Chosen {
                trajectory,
                a6,
                projected,
            }));
    }
    let line =
        planner::ReferenceLine::new(0.0, 0.0, problem.goal.x, 0.0).map_err(|e| e.to_string())?;
    let mut best: Option<(f64, f64, Trajectory)> = None;
    for candidate in candidates(step.result.a6_unconstrained, &step.result.feasible_set) {
        let Ok(t) = problem.trajectory(candidate) else {
            continue;
        };
        if max_steer(&t) > steer_limit {
            continue;
        }
        let cost = t.path().reference_cost(&line);
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, candidate, t));
        }
    }
    Ok(best.map(|(_, a6, trajectory)| Chosen {
        trajectory,
        a6,
        projected,
    }))
}

/// A feasible path of one planning problem.
struct Chosen {
    trajectory: Trajectory,
    a6: f64,
    projected: bool,
}

fn record(
    time: f64,
    frame: &PathFrame,
    chosen: Option<Chosen>,
    moving: bool,
) -> (Option<Trajectory>, PlanRecord) {
    let record = PlanRecord {
        time,
        feasible: chosen.is_some(),
        a6: chosen.as_ref().map(|c| c.a6),
        projected_to_boundary: chosen.as_ref().is_some_and(|c| c.projected),
        max_steer_deg: chosen
            .as_ref()
            .map(|c| max_steer(&c.trajectory).to_degrees()),
        path: chosen.as_ref().map_or_else(Vec::new, |c| {
            let p = c.trajectory.path();
            (0..=40)
                .map(|j| {
                    let x = p.x_k() + p.span() * f64::from(j) / 40.0;
                    let (wx, wy) = frame.to_world(x, p.y(x));
                    [wx, wy]
                })
                .collect()
        }),
        pace: chosen.as_ref().map(|c| c.trajectory.w1()),
        moving,
        align: None,
    };
    (chosen.map(|c| c.trajectory), record)
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
        let pacing = Pacing {
            speeds: vec![2.0, 1.0],
            speed_now: 2.0,
            accel: 1.0,
            decel: 1.0,
            time_margin: 1.0,
            time_weight: 2.0,
        };
        assert_eq!(pacing.schedule_slip(2.0), 0.0);
        // Slowing from 2 to 1 m/s at 1 m/s^2 takes 1 s and 1.5 m instead of 1 m.
        assert!((pacing.schedule_slip(1.0) - 0.5).abs() < 1e-12);
        // A straight path at half pace beats a 1.5 m swerve at full pace, not a 0.5 m one.
        assert!(pacing.score(0.0, 1.0, 2.0) < pacing.score(1.5, 2.0, 2.0));
        assert!(pacing.score(0.0, 1.0, 2.0) > pacing.score(0.5, 2.0, 2.0));
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
