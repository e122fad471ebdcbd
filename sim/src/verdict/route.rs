//! Whether a run drove the scenario's route: every waypoint passed in order, and how
//! far along the route the car got.
//!
//! Progress is the arc length of the rear axle's place on the route (its nearest
//! point), followed from the start within a window as the controller follows it, so
//! that a route which doubles back, or whose goal lies near or behind its start, is not
//! short-cut: backing from the start onto a goal behind it makes no progress. A
//! waypoint is passed once the progress has come within its `tolerance`
//! (`[[waypoints]] tolerance`, default 2 m) of it along the route: the distance,
//! measured along the route, within which the controller moves its local goals onto
//! it. Not the straight distance: the receding horizon cuts a route's corners (by
//! 4-8 m at the suite's 45-90 degree corners with the 20 m horizon), which the closest
//! approach to each waypoint and the farthest the car strayed from the route report.
//! Passed in order, since progress only moves on; the goal counts as reached only once
//! every waypoint is passed.

use serde::Serialize;
use ugv_controller::route::{Mission, Route};

use crate::scenario::Scenario;

/// How far back and ahead of its last value progress is looked for at each physics
/// step, metres (the car moves centimetres in one).
const PROGRESS_BACK: f64 = 2.0;
const PROGRESS_AHEAD: f64 = 5.0;

/// One waypoint of the route, as the run passed it or not.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WaypointPass {
    pub x: f64,
    pub y: f64,
    /// Its arc length along the route, metres.
    pub at_m: f64,
    /// How near it, along the route, the progress must come to pass it, metres.
    pub tolerance: f64,
    /// When the progress came that near, simulated seconds.
    pub passed_s: Option<f64>,
    /// The rear axle's closest approach to it over the run, metres.
    pub closest_m: f64,
}

/// How much of the route a run drove.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RouteReport {
    /// The route's length from the start through the waypoints to the goal, metres.
    pub length_m: f64,
    /// The furthest progress along the route, metres.
    pub progress_m: f64,
    /// `progress_m` over `length_m`.
    pub progress_fraction: f64,
    /// The farthest the rear axle strayed from its place on the route, metres.
    pub max_off_route_m: f64,
    pub waypoints: Vec<WaypointPass>,
}

impl RouteReport {
    /// Every waypoint passed in order.
    pub fn driven(&self) -> bool {
        self.waypoints.iter().all(|w| w.passed_s.is_some())
    }

    /// Why the route does not count as driven, naming the missed waypoints (numbered
    /// from 1, as the scenario lists them); `None` when it was driven.
    pub fn failure(&self) -> Option<String> {
        let missed: Vec<String> = self
            .waypoints
            .iter()
            .enumerate()
            .filter(|(_, w)| w.passed_s.is_none())
            .map(|(i, w)| {
                format!(
                    "waypoint {} ({:.1}, {:.1}) missed ({:.1} m along the route, closest {:.2} m)",
                    i + 1,
                    w.x,
                    w.y,
                    w.at_m,
                    w.closest_m
                )
            })
            .collect();
        if missed.is_empty() {
            return None;
        }
        Some(format!(
            "route not driven: {}; {:.1} of {:.1} m along it ({:.0} %)",
            missed.join(", "),
            self.progress_m,
            self.length_m,
            self.progress_fraction * 100.0
        ))
    }
}

/// Follows a run along its scenario's route.
#[derive(Clone, Debug)]
pub struct RouteCheck {
    route: Route,
    /// Where progress was last found (the window's centre), metres.
    progress: f64,
    /// The furthest it reached, metres.
    furthest: f64,
    max_off_route: f64,
    /// The waypoints passed so far (the next one to pass is this index).
    next: usize,
    waypoints: Vec<WaypointPass>,
}

impl RouteCheck {
    /// The check of `scenario`'s route; `None` for a start-goal scenario (no
    /// waypoints), whose goal counts as before.
    pub fn new(scenario: &Scenario) -> Option<RouteCheck> {
        if scenario.waypoints.is_empty() {
            return None;
        }
        let route = Route::new(&Mission {
            start_x: scenario.start.x,
            start_y: scenario.start.y,
            waypoints: scenario.waypoints.clone(),
            goal_x: scenario.goal.x,
            goal_y: scenario.goal.y,
            goal_tolerance: scenario.goal.tolerance,
            ..Mission::default()
        });
        let waypoints = scenario
            .waypoints
            .iter()
            .zip(route.arc().iter().skip(1))
            .map(|(w, &at_m)| WaypointPass {
                x: w.x,
                y: w.y,
                at_m,
                tolerance: w.tolerance,
                passed_s: None,
                closest_m: f64::INFINITY,
            })
            .collect();
        Some(RouteCheck {
            route,
            progress: 0.0,
            furthest: 0.0,
            max_off_route: 0.0,
            next: 0,
            waypoints,
        })
    }

