//! Hybrid A* (Dolgov, Thrun, Montemerlo and Diebel 2008, "Practical search techniques
//! in path planning for autonomous driving"): A* over continuous poses, one kept per
//! cell of a grid of position and heading; successors are arcs of one step at a few
//! steering curvatures up to the planned lock, forward and backward; the cost is the
//! length driven, backwards dearer, plus a penalty per change of direction (cusp) and
//! for steering and changes of it. Two heuristics, the larger taken: the holonomic one
//! with obstacles (the length of the shortest 8-connected way on the grid from the
//! goal, through cells the rear axle may occupy) and, within a few turning radii of the
//! goal, the non-holonomic one without obstacles (the shortest Reeds-Shepp curve). Every
//! few expansions the shortest Reeds-Shepp curves to the goal are tried as an analytic
//! expansion; the first one the car's rectangle clears ends the search. The search is
//! bounded by a number of expansions (not by time: a plan must not depend on the
//! machine's speed).

use super::curves;
use super::field::Field;
use super::path::{Manoeuvre, PathPoint, arc, turned_arc};
use crate::grid::Grid;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Step between the poses a path is sampled and checked at, metres.
pub const SAMPLE: f64 = 0.1;

/// The search's tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Turning radius at the lock the manoeuvre may use (rear axle), metres.
    pub turn_radius: f64,
    /// Arc length of one successor, metres (more than a cell's diagonal).
    pub step: f64,
    /// Side of a grid cell, metres.
    pub xy_res: f64,
    /// Heading cells in a full turn.
    pub heading_bins: usize,
    /// Cost per metre driven backwards, against 1 forwards.
    pub reverse_weight: f64,
    /// Cost of a change of direction, metres' worth.
    pub cusp_cost: f64,
    /// Cost per metre driven at full lock (in proportion to the curvature).
    pub steer_weight: f64,
    /// Cost of a change of steering between successors, metres' worth per full lock.
    pub steer_change_cost: f64,
    /// Expansions before the search gives up.
    pub max_expansions: usize,
}

impl Default for Settings {
    /// The golf car's: arcs of 0.4 m on a grid of 0.25 m and 5 degrees; backwards at
    /// twice the cost, a cusp worth 3 m.
    fn default() -> Settings {
        Settings {
            turn_radius: 2.6,
            step: 0.4,
            xy_res: 0.25,
            heading_bins: 72,
            reverse_weight: 2.0,
            cusp_cost: 3.0,
            steer_weight: 0.1,
            steer_change_cost: 0.3,
            max_expansions: 20_000,
        }
    }
}

/// Where the manoeuvre ends: a pose, and how near it counts as there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Goal {
    pub pose: [f64; 3],
    /// Metres and radians.
    pub tol_xy: f64,
    pub tol_theta: f64,
}

/// A manoeuvre found, and what the search took.
#[derive(Clone, Debug)]
pub struct Found {
    pub manoeuvre: Manoeuvre,
    pub expansions: usize,
    /// It ends at the goal; else it ends where the search, within what is known, came
    /// at least [`PARTIAL_PROGRESS`] nearer the goal (by the holonomic way's length),
    /// the nearer the better but not at any cost ([`PARTIAL_COST_WEIGHT`]): driven, it
    /// shows the laser more, and the next search goes on.
    pub complete: bool,
}

/// A partial manoeuvre must bring the car this much nearer the goal (by the holonomic
/// way's length), metres.
pub const PARTIAL_PROGRESS: f64 = 1.0;
/// A partial manoeuvre ends where the holonomic way left plus this much of the cost of
/// getting there (metres' worth: length, backwards dearer, cusps) is least: a metre
/// nearer the goal is worth five of driving forward, or a little under two cusps, so
/// a partial manoeuvre does not shuffle back and forth for the last few decimetres of
/// progress (the next search, from where it ends, sees more).
pub const PARTIAL_COST_WEIGHT: f64 = 0.2;

/// Why no manoeuvre was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Failure {
    #[error("the car's rectangle does not clear its own pose")]
    StartBlocked,
    #[error("the car's rectangle does not fit at the goal")]
    GoalBlocked,
    #[error("no way to the goal on the map (holonomic)")]
    Unreachable,
    #[error("no manoeuvre nearer the goal within {0} expansions")]
    Exhausted(usize),
}

