//! Whether a world has a way through for the car at all: the controller's manoeuvre
//! planner (Hybrid A*, `ugv_controller::guidance::manoeuvre`) run offline, knowing the
//! whole world, from the start to the goal at a fine resolution until its open set is
//! empty. A world it finds no way through is one where a controlled stop is the right
//! outcome for a car that cannot turn on the spot (issue 34's "no way through" list;
//! `scripts/barn.py --exclude-list`).
//!
//! The world's static obstacles become the planner's discs: a circle as it is, a wall as
//! a chain of discs of half its thickness along each segment (its capsule: the
//! simulator's square segment ends stick out of it by at most 0.21 of the thickness), a
//! box as rows of discs inside it. Each is inside the obstacle, so a way found may graze
//! a square corner, but no way is missed: a world listed as having none has none for the
//! car's rectangle at the margin searched (up to the search's resolution).

use crate::scenario::Obstacle;
use crate::{Scenario, ScenarioError};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Instant;
use ugv_controller::config::FollowerKind;
use ugv_controller::guidance::Footprint;
use ugv_controller::guidance::manoeuvre::{Disc, Field, Goal, Settings, hybrid};

/// Spacing of the discs along a wall or a box, metres.
const DISC_SPACING: f64 = 0.05;
/// The field's window reaches this far beyond the obstacles, the start and the goal,
/// metres.
const WINDOW_MARGIN: f64 = 4.0;
/// Cell of the distance field, metres (only the speed depends on it: the rectangle is
/// checked exactly wherever the field does not settle a pose).
const FIELD_RES: f64 = 0.1;

/// How the search is run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// Clearance between the car's rectangle and every obstacle, metres.
    pub margin: f64,
    /// The share of the steering lock the search may use (1: full lock).
    pub steer_usage: f64,
    /// Side of a search cell, metres, and heading cells in a turn.
    pub xy_res: f64,
    pub heading_bins: usize,
    /// Expansions before the search is called undecided.
    pub max_expansions: usize,
}

impl Default for Options {
    /// Exact contact (margin 0), full lock, 0.1 m and 2.5 degrees, 4 million expansions.
    fn default() -> Options {
        Options {
            margin: 0.0,
            steer_usage: 1.0,
            xy_res: 0.1,
            heading_bins: 144,
            max_expansions: 4_000_000,
        }
    }
}

/// Search each scenario file on `jobs` threads: each file with what was found and the
/// wall time its search took, seconds, in the order given; or the first file that does
/// not load.
pub fn search_all(
    paths: &[PathBuf],
    opts: &Options,
    jobs: usize,
) -> Result<Vec<(PathBuf, WayThrough, f64)>, ScenarioError> {
    let scenarios = paths
        .iter()
        .map(|p| Scenario::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let next = AtomicUsize::new(0);
    let found = Mutex::new(vec![None; paths.len()]);
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(scenario) = scenarios.get(k) else {
                        break;
                    };
                    let t0 = Instant::now();
                    let w = way_through(scenario, opts);
                    let wall = t0.elapsed().as_secs_f64();
                    if let Ok(mut found) = found.lock() {
                        found[k] = Some((w, wall));
                    }
                }
            });
        }
    });
    let found = found.into_inner().unwrap_or_else(PoisonError::into_inner);
    Ok(paths
        .iter()
        .zip(found)
        .filter_map(|(p, f)| f.map(|(w, wall)| (p.clone(), w, wall)))
        .collect())
}

/// What the search found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WayThrough {
    /// A way to the goal: its length driven and its changes of direction.
    Found {
        length: f64,
        cusps: usize,
        expansions: usize,
    },
    /// Every pose reachable from the start was expanded and none reaches the goal.
    None {
        expansions: usize,
        why: &'static str,
    },
    /// The search stopped at its bound of expansions.
    Undecided { expansions: usize },
}

