//! The car's real footprint: the oriented rectangle around the rear axle (the pose's
//! origin), grown by a margin, checked against obstacle circles at a pose and along a
//! planned path. The planning circle (`vehicle.radius` + `safety_margin`) contains the
//! rectangle, so a path planned with it needs no check; passages narrower than that
//! circle are planned with the half width plus the margin as the circle and every
//! candidate path is then checked with the rectangle ([`super::solve`]).

use crate::planner::{Obstacle, Trajectory};

/// How far outside the grown footprint the car must be for an obstacle to be checked
/// at its full size, metres (as [`super::frame`]'s slack for the circle).
const START_SLACK: f64 = 0.05;
/// Step along x between the poses a path is checked at, metres.
const PATH_STEP: f64 = 0.1;
/// Step along a moving obstacle's track between the places it is checked at, metres.
const TRACK_STEP: f64 = 0.05;

/// The rectangle the car occupies, in the vehicle frame (x forward from the rear axle).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Rear axle to the front bumper, metres.
    pub front: f64,
    /// Rear axle to the rear bumper, metres.
    pub rear: f64,
    pub half_width: f64,
    /// Clearance required between the rectangle and every obstacle, metres.
    pub margin: f64,
}

impl Footprint {
    /// The rectangle of the car `v` (its length, width and rear overhang), grown by
    /// `margin`.
    pub fn of(v: &crate::config::Vehicle, margin: f64) -> Footprint {
        Footprint {
            front: v.length - v.rear_overhang,
            rear: v.rear_overhang,
            half_width: v.width / 2.0,
            margin,
        }
    }

    /// The distance from the rectangle of the car at (x, y, heading) to the point
    /// (px, py); 0 inside.
    pub fn distance(&self, x: f64, y: f64, heading: f64, px: f64, py: f64) -> f64 {
        let (c, s) = (heading.cos(), heading.sin());
        let (du, dv) = self.outside(c, s, px - x, py - y);
        du.hypot(dv)
    }

    /// How far the point (`dx`, `dy`) from the rear axle lies outside the rectangle,
    /// along the car and across it, the car heading (cos `c`, sin `s`).
    pub fn outside(&self, c: f64, s: f64, dx: f64, dy: f64) -> (f64, f64) {
        let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
        let du = (u - u.clamp(-self.rear, self.front)).abs();
        let dv = (v - v.clamp(-self.half_width, self.half_width)).abs();
        (du, dv)
    }

    /// Whether the car at (x, y, heading) clears every static obstacle (moving ones
    /// are planned in space-time elsewhere) by the margin.
    pub fn clear_at(&self, x: f64, y: f64, heading: f64, obstacles: &[Obstacle]) -> bool {
        obstacles
            .iter()
            .filter(|o| o.vx == 0.0 && o.vy == 0.0)
            .all(|o| self.distance(x, y, heading, o.x, o.y) > o.radius + self.margin)
    }

    /// Whether the car at (x, y, heading) clears the moving obstacle `o` by the margin
    /// wherever its constant-velocity track takes it from `from` to `to` seconds after
    /// the instant its position is of.
    pub fn clear_of_track(&self, pose: (f64, f64, f64), o: &Obstacle, from: f64, to: f64) -> bool {
        self.track_distance(pose, o, from, to) > o.radius + self.margin
    }

