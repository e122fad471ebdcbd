//! The sixth-order polynomial path y(x) = p(x) + a6 h(x) and its time parameterisation.
//!
//! # Boundary conditions
//!
//! With the kinematic model (paper eq. 3, `x' = u1 cos(theta)`, `y' = u1 sin(theta)`,
//! `theta' = u1 tan(phi) / l`, `phi' = u2`) a path written as y(x) has
//! `dy/dx = tan(theta)` and curvature `kappa = y'' / (1 + y'^2)^(3/2) = y'' cos^3(theta)`;
//! since `kappa = tan(phi) / l` this gives `y'' = tan(phi) / (l cos^3(theta))` (ERRATA 3).
//! Each end of the step therefore fixes y, y' and y''.
//!
//! # Robust construction
//!
//! The paper solves `B a = Y - A a6` with the raw monomial matrix B in x, which is
//! hopelessly ill-conditioned once |x| is large compared to the step (entries range
//! from 1 to x^5). Here the quintic is written on the normalised abscissa
//! `sigma = (x - x_k) / D`, `D = x_f - x_k`, in the quintic Hermite basis
//! H0..H5 on [0, 1] (H0/H3 carry the end values, H1/H4 the slopes, H2/H5 the second
//! derivatives):
//!
//! `p = y_k H0 + D y'_k H1 + D^2 y''_k H2 + y_f H3 + D y'_f H4 + D^2 y''_f H5`.
//!
//! No linear system is solved at all; the coefficients of p in sigma are small integer
//! combinations of the boundary data. Derivatives in x follow from the chain rule
//! `d/dx = (1/D) d/dsigma`.
//!
//! h(x) = (x - x_k)^3 (x - x_f)^3 (ERRATA 1) is always evaluated in this factored form,
//! as are its derivatives. h and h', h'' vanish at both ends, so a6 does not disturb the
//! boundary conditions; and `h = -(s (D - s))^3` with `s = x - x_k`, so h < 0 strictly
//! inside the step whichever sign D has.

use serde::{Deserialize, Serialize};

use super::PlanError;

/// Monomial coefficients (sigma^0 .. sigma^5) of the quintic Hermite basis on [0, 1].
const HERMITE: [[f64; 6]; 6] = [
    [1.0, 0.0, 0.0, -10.0, 15.0, -6.0],
    [0.0, 1.0, 0.0, -6.0, 8.0, -3.0],
    [0.0, 0.0, 0.5, -1.5, 1.5, -0.5],
    [0.0, 0.0, 0.0, 10.0, -15.0, 6.0],
    [0.0, 0.0, 0.0, -4.0, 7.0, -3.0],
    [0.0, 0.0, 0.0, 0.5, -1.0, 0.5],
];

/// Seven-point Gauss-Legendre rule on [-1, 1]: exact for polynomials up to degree 13,
/// so it integrates the squared sextic deviation (degree 12) of the cost exactly.
const GAUSS7: [(f64, f64); 7] = [
    (0.0, 0.417_959_183_673_469_4),
    (0.405_845_151_377_397_2, 0.381_830_050_505_118_9),
    (-0.405_845_151_377_397_2, 0.381_830_050_505_118_9),
    (0.741_531_185_599_394_4, 0.279_705_391_489_276_7),
    (-0.741_531_185_599_394_4, 0.279_705_391_489_276_7),
    (0.949_107_912_342_758_5, 0.129_484_966_168_869_7),
    (-0.949_107_912_342_758_5, 0.129_484_966_168_869_7),
];

/// A vehicle configuration: position, heading theta and steering angle phi (radians).
///
/// Used for the state at t_k, the goal at t_f and the time-parameterised state along a
/// planned path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleState {
    /// x position (m).
    pub x: f64,
    /// y position (m).
    pub y: f64,
    /// Heading from the x axis (rad); |theta| < 90 degrees for the y(x) form.
    pub theta: f64,
    /// Front-wheel steering angle (rad); |phi| < 90 degrees.
    pub phi: f64,
}

