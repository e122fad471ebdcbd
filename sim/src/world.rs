//! The golf car's world in rapier2d: obstacles as colliders (posts, boxes, walls),
//! moving ones on kinematic bodies, and the queries the simulator needs: does the
//! footprint touch anything, how far is each obstacle, where does a laser ray hit.
//!
//! The vehicle itself is not a collider (a laser must not see its own car); its
//! footprint is tested against the world at its pose. rapier works in f32; the
//! vehicle's state is integrated in f64 and converted at this boundary (f32 resolves
//! better than 10 micrometres at a few hundred metres from the origin).

use rapier2d::parry;
use rapier2d::prelude::*;

use crate::scenario::schema::{Motion, Obstacle, VehicleConfig};
use crate::vehicle::VehicleState;

mod clearance;
pub mod ray;

pub use clearance::Clearances;
use ray::{Bins, Fan, Form, Hit, Prim, ScannerPose};

/// One obstacle of the scenario in the physics world.
#[derive(Debug)]
struct Body {
    spec: Obstacle,
    handle: RigidBodyHandle,
    colliders: Vec<ColliderHandle>,
    /// Its shapes in [`World::prims`].
    prims: std::ops::Range<usize>,
}

/// The physics world of one run.
pub struct World {
    physics: PhysicsWorld,
    bodies: Vec<Body>,
    /// Which of `bodies` move: the ones [`World::set_time`] visits (a world of a
    /// thousand posts and two carts moves two).
    movers: Vec<usize>,
    /// The same shapes in f64 for the laser ([`ray`]), in the order of `bodies`.
    prims: Vec<Prim>,
    /// The laser's broad phase over `prims`.
    bins: Bins,
    time: f64,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("obstacles", &self.bodies.len())
            .field("time", &self.time)
            .finish()
    }
}

fn vec2(x: f64, y: f64) -> Vector {
    Vector::new(x as Real, y as Real)
}

/// A moving obstacle rides a kinematic body, a static one a fixed body.
fn body_for(motion: &Option<Motion>) -> RigidBodyBuilder {
    if motion.is_some() {
        RigidBodyBuilder::kinematic_position_based()
    } else {
        RigidBodyBuilder::fixed()
    }
}

/// Position of a moving obstacle's reference point at time `t`, from its start `(x0, y0)`.
pub fn position_at(x0: f64, y0: f64, motion: &Option<Motion>, t: f64) -> (f64, f64) {
    match motion {
        None => (x0, y0),
        Some(Motion::Velocity { vx, vy }) => (x0 + vx * t, y0 + vy * t),
        Some(Motion::Waypoints {
            points,
            speed,
            cyclic,
        }) => {
            let mut legs: Vec<([f64; 2], [f64; 2])> =
                points.windows(2).map(|w| (w[0], w[1])).collect();
            if *cyclic && let (Some(last), Some(first)) = (points.last(), points.first()) {
                legs.push((*last, *first));
            }
            let lengths: Vec<f64> = legs
                .iter()
                .map(|(a, b)| ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt())
                .collect();
            let total: f64 = lengths.iter().sum();
            let mut s = speed * t.max(0.0);
            if total <= 0.0 {
                return points.first().map_or((x0, y0), |p| (p[0], p[1]));
            }
            if *cyclic {
                s = s.rem_euclid(total);
            } else if s >= total {
                return points.last().map_or((x0, y0), |p| (p[0], p[1]));
            }
            for ((a, b), len) in legs.iter().zip(&lengths) {
                if s <= *len && *len > 0.0 {
                    let f = s / len;
                    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]));
                }
                s -= len;
            }
            points.last().map_or((x0, y0), |p| (p[0], p[1]))
        }
    }
}

impl World {
    /// Build the world of a scenario's obstacles at t = 0.
    pub fn new(obstacles: &[Obstacle]) -> World {
        let mut physics = PhysicsWorld::new();
        physics.gravity = Vector::ZERO;
        let mut bodies = Vec::with_capacity(obstacles.len());
        let mut prims = Vec::with_capacity(obstacles.len());
        for (i, o) in obstacles.iter().enumerate() {
            let first = prims.len();
            prims.extend(prims_of(i, o));
            let shapes = &prims[first..];
            // A post or a box rides its body (moving or fixed); a wall's segments and
            // joints sit on one fixed body at the origin.
            let (body, placed) = match o {
                Obstacle::Wall { .. } => (RigidBodyBuilder::fixed(), true),
                Obstacle::Circle { motion, .. } | Obstacle::Box { motion, .. } => {
                    let pose = shapes.first().map_or(Pose::IDENTITY, pose_of);
                    (body_for(motion).pose(pose), false)
                }
            };
            let handle = physics.insert_body(body);
            let colliders = shapes
                .iter()
                .map(|p| {
                    let c = collider_of(p).user_data(i as u128);
                    let c = if placed { c.position(pose_of(p)) } else { c };
                    physics
                        .colliders
                        .insert_with_parent(c, handle, &mut physics.bodies)
                })
                .collect();
            bodies.push(Body {
                spec: o.clone(),
                handle,
                colliders,
                prims: first..prims.len(),
            });
        }
        let movers = (bodies.iter().enumerate())
            .filter(|(_, b)| b.spec.moves())
            .map(|(i, _)| i)
            .collect();
        let bins = Bins::new(&prims, |k| bodies[prims[k].obstacle].spec.moves());
        let mut world = World {
            physics,
            bodies,
            movers,
            prims,
            bins,
            time: 0.0,
        };
        world.refresh();
        world
    }

