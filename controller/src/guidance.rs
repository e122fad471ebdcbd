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
//!   Arrival and "passed the goal" go by the progress along the whole route, not by
//!   one leg: the goal's tolerance counts only with the progress on the last leg (or
//!   that near the route's end), and the goal is passed only at the route's end, so a
//!   route whose goal lies near or behind its start (a lap, a switchback) is driven.
//! - Detours: when the local goal has no feasible path, other local goals (shifted
//!   sideways, or at half the distance; [`Navigator::detours`]) are planned in the
//!   order of their stated cost, each its own Qu et al. polynomial, and the first
//!   feasible one is taken ([`solve`]).
//!
//! - The real footprint: when neither the local goal nor a detour has a path with the
//!   planning circle, the same local goals are planned with half the car's width plus
//!   `passage_margin` as the circle, each candidate checked with the car's rectangle
//!   grown by that margin ([`Footprint`]), and a path through such a passage is driven
//!   at `passage_speed`. An obstacle on the mission's goal makes the stop short of it
//!   say so, and is no dead end to back out of.
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
//! - Traffic: behind an obstacle going the car's way the pace follows the gap
//!   ([`pacing::traffic`]); when traffic slows the local goal's path, or it swerves
//!   past oncoming traffic on the side not kept to, the detours are weighed against
//!   it (deviation, dearer on that side, plus time lost), so the car gives way
//!   sideways before it slows or stops. A leader keeping to its line, with a horizon
//!   of route left, is passed on the side not kept to: local goals on a lane clear of
//!   it, at every pace, are taken first ([`pacing::pass_lane`], `solver::pass_by`).
//! - Headings the polynomial cannot start from: beyond `align_enter_deg` from the
//!   line, the car first turns towards the goal on the planned steering limit at low
//!   speed, when the whole turning circle is clear ([`Align`]), until within
//!   `align_exit_deg`.
//! - Recovery from dead ends: standing still (below [`STANDING`]) with no feasible
//!   path for `recover_after_s` (a dead end, an obstacle too close ahead to swerve
//!   round, both turning circles blocked), the car backs `reverse_distance_m` at
//!   `reverse_speed` in gear R ([`Guidance::Reverse`]) along a straight or gently
//!   curved arc checked against the obstacles perception reports ([`Reverse`]; the
//!   laser looks forward, so the way is kept short and slow), stopping early when the
//!   rest of it is no longer clear, then replans. At most `max_reversals` times until
//!   the car has made `reversal_reset_m` of progress past the place of the last one;
//!   then, or with no clear way back, a controlled stop whose reason says so ("no
//!   forward path after 2 reversals").
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
//! `align` (turning towards the goal first), `reverse` (backing out of a dead end),
//! `footprint` (the car's rectangle), `solver` (solving a replanning),
//! `follower` (the steering laws) and `error`; this file keeps the navigator, which
//! builds the requests, takes the outcomes and follows the path.

mod align;
mod error;
pub(crate) mod follower;
mod footprint;
mod frame;
mod lanes;
pub mod manoeuvre;
mod pacing;
mod reuse;
mod reverse;
mod search;
mod solver;
#[cfg(test)]
mod traffic_tests;

pub use align::Align;
pub use error::{GuidanceError, ReplanError};
pub use follower::{FollowInputs, SteeringLaw};
pub use footprint::Footprint;
pub use frame::PathFrame;
pub use pacing::{Pacing, sweep};
pub use reuse::Reuse;
pub use reverse::Reverse;
pub use solver::{ManoeuvreRecord, Pass, PlanOutcome, PlanRecord, PlanRequest, solve};

use crate::config::ControllerConfig;
use crate::localisation::Pose;
use crate::planner::{self, PlanProblem, Trajectory};
use crate::route::{Route, RoutePoint};
use frame::{clear_at, clip_to_start, wrap};
use search::{Clearance, MAX_GOAL_HEADING, MAX_LOCAL_HEADING};

/// What guidance asks of the actuators.
#[derive(Clone, Debug, PartialEq)]
pub enum Guidance {
    Drive {
        /// Road-wheel angle, radians.
        steer: f64,
        /// Speed, m/s.
        speed: f64,
        /// The distance the car must be able to stop within (the goal, or the path's
        /// end: where the next replanning may find no way on), metres; infinite when
        /// no stop lies ahead.
        room: f64,
        /// The deceleration the brake is asked to add, m/s^2 (a manoeuvre's cusp).
        brake: f64,
        inputs: FollowInputs,
    },
    /// Back out of a dead end in gear R ([`Reverse`]), or a manoeuvre's backward
    /// segment.
    Reverse {
        /// Road-wheel angle, radians.
        steer: f64,
        /// Speed backwards (a magnitude), m/s; 0 while braking at the end.
        speed: f64,
        /// The deceleration the brake is asked to add, m/s^2.
        brake: f64,
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
/// Progress this near the route's length is at its end (past the goal), metres.
const ROUTE_END: f64 = 1e-9;
/// The car arrives this far inside the goal's tolerance (metres; at most half of it),
/// short of the route's end: it judges arrival by its estimate of the pose, which RTK
/// puts a few millimetres to centimetres off the true one, and a car stopped on the
/// tolerance's edge by its estimate may stand a hair outside it (barn-211: 0.8 mm out,
/// judged not arrived).
const ARRIVAL_MARGIN: f64 = 0.05;
/// Below this speed the car stands (for recovery, and at the end of a reversal), m/s.
pub const STANDING: f64 = 0.05;
/// A path being followed is kept past a replanning that finds none only with the car
/// this near it sideways (metres) and in heading (radians), and this much of it left
/// (metres), unless it ends at the goal: a path whose end is near is driven to its end
/// and stopped at, so that recovery can begin ([`Navigator::recover`]). A path ends at
/// the goal when its end lies within [`KEEP_AT_GOAL`] of it, metres.
const KEEP_OFF_PATH: f64 = 0.3;
const KEEP_HEADING: f64 = 0.2;
const KEEP_LEFT: f64 = 3.0;
const KEEP_AT_GOAL: f64 = 0.1;
/// Step along a kept path at which it is checked against the obstacles, metres.
const KEEP_CHECK_STEP: f64 = 0.25;
/// Giving way to oncoming traffic ([`Navigator::yields`]): the car is at its stand
/// within this of the farthest a stand could lie aside (the stands keep up to 0.45 m
/// short of it: `search::YIELD_SLACKS`), metres; the stand lies at least this much
/// beyond where the car can stop, metres, and this many metres along the route per
/// metre aside.
const YIELD_THERE: f64 = 0.6;
const YIELD_MIN_RUN: f64 = 1.0;
const YIELD_RUN_PER_M: f64 = 6.0;

/// Seen space is marked from a scan at most this often while the car stands
/// (seconds), and whenever it has moved this far (metres) or turned this much
/// (radians).
const SEEN_PERIOD: f64 = 1.0;
const SEEN_MOVE: f64 = 1.0;
const SEEN_TURN: f64 = 0.05;
/// Step along a reversal at which its poses are checked against the seen space,
/// metres.
const SEEN_CHECK_STEP: f64 = 0.2;
/// After a manoeuvre search that found nothing, none for this long at first, seconds.
const MANOEUVRE_RETRY_S: f64 = 2.0;

/// What the next manoeuvre search may take, and when: each search that finds nothing
/// gives the next [`SearchEffort::GROWTH`] times its effort (`manoeuvre_expansions`),
/// up to [`SearchEffort::MAX`] times the first, after a wait that grows alike from
/// [`MANOEUVRE_RETRY_S`] (2, 8, then 32 s); one that finds a manoeuvre sets both back.
/// A car standing before a tight place searches the same map again, deeper each time,
/// instead of giving up where the first budget ran out, and a car that stands for good
/// does not search its unchanged map in full every 2 s. A bound in expansions, not
/// time: SIL stays deterministic.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct SearchEffort {
    /// Searches that found nothing since the last that found a manoeuvre.
    failures: u32,
}

impl SearchEffort {
    const FIRST: SearchEffort = SearchEffort { failures: 0 };
    const GROWTH: u32 = 4;
    const MAX: u32 = 16;

    /// The effort after a search that `failed` (found nothing) or `found` a manoeuvre.
    fn after(self, failed: bool, found: bool) -> SearchEffort {
        if failed {
            SearchEffort {
                failures: self.failures + 1,
            }
        } else if found {
            Self::FIRST
        } else {
            self
        }
    }

    /// `GROWTH` to the power `n`, at most `MAX`.
    fn grown(n: u32) -> u32 {
        Self::GROWTH.saturating_pow(n).min(Self::MAX)
    }

    /// How long after a search that found nothing the next may start, seconds.
    fn retry_wait(self) -> f64 {
        MANOEUVRE_RETRY_S * f64::from(Self::grown(self.failures.saturating_sub(1)))
    }

    /// The expansions of a search with a first budget of `base`.
    fn expansions(self, base: u32) -> usize {
        base as usize * Self::grown(self.failures) as usize
    }
}
/// No manoeuvre is searched with a moving obstacle this near the car, metres.
const MANOEUVRE_TRAFFIC_RANGE: f64 = 12.0;
/// A manoeuvre aims this far along the route ahead (the first within reach of the
/// route's end: the goal), metres, at these offsets sideways (left positive), metres,
/// each goal within this of it and of the route's heading (metres, radians).
const MANOEUVRE_AHEAD: [f64; 4] = [8.0, 11.0, 5.0, 14.0];
const MANOEUVRE_OFFSETS: [f64; 5] = [0.0, 1.0, -1.0, 2.0, -2.0];
const MANOEUVRE_GOAL_XY: f64 = 0.5;
const MANOEUVRE_GOAL_HEADING: f64 = 0.35;

/// The way back, as the last try at recovery found it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum WayBack {
    Open,
    /// Obstacles on every reversal.
    Blocked,
    /// A reversal clear of the obstacles, into space the laser has not seen.
    Unseen,
}

/// Replanning and following.
#[derive(Debug)]
pub struct Navigator {
    cfg: ControllerConfig,
    route: Route,
    /// The car's progress along the route (arc length), metres.
    progress: f64,
    /// The frame of the active plan (or of the alignment turn).
    frame: PathFrame,
    law: SteeringLaw,
    active: Option<Trajectory>,
    /// The active path was planned around moving obstacles: drive its pace.
    paced: bool,
    /// The active path goes through a passage narrower than the planning circle:
    /// drive it at the passage speed.
    passage: bool,
    /// That passage is narrow ahead of the car's nose ([`PlanRecord::narrow_ahead`]):
    /// slow to the passage speed at once, not eased into.
    narrow_ahead: bool,
    /// The last replanning found an obstacle on the mission's goal.
    goal_blocked: bool,
    /// Turning towards the goal on this road-wheel angle before planning, radians.
    aligning: Option<f64>,
    next_replan: f64,
    infeasible_since: Option<f64>,
    /// Why the last replanning was refused, if it was.
    planner_error: Option<ReplanError>,
    /// Backing out of a dead end.
    reversing: Option<Reverse>,
    /// Reversals begun this mission.
    reversals: u32,
    /// Reversals begun since the car last made `reversal_reset_m` of progress past
    /// the place of the last one (those `max_reversals` bounds).
    recent_reversals: u32,
    /// Route progress where the last reversal began, metres.
    reversed_at: f64,
    /// What the last try at recovery found behind the car.
    no_way_back: WayBack,
    /// Replannings taken ([`Navigator::accept`]), dropped ones included.
    accepted: u64,
    /// The manoeuvre being followed (the polynomial had no path).
    manoeuvre: Option<manoeuvre::Following>,
    /// New manoeuvres taken since the car last made `manoeuvre_progress_m` of progress
    /// past `manoeuvre_best` (the most progress since then); past `max_manoeuvres`, no
    /// more are taken.
    manoeuvres: u32,
    manoeuvre_best: f64,
    /// When a manoeuvre search last found nothing: none is searched again for
    /// [`SearchEffort::retry_wait`] (a car standing in a dead end would search at every
    /// replanning).
    search_failed_at: Option<f64>,
    /// What the next manoeuvre search may take.
    search_effort: SearchEffort,
    /// Space the laser has seen free, or the car stood in: manoeuvres back only into it.
    seen: crate::perception::SeenSpace,
    /// When and from where `seen` was last marked.
    seen_at: Option<(f64, [f64; 3])>,
    pub plans: Vec<PlanRecord>,
}