/// Value, first and second x-derivative of the path at one end of the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndConditions {
    /// y at the end.
    pub y: f64,
    /// dy/dx = tan(theta).
    pub dy: f64,
    /// d2y/dx2 = tan(phi) / (l cos^3(theta)).
    pub d2y: f64,
}

impl EndConditions {
    /// The boundary conditions a vehicle state imposes (ERRATA 3).
    pub fn from_state(state: &VehicleState, wheelbase: f64) -> Self {
        let cos = state.theta.cos();
        Self {
            y: state.y,
            dy: state.theta.tan(),
            d2y: state.phi.tan() / (wheelbase * cos * cos * cos),
        }
    }
}

/// Inputs of the kinematic model along the path, and the paper's auxiliary inputs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControlInputs {
    /// Linear speed u1 = w1 / cos(theta) (ERRATA 9: rho = 1), m/s.
    pub u1: f64,
    /// Steering rate u2 = d(phi)/dt (ERRATA 8 sign), rad/s.
    pub u2: f64,
    /// dx/dt = (x_f - x_k) / (t_f - t_k), m/s.
    pub w1: f64,
    /// w2 = y'''(x(t)) w1, the paper's Taylor form of it evaluated directly.
    pub w2: f64,
}

/// The path y(x) = p(x) + a6 h(x) of one planning step, in the coordinates given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolynomialPath {
    x_k: f64,
    x_f: f64,
    start: EndConditions,
    goal: EndConditions,
    wheelbase: f64,
    /// Coefficients of p in sigma = (x - x_k) / D.
    p_sigma: [f64; 6],
    a6: f64,
}

impl PolynomialPath {
    /// The path between two vehicle states for a given a6.
    ///
    /// Only checks what the construction itself needs (x_f != x_k, positive wheelbase,
    /// finite boundary data); [`super::plan`] validates a whole problem.
    pub fn from_states(
        start: &VehicleState,
        goal: &VehicleState,
        wheelbase: f64,
        a6: f64,
    ) -> Result<Self, PlanError> {
        if !(wheelbase.is_finite() && wheelbase > 0.0) {
            return Err(PlanError::NonPositiveWheelbase { value: wheelbase });
        }
        Self::from_conditions(
            start.x,
            EndConditions::from_state(start, wheelbase),
            goal.x,
            EndConditions::from_state(goal, wheelbase),
            wheelbase,
            a6,
        )
    }

    /// The path from explicit end conditions (y, y', y'') at x_k and x_f.
    pub fn from_conditions(
        x_k: f64,
        start: EndConditions,
        x_f: f64,
        goal: EndConditions,
        wheelbase: f64,
        a6: f64,
    ) -> Result<Self, PlanError> {
        let d = x_f - x_k;
        if d == 0.0 {
            return Err(PlanError::DegenerateSpan { x_k, x_f });
        }
        let weights = [
            start.y,
            d * start.dy,
            d * d * start.d2y,
            goal.y,
            d * goal.dy,
            d * d * goal.d2y,
        ];
        let mut p_sigma = [0.0; 6];
        for (w, basis) in weights.iter().zip(HERMITE.iter()) {
            for (c, b) in p_sigma.iter_mut().zip(basis.iter()) {
                *c += w * b;
            }
        }
        let all = [x_k, x_f, d, a6, wheelbase];
        if all.iter().chain(p_sigma.iter()).any(|v| !v.is_finite()) {
            return Err(PlanError::Overflow {
                what: "path boundary conditions",
            });
        }
        Ok(Self {
            x_k,
            x_f,
            start,
            goal,
            wheelbase,
            p_sigma,
            a6,
        })
    }

    /// The same boundary conditions with another a6.
    pub fn with_a6(&self, a6: f64) -> Self {
        Self { a6, ..*self }
    }

    /// The free parameter a6 (coefficient of x^6).
    pub fn a6(&self) -> f64 {
        self.a6
    }

    /// x at the start of the step.
    pub fn x_k(&self) -> f64 {
        self.x_k
    }

