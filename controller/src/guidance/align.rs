//! Headings the polynomial cannot start from: turning towards the goal on the planned
//! steering limit first, when a whole turning circle is clear ([`Align`]).

use crate::planner::Obstacle;

/// A car's nearest thing to turning on the spot: full planned lock at low speed, until
/// the heading is within reach of a y(x) path. Taken only when the whole turning
/// circle (grown by the planner's vehicle radius) is clear of every obstacle.
#[derive(Clone, Debug, PartialEq)]
pub struct Align {
    /// The rear axle's pose, world frame.
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Turning left is the short way round.
    pub prefer_left: bool,
    /// Turning radius of the rear axle at the planned steering limit, metres.
    pub turn_radius: f64,
    /// Obstacles in the world frame.
    pub obstacles: Vec<Obstacle>,
}

impl Align {
    /// Whether the full turning circle to the left (or right) is clear: every obstacle
    /// is farther than its radius plus `r0` from the circle the rear axle drives.
    pub fn clear(&self, left: bool, r0: f64) -> bool {
        let s = if left { 1.0 } else { -1.0 };
        let r = self.turn_radius;
        let (cx, cy) = (
            self.x - s * r * self.theta.sin(),
            self.y + s * r * self.theta.cos(),
        );
        self.obstacles
            .iter()
            .all(|o| ((o.x - cx).hypot(o.y - cy) - r).abs() > o.radius + r0)
    }

    /// The road-wheel angle to turn with (the short way if clear, else the long way),
    /// or None when neither turning circle is clear.
    pub fn steer(&self, r0: f64, steer_limit: f64) -> Option<f64> {
        [self.prefer_left, !self.prefer_left]
            .into_iter()
            .find(|left| self.clear(*left, r0))
            .map(|left| if left { steer_limit } else { -steer_limit })
    }
}
