//! Moving circular obstacles and the a6 values they forbid.
//!
//! # Collision window (ERRATA 6)
//!
//! The vehicle's x is x(t) = x_k + w1 tau, the obstacle's x_i + v_x tau (tau = t - t_k).
//! A collision needs |x(t) - x_obs(t)| < R, R = r_i + r_0. With the relative speed
//! v = w1 - v_x != 0 that is tau strictly between (x_i - x_k - R) / v and
//! (x_i - x_k + R) / v: the printed order only when v > 0, so the ends are sorted, then
//! clipped to [0, t_f - t_k]. With v == 0 the gap never changes: the window is the
//! whole step if |x_k - x_i| < R, else empty.
//!
//! # Forbidden a6 at one instant (ERRATA 4)
//!
//! With y = p + a6 h at x = x(t), c = y_obs(t) - p and dx = x(t) - x_obs(t),
//! G(a6) = (p + a6 h - y_obs)^2 + dx^2 - R^2 = g2 a6^2 + g1 a6 + g0 with g2 = h^2,
//! g1 = 2 h (p - y_obs), g0 = (p - y_obs)^2 + dx^2 - R^2. Its discriminant is
//! g1^2 - 4 g2 g0 = 4 h^2 (R^2 - dx^2), so for h != 0 and |dx| < R the roots are
//! (c -+ w) / h with w = sqrt(R^2 - dx^2) (computed as sqrt((R - dx)(R + dx))), and
//! G < 0 exactly between them. This form avoids the quadratic formula's cancellation.
//!
//! # Union over the window (ERRATA 5)
//!
//! a6 collides iff it collides at SOME instant, so the forbidden set is the union of the
//! per-instant open intervals. The intervals move continuously with t inside the window
//! (h != 0 there), so the union is the single interval
//! (min_t lower root, max_t upper root).
//!
//! At t_k and t_f, h = 0 and G = g0 does not depend on a6: g0 < 0 means the start or the
//! goal itself collides and every a6 is forbidden. Otherwise, when the window reaches
//! that end, the roots diverge as t approaches it: h -> 0 from below (h < 0 inside the
//! step) and c -> c_end != 0, so both roots tend to -sign(c_end) infinity and the
//! forbidden set is a half-line (-inf, .) when the obstacle is above the path's end
//! (c_end > 0) and (., +inf) when below. The finite end is still the sampled extremum.

use serde::{Deserialize, Serialize};

use super::interval::Interval;
use super::path::Trajectory;
use super::sampling::{Sampling, maximise, maximise_pair};

/// A circular obstacle: centre at t_k, radius, constant velocity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// Centre x at t_k (m).
    pub x: f64,
    /// Centre y at t_k (m).
    pub y: f64,
    /// Radius r_i (m), >= 0.
    pub radius: f64,
    /// Velocity x component (m/s); 0 when omitted.
    #[serde(default)]
    pub vx: f64,
    /// Velocity y component (m/s); 0 when omitted.
    #[serde(default)]
    pub vy: f64,
}

impl Obstacle {
    /// Centre at tau = t - t_k.
    pub fn centre_at(&self, tau: f64) -> (f64, f64) {
        (self.x + self.vx * tau, self.y + self.vy * tau)
    }
}

/// What one obstacle does to the choice of a6.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObstacleConstraint {
    /// The collision time window [t_a, t_b] within [t_k, t_f], or None when the x-bands
    /// never overlap during the step.
    pub window: Option<[f64; 2]>,
    /// The open interval of a6 values that collide, or None when the obstacle never
    /// constrains a6. `[-inf, inf]` when the start or the goal collides (or the obstacle
    /// traps the vehicle).
    pub forbidden: Option<Interval>,
    /// The vehicle at (x_k, y_k) already overlaps the obstacle at t_k.
    pub start_collides: bool,
    /// The vehicle at (x_f, y_f) overlaps the obstacle at t_f.
    pub goal_collides: bool,
}

/// The collision window of an obstacle as absolute times, or None.
pub fn collision_window(traj: &Trajectory, obstacle: &Obstacle, r0: f64) -> Option<[f64; 2]> {
    let r = obstacle.radius + r0;
    let duration = traj.t_f() - traj.t_k();
    let gap = obstacle.x - traj.path().x_k();
    let v = traj.w1() - obstacle.vx;
    let (lo, hi) = if v == 0.0 {
        if gap.abs() < r {
            (0.0, duration)
        } else {
            return None;
        }
    } else {
        let a = (gap - r) / v;
        let b = (gap + r) / v;
        (a.min(b).max(0.0), a.max(b).min(duration))
    };
    if lo < hi {
        // Exact ends where the window is clipped, so h = 0 is seen there exactly.
        let ta = if lo == 0.0 {
            traj.t_k()
        } else {
            traj.t_k() + lo
        };
        let tb = if hi == duration {
            traj.t_f()
        } else {
            traj.t_k() + hi
        };
        Some([ta, tb])
    } else {
        None
    }
}