    /// x at the goal.
    pub fn x_f(&self) -> f64 {
        self.x_f
    }

    /// D = x_f - x_k.
    pub fn span(&self) -> f64 {
        self.x_f - self.x_k
    }

    /// The `n + 1` stations from x_k to x_f, evenly spaced (`n` at least 1).
    pub fn stations(&self, n: usize) -> impl Iterator<Item = f64> + use<> {
        let (x_k, span) = (self.x_k(), self.span());
        (0..=n).map(move |j| x_k + span * j as f64 / n as f64)
    }

    /// The wheelbase l used for the curvature conditions.
    pub fn wheelbase(&self) -> f64 {
        self.wheelbase
    }

    /// (y, y', y'') imposed at x_k.
    pub fn start_conditions(&self) -> EndConditions {
        self.start
    }

    /// (y, y', y'') imposed at x_f.
    pub fn goal_conditions(&self) -> EndConditions {
        self.goal
    }

    /// p and its first three x-derivatives.
    fn quintic_derivs(&self, x: f64) -> [f64; 4] {
        let d = self.span();
        let sigma = (x - self.x_k) / d;
        let c = &self.p_sigma;
        let v =
            ((((c[5] * sigma + c[4]) * sigma + c[3]) * sigma + c[2]) * sigma + c[1]) * sigma + c[0];
        let d1 = (((5.0 * c[5] * sigma + 4.0 * c[4]) * sigma + 3.0 * c[3]) * sigma + 2.0 * c[2])
            * sigma
            + c[1];
        let d2 = ((20.0 * c[5] * sigma + 12.0 * c[4]) * sigma + 6.0 * c[3]) * sigma + 2.0 * c[2];
        let d3 = (60.0 * c[5] * sigma + 24.0 * c[4]) * sigma + 6.0 * c[3];
        [v, d1 / d, d2 / (d * d), d3 / (d * d * d)]
    }

    /// h and its first three x-derivatives, all in factored form.
    fn h_derivs(&self, x: f64) -> [f64; 4] {
        let s1 = x - self.x_k;
        let s2 = x - self.x_f;
        let s1s2 = s1 * s2;
        [
            s1s2 * s1s2 * s1s2,
            3.0 * s1s2 * s1s2 * (s1 + s2),
            6.0 * s1s2 * (s2 * s2 + 3.0 * s1s2 + s1 * s1),
            6.0 * (s2 * s2 * s2 + 9.0 * s1s2 * (s1 + s2) + s1 * s1 * s1),
        ]
    }

    /// y and its first three x-derivatives.
    pub fn derivatives(&self, x: f64) -> [f64; 4] {
        let p = self.quintic_derivs(x);
        let h = self.h_derivs(x);
        [
            p[0] + self.a6 * h[0],
            p[1] + self.a6 * h[1],
            p[2] + self.a6 * h[2],
            p[3] + self.a6 * h[3],
        ]
    }

    /// The quintic p(x) that meets the six boundary conditions (a6 = 0).
    pub fn quintic(&self, x: f64) -> f64 {
        self.quintic_derivs(x)[0]
    }

    /// h(x) = (x - x_k)^3 (x - x_f)^3, in factored form.
    pub fn h(&self, x: f64) -> f64 {
        self.h_derivs(x)[0]
    }

    /// y(x).
    pub fn y(&self, x: f64) -> f64 {
        self.derivatives(x)[0]
    }

    /// dy/dx.
    pub fn dy_dx(&self, x: f64) -> f64 {
        self.derivatives(x)[1]
    }

    /// d2y/dx2.
    pub fn d2y_dx2(&self, x: f64) -> f64 {
        self.derivatives(x)[2]
    }

    /// d3y/dx3.
    pub fn d3y_dx3(&self, x: f64) -> f64 {
        self.derivatives(x)[3]
    }

    /// Heading theta = atan(dy/dx) of a vehicle driving along the path.
    pub fn heading(&self, x: f64) -> f64 {
        self.dy_dx(x).atan()
    }

