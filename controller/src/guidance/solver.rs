//! Solving a replanning (pure: inline or on a planning thread): the request, the
//! cheapest feasible a6 within the steering limit, the best-scoring pace around moving
//! obstacles, the local goal before its detours, and the outcome with its record.

use super::align::Align;
use super::error::ReplanError;
use super::footprint::Footprint;
use super::frame::PathFrame;
use super::lanes::{self, Lanes};
use super::manoeuvre::{Field, Manoeuvre, ManoeuvreRequest, Planned};
use super::pacing::{Pacing, sweep};
use crate::planner::{self, Interval, Obstacle, PlanOptions, PlanProblem, Trajectory};

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
    /// Planned through a passage narrower than the planning circle: with the car's
    /// width as its circle and the rectangle checked along the path; driven slowly.
    #[serde(default)]
    pub passage: bool,
    /// An obstacle stands on the mission's goal (within the car's half width plus the
    /// passage margin of it): the car can only stop short of it.
    #[serde(default)]
    pub goal_blocked: bool,
    /// No feasible path was found, and the path being followed was kept: it still
    /// clears every obstacle now reported ([`PlanRequest::current_holds`]).
    #[serde(default)]
    pub kept: bool,
    /// A detour passing slower traffic ([`Pass`]).
    #[serde(default)]
    pub passing: bool,
    /// No path was feasible, and braking would have left the car standing in a moving
    /// obstacle's track: a path among the static obstacles whose rectangle clears every
    /// moving one in space-time, driven at its pace ([`escape`]).
    #[serde(default)]
    pub escape: bool,
    /// Oncoming traffic and no room to pass it on the side kept to: a slow path to a
    /// stand as far to that side as the car's rectangle allows, there to wait
    /// ([`PlanRequest::yields`]).
    #[serde(default)]
    pub yielding: bool,
    /// A passage whose narrow part lies ahead of the car's nose (a static obstacle
    /// there within the planning circle of the path): entered at the passage speed.
    /// One whose narrow part is only beside the car (something that appeared there)
    /// is eased into at the follower's deceleration.
    #[serde(default)]
    pub narrow_ahead: bool,
    /// Made by the manoeuvre planner (no polynomial path was feasible): its segments
    /// and cusps; `path` is the manoeuvre's. None for the paper's polynomial.
    #[serde(default)]
    pub manoeuvre: Option<ManoeuvreRecord>,
}

/// A manoeuvre in a replanning's record.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ManoeuvreRecord {
    /// Expansions the search took (0: the manoeuvre being followed was kept).
    pub expansions: usize,
    /// It reaches its goal; else it goes as far towards it as what the car knows
    /// allows, and the search goes on from there.
    #[serde(default)]
    pub complete: bool,
    /// The search found none (`path` is empty).
    #[serde(default)]
    pub failed: bool,
    /// Where the car changes direction, world frame.
    pub cusps: Vec<[f64; 2]>,
    /// The spans of `path` (first index, one past the last) driven backwards.
    pub reverse: Vec<[usize; 2]>,
    /// An escape out of a place the car was hemmed in at the manoeuvre margin: the
    /// narrower margin it keeps, metres (driven at a crawl).
    #[serde(default)]
    pub escape_margin: Option<f64>,
    /// The manoeuvre itself, for the navigator to follow (not in the trace: `path`,
    /// `reverse` and `cusps` say what it is).
    #[serde(skip)]
    pub plan: Option<Manoeuvre>,
}

impl ManoeuvreRecord {
    fn new(planned: Planned, expansions: usize) -> ManoeuvreRecord {
        let Planned {
            manoeuvre: m,
            complete,
            escape_margin,
        } = planned;
        let segments = m.segments();
        ManoeuvreRecord {
            expansions,
            complete,
            failed: false,
            escape_margin,
            cusps: segments
                .iter()
                .skip(1)
                .map(|r| {
                    let p = &m.points[r.start - 1];
                    [p.x, p.y]
                })
                .collect(),
            reverse: segments
                .iter()
                .filter(|r| !m.points[r.start].forward)
                .map(|r| [r.start, r.end])
                .collect(),
            plan: Some(m),
        }
    }
}

