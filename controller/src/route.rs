//! The mission as a route: the start, the waypoints in order, and the goal, joined by
//! straight legs. Guidance plans towards local goals on it (a receding horizon) and
//! measures the car's progress along it.

use firmware_bridge::geodesy::Datum;
use serde::{Deserialize, Serialize};
use ugv_fields::{FieldError, FieldPath, angle_deg, coordinate, positive_up_to};

/// Where to go: the route from `start` through `waypoints` (in order) to `goal`; its
/// legs are the reference the planner keeps close to (the paper's L: one leg, start
/// to goal, without waypoints).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Mission {
    pub datum: Datum,
    pub start_x: f64,
    pub start_y: f64,
    /// Points to pass in order before the goal (`[[mission.waypoints]]`).
    pub waypoints: Vec<Waypoint>,
    pub goal_x: f64,
    pub goal_y: f64,
    /// Heading at the goal, degrees CCW from East; default: along the line.
    pub goal_heading_deg: Option<f64>,
    /// Distance from the goal at which the mission is complete, metres.
    pub goal_tolerance: f64,
    /// Speed limit on the last leg (into the goal), m/s.
    pub goal_speed_limit: Option<f64>,
}

impl Default for Mission {
    fn default() -> Self {
        Mission {
            datum: Datum::default(),
            start_x: 0.0,
            start_y: 0.0,
            waypoints: Vec::new(),
            goal_x: 30.0,
            goal_y: 15.0,
            goal_heading_deg: None,
            goal_tolerance: 1.0,
            goal_speed_limit: None,
        }
    }
}

/// A point of the route the car must pass, before the goal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    pub x: f64,
    pub y: f64,
    /// Local goals placed within this distance of the waypoint (along the route) are
    /// moved onto it, so a plan passes through it; the simulator's verdict counts the
    /// waypoint passed once the car's progress along the route comes this near it,
    /// metres.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Heading a plan ending on the waypoint arrives with, degrees CCW from East;
    /// default: along the route there.
    #[serde(default)]
    pub heading_deg: Option<f64>,
    /// Speed limit on the leg that ends at this waypoint, m/s.
    #[serde(default)]
    pub speed_limit: Option<f64>,
}

fn default_tolerance() -> f64 {
    2.0
}

/// The route's polyline with the arc length at each vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    points: Vec<(f64, f64)>,
    /// Arc length at each point (0 at the start).
    arc: Vec<f64>,
    /// Per point after the start: snapping tolerance, heading (radians), and the speed
    /// limit of the leg ending there.
    ends: Vec<(f64, Option<f64>, Option<f64>)>,
}

/// A place on the route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoutePoint {
    /// Arc length from the start, metres.
    pub s: f64,
    pub x: f64,
    pub y: f64,
    /// The route's heading there (of the leg it lies on), radians CCW from East.
    pub heading: f64,
}

impl Route {
    /// The mission's route: start, waypoints, goal (a start-goal mission is one leg).
    pub fn new(m: &Mission) -> Route {
        let mut points = vec![(m.start_x, m.start_y)];
        let mut ends = Vec::new();
        for w in &m.waypoints {
            points.push((w.x, w.y));
            ends.push((
                w.tolerance,
                w.heading_deg.map(f64::to_radians),
                w.speed_limit,
            ));
        }
        points.push((m.goal_x, m.goal_y));
        ends.push((
            m.goal_tolerance,
            m.goal_heading_deg.map(f64::to_radians),
            m.goal_speed_limit,
        ));
        let mut arc = vec![0.0];
        for w in points.windows(2) {
            let last = arc.last().copied().unwrap_or(0.0);
            arc.push(last + (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1));
        }
        Route { points, arc, ends }
    }

    /// Total length, metres.
    pub fn length(&self) -> f64 {
        self.arc.last().copied().unwrap_or(0.0)
    }

    /// Arc length where the last leg (into the goal) begins, metres.
    pub fn last_leg_start(&self) -> f64 {
        self.arc.iter().rev().nth(1).copied().unwrap_or(0.0)
    }

    /// The arc length at each vertex, 0 at the start, the length at the goal.
    pub fn arc(&self) -> &[f64] {
        &self.arc
    }

    /// The vertices, start first, goal last.
    pub fn points(&self) -> &[(f64, f64)] {
        &self.points
    }

    fn leg_of(&self, s: f64) -> usize {
        let legs = self.points.len() - 1;
        (0..legs)
            .find(|&i| s <= self.arc[i + 1])
            .unwrap_or(legs - 1)
    }

