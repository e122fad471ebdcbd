//! The verdict of a route: a run counts as reaching the goal only once the route was
//! driven (every waypoint passed in order), not whenever the rear axle comes within
//! the goal's tolerance.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used)]

use firmware_bridge::CanPort;
use firmware_bridge::can::membus::MemBus;
use ugv_sim::Mode;
use ugv_sim::run::{Outcome, Sim};
use ugv_sim::scenario::Scenario;
use ugv_sim::verdict::Verdict;

fn suite(file: &str) -> Scenario {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite");
    Scenario::load(&dir.join(file)).expect("suite scenario")
}

/// `scenario` run with the car moved by hand to `at(t)` every step (no controller),
/// to its time limit or until the simulator ends the run: the outcome, and the
/// verdict on the report.
fn moved(scenario: &Scenario, at: impl Fn(f64) -> (f64, f64)) -> (Outcome, Verdict) {
    let bus = MemBus::new();
    let mut sim = Sim::new(
        scenario.clone(),
        CanPort::new(bus.endpoint(), "test"),
        CanPort::new(bus.endpoint(), "test"),
    );
    let outcome = loop {
        let now = sim.next_tick() as f64 * sim.dt();
        (sim.vehicle.x, sim.vehicle.y) = at(now);
        if let Some(o) = sim.step(now, 0.0).expect("step") {
            break o;
        }
    };
    let report = sim.report(outcome.clone());
    (outcome, Verdict::judge(Mode::Sil, scenario, report, None))
}

#[test]
fn backing_from_the_start_onto_a_goal_behind_it_does_not_reach_the_goal() {
    // The lap round the building: its goal lies 12 m behind the start. Backing 12 m
    // (1 m/s) puts the rear axle on the goal without driving the route.
    let mut sc = suite("55-lap-round-building.toml");
    sc.sim.time_limit_s = 20.0;
    let (outcome, v) = moved(&sc, |t| (-t.min(12.0), 0.0));
    assert_eq!(
        outcome,
        Outcome::TimeLimit { time: 20.0 },
        "{:?}",
        v.failures
    );
    assert!(v.report.distance_to_goal < 1e-9, "on the goal");
    assert!(!v.passed && !v.goal_reached);
    let route = v.report.route.as_ref().expect("a route report");
    assert_eq!((route.progress_m, route.length_m), (0.0, 136.0));
    assert_eq!(
        v.failures,
        [
            "goal not reached (0.00 m away)",
            "route not driven: waypoint 1 (20.0, 0.0) missed (20.0 m along the route, closest 20.00 m), \
             waypoint 2 (20.0, 24.0) missed (44.0 m along the route, closest 31.24 m), \
             waypoint 3 (-30.0, 24.0) missed (94.0 m along the route, closest 30.00 m), \
             waypoint 4 (-30.0, 0.0) missed (118.0 m along the route, closest 18.00 m); \
             0.0 of 136.0 m along it (0 %)"
        ]
    );
    // A report that says the goal was reached (as the run's end used to) is judged
    // by its route all the same.
    let report = v.report.clone();
    let claimed = ugv_sim::run::RunReport {
        outcome: Outcome::GoalReached { time: 12.0 },
        ..report
    };
    let v = Verdict::judge(Mode::Sil, &sc, claimed, None);
    assert!(!v.passed && !v.goal_reached, "{:?}", v.failures);
    assert!(
        v.failures
            .iter()
            .any(|f| f.contains("waypoint 4 (-30.0, 0.0) missed"))
    );
}

#[test]
fn driving_the_route_reaches_the_goal_and_a_start_goal_verdict_has_no_route() {
    // The switchback driven along its route with both corners cut 3.6 m (as the
    // receding horizon cuts them): the goal counts, at the goal.
    let sc = suite("56-switchback.toml");
    let path = [
        (0.0, 0.0),
        (30.0, 0.0),
        (32.0, 4.0),
        (30.0, 8.0),
        (2.0, 8.0),
    ];
    let (outcome, v) = moved(&sc, |t| along(&path, t));
    let Outcome::GoalReached { time } = outcome else {
        panic!("{outcome:?}: {:?}", v.failures);
    };
    assert!(v.passed && v.goal_reached, "{:?}", v.failures);
    assert!((time - (along_length(&path) - 1.0)).abs() < 0.01, "{time}");
    let route = v.report.route.as_ref().expect("a route report");
    assert!(
        route.waypoints.iter().all(|w| w.passed_s.is_some()),
        "{route:?}"
    );
    // Without waypoints the report and the verdict say nothing of a route.
    let mut plain = sc.clone();
    plain.waypoints.clear();
    let (_, v) = moved(&plain, |t| along(&path, t));
    let json = serde_json::to_string(&v).expect("verdict");
    assert!(
        v.report.route.is_none() && !json.contains("\"route\""),
        "{json}"
    );
}

/// The point `t` metres along the polyline `path` (its end beyond it).
fn along(path: &[(f64, f64)], t: f64) -> (f64, f64) {
    let mut left = t;
    for w in path.windows(2) {
        let len = (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
        if left <= len {
            let f = left / len;
            return (
                w[0].0 + f * (w[1].0 - w[0].0),
                w[0].1 + f * (w[1].1 - w[0].1),
            );
        }
        left -= len;
    }
    path[path.len() - 1]
}

fn along_length(path: &[(f64, f64)]) -> f64 {
    path.windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum()
}