    /// The least distance from the car's rectangle at (x, y, heading) to the centre of
    /// the moving obstacle `o` along its constant-velocity track from `from` to `to`
    /// seconds after the instant its position is of (every [`TRACK_STEP`] along it).
    fn track_distance(
        &self,
        (x, y, heading): (f64, f64, f64),
        o: &Obstacle,
        from: f64,
        to: f64,
    ) -> f64 {
        let travel = o.vx.hypot(o.vy) * (to - from);
        let n = (travel / TRACK_STEP).ceil().clamp(1.0, 4096.0) as usize;
        (0..=n)
            .map(|j| {
                let s = from + (to - from) * j as f64 / n as f64;
                self.distance(x, y, heading, o.x + o.vx * s, o.y + o.vy * s)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The moving obstacles as [`Self::path_clear_of_moving`] sees them from the car
    /// at `pose`, each swept over +- `margin_s`: one whose swept track comes within the
    /// margin of the car where it stands is shrunk to just clear of it there, so a path
    /// that never brings the car nearer its track is not refused (as
    /// [`Self::clip_to_start`] does for static obstacles).
    pub fn clip_tracks_to_start(
        &self,
        pose: (f64, f64, f64),
        moving: &[Obstacle],
        margin_s: f64,
    ) -> Vec<Obstacle> {
        moving
            .iter()
            .map(|o| {
                let gap =
                    self.track_distance(pose, o, -margin_s, margin_s) - self.margin - START_SLACK;
                Obstacle {
                    radius: o.radius.min(gap.max(0.0)),
                    ..*o
                }
            })
            .collect()
    }

    /// Whether the car, driving the trajectory's path at its pace (dx/dt) from the
    /// instant the obstacles' positions are of, clears every moving obstacle by the
    /// margin at every pose (every `PATH_STEP` of x), each swept over +- `margin_s`
    /// along its velocity around the instant the car is there.
    pub fn path_clear_of_moving(&self, t: &Trajectory, moving: &[Obstacle], margin_s: f64) -> bool {
        let p = t.path();
        let pace = t.w1();
        if pace <= 0.0 {
            return false;
        }
        let n = (p.span().abs() / PATH_STEP).ceil().max(1.0) as usize;
        p.stations(n).all(|x| {
            let at = (x - p.x_k()) / pace;
            let pose = (x, p.y(x), p.heading(x));
            moving
                .iter()
                .all(|o| self.clear_of_track(pose, o, at - margin_s, at + margin_s))
        })
    }

    /// The static obstacles as the path check sees them from the car at (x, y,
    /// heading): one the car already stands within the margin of is clipped to just
    /// clear of it, so a path leading away from it is not refused (as the planning
    /// circle's [`super::frame::clip_to_start`]).
    pub fn clip_to_start(
        &self,
        x: f64,
        y: f64,
        heading: f64,
        obstacles: &[Obstacle],
    ) -> Vec<Obstacle> {
        obstacles
            .iter()
            .filter(|o| o.vx == 0.0 && o.vy == 0.0)
            .map(|o| {
                let gap = self.distance(x, y, heading, o.x, o.y) - self.margin - START_SLACK;
                Obstacle {
                    radius: o.radius.min(gap.max(0.0)),
                    ..*o
                }
            })
            .collect()
    }

    /// Whether the car clears `obstacles` (planning frame, already clipped) by the
    /// margin at every pose of the trajectory's path, every `PATH_STEP` of x.
    pub fn path_clear(&self, t: &Trajectory, obstacles: &[Obstacle]) -> bool {
        let p = t.path();
        let n = (p.span().abs() / PATH_STEP).ceil().max(1.0) as usize;
        let poses: Vec<[f64; 3]> = p.stations(n).map(|x| [x, p.y(x), p.heading(x)]).collect();
        // Only obstacles within reach of the rear axle's track can touch the car.
        let reach = self.front.max(self.rear).hypot(self.half_width) + self.margin;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in &poses {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let near: Vec<Obstacle> = obstacles
            .iter()
            .filter(|o| {
                let r = reach + o.radius;
                o.x > lo[0] - r && o.x < hi[0] + r && o.y > lo[1] - r && o.y < hi[1] + r
            })
            .copied()
            .collect();
        poses.iter().all(|q| self.clear_at(q[0], q[1], q[2], &near))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAR: Footprint = Footprint {
        front: 2.0,
        rear: 0.4,
        half_width: 0.6,
        margin: 0.2,
    };

    fn post(x: f64, y: f64, radius: f64) -> Obstacle {
        Obstacle {
            x,
            y,
            radius,
            vx: 0.0,
            vy: 0.0,
        }
    }

    #[test]
    fn distance_is_to_the_oriented_rectangle() {
        // Beside the middle, ahead of the bumper, off a corner, inside.
        assert!((CAR.distance(0.0, 0.0, 0.0, 1.0, 1.6) - 1.0).abs() < 1e-12);
        assert!((CAR.distance(0.0, 0.0, 0.0, 3.0, 0.0) - 1.0).abs() < 1e-12);
        assert!((CAR.distance(0.0, 0.0, 0.0, -0.4 - 3.0, 0.6 + 4.0) - 5.0).abs() < 1e-12);
        assert_eq!(CAR.distance(0.0, 0.0, 0.0, 1.0, 0.3), 0.0);
        // Turned by 90 degrees the car's front points along +y.
        let h = std::f64::consts::FRAC_PI_2;
        assert!((CAR.distance(5.0, 5.0, h, 5.0, 8.0) - 1.0).abs() < 1e-12);
        assert!((CAR.distance(5.0, 5.0, h, 6.6, 6.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_post_within_the_margin_is_not_clear_and_moving_obstacles_are_not_checked() {
        assert!(CAR.clear_at(0.0, 0.0, 0.0, &[post(1.0, 1.15, 0.3)]));
        assert!(!CAR.clear_at(0.0, 0.0, 0.0, &[post(1.0, 1.05, 0.3)]));
        let moving = Obstacle {
            vx: 1.0,
            ..post(1.0, 0.0, 0.3)
        };
        assert!(CAR.clear_at(0.0, 0.0, 0.0, &[moving]));
        // Clipped to where the car stands, the post no longer blocks it.
        let clipped = CAR.clip_to_start(0.0, 0.0, 0.0, &[post(1.0, 1.05, 0.3)]);
        assert!(CAR.clear_at(0.0, 0.0, 0.0, &clipped));
        assert!(clipped[0].radius < 0.3);
    }
}
