//! Recovery from a dead end: standing still with no forward path, the car backs a
//! short way along an arc checked against the obstacles it knows of ([`Reverse`]),
//! then replans.

use super::frame::{clear_at, wrap};
use super::lanes;
use crate::planner::Obstacle;

/// Points checked per metre of a reverse path.
const CHECKS_PER_M: f64 = 5.0;
/// A gentle reverse arc turns on this fraction of the planned steering limit.
const GENTLE: f64 = 0.5;

/// One reversal: the rear axle backs `distance` along the arc of road-wheel angle
/// `steer` from where it started. The laser looks forward, so the path is checked
/// against the obstacles perception reports (what it sees and remembers), and kept
/// short and slow.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reverse {
    /// The rear axle's pose at the start, world frame.
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Road-wheel angle, radians (positive left, as when driving forwards).
    pub steer: f64,
    /// Arc length of the rear axle's path, metres.
    pub distance: f64,
    /// Distance between the axles, metres.
    pub wheelbase: f64,
    /// The distance is covered (or the rest is blocked): braking to a stand.
    pub done: bool,
}

impl Reverse {
    /// The first clear reversal from the rear axle's pose (`x`, `y`, `theta`): straight
    /// back, else a gentle arc (half the planned steering limit `steer_limit`) that
    /// turns the nose towards the world angle `towards`, else the other; None when
    /// none is clear of every obstacle grown by `r0` ([`Reverse::clear`]).
    pub fn choose(
        (x, y, theta): (f64, f64, f64),
        towards: f64,
        distance: f64,
        wheelbase: f64,
        steer_limit: f64,
        obstacles: &[Obstacle],
        r0: f64,
    ) -> Option<Reverse> {
        // Backing on a left lock turns the nose right (clockwise).
        let turn = if wrap(towards - theta) > 0.0 {
            -GENTLE
        } else {
            GENTLE
        };
        [0.0, turn, -turn]
            .into_iter()
            .map(|f| Reverse {
                x,
                y,
                theta,
                steer: f * steer_limit,
                distance,
                wheelbase,
                done: false,
            })
            .find(|r| r.clear(obstacles, r0))
    }

    /// Curvature of the rear axle's path, 1/m.
    fn curvature(&self) -> f64 {
        self.steer.tan() / self.wheelbase
    }

    /// The rear axle's pose after backing `s` metres from the start (bicycle model).
    pub fn pose_at(&self, s: f64) -> (f64, f64, f64) {
        let k = self.curvature();
        let theta = self.theta - k * s;
        if k.abs() < 1e-9 {
            return (
                self.x - s * self.theta.cos(),
                self.y - s * self.theta.sin(),
                theta,
            );
        }
        (
            self.x + (theta.sin() - self.theta.sin()) / k,
            self.y - (theta.cos() - self.theta.cos()) / k,
            theta,
        )
    }

    /// Whether the path is clear: at every checked point the rear axle is farther than
    /// `r0` from each obstacle, planned (as forward paths are) with its radius clipped
    /// to just clear of where the car starts, so an obstacle the car already stands
    /// within the margin of (the one ahead it backs away from) may not come closer.
    /// Moving obstacles count where they are now.
    pub fn clear(&self, obstacles: &[Obstacle], r0: f64) -> bool {
        let n = (self.distance * CHECKS_PER_M).ceil().max(1.0) as usize;
        (1..=n).all(|j| {
            let (px, py, _) = self.pose_at(self.distance * j as f64 / n as f64);
            clear_at(px, py, obstacles, (self.x, self.y), r0)
        })
    }

    /// Whether the way back, driven at `speed` (m/s), is clear of traffic: no moving
    /// obstacle is within `r0` of the rear axle's path, or comes there while the car
    /// backs or soon after ([`lanes::clear_to_reverse`]).
    pub fn clear_of_traffic(&self, obstacles: &[Obstacle], r0: f64, speed: f64) -> bool {
        let n = (self.distance * CHECKS_PER_M).ceil().max(1.0) as usize;
        let points: Vec<(f64, f64)> = (0..=n)
            .map(|j| {
                let (x, y, _) = self.pose_at(self.distance * j as f64 / n as f64);
                (x, y)
            })
            .collect();
        lanes::clear_to_reverse(&points, self.distance / speed.max(0.1), obstacles, r0)
    }

