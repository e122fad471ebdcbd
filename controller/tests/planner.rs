//! Integration tests of the optimal collision-free planner (controller::planner).
//!
//! Every check recomputes what it asserts independently of the planner's internals:
//! clearances by brute-force sampling of the moving geometry, the cost by composite
//! Simpson, derivatives by finite differences, the printed (wrong) formulas from the
//! seed paper as printed.

use std::f64::consts::FRAC_PI_4;

use anyhow::{Context, Result, bail, ensure};
use proptest::prelude::*;
use ugv_controller::planner::{
    Interval, LineStart, Obstacle, PlanError, PlanOptions, PlanProblem, PlanResult, Point,
    PolynomialPath, ReferenceLine, Trajectory, VehicleState, plan, plan_with,
};

// ---------------------------------------------------------------- helpers

fn state(x: f64, y: f64, theta: f64, phi: f64) -> VehicleState {
    VehicleState { x, y, theta, phi }
}

fn obstacle(x: f64, y: f64, radius: f64, vx: f64, vy: f64) -> Obstacle {
    Obstacle {
        x,
        y,
        radius,
        vx,
        vy,
    }
}

/// The seed paper's scenario: start (0, 0) heading 45 degrees, goal (30, 15) heading
/// along the start-goal line, straight wheels, r_0 = 2, obstacle r = 3 at (19, 8).
/// Chosen here: 15 s for the step (2 m/s in x), wheelbase 1.65 m (a golf car).
fn paper_problem() -> PlanProblem {
    PlanProblem {
        state: state(0.0, 0.0, FRAC_PI_4, 0.0),
        goal: state(30.0, 15.0, 15.0_f64.atan2(30.0), 0.0),
        line_start: LineStart { x0: 0.0, y0: 0.0 },
        line_end: None,
        t_k: 0.0,
        t_f: 15.0,
        wheelbase: 1.65,
        vehicle_radius: 2.0,
        obstacles: vec![obstacle(19.0, 8.0, 3.0, 0.0, 0.0)],
    }
}

/// Distance between centres minus (r_i + r_0) at time t.
fn margin_at(traj: &Trajectory, o: &Obstacle, r0: f64, t: f64) -> f64 {
    let s = traj.state_at(t);
    let tau = t - traj.t_k();
    let (ox, oy) = (o.x + o.vx * tau, o.y + o.vy * tau);
    (s.x - ox).hypot(s.y - oy) - (o.radius + r0)
}

/// Smallest margin over [t_k, t_f]: 20 000 uniform samples, then a 2 000-point scan
/// around each of the three lowest local minima.
fn min_margin(traj: &Trajectory, o: &Obstacle, r0: f64) -> f64 {
    let (a, b) = (traj.t_k(), traj.t_f());
    let n = 20_000;
    let ts: Vec<f64> = (0..=n).map(|j| a + (b - a) * j as f64 / n as f64).collect();
    let ms: Vec<f64> = ts.iter().map(|&t| margin_at(traj, o, r0, t)).collect();
    let mut minima: Vec<usize> = (0..=n)
        .filter(|&j| (j == 0 || ms[j] <= ms[j - 1]) && (j == n || ms[j] <= ms[j + 1]))
        .collect();
    minima.sort_by(|&i, &j| ms[i].total_cmp(&ms[j]));
    let mut best = ms.iter().copied().fold(f64::INFINITY, f64::min);
    for &j in minima.iter().take(3) {
        let lo = ts[j.saturating_sub(1)];
        let hi = ts[(j + 1).min(n)];
        for k in 0..=2000 {
            let t = lo + (hi - lo) * k as f64 / 2000.0;
            best = best.min(margin_at(traj, o, r0, t));
        }
    }
    best
}

fn chosen_trajectory(problem: &PlanProblem, result: &PlanResult) -> Result<Trajectory> {
    let a6 = result.a6_chosen.context("feasible plan has a chosen a6")?;
    Ok(problem.trajectory(a6)?)
}

/// J by composite Simpson with 4000 panels (independent of the planner's quadrature).
fn simpson_cost(path: &PolynomialPath, line: &ReferenceLine) -> f64 {
    let n = 4000;
    let (a, b) = (path.x_k(), path.x_f());
    let h = (b - a) / n as f64;
    let f = |x: f64| (path.y(x) - line.y(x)).powi(2);
    let mut sum = f(a) + f(b);
    for j in 1..n {
        let w = if j % 2 == 1 { 4.0 } else { 2.0 };
        sum += w * f(a + h * j as f64);
    }
    (sum * h / 3.0).abs()
}