    /// Signed curvature y'' / (1 + y'^2)^(3/2) (1/m).
    pub fn curvature(&self, x: f64) -> f64 {
        let [_, d1, d2, _] = self.derivatives(x);
        // sqrt, not hypot: d1^2 + 1 neither underflows nor loses digits, and where d1^2
        // overflows cos^3 is 0 either way.
        let cos = 1.0 / (d1 * d1 + 1.0).sqrt();
        d2 * cos * cos * cos
    }

    /// Steering angle phi = atan(l kappa) that the kinematic model needs (rad).
    pub fn steering_angle(&self, x: f64) -> f64 {
        (self.wheelbase * self.curvature(x)).atan()
    }

    /// Coefficients c0..c6 of y in the shifted abscissa s = x - x_k.
    ///
    /// c_j = b_j / D^j from the Hermite form's coefficients b_j in sigma, plus
    /// a6 h(s) = a6 (s^6 - 3 D s^5 + 3 D^2 s^4 - D^3 s^3).
    pub fn shifted_coefficients(&self) -> [f64; 7] {
        let d = self.span();
        let mut c = [0.0; 7];
        let mut dj = 1.0;
        for (cj, bj) in c.iter_mut().zip(self.p_sigma.iter()) {
            *cj = bj / dj;
            dj *= d;
        }
        c[3] -= self.a6 * d * d * d;
        c[4] += 3.0 * self.a6 * d * d;
        c[5] -= 3.0 * self.a6 * d;
        c[6] = self.a6;
        c
    }

    /// Coefficients a0..a6 of y as a polynomial in x (the paper's form).
    ///
    /// Obtained by binomial expansion of [`Self::shifted_coefficients`]:
    /// a_m = sum_{j >= m} c_j C(j, m) (-x_k)^(j - m). This is for reporting and
    /// interchange only: with |x_k| much larger than D the expansion loses digits, so all
    /// evaluation here uses the shifted/Hermite form and the factored h.
    pub fn coefficients(&self) -> [f64; 7] {
        let c = self.shifted_coefficients();
        let mut a = [0.0; 7];
        let neg = -self.x_k;
        for (j, cj) in c.iter().enumerate() {
            // Add c_j (x + neg)^j expanded: sum_m C(j, m) neg^(j-m) x^m.
            let mut binom = 1.0;
            for m in (0..=j).rev() {
                // Term x^m has coefficient C(j, m) neg^(j - m).
                let power = neg.powi((j - m) as i32);
                a[m] += cj * binom * power;
                // C(j, m-1) = C(j, m) * m / (j - m + 1)
                binom = binom * m as f64 / (j - m + 1) as f64;
            }
        }
        a
    }

    /// J = integral over the step of (y(x) - L(x))^2 dx, exact (7-point Gauss-Legendre
    /// on a degree-12 integrand). The integral runs over the step with positive measure,
    /// so J >= 0 also when x_f < x_k.
    pub fn reference_cost(&self, line: &ReferenceLine) -> f64 {
        let half = 0.5 * self.span().abs();
        let mid = 0.5 * (self.x_k + self.x_f);
        let sum: f64 = GAUSS7
            .iter()
            .map(|(node, weight)| {
                let x = mid + 0.5 * self.span() * node;
                let e = self.y(x) - line.y(x);
                weight * e * e
            })
            .sum();
        half * sum
    }
}

/// The straight reference line L through (x0, y0) (the ORIGINAL start) and (x1, y1)
/// (the goal, unless configured otherwise), as a function of x.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceLine {
    /// x of the line's start.
    pub x0: f64,
    /// y of the line's start.
    pub y0: f64,
    /// x of the line's end.
    pub x1: f64,
    /// y of the line's end.
    pub y1: f64,
}

impl ReferenceLine {
    /// A line through two points with different x.
    pub fn new(x0: f64, y0: f64, x1: f64, y1: f64) -> Result<Self, PlanError> {
        if x0 == x1 {
            return Err(PlanError::VerticalReferenceLine { x: x0 });
        }
        Ok(Self { x0, y0, x1, y1 })
    }

