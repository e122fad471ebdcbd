//! Where a replanning aims: the local goal `horizon_m` along the route from the car's
//! progress, moved on along the route or back towards the car until it and its
//! approach are clear of every inflated static obstacle, and the detours tried when it
//! has no feasible path: local goals shifted sideways or at half the distance, ordered
//! by their stated cost.

use super::footprint::Footprint;
use super::frame::wrap;
use crate::config::PlannerConfig;
use crate::perception::distance_to_segment;
use crate::planner::Obstacle;
use crate::route::{Route, RoutePoint};

/// Step of the search for a clear local goal along the route, metres.
const LOCAL_GOAL_STEP: f64 = 1.0;
/// Sideways shifts of a detour's local goal, metres (negative: right).
const DETOUR_SHIFTS: [f64; 7] = [0.0, -1.5, 1.5, -3.0, 3.0, -4.5, 4.5];
/// Most detours tried per replanning.
pub(super) const MAX_DETOURS: usize = 8;

/// Whether `p` lies outside every static obstacle grown by `r0`.
pub(super) fn clear_of(p: &RoutePoint, obstacles: &[Obstacle], r0: f64) -> bool {
    obstacles
        .iter()
        .filter(|o| o.vx == 0.0 && o.vy == 0.0)
        .all(|o| (o.x - p.x).hypot(o.y - p.y) > o.radius + r0)
}

/// What a local goal must be clear of every static obstacle by: the planning circle of
/// radius `r0` (the car's circle plus its margin) around the rear axle, on the goal and
/// on the route before it; in a passage also the car's rectangle at the goal, with the
/// route's heading there.
#[derive(Clone, Copy, Debug)]
pub(super) struct Clearance {
    pub r0: f64,
    pub footprint: Option<Footprint>,
}

impl Clearance {
    /// The planning circle alone (it contains the footprint).
    pub fn circle(r0: f64) -> Clearance {
        Clearance {
            r0,
            footprint: None,
        }
    }

    /// Whether the car at `g` clears every static obstacle.
    fn goal_clear(&self, g: &RoutePoint, obstacles: &[Obstacle]) -> bool {
        clear_of(g, obstacles, self.r0)
            && self
                .footprint
                .is_none_or(|f| f.clear_at(g.x, g.y, g.heading, obstacles))
    }
}

/// The stretch of route before a local goal that must be clear of obstacles, metres.
const LOCAL_GOAL_APPROACH: f64 = 5.0;
/// A local goal's heading in its frame is kept within this (y(x) cannot arrive
/// steeper), radians.
pub(super) const MAX_GOAL_HEADING: f64 = 1.2;
/// A local goal before the goal arrives within this of its chord, so that round a
/// corner the car turns over several replannings instead of at once, radians.
pub(super) const MAX_LOCAL_HEADING: f64 = 0.5;

/// The local goal on `route` from progress `s`: `horizon_m` further along the route
/// (the goal once that near), moved on along the route, or else back towards the car,
/// until it and the route before it are clear ([`Clearance`]) and, round a corner, the
/// straight line to it too (back towards the car first when only the nominal one's
/// line is not); the nominal one when none is (the planner then finds no path, and the car
/// stops).
pub(super) fn local_goal(
    route: &Route,
    pc: &PlannerConfig,
    clearance: &Clearance,
    s: f64,
    obstacles: &[Obstacle],
) -> RoutePoint {
    let end = route.length();
    let nominal = (s + pc.horizon_m).min(end);
    // The route's last LOCAL_GOAL_APPROACH before the goal is clear too, so a plan
    // can arrive on it with its heading.
    let clear = |g: &RoutePoint| {
        let n = (LOCAL_GOAL_APPROACH / LOCAL_GOAL_STEP) as usize;
        clearance.goal_clear(g, obstacles)
            && (1..=n)
                .map(|k| route.at((g.s - k as f64 * LOCAL_GOAL_STEP).max(s)))
                .all(|p| clear_of(&p, obstacles, clearance.r0))
    };
    // Round a corner, the goal is one the car can see: the straight line to it from
    // the route at `s` clear too. A goal far along the next leg pulled the path across
    // the corner's inside, into the trees standing there, and the car came to the
    // corner heading away from it; one further on still, whose line passes inside the
    // trees, took the car 12 m off the route. So a nominal goal clear but out of sight
    // is brought nearer, towards the corner, before one further on is tried.
    let here = route.at(s);
    let in_sight =
        |g: &RoutePoint| !turns(route, s, g.s) || chord_clear(&here, g, obstacles, clearance.r0);
    let steps = ((end - nominal) / LOCAL_GOAL_STEP).ceil() as usize;
    let back = ((pc.horizon_m - pc.horizon_min_m).max(0.0) / LOCAL_GOAL_STEP) as usize;
    let on = (0..=steps).map(|i| (nominal + i as f64 * LOCAL_GOAL_STEP).min(end));
    let nearer = (1..=back)
        .map(|i| nominal - i as f64 * LOCAL_GOAL_STEP)
        .filter(|&g| g > s);
    let first = route.local_goal(nominal);
    let order: Vec<f64> = if clear(&first) && !in_sight(&first) {
        nearer.chain(on).collect()
    } else {
        on.chain(nearer).collect()
    };
    order
        .into_iter()
        .map(|g| route.local_goal(g))
        .find(|g| clear(g) && in_sight(g))
        .unwrap_or_else(|| route.local_goal(nominal))
}