/// Numerical minimiser of J over a6, by golden section on a bracket found by doubling,
/// polished by the vertex of the parabola through J at the bracket's ends and middle
/// (golden section alone stalls where J is flat to rounding, about 1e-6 relative).
fn numeric_minimiser(path: &PolynomialPath, line: &ReferenceLine) -> f64 {
    let j = |a: f64| simpson_cost(&path.with_a6(a), line);
    let scale = path.span().abs().powi(-4).max(1e-12);
    let (mut lo, mut hi) = (-scale, scale);
    while j(lo) < j(0.5 * (lo + hi)) {
        lo *= 2.0;
    }
    while j(hi) < j(0.5 * (lo + hi)) {
        hi *= 2.0;
    }
    let g = 0.5 * (5.0_f64.sqrt() - 1.0);
    for _ in 0..60 {
        let x1 = hi - g * (hi - lo);
        let x2 = lo + g * (hi - lo);
        if j(x1) < j(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    let mid = 0.5 * (lo + hi);
    let s = (hi - lo).max(1e-3 * mid.abs());
    let (jm, j0, jp) = (j(mid - s), j(mid), j(mid + s));
    mid - 0.5 * s * (jp - jm) / (jp - 2.0 * j0 + jm)
}

/// End conditions (y, y', y'') a state imposes, recomputed from the kinematics.
fn expected_conditions(s: &VehicleState, l: f64) -> [f64; 3] {
    [
        s.y,
        s.theta.tan(),
        s.phi.tan() / (l * s.theta.cos().powi(3)),
    ]
}

/// |a - b| within tol of the larger magnitude, floored at 1 (for lengths, angles, rates).
fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
}

/// Purely relative closeness, for small quantities (a6 is typically 1e-8..1e-4).
fn a6_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs())
}

fn check_boundary_conditions(problem: &PlanProblem, traj: &Trajectory) -> Result<()> {
    let path = traj.path();
    for (s, name) in [(&problem.state, "start"), (&problem.goal, "goal")] {
        let expected = expected_conditions(s, problem.wheelbase);
        let got = path.derivatives(s.x);
        for k in 0..3 {
            ensure!(
                rel_close(got[k], expected[k], 1e-9),
                "{name} derivative {k}: {} vs {}",
                got[k],
                expected[k]
            );
        }
    }
    let start = traj.state_at(problem.t_k);
    let goal = traj.state_at(problem.t_f);
    for (got, want) in [(start, problem.state), (goal, problem.goal)] {
        ensure!(got.x == want.x, "x at the ends is exact");
        ensure!(rel_close(got.y, want.y, 1e-9));
        ensure!(rel_close(got.theta, want.theta, 1e-9));
        ensure!(
            rel_close(got.phi, want.phi, 1e-9),
            "{} vs {}",
            got.phi,
            want.phi
        );
    }
    Ok(())
}

// ---------------------------------------------------------------- path

#[test]
fn boundary_conditions_hold_in_both_evaluations() -> Result<()> {
    let problem = paper_problem();
    let result = plan(&problem)?;
    let traj = chosen_trajectory(&problem, &result)?;
    check_boundary_conditions(&problem, &traj)?;
    // The reported x-monomial coefficients describe the same polynomial.
    let a = result.coefficients.context("coefficients")?;
    for x in [0.0_f64, 7.5, 19.0, 30.0] {
        let y: f64 = a
            .iter()
            .enumerate()
            .map(|(j, c)| c * x.powi(j as i32))
            .sum();
        ensure!(rel_close(y, traj.path().y(x), 1e-9), "y({x})");
    }
    let c = result
        .shifted_coefficients
        .context("shifted coefficients")?;
    ensure!(c[6] == result.a6_chosen.context("a6")? && a[6] == c[6]);
    Ok(())
}

#[test]
fn boundary_conditions_hold_far_from_the_origin() -> Result<()> {
    // |x| = 1e5 with a 12 m step: the raw monomial system would be hopeless.
    let start = state(1.0e5, -3.0e4, 0.3, 0.2);
    let goal = state(1.0e5 + 12.0, -3.0e4 + 2.0, -0.25, -0.1);
    let problem = PlanProblem {
        state: start,
        goal,
        line_start: LineStart {
            x0: 1.0e5 - 40.0,
            y0: -3.0e4 - 1.0,
        },
        line_end: None,
        t_k: 1000.0,
        t_f: 1006.0,
        wheelbase: 1.65,
        vehicle_radius: 1.0,
        obstacles: vec![],
    };
    let result = plan(&problem)?;
    check_boundary_conditions(&problem, &chosen_trajectory(&problem, &result)?)
}

#[test]
fn h_is_the_factored_sextic_and_a6_only_moves_the_interior() -> Result<()> {
    let path = PolynomialPath::from_states(
        &state(2.0, 1.0, 0.2, 0.05),
        &state(25.0, 4.0, 0.1, -0.02),
        1.6,
        0.0,
    )?;
    let a6 = 3.7e-6;
    let moved = path.with_a6(a6);
    for j in 0..=100 {
        let x = 2.0 + 23.0 * j as f64 / 100.0;
        let factored = (x - 2.0).powi(3) * (x - 25.0).powi(3);
        ensure!(
            (path.h(x) - factored).abs() <= 1e-14 * factored.abs(),
            "h({x}) is the factored sextic"
        );
        ensure!(factored <= 0.0, "h <= 0 on the step");
        let diff = moved.y(x) - path.y(x);
        ensure!((diff - a6 * factored).abs() <= 1e-12 * path.y(x).abs().max(1.0));
    }
    // Near x_f the factored h is accurate where the expanded sextic cancels.
    let x = 25.0_f64 - 1e-4;
    let expanded: f64 = {
        let (k, f) = (2.0_f64, 25.0_f64);
        // (x-k)^3 (x-f)^3 expanded in powers of x.
        let p1 = [-k * k * k, 3.0 * k * k, -3.0 * k, 1.0];
        let p2 = [-f * f * f, 3.0 * f * f, -3.0 * f, 1.0];
        let mut c = [0.0; 7];
        for (i, a) in p1.iter().enumerate() {
            for (j, b) in p2.iter().enumerate() {
                c[i + j] += a * b;
            }
        }
        c.iter()
            .enumerate()
            .map(|(j, cj)| cj * x.powi(j as i32))
            .sum()
    };
    let exact = (x - 2.0).powi(3) * (x - 25.0).powi(3);
    ensure!(a6_close(path.h(x), exact, 1e-12));
    ensure!(
        (expanded - exact).abs() > 1e3 * (path.h(x) - exact).abs(),
        "the expanded form cancels catastrophically near x_f ({expanded} vs {exact})"
    );
    Ok(())
}

