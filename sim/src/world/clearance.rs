//! The footprint's closest approach to each obstacle, exact, without measuring what
//! provably cannot matter.
//!
//! No point of the footprint moves more than the sweep (its centre's path plus the
//! half-diagonal times the heading's change), so a distance `d` measured at sweep
//! `s0` is at least `d - (s - s0)` at sweep `s`. A static collider is measured again
//! only when that bound comes within [`MARGIN`] of contact; the poses in between are
//! kept, and its closest approach over them is found when it is measured or when the
//! minima are read ([`Clearances::resolved`]): a branch and bound over the poses that
//! measures a pose only where the bound cannot rule it out. A moving obstacle is
//! measured every step. The figures are those of measuring everything every step: a
//! pose left out could not have lowered a minimum, and contact is checked whenever it
//! is possible. The cost follows the obstacles near the car, not those in the world.

use rapier2d::prelude::ColliderHandle;

use super::World;
use crate::scenario::schema::VehicleConfig;
use crate::vehicle::VehicleState;

/// Metres of slack for rounding (rapier measures in f32, a few ulp at a kilometre).
const MARGIN: f64 = 0.01;

#[derive(Clone, Copy, Debug)]
struct Item {
    obstacle: usize,
    collider: ColliderHandle,
    moving: bool,
    /// The pose last measured at and the distance then.
    at: usize,
    d: f64,
    /// Sweep from which contact is possible.
    due: f64,
}

/// A footprint pose: centre, heading, and the sweep so far.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sample {
    x: f64,
    y: f64,
    theta: f64,
    sweep: f64,
}

/// A static item's place in the queue of measurements: due from sweep `0`.
#[derive(Clone, Copy, Debug)]
struct Due(f64, usize);