/// Search the scenario's world for a way from its start to its goal.
pub fn way_through(scenario: &Scenario, opts: &Options) -> WayThrough {
    let v = &scenario.vehicle;
    let cfg = crate::mission::controller_config(scenario, FollowerKind::Optimal);
    let car = Footprint::of(&cfg.vehicle, opts.margin);
    let discs: Vec<Disc> = scenario.obstacles.iter().flat_map(discs).collect();
    let start = [scenario.start.x, scenario.start.y, scenario.start.heading()];
    // The verdict counts the goal reached at any heading.
    let goal = Goal {
        pose: [scenario.goal.x, scenario.goal.y, 0.0],
        tol_xy: scenario.goal.tolerance,
        tol_theta: std::f64::consts::PI,
    };
    let (lo, hi) = window(&discs, start, goal.pose);
    let field = Field::new(lo, hi, FIELD_RES, discs, car);
    let lock = (v.max_steer_deg * opts.steer_usage).to_radians();
    let settings = Settings {
        turn_radius: v.wheelbase / lock.tan(),
        // A step longer than a cell's diagonal, so a successor leaves its cell.
        step: 2.0 * opts.xy_res,
        xy_res: opts.xy_res,
        heading_bins: opts.heading_bins,
        max_expansions: opts.max_expansions,
        ..Settings::default()
    };
    match hybrid::search(&field, start, &goal, &settings) {
        Ok(found) if found.complete => WayThrough::Found {
            length: found.manoeuvre.length(start),
            cusps: found.manoeuvre.cusps(),
            expansions: found.expansions,
        },
        Ok(found) if found.expansions < opts.max_expansions => WayThrough::None {
            expansions: found.expansions,
            why: "every reachable pose expanded",
        },
        Ok(found) => WayThrough::Undecided {
            expansions: found.expansions,
        },
        Err(hybrid::Failure::Exhausted(n)) if n >= opts.max_expansions => {
            WayThrough::Undecided { expansions: n }
        }
        Err(e) => WayThrough::None {
            expansions: match e {
                hybrid::Failure::Exhausted(n) => n,
                _ => 0,
            },
            why: match e {
                hybrid::Failure::StartBlocked => "the car does not clear its start",
                hybrid::Failure::GoalBlocked => "the car does not fit at the goal",
                hybrid::Failure::Unreachable => "no way on the map even for the rear axle",
                hybrid::Failure::Exhausted(_) => "every reachable pose expanded",
            },
        },
    }
}

/// The discs inside a static obstacle (a moving one where it starts).
fn discs(o: &Obstacle) -> Vec<Disc> {
    match o {
        Obstacle::Circle { x, y, radius, .. } => vec![Disc {
            x: *x,
            y: *y,
            r: *radius,
        }],
        Obstacle::Wall { points, thickness } => points
            .windows(2)
            .flat_map(|w| chain(w[0], w[1], thickness / 2.0))
            .collect(),
        Obstacle::Box {
            x,
            y,
            length,
            width,
            heading_deg,
            ..
        } => {
            // Rows of discs of radius r, r in from each side: together they cover the
            // box but for a rim of r(1 - 1/sqrt 2) at its corners and between rows.
            let r = (width.min(*length) / 2.0).min(0.25);
            let (c, s) = (
                heading_deg.to_radians().cos(),
                heading_deg.to_radians().sin(),
            );
            let (hl, hw) = (length / 2.0 - r, width / 2.0 - r);
            let rows = ((2.0 * hw / r).ceil() as usize).max(1);
            (0..=rows)
                .flat_map(|k| {
                    let v = -hw + 2.0 * hw * k as f64 / rows as f64;
                    let end = |u: f64| [x + u * c - v * s, y + u * s + v * c];
                    chain(end(-hl), end(hl), r)
                })
                .collect()
        }
    }
}

/// Discs of radius `r` from `a` to `b`, [`DISC_SPACING`] apart or closer.
fn chain(a: [f64; 2], b: [f64; 2], r: f64) -> Vec<Disc> {
    let n = (((b[0] - a[0]).hypot(b[1] - a[1]) / DISC_SPACING).ceil() as usize).max(1);
    (0..=n)
        .map(|k| {
            let t = k as f64 / n as f64;
            Disc {
                x: a[0] + t * (b[0] - a[0]),
                y: a[1] + t * (b[1] - a[1]),
                r,
            }
        })
        .collect()
}