/// Steering curvatures tried, as fractions of the lock.
const STEERS: [f64; 5] = [1.0, 0.5, 0.0, -0.5, -1.0];
/// The Reeds-Shepp heuristic is evaluated within this many turning radii of the goal.
const RS_HEURISTIC_RADII: f64 = 4.0;
/// Analytic expansions are tried within this of the goal, metres, and at most this
/// many curves each time (shortest first).
const ANALYTIC_RANGE: f64 = 25.0;
const ANALYTIC_CURVES: usize = 6;
/// An analytic expansion's samples are checked this many apart first (0.8 m).
const STRIDE: usize = 8;

/// A successor: its pose, direction, curvature and the step's cost.
type Step = ([f64; 3], bool, f64, f64);

#[derive(Clone, Copy, Debug)]
struct Node {
    pose: [f64; 3],
    /// Its cell of position and heading ([`Kept::slot`]).
    slot: usize,
    g: f64,
    parent: usize,
    forward: bool,
    curvature: f64,
}

/// Search a manoeuvre from `start` to `goal` in `field`.
pub fn search(field: &Field, start: [f64; 3], goal: &Goal, s: &Settings) -> Result<Found, Failure> {
    if !field.clear(start) {
        return Err(Failure::StartBlocked);
    }
    if !field.clear(goal.pose) {
        return Err(Failure::GoalBlocked);
    }
    let holo = Holonomic::new(field, goal.pose, s.xy_res);
    let h0 = holo.at(start[0], start[1]);
    if !h0.is_finite() {
        return Err(Failure::Unreachable);
    }
    let mut best = Kept::new(field, s);
    let Some(slot) = best.slot(start) else {
        return Err(Failure::StartBlocked);
    };
    let mut nodes = vec![Node {
        pose: start,
        slot,
        g: 0.0,
        parent: usize::MAX,
        forward: true,
        curvature: 0.0,
    }];
    best.set(slot, 0);
    let mut open = Open::default();
    open.push(h0, 0, false);
    let mut expansions = 0;
    // The partial manoeuvre's end: of least `partial_score`, `PARTIAL_PROGRESS` nearer.
    let mut partial: Option<(f64, usize)> = None;
    // The successors of the node being expanded, the buffer kept from one to the next.
    let mut steps = Vec::with_capacity(2 * STEERS.len());
    while let Some((key, id, exact)) = open.pop() {
        let node = nodes[id];
        // A node since bettered in its cell is not expanded.
        if best.get(node.slot) != Some(id) {
            continue;
        }
        // Queued on the holonomic heuristic, again if the Reeds-Shepp one raises it.
        if !exact {
            let h = reeds_shepp(&holo, node.pose, goal, s);
            if !h.is_finite() {
                continue;
            }
            if node.g + h > key {
                open.push(node.g + h, id, true);
                continue;
            }
        }
        if at_goal(node.pose, goal) {
            return Ok(reached(&nodes, id, Vec::new(), s, expansions));
        }
        expansions += 1;
        if expansions > s.max_expansions {
            break;
        }
        if let Some(tail) = analytic(field, &node, goal, s, expansions) {
            return Ok(reached(&nodes, id, tail, s, expansions));
        }
        successors(field, &node, s, &mut steps);
        for &(pose, forward, curvature, step_cost) in &steps {
            let g = node.g + step_cost;
            // Into a cell of position and heading only if better than its node.
            let better = |&k: &usize| best.get(k).is_none_or(|b| nodes[b].g > g);
            let Some(slot) = best.slot(pose).filter(better) else {
                continue;
            };
            let h = holo.at(pose[0], pose[1]);
            if !h.is_finite() {
                continue;
            }
            nodes.push(Node {
                pose,
                slot,
                g,
                parent: id,
                forward,
                curvature,
            });
            let child = nodes.len() - 1;
            let score = partial_score(h, g);
            if h <= h0 - PARTIAL_PROGRESS && partial.is_none_or(|(best, _)| score < best) {
                partial = Some((score, child));
            }
            best.set(slot, child);
            open.push(g + h, child, false);
        }
    }
    let expansions = expansions.min(s.max_expansions);
    let Some((_, end)) = partial else {
        return Err(Failure::Exhausted(expansions));
    };
    Ok(Found {
        manoeuvre: finish(&nodes, end, Vec::new(), s.step),
        expansions,
        complete: false,
    })
}

/// The open set: node ids by key (g + h, h exact or a lower bound of it), the first
/// queued first among equal keys.
#[derive(Default)]
struct Open {
    heap: BinaryHeap<Reverse<(u64, u64, usize, bool)>>,
    queued: u64,
}

impl Open {
    fn push(&mut self, key: f64, id: usize, exact: bool) {
        self.queued += 1;
        self.heap
            .push(Reverse((key.to_bits(), self.queued, id, exact)));
    }