    /// The straight distance from the start to the end of the arc, metres.
    fn chord(&self) -> f64 {
        let k = self.curvature();
        if k.abs() < 1e-9 {
            self.distance
        } else {
            2.0 * (k * self.distance / 2.0).sin().abs() / k.abs()
        }
    }

    /// The rest of the reversal from the rear axle's position (`x`, `y`) heading
    /// `theta`: the same arc for what is left of the distance (judged by the chord).
    /// Covered when it is nothing.
    pub fn rest(&self, x: f64, y: f64, theta: f64) -> Reverse {
        let gone = (x - self.x).hypot(y - self.y);
        let left = if gone >= self.chord() {
            0.0
        } else {
            // Along a gentle arc the chord is within a few percent of the arc.
            (self.distance - gone).max(0.0)
        };
        Reverse {
            x,
            y,
            theta,
            distance: left,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn post(x: f64, y: f64) -> Obstacle {
        Obstacle {
            x,
            y,
            radius: 0.5,
            vx: 0.0,
            vy: 0.0,
        }
    }

    #[test]
    fn a_reverse_arc_backs_and_turns_the_nose_the_right_way() {
        let r = Reverse {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            steer: 0.3,
            distance: 4.0,
            wheelbase: 1.65,
            done: false,
        };
        let (x, y, theta) = r.pose_at(4.0);
        // Backing on a left lock: behind, to the left, nose turned right.
        assert!(x < -3.5 && y > 0.0 && theta < 0.0, "{x} {y} {theta}");
        assert!(((x * x + y * y).sqrt() - r.chord()).abs() < 1e-9);
        let straight = Reverse { steer: 0.0, ..r };
        assert_eq!(straight.pose_at(4.0), (-4.0, 0.0, 0.0));
        // Half way along, half is left; at the end nothing is.
        let (hx, hy, ht) = straight.pose_at(2.0);
        assert!((straight.rest(hx, hy, ht).distance - 2.0).abs() < 1e-9);
        assert_eq!(straight.rest(-4.0, 0.0, 0.0).distance, 0.0);
    }

    #[test]
    fn an_obstacle_behind_blocks_straight_back_and_one_ahead_does_not() {
        let r0 = 2.3;
        let limit = 0.5;
        // The car stands 0.5 m inside the margin of a post ahead: backing away is clear.
        let ahead = post(2.3, 0.0);
        let r = Reverse::choose((0.0, 0.0, 0.0), 0.0, 4.0, 1.65, limit, &[ahead], r0)
            .expect("clear backwards");
        assert_eq!(r.steer, 0.0);
        // A post behind on the left blocks straight back: the arc that turns the nose
        // left (towards the way to face) backs to the right, clear of it.
        let left_behind = post(-4.5, 2.0);
        let r = Reverse::choose(
            (0.0, 0.0, 0.0),
            1.0,
            4.0,
            1.65,
            limit,
            &[ahead, left_behind],
            r0,
        )
        .expect("an arc");
        assert!((r.steer + GENTLE * limit).abs() < 1e-12, "{r:?}");
        // The same post on the right: that arc is blocked, the other is taken.
        let right_behind = post(-4.5, -2.0);
        let r = Reverse::choose(
            (0.0, 0.0, 0.0),
            1.0,
            4.0,
            1.65,
            limit,
            &[ahead, right_behind],
            r0,
        )
        .expect("an arc");
        assert!((r.steer - GENTLE * limit).abs() < 1e-12, "{r:?}");
        // Posts behind and on both sides behind: no way back.
        let wall: Vec<Obstacle> = (-8..=8)
            .map(|i| post(-4.5, f64::from(i) * 0.5))
            .chain([ahead])
            .collect();
        assert_eq!(
            Reverse::choose((0.0, 0.0, 0.0), 0.0, 4.0, 1.65, limit, &wall, r0),
            None
        );
    }
}
