//! The a6 that keeps the path closest to the reference line (ERRATA 7).
//!
//! # Derivation
//!
//! J(a6) = int_{x_k}^{x_f} (p - L + a6 h)^2 dx = f1 a6^2 + 2 a6 int h (p - L) dx + const,
//! so the minimiser is a6* = -int h e dx / int h^2 dx with e = p - L.
//!
//! Substitute x = x_k + D sigma: h = D^6 sigma^3 (sigma - 1)^3 and dx = D dsigma.
//! * f1 = int h^2 dx = D^13 B(7, 7) = D^13 6! 6! / 13! = D^13 / 12012.
//! * e is a quintic, so it has the Hermite form with the data
//!   e_k = y_k - L(x_k), y'_k - m, y''_k, e_f = y_f - L(x_f), y'_f - m, y''_f
//!   (m the line's slope; L'' = 0). With
//!   I_i = int_0^1 sigma^3 (sigma - 1)^3 H_i dsigma =
//!   (-1/280, -3/3080, -1/11088, -1/280, 3/3080, -1/11088) (from
//!   int_0^1 sigma^(n+3) (sigma - 1)^3 = -B(n + 4, 4)), the slope terms combine to
//!   D (I_1 (y'_k - m) + I_4 (y'_f - m)) = -3 D / 3080 (y'_f - y'_k): m cancels.
//!
//! Multiplying out (-12012 I_i = 429/10, 117/10, 13/12, ...):
//!
//! a6* = 13 / (60 D^6) [ 5 D^2 (y''_k + y''_f) - 54 D (y'_f - y'_k) + 198 (e_k + e_f) ].
//!
//! ERRATA 7's formula is the special case e_f = 0, i.e. it holds exactly when the goal
//! lies on L — which is always the case when L ends at the goal, but not when a
//! separate `line_end` is configured. Both integrals change sign with D, so the formula
//! holds for x_f < x_k as well (J is then taken over the step with positive measure).

use super::path::{PolynomialPath, ReferenceLine};

/// The unconstrained minimiser a6* of J (see the module docs for the derivation).
/// Evaluated with the powers of D divided into each term, so it does not overflow for
/// long steps.
pub fn optimal_a6(path: &PolynomialPath, line: &ReferenceLine) -> f64 {
    let d = path.span();
    let k = path.start_conditions();
    let f = path.goal_conditions();
    let e_k = k.y - line.y(path.x_k());
    let e_f = f.y - line.y(path.x_f());
    let d2 = d * d;
    let d4 = d2 * d2;
    13.0 / 60.0
        * (5.0 * (k.d2y + f.d2y) / d4 - 54.0 * (f.dy - k.dy) / (d4 * d)
            + 198.0 * (e_k + e_f) / (d4 * d2))
}

/// f1 = int h^2 dx = D^13 / 12012 (with the sign of D, as in the x-form of J).
pub fn cost_curvature(path: &PolynomialPath) -> f64 {
    path.span().powi(13) / 12012.0
}

#[cfg(test)]
mod tests {
    use super::super::PlanError;
    use super::super::path::VehicleState;
    use super::*;

    #[test]
    fn minimiser_is_a_stationary_point_of_the_exact_cost() -> Result<(), PlanError> {
        let start = VehicleState {
            x: 2.0,
            y: 1.0,
            theta: 0.3,
            phi: 0.2,
        };
        let goal = VehicleState {
            x: 17.0,
            y: 6.0,
            theta: -0.1,
            phi: 0.0,
        };
        let line = ReferenceLine::new(-3.0, -1.0, 17.0, 6.0)?;
        let path = PolynomialPath::from_states(&start, &goal, 1.6, 0.0)?;
        let a = optimal_a6(&path, &line);
        let j = |v: f64| path.with_a6(v).reference_cost(&line);
        // J is an exact quadratic: its second difference is 2 f1 step^2 and its
        // central first difference vanishes at the minimiser.
        let step = 1e-6;
        let curv = (j(a + step) - 2.0 * j(a) + j(a - step)) / (step * step);
        assert!((curv / (2.0 * cost_curvature(&path)) - 1.0).abs() < 1e-3);
        let slope = (j(a + step) - j(a - step)) / (2.0 * step);
        assert!(slope.abs() < 1e-6 * curv * step.max(a.abs()) + 1e-9);
        Ok(())
    }
}