    /// The node of least key: the key, the node, whether its heuristic is exact.
    fn pop(&mut self) -> Option<(f64, usize, bool)> {
        let Reverse((key, _, id, exact)) = self.heap.pop()?;
        Some((f64::from_bits(key), id, exact))
    }
}

/// The complete manoeuvre to node `id` then along `tail`, found after `expansions`.
fn reached(
    nodes: &[Node],
    id: usize,
    tail: Vec<PathPoint>,
    s: &Settings,
    expansions: usize,
) -> Found {
    Found {
        manoeuvre: finish(nodes, id, tail, s.step),
        expansions,
        complete: true,
    }
}

/// What a partial manoeuvre ending `way` from the goal (the holonomic way's length)
/// at cost `g` scores (the least is taken): see [`PARTIAL_COST_WEIGHT`].
fn partial_score(way: f64, g: f64) -> f64 {
    way + PARTIAL_COST_WEIGHT * g
}

fn at_goal(pose: [f64; 3], goal: &Goal) -> bool {
    (pose[0] - goal.pose[0]).hypot(pose[1] - goal.pose[1]) <= goal.tol_xy
        && super::super::frame::wrap(pose[2] - goal.pose[2]).abs() <= goal.tol_theta
}

/// The node kept in each cell of position and heading (the best found there): a
/// table over the field's window.
struct Kept {
    grid: Grid,
    bins: usize,
    /// Node id + 1 per cell; 0: none yet. Taken from [`TABLE`] and given back.
    node: Vec<u32>,
    /// The cells set, cleared when the table is given back.
    written: Vec<usize>,
}

thread_local! {
    /// The table of [`Kept`], all zeros between searches. A window's table is megabytes
    /// (72 headings per cell) of which a search sets a few thousand cells: zeroing it
    /// anew for each search was nearly a fifth of the searches' cost where they end
    /// soon (boxed in: 96 searches of 38 expansions on average).
    static TABLE: std::cell::Cell<Vec<u32>> = const { std::cell::Cell::new(Vec::new()) };
}

impl Kept {
    fn new(field: &Field, s: &Settings) -> Kept {
        let (lo, hi) = field.bounds();
        let grid = Grid::covering(lo, hi, s.xy_res);
        // Only grown: a longer table's cells beyond this window's are zero, unused.
        let mut node = TABLE.take();
        let len = grid.len() * s.heading_bins;
        if node.len() < len {
            node.resize(len, 0);
        }
        Kept {
            grid,
            bins: s.heading_bins,
            node,
            written: Vec::new(),
        }
    }

    /// The cell of `pose`; None outside the window.
    fn slot(&self, pose: [f64; 3]) -> Option<usize> {
        let turn = std::f64::consts::TAU;
        let h = (pose[2].rem_euclid(turn) / turn * self.bins as f64) as usize % self.bins;
        self.grid.index(pose[0], pose[1]).map(|k| k * self.bins + h)
    }

    fn get(&self, slot: usize) -> Option<usize> {
        self.node[slot].checked_sub(1).map(|id| id as usize)
    }

    fn set(&mut self, slot: usize, id: usize) {
        if self.node[slot] == 0 {
            self.written.push(slot);
        }
        self.node[slot] = id as u32 + 1;
    }
}

impl Drop for Kept {
    fn drop(&mut self) {
        for &slot in &self.written {
            self.node[slot] = 0;
        }
        TABLE.set(std::mem::take(&mut self.node));
    }
}

/// The heuristic at `pose`: the holonomic one and, near the goal, the Reeds-Shepp one,
/// the larger. Computed for the nodes taken out of the queue only (a few in ten of
/// those queued): they are queued on the holonomic one, a lower bound of it.
fn reeds_shepp(holo: &Holonomic, pose: [f64; 3], goal: &Goal, s: &Settings) -> f64 {
    let h = holo.at(pose[0], pose[1]);
    let near =
        (pose[0] - goal.pose[0]).hypot(pose[1] - goal.pose[1]) < RS_HEURISTIC_RADII * s.turn_radius;
    if near && h.is_finite() {
        // The shortest curve to anywhere within the goal's tolerance is shorter by at
        // most that tolerance.
        let rs = curves::shortest(pose, goal.pose, s.turn_radius) - goal.tol_xy;
        return h.max(rs);
    }
    h
}

