//! The manoeuvre planner: where the paper's polynomial family has no path (a gate right
//! after a corner, a gap in a row of parked carts, a hairpin, turning round, backing
//! out of a nose-in spot), a Hybrid A* search over the local map finds a path of arcs
//! forward and backward, with cusps, that the car's rectangle clears ([`hybrid`],
//! [`field`]); it is smoothed ([`path`]) and followed segment by segment ([`follow`]),
//! and the polynomial takes over again once the way ahead is open
//! (`super::Navigator`).
//!
//! The search runs in the replanning (`super::solve`): on the planning thread in the
//! binary, so the command loop keeps its rhythm; inline in SIL, bounded by a number of
//! expansions, so a run is deterministic for a seed.

pub mod curves;
pub mod field;
pub mod follow;
pub mod hybrid;
pub mod path;

pub use field::{Disc, Field};
pub use follow::Following;
pub use hybrid::{Failure, Goal, Settings};
pub use path::{Manoeuvre, PathPoint};

use super::footprint::Footprint;
use super::frame::wrap;
use crate::perception::{SeenSpace, SeenWindow};
use crate::planner::Obstacle;

/// An obstacle within the margin of the car where it stands is shrunk to this much
/// clear of it, metres.
const START_SLACK: f64 = 0.05;
/// Cell of the distance field, metres.
const FIELD_RES: f64 = 0.1;
/// The field's window reaches this far round the start and the goals, metres.
const WINDOW_MARGIN: f64 = 10.0;
/// Moving obstacles are planned as swept along their velocity over this long, seconds,
/// every this many metres.
const SWEEP_S: f64 = 3.0;
const SWEEP_STEP: f64 = 0.3;
/// A manoeuvre is searched anew once the car is this far off the one it follows
/// (among its first this many samples), metres.
const OFF_PATH: f64 = 0.3;
const OFF_PATH_LOOK: usize = 20;
/// ... or, standing, once its heading where it goes on is this far off the car's,
/// radians: a segment ended off its planned end (a steering bias, a slow speed loop)
/// leaves the next one beginning askew, tracked only at the lock on a tight arc (0.17
/// rad askew at a lock arc's start passed a hedge's end 0.1 m nearer than planned); a
/// search from the stand plans from the pose the car has.
const STAND_HEADING: f64 = 0.1;
/// Goals searched towards at most, the first the field clears (a goal clear of the
/// obstacles in view may stand on a remembered return).
const GOALS_SEARCHED: usize = 3;
/// The manoeuvre being followed is kept while it clears every obstacle by the margin
/// less this, metres.
pub const HOLD_SLACK: f64 = 0.1;
/// ... along this many samples of it ahead of the car (3 m, well beyond the stopping
/// distance at a manoeuvre's pace): a place farther on that the laser now shows a few
/// centimetres too tight, seen from afar, is driven towards and looked at again from
/// nearer, not given up at once for a search from here.
const HOLD_AHEAD: usize = 30;
/// A search that runs out of poses within this many expansions found the car hemmed
/// in at the margin: every step from where it stands, forward or back, comes nearer
/// an obstacle than the margin (outlines grow as the car comes near them).
pub const HEMMED: usize = 50;
/// An escape is cut this many samples (0.4 m) into the first stretch, after the part
/// that needed the narrower margin, that clears every obstacle by the full margin: from
/// there the searches keep the margin again.
const ESCAPE_CLEAR: usize = 4;

/// One manoeuvre search: from the car's pose to the first of `goals` it reaches, among
/// the obstacles, the car's rectangle grown by the manoeuvre margin.
#[derive(Clone, Debug)]
pub struct ManoeuvreRequest {
    pub start: [f64; 3],
    /// Goals to try, in order ([`GOALS_SEARCHED`] of them at most).
    pub goals: Vec<Goal>,
    pub obstacles: Vec<Obstacle>,
    pub footprint: Footprint,
    pub settings: Settings,
    /// The manoeuvre being followed, from the pose it has reached: kept while the
    /// rectangle clears all of it.
    pub following: Option<Manoeuvre>,
    /// The car stands (at a cusp, or before moving off): the manoeuvre followed must
    /// go on in the car's heading (within [`STAND_HEADING`]).
    pub standing: bool,
    /// The space seen free over the field's window: backward motion only into it (None:
    /// everywhere, as in tests of the search alone).
    pub seen: Option<SeenWindow>,
    /// The cells beams returned from in the window ([`SeenSpace::hits_in`]): obstacles
    /// the laser saw that may be out of its view now, each a disc over its cell.
    pub remembered: Vec<[f64; 2]>,
    /// The manoeuvre being followed is partial and the car has driven on along it
    /// ([`Following::look_again`]): search again while it holds, and take a complete
    /// manoeuvre if one is found now.
    pub look_again: bool,
    /// The manoeuvre being followed is an escape planned with this narrower margin: it
    /// holds while it clears the obstacles by that ([`ManoeuvreRequest::escape`]).
    pub following_margin: Option<f64>,
    /// The least margin an escape keeps, metres: it tries twice this, then this.
    pub escape_margin: f64,
}

