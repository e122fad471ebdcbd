//! Traffic rules the planning discs do not state: the lane of traffic meeting or
//! overtaking the car is not driven into while the car is ahead of it ([`Lanes`]);
//! traffic overtaking the car (beside or behind it, going its way faster) is no reason
//! to brake or swerve ([`overtaking`]); and a reversal needs the space behind clear of
//! traffic ([`clear_to_reverse`]).

use super::footprint::Footprint;
use crate::planner::{Obstacle, Trajectory, VehicleState};

/// Slower than this, an obstacle is no traffic, m/s.
const MIN_SPEED: f64 = 0.2;
/// Traffic goes more along its line than across: its speed across the car's heading
/// at most this fraction of its speed along it.
const ALONG: f64 = 0.3;
/// A path may go this much deeper into a lane than the car already is (noise), metres.
const LANE_SLACK: f64 = 0.05;
/// Step along x between the poses a path is checked at, metres.
const LANE_STEP: f64 = 0.2;

/// The car's heading frame at `state`: `o`'s position (along, left of the car) and
/// velocity (along, left).
fn in_car_frame(o: &Obstacle, state: &VehicleState) -> ((f64, f64), (f64, f64)) {
    let (c, s) = (state.theta.cos(), state.theta.sin());
    let (dx, dy) = (o.x - state.x, o.y - state.y);
    (
        (c * dx + s * dy, -s * dx + c * dy),
        (c * o.vx + s * o.vy, -s * o.vx + c * o.vy),
    )
}

/// Whether the moving obstacle `o` comes towards the car at `state` (planning frame):
/// against its heading faster than [`MIN_SPEED`], more along than across, and ahead of
/// its rear axle.
pub fn oncoming(o: &Obstacle, state: &VehicleState) -> bool {
    let ((along, _), (va, vl)) = in_car_frame(o, state);
    va < -MIN_SPEED && vl.abs() <= -va && along > 0.0
}

/// Whether the moving obstacle `o` overtakes the car at `state` driving at `speed`
/// (planning frame) or otherwise moves away from its path: going the car's way faster
/// by [`MIN_SPEED`], keeping to its line (not closing in on the car sideways faster
/// than [`ALONG`] of its speed), and either beside or behind the car (its centre no
/// farther ahead of the rear axle than `reach`: the nose plus the planning circle) or
/// off the car's line (farther aside than its radius and `half_width`, the car's
/// half width with its margin). At constant velocities it never comes nearer the car
/// along its way: the car holds its line and speed and keeps out of its lane
/// ([`Lanes`]); braking or swerving for it is what would bring the two together. One
/// ahead on the car's line is a leader to keep a headway to.
pub fn overtaking(
    o: &Obstacle,
    state: &VehicleState,
    speed: f64,
    reach: f64,
    half_width: f64,
) -> bool {
    let ((along, left), (va, vl)) = in_car_frame(o, state);
    let closing = -vl * left.signum();
    va > speed.max(0.0) + MIN_SPEED
        && closing <= ALONG * va
        && (along <= reach || left.abs() >= o.radius + half_width)
}

/// One lane not to be driven into: a moving obstacle's line (along its velocity,
/// its radius either side), the side of it the car is on, and how deep the car's
/// rectangle already reaches into it, metres.
#[derive(Clone, Copy, Debug)]
struct Lane {
    o: Obstacle,
    side: f64,
    depth: f64,
}

/// The lanes of the traffic meeting or overtaking the car (planning frame): while
/// the car is ahead of such an obstacle along its velocity (it has not passed the
/// car), the car's rectangle, grown by the footprint's margin, may reach no deeper into
/// its lane than it already does, nor cross to its far side. So the car keeps to its
/// own side of oncoming traffic, never swerves into the swept lane of a cart that
/// comes towards it, and holds its line beside one overtaking it. An obstacle whose
/// line runs through the car's rear axle (head-on on the car's line) has no side to
/// keep to and is left to the discs.
#[derive(Clone, Debug)]
pub struct Lanes {
    lanes: Vec<Lane>,
    footprint: Footprint,
}

impl Lanes {
    /// The lanes of `tracks` (moving obstacles, planning frame) seen from the car at
    /// `state` with its rectangle `footprint`.
    pub fn new(tracks: &[Obstacle], state: &VehicleState, footprint: &Footprint) -> Lanes {
        let mut lanes = Lanes {
            lanes: Vec::new(),
            footprint: *footprint,
        };
        let pose = (state.x, state.y, state.theta);
        lanes.lanes = tracks
            .iter()
            .filter_map(|o| {
                let centre = lanes.lateral(o, state.x, state.y);
                let (ahead, lo, hi) = lanes.extent(o, pose, 0.0);
                (ahead && centre.abs() >= o.radius).then(|| {
                    let side = centre.signum();
                    Lane {
                        o: *o,
                        side,
                        depth: depth(side, lo, hi, o.radius),
                    }
                })
            })
            .collect();
        lanes
    }