/// Passing slower traffic going the car's way: problems towards local goals on a lane
/// clear of it (with their frames), and the paces they may take (every one, not held
/// to the leader's).
#[derive(Clone, Debug)]
pub struct Pass {
    pub goals: Vec<(PlanProblem, PathFrame)>,
    /// dx/dt to try, m/s, fastest first.
    pub speeds: Vec<f64>,
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
    /// How far perception reports static obstacles, metres: a detour's path passes the
    /// obstacles in view only within it ([`in_sight`]).
    pub sight: f64,
    /// Problems through passages (with their frames), tried in order when neither
    /// `problem` nor a detour has a feasible path: planned with the car's half width
    /// plus the passage margin as the circle, each candidate path checked with
    /// `footprint`.
    pub passages: Vec<(PlanProblem, PathFrame)>,
    /// With oncoming traffic in view, problems towards a stand on the side kept to (as
    /// far to that side as the car's rectangle clears the static obstacles), planned
    /// like the passages, tried at the slowest pace first when nothing else is feasible:
    /// the car pulls over and waits there for the traffic to go by.
    pub yields: Vec<(PlanProblem, PathFrame)>,
    /// The car's rectangle, grown by the passage margin.
    pub footprint: Footprint,
    /// An obstacle stands on the mission's goal ([`PlanRecord::goal_blocked`]).
    pub goal_blocked: bool,
    /// Set when moving obstacles are in view: the paces to try.
    pub pacing: Option<Pacing>,
    /// Set behind traffic going the car's way with the route long enough left.
    pub pass: Option<Pass>,
    /// Set when the car heads too far from the line: turn towards the goal first.
    pub align: Option<Align>,
    /// The path being followed may be kept if this replanning finds none: planned
    /// among static obstacles, the car on it, and the rest of it clear of every
    /// obstacle now reported (`Navigator::current_path_holds`).
    pub current_holds: bool,
    /// The manoeuvre planner's search, when no polynomial path is feasible, or the
    /// check of the manoeuvre being followed; None with traffic near the car.
    pub manoeuvre: Option<ManoeuvreRequest>,
    /// The manoeuvre being followed is on a forward segment with at most a short nudge
    /// after it ([`super::manoeuvre::Following::may_hand_back`]): a feasible polynomial path
    /// takes over from it.
    pub hand_back: bool,
    /// The car standing among static obstacles: the world [`super::Reuse`] compares.
    pub standing: Option<super::reuse::Standing>,
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
/// detours' problems in their order ([`PlanRequest::detours`]), then the passages'
/// ([`PlanRequest::passages`], whose paths must also clear the car's rectangle), and
/// the first with one is taken, in its own frame ([`PlanOutcome::frame`]).
pub fn solve(req: &PlanRequest) -> PlanOutcome {
    if let Some(m) = &req.manoeuvre
        && m.following.is_some()
    {
        return solve_following(req, m);
    }
    // Turning towards the line first is more turning than the polynomial allows: a
    // manoeuvre, where one is found, does it round the obstacles ([`Align`] turns on
    // the spot's circle only).
    if req.align.is_some()
        && let Some(m) = &req.manoeuvre
        && let Ok(found) = manoeuvre(req, m, &m.field())
    {
        return found;
    }
    let mut outcome = solve_polynomial(req);
    let stuck = matches!(&outcome.result, Ok((None, r))
        if !r.kept && !r.goal_blocked && r.align.is_none());
    if stuck && let Some(m) = &req.manoeuvre {
        match manoeuvre(req, m, &m.field()) {
            Ok(found) => return found,
            Err(failed) => failed_search(&mut outcome, failed),
        }
    }
    outcome
}

/// The polynomial's `outcome` with the record of a manoeuvre search that found none.
fn failed_search(outcome: &mut PlanOutcome, failed: ManoeuvreRecord) {
    if let Ok((_, r)) = &mut outcome.result {
        r.manoeuvre = Some(failed);
    }
}

/// [`solve`] while a manoeuvre is followed: kept while the car's rectangle clears the
/// rest of it (on a forward segment with at most a short nudge after it, a feasible
/// polynomial path takes over; a partial one driven on is searched again,
/// [`ManoeuvreRequest::look_again`], and a complete manoeuvre found takes over); else
/// searched anew from where the car is, and with none found, the polynomial's outcome.
fn solve_following(req: &PlanRequest, m: &ManoeuvreRequest) -> PlanOutcome {
    if m.following_holds() {
        if req.hand_back {
            let outcome = solve_polynomial(req);
            if matches!(&outcome.result, Ok((Some(_), r)) if !r.passage) {
                return outcome;
            }
        }
        // A partial manoeuvre driven on: a complete one found from here takes over.
        let mut looked = 0;
        if m.look_again {
            let (found, expansions) = m.plan(&m.field());
            match found {
                Ok(planned) if planned.complete => {
                    return found_manoeuvre(req, planned, expansions);
                }
                _ => looked = expansions.max(1),
            }
        }
        let (_, mut record) = record(req.time, &req.frame, None, false);
        record.kept = true;
        record.feasible = true;
        record.manoeuvre = Some(ManoeuvreRecord {
            expansions: looked,
            ..ManoeuvreRecord::default()
        });
        return PlanOutcome {
            time: req.time,
            frame: req.frame,
            result: Ok((None, record)),
        };
    }
    manoeuvre(req, m, &m.field()).unwrap_or_else(|failed| {
        let mut outcome = solve_polynomial(req);
        if let Ok((_, r)) = &mut outcome.result {
            r.kept = false;
        }
        failed_search(&mut outcome, failed);
        outcome
    })
}

/// A manoeuvre search: the outcome with it, or the record of a search that found none.
fn manoeuvre(
    req: &PlanRequest,
    m: &ManoeuvreRequest,
    field: &Field,
) -> Result<PlanOutcome, ManoeuvreRecord> {
    let (found, expansions) = m.plan_or_escape(field);
    let Ok(planned) = found else {
        return Err(ManoeuvreRecord {
            expansions,
            failed: true,
            ..ManoeuvreRecord::default()
        });
    };
    Ok(found_manoeuvre(req, planned, expansions))
}

/// The outcome of a search that found `planned` after `expansions`.
fn found_manoeuvre(req: &PlanRequest, planned: Planned, expansions: usize) -> PlanOutcome {
    let (_, mut record) = record(req.time, &req.frame, None, false);
    record.feasible = true;
    record.goal_blocked = req.goal_blocked;
    record.path = planned
        .manoeuvre
        .points
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    record.manoeuvre = Some(ManoeuvreRecord::new(planned, expansions));
    PlanOutcome {
        time: req.time,
        frame: req.frame,
        result: Ok((None, record)),
    }
}

/// The paper's polynomial: [`solve_in_order`], and whether the path being followed is
/// kept when it finds none.
fn solve_polynomial(req: &PlanRequest) -> PlanOutcome {
    let mut outcome = solve_in_order(req);
    if let Ok((trajectory, record)) = &mut outcome.result {
        record.goal_blocked = req.goal_blocked;
        // A replanning on the edge of feasibility (the steering it needs just over the
        // limit) must not stop a car on a path that still holds.
        record.kept = trajectory.is_none()
            && record.align.is_none()
            && !req.goal_blocked
            && req.current_holds;
    }
    outcome
}

/// [`solve`]: alignment, or the local goal, its detours and the passages in order.
fn solve_in_order(req: &PlanRequest) -> PlanOutcome {
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
    let towards =
        |problem: &PlanProblem, frame: PathFrame, footprint: Option<&Footprint>| PlanOutcome {
            time: req.time,
            frame,
            result: solve_towards(req, problem, &frame, footprint, None),
        };
    let no_path = |outcome: &PlanOutcome| matches!(outcome.result, Ok((None, _)));
    // The local goal, then the detours in order: the first with a feasible path (or
    // the planner's refusal); with none, the local goal's outcome.
    let nominal = towards(&req.problem, req.frame, None);
    if let Some(pacing) = &req.pacing
        && let Some(outcome) = give_way_or_pass(req, pacing, &nominal, towards)
    {
        return outcome;
    }
    if !no_path(&nominal) {
        return nominal;
    }
    for (problem, frame) in &req.detours {
        let outcome = towards(problem, *frame, None);
        let seen = match &outcome.result {
            Ok((Some(t), _)) => in_sight(problem, t, req.sight),
            _ => true,
        };
        if !no_path(&outcome) && seen {
            return outcome;
        }
    }
    for (problem, frame) in &req.passages {
        let mut outcome = towards(problem, *frame, Some(&req.footprint));
        if !no_path(&outcome) {
            if let Ok((Some(t), record)) = &mut outcome.result {
                record.passage = true;
                let reach = problem.state.x + req.footprint.front;
                record.narrow_ahead = narrow_ahead(problem, t, reach, req.problem.vehicle_radius);
            }
            return outcome;
        }
    }
    if let Some(pacing) = &req.pacing
        && let Some(outcome) = give_way(req, pacing).or_else(|| escape(req, pacing))
    {
        return outcome;
    }
    nominal
}

/// How long a car braked to a stand watches a moving obstacle's track, seconds:
/// standing where one comes within this is no yielding.
const STOP_WATCH_S: f64 = 5.0;

/// With no path feasible around moving obstacles the car brakes to a stand, yielding.
/// Where a moving obstacle's constant-velocity track crosses the place it would stand
/// (braking straight on at the pacing's deceleration, the car's rectangle grown by the
/// passage margin, within [`STOP_WATCH_S`]), standing is no yielding: drive on. The
/// local goal and its detours, in order, are planned among the static obstacles alone
/// (the planning circle), at each pace fastest first, and the first path whose
/// rectangle clears every moving obstacle in space-time (swept over the pace's time
/// margin, as in planning) is taken. The planning circle, centred on the rear axle,
/// keeps 2.3 m from a walker beside the car that the rectangle passes 1.5 m clear of;
/// a walker converging from beside or behind can leave no circle-clear path while the
/// rectangle is clear. None when standing is safe, or no such path exists.
pub(super) fn escape(req: &PlanRequest, pacing: &Pacing) -> Option<PlanOutcome> {
    let s = &req.problem.state;
    let coast = pacing.speed_now.powi(2) / (2.0 * pacing.decel.max(MIN_DECEL));
    let stand = (
        s.x + coast * s.theta.cos(),
        s.y + coast * s.theta.sin(),
        s.theta,
    );
    if moving(&req.problem)
        .iter()
        .all(|o| req.footprint.clear_of_track(stand, o, 0.0, STOP_WATCH_S))
    {
        return None;
    }
    let goals =
        std::iter::once((&req.problem, req.frame)).chain(req.detours.iter().map(|(q, f)| (q, *f)));
    let (chosen, frame) = rectangle_path(req, pacing, goals, &pacing.speeds, false)?;
    let (trajectory, mut record) = record(req.time, &frame, Some(chosen), true);
    record.escape = true;
    Some(PlanOutcome {
        time: req.time,
        frame,
        result: Ok((trajectory, record)),
    })
}

/// Giving way to oncoming traffic when nothing else is feasible (the local goal, its
/// detours and the passages all refused, every path into the traffic's lane among
/// them): towards a stand on the side kept to ([`PlanRequest::yields`]), planned like
/// a passage (the car's rectangle clearing the static obstacles) with the rectangle
/// clearing every moving obstacle in space-time and keeping out of traffic's lanes,
/// at the fastest pace that has such a path (the car must be aside before the traffic
/// arrives). Driven at its pace and stopped at its end (the follower's stop within the
/// room left), where the car stands and waits; the next replannings find the way on
/// once the traffic has gone by. None when there is no stand to go to (the car is
/// there already), or no such path.
fn give_way(req: &PlanRequest, pacing: &Pacing) -> Option<PlanOutcome> {
    let goals = req.yields.iter().map(|(q, f)| (q, *f));
    let (chosen, frame) = rectangle_path(req, pacing, goals, &pacing.speeds, true)?;
    let (trajectory, mut record) = record(req.time, &frame, Some(chosen), true);
    record.yielding = true;
    Some(PlanOutcome {
        time: req.time,
        frame,
        result: Ok((trajectory, record)),
    })
}

/// The moving obstacles of a problem.
fn moving(q: &PlanProblem) -> Vec<Obstacle> {
    q.obstacles
        .iter()
        .filter(|o| o.vx != 0.0 || o.vy != 0.0)
        .copied()
        .collect()
}

/// Whether `o` (a moving obstacle of a problem whose car is at `q.state`) overtakes
/// the car or moves away from its path ([`lanes::overtaking`]).
fn overtakes(req: &PlanRequest, pacing: &Pacing, q: &PlanProblem, o: &Obstacle) -> bool {
    let f = &req.footprint;
    lanes::overtaking(
        o,
        &q.state,
        pacing.speed_now,
        f.front + pacing.circle,
        f.half_width + f.margin,
    )
}

/// The lanes of the traffic meeting or overtaking the car in problem `q` ([`Lanes`]).
fn traffic_lanes(req: &PlanRequest, pacing: &Pacing, q: &PlanProblem) -> Lanes {
    let tracks: Vec<Obstacle> = moving(q)
        .into_iter()
        .filter(|o| lanes::oncoming(o, &q.state) || overtakes(req, pacing, q, o))
        .collect();
    Lanes::new(&tracks, &q.state, &req.footprint)
}

/// The first path, over `goals` in order and each at the paces of `speeds` in order,
/// planned among the static obstacles alone (with the problem's circle), whose
/// rectangle clears every moving obstacle in space-time (swept over the pace's time
/// margin, as in planning) and keeps out of traffic's lanes ([`Lanes`]); with its
/// frame. Giving way (`aside`), the rectangle must also clear the static obstacles (as
/// through a passage), and a moving obstacle whose swept track the car already stands
/// within the margin of is clipped to just clear of it: the car may only move away.
fn rectangle_path<'a>(
    req: &PlanRequest,
    pacing: &Pacing,
    goals: impl Iterator<Item = (&'a PlanProblem, PathFrame)>,
    speeds: &[f64],
    aside: bool,
) -> Option<(Chosen, PathFrame)> {
    for (q, frame) in goals {
        let lanes = traffic_lanes(req, pacing, q);
        let mut statics = q.clone();
        statics.obstacles.retain(|o| o.vx == 0.0 && o.vy == 0.0);
        let start = (q.state.x, q.state.y, q.state.theta);
        let fits = aside.then(|| {
            req.footprint
                .clip_to_start(start.0, start.1, start.2, &statics.obstacles)
        });
        let span = q.goal.x - q.state.x;
        for &pace in speeds {
            statics.t_f = q.t_k + span / pace;
            let margin = pacing.time_margin + pacing.schedule_slip(pace);
            let tracks = match aside {
                true => req
                    .footprint
                    .clip_tracks_to_start(start, &moving(q), margin),
                false => moving(q),
            };
            let clear = |t: &Trajectory| {
                fits.as_ref().is_none_or(|o| req.footprint.path_clear(t, o))
                    && req.footprint.path_clear_of_moving(t, &tracks, margin)
                    && lanes.keeps_out(t, margin)
            };
            if let Ok(Some(chosen)) = solve_one(&statics, req.steer_limit, &clear) {
                return Some((chosen, frame));
            }
        }
    }
    None
}

/// The least deceleration the stand is reckoned with, m/s^2 (a configured 0 would put
/// it at infinity).
const MIN_DECEL: f64 = 0.1;

/// Below this fraction of the fastest pace the local goal's path is slowed by traffic,
/// and the detours are weighed against it.
const SLOWED: f64 = 0.8;

/// A swerve past oncoming traffic wider than this on the side not kept to is weighed
/// against the detours, metres.
const WRONG_SIDE: f64 = 0.5;

/// With moving obstacles in view and the local goal's path slowed below [`SLOWED`] of
/// the fastest pace, or swerving past oncoming traffic on the side not kept to (more
/// than [`WRONG_SIDE`]), or none feasible: the local goal and every detour, each at its
/// best pace, and the one with the least [`Pacing::score`] wins, its deviation taken
/// from the local goal's line and weighted by [`Pacing::side_weight`] (giving way to
/// the side kept to, passing slower traffic where that beats following it). None when
/// the local goal is not slowed, or nothing is feasible.
fn give_way_or_pass(
    req: &PlanRequest,
    pacing: &Pacing,
    nominal: &PlanOutcome,
    towards: impl Fn(&PlanProblem, PathFrame, Option<&Footprint>) -> PlanOutcome,
) -> Option<PlanOutcome> {
    let fastest = pacing.speeds.iter().copied().fold(0.0, f64::max);
    // The path's deviations from the local goal's line, at 21 points.
    let deviations = |o: &PlanOutcome| -> Option<Vec<f64>> {
        let Ok((Some(t), _)) = &o.result else {
            return None;
        };
        let p = t.path();
        Some(
            p.stations(20)
                .map(|x| {
                    let (wx, wy) = o.frame.to_world(x, p.y(x));
                    req.frame.to_path(wx, wy).1
                })
                .collect(),
        )
    };
    if let Some(pass) = &req.pass
        && let Some(outcome) = pass_by(req, pacing, pass, &deviations)
    {
        return Some(outcome);
    }
    let weigh = match &nominal.result {
        Ok((Some(_), r)) => {
            r.pace.is_some_and(|p| p < SLOWED * fastest)
                || deviations(nominal).is_some_and(|ys| {
                    ys.iter()
                        .any(|&y| y.abs() > WRONG_SIDE && pacing.side_weight(y) > 1.0)
                })
        }
        Ok((None, _)) => true,
        Err(_) => false,
    };
    if !weigh {
        return None;
    }
    let cost = |o: &PlanOutcome| -> Option<f64> {
        let ys = deviations(o)?;
        let deviation = ys
            .iter()
            .map(|&y| pacing.side_weight(y) * y * y)
            .sum::<f64>()
            / ys.len() as f64;
        let pace = o.result.as_ref().ok().and_then(|r| r.1.pace)?;
        Some(pacing.score(deviation, pace, fastest))
    };
    let mut best: Option<(f64, PlanOutcome)> = cost(nominal).map(|c| (c, nominal.clone()));
    for (problem, frame) in &req.detours {
        let outcome = towards(problem, *frame, None);
        if let Some(c) = cost(&outcome)
            && best.as_ref().is_none_or(|b| c < b.0)
        {
            best = Some((c, outcome));
        }
    }
    best.map(|b| b.1)
}

/// Passing slower traffic ([`Pass`]): the local goals on the pass lane, each at its
/// best pace among every pace, and the one with the least [`Pacing::score`]
/// (deviation from the local goal's line) wins. Behind the leader only the slow paces
/// are feasible and the car pulls out at the leader's pace; beside
/// it the fast ones are, and the car goes by; once the leader is behind it is no
/// traffic, and the next replanning returns to the route. None when no such detour is
/// feasible (the car then follows).
fn pass_by(
    req: &PlanRequest,
    pacing: &Pacing,
    pass: &Pass,
    deviations: &dyn Fn(&PlanOutcome) -> Option<Vec<f64>>,
) -> Option<PlanOutcome> {
    let fastest = pass.speeds.iter().copied().fold(0.0, f64::max);
    let mut best: Option<(f64, PlanOutcome)> = None;
    for (problem, frame) in &pass.goals {
        let outcome = PlanOutcome {
            time: req.time,
            frame: *frame,
            result: solve_towards(req, problem, frame, None, Some(&pass.speeds)),
        };
        let Some(ys) = deviations(&outcome) else {
            continue;
        };
        let deviation = ys.iter().map(|y| y * y).sum::<f64>() / ys.len() as f64;
        let Some(pace) = outcome.result.as_ref().ok().and_then(|r| r.1.pace) else {
            continue;
        };
        let cost = pacing.score(deviation, pace, fastest);
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, outcome));
        }
    }
    let (_, mut outcome) = best?;
    if let Ok((_, record)) = &mut outcome.result {
        record.passing = true;
    }
    Some(outcome)
}