#[test]
fn curvature_and_steering_follow_the_kinematic_model() -> Result<()> {
    let l = 1.65;
    let path = PolynomialPath::from_states(
        &state(0.0, 0.0, 0.5, 0.3),
        &state(20.0, 6.0, -0.2, 0.1),
        l,
        -2.0e-6,
    )?;
    for x in [0.0, 3.0, 10.0, 17.0, 20.0] {
        let [_, d1, d2, _] = path.derivatives(x);
        let theta = d1.atan();
        // kappa = y'' / (1 + y'^2)^1.5 and tan(phi) = l kappa.
        let kappa = d2 / (1.0 + d1 * d1).powf(1.5);
        ensure!(rel_close(path.curvature(x), kappa, 1e-12));
        ensure!(rel_close(path.steering_angle(x).tan(), l * kappa, 1e-12));
        ensure!(rel_close(path.heading(x), theta, 1e-15));
    }
    ensure!(rel_close(path.steering_angle(0.0), 0.3, 1e-12));
    ensure!(rel_close(path.steering_angle(20.0), 0.1, 1e-12));
    Ok(())
}

// ---------------------------------------------------------------- controls

#[test]
fn open_loop_inputs_match_finite_differences_of_the_state() -> Result<()> {
    let l = 1.65;
    let path = PolynomialPath::from_states(
        &state(3.0, 1.0, 0.6, 0.35),
        &state(23.0, 9.0, 0.1, -0.2),
        l,
        1.5e-6,
    )?;
    let traj = Trajectory::new(path, 2.0, 12.0)?;
    let dt = 1e-5;
    let mut printed_u2_wrong = false;
    for t in [2.5, 4.0, 7.3, 9.9, 11.5] {
        let c = traj.controls_at(t);
        let (sp, sm) = (traj.state_at(t + dt), traj.state_at(t - dt));
        let s = traj.state_at(t);
        let fd = |a: f64, b: f64| (a - b) / (2.0 * dt);
        // Model (3): x' = u1 cos(theta), y' = u1 sin(theta), theta' = u1 tan(phi) / l, phi' = u2.
        ensure!(rel_close(fd(sp.x, sm.x), c.u1 * s.theta.cos(), 1e-7));
        ensure!(rel_close(fd(sp.y, sm.y), c.u1 * s.theta.sin(), 1e-6));
        ensure!(rel_close(
            fd(sp.theta, sm.theta),
            c.u1 * s.phi.tan() / l,
            1e-6
        ));
        ensure!(
            a6_close(fd(sp.phi, sm.phi), c.u2, 1e-5),
            "u2 at {t}: fd {} vs {}",
            fd(sp.phi, sm.phi),
            c.u2
        );
        ensure!(c.w1 == 2.0, "w1 = (23 - 3) / (12 - 2)");
        // The printed u2 (+ on the first term) disagrees wherever sin(theta) sin(phi) != 0.
        let (st, ct) = s.theta.sin_cos();
        let (sph, cph) = s.phi.sin_cos();
        let printed =
            3.0 * st * sph * sph * c.w1 / (l * ct * ct) + l * ct.powi(3) * cph * cph * c.w2;
        if !rel_close(printed, fd(sp.phi, sm.phi), 1e-3) {
            printed_u2_wrong = true;
        }
    }
    ensure!(
        printed_u2_wrong,
        "the printed sign of u2 must be detectably wrong"
    );
    Ok(())
}

#[test]
fn w2_equals_the_printed_taylor_form() -> Result<()> {
    let path = PolynomialPath::from_states(
        &state(3.0, 1.0, 0.6, 0.35),
        &state(23.0, 9.0, 0.1, -0.2),
        1.65,
        1.5e-6,
    )?;
    let traj = Trajectory::new(path, 2.0, 12.0)?;
    let a = path.coefficients();
    let (x1, w1) = (path.x_k(), traj.w1());
    for t in [2.0, 4.0, 8.0, 12.0] {
        let tau = t - traj.t_k();
        let printed =
            6.0 * (a[3] + 4.0 * a[4] * x1 + 10.0 * a[5] * x1 * x1 + 20.0 * a[6] * x1.powi(3)) * w1
                + 24.0 * (a[4] + 5.0 * a[5] * x1 + 15.0 * a[6] * x1 * x1) * tau * w1 * w1
                + 60.0 * (a[5] + 6.0 * a[6] * x1) * tau * tau * w1.powi(3)
                + 120.0 * a[6] * tau.powi(3) * w1.powi(4);
        let w2 = traj.controls_at(t).w2;
        ensure!(a6_close(printed, w2, 1e-8), "w2 at {t}: {printed} vs {w2}");
    }
    Ok(())
}

// ---------------------------------------------------------------- optimal a6