    /// The signed distance of (x, y) from `o`'s line, left of its velocity positive.
    fn lateral(&self, o: &Obstacle, x: f64, y: f64) -> f64 {
        let speed = o.vx.hypot(o.vy).max(1e-9);
        (o.vx * (y - o.y) - o.vy * (x - o.x)) / speed
    }

    /// The car's rectangle at `pose` against `o` at `at` seconds: whether some corner
    /// is still ahead of the obstacle's back along its velocity, and the least and
    /// greatest lateral offset of the corners from its line.
    fn extent(&self, o: &Obstacle, (x, y, heading): (f64, f64, f64), at: f64) -> (bool, f64, f64) {
        let f = &self.footprint;
        let (c, s) = (heading.cos(), heading.sin());
        let speed = o.vx.hypot(o.vy).max(1e-9);
        let (ox, oy) = (o.x + o.vx * at, o.y + o.vy * at);
        let (mut ahead, mut lo, mut hi) = (false, f64::INFINITY, f64::NEG_INFINITY);
        for (u, v) in [
            (f.front + f.margin, f.half_width + f.margin),
            (f.front + f.margin, -f.half_width - f.margin),
            (-f.rear - f.margin, f.half_width + f.margin),
            (-f.rear - f.margin, -f.half_width - f.margin),
        ] {
            let (px, py) = (x + c * u - s * v, y + s * u + c * v);
            let along = (o.vx * (px - ox) + o.vy * (py - oy)) / speed;
            ahead |= along > -o.radius;
            let n = self.lateral(o, px, py);
            lo = lo.min(n);
            hi = hi.max(n);
        }
        (ahead, lo, hi)
    }

    /// Whether the car, driving the trajectory's path at its pace from the instant the
    /// obstacles' positions are of, keeps out of every lane (every [`LANE_STEP`] of
    /// x); each obstacle is taken `margin_s` late, so it is passed only once it has
    /// surely gone by.
    pub fn keeps_out(&self, t: &Trajectory, margin_s: f64) -> bool {
        if self.lanes.is_empty() {
            return true;
        }
        let p = t.path();
        let pace = t.w1();
        if pace <= 0.0 {
            return false;
        }
        let n = (p.span().abs() / LANE_STEP).ceil().max(1.0) as usize;
        (0..=n).all(|j| {
            let x = p.x_k() + p.span() * j as f64 / n as f64;
            let at = ((x - p.x_k()) / pace - margin_s).max(0.0);
            let pose = (x, p.y(x), p.heading(x));
            self.lanes.iter().all(|l| {
                let (ahead, lo, hi) = self.extent(&l.o, pose, at);
                !ahead || depth(l.side, lo, hi, l.o.radius) <= l.depth + LANE_SLACK
            })
        })
    }
}

/// How deep the lateral extent [`lo`, `hi`] on `side` of a lane of half width `r`
/// reaches into it (past its far edge: deeper than its width), metres.
fn depth(side: f64, lo: f64, hi: f64, r: f64) -> f64 {
    if side < 0.0 {
        (hi + r).max(0.0)
    } else {
        (r - lo).max(0.0)
    }
}

/// How long a reversal watches the traffic beyond its own duration, seconds.
const REVERSE_WATCH_S: f64 = 5.0;
/// Samples along a moving obstacle's track when a reversal is checked.
const REVERSE_TRACK_SAMPLES: u32 = 100;