/// Per-instant quantities: c = y_obs - p, w^2 = R^2 - dx^2 (as a product), h.
struct Instant {
    c: f64,
    w2: f64,
    h: f64,
}

fn instant(traj: &Trajectory, obstacle: &Obstacle, r: f64, t: f64) -> Instant {
    let x = traj.x_at(t);
    let (ox, oy) = obstacle.centre_at(t - traj.t_k());
    let dx = x - ox;
    Instant {
        c: oy - traj.path().quintic(x),
        w2: (r - dx) * (r + dx),
        h: traj.path().h(x),
    }
}

/// The colliding open a6 interval at time t, if any (h != 0 and |dx| < R).
fn roots_at(traj: &Trajectory, obstacle: &Obstacle, r: f64, t: f64) -> Option<(f64, f64)> {
    let i = instant(traj, obstacle, r, t);
    if i.h == 0.0 || i.w2.is_nan() || i.w2 <= 0.0 {
        return None;
    }
    let w = i.w2.sqrt();
    let a = (i.c - w) / i.h;
    let b = (i.c + w) / i.h;
    Some((a.min(b), a.max(b)))
}

/// Whether the vehicle overlaps the obstacle at time t (distance < R).
fn overlaps_at(traj: &Trajectory, obstacle: &Obstacle, r: f64, t: f64) -> bool {
    // The position only (x and y of `traj.state_at(t)`, without its heading and
    // steering angle).
    let x = traj.x_at(t);
    let y = traj.path().y(x);
    let (ox, oy) = obstacle.centre_at(t - traj.t_k());
    (x - ox).hypot(y - oy) < r
}

/// Whether the vehicle overlaps the obstacle at the start or at the goal of the step
/// (then [`obstacle_constraint`] forbids every a6).
pub fn ends_collide(traj: &Trajectory, obstacle: &Obstacle, vehicle_radius: f64) -> bool {
    let r = obstacle.radius + vehicle_radius;
    overlaps_at(traj, obstacle, r, traj.t_k()) || overlaps_at(traj, obstacle, r, traj.t_f())
}

/// The a6 values an obstacle forbids during the step (the union over its collision
/// window, see the module docs). `traj`'s own a6 is irrelevant.
pub fn obstacle_constraint(
    traj: &Trajectory,
    obstacle: &Obstacle,
    vehicle_radius: f64,
    sampling: &Sampling,
) -> ObstacleConstraint {
    let r = obstacle.radius + vehicle_radius;
    let start_collides = overlaps_at(traj, obstacle, r, traj.t_k());
    let goal_collides = overlaps_at(traj, obstacle, r, traj.t_f());
    let window = collision_window(traj, obstacle, vehicle_radius);
    let mut result = ObstacleConstraint {
        window,
        forbidden: None,
        start_collides,
        goal_collides,
    };
    if start_collides || goal_collides {
        result.forbidden = Some(Interval::ALL);
        return result;
    }
    let Some([ta, tb]) = window else {
        return result;
    };
    // Half-lines from a window that reaches an end of the step (h -> 0 there).
    let mut lower_infinite = false;
    let mut upper_infinite = false;
    for (reaches, t_end) in [(ta == traj.t_k(), ta), (tb == traj.t_f(), tb)] {
        if reaches {
            let c = instant(traj, obstacle, r, t_end).c;
            if c >= 0.0 {
                lower_infinite = true;
            }
            if c <= 0.0 {
                upper_infinite = true;
            }
        }
    }
    let neg_lower = |t: f64| roots_at(traj, obstacle, r, t).map_or(f64::NEG_INFINITY, |(a, _)| -a);
    let upper_root = |t: f64| roots_at(traj, obstacle, r, t).map_or(f64::NEG_INFINITY, |(_, b)| b);
    let (lower, upper) = match (lower_infinite, upper_infinite) {
        (true, true) => (f64::NEG_INFINITY, f64::INFINITY),
        (true, false) => (f64::NEG_INFINITY, maximise(&upper_root, ta, tb, sampling).1),
        (false, true) => (-maximise(&neg_lower, ta, tb, sampling).1, f64::INFINITY),
        (false, false) => {
            // Both ends from one set of samples: the roots at each sampled time once.
            let both = |t: f64| {
                roots_at(traj, obstacle, r, t)
                    .map_or((f64::NEG_INFINITY, f64::NEG_INFINITY), |(a, b)| (-a, b))
            };
            let (lo, hi) = maximise_pair(&both, &neg_lower, &upper_root, ta, tb, sampling);
            (-lo.1, hi.1)
        }
    };
    if lower < upper {
        result.forbidden = Some(Interval {
            lo: lower,
            hi: upper,
        });
    }
    result
}

