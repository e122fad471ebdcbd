//! The serde API of one planning step (the `plan` subcommand's JSON in and out).

use std::f64::consts::FRAC_PI_2;

use serde::{Deserialize, Serialize};

use super::PlanError;
use super::interval::{Interval, feasible_set, nearest_feasible};
use super::obstacle::{
    Obstacle, ObstacleConstraint, ends_collide, min_clearance, obstacle_constraint,
};
use super::optimal::optimal_a6;
use super::path::{PolynomialPath, ReferenceLine, Trajectory, VehicleState};
use super::sampling::Sampling;

/// The start (x0, y0) of the reference line L: the ORIGINAL start of the manoeuvre, not
/// the current state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineStart {
    /// x0 (m).
    pub x0: f64,
    /// y0 (m).
    pub y0: f64,
}

/// A point (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
}

/// One planning step, in the coordinates given (no frame change: headings within 90
/// degrees of the x axis, x_f != x_k; x_f < x_k is a reversing step, u1 < 0). Angles in
/// radians, lengths in metres, times in seconds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanProblem {
    /// Vehicle state at t_k.
    pub state: VehicleState,
    /// Goal state at t_f.
    pub goal: VehicleState,
    /// Start of the reference line L.
    pub line_start: LineStart,
    /// End of the reference line L; the goal's position when omitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub line_end: Option<Point>,
    /// Start time of the step.
    pub t_k: f64,
    /// Time the goal is reached (> t_k).
    pub t_f: f64,
    /// Wheelbase l (> 0).
    pub wheelbase: f64,
    /// Vehicle radius r_0 (>= 0).
    pub vehicle_radius: f64,
    /// Obstacles, positions at t_k.
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
}

/// What one obstacle contributes, in the order of [`PlanProblem::obstacles`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObstacleReport {
    /// Open interval of colliding a6 values, null when the obstacle never constrains a6.
    pub forbidden: Option<Interval>,
    /// Collision time window [t_a, t_b] within [t_k, t_f], null when none.
    pub window: Option<[f64; 2]>,
    /// The start overlaps this obstacle.
    pub start_collides: bool,
    /// The goal overlaps this obstacle (at t_f).
    pub goal_collides: bool,
    /// Smallest distance between centres minus (r_i + r_0) along the chosen path
    /// (sampled and refined); null when infeasible.
    pub min_clearance: Option<f64>,
}

/// The planned step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanResult {
    /// a0..a6 of y(x) = sum a_j x^j for the chosen a6, in the given coordinates; null
    /// when infeasible. Computed by binomial expansion of `shifted_coefficients`, which
    /// come from the Hermite form (no linear solve): exact in exact arithmetic, but
    /// digits are lost when |x_k| >> x_f - x_k, so prefer the shifted form.
    pub coefficients: Option<[f64; 7]>,
    /// c0..c6 of y = sum c_j (x - x_k)^j for the chosen a6 (c6 = a6); null when
    /// infeasible.
    pub shifted_coefficients: Option<[f64; 7]>,
    /// x_k, the origin of `shifted_coefficients`.
    pub x_k: f64,
    /// dx/dt = (x_f - x_k) / (t_f - t_k).
    pub w1: f64,
    /// Per obstacle.
    pub obstacles: Vec<ObstacleReport>,
    /// Feasible a6: sorted disjoint closed pieces, infinite ends as "inf"/"-inf".
    pub feasible_set: Vec<Interval>,
    /// Minimiser a6* of J without obstacles.
    pub a6_unconstrained: f64,
    /// The a6 used: a6* if feasible, else the nearest feasible boundary; null when the
    /// feasible set is empty.
    pub a6_chosen: Option<f64>,
    /// The feasible set is not empty.
    pub feasible: bool,
    /// a6* was infeasible and a6_chosen is a boundary of the feasible set.
    pub projected_to_boundary: bool,
    /// The start or the goal overlaps an obstacle (then nothing is feasible).
    pub start_or_goal_collides: bool,
    /// J(a6_chosen) = integral of (y - L)^2 over the step (m^3).
    pub cost: Option<f64>,
    /// Largest |curvature| along the chosen path (sampled, 1/m).
    pub max_abs_curvature: Option<f64>,
    /// Largest |steering angle| the chosen path needs (sampled, rad). The method has no
    /// steering limit: the caller must check this against the actuator.
    pub max_abs_steering: Option<f64>,
}