fn cost_problem(line_end: Option<Point>, start_y: f64) -> Result<(PolynomialPath, ReferenceLine)> {
    let problem = PlanProblem {
        state: state(4.0, start_y, 0.35, 0.15),
        goal: state(26.0, 9.0, -0.1, 0.05),
        line_start: LineStart { x0: -2.0, y0: -1.0 },
        line_end,
        t_k: 0.0,
        t_f: 11.0,
        wheelbase: 1.65,
        vehicle_radius: 1.0,
        obstacles: vec![],
    };
    Ok((*problem.trajectory(0.0)?.path(), problem.reference_line()?))
}

/// ERRATA 7's printed correction: the e_f term is missing.
fn errata_formula(path: &PolynomialPath, line: &ReferenceLine) -> f64 {
    let (k, f, d) = (path.start_conditions(), path.goal_conditions(), path.span());
    13.0 / (60.0 * d.powi(6))
        * (5.0 * d * d * (k.d2y + f.d2y) - 54.0 * d * (f.dy - k.dy)
            + 198.0 * (k.y - line.y(path.x_k())))
}

#[test]
fn closed_form_a6_equals_the_numerical_minimiser_of_j() -> Result<()> {
    for (line_end, start_y) in [
        (None, 2.0),
        (None, -3.0),
        (Some(Point { x: 30.0, y: 4.0 }), 2.0),
        (Some(Point { x: 20.0, y: 12.0 }), -1.0),
    ] {
        let (path, line) = cost_problem(line_end, start_y)?;
        let closed = ugv_controller::planner::optimal_a6(&path, &line);
        let numeric = numeric_minimiser(&path, &line);
        ensure!(
            a6_close(closed, numeric, 1e-6),
            "line_end {line_end:?}: closed {closed} vs numeric {numeric}"
        );
        // The exact quadrature agrees with Simpson.
        let p = path.with_a6(closed);
        ensure!(rel_close(
            p.reference_cost(&line),
            simpson_cost(&p, &line),
            1e-9
        ));
        // The errata's formula holds exactly when the goal lies on L.
        let goal_on_line = line_end.is_none();
        let errata = errata_formula(&path, &line);
        ensure!(
            a6_close(errata, numeric, 1e-6) == goal_on_line,
            "errata formula {errata} vs minimiser {numeric}, goal on L: {goal_on_line}"
        );
    }
    Ok(())
}

#[test]
fn printed_f2_sign_is_wrong_exactly_when_the_vehicle_is_off_the_line() -> Result<()> {
    // The paper's -f2 / (2 f1) as printed, with x0 the line start.
    let printed = |path: &PolynomialPath, line: &ReferenceLine| {
        let (k, f) = (path.start_conditions(), path.goal_conditions());
        let (xk, xf, x0, y0) = (path.x_k(), path.x_f(), line.x0, line.y0);
        let dk = xk - xf;
        let f1 = -dk.powi(12) / 12012.0;
        let f2 = dk.powi(6) / 27720.0
            * (5.0 * (k.d2y + f.d2y) * dk * dk
                + 54.0 * (f.dy - k.dy) * dk
                + 198.0 * ((f.y - y0) * dk - (k.y - f.y) * (xf - x0)) / (xf - x0));
        -f2 / (2.0 * f1)
    };
    // Start on L (the line from (-2, -1) to the goal (26, 9)).
    let on_l = ReferenceLine::new(-2.0, -1.0, 26.0, 9.0)?.y(4.0);
    let (on_path, on_line) = cost_problem(None, on_l)?;
    let numeric = numeric_minimiser(&on_path, &on_line);
    ensure!(a6_close(printed(&on_path, &on_line), numeric, 1e-6));
    let (off_path, off_line) = cost_problem(None, -3.0)?;
    let numeric = numeric_minimiser(&off_path, &off_line);
    ensure!(!a6_close(printed(&off_path, &off_line), numeric, 1e-2));
    Ok(())
}

// ---------------------------------------------------------------- scenarios

#[test]
fn paper_scenario_avoids_the_obstacle() -> Result<()> {
    let problem = paper_problem();
    let result = plan(&problem)?;
    ensure!(result.feasible && !result.start_or_goal_collides);
    let o = problem.obstacles[0];
    let r = o.radius + problem.vehicle_radius;
    // The straight reference line passes within r of the obstacle centre...
    let line_gap = (15.0 * o.x - 30.0 * o.y).abs() / 15.0_f64.hypot(30.0);
    ensure!(
        line_gap < r,
        "the obstacle blocks the reference line ({line_gap})"
    );
    // ...and so does the unconstrained optimum, so a6 must be projected.
    let unconstrained = problem.trajectory(result.a6_unconstrained)?;
    ensure!(min_margin(&unconstrained, &o, problem.vehicle_radius) < 0.0);
    ensure!(result.projected_to_boundary);
    let forbidden = result.obstacles[0]
        .forbidden
        .context("the obstacle constrains a6")?;
    ensure!(forbidden.contains_open(result.a6_unconstrained));
    let traj = chosen_trajectory(&problem, &result)?;
    let margin = min_margin(&traj, &o, problem.vehicle_radius);
    ensure!(margin >= -1e-9, "clearance {margin}");
    // On the boundary the path just touches the inflated obstacle.
    ensure!(margin <= 1e-3, "boundary a6 is tight, margin {margin}");
    check_boundary_conditions(&problem, &traj)?;
    // The report's own clearance agrees with the brute-force one.
    let reported = result.obstacles[0].min_clearance.context("clearance")?;
    ensure!((reported - margin).abs() < 1e-6);
    Ok(())
}