/// The smallest clearance (distance between centres minus r_i + r_0) along a
/// trajectory over [t_k, t_f], by sampling with refinement.
pub fn min_clearance(
    traj: &Trajectory,
    obstacle: &Obstacle,
    vehicle_radius: f64,
    sampling: &Sampling,
) -> f64 {
    let r = obstacle.radius + vehicle_radius;
    let neg_clearance = |t: f64| {
        let state = traj.state_at(t);
        let (ox, oy) = obstacle.centre_at(t - traj.t_k());
        r - (state.x - ox).hypot(state.y - oy)
    };
    -maximise(&neg_clearance, traj.t_k(), traj.t_f(), sampling).1
}

#[cfg(test)]
mod tests {
    use super::super::PlanError;
    use super::super::path::{PolynomialPath, VehicleState};
    use super::*;

    fn straight(t_f: f64) -> Result<Trajectory, PlanError> {
        let s = VehicleState {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            phi: 0.0,
        };
        let g = VehicleState { x: 10.0, ..s };
        Trajectory::new(PolynomialPath::from_states(&s, &g, 1.5, 0.0)?, 0.0, t_f)
    }

    fn obstacle(x: f64, y: f64, vx: f64) -> Obstacle {
        Obstacle {
            x,
            y,
            radius: 1.0,
            vx,
            vy: 0.0,
        }
    }

    #[test]
    fn window_for_faster_vehicle_follows_the_printed_formula() -> Result<(), PlanError> {
        // w1 = 1 m/s, static obstacle at x = 5, R = 1.5: band [3.5, 6.5] -> t in [3.5, 6.5].
        let w = collision_window(&straight(10.0)?, &obstacle(5.0, 3.0, 0.0), 0.5);
        assert_eq!(w, Some([3.5, 6.5]));
        Ok(())
    }

    #[test]
    fn window_for_faster_obstacle_is_swapped_and_clipped() -> Result<(), PlanError> {
        // Obstacle behind the vehicle moving at 3 m/s, vehicle at 1 m/s: v = -2.
        // gap = -5: ends (-5 -+ 1.5) / -2 = 3.25 and 1.75 -> [1.75, 3.25].
        let w = collision_window(&straight(10.0)?, &obstacle(-5.0, 3.0, 3.0), 0.5);
        assert_eq!(w, Some([1.75, 3.25]));
        // Ahead and faster: never caught.
        assert_eq!(
            collision_window(&straight(10.0)?, &obstacle(5.0, 3.0, 3.0), 0.5),
            None
        );
        Ok(())
    }

    #[test]
    fn window_with_equal_speeds_is_all_or_nothing() -> Result<(), PlanError> {
        let traj = straight(10.0)?;
        assert_eq!(
            collision_window(&traj, &obstacle(1.0, 3.0, 1.0), 0.5),
            Some([0.0, 10.0])
        );
        assert_eq!(collision_window(&traj, &obstacle(2.0, 3.0, 1.0), 0.5), None);
        Ok(())
    }

    #[test]
    fn band_covering_the_start_gives_a_half_line_towards_the_obstacle_side() -> Result<(), PlanError>
    {
        let traj = straight(10.0)?;
        // Obstacle above the start: huge negative a6 (h < 0) lifts the path into it.
        let above = obstacle_constraint(&traj, &obstacle(0.5, 4.0, 0.0), 0.5, &Sampling::default());
        let f = above
            .forbidden
            .ok_or(PlanError::Overflow { what: "none" })?;
        assert_eq!(f.lo, f64::NEG_INFINITY);
        assert!(f.hi.is_finite() && f.hi < 0.0);
        let below =
            obstacle_constraint(&traj, &obstacle(0.5, -4.0, 0.0), 0.5, &Sampling::default());
        let f = below
            .forbidden
            .ok_or(PlanError::Overflow { what: "none" })?;
        assert_eq!(f.hi, f64::INFINITY);
        assert!(f.lo.is_finite() && f.lo > 0.0);
        Ok(())
    }

    #[test]
    fn obstacle_on_the_goal_forbids_everything() -> Result<(), PlanError> {
        let traj = straight(10.0)?;
        let c = obstacle_constraint(&traj, &obstacle(10.5, 0.2, 0.0), 0.5, &Sampling::default());
        assert!(c.goal_collides && !c.start_collides);
        assert_eq!(c.forbidden, Some(Interval::ALL));
        Ok(())
    }
}