/// Numerical settings of the planner.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanOptions {
    /// Time sampling of the collision windows and of the clearance diagnostic.
    pub sampling: Sampling,
    /// Leave out the clearance diagnostic ([`ObstacleReport::min_clearance`] is null):
    /// guidance, which plans several problems every T_s, does not read it, and it
    /// costs more than the plan.
    pub skip_clearance: bool,
    /// Stop at infeasibility: once a start or a goal overlaps an obstacle, or the
    /// forbidden intervals of the obstacles so far leave no a6, the rest are not
    /// constrained (their sampling is most of a plan's cost). The result is the same
    /// infeasible one, but [`PlanResult::obstacles`] holds only the reports computed
    /// (and [`PlanResult::start_or_goal_collides`] only what they show): guidance,
    /// which reads neither, replans infeasible problems every T_s for a standing car.
    pub stop_when_infeasible: bool,
}

/// A planned step with the trajectory a follower needs.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedStep {
    /// The serialisable result.
    pub result: PlanResult,
    /// The chosen path, time-parameterised; None when infeasible.
    pub trajectory: Option<Trajectory>,
}

fn check_finite(field: &str, value: f64) -> Result<(), PlanError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(PlanError::NonFinite {
            field: field.to_owned(),
            value,
        })
    }
}

fn check_angle(field: &str, value: f64, steering: bool) -> Result<(), PlanError> {
    if value.abs() < FRAC_PI_2 {
        Ok(())
    } else if steering {
        Err(PlanError::SteeringOutOfRange {
            field: field.to_owned(),
            value,
        })
    } else {
        Err(PlanError::HeadingOutOfRange {
            field: field.to_owned(),
            value,
        })
    }
}

fn check_radius(field: &str, value: f64) -> Result<(), PlanError> {
    if value >= 0.0 {
        Ok(())
    } else {
        Err(PlanError::NegativeRadius {
            field: field.to_owned(),
            value,
        })
    }
}