    /// Slope (y1 - y0) / (x1 - x0).
    pub fn slope(&self) -> f64 {
        (self.y1 - self.y0) / (self.x1 - self.x0)
    }

    /// L(x), interpolated from the nearer end.
    pub fn y(&self, x: f64) -> f64 {
        let t = (x - self.x0) / (self.x1 - self.x0);
        if t <= 0.5 {
            self.y0 + t * (self.y1 - self.y0)
        } else {
            self.y1 + (t - 1.0) * (self.y1 - self.y0)
        }
    }
}

/// A path driven with x advancing uniformly from x_k at t_k to x_f at t_f.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trajectory {
    path: PolynomialPath,
    t_k: f64,
    t_f: f64,
}

impl Trajectory {
    /// Time-parameterise a path over [t_k, t_f].
    pub fn new(path: PolynomialPath, t_k: f64, t_f: f64) -> Result<Self, PlanError> {
        if !(t_k.is_finite() && t_f.is_finite() && t_f > t_k) {
            return Err(PlanError::TimeNotIncreasing { t_k, t_f });
        }
        Ok(Self { path, t_k, t_f })
    }

    /// The geometric path.
    pub fn path(&self) -> &PolynomialPath {
        &self.path
    }

    /// Start time t_k.
    pub fn t_k(&self) -> f64 {
        self.t_k
    }

    /// Goal time t_f.
    pub fn t_f(&self) -> f64 {
        self.t_f
    }

    /// The same timing with another a6.
    pub fn with_a6(&self, a6: f64) -> Self {
        Self {
            path: self.path.with_a6(a6),
            ..*self
        }
    }

    /// w1 = dx/dt = (x_f - x_k) / (t_f - t_k).
    pub fn w1(&self) -> f64 {
        self.path.span() / (self.t_f - self.t_k)
    }

    /// x(t) = x_k + w1 (t - t_k), as an interpolation that is exact at both ends.
    /// t is clamped to [t_k, t_f].
    pub fn x_at(&self, t: f64) -> f64 {
        let sigma = ((t - self.t_k) / (self.t_f - self.t_k)).clamp(0.0, 1.0);
        if sigma >= 1.0 {
            self.path.x_f
        } else {
            self.path.x_k + sigma * self.path.span()
        }
    }

    /// (x, y, theta, phi) at time t (clamped to [t_k, t_f]).
    pub fn state_at(&self, t: f64) -> VehicleState {
        let x = self.x_at(t);
        VehicleState {
            x,
            y: self.path.y(x),
            theta: self.path.heading(x),
            phi: self.path.steering_angle(x),
        }
    }