#[test]
fn moving_obstacle_is_avoided_where_it_will_be() -> Result<()> {
    // The vehicle drives straight along y = 0 at 2 m/s; the obstacle starts 8 m to the
    // side and crosses y = 0 at x = 10 exactly when the vehicle gets there (t = 5).
    let crossing = obstacle(10.0, 8.0, 1.0, 0.0, -1.6);
    let mut problem = PlanProblem {
        state: state(0.0, 0.0, 0.0, 0.0),
        goal: state(20.0, 0.0, 0.0, 0.0),
        line_start: LineStart { x0: 0.0, y0: 0.0 },
        line_end: None,
        t_k: 0.0,
        t_f: 10.0,
        wheelbase: 1.65,
        vehicle_radius: 1.0,
        obstacles: vec![crossing],
    };
    // Seen as static at its t_k position it would not matter at all.
    let mut frozen = problem.clone();
    frozen.obstacles[0].vy = 0.0;
    let naive = plan(&frozen)?;
    ensure!(!naive.projected_to_boundary);
    let naive_traj = chosen_trajectory(&frozen, &naive)?;
    ensure!(
        min_margin(&naive_traj, &crossing, 1.0) < -1.0,
        "the naive path is hit"
    );

    let result = plan(&problem)?;
    ensure!(result.feasible && result.projected_to_boundary);
    let traj = chosen_trajectory(&problem, &result)?;
    ensure!(min_margin(&traj, &crossing, 1.0) >= -1e-9);
    // A faster obstacle overtaking from behind in the next lane: its window is the
    // swapped formula, and the plan still clears it.
    problem.obstacles.push(obstacle(-12.0, -2.5, 1.0, 4.0, 0.0));
    let result = plan(&problem)?;
    let window = result.obstacles[1].window.context("overtaker window")?;
    // |x(t) - x_o(t)| < 2 with x(t) = 2t, x_o(t) = -12 + 4t: t in (5, 7).
    ensure!((window[0] - 5.0).abs() < 1e-12 && (window[1] - 7.0).abs() < 1e-12);
    if result.feasible {
        let traj = chosen_trajectory(&problem, &result)?;
        for o in &problem.obstacles {
            ensure!(min_margin(&traj, o, 1.0) >= -1e-9);
        }
    }
    Ok(())
}

#[test]
fn obstacle_on_the_goal_leaves_nothing_feasible() -> Result<()> {
    let mut problem = paper_problem();
    problem.obstacles.push(obstacle(30.5, 15.5, 1.0, 0.0, 0.0));
    let result = plan(&problem)?;
    ensure!(!result.feasible && result.start_or_goal_collides);
    ensure!(result.feasible_set.is_empty() && result.a6_chosen.is_none());
    ensure!(result.coefficients.is_none() && result.cost.is_none());
    ensure!(result.obstacles[1].goal_collides && !result.obstacles[1].start_collides);
    ensure!(result.obstacles[1].forbidden == Some(Interval::ALL));
    let json = serde_json::to_value(&result)?;
    ensure!(json["a6_chosen"].is_null() && json["feasible_set"] == serde_json::json!([]));
    Ok(())
}

#[test]
fn obstacle_sweeping_across_the_band_traps_the_vehicle() -> Result<()> {
    // Moving with the vehicle (equal x-speed, so the window is the whole step) from
    // above the start to below the goal: any path must cross it.
    let sweeper = obstacle(1.0, 4.0, 0.5, 2.0, -0.8);
    let problem = PlanProblem {
        state: state(0.0, 0.0, 0.0, 0.0),
        goal: state(20.0, 0.0, 0.0, 0.0),
        line_start: LineStart { x0: 0.0, y0: 0.0 },
        line_end: None,
        t_k: 0.0,
        t_f: 10.0,
        wheelbase: 1.65,
        vehicle_radius: 1.0,
        obstacles: vec![sweeper],
    };
    let result = plan(&problem)?;
    ensure!(result.obstacles[0].window == Some([0.0, 10.0]));
    ensure!(!result.feasible && !result.start_or_goal_collides);
    for a6 in [-1e-3, -1e-5, 0.0, 1e-5, 1e-3] {
        ensure!(min_margin(&problem.trajectory(a6)?, &sweeper, 1.0) < 0.0);
    }
    Ok(())
}