impl PlanProblem {
    /// Check the problem; the first offending field is named.
    pub fn validate(&self) -> Result<(), PlanError> {
        // Values first, names only for the one that fails: validate runs for every
        // candidate the planner scores, and building field names was most of its cost.
        for (name, s) in [("state", &self.state), ("goal", &self.goal)] {
            if [s.x, s.y, s.theta, s.phi].iter().all(|v| v.is_finite()) {
                continue;
            }
            check_finite(&format!("{name}.x"), s.x)?;
            check_finite(&format!("{name}.y"), s.y)?;
            check_finite(&format!("{name}.theta"), s.theta)?;
            check_finite(&format!("{name}.phi"), s.phi)?;
        }
        check_finite("line_start.x0", self.line_start.x0)?;
        check_finite("line_start.y0", self.line_start.y0)?;
        if let Some(end) = &self.line_end {
            check_finite("line_end.x", end.x)?;
            check_finite("line_end.y", end.y)?;
        }
        check_finite("t_k", self.t_k)?;
        check_finite("t_f", self.t_f)?;
        check_finite("wheelbase", self.wheelbase)?;
        check_finite("vehicle_radius", self.vehicle_radius)?;
        for (i, o) in self.obstacles.iter().enumerate() {
            if [o.x, o.y, o.radius, o.vx, o.vy]
                .iter()
                .all(|v| v.is_finite())
                && o.radius >= 0.0
            {
                continue;
            }
            check_finite(&format!("obstacles[{i}].x"), o.x)?;
            check_finite(&format!("obstacles[{i}].y"), o.y)?;
            check_finite(&format!("obstacles[{i}].radius"), o.radius)?;
            check_finite(&format!("obstacles[{i}].vx"), o.vx)?;
            check_finite(&format!("obstacles[{i}].vy"), o.vy)?;
            check_radius(&format!("obstacles[{i}].radius"), o.radius)?;
        }
        if self.t_f <= self.t_k {
            return Err(PlanError::TimeNotIncreasing {
                t_k: self.t_k,
                t_f: self.t_f,
            });
        }
        if self.wheelbase <= 0.0 {
            return Err(PlanError::NonPositiveWheelbase {
                value: self.wheelbase,
            });
        }
        // A car's, as `vehicle.wheelbase` of the configuration (1e300 is no vehicle);
        // the field's path only built for a value outside.
        if !crate::ranges::WHEELBASE.contains(self.wheelbase) {
            crate::ranges::WHEELBASE
                .check(&ugv_fields::FieldPath::of(&["wheelbase"]), self.wheelbase)
                .map_err(|e| PlanError::OutOfRange {
                    field: e.path.to_string(),
                    message: e.message,
                })?;
        }
        check_radius("vehicle_radius", self.vehicle_radius)?;
        check_angle("state.theta", self.state.theta, false)?;
        check_angle("goal.theta", self.goal.theta, false)?;
        check_angle("state.phi", self.state.phi, true)?;
        check_angle("goal.phi", self.goal.phi, true)?;
        if self.goal.x == self.state.x {
            return Err(PlanError::DegenerateSpan {
                x_k: self.state.x,
                x_f: self.goal.x,
            });
        }
        let line = self.reference_line_unchecked();
        if line.x0 == line.x1 {
            return Err(PlanError::VerticalReferenceLine { x: line.x0 });
        }
        Ok(())
    }

    fn reference_line_unchecked(&self) -> ReferenceLine {
        let end = self.line_end.unwrap_or(Point {
            x: self.goal.x,
            y: self.goal.y,
        });
        ReferenceLine {
            x0: self.line_start.x0,
            y0: self.line_start.y0,
            x1: end.x,
            y1: end.y,
        }
    }

    /// The reference line L: from `line_start` to `line_end` (default: the goal).
    pub fn reference_line(&self) -> Result<ReferenceLine, PlanError> {
        let l = self.reference_line_unchecked();
        ReferenceLine::new(l.x0, l.y0, l.x1, l.y1)
    }

    /// The step's trajectory for a given a6 (after validation).
    pub fn trajectory(&self, a6: f64) -> Result<Trajectory, PlanError> {
        self.validate()?;
        let path = PolynomialPath::from_states(&self.state, &self.goal, self.wheelbase, a6)?;
        Trajectory::new(path, self.t_k, self.t_f)
    }
}

/// The obstacles' constraints in order, up to the one that leaves nothing feasible
/// ([`PlanOptions::stop_when_infeasible`]). An obstacle the start or the goal
/// overlaps (checked first for all of them: two positions each) is the only one
/// constrained. Otherwise the forbidden intervals can only leave no a6 once a lower
/// and an upper half-line are among them; from then on the feasible set of those so
/// far is checked after each, and a set already empty stays empty with more.
fn constraints_until_infeasible(
    problem: &PlanProblem,
    base: &Trajectory,
    sampling: &Sampling,
) -> Vec<ObstacleConstraint> {
    let r0 = problem.vehicle_radius;
    if let Some(o) = problem.obstacles.iter().find(|o| ends_collide(base, o, r0)) {
        return vec![obstacle_constraint(base, o, r0, sampling)];
    }
    let mut out = Vec::with_capacity(problem.obstacles.len());
    let mut forbidden = Vec::new();
    let (mut below, mut above) = (false, false);
    for o in &problem.obstacles {
        let c = obstacle_constraint(base, o, r0, sampling);
        if let Some(f) = c.forbidden {
            below |= f.lo == f64::NEG_INFINITY;
            above |= f.hi == f64::INFINITY;
            forbidden.push(f);
        }
        out.push(c);
        if below && above && feasible_set(&forbidden).is_empty() {
            break;
        }
    }
    out
}

