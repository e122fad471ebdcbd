//! The frames guidance works in: obstacles in the world frame (perception's discs, the
//! planner's [`Obstacle`]), the planning frame whose origin is on the route and whose
//! x axis points at the local goal ([`PathFrame`]), angles wrapped into (-pi, pi], and
//! a static obstacle's radius clipped to just clear of where the car starts in that
//! frame.

use crate::planner::Obstacle;

/// A planning frame: origin on the route, x towards the local goal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathFrame {
    pub ox: f64,
    pub oy: f64,
    pub angle: f64,
    pub length: f64,
}

impl PathFrame {
    pub fn new(start: (f64, f64), goal: (f64, f64)) -> PathFrame {
        let (dx, dy) = (goal.0 - start.0, goal.1 - start.1);
        PathFrame {
            ox: start.0,
            oy: start.1,
            angle: dy.atan2(dx),
            length: dx.hypot(dy),
        }
    }

    pub fn to_path(&self, x: f64, y: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        let (dx, dy) = (x - self.ox, y - self.oy);
        (c * dx + s * dy, -s * dx + c * dy)
    }

    pub fn to_world(&self, px: f64, py: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        (self.ox + c * px - s * py, self.oy + s * px + c * py)
    }

    pub fn rotate_to_path(&self, vx: f64, vy: f64) -> (f64, f64) {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        (c * vx + s * vy, -s * vx + c * vy)
    }
}

/// How far outside an inflated obstacle the car must be for the obstacle to be
/// planned at its full size, metres.
const MARGIN_SLACK: f64 = 0.05;

/// An angle wrapped into (-pi, pi], radians.
pub(super) fn wrap(a: f64) -> f64 {
    firmware_bridge::geodesy::normalize_rad_pi(a)
}

/// The radius to plan a static obstacle with: its own, or less where the car at
/// (px, py) is already within the inflated radius r0 (plus a slack).
pub(super) fn clip_to_start(radius: f64, x: f64, y: f64, px: f64, py: f64, r0: f64) -> f64 {
    let gap = (px - x).hypot(py - y) - r0 - MARGIN_SLACK;
    radius.min(gap.max(0.0))
}

/// Whether the rear axle at (px, py) is farther than `r0` from every obstacle, each
/// with its radius clipped to just clear of `from` (where the car starts, as planned:
/// [`clip_to_start`]), so an obstacle the car already stands within the margin of may
/// come no closer.
pub(super) fn clear_at(
    px: f64,
    py: f64,
    obstacles: &[Obstacle],
    from: (f64, f64),
    r0: f64,
) -> bool {
    obstacles.iter().all(|o| {
        let radius = clip_to_start(o.radius, o.x, o.y, from.0, from.1, r0);
        (px - o.x).hypot(py - o.y) > radius + r0
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_frame_round_trips_and_points_at_the_goal() {
        let f = PathFrame::new((0.0, 0.0), (30.0, 15.0));
        let (px, py) = f.to_path(30.0, 15.0);
        assert!((px - f.length).abs() < 1e-12 && py.abs() < 1e-12);
        let (x, y) = f.to_world(3.0, -2.0);
        let (bx, by) = f.to_path(x, y);
        assert!((bx - 3.0).abs() < 1e-12 && (by + 2.0).abs() < 1e-12);
    }
}