/// The window round every disc, the start and the goal.
fn window(discs: &[Disc], start: [f64; 3], goal: [f64; 3]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [start[0].min(goal[0]), start[1].min(goal[1])];
    let mut hi = [start[0].max(goal[0]), start[1].max(goal[1])];
    for d in discs {
        lo = [lo[0].min(d.x - d.r), lo[1].min(d.y - d.r)];
        hi = [hi[0].max(d.x + d.r), hi[1].max(d.y + d.r)];
    }
    (
        [lo[0] - WINDOW_MARGIN, lo[1] - WINDOW_MARGIN],
        [hi[0] + WINDOW_MARGIN, hi[1] + WINDOW_MARGIN],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(obstacles: &str) -> Scenario {
        let text = format!(
            "name = \"t\"\n[start]\nx = 0.0\ny = 0.0\n[goal]\nx = 20.0\ny = 0.0\ntolerance = 1.0\n{obstacles}"
        );
        Scenario::from_toml(&text, "t.toml").expect("scenario")
    }

    fn fence(gap: f64) -> String {
        // A closed corridor 6 m wide from x = -3 to 25, a fence across it at x = 10 with
        // a gap of `gap` (between the walls' faces, 0.2 m inside their points) on the
        // line.
        let h = gap / 2.0 + 0.2;
        format!(
            "[[obstacles]]\nkind = \"wall\"\npoints = [[-3.0, -3.0], [25.0, -3.0], [25.0, 3.0], [-3.0, 3.0], [-3.0, -3.0]]\nthickness = 0.4\n\
             [[obstacles]]\nkind = \"wall\"\npoints = [[10.0, {h}], [10.0, 3.0]]\nthickness = 0.4\n\
             [[obstacles]]\nkind = \"wall\"\npoints = [[10.0, -{h}], [10.0, -3.0]]\nthickness = 0.4\n"
        )
    }

    const QUICK: Options = Options {
        margin: 0.0,
        steer_usage: 1.0,
        xy_res: 0.5,
        heading_bins: 36,
        max_expansions: 400_000,
    };

    #[test]
    fn a_gap_wider_than_the_car_is_a_way_through_and_a_narrower_one_is_not() {
        // The car is 1.2 m wide.
        match way_through(&scenario(&fence(1.4)), &QUICK) {
            WayThrough::Found { length, cusps, .. } => {
                assert!((19.0..26.0).contains(&length), "{length}");
                assert_eq!(cusps, 0);
            }
            other => panic!("1.4 m gap: {other:?}"),
        }
        match way_through(&scenario(&fence(1.1)), &QUICK) {
            WayThrough::None { expansions, why } => {
                assert!(expansions > 100, "{expansions}: {why}");
            }
            other => panic!("1.1 m gap: {other:?}"),
        }
    }

    #[test]
    fn a_wall_is_discs_along_its_capsule_and_a_box_discs_inside_it() {
        let wall = Obstacle::Wall {
            points: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
            thickness: 0.4,
        };
        let d = discs(&wall);
        assert!(d.iter().all(|d| d.r == 0.2));
        assert!(d.len() >= 2 * 21);
        let b = Obstacle::Box {
            x: 5.0,
            y: 5.0,
            length: 4.0,
            width: 2.0,
            heading_deg: 90.0,
            motion: None,
        };
        let d = discs(&b);
        // Inside the box: 2 m along x (the box turned 90 degrees), 4 m along y.
        assert!(d.iter().all(|d| (d.x - 5.0).abs() + d.r <= 1.0 + 1e-9));
        assert!(d.iter().all(|d| (d.y - 5.0).abs() + d.r <= 2.0 + 1e-9));
        // And covering its middle and near its corners.
        for p in [[5.0, 5.0], [5.8, 6.8], [4.2, 3.2]] {
            assert!(
                d.iter().any(|d| (d.x - p[0]).hypot(d.y - p[1]) <= d.r),
                "{p:?}"
            );
        }
    }
}