impl PartialEq for Due {
    fn eq(&self, other: &Due) -> bool {
        self.cmp(other).is_eq()
    }
}
impl Eq for Due {}
impl PartialOrd for Due {
    fn partial_cmp(&self, other: &Due) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Due {
    /// The soonest due first out of a max-heap.
    fn cmp(&self, other: &Due) -> std::cmp::Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// Closest approach of the footprint to each obstacle so far.
#[derive(Clone, Debug)]
pub struct Clearances {
    /// Minima over the poses each collider's search has covered.
    min: Vec<f64>,
    items: Vec<Item>,
    /// The moving items (measured every step) and the static ones by when they are
    /// due: a step looks at those due, not at every collider of the world.
    moving: Vec<usize>,
    queue: std::collections::BinaryHeap<Due>,
    /// Every distinct pose since the start.
    poses: Vec<Sample>,
    cfg: VehicleConfig,
    half_diagonal: f64,
}

impl Clearances {
    /// Every obstacle measured from the footprint at `state`.
    pub fn new(world: &World, cfg: &VehicleConfig, state: &VehicleState) -> Clearances {
        let items: Vec<Item> = world
            .bodies
            .iter()
            .enumerate()
            .flat_map(|(i, b)| {
                let moving = b.spec.moves();
                b.colliders.iter().map(move |&collider| Item {
                    obstacle: i,
                    collider,
                    moving,
                    at: 0,
                    d: f64::INFINITY,
                    due: f64::NEG_INFINITY,
                })
            })
            .collect();
        let (x, y) = state.footprint_center(cfg);
        let mut c = Clearances {
            min: vec![f64::INFINITY; world.bodies.len()],
            moving: (items.iter().enumerate())
                .filter(|(_, it)| it.moving)
                .map(|(i, _)| i)
                .collect(),
            queue: std::collections::BinaryHeap::new(),
            items,
            poses: vec![Sample {
                x,
                y,
                theta: state.theta,
                sweep: 0.0,
            }],
            cfg: cfg.clone(),
            half_diagonal: (cfg.length / 2.0).hypot(cfg.width / 2.0),
        };
        for i in 0..c.items.len() {
            c.measure_now(world, i);
            if !c.items[i].moving {
                c.queue.push(Due(c.items[i].due, i));
            }
        }
        c
    }

    /// The closest approach to each obstacle so far, metres (0: touched), every pose
    /// searched.
    pub fn resolved(&self, world: &World) -> Vec<f64> {
        let mut min = self.min.clone();
        let last = self.poses.len() - 1;
        for it in self.items.iter().filter(|it| it.at < last) {
            let d = self.distance(world, it.collider, last);
            let best = &mut min[it.obstacle];
            *best = best.min(d);
            self.search(world, it.collider, (it.at, it.d), (last, d), best);
        }
        min
    }

    /// The footprint at `state`: the lowest index of an obstacle it touches or
    /// overlaps now, if any.
    pub fn update(
        &mut self,
        world: &World,
        cfg: &VehicleConfig,
        state: &VehicleState,
    ) -> Option<usize> {
        let (cx, cy) = state.footprint_center(cfg);
        self.advance(cx, cy, state.theta);
        let (now, sweep) = (self.poses.len() - 1, self.sweep());
        let mut touched: Option<usize> = None;
        let mut touch = |d: f64, obstacle: usize| {
            if d <= 0.0 {
                touched = Some(touched.map_or(obstacle, |t| t.min(obstacle)));
            }
        };
        for k in 0..self.moving.len() {
            let i = self.moving[k];
            touch(self.measure_now(world, i), self.items[i].obstacle);
        }
        // A static item not due cannot touch: measured at this pose, it is due unless
        // more than the margin away.
        let mut due = Vec::new();
        while let Some(&Due(at, i)) = self.queue.peek() {
            if at > sweep {
                break;
            }
            self.queue.pop();
            due.push(i);
        }
        for i in due {
            let it = self.items[i];
            // Measured at this very pose already, or not.
            let d = if it.at == now {
                it.d
            } else {
                self.measure_now(world, i)
            };
            touch(d, it.obstacle);
            self.queue.push(Due(self.items[i].due, i));
        }
        touched
    }

    /// Measure item `i` at the latest pose, its poses since the last measurement
    /// searched: the distance now.
    fn measure_now(&mut self, world: &World, i: usize) -> f64 {
        let now = self.poses.len() - 1;
        let it = self.items[i];
        let d = self.distance(world, it.collider, now);
        let mut best = self.min[it.obstacle].min(d);
        if it.at < now {
            self.search(world, it.collider, (it.at, it.d), (now, d), &mut best);
        }
        self.min[it.obstacle] = best;
        self.items[i] = Item {
            at: now,
            d,
            due: self.sweep() + d - MARGIN,
            ..it
        };
        d
    }

    /// Lower `best` to the smallest distance at the poses strictly between `a` and
    /// `b` (measured `da`, `db`) that could be below it: between two poses the
    /// distance is at least the mean of theirs less half the sweep between them.
    fn search(
        &self,
        world: &World,
        collider: ColliderHandle,
        (a, da): (usize, f64),
        (b, db): (usize, f64),
        best: &mut f64,
    ) {
        if b <= a + 1 {
            return;
        }
        let span = self.poses[b].sweep - self.poses[a].sweep;
        if (da + db - span) / 2.0 - MARGIN > *best {
            return;
        }
        let mid = a + (b - a) / 2;
        let dm = self.distance(world, collider, mid);
        *best = best.min(dm);
        self.search(world, collider, (a, da), (mid, dm), best);
        self.search(world, collider, (mid, dm), (b, db), best);
    }

    /// The distance from the footprint at pose `k` to a collider (infinite when it
    /// cannot be measured).
    fn distance(&self, world: &World, collider: ColliderHandle, k: usize) -> f64 {
        let p = self.poses[k];
        let (pose, shape) = World::footprint_at(&self.cfg, p.x, p.y, p.theta);
        world
            .distance(collider, &pose, &shape)
            .unwrap_or(f64::INFINITY)
    }

    fn sweep(&self) -> f64 {
        self.poses.last().map_or(0.0, |p| p.sweep)
    }

    /// A new pose when the footprint moved, the sweep grown by how far it may have.
    fn advance(&mut self, x: f64, y: f64, theta: f64) {
        let Some(&last) = self.poses.last() else {
            return;
        };
        let same =
            [x, y, theta].map(f64::to_bits) == [last.x, last.y, last.theta].map(f64::to_bits);
        if !same {
            let moved =
                (x - last.x).hypot(y - last.y) + self.half_diagonal * (theta - last.theta).abs();
            self.poses.push(Sample {
                x,
                y,
                theta,
                sweep: last.sweep + moved,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use crate::scenario::schema::Obstacle;
    use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};

    /// Every collider measured at every step, as before the schedule.
    fn brute(world: &World, cfg: &VehicleConfig, state: &VehicleState) -> Vec<f64> {
        let (pose, shape) = World::footprint(cfg, state);
        world
            .bodies
            .iter()
            .map(|b| {
                b.colliders
                    .iter()
                    .filter_map(|h| world.distance(*h, &pose, &shape))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    #[test]
    fn the_minima_and_contacts_are_those_of_measuring_everything_every_step() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut obstacles: Vec<Obstacle> = (0..80)
            .map(|_| Obstacle::Circle {
                x: rng.random_range(-60.0..60.0),
                y: rng.random_range(-60.0..60.0),
                radius: rng.random_range(0.2..1.5),
                motion: None,
            })
            .collect();
        // Touching the car at the start, a wall with a corner, and a walker.
        obstacles.push(Obstacle::Circle {
            x: 1.0,
            y: 0.0,
            radius: 0.5,
            motion: None,
        });
        obstacles.push(Obstacle::Wall {
            points: vec![[-30.0, -40.0], [30.0, -40.0], [30.0, 40.0]],
            thickness: 0.4,
        });
        obstacles.push(Obstacle::Circle {
            x: 20.0,
            y: -20.0,
            radius: 0.3,
            motion: Some(crate::scenario::schema::Motion::Velocity { vx: -0.5, vy: 0.5 }),
        });
        let s = Scenario {
            obstacles,
            ..Scenario::default()
        };
        let mut world = World::new(&s.obstacles);
        let mut state = VehicleState::at(&crate::scenario::Pose {
            x: 0.0,
            y: 0.0,
            heading_deg: 0.0,
        });
        let mut c = Clearances::new(&world, &s.vehicle, &state);
        let mut min = brute(&world, &s.vehicle, &state);
        let mut contacts = 0;
        for k in 1..=10_000 {
            // Drive, turn, stand still in turns.
            let (v, phi) = match (k / 400) % 3 {
                0 => (3.0, rng.random_range(-0.4..0.4)),
                1 => (0.0, 0.0),
                _ => (-1.5, 0.3),
            };
            state.step(s.vehicle.wheelbase, v, phi, 0.005);
            world.set_time(k as f64 * 0.005);
            let now = brute(&world, &s.vehicle, &state);
            for (m, d) in min.iter_mut().zip(&now) {
                *m = m.min(*d);
            }
            let touched = c.update(&world, &s.vehicle, &state);
            assert_eq!(touched, now.iter().position(|d| *d <= 0.0), "step {k}");
            contacts += usize::from(touched.is_some());
            if k % 500 == 0 {
                assert_eq!(c.resolved(&world), min, "step {k}");
            }
        }
        assert!(contacts > 0, "the drive touches something");
        // Far fewer measurements than every collider at every pose.
        let measured = c.items.iter().filter(|i| i.at + 1 < c.poses.len()).count();
        assert!(
            measured > 0,
            "some colliders were left unmeasured at the end"
        );
    }

    #[test]
    fn a_far_obstacle_is_not_measured_while_the_car_approaches() {
        let s = Scenario {
            obstacles: vec![Obstacle::Circle {
                x: 200.0,
                y: 0.0,
                radius: 1.0,
                motion: None,
            }],
            ..Scenario::default()
        };
        let world = World::new(&s.obstacles);
        let mut state = VehicleState::at(&crate::scenario::Pose {
            x: 0.0,
            y: 0.0,
            heading_deg: 0.0,
        });
        let mut c = Clearances::new(&world, &s.vehicle, &state);
        for _ in 0..1_000 {
            state.step(s.vehicle.wheelbase, 5.0, 0.0, 0.005);
            assert_eq!(c.update(&world, &s.vehicle, &state), None);
        }
        assert_eq!(c.items[0].at, 0, "measured only at the start");
        let r = c.resolved(&world)[0];
        let want = brute(&world, &s.vehicle, &state)[0];
        assert_eq!(r, want);
    }
}
