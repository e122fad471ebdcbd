//! Circle and line fits of a cluster's world points.

use std::ops::Range;

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// A circle fitted to points.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CircleFit {
    pub centre: [f64; 2],
    pub radius: f64,
    /// RMS of the geometric residuals |p - c| - r.
    pub rms: f64,
    /// Covariance of (cx, cy, r): s^2 (J'J)^-1 at the solution, s^2 the residual
    /// variance floored at the range noise variance.
    pub covariance: [[f64; 3]; 3],
    /// Levenberg-Marquardt iterations taken.
    pub iterations: usize,
}

/// Largest radius a circle fit returns: beyond it the points are collinear.
const MAX_RADIUS: f64 = 1e4;
const MAX_ITERATIONS: usize = 50;
/// The fit has converged once a step moves the circle less than this many metres
/// (times 1 + the radius): a tenth of a micrometre, five orders below a laser's range
/// noise. Taubin's start lies within a fraction of a millimetre; the steps after this
/// one would only polish the last digits (and end in a run of rejected trials).
const STEP_TOLERANCE: f64 = 1e-7;

/// Fits a circle: Taubin's algebraic fit (Chernov's Newton iteration on its
/// characteristic polynomial) as the start, then Levenberg-Marquardt on the geometric
/// residuals. `noise_sigma` floors the residual standard deviation in the covariance.
/// None with fewer than 3 points, collinear points or a non-finite result.
///
/// Each point's distance to the centre is taken once per trial (a `sqrt` of the squared
/// sum, not `hypot`: the coordinates are metres, far from overflow): the cost of a trial
/// and, once it is accepted, the normal equations of the next step (and the covariance
/// at the end) come from the same distances.
pub fn fit_circle(points: &[[f64; 2]], noise_sigma: f64) -> Option<CircleFit> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let (mut a, mut b, mut r) = taubin(points)?;
    let mut dist = vec![0.0; n];
    let mut trial = vec![0.0; n];
    let mut current = cost(points, a, b, r, &mut dist);
    let (mut jtj, mut jtr) = normal_equations(points, a, b, r, &dist);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for _ in 0..MAX_ITERATIONS {
        iterations += 1;
        let mut accepted = false;
        let mut step_norm = 0.0;
        while lambda < 1e12 {
            let mut m = jtj;
            for i in 0..3 {
                m[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(delta) = m.lu().solve(&(-jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let (na, nb, nr) = (a + delta[0], b + delta[1], r + delta[2]);
            let c = cost(points, na, nb, nr, &mut trial);
            if c.is_finite() && c <= current {
                a = na;
                b = nb;
                r = nr;
                current = c;
                std::mem::swap(&mut dist, &mut trial);
                (jtj, jtr) = normal_equations(points, a, b, r, &dist);
                lambda = (lambda * 0.1).max(1e-12);
                accepted = true;
                step_norm = delta.norm();
                break;
            }
            lambda *= 10.0;
        }
        if !accepted || step_norm <= STEP_TOLERANCE * (1.0 + r.abs()) {
            break;
        }
    }
    if !(a.is_finite() && b.is_finite() && r.is_finite()) || r <= 0.0 || r > MAX_RADIUS {
        return None;
    }
    let rms = (current / n as f64).sqrt();
    let dof = n.saturating_sub(3).max(1) as f64;
    let s2 = (current / dof).max(noise_sigma * noise_sigma);
    let inv = jtj.try_inverse()?;
    let mut covariance = [[0.0; 3]; 3];
    for (i, row) in covariance.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = s2 * inv[(i, j)];
        }
    }
    Some(CircleFit {
        centre: [a, b],
        radius: r,
        rms,
        covariance,
        iterations,
    })
}

/// Sum of the squared geometric residuals |p_i - c| - r, the distances |p_i - c| left
/// in `dist`.
fn cost(points: &[[f64; 2]], a: f64, b: f64, r: f64, dist: &mut [f64]) -> f64 {
    let mut sum = 0.0;
    for (p, d) in points.iter().zip(dist.iter_mut()) {
        let (dx, dy) = (p[0] - a, p[1] - b);
        *d = (dx * dx + dy * dy).sqrt();
        let e = *d - r;
        sum += e * e;
    }
    sum
}

/// J'J and J'e of the geometric residuals e_i = |p_i - c| - r over (a, b, r), with
/// the distances |p_i - c| of [`cost`] at the same (a, b, r).
///
/// Each point's row j = (-dx/d, -dy/d, -1) adds j_k j_l to entry (k, l) of J'J and
/// j_k e to J'e, in the order of the points, and so the sums here are those bit for
/// bit: J'J is symmetric (j_k j_l and j_l j_k are the same product); a sum of -1 times
/// each term is `0 - ` the sum of the terms (rounding is symmetric, and neither ever
/// gives -0); and a sum of n ones is n.
fn normal_equations(
    points: &[[f64; 2]],
    a: f64,
    b: f64,
    r: f64,
    dist: &[f64],
) -> (Matrix3<f64>, Vector3<f64>) {
    let [mut xx, mut xy, mut yy, mut x, mut y] = [0.0; 5];
    let [mut ex, mut ey, mut e] = [0.0; 3];
    for (p, &d) in points.iter().zip(dist) {
        let dx = p[0] - a;
        let dy = p[1] - b;
        let (jx, jy) = if d > 0.0 {
            (-dx / d, -dy / d)
        } else {
            (0.0, 0.0)
        };
        xx += jx * jx;
        xy += jx * jy;
        yy += jy * jy;
        x += jx;
        y += jy;
        let residual = d - r;
        ex += jx * residual;
        ey += jy * residual;
        e += residual;
    }
    let (xr, yr, rr) = (0.0 - x, 0.0 - y, points.len().min(dist.len()) as f64);
    let jtj = Matrix3::new(xx, xy, xr, xy, yy, yr, xr, yr, rr);
    (jtj, Vector3::new(ex, ey, 0.0 - e))
}

/// Taubin's fit (Chernov, "Circular and linear regression", 2010): centre and radius.
fn taubin(points: &[[f64; 2]]) -> Option<(f64, f64, f64)> {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let (mut mxx, mut myy, mut mxy, mut mxz, mut myz, mut mzz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let xi = p[0] - mx;
        let yi = p[1] - my;
        let zi = xi * xi + yi * yi;
        mxy += xi * yi;
        mxx += xi * xi;
        myy += yi * yi;
        mxz += xi * zi;
        myz += yi * zi;
        mzz += zi * zi;
    }
    mxx /= n;
    myy /= n;
    mxy /= n;
    mxz /= n;
    myz /= n;
    mzz /= n;
    let mz = mxx + myy;
    let cov_xy = mxx * myy - mxy * mxy;
    let var_z = mzz - mz * mz;
    let a3 = 4.0 * mz;
    let a2 = -3.0 * mz * mz - mzz;
    let a1 = var_z * mz + 4.0 * cov_xy * mz - mxz * mxz - myz * myz;
    let a0 = mxz * (mxz * myy - myz * mxy) + myz * (myz * mxx - mxz * mxy) - var_z * cov_xy;
    let a22 = a2 + a2;
    let a33 = a3 + a3 + a3;
    let mut x = 0.0f64;
    let mut y = a0;
    for _ in 0..99 {
        let dy = a1 + x * (a22 + a33 * x);
        let x_new = x - y / dy;
        if x_new == x || !x_new.is_finite() {
            break;
        }
        let y_new = a0 + x_new * (a1 + x_new * (a2 + x_new * a3));
        if y_new.abs() >= y.abs() {
            break;
        }
        x = x_new;
        y = y_new;
    }
    let det = x * x - x * mz + cov_xy;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let xc = (mxz * (myy - x) - myz * mxy) / det / 2.0;
    let yc = (myz * (mxx - x) - mxz * mxy) / det / 2.0;
    let r = (xc * xc + yc * yc + mz).sqrt();
    (xc.is_finite() && yc.is_finite() && r.is_finite() && r <= MAX_RADIUS).then_some((
        xc + mx,
        yc + my,
        r,
    ))
}

/// A line fitted to points by total least squares.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LineFit {
    pub centroid: [f64; 2],
    /// Unit direction, from the first point's end towards the last point's end.
    pub direction: [f64; 2],
    /// Unit normal (direction turned by +90 degrees).
    pub normal: [f64; 2],
    /// RMS of the perpendicular residuals.
    pub rms: f64,
    /// Smallest and largest signed perpendicular residual.
    pub residual_min: f64,
    pub residual_max: f64,
    /// The extreme points projected on the line (p0 at the first point's end).
    pub p0: [f64; 2],
    pub p1: [f64; 2],
}