/// The obstacles as discs: static ones as they are, moving ones swept along their
/// velocity over [`SWEEP_S`] (never back into one's way, nor in front of it).
pub fn discs(obstacles: &[Obstacle]) -> Vec<Disc> {
    let mut out = Vec::with_capacity(obstacles.len());
    for o in obstacles {
        let speed = o.vx.hypot(o.vy);
        let n = (speed * SWEEP_S / SWEEP_STEP).ceil() as usize;
        out.extend((0..=n).map(|k| {
            let t = if n == 0 {
                0.0
            } else {
                SWEEP_S * k as f64 / n as f64
            };
            Disc {
                x: o.x + o.vx * t,
                y: o.y + o.vy * t,
                r: o.radius,
            }
        }));
    }
    out
}

impl ManoeuvreRequest {
    /// The request with the seen space over its window.
    pub fn with_seen(self, seen: &SeenSpace) -> ManoeuvreRequest {
        let (lo, hi) = self.window();
        ManoeuvreRequest {
            seen: Some(seen.window(lo, hi)),
            remembered: seen.hits_in(lo, hi),
            ..self
        }
    }

    /// The distance field round the start and the goals (and the manoeuvre being
    /// followed).
    pub fn field(&self) -> Field {
        self.field_at(Some(self.start))
    }

    /// The distance field with every obstacle the car standing at `shrink` is within
    /// the margin of planned as just clear of it (as the passages' check does), so a
    /// manoeuvre may lead away from it: its radius shrinks, below zero if need be (a
    /// disc's radius plus the margin is the clearance the rectangle keeps from its
    /// centre). None: every obstacle as it is.
    fn field_at(&self, shrink: Option<[f64; 3]>) -> Field {
        let (lo, hi) = self.window();
        let discs = self.discs(shrink, &self.footprint);
        Field::new(lo, hi, FIELD_RES, discs, self.footprint).with_seen(self.seen.clone())
    }

    /// The obstacles and the remembered returns as discs, shrunk for the rectangle `f`
    /// standing at `shrink` ([`ManoeuvreRequest::field_at`]).
    fn discs(&self, shrink: Option<[f64; 3]>, f: &Footprint) -> Vec<Disc> {
        let cell = crate::perception::SEEN_CELL * std::f64::consts::FRAC_1_SQRT_2;
        let remembered = self.remembered.iter().map(|h| Disc {
            x: h[0],
            y: h[1],
            r: cell,
        });
        discs(&self.obstacles)
            .into_iter()
            .chain(remembered)
            .map(|d| match shrink {
                Some([x, y, theta]) => Disc {
                    r: d.r.min(
                        (f.distance(x, y, theta, d.x, d.y) - f.margin - START_SLACK).max(-f.margin),
                    ),
                    ..d
                },
                None => d,
            })
            .collect()
    }