/// The successors of `node` into `out` (emptied first): one step on each steering,
/// forward and backward, whose every sampled pose the car's rectangle clears; with the
/// cost of the step.
fn successors(field: &Field, node: &Node, s: &Settings, out: &mut Vec<Step>) {
    let n = (s.step / SAMPLE).ceil().max(1.0) as usize;
    let root = node.parent == usize::MAX;
    let turn = node.pose[2].sin_cos();
    out.clear();
    for forward in [true, false] {
        for fraction in STEERS {
            let curvature = fraction / s.turn_radius;
            let d = if forward { s.step } else { -s.step };
            let Some(end) = step_clear(field, node.pose, turn, d, forward, curvature, n) else {
                continue;
            };
            let mut cost = s.step * if forward { 1.0 } else { s.reverse_weight };
            cost += s.steer_weight * fraction.abs() * s.step;
            if !root {
                cost += s.steer_change_cost * (curvature - node.curvature).abs() * s.turn_radius;
                if forward != node.forward {
                    cost += s.cusp_cost;
                }
            }
            out.push((end, forward, curvature, cost));
        }
    }
}

/// Where a step of `d` metres on `curvature` from `from` (its heading's sine and
/// cosine `turn`) ends, if the rectangle clears its `n` samples (and, not `forward`,
/// they lie in seen space); the last sample is the end when it is `d` along.
fn step_clear(
    field: &Field,
    from: [f64; 3],
    turn: (f64, f64),
    d: f64,
    forward: bool,
    curvature: f64,
    n: usize,
) -> Option<[f64; 3]> {
    let mut end = None;
    for k in 1..=n {
        let along = d * k as f64 / n as f64;
        let (p, at) = turned_arc(from, turn, along, curvature);
        if !(field.clear_turned(p, at) && (forward || field.seen_turned(p, at))) {
            return None;
        }
        if along == d {
            end = Some(p);
        }
    }
    Some(end.unwrap_or_else(|| arc(from, d, curvature)))
}

/// An analytic expansion from `node`: the shortest Reeds-Shepp curves to the goal, the
/// first the rectangle clears at every sample, sampled. Tried more often nearer
/// the goal.
fn analytic(
    field: &Field,
    node: &Node,
    goal: &Goal,
    s: &Settings,
    expansions: usize,
) -> Option<Vec<PathPoint>> {
    let dist = (node.pose[0] - goal.pose[0]).hypot(node.pose[1] - goal.pose[1]);
    let every = 1 + (dist / 3.0) as usize;
    if dist > ANALYTIC_RANGE || !expansions.is_multiple_of(every) {
        return None;
    }
    let mut samples = Vec::new();
    curves::curves(node.pose, goal.pose, s.turn_radius)
        .take(ANALYTIC_CURVES)
        .find(|c| passable_all(field, c.turned_points(node.pose, SAMPLE), &mut samples))
        .map(|_| samples.into_iter().map(|(p, _)| p).collect())
}

/// Whether the car may be at each of `samples` (with its heading's sine and cosine),
/// kept in `out` (emptied first): every [`STRIDE`]th as it is made, then the rest. A
/// curve the rectangle does not clear mostly meets its obstacle over a stretch of
/// samples, wherever along it, and the answer does not depend on the order; most are
/// blocked within their first few strides, and the samples beyond are never made (they
/// were 23 % of a standing car's instructions in `unreachable`).
fn passable_all(
    field: &Field,
    samples: impl Iterator<Item = (PathPoint, (f64, f64))>,
    out: &mut Vec<(PathPoint, (f64, f64))>,
) -> bool {
    let passable = |(p, turn): &(PathPoint, (f64, f64))| field.passable_turned(p, *turn);
    out.clear();
    for (k, sample) in samples.enumerate() {
        if k % STRIDE == 0 && !passable(&sample) {
            return false;
        }
        out.push(sample);
    }
    out.iter()
        .enumerate()
        .all(|(k, sample)| k % STRIDE == 0 || passable(sample))
}

/// The manoeuvre from the start to node `id` (each node one step of `step` metres from
/// its parent), then `tail`, sampled every [`SAMPLE`].
fn finish(nodes: &[Node], id: usize, tail: Vec<PathPoint>, step: f64) -> Manoeuvre {
    let mut chain = Vec::new();
    let mut at = id;
    while at != usize::MAX && nodes[at].parent != usize::MAX {
        chain.push(nodes[at]);
        at = nodes[at].parent;
    }
    chain.reverse();
    let n = (step / SAMPLE).ceil().max(1.0) as usize;
    let mut points = Vec::with_capacity(chain.len() * n + tail.len());
    for node in &chain {
        let parent = nodes[node.parent].pose;
        let signed = if node.forward { step } else { -step };
        points.extend((1..=n).map(|k| {
            let p = arc(parent, signed * k as f64 / n as f64, node.curvature);
            PathPoint {
                x: p[0],
                y: p[1],
                theta: p[2],
                curvature: node.curvature,
                forward: node.forward,
            }
        }));
    }
    points.extend(tail);
    Manoeuvre { points }
}

