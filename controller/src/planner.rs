//! Optimal collision-free polynomial path of one planning step (Qu, Wang & Plaisted
//! 2004, as transcribed in the seed paper and corrected by shared/seed/ERRATA.md).
//!
//! # The bare method
//!
//! In the coordinates given (no frame change) the path is y(x) = p(x) + a6 h(x) on
//! [x_k, x_f]: p is the quintic meeting y, dy/dx = tan(theta) and
//! d2y/dx2 = tan(phi) / (l cos^3(theta)) at both ends, and
//! h(x) = (x - x_k)^3 (x - x_f)^3 ([`PolynomialPath`]). x advances uniformly in time,
//! w1 = (x_f - x_k) / (t_f - t_k) ([`Trajectory`]).
//!
//! 1. Each obstacle forbids an open interval of a6: the union over its collision window
//!    of the per-instant roots of G_i(a6) ([`obstacle_constraint`]); a half-line when
//!    its x-band reaches the start or the goal; everything when the start or the goal
//!    collides.
//! 2. The feasible set is the complement of the union of those intervals
//!    ([`feasible_set`]).
//! 3. a6* minimises J = int (y - L)^2 dx in closed form ([`optimal_a6`]); when it is
//!    infeasible the nearest feasible boundary is taken ([`nearest_feasible`]), which is
//!    the constrained minimiser because J is a convex quadratic in a6.
//!
//! [`plan`] runs the whole step from a JSON-friendly [`PlanProblem`] to a [`PlanResult`].
//!
//! # Time sampling
//!
//! The extremes of the root bounds over a collision window are found by sampling the
//! window uniformly ([`Sampling::steps`], default 2048 steps, both ends included) and
//! refining the 8 best discrete local extrema by golden section on the two steps around
//! each, down to floating-point resolution in t. The per-instant roots are exact, so the
//! chosen a6 clears every obstacle up to that refinement.
//!
//! # Not covered here
//!
//! The method has no steering or curvature limit: [`PlanResult::max_abs_steering`]
//! reports what the chosen path needs and the caller must compare it with the actuator
//! (with a margin). Steps whose heading reaches 90 degrees from the x axis must be
//! planned in a rotated frame by the caller.

mod api;
mod interval;
mod obstacle;
mod optimal;
mod path;
mod sampling;

pub use api::{
    LineStart, ObstacleReport, PlanOptions, PlanProblem, PlanResult, PlannedStep, Point, plan,
    plan_with,
};
pub use interval::{Interval, feasible_set, nearest_feasible};
pub use obstacle::{
    Obstacle, ObstacleConstraint, collision_window, min_clearance, obstacle_constraint,
};
pub use optimal::{cost_curvature, optimal_a6};
pub use path::{
    ControlInputs, EndConditions, PolynomialPath, ReferenceLine, Trajectory, VehicleState,
};
pub use sampling::Sampling;

/// Why a planning step could not be set up.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// An input is NaN or infinite.
    #[error("{field} is not a finite number ({value})")]
    NonFinite { field: String, value: f64 },
    /// x_f == x_k: y(x) cannot describe the step.
    #[error(
        "goal x ({x_f}) equals start x ({x_k}): y(x) cannot describe the step; plan it in a rotated frame"
    )]
    DegenerateSpan { x_k: f64, x_f: f64 },
    /// t_f <= t_k.
    #[error("t_f ({t_f}) must be later than t_k ({t_k})")]
    TimeNotIncreasing { t_k: f64, t_f: f64 },
    /// A radius below zero.
    #[error("{field} must not be negative, got {value}")]
    NegativeRadius { field: String, value: f64 },
    /// l <= 0.
    #[error("wheelbase must be positive, got {value}")]
    NonPositiveWheelbase { value: f64 },
    /// A physical input beyond its plausible range (`crate::ranges`), with the range
    /// and its source.
    #[error("{field}: {message}")]
    OutOfRange { field: String, message: String },
    /// |theta| >= 90 degrees: tan(theta) and 1/cos(theta) blow up.
    #[error(
        "{field} = {value} rad: the heading must be within 90 degrees of the x axis (tan(theta) blows up); plan in a rotated frame"
    )]
    HeadingOutOfRange { field: String, value: f64 },
    /// |phi| >= 90 degrees.
    #[error("{field} = {value} rad: the steering angle must be within 90 degrees")]
    SteeringOutOfRange { field: String, value: f64 },
    /// The reference line's ends have the same x, so L is not a function of x.
    #[error("the reference line is vertical (both ends at x = {x})")]
    VerticalReferenceLine { x: f64 },
    /// A numerical option is out of range.
    #[error("option {name}: {reason}")]
    InvalidOption { name: &'static str, reason: String },
    /// Finite inputs whose path overflows f64.
    #[error("{what} overflows: inputs too extreme")]
    Overflow { what: &'static str },
}