/// One local goal's planning problem solved (see [`solve`]); with a footprint, only
/// paths along which the car's rectangle clears the static obstacles are taken. Around
/// moving obstacles at the paces of `speeds` (fastest first), or else of the request's
/// pacing.
fn solve_towards(
    req: &PlanRequest,
    p: &PlanProblem,
    frame: &PathFrame,
    footprint: Option<&Footprint>,
    speeds: Option<&[f64]>,
) -> Result<(Option<Trajectory>, PlanRecord), ReplanError> {
    let fits = footprint.map(|f| {
        let statics = f.clip_to_start(p.state.x, p.state.y, p.state.theta, &p.obstacles);
        (f, statics)
    });
    let clear = |t: &Trajectory| fits.as_ref().is_none_or(|(f, o)| f.path_clear(t, o));
    if p.goal.x <= p.state.x {
        // The car has turned past the goal (round a hedge's end towards the route's
        // way back): no polynomial leads there (x_f must lie ahead of x_k), so the
        // problem has no path; it is no planner error that stops the car.
        return Ok(record(req.time, frame, None, req.pacing.is_some()));
    }
    let Some(pacing) = &req.pacing else {
        let chosen = solve_one(p, req.steer_limit, &clear)?;
        return Ok(record(req.time, frame, chosen, false));
    };
    let span = p.goal.x - p.state.x;
    let line = p.reference_line().map_err(ReplanError::ReferenceLine)?;
    let speeds = speeds.unwrap_or(&pacing.speeds);
    let fastest = speeds.iter().copied().fold(0.0, f64::max);
    let inflation = (pacing.circle - p.vehicle_radius).max(0.0);
    let start = (p.state.x, p.state.y, p.state.theta);
    let lanes = traffic_lanes(req, pacing, p);
    let mut best: Option<(f64, Chosen)> = None;
    for &pace in speeds {
        // The paces come fastest first, and a slower one loses more time: once that
        // alone scores no better than the best path found, none further on can win.
        if best
            .as_ref()
            .is_some_and(|b| pacing.score(0.0, pace, fastest) >= b.0)
        {
            break;
        }
        let margin = pacing.time_margin + pacing.schedule_slip(pace);
        let mut problem = p.clone();
        problem.t_f = p.t_k + span / pace;
        // Moving obstacles the car is already within the planning circle of (a walker
        // it is passing, or that passes it) are shrunk in the sweep so the car can
        // drive on; shrunk, they no longer keep the nose and the corners clear, so the
        // car's rectangle must then clear their tracks in space-time as well. Traffic
        // overtaking the car is no disc at all: the car holds its line (keeps out of
        // its lane) and its speed.
        let mut near = Vec::new();
        problem.obstacles = p
            .obstacles
            .iter()
            .flat_map(|o| {
                if o.vx == 0.0 && o.vy == 0.0 {
                    return vec![*o];
                }
                if overtakes(req, pacing, p, o) {
                    return Vec::new();
                }
                let inflated = Obstacle {
                    radius: o.radius + inflation,
                    ..*o
                };
                let swept = sweep(&inflated, margin, p.state.x, p.state.y, p.vehicle_radius);
                if swept.iter().any(|c| c.radius < inflated.radius) {
                    near.push(*o);
                }
                swept
            })
            .collect();
        let near = req.footprint.clip_tracks_to_start(start, &near, margin);
        let clear = |t: &Trajectory| {
            clear(t)
                && (near.is_empty() || req.footprint.path_clear_of_moving(t, &near, margin))
                && lanes.keeps_out(t, margin)
        };
        if let Some(c) = solve_one(&problem, req.steer_limit, &clear)? {
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

/// Whether the path `t` of `problem` passes the static obstacles in view within `sight`
/// of the car (metres): every point of it up to the farthest obstacle's far side (along
/// the frame's x) lies within `sight`. Beyond, perception reports nothing, so a detour
/// swinging wide round the ends of a fence seen at the edge of the sight would pass
/// where the rest of that fence may stand (a gate's posts seen first from 8 m: the
/// detour round them led through the fence beside the gate).
fn in_sight(problem: &PlanProblem, t: &Trajectory, sight: f64) -> bool {
    let (sx, sy) = (problem.state.x, problem.state.y);
    let p = t.path();
    let reach = problem
        .obstacles
        .iter()
        .filter(|o| o.vx == 0.0 && o.vy == 0.0)
        .map(|o| o.x + o.radius)
        .fold(f64::NEG_INFINITY, f64::max)
        .min(p.x_f());
    p.stations(40)
        .take_while(|&x| x <= reach)
        .all(|x| (x - sx).hypot(p.y(x) - sy) <= sight)
}

/// Whether a static obstacle of `problem` lying beyond `reach` (the car's nose, x in
/// the planning frame) comes within the planning circle `r0` of the path `t`: the
/// passage is narrow ahead of the car, not only beside it.
fn narrow_ahead(problem: &PlanProblem, t: &Trajectory, reach: f64, r0: f64) -> bool {
    let p = t.path();
    let points: Vec<(f64, f64)> = p.stations(40).map(|x| (x, p.y(x))).collect();
    problem
        .obstacles
        .iter()
        .filter(|o| o.vx == 0.0 && o.vy == 0.0 && o.x - o.radius > reach)
        .any(|o| {
            points
                .iter()
                .any(|&(x, y)| (x - o.x).hypot(y - o.y) < o.radius + r0)
        })
}

/// The planner's time sampling in guidance: the bare method's 2048 steps per
/// collision window, with 8 extrema refined by golden section, resolve the forbidden
/// intervals far finer than the car follows a path; 256 with the same refinement keep
/// every suite scenario's path within millimetres at an eighth of the cost.
const GUIDANCE_SAMPLING: planner::Sampling = planner::Sampling {
    steps: 256,
    refine_candidates: 8,
};

/// The chosen path of one planning problem: the planner's a6 when its path is within
/// the steering limit (and `clear`: for example, the car's rectangle clears the static
/// obstacles along it), else the cheapest feasible a6 whose path is; None when none.
fn solve_one(
    problem: &PlanProblem,
    steer_limit: f64,
    clear: &dyn Fn(&Trajectory) -> bool,
) -> Result<Option<Chosen>, ReplanError> {
    let options = PlanOptions {
        sampling: GUIDANCE_SAMPLING,
        skip_clearance: true,
        stop_when_infeasible: true,
    };
    let step = planner::plan_with(problem, &options).map_err(ReplanError::Planner)?;
    let projected = step.result.projected_to_boundary;
    let within = !step
        .result
        .max_abs_steering
        .is_some_and(|s| s > steer_limit);
    if within && step.trajectory.as_ref().is_none_or(clear) {
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
    // The problem was validated once, by the planner: each candidate is its path with
    // another a6 (the same as `problem.trajectory(a6)` for a finite a6, and the
    // candidates are finite).
    let Some(base) = step.trajectory.or_else(|| problem.trajectory(0.0).ok()) else {
        return Ok(None);
    };
    // Cheapest first (the cost is a 7-point quadrature); the steering and footprint
    // checks, sampled along the path, only until one passes.
    let mut paths: Vec<(f64, f64, Trajectory)> =
        candidates(step.result.a6_unconstrained, &step.result.feasible_set)
            .into_iter()
            .map(|a6| (a6, base.with_a6(a6)))
            .map(|(a6, t)| (t.path().reference_cost(&line), a6, t))
            .collect();
    paths.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(paths
        .into_iter()
        .find(|(_, _, t)| steer_within(t, steer_limit) && clear(t))
        .map(|(_, a6, trajectory)| Chosen {
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
            p.stations(40)
                .map(|x| {
                    let (wx, wy) = frame.to_world(x, p.y(x));
                    [wx, wy]
                })
                .collect()
        }),
        pace: chosen.as_ref().map(|c| c.trajectory.w1()),
        moving,
        align: None,
        passage: false,
        goal_blocked: false,
        kept: false,
        passing: false,
        escape: false,
        yielding: false,
        narrow_ahead: false,
        manoeuvre: None,
    };
    (chosen.map(|c| c.trajectory), record)
}

/// Maximum steering angle along a path, radians: atan(l kappa) is monotonic, so the
/// angle at the largest |curvature| of 201 samples.
fn max_steer(t: &Trajectory) -> f64 {
    let p = t.path();
    let kappa = (0..=STEER_SAMPLES)
        .map(|j| steer_sample(p, j))
        .fold(0.0, f64::max);
    (p.wheelbase() * kappa).atan()
}

/// Intervals of the samples [`max_steer`] takes along a path.
const STEER_SAMPLES: u32 = 200;

/// |curvature| at sample `j` of [`max_steer`].
fn steer_sample(p: &planner::PolynomialPath, j: u32) -> f64 {
    p.curvature(p.x_k() + p.span() * f64::from(j) / f64::from(STEER_SAMPLES))
        .abs()
}

/// `max_steer(t) <= limit`, stopping at the first sample whose curvature is over the
/// limit's by more than rounding: above `tan(limit) / l (1 + 1e-9)` the angle
/// `atan(l kappa)` is over `limit` whatever the rounding, so the answer is the same as
/// the full maximum's; up to it, the maximum decides exactly as [`max_steer`] does.
fn steer_within(t: &Trajectory, limit: f64) -> bool {
    let p = t.path();
    let l = p.wheelbase();
    let over = if limit > 0.0 && limit < 1.5 {
        limit.tan() / l * (1.0 + 1e-9)
    } else {
        f64::INFINITY
    };
    let mut kappa = 0.0_f64;
    for j in 0..=STEER_SAMPLES {
        let k = steer_sample(p, j);
        if k > over {
            return false;
        }
        kappa = kappa.max(k);
    }
    (l * kappa).atan() <= limit
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