    /// Let the broad phase see the current positions.
    fn refresh(&mut self) {
        self.physics.step();
    }

    /// Move every moving obstacle to where it is at time `t`.
    pub fn set_time(&mut self, t: f64) {
        self.time = t;
        let mut moved = false;
        for b in self.movers.iter().map(|&i| &self.bodies[i]) {
            let (x0, y0, heading, motion) = match &b.spec {
                Obstacle::Circle { x, y, motion, .. } => (*x, *y, 0.0, motion),
                Obstacle::Box {
                    x,
                    y,
                    heading_deg,
                    motion,
                    ..
                } => (*x, *y, heading_deg.to_radians(), motion),
                // Walls never move: not among the movers.
                Obstacle::Wall { .. } => continue,
            };
            let (x, y) = position_at(x0, y0, motion, t);
            for p in self.prims.get_mut(b.prims.clone()).into_iter().flatten() {
                (p.x, p.y) = (x, y);
            }
            if let Some(body) = self.physics.bodies.get_mut(b.handle) {
                body.set_position(Pose::new(vec2(x, y), heading as Real), true);
                moved = true;
            }
        }
        if moved {
            self.refresh();
        }
    }

    fn hits(&self, pose: Pose, shape: &dyn Shape) -> Vec<usize> {
        let mut hits: Vec<usize> = self
            .physics
            .intersect_shape(pose, shape, QueryFilter::default())
            .map(|(_, c)| c.user_data as usize)
            .collect();
        hits.sort_unstable();
        hits.dedup();
        hits
    }

    fn footprint(cfg: &VehicleConfig, state: &VehicleState) -> (Pose, Cuboid) {
        let (cx, cy) = state.footprint_center(cfg);
        Self::footprint_at(cfg, cx, cy, state.theta)
    }

    /// The footprint centred at `(cx, cy)` with heading `theta`.
    fn footprint_at(cfg: &VehicleConfig, cx: f64, cy: f64, theta: f64) -> (Pose, Cuboid) {
        (
            Pose::new(vec2(cx, cy), theta as Real),
            Cuboid::new(Vector::new(
                (cfg.length / 2.0) as Real,
                (cfg.width / 2.0) as Real,
            )),
        )
    }

    /// Obstacles the vehicle's footprint overlaps (indices into the scenario's list).
    pub fn footprint_hits(&self, cfg: &VehicleConfig, state: &VehicleState) -> Vec<usize> {
        let (pose, shape) = Self::footprint(cfg, state);
        self.hits(pose, &shape)
    }

    /// Obstacles a circle overlaps.
    pub fn circle_hits(&self, x: f64, y: f64, radius: f64) -> Vec<usize> {
        self.hits(
            Pose::from_translation(vec2(x, y)),
            &Ball::new(radius as Real),
        )
    }

    /// Distance from a shape at `pose` to one collider (0 when touching or
    /// overlapping), or `None` when it cannot be measured.
    fn distance(&self, collider: ColliderHandle, pose: &Pose, shape: &Cuboid) -> Option<f64> {
        let c = self.physics.colliders.get(collider)?;
        parry::query::distance(pose, shape, c.position(), c.shape())
            .ok()
            .map(|d| f64::from(d.distance))
    }

    /// Cast a ray from `(x, y)` in direction `angle` (radians, world frame) up to
    /// `max_range`: the obstacle hit and the range, or `None` for no return.
    pub fn cast_ray(&self, x: f64, y: f64, angle: f64, max_range: f64) -> Option<(usize, f64)> {
        ray::cast(&self.prims, x, y, angle, max_range).map(|(t, i)| (i, t))
    }

    /// Every beam of `fan` from the scanner pose `(x, y, heading)` up to `max_range`:
    /// `hits[i]` is beam `i`'s range and obstacle (`f64::INFINITY` for no return).
    pub fn scan(&self, pose: ScannerPose, fan: &Fan, max_range: f64, hits: &mut Vec<Hit>) {
        ray::scan(&self.prims, &self.bins, fan, pose, max_range, hits);
    }
}

/// A shape's pose for rapier.
fn pose_of(p: &Prim) -> Pose {
    Pose::new(vec2(p.x, p.y), p.heading as Real)
}

/// A shape's collider in its own frame.
fn collider_of(p: &Prim) -> ColliderBuilder {
    match p.form {
        Form::Circle { r } => ColliderBuilder::ball(r as Real),
        Form::Rect { hx, hy } => ColliderBuilder::cuboid(hx as Real, hy as Real),
    }
}

