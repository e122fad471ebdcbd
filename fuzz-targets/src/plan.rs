//! The planning problem as JSON: `ugv-controller plan` reads it with serde_json into a
//! `PlanProblem`, then `planner::plan` (which validates it first).

use ugv_controller::planner::{PlanProblem, PlanResult, plan};

/// More obstacles than this are not planned: the planner's work grows with the
/// obstacles (a sampled collision window each, 2048 steps by default), and the product
/// has no bound of its own (the controller gives it what perception found, tens at
/// most). 32 keeps one execution in milliseconds.
pub const MAX_OBSTACLES: usize = 32;

/// Problems whose numbers all lie within this many metres (seconds, radians) are
/// "plausible": there the planner's promises are checked to the millimetre; beyond,
/// floating point alone can break them and only the absence of a panic is checked.
const PLAUSIBLE: f64 = 1.0e4;

/// `plan_json`: the bytes as the `plan` subcommand's input (read as UTF-8 text,
/// `serde_json::from_str::<PlanProblem>`, `planner::plan`, and the result printed with
/// `serde_json::to_string_pretty`).
///
/// Invariants: the problem round trips through JSON; `validate` and `plan` agree (a
/// problem `validate` refuses is not planned); of a result: `feasible` is "the feasible
/// set is not empty", the feasible pieces are sorted, disjoint and not reversed, the
/// chosen a6 lies in one of them (and is a6* unless projected), no forbidden interval
/// has a NaN end (an obstacle would silently stop constraining the path), the result
/// prints as JSON; for plausible problems the chosen path keeps its clearance to every
/// obstacle (to 1 mm).
pub fn plan_json(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(problem) = serde_json::from_str::<PlanProblem>(text) else {
        return;
    };
    match serde_json::to_string(&problem) {
        Ok(json) => match serde_json::from_str::<PlanProblem>(&json) {
            Ok(back) => assert_eq!(back, problem, "the problem does not round trip"),
            Err(e) => panic!("a serialised problem does not parse: {e}\n{json}"),
        },
        Err(e) => panic!("a parsed problem does not serialise: {e}"),
    }
    if problem.obstacles.len() > MAX_OBSTACLES {
        return;
    }
    let valid = problem.validate();
    let result = plan(&problem);
    if valid.is_err() {
        assert!(result.is_err(), "plan accepted what validate refuses");
        return;
    }
    let Ok(result) = result else {
        return;
    };
    check_result(&problem, &result);
}

fn plausible(p: &PlanProblem) -> bool {
    let mut values = vec![
        p.state.x,
        p.state.y,
        p.goal.x,
        p.goal.y,
        p.line_start.x0,
        p.line_start.y0,
        p.t_k,
        p.t_f,
        p.wheelbase,
        p.vehicle_radius,
    ];
    if let Some(end) = &p.line_end {
        values.extend([end.x, end.y]);
    }
    for o in &p.obstacles {
        values.extend([o.x, o.y, o.radius, o.vx, o.vy]);
    }
    let small = values.iter().all(|v| v.abs() <= PLAUSIBLE);
    // Steps shorter than a millimetre or a millisecond are numerically meaningless.
    small
        && (p.goal.x - p.state.x).abs() >= 1e-3
        && p.t_f - p.t_k >= 1e-3
        && p.wheelbase >= 1e-3
        && p.state.theta.abs() < 1.5
        && p.goal.theta.abs() < 1.5
        && p.state.phi.abs() < 1.5
        && p.goal.phi.abs() < 1.5
}

fn check_result(problem: &PlanProblem, r: &PlanResult) {
    assert_eq!(r.feasible, !r.feasible_set.is_empty(), "{r:?}");
    assert_eq!(r.a6_chosen.is_some(), r.feasible, "{r:?}");
    for w in r.feasible_set.windows(2) {
        assert!(
            w[0].hi <= w[1].lo,
            "feasible pieces overlap: {:?}",
            r.feasible_set
        );
    }
    for piece in &r.feasible_set {
        assert!(piece.lo <= piece.hi, "reversed piece {piece:?}");
    }
    if let Some(a6) = r.a6_chosen {
        assert!(a6.is_finite(), "{r:?}");
        assert!(
            r.feasible_set.iter().any(|p| p.contains(a6)),
            "a6 {a6} outside the feasible set {:?}",
            r.feasible_set
        );
        if !r.projected_to_boundary {
            assert_eq!(a6, r.a6_unconstrained, "{r:?}");
        }
    }
    for (i, o) in r.obstacles.iter().enumerate() {
        if let Some(f) = o.forbidden {
            assert!(
                !f.lo.is_nan() && !f.hi.is_nan(),
                "obstacle {i}: forbidden interval {f:?} has a NaN end"
            );
        }
    }
    if let Err(e) = serde_json::to_string_pretty(r) {
        panic!("a plan result does not print as JSON: {e}: {r:?}");
    }
    if plausible(problem) && r.feasible {
        for (i, o) in r.obstacles.iter().enumerate() {
            if let Some(c) = o.min_clearance {
                assert!(
                    c >= -1e-3,
                    "obstacle {i}: the chosen path comes {c} m inside its clearance: {problem:?}"
                );
            }
        }
    }
}
