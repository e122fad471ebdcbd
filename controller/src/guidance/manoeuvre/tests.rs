//! The manoeuvre planner on the tight places it is for.

use super::*;
use std::f64::consts::PI;

const CAR: Footprint = Footprint {
    front: 2.025,
    rear: 0.375,
    half_width: 0.6,
    margin: 0.15,
};

fn settings() -> Settings {
    Settings {
        max_expansions: 40_000,
        ..Settings::default()
    }
}

fn post(x: f64, y: f64, radius: f64) -> Obstacle {
    Obstacle {
        x,
        y,
        radius,
        vx: 0.0,
        vy: 0.0,
    }
}

/// A wall from `a` to `b` as a chain of circles of radius `r`.
fn wall(a: (f64, f64), b: (f64, f64), r: f64) -> Vec<Obstacle> {
    let n = ((b.0 - a.0).hypot(b.1 - a.1) / r).ceil() as usize;
    (0..=n)
        .map(|k| {
            let t = k as f64 / n as f64;
            post(a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t, r)
        })
        .collect()
}

fn request(start: [f64; 3], goal: [f64; 3], obstacles: Vec<Obstacle>) -> ManoeuvreRequest {
    ManoeuvreRequest {
        start,
        goals: vec![Goal {
            pose: goal,
            tol_xy: 0.3,
            tol_theta: 0.2,
        }],
        obstacles,
        footprint: CAR,
        settings: settings(),
        following: None,
        seen: None,
        remembered: Vec::new(),
        look_again: false,
        following_margin: None,
        standing: false,
        escape_margin: 0.05,
    }
}

/// Plan, and check the result: found, every pose clear, ending near the goal.
fn planned(req: &ManoeuvreRequest) -> Manoeuvre {
    let field = req.field();
    let (result, expansions) = req.plan(&field);
    let m = match result {
        Ok(p) if p.complete => p.manoeuvre,
        Ok(_) => panic!("a partial manoeuvre only"),
        Err(e) => panic!("no manoeuvre: {e} after {expansions} expansions"),
    };
    assert!(m.points.iter().all(|p| field.clear(p.pose())));
    let end = m.points[m.points.len() - 1];
    let goal = req.goals[0].pose;
    assert!(
        (end.x - goal[0]).hypot(end.y - goal[1]) <= 0.3 + 1e-6,
        "{end:?}"
    );
    m
}

#[test]
fn an_open_field_is_crossed_forward_without_a_cusp() {
    let m = planned(&request([0.0, 0.0, 0.0], [12.0, 3.0, 0.0], Vec::new()));
    assert_eq!(m.cusps(), 0);
    assert!(m.points.iter().all(|p| p.forward));
    assert!(m.length([0.0, 0.0, 0.0]) < 14.0);
}

#[test]
fn the_end_of_a_dead_end_alley_is_turned_round_in_with_cusps() {
    // A 6 m wide alley, closed 5 m ahead of the car's nose; the goal is behind.
    let mut obstacles = wall((-12.0, 3.0), (7.0, 3.0), 0.2);
    obstacles.extend(wall((-12.0, -3.0), (7.0, -3.0), 0.2));
    obstacles.extend(wall((7.0, -3.0), (7.0, 3.0), 0.2));
    let m = planned(&request([0.0, 0.0, 0.0], [-6.0, 0.0, PI], obstacles));
    assert!(m.cusps() >= 1, "turned round without a cusp");
    assert!(m.points.iter().any(|p| !p.forward));
}

#[test]
fn a_car_parked_nose_in_backs_out_first() {
    // Carts 0.6 m either side, a wall 0.5 m ahead of the nose; the goal behind.
    let mut obstacles = wall((-0.4, 1.35), (2.0, 1.35), 0.15);
    obstacles.extend(wall((-0.4, -1.35), (2.0, -1.35), 0.15));
    obstacles.extend(wall((2.7, -3.0), (2.7, 3.0), 0.15));
    let m = planned(&request([0.0, 0.0, 0.0], [-7.0, 3.0, PI / 2.0], obstacles));
    assert!(!m.points[0].forward, "the first move is not backwards");
}