/// A route heading that turns by more than this from progress `s` is a corner for
/// [`local_goal`], radians.
const CORNER_TURN: f64 = 0.5;

/// Whether the route turns a corner between `s0` and `s1`: the heading of a leg
/// between them more than [`CORNER_TURN`] from its heading at `s0`.
fn turns(route: &Route, s0: f64, s1: f64) -> bool {
    let h0 = route.at(s0).heading;
    let (arc, points) = (route.arc(), route.points());
    arc.windows(2)
        .zip(points.windows(2))
        .filter(|(ends, _)| ends[1] > s0 && ends[0] < s1)
        .any(|(_, leg)| {
            let h = (leg[1].1 - leg[0].1).atan2(leg[1].0 - leg[0].0);
            wrap(h - h0).abs() > CORNER_TURN
        })
}

/// Whether the straight line from `a` to `b` keeps `r0` clear of every static obstacle.
fn chord_clear(a: &RoutePoint, b: &RoutePoint, obstacles: &[Obstacle], r0: f64) -> bool {
    obstacles
        .iter()
        .filter(|o| o.vx == 0.0 && o.vy == 0.0)
        .all(|o| distance_to_segment([o.x, o.y], [a.x, a.y], [b.x, b.y]) > o.radius + r0)
}

/// `base` moved `shift` metres to its left (negative: right).
fn shifted(base: &RoutePoint, shift: f64) -> RoutePoint {
    RoutePoint {
        x: base.x - shift * base.heading.sin(),
        y: base.y + shift * base.heading.cos(),
        ..*base
    }
}

/// Local goals to pass slower traffic on a lane `lane` metres to the left of the route
/// (negative: right): the first local goal and the route's point at half its distance,
/// shifted onto the lane, each clear ([`Clearance`]).
pub(super) fn pass_goals(
    route: &Route,
    clearance: &Clearance,
    s: f64,
    first: &RoutePoint,
    lane: f64,
    obstacles: &[Obstacle],
) -> Vec<RoutePoint> {
    let half = route.at(s + (first.s - s) / 2.0);
    [*first, half]
        .iter()
        .map(|base| shifted(base, lane))
        .filter(|g| clearance.goal_clear(g, obstacles))
        .collect()
}

/// Step of the search for how far aside a stand to give way at lies, metres.
const YIELD_STEP: f64 = 0.1;
/// The farthest a stand to give way at lies aside of the route, metres.
const YIELD_MAX_SHIFT: f64 = 3.0;
/// Stands to give way at keep this much short of the farthest clear one, nearest it
/// first, so that the path there, its nose turned towards the side, still clears the
/// obstacles beside it, metres.
pub(super) const YIELD_SLACKS: [f64; 3] = [0.15, 0.3, 0.45];

/// Stands to give way to oncoming traffic at: the route's point `run` ahead of
/// progress `s`, moved to `side` (+1 left, -1 right) as far as the car, with the
/// route's heading, still clears every static obstacle there and at the route's points
/// a quarter, half and three quarters of the way ([`Clearance`]; with the car's
/// rectangle: as far aside as the footprint, not the planning circle, allows), up to
/// `YIELD_MAX_SHIFT`, less each of `YIELD_SLACKS`; and that farthest distance aside.
/// None when the route's point itself is not clear.
pub(super) fn yield_goals(
    route: &Route,
    clearance: &Clearance,
    s: f64,
    run: f64,
    side: f64,
    obstacles: &[Obstacle],
) -> Option<(f64, Vec<RoutePoint>)> {
    let along = |j: u32| route.at((s + run * f64::from(j) / 4.0).min(route.length()));
    let steps = (YIELD_MAX_SHIFT / YIELD_STEP).round() as usize;
    let base = along(4);
    // As far aside as is clear along the way there (what lies beyond the laser's
    // reach, perception cannot say).
    let farthest = (0..=steps)
        .map(|k| YIELD_STEP * k as f64)
        .take_while(|&d| {
            (1..=4).all(|j| clearance.goal_clear(&shifted(&along(j), side * d), obstacles))
        })
        .last()?;
    let goals = YIELD_SLACKS
        .iter()
        .filter(|&&slack| slack < farthest)
        .map(|slack| shifted(&base, side * (farthest - slack)))
        .collect();
    Some((farthest, goals))
}

/// Local goals to try when the first has no feasible path (detours): the first
/// local goal shifted sideways by 1.5, 3 and 4.5 m, and the route's point at half
/// its distance, unshifted and shifted the same; each clear ([`Clearance`], the goal
/// itself); at most `MAX_DETOURS`. The order is the stated cost, and the first
/// with a feasible path wins: the least lateral shift, then the farther goal, then
/// right before left.
pub(super) fn detours(
    route: &Route,
    pc: &PlannerConfig,
    clearance: &Clearance,
    s: f64,
    first: &RoutePoint,
    obstacles: &[Obstacle],
) -> Vec<RoutePoint> {
    let half = route.at(s + (first.s - s) / 2.0);
    let mut tries: Vec<(f64, RoutePoint)> = Vec::new();
    for (i, base) in [*first, half].into_iter().enumerate() {
        if base.s - s < pc.horizon_min_m / 2.0 {
            continue;
        }
        for shift in DETOUR_SHIFTS {
            if i == 0 && shift == 0.0 {
                continue;
            }
            let g = shifted(&base, shift);
            if clearance.goal_clear(&g, obstacles) {
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
