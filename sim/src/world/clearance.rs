//! The footprint's closest approach to each obstacle, kept up to date each physics
//! step without measuring what provably cannot come closer.
//!
//! Each collider remembers the distance `d` measured when the footprint had swept
//! `s0` metres. No point of the footprint moves more than the sweep (the centre's
//! path plus the half-diagonal times the heading's change), so until the sweep has
//! grown by `d - min - MARGIN` the distance stays above the obstacle's recorded
//! minimum: the minimum cannot change and there is no contact. A static collider is
//! measured again only then, or when the pose changed and it was touching; a moving
//! obstacle every step. The figures are those of measuring everything every step:
//! a skipped measurement could not have lowered a minimum or found a contact.

use rapier2d::prelude::ColliderHandle;

use super::World;
use crate::scenario::schema::{Obstacle, VehicleConfig};
use crate::vehicle::VehicleState;

/// Metres of slack for rounding (rapier measures in f32, a few ulp at a kilometre).
const MARGIN: f64 = 0.01;

#[derive(Clone, Copy, Debug)]
struct Item {
    obstacle: usize,
    collider: ColliderHandle,
    moving: bool,
    /// Sweep at which it must be measured again.
    due: f64,
    /// The last distance measured, and the pose's version then.
    last: f64,
    version: u64,
}

/// Closest approach of the footprint to each obstacle so far.
#[derive(Clone, Debug)]
pub struct Clearances {
    min: Vec<f64>,
    items: Vec<Item>,
    /// Metres any point of the footprint may have moved since the start.
    sweep: f64,
    /// Footprint centre and heading at the last update, and a counter of changes.
    pose: Option<[u64; 3]>,
    version: u64,
    half_diagonal: f64,
}

impl Clearances {
    /// Every obstacle measured from the footprint at `state`.
    pub fn new(world: &World, cfg: &VehicleConfig, state: &VehicleState) -> Clearances {
        let items = world
            .bodies
            .iter()
            .enumerate()
            .flat_map(|(i, b)| {
                let moving = match &b.spec {
                    Obstacle::Circle { motion, .. } | Obstacle::Box { motion, .. } => {
                        motion.is_some()
                    }
                    Obstacle::Wall { .. } => false,
                };
                b.colliders.iter().map(move |&collider| Item {
                    obstacle: i,
                    collider,
                    moving,
                    due: f64::NEG_INFINITY,
                    last: 0.0,
                    version: u64::MAX,
                })
            })
            .collect();
        let mut c = Clearances {
            min: vec![f64::INFINITY; world.bodies.len()],
            items,
            sweep: 0.0,
            pose: None,
            version: 0,
            half_diagonal: (cfg.length / 2.0).hypot(cfg.width / 2.0),
        };
        c.update(world, cfg, state);
        c
    }

    /// The closest approach to each obstacle so far, metres (0: touched).
    pub fn min(&self) -> &[f64] {
        &self.min
    }

    /// Measure what could have come closer from the footprint at `state`: the lowest
    /// index of an obstacle it touches or overlaps now, if any.
    pub fn update(
        &mut self,
        world: &World,
        cfg: &VehicleConfig,
        state: &VehicleState,
    ) -> Option<usize> {
        let (cx, cy) = state.footprint_center(cfg);
        self.advance(cx, cy, state.theta);
        let (pose, shape) = World::footprint(cfg, state);
        let mut touched: Option<usize> = None;
        for it in &mut self.items {
            let unchanged = it.version == self.version && it.last > 0.0;
            if !it.moving && (unchanged || self.sweep < it.due) {
                continue;
            }
            let Some(d) = world.distance(it.collider, &pose, &shape) else {
                continue;
            };
            let m = &mut self.min[it.obstacle];
            *m = m.min(d);
            (it.due, it.last, it.version) = (self.sweep + (d - *m) - MARGIN, d, self.version);
            if d <= 0.0 {
                touched = Some(touched.map_or(it.obstacle, |t| t.min(it.obstacle)));
            }
        }
        touched
    }

    /// Grow the sweep by how far the footprint may have moved since the last update.
    fn advance(&mut self, cx: f64, cy: f64, theta: f64) {
        let now = [cx.to_bits(), cy.to_bits(), theta.to_bits()];
        if let Some(was) = self.pose {
            if was == now {
                return;
            }
            let [x, y, t] = was.map(f64::from_bits);
            self.sweep += (cx - x).hypot(cy - y) + self.half_diagonal * (theta - t).abs();
        }
        self.pose = Some(now);
        self.version += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
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
    fn the_schedule_gives_the_minima_and_contacts_of_measuring_everything() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut s = Scenario::default();
        s.obstacles = (0..80)
            .map(|_| Obstacle::Circle {
                x: rng.random_range(-60.0..60.0),
                y: rng.random_range(-60.0..60.0),
                radius: rng.random_range(0.2..1.5),
                motion: None,
            })
            .collect();
        // Touching the car at the start.
        s.obstacles.push(Obstacle::Circle {
            x: 1.0,
            y: 0.0,
            radius: 0.5,
            motion: None,
        });
        s.obstacles.push(Obstacle::Wall {
            points: vec![[-30.0, -40.0], [30.0, -40.0], [30.0, 40.0]],
            thickness: 0.4,
        });
        let world = World::new(&s.obstacles);
        let mut state = VehicleState::at(&crate::scenario::Pose {
            x: 0.0,
            y: 0.0,
            heading_deg: 0.0,
        });
        let mut c = Clearances::new(&world, &s.vehicle, &state);
        let mut min = brute(&world, &s.vehicle, &state);
        let (mut skipped_steps, mut contacts) = (0, 0);
        for k in 0..20_000 {
            // Drive, turn, stand still in turns.
            let (v, phi) = match (k / 400) % 3 {
                0 => (3.0, rng.random_range(-0.4..0.4)),
                1 => (0.0, 0.0),
                _ => (-1.5, 0.3),
            };
            state.step(s.vehicle.wheelbase, v, phi, 0.005);
            let now = brute(&world, &s.vehicle, &state);
            for (m, d) in min.iter_mut().zip(&now) {
                *m = m.min(*d);
            }
            let before = c.items.iter().map(|i| i.version).collect::<Vec<_>>();
            let touched = c.update(&world, &s.vehicle, &state);
            assert_eq!(touched, now.iter().position(|d| *d <= 0.0), "step {k}");
            contacts += usize::from(touched.is_some());
            assert_eq!(c.min(), &min[..], "step {k}");
            let measured = c
                .items
                .iter()
                .zip(&before)
                .filter(|(i, b)| i.version != **b);
            skipped_steps += c.items.len() - measured.count();
        }
        assert!(contacts > 0, "the drive touches something");
        // Most measurements were skipped.
        eprintln!("{skipped_steps} of {}", 20_000 * c.items.len());
        assert!(
            skipped_steps > 20_000 * c.items.len() / 3,
            "{skipped_steps}"
        );
    }
}