#[test]
fn union_not_intersection_of_root_intervals_is_forbidden() -> Result<()> {
    let problem = paper_problem();
    let o = problem.obstacles[0];
    let r = o.radius + problem.vehicle_radius;
    let base = problem.trajectory(0.0)?;
    let path = base.path();
    // Printed (ERRATA 5 wrong): lower = max_t root-, upper = min_t root+, with the
    // roots of G from the printed quadratic formula.
    let (mut printed_lower, mut printed_upper) = (f64::NEG_INFINITY, f64::INFINITY);
    let n = 20_000;
    for j in 1..n {
        let t = problem.t_f * j as f64 / n as f64;
        let x = base.x_at(t);
        let (h, p) = (path.h(x), path.quintic(x));
        let dx = x - o.x;
        let (g2, g1, g0) = (
            h * h,
            2.0 * h * (p - o.y),
            (p - o.y).powi(2) + dx * dx - r * r,
        );
        let disc = g1 * g1 - 4.0 * g2 * g0;
        if dx.abs() < r && disc > 0.0 {
            let lo = (-g1 - disc.sqrt()) / (2.0 * g2);
            let hi = (-g1 + disc.sqrt()) / (2.0 * g2);
            printed_lower = printed_lower.max(lo);
            printed_upper = printed_upper.min(hi);
        }
    }
    let printed_allows = |a6: f64| a6 <= printed_lower || a6 >= printed_upper;
    let result = plan(&problem)?;
    let a6_star = result.a6_unconstrained;
    ensure!(printed_allows(a6_star), "the intersection lets a6* through");
    ensure!(
        min_margin(&problem.trajectory(a6_star)?, &o, problem.vehicle_radius) < -0.5,
        "and the a6* path drives into the obstacle"
    );
    let forbidden = result.obstacles[0].forbidden.context("forbidden")?;
    ensure!(forbidden.contains_open(a6_star));
    // The union is the widest of the per-instant intervals' hull.
    ensure!(forbidden.lo <= printed_upper && forbidden.hi >= printed_lower);
    Ok(())
}

#[test]
fn several_obstacles_split_the_feasible_set() -> Result<()> {
    let problem = PlanProblem {
        state: state(0.0, 0.0, 0.0, 0.0),
        goal: state(40.0, 0.0, 0.0, 0.0),
        line_start: LineStart { x0: 0.0, y0: 0.0 },
        line_end: None,
        t_k: 0.0,
        t_f: 20.0,
        wheelbase: 1.65,
        vehicle_radius: 1.0,
        obstacles: vec![
            obstacle(20.0, 6.0, 1.0, 0.0, 0.0),
            obstacle(20.0, -6.0, 1.0, 0.0, 0.0),
        ],
    };
    let result = plan(&problem)?;
    ensure!(result.feasible_set.len() == 3, "{:?}", result.feasible_set);
    for pair in result.feasible_set.windows(2) {
        ensure!(pair[0].hi < pair[1].lo, "sorted and disjoint");
    }
    ensure!(result.feasible_set[0].lo == f64::NEG_INFINITY);
    ensure!(result.feasible_set[2].hi == f64::INFINITY);
    // Straight ahead (between the obstacles) is optimal and feasible.
    ensure!(!result.projected_to_boundary && result.a6_chosen == Some(result.a6_unconstrained));
    // A point of each piece clears both; a point of each gap hits one.
    let probes = [
        result.feasible_set[0].hi * 1.5,
        0.5 * (result.feasible_set[1].lo + result.feasible_set[1].hi),
        result.feasible_set[2].lo * 1.5,
    ];
    for a6 in probes {
        let traj = problem.trajectory(a6)?;
        for o in &problem.obstacles {
            ensure!(min_margin(&traj, o, 1.0) >= -1e-9, "a6 {a6}");
        }
    }
    for gap in [
        0.5 * (result.feasible_set[0].hi + result.feasible_set[1].lo),
        0.5 * (result.feasible_set[1].hi + result.feasible_set[2].lo),
    ] {
        let traj = problem.trajectory(gap)?;
        let worst = problem
            .obstacles
            .iter()
            .map(|o| min_margin(&traj, o, 1.0))
            .fold(f64::INFINITY, f64::min);
        ensure!(worst < 0.0, "a6 {gap} in a gap collides");
    }
    Ok(())
}

#[test]
fn mirrored_problem_reverses_along_x_with_the_same_a6() -> Result<()> {
    let problem = paper_problem();
    let mirror = |s: VehicleState| state(-s.x, s.y, -s.theta, s.phi);
    let mirrored = PlanProblem {
        state: mirror(problem.state),
        goal: mirror(problem.goal),
        line_start: LineStart { x0: 0.0, y0: 0.0 },
        obstacles: problem
            .obstacles
            .iter()
            .map(|o| obstacle(-o.x, o.y, o.radius, -o.vx, o.vy))
            .collect(),
        ..problem.clone()
    };
    let a = plan(&problem)?;
    let b = plan(&mirrored)?;
    ensure!(b.w1 == -a.w1);
    ensure!(a6_close(a.a6_unconstrained, b.a6_unconstrained, 1e-9));
    let (ca, cb) = (a.a6_chosen.context("a")?, b.a6_chosen.context("b")?);
    ensure!(a6_close(ca, cb, 1e-7), "{ca} vs {cb}");
    let traj = chosen_trajectory(&mirrored, &b)?;
    ensure!(traj.controls_at(3.0).u1 < 0.0, "a reversing step");
    ensure!(min_margin(&traj, &mirrored.obstacles[0], 2.0) >= -1e-9);
    Ok(())
}

// ---------------------------------------------------------------- JSON

