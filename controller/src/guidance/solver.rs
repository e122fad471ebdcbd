//! Solving a replanning (pure: inline or on a planning thread): the request, the
//! cheapest feasible a6 within the steering limit, the best-scoring pace around moving
//! obstacles, the local goal before its detours, and the outcome with its record.

use super::align::Align;
use super::error::ReplanError;
use super::frame::PathFrame;
use super::pacing::{Pacing, sweep};
use crate::planner::{self, Interval, PlanOptions, PlanProblem, Trajectory};

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

/// One replanning to do: the problem in the planning frame and the steering limit.
#[derive(Clone, Debug)]
pub struct PlanRequest {
    pub time: f64,
    pub problem: PlanProblem,
    /// Road-wheel angle a planned path may use, radians.
    pub steer_limit: f64,
    pub(super) frame: PathFrame,
    /// Problems towards other local goals (with their frames), tried in order when
    /// `problem` has no feasible path.
    pub detours: Vec<(PlanProblem, PathFrame)>,
    /// Set when moving obstacles are in view: the paces to try.
    pub pacing: Option<Pacing>,
    /// Set when the car heads too far from the line: turn towards the goal first.
    pub align: Option<Align>,
}

/// A finished replanning: the path (None when no feasible path exists) and its
/// record, or why the planner refused the problem.
#[derive(Clone, Debug)]
pub struct PlanOutcome {
    pub time: f64,
    /// The frame it was planned in.
    pub frame: PathFrame,
    pub result: Result<(Option<Trajectory>, PlanRecord), ReplanError>,
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
    let towards = |problem: &PlanProblem, frame: PathFrame| PlanOutcome {
        time: req.time,
        frame,
        result: solve_towards(req, problem, &frame),
    };
    let no_path = |outcome: &PlanOutcome| matches!(outcome.result, Ok((None, _)));
    // The local goal, then the detours in order: the first with a feasible path (or
    // the planner's refusal); with none, the local goal's outcome.
    let nominal = towards(&req.problem, req.frame);
    if !no_path(&nominal) {
        return nominal;
    }
    for (problem, frame) in &req.detours {
        let outcome = towards(problem, *frame);
        if !no_path(&outcome) {
            return outcome;
        }
    }
    nominal
}

/// One local goal's planning problem solved (see [`solve`]).
fn solve_towards(
    req: &PlanRequest,
    p: &PlanProblem,
    frame: &PathFrame,
) -> Result<(Option<Trajectory>, PlanRecord), ReplanError> {
    let Some(pacing) = &req.pacing else {
        let chosen = solve_one(p, req.steer_limit)?;
        return Ok(record(req.time, frame, chosen, false));
    };
    let span = p.goal.x - p.state.x;
    let line = p.reference_line().map_err(ReplanError::ReferenceLine)?;
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
fn solve_one(problem: &PlanProblem, steer_limit: f64) -> Result<Option<Chosen>, ReplanError> {
    let step =
        planner::plan_with(problem, &PlanOptions::default()).map_err(ReplanError::Planner)?;
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
    let line = planner::ReferenceLine::new(0.0, 0.0, problem.goal.x, 0.0)
        .map_err(ReplanError::ReferenceLine)?;
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