/// Where a replanning starts: its time, the car's pose and the obstacles reported, and
/// the car's progress along the route with the route's point there.
#[derive(Debug)]
struct Replanning<'a> {
    now: f64,
    pose: &'a Pose,
    obstacles: &'a [planner::Obstacle],
    s: f64,
    here: RoutePoint,
}

impl Navigator {
    pub fn new(cfg: &ControllerConfig) -> Result<Navigator, GuidanceError> {
        let law = SteeringLaw::from_config(cfg)?;
        let route = Route::new(&cfg.mission);
        let points = route.points();
        Ok(Navigator {
            cfg: cfg.clone(),
            frame: PathFrame::new(points[0], points[1]),
            route,
            progress: 0.0,
            law,
            active: None,
            paced: false,
            passage: false,
            narrow_ahead: false,
            goal_blocked: false,
            aligning: None,
            next_replan: 0.0,
            infeasible_since: None,
            planner_error: None,
            reversing: None,
            reversals: 0,
            recent_reversals: 0,
            reversed_at: 0.0,
            no_way_back: WayBack::Open,
            accepted: 0,
            manoeuvre: None,
            manoeuvres: 0,
            manoeuvre_best: 0.0,
            search_failed_at: None,
            search_effort: SearchEffort::FIRST,
            seen: crate::perception::SeenSpace::default(),
            seen_at: None,
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
    pub fn local_goal(&self, s: f64, obstacles: &[planner::Obstacle]) -> RoutePoint {
        search::local_goal(&self.route, &self.cfg.planner, &self.wide(), s, obstacles)
    }

    /// Local goals to try when the first has no feasible path (detours): the first
    /// local goal shifted sideways by 1.5, 3 and 4.5 m, and the route's point at half
    /// its distance, unshifted and shifted the same; each clear of every inflated
    /// static obstacle; at most `MAX_DETOURS`. The order is the stated cost, and the
    /// first with a feasible path wins: the least lateral shift, then the farther goal,
    /// then right before left.
    pub fn detours(
        &self,
        s: f64,
        first: &RoutePoint,
        obstacles: &[planner::Obstacle],
    ) -> Vec<RoutePoint> {
        search::detours(
            &self.route,
            &self.cfg.planner,
            &self.wide(),
            s,
            first,
            obstacles,
        )
    }

    /// What paths are planned with first: the car's circle plus the safety margin.
    fn wide(&self) -> Clearance {
        Clearance::circle(self.cfg.vehicle.radius + self.cfg.planner.safety_margin)
    }

    /// The car's rectangle grown by the passage margin.
    pub fn footprint(&self) -> Footprint {
        Footprint::of(&self.cfg.vehicle, self.cfg.planner.passage_margin)
    }

    /// What paths through passages are planned with: the car's half width plus the
    /// passage margin as the circle, and the rectangle at the local goal.
    fn narrow(&self) -> Clearance {
        let footprint = self.footprint();
        Clearance {
            r0: footprint.half_width + footprint.margin,
            footprint: Some(footprint),
        }
    }

    /// The planning problem towards `goal` from `pose` at `now`, in the frame from the
    /// car's place on the route (`here`) to the goal, with `r0` as the car's circle
    /// (margin included); and whether an obstacle moves.
    fn problem(
        &self,
        now: f64,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
        here: &RoutePoint,
        goal: &RoutePoint,
        r0: f64,
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
                        // Moving: swept and clipped per pace in `solve`, with the
                        // planning circle's clearance in every tier (Pacing::circle).
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
    /// goal, with the detours to try if it has no feasible path, and the same through
    /// passages narrower than the planning circle.
    pub fn request(&self, now: f64, pose: &Pose, obstacles: &[planner::Obstacle]) -> PlanRequest {
        let s = self.progress_at(pose);
        let at = Replanning {
            now,
            pose,
            obstacles,
            s,
            here: self.route.at(s),
        };
        let pc = &self.cfg.planner;
        let wide = self.wide();
        let goal = search::local_goal(&self.route, pc, &wide, s, obstacles);
        let (problem, frame, any_moving) =
            self.problem(now, pose, obstacles, &at.here, &goal, wide.r0);
        let detours = self.problems(
            &at,
            &search::detours(&self.route, pc, &wide, s, &goal, obstacles),
            wide.r0,
        );
        let narrow = self.narrow();
        let passages = self.passages(&at, &narrow);
        let end = self.route.local_goal(self.route.length());
        let goal_blocked = !search::clear_of(&end, obstacles, narrow.r0);
        let theta = wrap(pose.theta - frame.angle);
        let limit = (self.cfg.vehicle.max_steer_deg * pc.steer_usage).to_radians();
        let (leader, oncoming) = match any_moving {
            true => self.traffic(&problem, pose, wide.r0),
            false => (None, false),
        };
        let pass = self.pass(&at, &problem, &goal, &wide, leader);
        let pacing =
            any_moving.then(|| self.pacing(&at, leader.map(|l| l.pace), oncoming, wide.r0));
        let align = self.align(pose, obstacles, theta, limit);
        let yields = self.yields(now, pose, obstacles, s, &problem);
        let manoeuvre = self.manoeuvre_request(now, pose, obstacles, s, align.is_some());
        PlanRequest {
            time: now,
            problem,
            steer_limit: limit,
            frame,
            detours,
            sight: self.cfg.perception.detection_radius,
            passages,
            footprint: self.footprint(),
            goal_blocked,
            pacing,
            pass,
            align,
            current_holds: self.current_path_holds(pose, obstacles),
            yields,
            manoeuvre,
            hand_back: self
                .manoeuvre
                .as_ref()
                .is_some_and(manoeuvre::Following::may_hand_back),
            standing: reuse::Standing::new(pose, obstacles),
        }
    }

    /// The planning problems towards each of `goals` from where the replanning `at`
    /// starts, with `r0` as the car's circle.
    fn problems(
        &self,
        at: &Replanning<'_>,
        goals: &[RoutePoint],
        r0: f64,
    ) -> Vec<(PlanProblem, PathFrame)> {
        goals
            .iter()
            .map(|g| {
                let (p, f, _) = self.problem(at.now, at.pose, at.obstacles, &at.here, g, r0);
                (p, f)
            })
            .collect()
    }

    /// The problems through passages narrower than the planning circle: towards the
    /// local goal the `narrow` clearance allows, then towards its detours.
    fn passages(&self, at: &Replanning<'_>, narrow: &Clearance) -> Vec<(PlanProblem, PathFrame)> {
        let pc = &self.cfg.planner;
        let through = search::local_goal(&self.route, pc, narrow, at.s, at.obstacles);
        let mut goals = vec![through];
        goals.extend(search::detours(
            &self.route,
            pc,
            narrow,
            at.s,
            &through,
            at.obstacles,
        ));
        self.problems(at, &goals, narrow.r0)
    }

    /// The fixed paces to try, fastest first: the planner's fractions of the cruise
    /// speed below `cap`, and `cap` itself when finite.
    fn paces(&self, cap: f64) -> Vec<f64> {
        let pc = &self.cfg.planner;
        let mut speeds: Vec<f64> = pc
            .pace_fractions
            .iter()
            .map(|f| f * pc.cruise_speed)
            .filter(|&v| v < cap)
            .chain(cap.is_finite().then_some(cap))
            .collect();
        speeds.sort_by(|a, b| b.total_cmp(a));
        speeds
    }

    /// The pass of a `leader` keeping to its line: on the side not kept to, on a lane
    /// clear of it beside the local goal's `problem` (`goal`, the `wide` clearance),
    /// while the route has at least a horizon left to pass it in.
    fn pass(
        &self,
        at: &Replanning<'_>,
        problem: &PlanProblem,
        goal: &RoutePoint,
        wide: &Clearance,
        leader: Option<pacing::Leader>,
    ) -> Option<Pass> {
        let pc = &self.cfg.planner;
        (leader.is_some_and(|l| l.along_line) && self.route.length() - at.s >= pc.horizon_m).then(
            || {
                let side = if pc.keep_right { 1.0 } else { -1.0 };
                let lane = pacing::pass_lane(
                    &problem.obstacles,
                    problem.state.x,
                    problem.state.y,
                    wide.r0,
                    side,
                );
                Pass {
                    goals: self.problems(
                        at,
                        &search::pass_goals(&self.route, wide, at.s, goal, lane, at.obstacles),
                        wide.r0,
                    ),
                    speeds: self.paces(f64::INFINITY),
                }
            },
        )
    }

    /// How to pace among moving obstacles, the car's circle `r0`. Behind traffic going
    /// its way (at pace `follow`), the car paces itself on the gap: no fixed pace faster
    /// than that is tried (passing it is a detour's business, and the pass's).
    fn pacing(&self, at: &Replanning<'_>, follow: Option<f64>, oncoming: bool, r0: f64) -> Pacing {
        let pc = &self.cfg.planner;
        let slowest = pc.pace_fractions.iter().copied().fold(1.0, f64::min) * pc.cruise_speed;
        let cap = follow.map_or(f64::INFINITY, |v| v.clamp(slowest, pc.cruise_speed));
        let speeds = self.paces(cap);
        Pacing {
            speeds,
            speed_now: at.pose.v.max(0.0),
            accel: self.cfg.follower.accel_limit,
            decel: self.cfg.follower.decel,
            time_margin: pc.moving_time_margin_s,
            time_weight: pc.pace_time_weight,
            time_scale: follow.map_or(1.0, |_| {
                ((self.route.length() - at.s) / pc.horizon_m).max(1.0)
            }),
            oncoming,
            keep_right: pc.keep_right,
            circle: r0,
        }
    }

    /// The turn towards the line of a car at `pose` heading `theta` off it (more than
    /// the align threshold; none otherwise), at the steering `limit`.
    fn align(
        &self,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
        theta: f64,
        limit: f64,
    ) -> Option<Align> {
        let pc = &self.cfg.planner;
        let threshold = if self.aligning.is_some() {
            pc.align_exit_deg
        } else {
            pc.align_enter_deg
        };
        (theta.abs() > threshold.to_radians()).then(|| Align {
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            // Turn the short way round first.
            prefer_left: theta < 0.0,
            turn_radius: self.cfg.vehicle.wheelbase / limit.tan(),
            obstacles: obstacles.to_vec(),
        })
    }

    /// The manoeuvre search from `pose` at progress `s` at `now` ([`manoeuvre`]), or
    /// the check of the manoeuvre being followed; none with a moving obstacle within
    /// [`MANOEUVRE_TRAFFIC_RANGE`] of the car (traffic is given way to, not
    /// manoeuvred round), nor within [`SearchEffort::retry_wait`] of a search that
    /// found nothing, nor once `max_manoeuvres` are spent without progress.
    fn manoeuvre_request(
        &self,
        now: f64,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
        s: f64,
        turning: bool,
    ) -> Option<manoeuvre::ManoeuvreRequest> {
        let traffic = obstacles.iter().any(|o| {
            (o.vx != 0.0 || o.vy != 0.0)
                && (o.x - pose.x).hypot(o.y - pose.y) < MANOEUVRE_TRAFFIC_RANGE
        });
        // Built only when one may be needed (a manoeuvre followed, the last replanning
        // without a path, the car heading too far from the line: `turning`): the request
        // is made on the command loop, and copying the seen space costs (a dead end
        // found while driving waits one replanning).
        let needed = self.manoeuvre.is_some() || self.infeasible_since.is_some() || turning;
        let resting = !needed
            || self.manoeuvre.is_none()
                && (self.manoeuvres_spent()
                    || self
                        .search_failed_at
                        .is_some_and(|t| now - t < self.search_effort.retry_wait()));
        if traffic || resting {
            return None;
        }
        let pc = &self.cfg.planner;
        let v = &self.cfg.vehicle;
        let limit = (v.max_steer_deg * pc.manoeuvre_steer_usage).to_radians();
        let footprint = Footprint {
            margin: pc.manoeuvre_margin,
            ..self.footprint()
        };
        Some(
            manoeuvre::ManoeuvreRequest {
                start: [pose.x, pose.y, pose.theta],
                goals: self.manoeuvre_goals(s, &footprint, obstacles),
                obstacles: obstacles.to_vec(),
                footprint,
                settings: manoeuvre::Settings {
                    turn_radius: v.wheelbase / limit.tan(),
                    max_expansions: self.search_effort.expansions(pc.manoeuvre_expansions),
                    ..manoeuvre::Settings::default()
                },
                following: self.manoeuvre.as_ref().map(manoeuvre::Following::rest),
                standing: pose.v.abs() < STANDING,
                seen: None,
                remembered: Vec::new(),
                look_again: self
                    .manoeuvre
                    .as_ref()
                    .is_some_and(manoeuvre::Following::look_again),
                following_margin: self
                    .manoeuvre
                    .as_ref()
                    .and_then(manoeuvre::Following::escape_margin),
                escape_margin: pc.manoeuvre_escape_margin,
            }
            .with_seen(&self.seen),
        )
    }

    /// Where a manoeuvre from progress `s` aims: the goal once within reach (anywhere in
    /// its tolerance, any heading), else poses on the route ahead at the route's
    /// heading, a few distances and offsets sideways, those the car's rectangle clears
    /// among the obstacles in view (the search takes the first few that its map, with
    /// the remembered returns, clears too).
    fn manoeuvre_goals(
        &self,
        s: f64,
        footprint: &Footprint,
        obstacles: &[planner::Obstacle],
    ) -> Vec<manoeuvre::Goal> {
        let left = self.route.length() - s;
        let m = &self.cfg.mission;
        if left <= MANOEUVRE_AHEAD[0] {
            return vec![manoeuvre::Goal {
                pose: [
                    m.goal_x,
                    m.goal_y,
                    self.route.at(self.route.length()).heading,
                ],
                tol_xy: m.goal_tolerance * 0.8,
                tol_theta: std::f64::consts::PI,
            }];
        }
        let statics: Vec<planner::Obstacle> = obstacles.to_vec();
        let mut goals = Vec::new();
        for ahead in MANOEUVRE_AHEAD {
            for offset in MANOEUVRE_OFFSETS {
                let p = self.route.at((s + ahead).min(self.route.length()));
                let (c, sn) = (p.heading.cos(), p.heading.sin());
                let pose = [p.x - offset * sn, p.y + offset * c, p.heading];
                if footprint.clear_at(pose[0], pose[1], pose[2], &statics) {
                    goals.push(manoeuvre::Goal {
                        pose,
                        tol_xy: MANOEUVRE_GOAL_XY,
                        tol_theta: MANOEUVRE_GOAL_HEADING,
                    });
                }
            }
        }
        goals
    }

    /// What the moving obstacles of the local goal's `problem` do ([`pacing::traffic`],
    /// the car's circle `r0`): traffic overtaking the car is no leader to pace behind,
    /// it moves away ([`lanes::overtaking`]).
    fn traffic(
        &self,
        problem: &PlanProblem,
        pose: &Pose,
        r0: f64,
    ) -> (Option<pacing::Leader>, bool) {
        let f = self.footprint();
        let (reach, half) = (f.front + r0, f.half_width + f.margin);
        let ahead: Vec<planner::Obstacle> = problem
            .obstacles
            .iter()
            .filter(|o| !lanes::overtaking(o, &problem.state, pose.v, reach, half))
            .copied()
            .collect();
        pacing::traffic(&ahead, problem.state.x, problem.state.y, r0)
    }

    /// With oncoming traffic in view ([`lanes::oncoming`] in the local goal's
    /// `problem`), the problems towards stands to give way at (`search::yield_goals`):
    /// aside of the route to the side kept to as far as the car's rectangle allows,
    /// far enough ahead to stop at from the car's speed at `follower.decel` and to
    /// get there at a gentle angle; planned with the passages' circle. None once the
    /// car is within [`YIELD_THERE`] of the farthest stand's offset: it stands and
    /// waits.
    fn yields(
        &self,
        now: f64,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
        s: f64,
        problem: &PlanProblem,
    ) -> Vec<(PlanProblem, PathFrame)> {
        if !problem
            .obstacles
            .iter()
            .any(|o| lanes::oncoming(o, &problem.state))
        {
            return Vec::new();
        }
        let pc = &self.cfg.planner;
        let side = if pc.keep_right { -1.0 } else { 1.0 };
        let narrow = self.narrow();
        let v = pose.v.max(0.0);
        let stop = v * v / (2.0 * self.cfg.follower.decel.max(0.1))
            + self.cfg.vehicle.coast_m(v)
            + YIELD_MIN_RUN;
        let here = self.route.at(s);
        // The car's offset from the route, left positive.
        let offset =
            (pose.y - here.y) * here.heading.cos() - (pose.x - here.x) * here.heading.sin();
        let stands = |run: f64| search::yield_goals(&self.route, &narrow, s, run, side, obstacles);
        let Some((farthest, _)) = stands(stop) else {
            return Vec::new();
        };
        let aside = farthest - side * offset;
        if aside < YIELD_THERE {
            return Vec::new();
        }
        let run = stop.max(YIELD_RUN_PER_M * aside);
        let goals = stands(run).map_or_else(Vec::new, |(_, goals)| goals);
        goals
            .iter()
            .map(|goal| {
                let (p, f, _) = self.problem(now, pose, obstacles, &here, goal, narrow.r0);
                (p, f)
            })
            .collect()
    }

    /// Whether the path being followed may be kept when a replanning finds no feasible
    /// one: it was planned among static obstacles only, not while turning to align;
    /// the car is on it (within [`KEEP_OFF_PATH`] and [`KEEP_HEADING`]); at least
    /// [`KEEP_LEFT`] of it is left, or it ends at the goal (a polynomial over the last
    /// metres to the goal may need more steering than allowed where the one that leads
    /// there does not); and the rest of it clears every obstacle now
    /// reported as planned (none of them moving): by the planning circle, or through a
    /// passage by the car's rectangle grown by the passage margin, an obstacle the car
    /// already stands within the margin of allowed no closer. A car whose replanning
    /// needs a little more steering than allowed (a tracking error, a sensor bias), or
    /// finds the edge of a gate it is driving through a few centimetres inside the
    /// margin (GPS noise moves the world round the car), then drives on along a path
    /// that holds, where it would otherwise stop at once.
    fn current_path_holds(&self, pose: &Pose, obstacles: &[planner::Obstacle]) -> bool {
        let Some(t) = &self.active else {
            return false;
        };
        if self.paced
            || self.aligning.is_some()
            || obstacles.iter().any(|o| o.vx != 0.0 || o.vy != 0.0)
        {
            return false;
        }
        let path = t.path();
        let (px, py) = self.frame.to_path(pose.x, pose.y);
        let x = px.clamp(path.x_k(), path.x_f());
        let off = (py - path.y(x)).abs();
        let heading = wrap(pose.theta - self.frame.angle - path.heading(x)).abs();
        let left = path.x_f() - x;
        let short = left < KEEP_LEFT && {
            let (ex, ey) = self.frame.to_world(path.x_f(), path.y(path.x_f()));
            self.to_goal(ex, ey) > KEEP_AT_GOAL
        };
        if off > KEEP_OFF_PATH || heading > KEEP_HEADING || short {
            return false;
        }
        let n = (left / KEEP_CHECK_STEP).ceil() as usize;
        let mut rest = (0..=n).map(|j| {
            let qx = x + left * j as f64 / n as f64;
            let (wx, wy) = self.frame.to_world(qx, path.y(qx));
            (wx, wy, self.frame.angle + path.heading(qx))
        });
        if self.passage {
            let footprint = self.footprint();
            let statics: Vec<planner::Obstacle> = obstacles.to_vec();
            let clipped = footprint.clip_to_start(pose.x, pose.y, pose.theta, &statics);
            return rest.all(|(wx, wy, heading)| footprint.clear_at(wx, wy, heading, &clipped));
        }
        let r0 = self.wide().r0;
        rest.all(|(wx, wy, _)| clear_at(wx, wy, obstacles, (pose.x, pose.y), r0))
    }

    /// Whether a replanning is due at `now` from `pose` (not while reversing).
    pub fn replan_due(&self, now: f64, pose: &Pose) -> bool {
        now >= self.next_replan
            && self.reversing.is_none()
            && self.route.length() - self.progress_at(pose) > self.cfg.planner.final_approach
    }

    /// Guidance has what it needs to drive from `pose`: a replanning has finished (with
    /// a path or without), or none is needed (within the final approach).
    pub fn planned(&self, pose: &Pose) -> bool {
        // Every finished replanning leaves a record, or the planner's refusal.
        !self.plans.is_empty()
            || self.planner_error.is_some()
            || self.route.length() - self.progress_at(pose) <= self.cfg.planner.final_approach
    }

    /// A replanning was issued at `now`: the next is due one T_s later.
    /// How many replannings have been taken so far, dropped ones included.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }

    pub fn issued(&mut self, now: f64) {
        self.next_replan = now + self.cfg.planner.replan_period_s;
    }

    /// Take a finished replanning: its path is followed from now on. One that finishes
    /// while the car reverses (on a planning thread) was planned from where it stood,
    /// and is dropped.
    pub fn accept(&mut self, outcome: PlanOutcome) {
        self.accepted += 1;
        if self.reversing.is_some() {
            return;
        }
        match outcome.result {
            Ok((trajectory, mut record)) => {
                let plan = record.manoeuvre.as_mut().and_then(|m| m.plan.take());
                let failed = record.manoeuvre.as_ref().is_some_and(|m| m.failed);
                let complete = record.manoeuvre.as_ref().is_some_and(|m| m.complete);
                let escape = record.manoeuvre.as_ref().and_then(|m| m.escape_margin);
                let searched = record.manoeuvre.as_ref().is_some_and(|m| m.expansions > 0);
                // The manoeuvre being followed holds (a record without a new one).
                let holds = record.kept && plan.is_none() && record.manoeuvre.is_some() && !failed;
                if holds
                    && searched
                    && let Some(following) = self.manoeuvre.as_mut()
                {
                    // Searched again from where the car was: nothing complete yet.
                    following.looked();
                }
                if trajectory.is_some() || holds || plan.is_some() {
                    self.infeasible_since = None;
                } else {
                    self.infeasible_since.get_or_insert(outcome.time);
                }
                if failed {
                    self.search_failed_at = Some(outcome.time);
                }
                self.search_effort = self.search_effort.after(failed, plan.is_some());
                if !holds {
                    // A polynomial path, none, or a new manoeuvre: not the one followed.
                    self.manoeuvre = plan.and_then(|m| self.count_manoeuvre(m, complete, escape));
                }
                if !record.kept {
                    self.frame = outcome.frame;
                    self.active = trajectory;
                    self.paced = record.moving;
                    self.passage = record.passage;
                    self.narrow_ahead = record.narrow_ahead;
                    self.goal_blocked = record.goal_blocked;
                    self.aligning = record.align;
                }
                self.planner_error = None;
                self.plans.push(record);
            }
            Err(e) => {
                self.frame = outcome.frame;
                self.active = None;
                self.manoeuvre = None;
                self.aligning = None;
                self.planner_error = Some(e);
            }
        }
    }

    /// A new manoeuvre to follow, counted against `max_manoeuvres` since the last
    /// progress; None once they are spent.
    fn count_manoeuvre(
        &mut self,
        m: manoeuvre::Manoeuvre,
        complete: bool,
        escape: Option<f64>,
    ) -> Option<manoeuvre::Following> {
        let pc = &self.cfg.planner;
        if self.progress >= self.manoeuvre_best + pc.manoeuvre_progress_m {
            self.manoeuvres = 0;
            self.manoeuvre_best = self.progress;
        }
        if self.manoeuvres >= pc.max_manoeuvres {
            return None;
        }
        self.manoeuvres += 1;
        Some(manoeuvre::Following::new(m, complete).escaping(escape))
    }

    /// Whether the manoeuvres allowed without progress are spent.
    fn manoeuvres_spent(&self) -> bool {
        let pc = &self.cfg.planner;
        self.manoeuvres >= pc.max_manoeuvres
            && self.progress < self.manoeuvre_best + pc.manoeuvre_progress_m
    }

    /// Reversals begun this mission.
    pub fn reversals(&self) -> u32 {
        self.reversals
    }

    /// Recovery at `now` from `pose` among `obstacles` (every control tick, after
    /// planning): begin a reversal when the car has stood with no feasible path for
    /// `recover_after_s` and reversals are left; while reversing, brake once the
    /// distance is covered or the rest is no longer clear, and replan once standing.
    pub fn recover(&mut self, now: f64, pose: &Pose, obstacles: &[planner::Obstacle]) {
        let pc = &self.cfg.planner;
        let r0 = self.cfg.vehicle.radius + pc.safety_margin;
        if let Some(r) = &mut self.reversing {
            if !r.done {
                let rest = r.rest(pose.x, pose.y, pose.theta);
                r.done =
                    rest.distance <= self.cfg.vehicle.coast_m(pose.v) || !rest.clear(obstacles, r0);
            }
            if r.done && pose.v.abs() < STANDING {
                self.reversing = None;
                self.next_replan = now;
            }
            return;
        }
        if self.progress - self.reversed_at >= pc.reversal_reset_m {
            self.recent_reversals = 0;
        }
        // A blocked goal is no dead end: backing away from it leads nowhere nearer.
        let stuck = self.active.is_none()
            && self.manoeuvre.is_none()
            && !self.goal_blocked
            && self.aligning.is_none()
            && self.planner_error.is_none()
            && self
                .infeasible_since
                .is_some_and(|t| now - t >= pc.recover_after_s)
            && pose.v.abs() < STANDING;
        if !stuck || self.recent_reversals >= pc.max_reversals {
            return;
        }
        let limit = (self.cfg.vehicle.max_steer_deg * pc.steer_usage).to_radians();
        let s = self.progress_at(pose);
        let towards = self.local_goal(s, obstacles);
        let towards = (towards.y - pose.y).atan2(towards.x - pose.x);
        let speed = pc.reverse_speed.min(self.cfg.vehicle.max_speed);
        match Reverse::choose(
            (pose.x, pose.y, pose.theta),
            towards,
            pc.reverse_distance_m,
            self.cfg.vehicle.wheelbase,
            limit,
            obstacles,
            r0,
        ) {
            // Traffic behind the car or on its way: wait for it, never back into it.
            Some(r) if !r.clear_of_traffic(obstacles, r0, speed) => {}
            // Never back into space the laser has not seen.
            Some(r) if !self.reverse_seen(&r) => self.no_way_back = WayBack::Unseen,
            Some(r) => {
                self.reversing = Some(r);
                self.reversals += 1;
                self.recent_reversals += 1;
                self.reversed_at = s;
                self.infeasible_since = None;
                self.no_way_back = WayBack::Open;
            }
            None => self.no_way_back = WayBack::Blocked,
        }
    }

    /// Mark what a scan saw free ([`crate::perception::SeenSpace`]), the laser at `laser`
    /// and the car at `car` (world frame) at `now`, and the car's rectangle; at most
    /// every [`SEEN_PERIOD`] while the car stands. The first time, the rectangle
    /// behind the car its operator checked (`seen_behind_at_start_m` deep,
    /// `seen_behind_at_start_width_m` wide) too.
    pub fn observe(
        &mut self,
        now: f64,
        scan: &crate::perception::Scan<'_>,
        laser: &crate::perception::Pose2,
        car: [f64; 3],
    ) {
        let moved = self.seen_at.is_none_or(|(t, p)| {
            now - t >= SEEN_PERIOD
                || (car[0] - p[0]).hypot(car[1] - p[1]) >= SEEN_MOVE
                || wrap(car[2] - p[2]).abs() >= SEEN_TURN
        });
        if !moved {
            return;
        }
        let f = self.footprint();
        if self.seen_at.is_none() {
            let pc = &self.cfg.planner;
            let (depth, width) = (pc.seen_behind_at_start_m, pc.seen_behind_at_start_width_m);
            self.seen
                .mark_checked_behind(car, f.rear, depth, width / 2.0);
        }
        self.seen.mark_rectangle(car, f.rear, f.front, f.half_width);
        self.seen.update(scan, laser);
        self.seen_at = Some((now, car));
    }

    /// Follow the manoeuvre, if one is followed: forward segments as a drive, backward
    /// ones as a reversal; once it is driven to its end, a replanning is due at once.
    fn follow_manoeuvre(&mut self, pose: &Pose, ahead: &Pose) -> Option<Guidance> {
        let following = self.manoeuvre.as_mut()?;
        let pc = &self.cfg.planner;
        let v = &self.cfg.vehicle;
        // An escape creeps out, forward as backward.
        let forward = match following.escape_margin() {
            Some(_) => pc.manoeuvre_speed.min(pc.reverse_speed),
            None => pc.manoeuvre_speed,
        };
        let pace = manoeuvre::follow::Pace {
            forward_speed: forward.min(v.max_speed),
            reverse_speed: pc.reverse_speed.min(v.max_speed),
            decel: self.cfg.follower.decel,
            dead_time: v.speed_dead_time_s,
            time_constant: v.speed_time_constant_s,
            brake_decel: v.brake_decel,
            wheelbase: v.wheelbase,
            max_steer: v.max_steer_deg.to_radians(),
        };
        let Some(c) = following.command(pose, ahead, &self.law, &pace) else {
            self.manoeuvre = None;
            self.next_replan = 0.0;
            return None;
        };
        Some(if c.forward {
            Guidance::Drive {
                steer: c.steer,
                speed: c.speed,
                room: c.room,
                brake: c.brake,
                inputs: c.inputs,
            }
        } else {
            Guidance::Reverse {
                steer: c.steer,
                speed: c.speed,
                brake: c.brake,
            }
        })
    }

    /// Whether the car's rectangle stays in seen space all along the reversal `r`.
    fn reverse_seen(&self, r: &Reverse) -> bool {
        let f = self.footprint();
        let n = (r.distance / SEEN_CHECK_STEP).ceil().max(1.0) as usize;
        (1..=n).all(|j| {
            let (x, y, theta) = r.pose_at(r.distance * j as f64 / n as f64);
            crate::perception::rectangle_seen(
                |x, y| self.seen.seen(x, y),
                [x, y, theta],
                f.front,
                f.rear,
                f.half_width,
            )
        })
    }

    /// Follow the current path from `pose` (no planning).
    pub fn follow(&mut self, pose: &Pose) -> Guidance {
        self.follow_ahead(pose, pose)
    }

    /// The distance from (x, y) to the mission's goal, metres.
    fn to_goal(&self, x: f64, y: f64) -> f64 {
        (x - self.cfg.mission.goal_x).hypot(y - self.cfg.mission.goal_y)
    }

    /// Follow the current path: arrival, progress, passing the goal and the approach
    /// speed from `pose` (where the car is), steering from `ahead` (where it will be when
    /// the command acts: the pose propagated over the steering dead time).
    pub fn follow_ahead(&mut self, pose: &Pose, ahead: &Pose) -> Guidance {
        let to_goal = self.to_goal(pose.x, pose.y);
        self.progress = self.progress_at(pose);
        // Arrival and "passed the goal" by progress along the whole route, never by one
        // leg nor the distance alone: a route whose goal lies near or behind its start
        // (a lap, a switchback) is driven first.
        let tolerance = self.cfg.mission.goal_tolerance;
        let left = self.route.length() - self.progress;
        let within = if left <= ROUTE_END {
            tolerance
        } else {
            tolerance - ARRIVAL_MARGIN.min(tolerance / 2.0)
        };
        if to_goal <= within && (left <= tolerance || self.progress >= self.route.last_leg_start())
        {
            return Guidance::Arrived;
        }
        if left <= ROUTE_END {
            // At the route's end without reaching the goal: the polynomial cannot go back.
            return Guidance::Stop {
                reason: format!("passed the goal {to_goal:.2} m beside it"),
            };
        }
        if let Some(r) = &self.reversing {
            let speed = if r.done {
                0.0
            } else {
                self.cfg
                    .planner
                    .reverse_speed
                    .min(self.cfg.vehicle.max_speed)
            };
            return Guidance::Reverse {
                steer: r.steer,
                speed,
                brake: 0.0,
            };
        }
        if let Some(e) = &self.planner_error {
            return Guidance::Stop {
                reason: format!("planner: {e}"),
            };
        }
        if let Some(g) = self.follow_manoeuvre(pose, ahead) {
            return g;
        }
        let pose = ahead;
        if let Some(steer) = self.aligning {
            let theta = wrap(pose.theta - self.frame.angle);
            return Guidance::Drive {
                steer,
                speed: self.cfg.planner.align_speed.min(self.cfg.vehicle.max_speed),
                room: f64::INFINITY,
                brake: 0.0,
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
                reason: self.why_no_path(to_goal),
            };
        };
        self.drive_along(t, pose, to_goal)
    }

    /// Why the car stands without a path `to_goal` metres from the goal, in words: the
    /// goal blocked, the manoeuvres or reversals spent, no way back, or no path at all.
    fn why_no_path(&self, to_goal: f64) -> String {
        let pc = &self.cfg.planner;
        if self.goal_blocked {
            format!(
                "goal blocked by an obstacle: stopped {to_goal:.1} m from it, as near as a path leads"
            )
        } else if self.manoeuvres_spent() {
            format!(
                "no way through: {} manoeuvres without {} m of progress",
                self.manoeuvres, pc.manoeuvre_progress_m
            )
        } else if self.recent_reversals > 0 && self.recent_reversals >= pc.max_reversals {
            let n = self.recent_reversals;
            format!(
                "no forward path after {n} reversal{}",
                if n == 1 { "" } else { "s" }
            )
        } else if self.no_way_back == WayBack::Blocked {
            "no forward path, and no clear way back".to_owned()
        } else if self.no_way_back == WayBack::Unseen {
            "no forward path, and no way back the laser has seen (it looks forward)".to_owned()
        } else {
            "no collision-free path".to_owned()
        }
    }

    /// Drive along the trajectory `t` from `pose` (where the car will be when the
    /// command acts), `to_goal` metres from the goal: the steering law's angle, and the
    /// speed the plan, the curve, the route and the room to stop in allow.
    fn drive_along(&self, t: &Trajectory, pose: &Pose, to_goal: f64) -> Guidance {
        let (px, py) = self.frame.to_path(pose.x, pose.y);
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
        // Speed: the plan's pace, slower in curves, towards the goal and towards the
        // path's end. Around moving
        // obstacles the plan's timing matters: x must advance at the planned w1, so the
        // speed along the path is w1 sqrt(1 + y'^2).
        let f = &self.cfg.follower;
        // The speed that stops the car within `d`, commanded early by what it rolls on
        // while its speed loop catches up.
        let coast = self.cfg.vehicle.coast_m(pose.v);
        let stop_within = |d: f64| (2.0 * f.decel * (d - coast).max(0.0)).sqrt();
        let curvature = path.curvature(x).abs().max(1e-6);
        let pace = if self.paced {
            t.w1() * path.dy_dx(x).hypot(1.0)
        } else {
            self.cfg.planner.cruise_speed
        };
        let passage = if self.passage {
            self.cfg.planner.passage_speed
        } else {
            f64::INFINITY
        };
        let room = to_goal.min(path.x_f() - x);
        // Down to a slower pace, or the speed of a passage narrow only beside the car,
        // it eases off at `follower.decel` (what the plans' schedules reckon with),
        // never brakes: the speed loop (first order) follows a command held that far
        // under the speed at that rate, where a step would brake at its own. A passage
        // narrow ahead is entered at its speed.
        let ease = match self.passage && self.narrow_ahead {
            true => 0.0,
            false => pose.v - f.decel * self.cfg.vehicle.speed_time_constant_s,
        };
        let speed = pace
            .min(passage)
            .max(ease)
            .min(
                self.route
                    .speed_limit(self.progress)
                    .unwrap_or(f64::INFINITY),
            )
            .min((f.max_lateral_accel / curvature).sqrt())
            // The path's end is where the next replanning may find no way on (a local
            // goal before a blocked goal or a wall): the car can always stop there.
            .min(stop_within(room))
            .min(self.cfg.vehicle.max_speed);
        Guidance::Drive {
            steer,
            speed,
            room,
            brake: 0.0,
            inputs,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::search::{MAX_DETOURS, clear_of};
    use super::*;
    use crate::perception::{PerceptionConfig, cover_segment};

    #[test]
    fn each_search_that_finds_nothing_deepens_and_delays_the_next_up_to_a_bound_and_a_find_resets_it()
     {
        let mut e = SearchEffort::FIRST;
        let (mut budgets, mut waits) = (Vec::new(), Vec::new());
        for _ in 0..4 {
            budgets.push(e.expansions(20_000));
            e = e.after(true, false);
            waits.push(e.retry_wait());
        }
        assert_eq!(budgets, [20_000, 80_000, 320_000, 320_000]);
        assert_eq!(waits, [2.0, 8.0, 32.0, 32.0]);
        // A kept manoeuvre (neither failed nor new) leaves the effort as it is.
        assert_eq!(e.after(false, false), e);
        assert_eq!(e.after(false, true), SearchEffort::FIRST);
    }

    /// The default configuration with the goal at (goal_x, 0): a straight mission east.
    pub(super) fn east_to(goal_x: f64) -> ControllerConfig {
        let mut cfg = ControllerConfig::default();
        cfg.mission.goal_x = goal_x;
        cfg.mission.goal_y = 0.0;
        cfg
    }

    /// The car at (x, y) heading `theta`, at speed `v`, wheels straight.
    pub(super) fn car_at(x: f64, y: f64, theta: f64, v: f64) -> Pose {
        Pose {
            x,
            y,
            theta,
            v,
            phi: 0.0,
        }
    }

    /// A static post.
    pub(super) fn post(x: f64, y: f64, radius: f64) -> planner::Obstacle {
        planner::Obstacle {
            x,
            y,
            radius,
            vx: 0.0,
            vy: 0.0,
        }
    }

    /// The navigator's progress brought along the route to x = `to` tick by tick, as
    /// following does.
    fn drive_east(nav: &mut Navigator, to: i32) {
        for x in 0..=to {
            nav.follow(&car_at(f64::from(x), 0.0, 0.0, 0.0));
        }
    }

    /// A replanning from `pose` at 0.5 s allowed no steering and offered only the local
    /// goal: it finds no path, and what is kept is up to the path being followed.
    fn starved(nav: &Navigator, pose: &Pose, obstacles: &[planner::Obstacle]) -> PlanOutcome {
        let mut req = nav.request(0.5, pose, obstacles);
        req.steer_limit = 1e-6;
        req.detours.clear();
        req.passages.clear();
        // The polynomial alone: what it keeps when it finds nothing.
        req.manoeuvre = None;
        solve(&req)
    }

    fn replan_and_follow(
        nav: &mut Navigator,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
    ) -> Guidance {
        assert!(nav.replan_due(0.0, pose));
        nav.issued(0.0);
        nav.accept(solve(&nav.request(0.0, pose, obstacles)));
        nav.follow(pose)
    }

    #[test]
    fn a_goal_the_car_has_turned_past_is_no_path_not_a_planner_error() {
        // Round a hedge's end on a switchback, the car came past the end of a
        // problem's frame: t_f = t_k + span / pace fell before t_k, the planner refused
        // the problem and the car stopped for good ("planner: t_f must be later").
        let cfg = east_to(40.0);
        let nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(5.0, 0.0, 0.0, 2.0);
        for moving in [false, true] {
            let walker = planner::Obstacle {
                vx: 0.7,
                ..post(20.0, 6.0, 0.3)
            };
            let obstacles: Vec<planner::Obstacle> = if moving { vec![walker] } else { vec![] };
            let mut req = nav.request(0.5, &pose, &obstacles);
            assert_eq!(req.pacing.is_some(), moving);
            req.problem.goal.x = req.problem.state.x - 1.0;
            req.detours.clear();
            req.passages.clear();
            req.manoeuvre = None;
            match solve(&req).result {
                Ok((path, _)) => assert!(path.is_none(), "a path to a goal behind the car"),
                Err(e) => panic!("moving {moving}: {e}"),
            }
        }
    }

    #[test]
    fn a_replanning_that_finds_no_path_keeps_the_path_being_followed_while_it_holds() {
        let cfg = east_to(40.0);
        let post_beside = post(10.0, 4.0, 0.5);
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let start = car_at(0.0, 0.0, 0.0, 2.0);
        assert!(matches!(
            replan_and_follow(&mut nav, &start, &[post_beside]),
            Guidance::Drive { .. }
        ));
        // On the path, 0.1 m off it: a replanning allowed no steering finds nothing.
        let pose = car_at(2.0, 0.1, 0.0, 2.0);
        nav.follow(&pose);
        let starved =
            |nav: &Navigator, obstacles: &[planner::Obstacle]| starved(nav, &pose, obstacles);
        let outcome = starved(&nav, &[post_beside]);
        let Ok((None, record)) = &outcome.result else {
            panic!("a path with no steering: {:?}", outcome.result);
        };
        assert!(record.kept && !record.feasible, "{record:?}");
        nav.accept(outcome);
        assert!(matches!(nav.follow(&pose), Guidance::Drive { .. }));
        // A post now reported on the rest of the path: it is not kept, the car stops.
        let on_path = post(15.0, 0.0, 0.5);
        let outcome = starved(&nav, &[post_beside, on_path]);
        assert!(matches!(&outcome.result, Ok((None, r)) if !r.kept));
        nav.accept(outcome);
        assert!(matches!(nav.follow(&pose), Guidance::Stop { .. }));
        // Nor with the car off it, nor with a moving obstacle in view anywhere.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        replan_and_follow(&mut nav, &start, &[post_beside]);
        let off = car_at(2.0, 0.6, 0.0, 2.0);
        assert!(!nav.current_path_holds(&off, &[post_beside]));
        let walker = planner::Obstacle {
            vx: 1.0,
            ..post(30.0, 20.0, 0.3)
        };
        assert!(!nav.current_path_holds(&pose, &[post_beside, walker]));
        assert!(nav.current_path_holds(&pose, &[post_beside]));
    }

    #[test]
    fn a_path_that_ends_at_the_goal_is_kept_over_its_last_metres() {
        // Under GPS noise a replanning 1.6 m from the goal found no polynomial within
        // the steering limit, and the path that led there was dropped for having less
        // than KEEP_LEFT left: the car stopped 1.25 m from the goal for good.
        let cfg = east_to(20.0);
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let start = car_at(15.0, 0.0, 0.0, 2.0);
        assert!(matches!(
            replan_and_follow(&mut nav, &start, &[]),
            Guidance::Drive { .. }
        ));
        let pose = car_at(18.2, 0.05, 0.0, 1.5);
        nav.follow(&pose);
        assert!(nav.replan_due(0.5, &pose));
        let outcome = starved(&nav, &pose, &[]);
        assert!(
            matches!(&outcome.result, Ok((None, r)) if r.kept),
            "{:?}",
            outcome.result
        );
        nav.accept(outcome);
        assert!(matches!(nav.follow(&pose), Guidance::Drive { .. }));
        // A path with as little left whose end is not the goal is not kept.
        let mut nav = Navigator::new(&east_to(40.0)).expect("navigator");
        replan_and_follow(&mut nav, &car_at(0.0, 0.0, 0.0, 2.0), &[]);
        let Some(t) = &nav.active else {
            panic!("no path")
        };
        let end = t.path().x_f();
        assert!(end < 38.0, "the first path ends at the goal: {end}");
        assert!(!nav.current_path_holds(&car_at(end - 1.8, 0.0, 0.0, 2.0), &[]));
    }

    #[test]
    fn the_paper_scenario_plans_around_the_post_within_the_steering_limit() {
        let cfg = ControllerConfig::default();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(0.0, 0.0, 45f64.to_radians(), 0.0);
        let post = planner::Obstacle {
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
        let pose = car_at(0.0, 0.0, 0.4, 0.0);
        let blocker = planner::Obstacle {
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
    fn an_oncoming_cart_on_the_line_is_given_way_to_on_the_right_without_stopping() {
        let mut cfg = east_to(50.0);
        let pose = car_at(0.0, 0.0, 0.0, 2.0);
        let cart = planner::Obstacle {
            vx: -1.5,
            ..post(16.0, 0.3, 1.3)
        };
        for keep_right in [true, false] {
            cfg.planner.keep_right = keep_right;
            let nav = Navigator::new(&cfg).expect("navigator");
            let req = nav.request(0.0, &pose, &[cart]);
            assert!(req.pacing.as_ref().is_some_and(|p| p.oncoming));
            let outcome = solve(&req);
            let (trajectory, record) = outcome.result.expect("planned");
            assert!(trajectory.is_some(), "{record:?}");
            let pace = record.pace.expect("pace");
            assert!(pace >= 0.8 * cfg.planner.cruise_speed, "no slowing: {pace}");
            // Where the car meets the cart, it is on the side it keeps to.
            let y_at_cart = record
                .path
                .iter()
                .min_by(|a, b| (a[0] - 10.0).abs().total_cmp(&(b[0] - 10.0).abs()))
                .map(|p| p[1])
                .expect("path");
            assert!(
                if keep_right {
                    y_at_cart < -1.0
                } else {
                    y_at_cart > 1.0
                },
                "keep_right {keep_right}: y {y_at_cart}"
            );
        }
    }

    #[test]
    fn a_slow_cart_ahead_in_an_open_field_is_overtaken_not_followed() {
        // A cart at walking pace on the route, nothing else: passing it beats following
        // it at its pace for the rest of the local horizon.
        let cfg = east_to(60.0);
        let pose = car_at(0.0, 0.0, 0.0, 2.0);
        let cart = planner::Obstacle {
            vx: 0.3,
            ..post(9.0, 0.0, 1.3)
        };
        let nav = Navigator::new(&cfg).expect("navigator");
        let req = nav.request(0.0, &pose, &[cart]);
        assert!(req.pacing.as_ref().is_some_and(|p| !p.oncoming));
        let (trajectory, record) = solve(&req).result.expect("planned");
        assert!(trajectory.is_some(), "{record:?}");
        let pace = record.pace.expect("pace");
        let widest = record.path.iter().map(|p| p[1].abs()).fold(0.0, f64::max);
        eprintln!("slow cart ahead: pace {pace:.2} m/s, {widest:.2} m off the line");
        assert!(
            pace >= 0.5 * cfg.planner.cruise_speed,
            "not followed: {pace}"
        );
        assert!(widest > 1.3 + 1.0, "passed beside it: {widest}");
    }

    #[test]
    fn walkers_ahead_keeping_to_their_line_are_passed_on_the_side_not_kept_to() {
        // Two walkers side by side at 0.7 m/s, 6 m ahead: scored against following
        // them, no detour pays; the pass lane clears both and may take any pace.
        let walkers = |vy: f64| {
            [(6.0, 0.3), (8.0, -0.5)].map(|(x, y)| planner::Obstacle {
                vx: 0.7,
                vy,
                ..post(x, y, 0.3)
            })
        };
        let pose = car_at(0.0, 0.0, 0.0, 1.0);
        let plan = |cfg: &ControllerConfig, obstacles: &[planner::Obstacle]| {
            let nav = Navigator::new(cfg).expect("navigator");
            let (trajectory, record) = solve(&nav.request(0.0, &pose, obstacles))
                .result
                .expect("planned");
            assert!(trajectory.is_some(), "{record:?}");
            record
        };
        let mut cfg = east_to(60.0);
        let record = plan(&cfg, &walkers(0.0));
        let end = record.path.last().expect("a path");
        assert!(record.passing, "{record:?}");
        // The lane: beyond the walker at y = 0.3 by its radius and the car's circle.
        let r0 = cfg.vehicle.radius + cfg.planner.safety_margin;
        assert!(
            end[1] >= 0.3 + 0.3 + r0,
            "on the left, clear of both: {end:?}"
        );
        assert!(record.pace.expect("pace") > 0.7, "{record:?}");
        // Keeping to the left, the pass goes right.
        cfg.planner.keep_right = false;
        let record = plan(&cfg, &walkers(0.0));
        let end = record.path.last().expect("a path");
        assert!(record.passing && end[1] <= -(0.5 + 0.3 + r0), "{end:?}");
        // Walkers crossing the line on their way, or a route ending within a horizon:
        // followed, not passed.
        cfg.planner.keep_right = true;
        assert!(!plan(&cfg, &walkers(0.5)).passing);
        let short = east_to(cfg.planner.horizon_m - 1.0);
        assert!(!plan(&short, &walkers(0.0)).passing);
    }

    #[test]
    fn a_crossing_obstacle_timed_to_meet_the_car_is_yielded_to() {
        let mut cfg = ControllerConfig::default();
        cfg.mission.goal_x = 35.0;
        cfg.mission.goal_y = 0.0;
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(8.0, 0.0, 0.0, 2.0);
        // At 2 m/s the car is at x = 16 in 4 s, when the obstacle crosses y = 0.
        let crossing = planner::Obstacle {
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
        let still = planner::Obstacle {
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
    fn a_passage_path_is_kept_while_the_rectangle_clears_the_rest_of_it() {
        let cfg = east_to(30.0);
        // A fence across the route at x = 10 with a 2.0 m gate on the route.
        let fence: Vec<planner::Obstacle> = (0..16)
            .flat_map(|k| {
                let y = 1.25 + 0.5 * f64::from(k);
                [post(10.0, y, 0.25), post(10.0, -y, 0.25)]
            })
            .collect();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let start = car_at(0.0, 0.0, 0.0, 1.0);
        assert!(matches!(
            replan_and_follow(&mut nav, &start, &fence),
            Guidance::Drive { .. }
        ));
        assert!(nav.passage, "planned through the gate");
        // In the gate, the fence's end 0.2 m beside the car's side (inside the 0.25 m
        // margin, as GPS noise puts it): a replanning allowed no steering finds nothing.
        let pose = car_at(9.0, 0.0, 0.0, 1.0);
        nav.follow(&pose);
        let mut edge = fence.clone();
        edge.push(post(10.0, 0.95, 0.15));
        let starved =
            |nav: &Navigator, obstacles: &[planner::Obstacle]| starved(nav, &pose, obstacles);
        let outcome = starved(&nav, &edge);
        assert!(
            matches!(&outcome.result, Ok((None, r)) if r.kept),
            "{:?}",
            outcome.result
        );
        // A post on the rest of the path: not kept.
        edge.push(post(16.0, 0.0, 0.3));
        let outcome = starved(&nav, &edge);
        assert!(matches!(&outcome.result, Ok((None, r)) if !r.kept));
    }

    #[test]
    fn a_walker_converging_from_beside_is_driven_away_from_not_waited_for() {
        // Suite scenario crossing, seed index 1, at the replanning that found nothing:
        // a walker level with the car, 3.9 m to its right, walking towards its line.
        // Every pace's circle-clear path is refused, and braking would leave the car
        // standing where the walker arrives in 4 s.
        let cfg = east_to(17.0);
        let nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(0.0, 0.3, 0.0, 2.0);
        let walker = |vx: f64, vy: f64| planner::Obstacle {
            x: -0.6,
            y: -3.6,
            radius: 0.5,
            vx,
            vy,
        };
        // Only the local goal is offered (in the run its detours were refused too).
        let request = |obstacles: &[planner::Obstacle]| {
            let mut req = nav.request(0.0, &pose, obstacles);
            req.detours.clear();
            req.passages.clear();
            req
        };
        let converging = walker(0.34, 0.78);
        let outcome = solve(&request(&[converging]));
        let (trajectory, record) = outcome.result.expect("planned");
        let t = trajectory.expect("a way out");
        assert!(record.escape && record.moving, "{record:?}");
        // Driven at its pace, the car's rectangle stays clear of the walker's track,
        // with the margins, at every pose.
        let walker_now = planner::Obstacle {
            x: -0.6,
            y: -3.6,
            radius: 0.5 + cfg.planner.moving_margin,
            vx: 0.34,
            vy: 0.78,
        };
        let fp = nav.footprint();
        assert!(fp.path_clear_of_moving(&t, &[walker_now], 0.0));
        assert!(record.pace.expect("pace") >= 0.5 * cfg.planner.cruise_speed);
        // Where braking from 2 m/s at 1 m/s^2 leaves the car (2 m on), the walker
        // arrives within the watch.
        assert!(!fp.clear_of_track((2.0, 0.3, 0.0), &walker_now, 0.0, 5.0));
        // A walker crossing just ahead passes in front of where the car would stand:
        // standing is yielding, and no escape is planned (the circle-clear tiers slow
        // the car instead).
        let ahead = planner::Obstacle {
            x: 6.0,
            y: -1.0,
            ..walker(0.0, 1.0)
        };
        let req = request(&[ahead]);
        assert!(super::solver::escape(&req, req.pacing.as_ref().expect("pacing")).is_none());
        let (trajectory, record) = solve(&req).result.expect("planned");
        assert!(trajectory.is_some() && !record.escape, "{record:?}");
    }

    #[test]
    fn a_walker_passing_the_standing_car_is_not_cut_in_front_of() {
        // Suite scenario pedestrians-ahead under 8 cm of GPS noise, seed index 2: the
        // car has overtaken two walkers on the left, turned back in, found nothing and
        // stood; the walker on the route then walks past its right side at 0.7 m/s.
        // The sweep shrinks that walker's circle so the car can move on, and the paths
        // back to the route crept at 0.4 m/s across the walker's way: the car's corner
        // came within 0.29 m of it. Two replannings of that run, each with the pose
        // and the walkers as the controller had them (positions and velocities
        // estimated from the scans, 2 s apart).
        let cfg = east_to(50.0);
        let mut nav = Navigator::new(&cfg).expect("navigator");
        drive_east(&mut nav, 25);
        let walker = |x: f64, y: f64, vx: f64, vy: f64| planner::Obstacle {
            x,
            y,
            radius: 0.3,
            vx,
            vy,
        };
        let replannings = [
            (
                24.27,
                car_at(25.865, 2.275, -0.2212, 0.27),
                [
                    walker(28.997, -0.552, 0.669, -0.054),
                    walker(26.998, 0.248, 0.657, -0.025),
                ],
            ),
            (
                26.27,
                car_at(26.598, 2.095, -0.2918, 0.42),
                [
                    walker(30.381, -0.525, 0.793, -0.016),
                    walker(28.382, 0.279, 0.794, 0.006),
                ],
            ),
        ];
        let fp = nav.footprint();
        let mut driven = 0;
        for (now, pose, walkers) in replannings {
            let outcome = solve(&nav.request(now, &pose, &walkers));
            let (trajectory, record) = outcome.result.as_ref().expect("planned");
            assert!(record.moving, "{record:?}");
            let Some(t) = trajectory else {
                continue; // standing 2 m beside the walker's track: yielding
            };
            driven += 1;
            // Driven at its pace, the path keeps the car's rectangle the passage margin
            // and the moving margin from both walkers as they truly walked (0.7 m/s
            // along the route from x = 10 and 12 at 0 s), with no time margin.
            let truth = [(10.0, 0.3), (12.0, -0.5)].map(|(x0, y)| {
                let (x, y) = outcome.frame.to_path(x0 + 0.7 * now, y);
                let (vx, vy) = outcome.frame.rotate_to_path(0.7, 0.0);
                planner::Obstacle {
                    x,
                    y,
                    radius: 0.3 + cfg.planner.moving_margin,
                    vx,
                    vy,
                }
            });
            assert!(
                fp.path_clear_of_moving(t, &truth, 0.0),
                "at {now} s: pace {:?}, passage {}",
                record.pace,
                record.passage
            );
        }
        assert!(driven > 0, "the car never moves on");
    }

    #[test]
    fn a_car_facing_away_turns_towards_the_goal_where_the_circle_is_clear() {
        let cfg = ControllerConfig::default();
        let mut nav = Navigator::new(&cfg).expect("navigator");
        // The line points at 26.6 degrees; the car at 170 degrees (143 off, to the
        // left): the short way round is a right turn.
        let pose = car_at(0.0, 0.0, 170f64.to_radians(), 0.0);
        let mut req = nav.request(0.0, &pose, &[]);
        // Turning on the circle is what is left when no manoeuvre is found.
        assert!(req.manoeuvre.is_some());
        req.manoeuvre = None;
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
        let post = planner::Obstacle {
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
        let other = planner::Obstacle {
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

    /// A mission east along y = 0 and a wall of posts across it at `wall_x`, from
    /// y = -25 to 25 (every 0.5 m): too long to go round.
    fn dead_end(wall_x: f64) -> (ControllerConfig, Vec<planner::Obstacle>) {
        let mut cfg = ControllerConfig::default();
        cfg.mission.goal_x = 30.0;
        cfg.mission.goal_y = 0.0;
        let wall = (-50..=50)
            .map(|i| planner::Obstacle {
                x: wall_x,
                y: f64::from(i) * 0.5,
                radius: 0.3,
                vx: 0.0,
                vy: 0.0,
            })
            .collect();
        (cfg, wall)
    }

    /// The navigator with 60 m x 60 m round the origin seen free (as if the laser had
    /// looked round): reversals are checked against the obstacles alone.
    pub(super) fn seen_round(mut nav: Navigator) -> Navigator {
        nav.seen.mark_rectangle([0.0, 0.0, 0.0], 30.0, 30.0, 30.0);
        nav
    }

    #[test]
    fn the_space_checked_behind_at_the_start_is_marked_at_most_half_a_cell_past_its_far_end() {
        // Marked cell by cell, the rectangle reached up to a cell past the depth the
        // operator checked: under GPS noise a reversal ended 0.1 m from a cart 0.4 m
        // beyond it (boxed-in).
        let cfg = ControllerConfig::default();
        let pc = &cfg.planner;
        let dropouts = [f32::NAN; 3];
        let scan = crate::perception::Scan {
            stamp: 0.0,
            angle_min: -0.1,
            angle_increment: 0.1,
            range_min: 0.1,
            range_max: 20.0,
            ranges: &dropouts,
        };
        for heading in [0.0, 0.3, std::f64::consts::FRAC_PI_4, 2.0, -2.8] {
            let mut nav = Navigator::new(&cfg).expect("navigator");
            let car = [3.1, -1.7, heading];
            let laser = crate::perception::Pose2 {
                x: car[0],
                y: car[1],
                yaw: heading,
            };
            nav.observe(0.0, &scan, &laser, car);
            let (c, s) = (heading.cos(), heading.sin());
            let rear = nav.footprint().rear;
            let behind = |d: f64, v: f64| {
                let u = -(rear + d);
                nav.seen
                    .seen(car[0] + u * c - v * s, car[1] + u * s + v * c)
            };
            let depth = pc.seen_behind_at_start_m;
            let half_cell = crate::perception::SEEN_CELL / 2.0 * (c.abs() + s.abs());
            for v in [-0.5, 0.0, 0.5] {
                for past in [0.01, 0.1, 0.2, 0.3].map(|d| half_cell + d) {
                    assert!(!behind(depth + past, v), "heading {heading}: {past} m past");
                }
                assert!(
                    behind(depth - 2.0 * crate::perception::SEEN_CELL, v),
                    "heading {heading}: inside"
                );
            }
        }
    }

    /// Replan at `now` from `pose` when due, recover, follow: as the controller's tick does.
    fn tick(
        nav: &mut Navigator,
        now: f64,
        pose: &Pose,
        obstacles: &[planner::Obstacle],
    ) -> Guidance {
        if nav.replan_due(now, pose) {
            nav.issued(now);
            nav.accept(solve(&nav.request(now, pose, obstacles)));
        }
        nav.recover(now, pose, obstacles);
        nav.follow(pose)
    }

    #[test]
    fn a_car_facing_a_wall_reverses_a_bounded_number_of_times_then_stops_with_the_reason() {
        let (cfg, wall) = dead_end(4.5);
        let pc = &cfg.planner;
        let mut nav = seen_round(Navigator::new(&cfg).expect("navigator"));
        let mut pose = car_at(0.0, 0.0, 0.0, 0.0);
        let mut now = 0.0;
        for round in 1..=pc.max_reversals {
            // No forward path: a controlled stop until it has stood recover_after_s.
            let stand_from = now;
            loop {
                let g = tick(&mut nav, now, &pose, &wall);
                if matches!(g, Guidance::Reverse { .. }) {
                    break;
                }
                assert!(matches!(g, Guidance::Stop { .. }), "{round}: {g:?}");
                assert!(now - stand_from < pc.recover_after_s + 0.5, "{round}");
                now += 0.01;
            }
            assert!(now - stand_from >= pc.recover_after_s - 1e-9);
            assert_eq!(nav.reversals(), round);
            // Straight back at the reverse speed, not replanning meanwhile.
            assert_eq!(
                nav.follow(&pose),
                Guidance::Reverse {
                    steer: 0.0,
                    speed: pc.reverse_speed,
                    brake: 0.0,
                }
            );
            // It brakes what the speed loop rolls on before the end of the way.
            let braked = pc.reverse_distance_m - cfg.vehicle.coast_m(pc.reverse_speed);
            while nav.reversing.is_some_and(|r| !r.done) {
                now += 0.01;
                pose.x -= pc.reverse_speed * 0.01;
                pose.v = -pc.reverse_speed;
                assert!(!nav.replan_due(now, &pose));
                nav.recover(now, &pose, &wall);
                assert!(pose.x > -(braked + 0.1) * f64::from(round));
            }
            assert!(pose.x < -(braked - 0.1) * f64::from(round), "{}", pose.x);
            // Braking to a stand, then replanning at once.
            assert!(matches!(
                nav.follow(&pose),
                Guidance::Reverse { speed: 0.0, .. }
            ));
            pose.v = 0.0;
            nav.recover(now, &pose, &wall);
            assert!(nav.reversing.is_none() && nav.replan_due(now, &pose));
        }
        // Out of reversals: a controlled stop that says why, held.
        for _ in 0..300 {
            now += 0.01;
            let g = tick(&mut nav, now, &pose, &wall);
            assert_eq!(
                g,
                Guidance::Stop {
                    reason: format!("no forward path after {} reversals", pc.max_reversals)
                }
            );
        }
        assert_eq!(nav.reversals(), pc.max_reversals);
        // Progress past the place of the last reversal gives them back: the way now
        // open, the car drives on, and a new dead end further along the route is
        // backed out of again.
        let x_end = pc.reversal_reset_m + 1.0;
        while pose.x < x_end {
            now += 0.1;
            pose.x += 0.1;
            pose.v = 1.0;
            tick(&mut nav, now, &pose, &[]);
            if pose.x < pc.reversal_reset_m - 0.2 {
                assert_eq!(nav.recent_reversals, pc.max_reversals, "at x = {}", pose.x);
            }
        }
        assert_eq!(nav.recent_reversals, 0);
        let (_, further) = dead_end(x_end + 4.5);
        pose.v = 0.0;
        let stand_from = now;
        while !matches!(
            tick(&mut nav, now, &pose, &further),
            Guidance::Reverse { .. }
        ) {
            now += 0.01;
            // Found infeasible at the next replanning, then stood recover_after_s.
            let limit = pc.replan_period_s + pc.recover_after_s + 0.1;
            assert!(now - stand_from < limit, "it reverses again");
        }
        assert_eq!(nav.recent_reversals, 1);
        assert_eq!(nav.reversals(), pc.max_reversals + 1);
    }

    #[test]
    fn a_blocked_way_back_is_not_taken_nor_followed_and_a_clear_forward_path_needs_no_reversal() {
        let (cfg, mut walls) = dead_end(4.5);
        // A second wall 4 m behind the car: backing up would hit it.
        let (_, behind) = dead_end(-4.0);
        walls.extend(behind);
        let mut nav = seen_round(Navigator::new(&cfg).expect("navigator"));
        let pose = car_at(0.0, 0.0, 0.0, 0.0);
        for k in 0..300 {
            let g = tick(&mut nav, f64::from(k) * 0.01, &pose, &walls);
            assert!(matches!(g, Guidance::Stop { .. }), "{g:?}");
        }
        assert_eq!(nav.reversals(), 0);
        assert_eq!(
            nav.follow(&pose),
            Guidance::Stop {
                reason: "no forward path, and no clear way back".to_owned()
            }
        );
        // The wall behind shows up only once the car backs: it brakes at once.
        let (_, ahead) = dead_end(4.5);
        let mut nav = seen_round(Navigator::new(&cfg).expect("navigator"));
        let mut now = 0.0;
        while !matches!(tick(&mut nav, now, &pose, &ahead), Guidance::Reverse { .. }) {
            now += 0.01;
            assert!(now < 3.0, "it reverses");
        }
        let backing = Pose {
            x: -0.5,
            v: -cfg.planner.reverse_speed,
            ..pose
        };
        nav.recover(now + 1.0, &backing, &ahead);
        assert!(matches!(
            nav.follow(&backing),
            Guidance::Reverse { speed, .. } if speed > 0.0
        ));
        nav.recover(now + 1.01, &backing, &walls);
        assert!(matches!(
            nav.follow(&backing),
            Guidance::Reverse { speed: 0.0, .. }
        ));
        // Nothing seen behind the car (the laser looks forward): it never backs up.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        for k in 0..300 {
            let g = tick(&mut nav, f64::from(k) * 0.01, &pose, &ahead);
            assert!(matches!(g, Guidance::Stop { .. }), "{g:?}");
        }
        assert_eq!(
            nav.follow(&pose),
            Guidance::Stop {
                reason: "no forward path, and no way back the laser has seen (it looks forward)"
                    .to_owned()
            }
        );
        // A car that is merely moving when its path goes infeasible does not reverse.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let rolling = Pose { v: 0.5, ..pose };
        for k in 0..300 {
            tick(&mut nav, f64::from(k) * 0.01, &rolling, &ahead);
        }
        assert_eq!(nav.reversals(), 0);
        // With the way open, it drives forwards and never reverses.
        let mut nav = Navigator::new(&cfg).expect("navigator");
        for k in 0..300 {
            let g = tick(&mut nav, f64::from(k) * 0.01, &pose, &[]);
            assert!(matches!(g, Guidance::Drive { .. }), "{g:?}");
        }
        assert_eq!(nav.reversals(), 0);
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
        let pose = car_at(0.0, 0.0, 0.0, 0.0);
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
        let post = planner::Obstacle {
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
        let post = planner::Obstacle {
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

    /// A fence across the route at x = 20 with a gate `gap` wide centred on it, as
    /// perception covers it: chains of circles spaced for the passage margin.
    fn fence(gap: f64, margin: f64) -> Vec<planner::Obstacle> {
        let cfg = PerceptionConfig {
            vehicle_radius: margin,
            ..PerceptionConfig::default()
        };
        [
            ([20.0, -12.0], [20.0, -gap / 2.0]),
            ([20.0, gap / 2.0], [20.0, 12.0]),
        ]
        .into_iter()
        .flat_map(|(a, b)| {
            let (r, centres) = cover_segment(a, b, 0.1, &cfg);
            centres.into_iter().map(move |c| planner::Obstacle {
                x: c[0],
                y: c[1],
                radius: r,
                vx: 0.0,
                vy: 0.0,
            })
        })
        .collect()
    }

    #[test]
    fn a_gate_of_car_width_plus_0_8_m_is_driven_through_slowly() {
        let cfg = east_to(40.0);
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(15.5, 0.0, 0.0, 2.0);
        let gate = fence(cfg.vehicle.width + 0.8, cfg.planner.passage_margin);
        drive_east(&mut nav, 15);
        let req = nav.request(0.0, &pose, &gate);
        let outcome = solve(&req);
        let (trajectory, record) = outcome.result.clone().expect("planned");
        assert!(trajectory.is_some() && record.passage, "{record:?}");
        assert!(
            !record.projected_to_boundary,
            "straight through: {record:?}"
        );
        // The car's rectangle clears both posts of the gate along the whole path.
        let fp = nav.footprint();
        let t = trajectory.expect("path");
        let p = t.path();
        let obstacles: Vec<planner::Obstacle> = gate.to_vec();
        for x in p.stations(100) {
            let (wx, wy) = outcome.frame.to_world(x, p.y(x));
            let heading = outcome.frame.angle + p.heading(x);
            assert!(fp.clear_at(wx, wy, heading, &obstacles), "at x = {x}");
        }
        nav.accept(outcome);
        match nav.follow(&pose) {
            Guidance::Drive { speed, .. } => {
                assert!(speed <= cfg.planner.passage_speed + 1e-12, "{speed}");
            }
            other => panic!("expected to drive, got {other:?}"),
        }
        // A gate narrower than the car plus the margin on each side: no path.
        let narrow = fence(cfg.vehicle.width + 0.2, cfg.planner.passage_margin);
        let mut req = nav.request(0.0, &pose, &narrow);
        // The polynomial's passages alone (a manoeuvre would close in on the gate).
        req.manoeuvre = None;
        let (trajectory, record) = solve(&req).result.expect("planned");
        assert!(trajectory.is_none() && !record.feasible, "{record:?}");
    }

    #[test]
    fn a_gate_seen_at_the_edge_of_the_sight_is_driven_through_not_round_its_posts() {
        // A fence across the route with a gate of car width + 2 m, 7.8 m ahead: the
        // laser's 8 m show only the posts' ends. A detour round them would lead through
        // the fence beyond; the path goes through the gate.
        let cfg = east_to(40.0);
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let pose = car_at(12.2, 0.0, 0.0, 2.0);
        let sight = cfg.perception.detection_radius;
        let seen: Vec<planner::Obstacle> =
            fence(cfg.vehicle.width + 2.0, cfg.planner.passage_margin)
                .into_iter()
                .filter(|o| (o.x - pose.x).hypot(o.y - pose.y) - o.radius <= sight)
                .collect();
        assert!(
            !seen.is_empty() && seen.iter().all(|o| o.y.abs() < 2.5),
            "{seen:?}"
        );
        drive_east(&mut nav, 12);
        let outcome = solve(&nav.request(0.0, &pose, &seen));
        let (trajectory, record) = outcome.result.clone().expect("planned");
        let p = *trajectory.expect("a path").path();
        let through = p
            .stations(100)
            .map(|x| outcome.frame.to_world(x, p.y(x)))
            .filter(|(wx, _)| (wx - 20.0).abs() < 0.2)
            .all(|(_, wy)| wy.abs() < 1.0);
        assert!(through, "{record:?}");
    }

    #[test]
    fn a_blocked_goal_ends_in_a_stop_that_says_so() {
        let mut nav = Navigator::new(&east_to(12.0)).expect("navigator");
        // A cart parked on the goal; the car 3.5 m before it, no path further.
        let cart = post(12.3, 0.0, 1.3);
        let pose = car_at(8.5, 0.0, 0.0, 0.0);
        drive_east(&mut nav, 8);
        let req = nav.request(0.0, &pose, &[cart]);
        assert!(req.goal_blocked);
        let outcome = solve(&req);
        assert!(matches!(&outcome.result, Ok((None, r)) if r.goal_blocked));
        nav.accept(outcome);
        match nav.follow(&pose) {
            Guidance::Stop { reason } => {
                assert!(
                    reason.starts_with("goal blocked") && reason.contains("3.5 m"),
                    "{reason}"
                );
            }
            other => panic!("expected a stop, got {other:?}"),
        }
        // Without the cart the goal is free.
        assert!(!nav.request(0.0, &pose, &[]).goal_blocked);
    }

    /// A route from the start through `waypoints` to `goal`.
    fn route_to(waypoints: &[(f64, f64)], goal: (f64, f64)) -> ControllerConfig {
        let mut cfg = ControllerConfig::default();
        cfg.mission.waypoints = waypoints
            .iter()
            .map(|&(x, y)| crate::route::Waypoint {
                x,
                y,
                tolerance: 2.0,
                heading_deg: None,
                speed_limit: None,
            })
            .collect();
        (cfg.mission.goal_x, cfg.mission.goal_y) = goal;
        cfg
    }

    #[test]
    fn round_a_corner_with_trees_inside_the_local_goal_is_in_sight_and_near_the_route() {
        // A 90-degree left corner at (30, 0), trees 3.5 and 6.5 m in from its legs. A
        // local goal far up the next leg pulled the path into the trees; one further on
        // still, its line clear inside them, took the car 12 m off the route.
        let cfg = route_to(&[(30.0, 0.0)], (30.0, 30.0));
        let nav = Navigator::new(&cfg).expect("navigator");
        let trees = [post(24.5, 3.5, 0.4), post(27.0, 6.5, 0.4)];
        let wide = nav.wide();
        for s in [8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 22.0, 24.0, 26.0] {
            let goal = search::local_goal(&nav.route, &cfg.planner, &wide, s, &trees);
            let here = nav.route.at(s);
            let (dx, dy) = (goal.x - here.x, goal.y - here.y);
            let length = dx.hypot(dy);
            // The line from the route at s to the goal: clear of the trees by the
            // planning circle, and passing within 4 m of the corner.
            for t in &trees {
                let along =
                    (((t.x - here.x) * dx + (t.y - here.y) * dy) / length.powi(2)).clamp(0.0, 1.0);
                let (cx, cy) = (here.x + along * dx, here.y + along * dy);
                let gap = (t.x - cx).hypot(t.y - cy) - t.radius;
                assert!(
                    gap > wide.r0,
                    "s {s}: goal ({:.1}, {:.1}) hidden, {gap:.2} m",
                    goal.x,
                    goal.y
                );
            }
            let cut = if goal.s > 30.0 && s < 30.0 {
                ((30.0 - here.x) * dy - (0.0 - here.y) * dx).abs() / length
            } else {
                0.0
            };
            assert!(
                cut < 4.0,
                "s {s}: goal ({:.1}, {:.1}) cuts the corner by {cut:.1} m",
                goal.x,
                goal.y
            );
        }
    }

    #[test]
    fn the_car_arrives_a_margin_inside_the_goals_tolerance_short_of_the_routes_end() {
        let mut cfg = route_to(&[], (30.0, 0.0));
        cfg.mission.goal_tolerance = 2.0;
        let arrived = |x: f64| {
            let mut nav = Navigator::new(&cfg).expect("navigator");
            matches!(nav.follow(&car_at(x, 0.0, 0.0, 0.0)), Guidance::Arrived)
        };
        assert!(!arrived(28.0), "on the tolerance's edge by the estimate");
        assert!(
            !arrived(30.0 - 2.0 + ARRIVAL_MARGIN - 0.01),
            "within the margin"
        );
        assert!(
            arrived(30.0 - 2.0 + ARRIVAL_MARGIN + 0.01),
            "inside the margin"
        );
        // At the route's end the whole tolerance counts (the car can go no further).
        let mut nav = Navigator::new(&cfg).expect("navigator");
        let beside = car_at(30.0, 1.99, 0.0, 0.0);
        nav.progress = nav.route.length();
        assert!(matches!(nav.follow(&beside), Guidance::Arrived));
    }

    #[test]
    fn a_route_whose_goal_lies_behind_its_start_is_driven_before_it_arrives() {
        // A lap round a building ending 12 m behind the start on the line it began on,
        // and a switchback (out 34 m, back 8 m over). Judged by the last leg alone the
        // start was past the goal (a stop at t = 0); by the distance alone, backing
        // onto the goal arrived.
        let lap = route_to(
            &[(20.0, 0.0), (20.0, 20.0), (-30.0, 20.0), (-30.0, 0.0)],
            (-12.0, 0.0),
        );
        let switchback = route_to(&[(34.0, 0.0), (34.0, 8.0)], (0.0, 8.0));
        for cfg in [lap, switchback] {
            let mut nav = Navigator::new(&cfg).expect("navigator");
            let start = car_at(0.0, 0.0, 0.0, 0.0);
            let g = replan_and_follow(&mut nav, &start, &[]);
            assert!(matches!(g, Guidance::Drive { .. }), "at the start: {g:?}");
            let on_goal = car_at(cfg.mission.goal_x, cfg.mission.goal_y, 0.0, 0.0);
            let g = nav.follow(&on_goal);
            assert!(
                !matches!(g, Guidance::Arrived),
                "on the goal, route not driven"
            );
            // Along the route: no arrival and no "passed the goal" before its end.
            let mut nav = Navigator::new(&cfg).expect("navigator");
            let length = nav.route.length();
            let (mut s, mut arrived) = (0.0, None);
            while arrived.is_none() && s <= length + 1.0 {
                let p = nav.route.at(s);
                match nav.follow(&car_at(p.x, p.y, p.heading, 0.0)) {
                    Guidance::Arrived => arrived = Some(s),
                    Guidance::Stop { reason } => {
                        assert!(!reason.contains("passed"), "{reason} at {s} of {length} m");
                    }
                    _ => {}
                }
                s += 0.25;
            }
            let at = arrived.expect("arrived at the route's end");
            assert!(
                at >= length - cfg.mission.goal_tolerance,
                "{at} of {length} m"
            );
        }
    }

    #[test]
    fn stops_are_commanded_early_by_what_a_slow_speed_loop_rolls_on() {
        // Approaching the goal at 1.5 m/s, 1.5 m from it: the command lets the car
        // stop there after rolling on for the speed loop's dead time and time constant.
        let speed_at = |dead: f64, constant: f64| {
            let mut cfg = east_to(30.0);
            cfg.vehicle.speed_dead_time_s = dead;
            cfg.vehicle.speed_time_constant_s = constant;
            let mut nav = Navigator::new(&cfg).expect("navigator");
            let pose = car_at(28.5, 0.0, 0.0, 1.5);
            drive_east(&mut nav, 28);
            nav.accept(solve(&nav.request(0.0, &pose, &[])));
            match nav.follow(&pose) {
                Guidance::Drive { speed, .. } => (speed, cfg),
                other => panic!("expected to drive, got {other:?}"),
            }
        };
        let (quick, cfg) = speed_at(0.0, 0.0);
        let (slow, _) = speed_at(0.1, 0.3);
        let to_goal = 1.5;
        let decel = cfg.follower.decel;
        assert!(
            (quick - (2.0 * decel * to_goal).sqrt()).abs() < 1e-9,
            "{quick}"
        );
        let expected = (2.0 * decel * (to_goal - 1.5 * 0.4)).sqrt();
        assert!((slow - expected).abs() < 1e-9, "{slow} vs {expected}");
    }
}