#[test]
fn a_car_standing_nearer_a_post_than_the_margin_drives_away_from_it() {
    // A thin post (a remembered laser return's size) 0.1 m from the car's left side
    // (the margin is 0.15 m): the search starts (it found nothing, "start blocked",
    // whenever the car stood within the margin plus the start's slack of a centre) and
    // never takes the car nearer the post.
    let p = post(1.0, 0.73, 0.03);
    let m = planned(&request([0.0, 0.0, 0.0], [10.0, 0.0, 0.0], vec![p]));
    let nearest = m
        .points
        .iter()
        .map(|q| CAR.distance(q.x, q.y, q.theta, p.x, p.y) - p.radius)
        .fold(f64::INFINITY, f64::min);
    assert!(nearest >= 0.1 - START_SLACK - 1e-9, "{nearest}");
}

#[test]
fn a_gate_right_after_a_corner_is_entered() {
    // Driving east in a 4 m lane, then a 3.2 m gate in a wall to the north 4 m ahead.
    let mut obstacles = wall((-5.0, -2.0), (12.0, -2.0), 0.2);
    obstacles.extend(wall((-5.0, 2.0), (3.4, 2.0), 0.2));
    obstacles.extend(wall((6.6, 2.0), (12.0, 2.0), 0.2));
    let m = planned(&request([0.0, 0.0, 0.0], [5.0, 7.0, PI / 2.0], obstacles));
    assert!(m.points.iter().any(|p| p.y > 3.0));
}

#[test]
fn an_enclosed_goal_is_unreachable_and_says_so() {
    let mut obstacles = wall((8.0, -3.0), (14.0, -3.0), 0.2);
    obstacles.extend(wall((8.0, 3.0), (14.0, 3.0), 0.2));
    obstacles.extend(wall((8.0, -3.0), (8.0, 3.0), 0.2));
    obstacles.extend(wall((14.0, -3.0), (14.0, 3.0), 0.2));
    let req = request([0.0, 0.0, 0.0], [10.0, 0.0, 0.0], obstacles);
    let (result, _) = req.plan(&req.field());
    assert_eq!(result, Err(Failure::Unreachable));
    // A goal the rectangle cannot stand at is refused before any search.
    let req = request(
        [0.0, 0.0, 0.0],
        [10.0, 0.0, 0.0],
        vec![post(10.5, 0.0, 0.3)],
    );
    assert_eq!(req.plan(&req.field()).0, Err(Failure::GoalBlocked));
}

#[test]
fn a_moving_obstacle_is_kept_clear_of_along_its_way() {
    // A cart crossing 6 m ahead from the right at 1.5 m/s: its swept track blocks the
    // way straight on for the next 3 s.
    let cart = Obstacle {
        vy: 1.5,
        ..post(6.0, -4.0, 0.8)
    };
    let field = request([0.0, 0.0, 0.0], [12.0, 0.0, 0.0], vec![cart]).field();
    assert!(!field.clear([5.0, 0.0, 0.0]));
    assert!(field.clear([0.0, 0.0, 0.0]));
}

#[test]
fn the_search_is_the_same_every_time() {
    let mut obstacles = wall((-12.0, 3.0), (7.0, 3.0), 0.2);
    obstacles.extend(wall((-12.0, -3.0), (7.0, -3.0), 0.2));
    obstacles.extend(wall((7.0, -3.0), (7.0, 3.0), 0.2));
    let req = request([0.0, 0.0, 0.0], [-6.0, 0.0, PI], obstacles);
    let field = req.field();
    assert_eq!(req.plan(&field), req.plan(&field));
}

#[test]
fn goals_on_remembered_returns_are_passed_over_for_the_next_ones() {
    // Three goals ahead stand on returns the laser saw and no longer sees (in the
    // field, not among the obstacles in view); the fourth is clear and is reached.
    let goals = [[8.0, 0.0], [8.0, 1.0], [8.0, -1.0], [11.0, 0.0]];
    let mut req = request([0.0, 0.0, 0.0], [0.0; 3], Vec::new());
    req.goals = goals
        .iter()
        .map(|g| Goal {
            pose: [g[0], g[1], 0.0],
            tol_xy: 0.3,
            tol_theta: 0.2,
        })
        .collect();
    req.remembered = vec![[9.0, 0.0], [9.0, 1.0], [9.0, -1.0]];
    let field = req.field();
    assert!(req.goals[..3].iter().all(|g| !field.clear(g.pose)));
    let (result, _) = req.plan(&field);
    let m = result.expect("a manoeuvre").manoeuvre;
    let end = m.points[m.points.len() - 1];
    assert!((end.x - 11.0).hypot(end.y) <= 0.3 + 1e-6, "{end:?}");
}