/// The holonomic heuristic with obstacles: the length of the shortest 8-connected way
/// from each cell to the goal's, through cells whose distance to the nearest obstacle
/// lets the rear axle stand there (Dijkstra from the goal).
struct Holonomic {
    grid: Grid,
    cost: Vec<f64>,
}

impl Holonomic {
    fn new(field: &Field, goal: [f64; 3], res: f64) -> Holonomic {
        let (lo, hi) = field.bounds();
        let grid = Grid::covering(lo, hi, res);
        let f = field.footprint();
        // The rear axle is at least this far from every obstacle, less the field's
        // error over a cell.
        let room = f.rear.min(f.half_width) + f.margin - res;
        let passable: Vec<bool> = (0..grid.len())
            .map(|k| {
                let (x, y) = grid.centre(k);
                field.distance(x, y) >= room
            })
            .collect();
        let (nx, ny) = (grid.nx, grid.ny);
        let mut h = Holonomic {
            grid,
            cost: vec![f64::INFINITY; grid.len()],
        };
        let Some(g) = h.grid.index(goal[0], goal[1]) else {
            return h;
        };
        let mut open = BinaryHeap::new();
        h.cost[g] = 0.0;
        open.push(Reverse((0u64, g)));
        let moves = [
            (1i64, 0i64, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, std::f64::consts::SQRT_2),
            (1, -1, std::f64::consts::SQRT_2),
            (-1, 1, std::f64::consts::SQRT_2),
            (-1, -1, std::f64::consts::SQRT_2),
        ];
        while let Some(Reverse((bits, k))) = open.pop() {
            let c = f64::from_bits(bits);
            if c > h.cost[k] {
                continue;
            }
            let (i, j) = ((k % nx) as i64, (k / nx) as i64);
            for (di, dj, w) in moves {
                let (a, b) = (i + di, j + dj);
                if a < 0 || b < 0 || a >= nx as i64 || b >= ny as i64 {
                    continue;
                }
                let n = b as usize * nx + a as usize;
                let next = c + w * res;
                if passable[n] && next < h.cost[n] {
                    h.cost[n] = next;
                    open.push(Reverse((next.to_bits(), n)));
                }
            }
        }
        h
    }

    /// The way's length from (x, y), less a cell's diagonal (the cell's error).
    fn at(&self, x: f64, y: f64) -> f64 {
        self.grid.index(x, y).map_or(f64::INFINITY, |k| {
            (self.cost[k] - self.grid.res * std::f64::consts::SQRT_2).max(0.0)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::field::Disc;
    use super::*;
    use crate::guidance::footprint::Footprint;

    /// A search turning round in a dead end alley, as a value.
    fn alley(window: f64) -> Result<(Manoeuvre, usize, bool), Failure> {
        let car = Footprint {
            front: 2.025,
            rear: 0.375,
            half_width: 0.6,
            margin: 0.15,
        };
        let discs = (0..60)
            .flat_map(|k| {
                let x = -6.0 + 0.2 * f64::from(k);
                [2.8, -2.8].map(|y| Disc { x, y, r: 0.2 })
            })
            .chain((0..30).map(|k| Disc {
                x: 6.0,
                y: -2.8 + 0.2 * f64::from(k),
                r: 0.2,
            }))
            .collect();
        let field = Field::new([-window; 2], [window; 2], 0.1, discs, car);
        let goal = Goal {
            pose: [-3.0, 0.0, std::f64::consts::PI],
            tol_xy: 0.3,
            tol_theta: 0.2,
        };
        search(&field, [0.0, 0.0, 0.0], &goal, &Settings::default())
            .map(|f| (f.manoeuvre, f.expansions, f.complete))
    }

    #[test]
    fn a_search_gives_the_kept_table_back_all_zeros() {
        let first = alley(12.0);
        assert!(first.as_ref().is_ok_and(|f| f.2), "{first:?}");
        let table = TABLE.take();
        assert!(!table.is_empty() && table.iter().all(|&n| n == 0));
        TABLE.set(table);
        // The same search after one in a larger window (the table longer).
        assert!(alley(15.0).is_ok());
        assert_eq!(alley(12.0), first);
    }
}