    /// The window the field covers: round the start and the goals (and the manoeuvre
    /// being followed).
    fn window(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [self.start[0], self.start[1]];
        let mut hi = lo;
        let poses = self.goals.iter().map(|g| g.pose).chain(
            self.following
                .iter()
                .flat_map(|m| m.points.iter().map(PathPoint::pose)),
        );
        for p in poses {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let lo = [lo[0] - WINDOW_MARGIN, lo[1] - WINDOW_MARGIN];
        let hi = [hi[0] + WINDOW_MARGIN, hi[1] + WINDOW_MARGIN];
        (lo, hi)
    }

    /// Whether the manoeuvre being followed still clears every obstacle by the margin
    /// less [`HOLD_SLACK`] (perceived outlines shift from scan to scan; a manoeuvre
    /// dropped for a few centimetres would be searched anew, and the car would shuffle)
    /// over the next [`HOLD_AHEAD`] samples, with the car within [`OFF_PATH`] of it (and,
    /// standing, within [`STAND_HEADING`] of its heading).
    pub fn following_holds(&self) -> bool {
        let Some(m) = &self.following else {
            return false;
        };
        let on = m
            .points
            .iter()
            .take(OFF_PATH_LOOK)
            .any(|p| (p.x - self.start[0]).hypot(p.y - self.start[1]) <= OFF_PATH);
        let askew = self.standing
            && m.points
                .first()
                .is_some_and(|p| wrap(p.theta - self.start[2]).abs() > STAND_HEADING);
        if !(on && !askew || m.points.is_empty()) {
            return false;
        }
        let margin = self.following_margin.unwrap_or(self.footprint.margin);
        let footprint = Footprint {
            margin: (margin - HOLD_SLACK.min(0.4 * margin)).max(0.0),
            ..self.footprint
        };
        // Decided exactly for the few samples looked at: no distances over the window.
        let (lo, hi) = self.window();
        let discs = self.discs(Some(self.start), &footprint);
        let field =
            Field::exact_only(lo, hi, FIELD_RES, discs, footprint).with_seen(self.seen.clone());
        m.points.iter().take(HOLD_AHEAD).all(|p| field.passable(p))
    }

    /// Search towards each goal the field clears in turn ([`GOALS_SEARCHED`] at most),
    /// within one budget of expansions for all: the first complete manoeuvre found, else
    /// the first partial one
    /// ([`hybrid::Found::complete`]), smoothed; with the expansions all the searches
    /// took; or the last goal's failure.
    pub fn plan(&self, field: &Field) -> (Result<Planned, Failure>, usize) {
        let mut expansions = 0;
        let mut partial = None;
        let mut last = Err(Failure::Unreachable);
        let mut searched = 0;
        for goal in &self.goals {
            if searched == GOALS_SEARCHED {
                break;
            }
            if !field.clear(goal.pose) {
                last = Err(Failure::GoalBlocked);
                continue;
            }
            searched += 1;
            let settings = Settings {
                max_expansions: self.settings.max_expansions.saturating_sub(expansions),
                ..self.settings
            };
            if settings.max_expansions == 0 {
                break;
            }
            match hybrid::search(field, self.start, goal, &settings) {
                Ok(found) => {
                    expansions += found.expansions;
                    let planned = Planned {
                        manoeuvre: found.manoeuvre.smoothed(self.start, field),
                        complete: found.complete,
                        escape_margin: None,
                    };
                    if found.complete {
                        return (Ok(planned), expansions);
                    }
                    partial.get_or_insert(planned);
                }
                Err(e) => {
                    if let Failure::Exhausted(n) = e {
                        expansions += n;
                    }
                    last = Err(e);
                }
            }
        }
        (partial.map_or(last, Ok), expansions)
    }

    /// [`ManoeuvreRequest::plan`], and where it finds no way at the margin (the goal
    /// and the car's own pose clear), an escape ([`ManoeuvreRequest::escape`]); where it
    /// finds only a partial manoeuvre that backs off (a cusp or more: the way on is
    /// tight at the margin), a complete escape if there is one, so the car creeps
    /// through the narrow place before it rather than shuffling round it.
    pub fn plan_or_escape(&self, field: &Field) -> (Result<Planned, Failure>, usize) {
        let (found, expansions) = self.plan(field);
        match found {
            Err(e @ (Failure::Exhausted(_) | Failure::Unreachable)) => {
                let (escape, more) = self.escape(false);
                (escape.ok_or(e), expansions + more)
            }
            Ok(partial) if !partial.complete && partial.manoeuvre.cusps() > 0 => {
                let (escape, more) = self.escape(true);
                (Ok(escape.unwrap_or(partial)), expansions + more)
            }
            found => (found, expansions),
        }
    }

    /// Where the margin leaves no way (a gap wide enough for the car but not for its
    /// margin, as outlines seen from near look; a car hemmed in at the margin,
    /// [`HEMMED`], the outlines having grown as it came near), a careful driver creeps
    /// through: the same search with the margin narrowed to twice `escape_margin`,
    /// then (with what that one left of the budget) to it, cut where the rectangle
    /// clears every obstacle by the full margin again ([`ESCAPE_CLEAR`]); driven at a
    /// crawl. Only one that reaches a goal at its margin if `complete_only`. With the
    /// expansions it took.
    pub fn escape(&self, complete_only: bool) -> (Option<Planned>, usize) {
        let full = self.field_at(None);
        let mut expansions = 0;
        for margin in [2.0 * self.escape_margin, self.escape_margin] {
            if margin >= self.footprint.margin {
                continue;
            }
            let narrow = ManoeuvreRequest {
                footprint: Footprint {
                    margin,
                    ..self.footprint
                },
                settings: Settings {
                    max_expansions: self.settings.max_expansions.saturating_sub(expansions),
                    ..self.settings
                },
                ..self.clone()
            };
            if narrow.settings.max_expansions == 0 {
                break;
            }
            let (found, n) = narrow.plan(&narrow.field());
            expansions += n;
            match found {
                Ok(planned) if planned.complete || !complete_only => {
                    return (Some(planned.escaping(margin, &full)), expansions);
                }
                _ => {}
            }
        }
        (None, expansions)
    }
}

/// A manoeuvre found: to a goal (complete), or towards one as far as what is known
/// allows.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    pub manoeuvre: Manoeuvre,
    pub complete: bool,
    /// An escape ([`ManoeuvreRequest::escape`]): the narrower margin it keeps.
    pub escape_margin: Option<f64>,
}

impl Planned {
    /// This manoeuvre as an escape planned with `margin`: cut [`ESCAPE_CLEAR`] samples
    /// into the first stretch that `full` (the field at the full margin) clears after
    /// the first pose it does not.
    fn escaping(self, margin: f64, full: &Field) -> Planned {
        let points = &self.manoeuvre.points;
        let clear = |p: &PathPoint| full.clear(p.pose());
        let out = points.iter().position(|p| !clear(p)).and_then(|tight| {
            (tight..points.len().saturating_sub(ESCAPE_CLEAR))
                .find(|&k| points[k..k + ESCAPE_CLEAR].iter().all(clear))
        });
        let mut manoeuvre = self.manoeuvre;
        if let Some(k) = out {
            manoeuvre.points.truncate(k + ESCAPE_CLEAR);
        }
        Planned {
            manoeuvre,
            complete: self.complete && out.is_none(),
            escape_margin: Some(margin),
        }
    }
}

#[cfg(test)]
mod tests;