#[test]
fn a_partial_manoeuvre_does_not_shuffle_for_the_last_few_decimetres() {
    // The goal is beyond a wall 5 m ahead whose one opening, 3 m to the left, lets the
    // rear axle through (the holonomic way) but not the car: the search ends partial.
    // Nosing up to the opening takes cusps; a partial manoeuvre weighs what they cost
    // against the little they bring nearer.
    let mut obstacles = wall((5.0, -6.0), (5.0, 2.2), 0.2);
    obstacles.extend(wall((5.0, 3.8), (5.0, 8.0), 0.2));
    obstacles.extend(wall((-4.0, -6.0), (5.0, -6.0), 0.2));
    obstacles.extend(wall((-4.0, 8.0), (5.0, 8.0), 0.2));
    obstacles.extend(wall((-4.0, -6.0), (-4.0, 8.0), 0.2));
    let req = request([0.0, 0.0, 0.0], [12.0, 3.0, 0.0], obstacles);
    let field = req.field();
    let (result, _) = req.plan(&field);
    let planned = result.expect("a partial manoeuvre");
    assert!(!planned.complete);
    let m = planned.manoeuvre;
    assert!(m.points.iter().all(|p| field.clear(p.pose())));
    let end = m.points[m.points.len() - 1];
    // Nearer the opening than the start by more than the least progress...
    assert!((end.x - 5.0).hypot(end.y - 3.0) < 5.83 - hybrid::PARTIAL_PROGRESS);
    // ...without shuffling for it (taken nearest the opening at any cost, it backs up
    // to it after a cusp, 8.8 m driven for 5.2 m forward).
    assert_eq!(m.cusps(), 0);
    assert!(m.points.iter().all(|p| p.forward));
}

/// A straight 8 m forward manoeuvre along x from the origin, sampled every 0.1 m.
fn straight_8m() -> Manoeuvre {
    Manoeuvre {
        points: (1..=80)
            .map(|k| PathPoint {
                x: f64::from(k) * 0.1,
                y: 0.0,
                theta: 0.0,
                curvature: 0.0,
                forward: true,
            })
            .collect(),
    }
}

#[test]
fn a_manoeuvre_followed_is_held_while_only_its_far_part_is_blocked() {
    // Following a straight 8 m manoeuvre from its start: a post on it 6 m on (seen from
    // afar, perhaps a few centimetres too big) does not drop it yet; 2 m on, it does.
    let straight = straight_8m();
    let following = |post_x: f64| {
        let mut req = request(
            [0.0, 0.0, 0.0],
            [8.0, 0.0, 0.0],
            vec![post(post_x, 0.0, 0.2)],
        );
        req.following = Some(straight.clone());
        req.following_holds()
    };
    assert!(following(8.5));
    assert!(!following(4.0));
    assert!(following(14.0));
}

#[test]
fn a_manoeuvre_going_on_askew_of_the_standing_car_is_searched_anew() {
    // The car stands 0.15 rad off the heading its next segment begins with (the last
    // one ended askew): it holds while the car rolls on, not once it stands.
    let straight = straight_8m();
    let holds = |heading: f64, standing: bool| {
        let mut req = request([0.0, 0.0, heading], [8.0, 0.0, 0.0], Vec::new());
        req.following = Some(straight.clone());
        req.standing = standing;
        req.following_holds()
    };
    assert!(holds(0.15, false));
    assert!(!holds(0.15, true));
    assert!(holds(0.05, true));
}

/// The car hemmed in at a margin of 0.25 m by four posts 0.2 m clear of its corners,
/// diagonally: every step forward or back passes one nearer than 0.25 m (the posts
/// 0.08 m beside it), none nearer than 0.05 m.
fn hemmed() -> ManoeuvreRequest {
    let d = 0.4 * std::f64::consts::FRAC_1_SQRT_2;
    let posts = [(2.025 + d, 0.6 + d), (-0.375 - d, 0.6 + d)]
        .into_iter()
        .flat_map(|(x, y)| [post(x, y, 0.2), post(x, -y, 0.2)])
        .collect();
    ManoeuvreRequest {
        footprint: Footprint {
            margin: 0.25,
            ..CAR
        },
        ..request([0.0, 0.0, 0.0], [12.0, 0.0, 0.0], posts)
    }
}

