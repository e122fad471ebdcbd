//! Traffic the planning discs alone got wrong: oncoming carts with no room to keep
//! right (a hedge on the right), and a cart overtaking the car.

use super::*;
use crate::planner::Obstacle;

/// The default configuration with the goal at (goal_x, 0): a straight mission east.
fn east_to(goal_x: f64) -> ControllerConfig {
    let mut cfg = ControllerConfig::default();
    cfg.mission.goal_x = goal_x;
    cfg.mission.goal_y = 0.0;
    cfg
}

fn car_at(x: f64, y: f64, v: f64) -> Pose {
    Pose {
        x,
        y,
        theta: 0.0,
        v,
        phi: 0.0,
    }
}

/// A navigator for `cfg` with its progress brought along the route to x = `to`
/// metre by metre, as following does.
fn navigator_at(cfg: &ControllerConfig, to: i32) -> Navigator {
    let mut nav = super::tests::seen_round(Navigator::new(cfg).expect("navigator"));
    for x in 0..=to {
        nav.follow(&car_at(f64::from(x), 0.0, 0.0));
    }
    nav
}

fn circle(x: f64, y: f64, radius: f64, vx: f64) -> Obstacle {
    Obstacle {
        x,
        y,
        radius,
        vx,
        vy: 0.0,
    }
}

/// A hedge 2.9 m right of the route (its face at 2.6 m), as perception reports it:
/// circles of 0.25 m every 0.8 m, within 8 m of (x, 0).
fn hedge_near(x: f64) -> Vec<Obstacle> {
    (0..60)
        .map(|k| 6.0 + 0.8 * f64::from(k))
        .filter(|hx| (hx - x).abs() < 8.0)
        .map(|hx| circle(hx, -2.6, 0.25, 0.0))
        .collect()
}

/// The near side of a cart (2.4 m long) at `x`, 1.45 m left of the route, coming
/// the other way at 1.5 m/s: its face 0.85 m left of the route, as circles.
fn oncoming_cart(x: f64) -> Vec<Obstacle> {
    (0..4)
        .map(|k| circle(x - 1.2 + 0.8 * f64::from(k), 0.85, 0.25, -1.5))
        .collect()
}

/// One replanning from `pose` among `obstacles` at 0 s.
fn plan(nav: &Navigator, pose: &Pose, obstacles: &[Obstacle]) -> (Option<Trajectory>, PlanRecord) {
    solve(&nav.request(0.0, pose, obstacles))
        .result
        .expect("planned")
}

#[test]
fn with_no_room_to_keep_right_the_car_pulls_over_and_never_plans_into_the_oncoming_lane() {
    let cfg = east_to(60.0);
    let nav = navigator_at(&cfg, 12);
    let pose = car_at(12.0, 0.0, 2.0);
    let mut world = hedge_near(pose.x);
    world.extend(oncoming_cart(20.0));
    let (trajectory, record) = plan(&nav, &pose, &world);
    // Never into the cart's lane (its face 0.85 m left: the car's left side, 0.6 m
    // left of its axle, stays right of it), never across to the far side.
    let widest_left = record
        .path
        .iter()
        .map(|p| p[1])
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(widest_left <= 0.05, "into the oncoming lane: {widest_left}");
    // A slow path to a stand on the right, as far as the car's rectangle clears the
    // hedge (0.25 m margin: the axle 1.45 m right of the route at most).
    assert!(trajectory.is_some() && record.yielding, "{record:?}");
    let end = record.path.last().expect("a path");
    assert!(end[1] < -0.9 && end[1] > -1.5, "{end:?}");
}

/// The near side of a cart (2.4 m long) centred at `x`, 2.3 m left of the route, going
/// the car's way at 3.5 m/s: its face 1.7 m left of the route, as circles.
fn overtaking_cart(x: f64) -> Vec<Obstacle> {
    (0..4)
        .map(|k| circle(x - 1.2 + 0.8 * f64::from(k), 1.7, 0.25, 3.5))
        .collect()
}

#[test]
fn a_car_overtaken_on_its_left_holds_its_line_and_speed() {
    let cfg = east_to(80.0);
    let nav = navigator_at(&cfg, 10);
    let pose = car_at(10.0, 0.0, 2.0);
    // Behind the car, beside it, and just ahead of its nose: no braking, no swerve.
    for x in [6.0, 10.0, 13.0] {
        let (trajectory, record) = plan(&nav, &pose, &overtaking_cart(x));
        assert!(trajectory.is_some(), "cart at {x}: {record:?}");
        let pace = record.pace.expect("a pace");
        assert!(
            pace >= cfg.planner.cruise_speed - 1e-9,
            "cart at {x}: {pace}"
        );
        assert!(
            !record.passage && !record.yielding && !record.escape,
            "{record:?}"
        );
        let widest = record.path.iter().map(|p| p[1].abs()).fold(0.0, f64::max);
        assert!(widest < 0.3, "cart at {x}: holds its line, {widest}");
    }
    // The same cart at the car's speed is planned round as before: the car may not
    // stay beside it (its circle overlaps the planning circle all along).
    let abreast: Vec<Obstacle> = overtaking_cart(13.0)
        .into_iter()
        .map(|c| Obstacle { vx: 2.0, ..c })
        .collect();
    let (_, record) = plan(&nav, &pose, &abreast);
    assert!(
        !record.feasible || record.passage || record.pace.is_some_and(|p| p < 2.0),
        "{record:?}"
    );
}

#[test]
fn a_car_with_no_way_forward_does_not_back_into_traffic_beside_or_behind_it() {
    let cfg = east_to(80.0);
    // A post 2.5 m ahead of the nose on the line: no path with no steering, and the
    // car stands.
    let post = circle(14.5, 0.0, 0.5, 0.0);
    let standing = car_at(10.0, 0.0, 0.0);
    let stuck = |obstacles: &[Obstacle]| {
        let mut nav = navigator_at(&cfg, 10);
        let mut req = nav.request(0.0, &standing, obstacles);
        req.steer_limit = 1e-6;
        req.detours.clear();
        req.passages.clear();
        req.yields.clear();
        // Recovery by reversal, as when no manoeuvre is found either.
        req.manoeuvre = None;
        let outcome = solve(&req);
        assert!(
            matches!(outcome.result, Ok((None, _))),
            "{:?}",
            outcome.result
        );
        nav.accept(outcome);
        nav.recover(2.0, &standing, obstacles);
        nav
    };
    // Alone with the post, the car backs off.
    assert!(stuck(&[post]).reversing.is_some());
    // With a cart passing on its left, or coming up behind it, it waits instead.
    let mut beside = overtaking_cart(10.0);
    beside.push(post);
    assert!(stuck(&beside).reversing.is_none());
    let mut behind = overtaking_cart(-4.0);
    behind.push(post);
    assert!(stuck(&behind).reversing.is_none());
}