    /// The point at arc length `s` (clamped to the route).
    pub fn at(&self, s: f64) -> RoutePoint {
        let s = s.clamp(0.0, self.length());
        let i = self.leg_of(s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = self.arc[i + 1] - self.arc[i];
        let f = if len > 0.0 {
            (s - self.arc[i]) / len
        } else {
            0.0
        };
        RoutePoint {
            s,
            x: a.0 + f * (b.0 - a.0),
            y: a.1 + f * (b.1 - a.1),
            heading: (b.1 - a.1).atan2(b.0 - a.0),
        }
    }

    /// The car's progress: the arc length of the nearest route point to (x, y) among
    /// those from `from - back` to `from + ahead` (progress only moves on, within a
    /// window, so a route that doubles back is not short-cut).
    pub fn project(&self, x: f64, y: f64, from: f64, back: f64, ahead: f64) -> f64 {
        let (lo, hi) = ((from - back).max(0.0), (from + ahead).min(self.length()));
        let mut best = (f64::INFINITY, from.clamp(0.0, self.length()));
        for i in 0..self.points.len() - 1 {
            let (s0, s1) = (self.arc[i], self.arc[i + 1]);
            if s1 < lo || s0 > hi || s1 <= s0 {
                continue;
            }
            let (a, b) = (self.points[i], self.points[i + 1]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let t = (((x - a.0) * dx + (y - a.1) * dy) / (s1 - s0).powi(2)).clamp(0.0, 1.0);
            let s = (s0 + t * (s1 - s0)).clamp(lo, hi);
            let p = self.at(s);
            let d = (p.x - x).hypot(p.y - y);
            if d < best.0 {
                best = (d, s);
            }
        }
        best.1
    }

    /// A local goal placed at `s`: moved onto a route vertex (a waypoint or the goal)
    /// within that vertex's tolerance of it, and the heading to arrive with there (the
    /// vertex's own if given, else the route's).
    pub fn local_goal(&self, s: f64) -> RoutePoint {
        for (i, &(tolerance, heading, _)) in self.ends.iter().enumerate() {
            let at = self.arc[i + 1];
            if (s - at).abs() <= tolerance || (i + 1 == self.ends.len() && s >= at) {
                let p = self.at(at);
                return RoutePoint {
                    heading: heading.unwrap_or(p.heading),
                    ..p
                };
            }
        }
        self.at(s)
    }

    /// The speed limit of the leg at arc length `s`, if it has one.
    pub fn speed_limit(&self, s: f64) -> Option<f64> {
        self.ends[self.leg_of(s.clamp(0.0, self.length()))].2
    }
}

/// Most waypoints in a mission.
const MAX_WAYPOINTS: usize = 1_000;

/// Check a route's waypoints, `at` naming the list (`mission.waypoints`,
/// `waypoints`): coordinates, tolerance (0-50 m), heading, speed limit (0 to
/// `max_speed`), and every point at least 1 m from the one before it (the start
/// before the first, the goal after the last: `goal_at` names the goal's field).
pub fn check_waypoints(
    at: &FieldPath,
    waypoints: &[Waypoint],
    start: (f64, f64),
    goal: (f64, f64),
    goal_at: &FieldPath,
    max_speed: f64,
) -> Result<(), FieldError> {
    if waypoints.len() > MAX_WAYPOINTS {
        return Err(FieldError::new(
            at.clone(),
            format!(
                "has {} waypoints, at most {MAX_WAYPOINTS} are allowed",
                waypoints.len()
            ),
        ));
    }
    let mut previous = start;
    for (i, w) in waypoints.iter().enumerate() {
        let at = at.index(i);
        coordinate(&at.key("x"), w.x)?;
        coordinate(&at.key("y"), w.y)?;
        positive_up_to(&at.key("tolerance"), w.tolerance, 50.0, "m")?;
        if let Some(h) = w.heading_deg {
            angle_deg(&at.key("heading_deg"), h)?;
        }
        if let Some(v) = w.speed_limit {
            positive_up_to(
                &at.key("speed_limit"),
                v,
                max_speed,
                "m/s (the vehicle's max_speed)",
            )?;
        }
        if (w.x - previous.0).hypot(w.y - previous.1) < 1.0 {
            return Err(FieldError::new(
                at.key("x"),
                "must be at least 1 m from the point before it on the route",
            ));
        }
        previous = (w.x, w.y);
    }
    if (goal.0 - previous.0).hypot(goal.1 - previous.1) < 1.0 {
        return Err(FieldError::new(
            goal_at.clone(),
            "the goal must be at least 1 m from the point before it on the route",
        ));
    }
    Ok(())
}

/// The goal is not reached where the car starts: the mission is complete within
/// `tolerance` of the goal wherever the car is (guidance measures the straight
/// distance, whatever the route), so the start must lie farther than that from it.
/// `at` names the tolerance's field.
pub fn check_goal_not_at_start(
    at: &FieldPath,
    tolerance: f64,
    start: (f64, f64),
    goal: (f64, f64),
) -> Result<(), FieldError> {
    let distance = (goal.0 - start.0).hypot(goal.1 - start.1);
    if distance > tolerance {
        return Ok(());
    }
    Err(FieldError::new(
        at.clone(),
        format!(
            "{tolerance} m reaches the start: the goal is {distance:.3} m from it, so it would be reached at t = 0 with a path of 0 m; it must be below the start-to-goal distance"
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l_route() -> Route {
        let m = Mission {
            start_x: 0.0,
            start_y: 0.0,
            waypoints: vec![Waypoint {
                x: 20.0,
                y: 0.0,
                tolerance: 2.0,
                heading_deg: None,
                speed_limit: Some(1.0),
            }],
            goal_x: 20.0,
            goal_y: -30.0,
            ..Mission::default()
        };
        Route::new(&m)
    }

    #[test]
    fn arc_length_points_and_headings_along_an_l() {
        let r = l_route();
        assert_eq!(r.length(), 50.0);
        let p = r.at(10.0);
        assert!((p.x - 10.0).abs() < 1e-12 && p.y.abs() < 1e-12 && p.heading.abs() < 1e-12);
        let q = r.at(30.0);
        assert!((q.x - 20.0).abs() < 1e-12 && (q.y + 10.0).abs() < 1e-12);
        assert!(
            (q.heading + std::f64::consts::FRAC_PI_2).abs() < 1e-12,
            "south"
        );
        assert_eq!(r.at(99.0).s, 50.0);
        assert_eq!(r.speed_limit(5.0), Some(1.0));
        assert_eq!(r.speed_limit(25.0), None);
    }

    #[test]
    fn progress_is_the_nearest_point_within_the_window() {
        let r = l_route();
        assert!((r.project(8.0, 1.5, 0.0, 2.0, 30.0) - 8.0).abs() < 1e-12);
        // Beside the second leg, but the window ahead ends before it.
        assert!((r.project(21.0, -10.0, 0.0, 2.0, 15.0) - 15.0).abs() < 1e-12);
        assert!((r.project(21.0, -10.0, 18.0, 2.0, 30.0) - 30.0).abs() < 1e-12);
    }

    #[test]
    fn local_goals_snap_to_waypoints_and_the_goal() {
        let r = l_route();
        let w = r.local_goal(18.5);
        assert_eq!((w.x, w.y, w.s), (20.0, 0.0, 20.0));
        let free = r.local_goal(15.0);
        assert_eq!((free.x, free.y), (15.0, 0.0));
        let g = r.local_goal(49.5);
        assert_eq!((g.x, g.y), (20.0, -30.0));
        assert_eq!(r.local_goal(80.0).s, 50.0);
    }

    #[test]
    fn waypoints_are_checked_with_their_field() {
        let ok = |ws: &[Waypoint], goal: (f64, f64)| {
            check_waypoints(
                &FieldPath::of(&["waypoints"]),
                ws,
                (0.0, 0.0),
                goal,
                &FieldPath::of(&["goal", "x"]),
                6.7,
            )
        };
        let w = Waypoint {
            x: 20.0,
            y: 0.0,
            tolerance: 2.0,
            heading_deg: None,
            speed_limit: None,
        };
        assert!(ok(std::slice::from_ref(&w), (20.0, 10.0)).is_ok());
        let e = ok(
            &[
                w.clone(),
                Waypoint {
                    x: 20.5,
                    ..w.clone()
                },
            ],
            (20.0, 10.0),
        )
        .expect_err("too close");
        assert_eq!(e.path.to_string(), "waypoints[1].x");
        let e = ok(
            &[Waypoint {
                speed_limit: Some(9.0),
                ..w.clone()
            }],
            (20.0, 10.0),
        )
        .expect_err("too fast");
        assert_eq!(e.path.to_string(), "waypoints[0].speed_limit");
        let e = ok(
            &[Waypoint {
                tolerance: f64::NAN,
                ..w.clone()
            }],
            (20.0, 10.0),
        )
        .expect_err("NaN");
        assert_eq!(e.path.to_string(), "waypoints[0].tolerance");
        let e = ok(std::slice::from_ref(&w), (20.0, 0.5)).expect_err("goal on the waypoint");
        assert_eq!(e.path.to_string(), "goal.x");
    }
}