#[test]
fn a_car_hemmed_in_at_the_margin_creeps_out_with_a_narrower_one_until_it_clears_again() {
    let req = hemmed();
    let field = req.field();
    let (plain, n) = req.plan(&field);
    assert!(
        matches!(plain, Err(Failure::Exhausted(k)) if k < HEMMED),
        "{plain:?} after {n}"
    );
    let (found, expansions) = req.plan_or_escape(&field);
    let escape = found.expect("an escape");
    assert!(expansions > n);
    let margin = escape.escape_margin.expect("an escape's margin");
    assert!(margin < req.footprint.margin && margin >= req.escape_margin);
    // Every pose keeps the escape's margin from the posts (the brute-force check)...
    let keeps = |p: &PathPoint, m: f64| {
        req.obstacles
            .iter()
            .all(|o| req.footprint.distance(p.x, p.y, p.theta, o.x, o.y) > o.radius + m)
    };
    let points = &escape.manoeuvre.points;
    assert!(points.iter().all(|p| keeps(p, margin)));
    // ... and it ends once the full margin is kept again, over its last 0.4 m.
    assert!(points.len() >= 4 && !escape.complete);
    assert!(points[points.len() - 4..].iter().all(|p| keeps(p, 0.25)));
    assert!(!keeps(&points[0], 0.25));
}

/// A wall across the way, reaching `end` metres either side, with a gap 1.5 m wide: the
/// car (1.2 m) keeps 0.15 m either side, not its 0.25 m margin. The car stands before
/// it, its nose 0.5 m short (as far as partial manoeuvres brought it).
fn gap_in_wall(end: f64) -> ManoeuvreRequest {
    let mut posts = wall((6.0, 0.95), (6.0, end), 0.2);
    posts.extend(wall((6.0, -0.95), (6.0, -end), 0.2));
    ManoeuvreRequest {
        footprint: Footprint {
            margin: 0.25,
            ..CAR
        },
        ..request([3.275, 0.0, 0.0], [12.0, 0.0, 0.0], posts)
    }
}

#[test]
fn a_gap_wide_enough_for_the_car_but_not_its_margin_is_crept_through_and_left_behind() {
    let req = gap_in_wall(11.0);
    // At the margin no way through (at most a partial manoeuvre short of the gap).
    let field = req.field();
    assert!(!matches!(req.plan(&field).0, Ok(p) if p.complete));
    let escape = req.escape(false).0.expect("an escape");
    assert_eq!(escape.escape_margin, Some(0.1));
    let keeps = |p: &PathPoint, m: f64| {
        req.obstacles
            .iter()
            .all(|o| req.footprint.distance(p.x, p.y, p.theta, o.x, o.y) > o.radius + m)
    };
    let points = &escape.manoeuvre.points;
    assert!(points.iter().all(|p| keeps(p, 0.1)));
    assert!(points.iter().any(|p| !keeps(p, 0.25)));
    // Cut once the car is through, its rear axle past the wall, the full margin kept.
    let end = points[points.len() - 1];
    assert!(end.x > 6.0 && end.x < 12.0 - 0.3, "{end:?}");
    assert!(points[points.len() - 4..].iter().all(|p| keeps(p, 0.25)));
    assert!(!escape.complete);
}

#[test]
fn a_car_with_room_at_the_margin_gets_no_escape() {
    let req = request([0.0, 0.0, 0.0], [12.0, 0.0, 0.0], vec![post(6.0, 0.0, 0.5)]);
    let field = req.field();
    let (found, _) = req.plan_or_escape(&field);
    let found = found.expect("a manoeuvre");
    assert!(found.complete && found.escape_margin.is_none());
}

#[test]
fn a_partial_manoeuvre_that_backs_off_gives_way_to_an_escape_through_the_gap_ahead() {
    // The wall ending 9 m either side of the gap: at the margin the search backs off
    // towards an end it cannot reach within its budget; the gap before the car is the
    // way, at the escape's margin.
    let req = gap_in_wall(9.0);
    let field = req.field();
    let (plain, n) = req.plan(&field);
    let plain = plain.expect("a partial manoeuvre at the margin");
    assert!(!plain.complete && plain.manoeuvre.cusps() > 0, "{plain:?}");
    let (found, expansions) = req.plan_or_escape(&field);
    let escape = found.expect("a manoeuvre");
    assert!(expansions > n);
    assert_eq!(escape.escape_margin, Some(0.1));
    assert_eq!(escape.manoeuvre.cusps(), 0);
    let points = &escape.manoeuvre.points;
    assert!(points.iter().all(|p| p.forward));
    let end = points[points.len() - 1];
    assert!(end.x > 6.0 && end.y.abs() < 0.5, "{end:?}");
}