#[test]
fn json_round_trip_with_infinite_ends() -> Result<()> {
    let text = r#"{
        "state": {"x": 0, "y": 0, "theta": 0.7853981633974483, "phi": 0},
        "goal": {"x": 30, "y": 15, "theta": 0.4636476090008061, "phi": 0},
        "line_start": {"x0": 0, "y0": 0},
        "t_k": 0, "t_f": 15, "wheelbase": 1.65, "vehicle_radius": 2,
        "obstacles": [{"x": 19, "y": 8, "radius": 3}, {"x": 1, "y": -6, "radius": 1, "vx": 0.5, "vy": 0}]
    }"#;
    let problem: PlanProblem = serde_json::from_str(text)?;
    ensure!(problem.obstacles[0].vx == 0.0 && problem.obstacles[1].vx == 0.5);
    ensure!(problem.line_end.is_none());
    let again: PlanProblem = serde_json::from_str(&serde_json::to_string(&problem)?)?;
    ensure!(again == problem);

    let result = plan(&problem)?;
    let json = serde_json::to_value(&result)?;
    let set = json["feasible_set"].as_array().context("array")?;
    ensure!(set.first().context("first")?[0] == "-inf");
    // The second obstacle's band covers the start, below the path: a half-line to +inf.
    ensure!(json["obstacles"][1]["forbidden"][1] == "inf");
    ensure!(json["obstacles"][1]["forbidden"][0].is_number());
    let back: PlanResult = serde_json::from_value(json)?;
    ensure!(back == result);

    let iv: Interval = serde_json::from_str(r#"["-inf", 2.5]"#)?;
    ensure!(iv.lo == f64::NEG_INFINITY && iv.hi == 2.5);
    ensure!(serde_json::from_str::<Interval>(r#"["nan", 1]"#).is_err());
    ensure!(serde_json::from_str::<Interval>(r#"[2, 1]"#).is_err());
    ensure!(serde_json::from_str::<PlanProblem>(&text.replace("\"t_k\"", "\"tk\"")).is_err());
    Ok(())
}

#[test]
fn bad_inputs_are_named() -> Result<()> {
    let base = paper_problem();
    let expect = |p: PlanProblem, check: &dyn Fn(&PlanError) -> bool| -> Result<()> {
        match plan(&p) {
            Err(e) if check(&e) => Ok(()),
            other => bail!("unexpected {other:?}"),
        }
    };
    let mut p = base.clone();
    p.obstacles[0].vy = f64::NAN;
    expect(
        p,
        &|e| matches!(e, PlanError::NonFinite { field, .. } if field == "obstacles[0].vy"),
    )?;
    let mut p = base.clone();
    p.goal.x = p.state.x;
    expect(p, &|e| matches!(e, PlanError::DegenerateSpan { .. }))?;
    let mut p = base.clone();
    p.t_f = p.t_k;
    expect(p, &|e| matches!(e, PlanError::TimeNotIncreasing { .. }))?;
    let mut p = base.clone();
    p.obstacles[0].radius = -1.0;
    expect(
        p,
        &|e| matches!(e, PlanError::NegativeRadius { field, .. } if field == "obstacles[0].radius"),
    )?;
    let mut p = base.clone();
    p.vehicle_radius = -0.1;
    expect(
        p,
        &|e| matches!(e, PlanError::NegativeRadius { field, .. } if field == "vehicle_radius"),
    )?;
    let mut p = base.clone();
    p.state.theta = std::f64::consts::FRAC_PI_2;
    expect(
        p,
        &|e| matches!(e, PlanError::HeadingOutOfRange { field, .. } if field == "state.theta"),
    )?;
    let mut p = base.clone();
    p.goal.phi = -2.0;
    expect(
        p,
        &|e| matches!(e, PlanError::SteeringOutOfRange { field, .. } if field == "goal.phi"),
    )?;
    let mut p = base.clone();
    p.wheelbase = 0.0;
    expect(p, &|e| matches!(e, PlanError::NonPositiveWheelbase { .. }))?;
    let mut p = base.clone();
    p.wheelbase = 1e300;
    expect(p, &|e| {
        matches!(e, PlanError::OutOfRange { field, message }
            if field == "wheelbase" && message.starts_with("must be within [0.5, 5] m, is 1e300"))
    })?;
    let mut p = base.clone();
    p.line_start.x0 = 30.0;
    expect(p, &|e| matches!(e, PlanError::VerticalReferenceLine { .. }))?;
    let mut p = base.clone();
    p.t_k = f64::INFINITY;
    expect(
        p,
        &|e| matches!(e, PlanError::NonFinite { field, .. } if field == "t_k"),
    )?;
    let mut options = PlanOptions::default();
    options.sampling.steps = 3;
    ensure!(matches!(
        plan_with(&base, &options),
        Err(PlanError::InvalidOption { .. })
    ));
    Ok(())
}

// ---------------------------------------------------------------- properties

fn arb_problem() -> impl Strategy<Value = PlanProblem> {
    let ends = (
        (-50.0..50.0, -20.0..20.0, -1.0..1.0, -0.4..0.4),
        (
            prop_oneof![-40.0_f64..-8.0, 8.0_f64..40.0],
            -0.6_f64..0.6,
            -1.0_f64..1.0,
            -0.4_f64..0.4,
        ),
    );
    let timing = (0.0_f64..100.0, 2.0_f64..20.0, 1.2_f64..3.0, 0.3_f64..2.0);
    let line = (0.0_f64..20.0, -5.0_f64..5.0);
    let obstacles = prop::collection::vec(
        (
            0.0_f64..1.0,
            -12.0_f64..12.0,
            0.2_f64..3.0,
            -3.0_f64..3.0,
            -3.0_f64..3.0,
        ),
        0..4,
    );
    (ends, timing, line, obstacles).prop_map(
        |(((x, y, th, ph), (d, slope, thf, phf)), (t_k, dur, l, r0), (back, dy0), obs)| {
            let goal = state(x + d, y + d * slope, thf, phf);
            PlanProblem {
                state: state(x, y, th, ph),
                goal,
                line_start: LineStart {
                    x0: x - back * d.signum(),
                    y0: y + dy0,
                },
                line_end: None,
                t_k,
                t_f: t_k + dur,
                wheelbase: l,
                vehicle_radius: r0,
                obstacles: obs
                    .into_iter()
                    .map(|(u, dy, r, vx, vy)| {
                        obstacle(x + u * d, y + u * d * slope + dy, r, vx, vy)
                    })
                    .collect(),
            }
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, .. ProptestConfig::default() })]

    #[test]
    fn chosen_a6_clears_every_obstacle(problem in arb_problem()) {
        let result = plan(&problem).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let base = problem.trajectory(0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        check_boundary_conditions(&problem, &base).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(result.feasible, result.a6_chosen.is_some());
        if let Some(a6) = result.a6_chosen {
            prop_assert!(result.feasible_set.iter().any(|p| p.contains(a6)));
            prop_assert_eq!(result.projected_to_boundary, a6 != result.a6_unconstrained);
            let traj = base.with_a6(a6);
            for o in &problem.obstacles {
                let m = min_margin(&traj, o, problem.vehicle_radius);
                prop_assert!(m >= -1e-9, "margin {}", m);
            }
        } else {
            prop_assert!(result.feasible_set.is_empty());
        }
        // Start/goal overlap is exactly what makes the flag.
        let overlap_at = |t: f64| problem.obstacles.iter().any(|o| margin_at(&base, o, problem.vehicle_radius, t) < 0.0);
        prop_assert_eq!(result.start_or_goal_collides, overlap_at(problem.t_k) || overlap_at(problem.t_f));
    }

    #[test]
    fn forbidden_sets_are_exact(problem in arb_problem()) {
        let result = plan(&problem).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let base = problem.trajectory(0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let r0 = problem.vehicle_radius;
        for (o, report) in problem.obstacles.iter().zip(&result.obstacles) {
            let Some(f) = report.forbidden else {
                // Never constrains: a spread of a6 values all clear it.
                for a6 in [-1e-2, -1e-5, 0.0, 1e-5, 1e-2] {
                    prop_assert!(min_margin(&base.with_a6(a6), o, r0) >= -1e-6);
                }
                continue;
            };
            if f.is_all() {
                continue;
            }
            // Inside: the midpoint (or a point near the finite end of a half-line) collides.
            let inside = match (f.lo.is_finite(), f.hi.is_finite()) {
                (true, true) => 0.5 * (f.lo + f.hi),
                (true, false) => f.lo + 0.25 * f.lo.abs().max(1e-9),
                (false, true) => f.hi - 0.25 * f.hi.abs().max(1e-9),
                (false, false) => unreachable!("handled above"),
            };
            let width_ok = !(f.lo.is_finite() && f.hi.is_finite()) || f.hi - f.lo > 1e-6 * f.hi.abs().max(f.lo.abs());
            if width_ok {
                prop_assert!(min_margin(&base.with_a6(inside), o, r0) < 1e-9, "a6 {} in {:?}", inside, f);
            }
            // Just outside each finite end: clear of this obstacle.
            for end in [f.lo, f.hi] {
                if end.is_finite() {
                    let out = end + (end - inside).signum() * 1e-9 * end.abs().max(1e-12);
                    prop_assert!(min_margin(&base.with_a6(out), o, r0) >= -1e-6);
                }
            }
        }
    }

    #[test]
    fn collision_window_matches_brute_force(problem in arb_problem()) {
        let result = plan(&problem).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let base = problem.trajectory(0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let n = 4000;
        let step = (problem.t_f - problem.t_k) / n as f64;
        for (o, report) in problem.obstacles.iter().zip(&result.obstacles) {
            let r = o.radius + problem.vehicle_radius;
            let inside: Vec<f64> = (0..=n)
                .map(|j| problem.t_k + step * j as f64)
                .filter(|&t| (base.x_at(t) - (o.x + o.vx * (t - problem.t_k))).abs() < r)
                .collect();
            match (report.window, inside.first(), inside.last()) {
                (Some([a, b]), Some(&first), Some(&last)) => {
                    prop_assert!(a <= first + 1e-9 && first - a <= step * 1.0001);
                    prop_assert!(b >= last - 1e-9 && b - last <= step * 1.0001);
                }
                (Some([a, b]), None, None) => prop_assert!(b - a <= step * 1.0001),
                (None, None, None) => {}
                (w, f, l) => prop_assert!(false, "window {:?} vs samples {:?}..{:?}", w, f, l),
            }
        }
    }

    #[test]
    fn optimal_a6_minimises_the_cost(problem in arb_problem()) {
        let result = plan(&problem).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let base = problem.trajectory(0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let line = problem.reference_line().map_err(|e| TestCaseError::fail(e.to_string()))?;
        let a = result.a6_unconstrained;
        let j = |v: f64| simpson_cost(&base.path().with_a6(v), &line);
        let delta = 1e-3 * a.abs().max(base.path().span().abs().powi(-5));
        prop_assert!(j(a) <= j(a + delta) && j(a) <= j(a - delta));
    }
}