/// Whether the way back along `points` (the rear axle's, world frame), taking
/// `duration_s` to drive, is clear of traffic: no moving obstacle is, or comes within
/// [`REVERSE_WATCH_S`] after it at its constant velocity, within `r0` of any of them.
/// A car does not back into the space behind it while traffic is there or on its way.
pub fn clear_to_reverse(
    points: &[(f64, f64)],
    duration_s: f64,
    obstacles: &[Obstacle],
    r0: f64,
) -> bool {
    let watch = duration_s.max(0.0) + REVERSE_WATCH_S;
    obstacles
        .iter()
        .filter(|o| o.vx != 0.0 || o.vy != 0.0)
        .all(|o| {
            (0..=REVERSE_TRACK_SAMPLES).all(|k| {
                let t = watch * f64::from(k) / f64::from(REVERSE_TRACK_SAMPLES);
                let (ox, oy) = (o.x + o.vx * t, o.y + o.vy * t);
                points
                    .iter()
                    .all(|&(px, py)| (px - ox).hypot(py - oy) > o.radius + r0)
            })
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAR: Footprint = Footprint {
        front: 2.025,
        rear: 0.375,
        half_width: 0.6,
        margin: 0.25,
    };

    fn state(x: f64, y: f64) -> VehicleState {
        VehicleState {
            x,
            y,
            theta: 0.0,
            phi: 0.0,
        }
    }

    fn track(x: f64, y: f64, vx: f64, vy: f64) -> Obstacle {
        Obstacle {
            x,
            y,
            radius: 0.45,
            vx,
            vy,
        }
    }

    #[test]
    fn traffic_is_told_oncoming_or_overtaking_by_its_velocity_and_place() {
        let car = state(0.0, 0.0);
        assert!(oncoming(&track(15.0, 1.45, -1.5, 0.0), &car));
        // Crossing, behind the car, or too slow: not oncoming.
        assert!(!oncoming(&track(15.0, 1.45, -0.3, 1.0), &car));
        assert!(!oncoming(&track(-5.0, 1.45, -1.5, 0.0), &car));
        assert!(!oncoming(&track(15.0, 1.45, -0.1, 0.0), &car));
        // A cart at 3.5 m/s beside the car at 2 m/s, behind it, or ahead of it off its
        // line: overtaking, moving away.
        let reach = CAR.front + 2.3;
        let half = CAR.half_width + CAR.margin;
        let away = |o: Obstacle| overtaking(&o, &car, 2.0, reach, half);
        assert!(away(track(1.0, 1.7, 3.5, 0.0)));
        assert!(away(track(-6.0, 0.0, 3.5, 0.0)));
        assert!(away(track(10.0, 1.7, 3.5, 0.0)));
        // Not faster than the car, ahead on its line, or closing in on its side: no.
        assert!(!away(track(1.0, 1.7, 2.1, 0.0)));
        assert!(!away(track(10.0, 0.5, 3.5, 0.0)));
        assert!(!away(track(1.0, 1.7, 3.5, -1.5)));
        assert!(!away(track(1.0, -1.7, 3.5, 1.5)));
        // Moving away sideways is fine.
        assert!(away(track(1.0, -1.7, 3.5, -1.0)));
    }

    #[test]
    fn the_lane_ahead_of_oncoming_traffic_is_not_driven_into() {
        let car = state(0.0, 0.0);
        let cart = track(20.0, 1.45, -1.5, 0.0);
        let lanes = Lanes::new(&[cart], &car, &CAR);
        assert_eq!(lanes.lanes.len(), 1);
        let l = lanes.lanes[0];
        // The car is on the cart's left (its velocity points at the car); the grown
        // rectangle reaches 0.85 left of the axle, short of the lane's edge at 1.0.
        assert_eq!(l.side, 1.0);
        assert_eq!(l.depth, 0.0);
        let pose = |y: f64| (5.0, y, 0.0);
        let depth_at = |y: f64| {
            let (ahead, lo, hi) = lanes.extent(&cart, pose(y), 0.0);
            assert!(ahead);
            depth(l.side, lo, hi, cart.radius)
        };
        assert!(depth_at(-0.5) <= l.depth);
        assert!(depth_at(0.5) > l.depth + LANE_SLACK);
        // Across it, to its far side: deeper than its width.
        assert!(depth_at(3.0) > 2.0 * cart.radius);
        // Once the cart has gone by, its lane is free.
        let (ahead, _, _) = lanes.extent(&cart, pose(1.45), 20.0);
        assert!(!ahead);
        // A walker head-on on the car's line has no side: left to the discs.
        assert!(
            Lanes::new(&[track(20.0, 0.2, -1.0, 0.0)], &car, &CAR)
                .lanes
                .is_empty()
        );
        // Nor does anything behind the car.
        assert!(
            Lanes::new(&[track(-8.0, 1.45, -1.5, 0.0)], &car, &CAR)
                .lanes
                .is_empty()
        );
    }

    #[test]
    fn a_reversal_waits_for_traffic_behind_or_on_its_way() {
        let back: Vec<(f64, f64)> = (0..=8).map(|i| (-0.5 * f64::from(i), 0.0)).collect();
        let post = Obstacle {
            x: 6.0,
            y: 0.0,
            radius: 0.5,
            vx: 0.0,
            vy: 0.0,
        };
        let cart = |x: f64, y: f64, vx: f64| Obstacle {
            x,
            y,
            radius: 0.5,
            vx,
            vy: 0.0,
        };
        // Static obstacles are Reverse::clear's business.
        assert!(clear_to_reverse(&back, 8.0, &[post], 2.3));
        // A cart beside, one on its way from ahead, one behind: not clear.
        assert!(!clear_to_reverse(&back, 8.0, &[cart(1.0, 2.3, 3.5)], 2.3));
        assert!(!clear_to_reverse(
            &back,
            8.0,
            &[cart(20.0, 1.45, -1.5)],
            2.3
        ));
        assert!(!clear_to_reverse(
            &back,
            8.0,
            &[cart(-5.0, 1.45, -0.5)],
            2.3
        ));
        // Far ahead and going away, or far off to the side: clear.
        assert!(clear_to_reverse(&back, 8.0, &[cart(12.0, 0.0, 3.5)], 2.3));
        assert!(clear_to_reverse(&back, 8.0, &[cart(0.0, 20.0, 1.0)], 2.3));
    }
}