    /// Open-loop inputs at time t (clamped to [t_k, t_f]).
    ///
    /// From x' = u1 cos(theta): u1 = w1 / cos(theta). Differentiating
    /// tan(phi) = l y'' cos^3(theta) in time with theta' = y'' w1 cos^2(theta) and
    /// substituting y'' back gives
    /// u2 = -3 sin(theta) sin^2(phi) w1 / (l cos^2(theta)) + l cos^3(theta) cos^2(phi) w2
    /// with w2 = y'''(x(t)) w1 (the printed w2 is the Taylor expansion of this about
    /// x_k).
    pub fn controls_at(&self, t: f64) -> ControlInputs {
        let x = self.x_at(t);
        let w1 = self.w1();
        let [_, d1, _, d3] = self.path.derivatives(x);
        let theta = d1.atan();
        let phi = self.path.steering_angle(x);
        let (sin_t, cos_t) = theta.sin_cos();
        let (sin_p, cos_p) = phi.sin_cos();
        let l = self.path.wheelbase;
        let w2 = d3 * w1;
        let u2 = -3.0 * sin_t * sin_p * sin_p * w1 / (l * cos_t * cos_t)
            + l * cos_t * cos_t * cos_t * cos_p * cos_p * w2;
        ControlInputs {
            u1: w1 / cos_t,
            u2,
            w1,
            w2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_path(a6: f64) -> Result<PolynomialPath, PlanError> {
        let start = VehicleState {
            x: 1.0,
            y: -2.0,
            theta: 0.4,
            phi: 0.1,
        };
        let goal = VehicleState {
            x: 21.0,
            y: 3.0,
            theta: -0.2,
            phi: -0.05,
        };
        PolynomialPath::from_states(&start, &goal, 1.6, a6)
    }

    #[test]
    fn hermite_basis_is_cardinal() {
        // Each basis function has exactly one unit datum among (value, d1, d2) at 0 and 1.
        for (i, h) in HERMITE.iter().enumerate() {
            let eval = |s: f64| {
                let v: f64 = (0..6).map(|j| h[j] * s.powi(j as i32)).sum();
                let d1: f64 = (1..6).map(|j| j as f64 * h[j] * s.powi(j as i32 - 1)).sum();
                let d2: f64 = (2..6)
                    .map(|j| (j * (j - 1)) as f64 * h[j] * s.powi(j as i32 - 2))
                    .sum();
                [v, d1, d2]
            };
            let data: Vec<f64> = eval(0.0).into_iter().chain(eval(1.0)).collect();
            for (k, value) in data.iter().enumerate() {
                let expected = if k == i { 1.0 } else { 0.0 };
                assert!((value - expected).abs() < 1e-14, "H{i} datum {k} = {value}");
            }
        }
    }

    #[test]
    fn h_derivatives_match_finite_differences() -> Result<(), PlanError> {
        let path = sample_path(1e-6)?;
        let step = 1e-4;
        for x in [1.5, 7.0, 11.0, 20.5] {
            let h = path.h_derivs(x);
            let hp = path.h_derivs(x + step);
            let hm = path.h_derivs(x - step);
            for k in 0..3 {
                let fd = (hp[k] - hm[k]) / (2.0 * step);
                let scale = h[k + 1].abs().max(1.0);
                assert!((fd - h[k + 1]).abs() < 1e-6 * scale, "h^({}) at {x}", k + 1);
            }
        }
        Ok(())
    }

    #[test]
    fn quintic_derivatives_match_finite_differences() -> Result<(), PlanError> {
        let path = sample_path(0.0)?;
        let step = 1e-4;
        for x in [1.5, 7.0, 11.0, 20.5] {
            let p = path.quintic_derivs(x);
            let pp = path.quintic_derivs(x + step);
            let pm = path.quintic_derivs(x - step);
            for k in 0..3 {
                let fd = (pp[k] - pm[k]) / (2.0 * step);
                assert!((fd - p[k + 1]).abs() < 1e-6 * p[k + 1].abs().max(1.0));
            }
        }
        Ok(())
    }

    #[test]
    fn coefficient_forms_agree_with_evaluation() -> Result<(), PlanError> {
        let path = sample_path(3e-7)?;
        let c = path.shifted_coefficients();
        let a = path.coefficients();
        for x in [1.0, 4.0, 13.0, 21.0] {
            let s = x - path.x_k();
            let by_shift: f64 = c
                .iter()
                .enumerate()
                .map(|(j, cj)| cj * s.powi(j as i32))
                .sum();
            let by_x: f64 = a
                .iter()
                .enumerate()
                .map(|(j, aj)| aj * x.powi(j as i32))
                .sum();
            let y = path.y(x);
            assert!((by_shift - y).abs() < 1e-9 * y.abs().max(1.0));
            assert!((by_x - y).abs() < 1e-8 * y.abs().max(1.0));
        }
        Ok(())
    }

    #[test]
    fn reference_line_interpolates_both_ends_exactly() -> Result<(), PlanError> {
        let line = ReferenceLine::new(0.1, 0.7, 30.3, -4.9)?;
        assert_eq!(line.y(0.1), 0.7);
        assert_eq!(line.y(30.3), -4.9);
        assert!(matches!(
            ReferenceLine::new(2.0, 0.0, 2.0, 1.0),
            Err(PlanError::VerticalReferenceLine { .. })
        ));
        Ok(())
    }
}