    /// The rear axle at (`x`, `y`) at `time`.
    pub fn update(&mut self, time: f64, x: f64, y: f64) {
        self.progress = self
            .route
            .project(x, y, self.progress, PROGRESS_BACK, PROGRESS_AHEAD);
        self.furthest = self.furthest.max(self.progress);
        let on = self.route.at(self.progress);
        self.max_off_route = self.max_off_route.max((on.x - x).hypot(on.y - y));
        for w in &mut self.waypoints {
            w.closest_m = w.closest_m.min((w.x - x).hypot(w.y - y));
        }
        while let Some(w) = self.waypoints.get_mut(self.next)
            && self.furthest >= w.at_m - w.tolerance
        {
            w.passed_s = Some(time);
            self.next += 1;
        }
    }

    /// Every waypoint passed in order: the goal may count as reached.
    pub fn driven(&self) -> bool {
        self.next == self.waypoints.len()
    }

    pub fn report(&self) -> RouteReport {
        let length_m = self.route.length();
        RouteReport {
            length_m,
            progress_m: self.furthest,
            progress_fraction: if length_m > 0.0 {
                self.furthest / length_m
            } else {
                1.0
            },
            max_off_route_m: self.max_off_route,
            waypoints: self.waypoints.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ugv_controller::route::Waypoint;

    /// A switchback: out 34 m east, 8 m north, back west to (0, 8).
    fn switchback() -> Scenario {
        let at = |x, y| Waypoint {
            x,
            y,
            tolerance: 2.0,
            heading_deg: None,
            speed_limit: None,
        };
        let mut sc = Scenario {
            waypoints: vec![at(34.0, 0.0), at(34.0, 8.0)],
            ..Scenario::default()
        };
        (sc.goal.x, sc.goal.y) = (0.0, 8.0);
        sc
    }

    /// `check` fed the rear axle along `points` every 0.1 m, one second a step.
    fn drive(check: &mut RouteCheck, points: &[(f64, f64)]) {
        let mut t = 0.0;
        for w in points.windows(2) {
            let (dx, dy) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
            let steps = (dx.hypot(dy) / 0.1).ceil();
            let mut k = 0.0;
            while k <= steps {
                check.update(t, w[0].0 + dx * k / steps, w[0].1 + dy * k / steps);
                (k, t) = (k + 1.0, t + 1.0);
            }
        }
    }

    #[test]
    fn waypoints_are_passed_by_progress_along_the_route_in_order() {
        // Straight from the start onto the goal 8 m beside it: nothing passed.
        let mut check = RouteCheck::new(&switchback()).expect("a route");
        drive(&mut check, &[(0.0, 0.0), (0.0, 8.0)]);
        assert!(!check.driven());
        let r = check.report();
        assert_eq!((r.length_m, r.progress_m), (76.0, 0.0));
        let failure = r.failure().expect("missed");
        assert_eq!(
            failure,
            "route not driven: waypoint 1 (34.0, 0.0) missed (34.0 m along the route, closest 34.00 m), waypoint 2 (34.0, 8.0) missed (42.0 m along the route, closest 34.00 m); 0.0 of 76.0 m along it (0 %)"
        );
        // Beside the second waypoint without the first leg driven: not passed.
        let mut check = RouteCheck::new(&switchback()).expect("a route");
        check.update(0.0, 34.0, 7.0);
        assert_eq!(check.report().waypoints[1].passed_s, None);
        // Along the route, its corners cut (3.6 m from each) as a receding horizon cuts them.
        let mut check = RouteCheck::new(&switchback()).expect("a route");
        drive(
            &mut check,
            &[
                (0.0, 0.0),
                (30.0, 0.0),
                (32.0, 4.0),
                (30.0, 8.0),
                (0.0, 8.0),
            ],
        );
        let r = check.report();
        assert!(check.driven() && r.failure().is_none(), "{r:?}");
        let first = r.waypoints[0].passed_s;
        assert!(
            first.is_some_and(|t| t > 300.0 && t < 346.0),
            "on the cut, after the straight's 300 steps: {first:?}"
        );
        assert!((r.waypoints[0].closest_m - 3.578).abs() < 0.01, "{r:?}");
        // Equally far from both legs on the cut: (31.33, 2.67).
        assert!((r.max_off_route_m - 8.0 / 3.0).abs() < 0.01, "{r:?}");
        assert!((r.progress_fraction - 1.0).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn a_start_goal_scenario_has_no_route_to_check() {
        assert!(RouteCheck::new(&Scenario::default()).is_none());
    }
}