impl LineFit {
    pub fn length(&self) -> f64 {
        (self.p1[0] - self.p0[0]).hypot(self.p1[1] - self.p0[1])
    }
}

/// Total least squares: the line through the centroid along the principal axis. None
/// with fewer than 2 points or all points equal.
pub fn fit_line(points: &[[f64; 2]]) -> Option<LineFit> {
    let (first, last) = (points.first()?, points.last()?);
    let n = points.len();
    if n < 2 {
        return None;
    }
    let nf = n as f64;
    let cx = points.iter().map(|p| p[0]).sum::<f64>() / nf;
    let cy = points.iter().map(|p| p[1]).sum::<f64>() / nf;
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in points {
        let dx = p[0] - cx;
        let dy = p[1] - cy;
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    if sxx + syy <= 0.0 {
        return None;
    }
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let mut d = [theta.cos(), theta.sin()];
    let along = |p: &[f64; 2], d: &[f64; 2]| (p[0] - cx) * d[0] + (p[1] - cy) * d[1];
    if along(first, &d) > along(last, &d) {
        d = [-d[0], -d[1]];
    }
    let nrm = [-d[1], d[0]];
    let (mut tmin, mut tmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut rmin, mut rmax, mut ss) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for p in points {
        let t = along(p, &d);
        let e = (p[0] - cx) * nrm[0] + (p[1] - cy) * nrm[1];
        tmin = tmin.min(t);
        tmax = tmax.max(t);
        rmin = rmin.min(e);
        rmax = rmax.max(e);
        ss += e * e;
    }
    Some(LineFit {
        centroid: [cx, cy],
        direction: d,
        normal: nrm,
        rms: (ss / nf).sqrt(),
        residual_min: rmin,
        residual_max: rmax,
        p0: [cx + tmin * d[0], cy + tmin * d[1]],
        p1: [cx + tmax * d[0], cy + tmax * d[1]],
    })
}

/// Split-and-merge of an ordered point sequence into straight pieces: iterative
/// end-point fit (split at the point farthest from the chord while it is farther than
/// `split_distance`), then adjacent pieces merged while the total-least-squares line
/// of their union keeps every point within `split_distance`. Neighbouring pieces share
/// their corner point. Index ranges into `points`, in order.
pub fn split_and_merge(points: &[[f64; 2]], split_distance: f64) -> Vec<Range<usize>> {
    let whole = 0..points.len();
    if points.len() < 2 {
        return if points.is_empty() {
            Vec::new()
        } else {
            std::iter::once(whole).collect()
        };
    }
    let mut pieces = Vec::new();
    let mut stack = Vec::from([whole]);
    while let Some(range) = stack.pop() {
        match farthest_from_chord(&points[range.clone()]) {
            Some((k, d)) if d > split_distance && k > 0 && k + 1 < range.len() => {
                let corner = range.start + k;
                // Right half first on the stack so the left is processed first.
                stack.push(corner..range.end);
                stack.push(range.start..corner + 1);
            }
            _ => pieces.push(range),
        }
    }
    // Merge adjacent collinear pieces, the first pair that fits each time. The pairs
    // before a merge did not fit and are unchanged but for the one ending in the merged
    // piece: the next look starts there, not at the first pair.
    let mut merged = true;
    let mut from = 0;
    while merged && pieces.len() > 1 {
        merged = false;
        for i in from..pieces.len() - 1 {
            let union = pieces[i].start..pieces[i + 1].end;
            let fits = fit_line(&points[union.clone()])
                .is_some_and(|l| l.residual_min.abs().max(l.residual_max.abs()) <= split_distance);
            if fits {
                pieces[i] = union;
                pieces.remove(i + 1);
                merged = true;
                from = i.saturating_sub(1);
                break;
            }
        }
    }
    pieces
}

/// Index and distance of the point farthest from the chord first-last.
fn farthest_from_chord(points: &[[f64; 2]]) -> Option<(usize, f64)> {
    let (a, b) = (points.first()?, points.last()?);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let d = if len > 0.0 {
                ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len
            } else {
                (p[0] - a[0]).hypot(p[1] - a[1])
            };
            (i, d)
        })
        .max_by(|x, y| x.1.total_cmp(&y.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_circle_is_recovered() {
        let pts: Vec<[f64; 2]> = (0..20)
            .map(|i| {
                let t = 0.3 + 0.05 * i as f64;
                [19.0 + 3.0 * t.cos(), 8.0 + 3.0 * t.sin()]
            })
            .collect();
        let c = fit_circle(&pts, 0.01).expect("fit");
        assert!((c.centre[0] - 19.0).abs() < 1e-9);
        assert!((c.centre[1] - 8.0).abs() < 1e-9);
        assert!((c.radius - 3.0).abs() < 1e-9);
        assert!(c.rms < 1e-9);
    }

    #[test]
    fn the_normal_equations_are_the_sums_of_each_rows_outer_product_bit_for_bit() {
        // Noisy points round a circle, and one at the centre (a zero distance).
        let pts: Vec<[f64; 2]> = (0..60)
            .map(|i| {
                let (t, f) = (0.1 * f64::from(i), f64::from(i));
                let r = 2.0 + 0.01 * (1.3 * f).sin();
                [3.0 + r * t.cos(), -1.0 + r * t.sin()]
            })
            .chain([[3.0, -1.0]])
            .collect();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (a, b, r) in [(3.0, -1.0, 2.0), (3.1, -0.9, 1.9), (-5.0, 4.0, 30.0)] {
            let mut dist = vec![0.0; pts.len()];
            cost(&pts, a, b, r, &mut dist);
            let (mut jtj, mut jtr) = (Matrix3::zeros(), Vector3::zeros());
            for (p, &d) in pts.iter().zip(&dist) {
                let j = if d > 0.0 {
                    Vector3::new(-(p[0] - a) / d, -(p[1] - b) / d, -1.0)
                } else {
                    Vector3::new(0.0, 0.0, -1.0)
                };
                jtj += j * j.transpose();
                jtr += j * (d - r);
            }
            let (m, v) = normal_equations(&pts, a, b, r, &dist);
            assert_eq!(bits(m.as_slice()), bits(jtj.as_slice()), "({a}, {b}, {r})");
            assert_eq!(bits(v.as_slice()), bits(jtr.as_slice()), "({a}, {b}, {r})");
        }
    }

    #[test]
    fn merging_from_the_last_merge_gives_the_pieces_merging_from_the_first_does() {
        // A zig-zag of short noisy pieces (many merges) and a square's corners.
        let pts: Vec<[f64; 2]> = (0..200)
            .map(|i| {
                let f = f64::from(i);
                let bend = if (i / 25) % 2 == 0 {
                    0.0
                } else {
                    0.04 * (f % 25.0)
                };
                [0.05 * f, bend + 0.004 * (2.1 * f).sin()]
            })
            .collect();
        for split in [0.005, 0.01, 0.02, 0.05, 0.2] {
            let pieces = split_and_merge(&pts, split);
            // Every adjacent pair left does not fit, and the pieces cover the points.
            for w in pieces.windows(2) {
                let union = &pts[w[0].start..w[1].end];
                let fits = fit_line(union)
                    .is_some_and(|l| l.residual_min.abs().max(l.residual_max.abs()) <= split);
                assert!(!fits, "{split}: {w:?}");
                assert_eq!(w[0].end, w[1].start + 1);
            }
            assert_eq!(pieces.first().map(|p| p.start), Some(0));
            assert_eq!(pieces.last().map(|p| p.end), Some(pts.len()));
        }
    }

    #[test]
    fn collinear_points_have_no_circle() {
        let pts: Vec<[f64; 2]> = (0..10).map(|i| [i as f64, 2.0 * i as f64]).collect();
        assert!(fit_circle(&pts, 0.01).is_none_or(|c| c.radius > 1e3));
    }

    #[test]
    fn line_fit_orients_first_to_last() {
        let pts: Vec<[f64; 2]> = (0..10).map(|i| [5.0 - i as f64, 1.0]).collect();
        let l = fit_line(&pts).expect("fit");
        assert!((l.p0[0] - 5.0).abs() < 1e-12 && (l.p1[0] + 4.0).abs() < 1e-12);
        assert!((l.direction[0] + 1.0).abs() < 1e-12);
        assert!(l.rms < 1e-12);
    }

    #[test]
    fn l_shape_splits_into_two_pieces_sharing_the_corner() {
        let mut pts: Vec<[f64; 2]> = (0..10).map(|i| [i as f64 * 0.2, 0.0]).collect();
        pts.extend((1..10).map(|i| [1.8, i as f64 * 0.2]));
        let pieces = split_and_merge(&pts, 0.05);
        assert_eq!(pieces, vec![0..10, 9..19]);
    }
}