/// Plan one step with the default options.
pub fn plan(problem: &PlanProblem) -> Result<PlanResult, PlanError> {
    plan_with(problem, &PlanOptions::default()).map(|step| step.result)
}

/// Plan one step: constraints of every obstacle, feasible set, optimal a6.
pub fn plan_with(problem: &PlanProblem, options: &PlanOptions) -> Result<PlannedStep, PlanError> {
    let sampling = options.sampling;
    if sampling.steps < 16 || sampling.steps > 1 << 22 {
        return Err(PlanError::InvalidOption {
            name: "sampling.steps",
            reason: format!("{} is outside [16, 4194304]", sampling.steps),
        });
    }
    if sampling.refine_candidates == 0 {
        return Err(PlanError::InvalidOption {
            name: "sampling.refine_candidates",
            reason: "must be at least 1".to_owned(),
        });
    }
    let base = problem.trajectory(0.0)?;
    let line = problem.reference_line()?;
    let a6_star = optimal_a6(base.path(), &line);
    if !a6_star.is_finite() {
        return Err(PlanError::Overflow {
            what: "unconstrained a6",
        });
    }
    let constraints: Vec<_> = if options.stop_when_infeasible {
        constraints_until_infeasible(problem, &base, &sampling)
    } else {
        problem
            .obstacles
            .iter()
            .map(|o| obstacle_constraint(&base, o, problem.vehicle_radius, &sampling))
            .collect()
    };
    let start_or_goal_collides = constraints
        .iter()
        .any(|c| c.start_collides || c.goal_collides);
    let forbidden: Vec<Interval> = constraints.iter().filter_map(|c| c.forbidden).collect();
    let feasible = if start_or_goal_collides {
        Vec::new()
    } else {
        feasible_set(&forbidden)
    };
    let choice = nearest_feasible(a6_star, &feasible);
    let trajectory = choice.map(|(a6, _)| base.with_a6(a6));

    let obstacles = constraints
        .iter()
        .zip(problem.obstacles.iter())
        .map(|(c, o)| ObstacleReport {
            forbidden: c.forbidden,
            window: c.window,
            start_collides: c.start_collides,
            goal_collides: c.goal_collides,
            min_clearance: trajectory
                .as_ref()
                .filter(|_| !options.skip_clearance)
                .map(|t| min_clearance(t, o, problem.vehicle_radius, &sampling)),
        })
        .collect();

    let (max_abs_curvature, max_abs_steering) = match &trajectory {
        Some(t) => {
            let path = t.path();
            let n = 1000;
            let mut kappa = 0.0_f64;
            for j in 0..=n {
                let x = path.x_k() + path.span() * (j as f64 / n as f64);
                kappa = kappa.max(path.curvature(x).abs());
            }
            // phi = atan(l kappa) is monotonic in |kappa|.
            (Some(kappa), Some((path.wheelbase() * kappa).atan()))
        }
        None => (None, None),
    };

    let result = PlanResult {
        coefficients: trajectory.as_ref().map(|t| t.path().coefficients()),
        shifted_coefficients: trajectory.as_ref().map(|t| t.path().shifted_coefficients()),
        x_k: problem.state.x,
        w1: base.w1(),
        obstacles,
        feasible: !feasible.is_empty(),
        feasible_set: feasible,
        a6_unconstrained: a6_star,
        a6_chosen: choice.map(|(a6, _)| a6),
        projected_to_boundary: choice.is_some_and(|(_, projected)| projected),
        start_or_goal_collides,
        cost: trajectory.as_ref().map(|t| t.path().reference_cost(&line)),
        max_abs_curvature,
        max_abs_steering,
    };
    Ok(PlannedStep { result, trajectory })
}