/// The shapes of obstacle `i`: a box per wall segment (flat, exact ends) and a post at
/// every inner joint so corners are closed. Both the ray caster and rapier's
/// colliders are built from them.
fn prims_of(i: usize, o: &Obstacle) -> Vec<Prim> {
    match o {
        Obstacle::Circle { x, y, radius, .. } => vec![Prim::circle(i, *x, *y, *radius)],
        Obstacle::Box {
            x,
            y,
            length,
            width,
            heading_deg,
            ..
        } => vec![Prim::rect(
            i,
            *x,
            *y,
            heading_deg.to_radians(),
            length / 2.0,
            width / 2.0,
        )],
        Obstacle::Wall { points, thickness } => {
            let segments = points.windows(2).map(|w| {
                let (a, b) = (w[0], w[1]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let (mx, my) = ((a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0);
                let half = (dx * dx + dy * dy).sqrt() / 2.0;
                Prim::rect(i, mx, my, dy.atan2(dx), half, thickness / 2.0)
            });
            let joints = points.iter().skip(1).take(points.len().saturating_sub(2));
            segments
                .chain(joints.map(|p| Prim::circle(i, p[0], p[1], thickness / 2.0)))
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Pose as ScenarioPose;
    use crate::scenario::Scenario;

    #[test]
    fn paper_scenario_footprint_collides_only_inside_the_post() {
        let s = Scenario::paper().expect("the paper's scenario");
        let w = World::new(&s.obstacles);
        let at = |x, y| {
            VehicleState::at(&ScenarioPose {
                x,
                y,
                heading_deg: 0.0,
            })
        };
        assert!(w.footprint_hits(&s.vehicle, &at(0.0, 0.0)).is_empty());
        // The rear axle at (17.5, 8): the footprint reaches into the post at (19, 8).
        assert_eq!(w.footprint_hits(&s.vehicle, &at(17.5, 8.0)), vec![0]);
        // Clearance to the post: the front bumper at x = 2.025 from the axle.
        let c = Clearances::new(&w, &s.vehicle, &at(10.0, 8.0)).resolved(&w);
        let front = 10.0 + s.vehicle.length - s.vehicle.rear_overhang;
        assert!((c[0] - (19.0 - 3.0 - front)).abs() < 1e-4, "{c:?}");
    }

    #[test]
    fn rays_hit_posts_and_walls_where_geometry_says() {
        let mut s = Scenario::paper().expect("the paper's scenario");
        s.obstacles.push(Obstacle::Wall {
            points: vec![[-5.0, 10.0], [5.0, 10.0], [5.0, 20.0]],
            thickness: 0.4,
        });
        let w = World::new(&s.obstacles);
        // Straight at the post from (10, 8): hits at 19 - 3 - 10 = 6.
        let (i, r) = w.cast_ray(10.0, 8.0, 0.0, 20.0).expect("hit");
        assert_eq!(i, 0);
        assert!((r - 6.0).abs() < 1e-4);
        // Up at the wall from the origin: its near face is at y = 9.8.
        let (i, r) = w
            .cast_ray(0.0, 0.0, std::f64::consts::FRAC_PI_2, 20.0)
            .expect("hit");
        assert_eq!(i, 1);
        assert!((r - 9.8).abs() < 1e-4, "{r}");
        // Away from everything: no return.
        assert!(w.cast_ray(0.0, 0.0, std::f64::consts::PI, 20.0).is_none());
    }

    #[test]
    fn moving_obstacles_move() {
        let s = Scenario {
            obstacles: vec![Obstacle::Circle {
                x: 0.0,
                y: 10.0,
                radius: 0.5,
                motion: Some(Motion::Velocity { vx: 1.0, vy: 0.0 }),
            }],
            ..Scenario::default()
        };
        let mut w = World::new(&s.obstacles);
        assert!(
            w.cast_ray(5.0, 0.0, std::f64::consts::FRAC_PI_2, 20.0)
                .is_none()
        );
        w.set_time(5.0);
        let (_, r) = w
            .cast_ray(5.0, 0.0, std::f64::consts::FRAC_PI_2, 20.0)
            .expect("moved into the ray");
        assert!((r - 9.5).abs() < 1e-4);
    }

    #[test]
    fn waypoint_motion_follows_legs_and_stops_or_cycles() {
        let m = Some(Motion::Waypoints {
            points: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]],
            speed: 2.0,
            cyclic: false,
        });
        assert_eq!(position_at(0.0, 0.0, &m, 2.5), (5.0, 0.0));
        assert_eq!(position_at(0.0, 0.0, &m, 7.5), (10.0, 5.0));
        assert_eq!(position_at(0.0, 0.0, &m, 100.0), (10.0, 10.0));
        let c = Some(Motion::Waypoints {
            points: vec![[0.0, 0.0], [10.0, 0.0]],
            speed: 1.0,
            cyclic: true,
        });
        let (x, y) = position_at(0.0, 0.0, &c, 25.0);
        assert!((x - 5.0).abs() < 1e-12 && y == 0.0, "{x}");
    }
}
