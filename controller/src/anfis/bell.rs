//! The generalised bell membership function and its log-domain derivatives.

use serde::{Deserialize, Serialize};

/// A generalised bell membership function (Jang 1993, eq. 18):
///
/// ```text
/// mu(u) = 1 / (1 + |(u - c) / a|^(2 b)),   a > 0, b > 0
/// ```
///
/// c is the centre, a the half width (mu(c +- a) = 0.5) and b the slope
/// (dmu/du = -b / (2 a) at u = c + a). Parameters are in normalised input units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BellMf {
    /// Half width a (> 0).
    pub a: f64,
    /// Slope exponent b (> 0).
    pub b: f64,
    /// Centre c.
    pub c: f64,
}

/// The partial derivatives of an error measure with respect to one bell MF's
/// parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BellGradient {
    /// dE/da.
    pub a: f64,
    /// dE/db.
    pub b: f64,
    /// dE/dc.
    pub c: f64,
}

/// One evaluation of a bell MF, in the log domain.
///
/// With z = (u - c) / a and s = 2 b ln|z|: `ln mu = -softplus(s)` and
/// `1 - mu = sigmoid(s)`, both accurate where mu or 1 - mu is tiny and never NaN for
/// finite u.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BellEval {
    /// z = (u - c) / a.
    pub z: f64,
    /// ln mu.
    pub log_mu: f64,
    /// 1 - mu.
    pub one_minus_mu: f64,
}

impl BellMf {
    /// The membership grade mu(u) for a normalised input u.
    pub fn grade(&self, u: f64) -> f64 {
        self.eval(u).log_mu.exp()
    }

    pub(crate) fn eval(&self, u: f64) -> BellEval {
        let z = (u - self.c) / self.a;
        let s = 2.0 * self.b * z.abs().ln();
        // softplus(s) = ln(1 + e^s), stable for both signs (s = -inf at z = 0 gives 0).
        let softplus = s.max(0.0) + (-s.abs()).exp().ln_1p();
        let one_minus_mu = if s >= 0.0 {
            1.0 / (1.0 + (-s).exp())
        } else {
            let e = s.exp();
            e / (1.0 + e)
        };
        BellEval {
            z,
            log_mu: -softplus,
            one_minus_mu,
        }
    }

    /// (d ln mu / da, d ln mu / db, d ln mu / dc) at an evaluation of this MF.
    ///
    /// With q = |z|^(2b), mu = 1 / (1 + q) and mu q = 1 - mu:
    ///
    /// ```text
    /// d ln mu / da =  2 b (1 - mu) / a
    /// d ln mu / dc =  2 b (1 - mu) / (z a)     (0 at z = 0, the limit for b > 1/2)
    /// d ln mu / db = -2 (1 - mu) ln|z|         (0 at z = 0, the limit)
    /// ```
    pub(crate) fn log_derivatives(&self, e: &BellEval) -> (f64, f64, f64) {
        let d_a = 2.0 * self.b * e.one_minus_mu / self.a;
        if e.z == 0.0 {
            return (d_a, 0.0, 0.0);
        }
        let d_c = 2.0 * self.b * e.one_minus_mu / (e.z * self.a);
        let d_b = -2.0 * e.one_minus_mu * e.z.abs().ln();
        (d_a, d_b, d_c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn direct(mf: &BellMf, u: f64) -> f64 {
        1.0 / (1.0 + ((u - mf.c) / mf.a).abs().powf(2.0 * mf.b))
    }

    #[test]
    fn grade_matches_the_direct_formula_and_half_width() {
        let mf = BellMf {
            a: 0.4,
            b: 1.7,
            c: -0.2,
        };
        for k in 0..=40 {
            let u = -2.0 + 0.1 * f64::from(k);
            let d = direct(&mf, u);
            assert!((mf.grade(u) - d).abs() < 1e-14, "u = {u}");
            assert!((1.0 - d - mf.eval(u).one_minus_mu).abs() < 1e-14, "u = {u}");
        }
        assert!((mf.grade(-0.2 + 0.4) - 0.5).abs() < 1e-15);
        assert!((mf.grade(-0.2 - 0.4) - 0.5).abs() < 1e-15);
        assert_eq!(mf.grade(-0.2), 1.0);
    }

    #[test]
    fn far_inputs_stay_finite_in_the_log_domain() {
        let mf = BellMf {
            a: 1e-3,
            b: 50.0,
            c: 0.0,
        };
        let e = mf.eval(1e6);
        assert!(e.log_mu.is_finite() && e.log_mu < -700.0);
        assert_eq!(mf.grade(1e6), 0.0);
        let (da, db, dc) = mf.log_derivatives(&e);
        assert!(da.is_finite() && db.is_finite() && dc.is_finite());
    }

    #[test]
    fn log_derivatives_match_central_differences() {
        let mf = BellMf {
            a: 0.35,
            b: 2.3,
            c: 0.1,
        };
        let h = 1e-6;
        for &u in &[-1.3, -0.6, -0.2, 0.05, 0.1 + 1e-3, 0.3, 0.45, 1.2] {
            let (da, db, dc) = mf.log_derivatives(&mf.eval(u));
            let l = |m: BellMf| m.eval(u).log_mu;
            let fd_a =
                (l(BellMf { a: mf.a + h, ..mf }) - l(BellMf { a: mf.a - h, ..mf })) / (2.0 * h);
            let fd_b =
                (l(BellMf { b: mf.b + h, ..mf }) - l(BellMf { b: mf.b - h, ..mf })) / (2.0 * h);
            let fd_c =
                (l(BellMf { c: mf.c + h, ..mf }) - l(BellMf { c: mf.c - h, ..mf })) / (2.0 * h);
            for (name, an, fd) in [("a", da, fd_a), ("b", db, fd_b), ("c", dc, fd_c)] {
                let tol = 1e-6 * (1.0 + an.abs());
                assert!(
                    (an - fd).abs() < tol,
                    "u = {u}, d/d{name}: analytic {an}, fd {fd}"
                );
            }
        }
    }

    #[test]
    fn derivatives_at_the_centre_are_the_limits() {
        let mf = BellMf {
            a: 0.5,
            b: 2.0,
            c: 0.25,
        };
        let (da, db, dc) = mf.log_derivatives(&mf.eval(0.25));
        assert_eq!((da, db, dc), (0.0, 0.0, 0.0));
    }
}
