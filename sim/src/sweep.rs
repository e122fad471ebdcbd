//! Sweeps: every scenario of a suite with several seeds (`--seeds N`) and over a grid
//! of field values (`--vary KEY=SPEC`), as a plan of work items (scenario x grid
//! point x seed) that shards split deterministically (`--shard I/N`).

mod shard;
mod stats;
mod vary;

use std::path::{Path, PathBuf};

use rand::rngs::ChaCha8Rng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

pub use shard::{Shard, assign};
pub use stats::{Percentiles, wilson95};
pub use vary::{MAX_VALUES, Setting, Vary, scenario_with};

use ugv_controller::config::FollowerKind;
use ugv_fields::FieldError;

use crate::mission::checked_controller_config;
use crate::scenario::{Scenario, ScenarioError};

/// Most seeds per scenario and grid point.
pub const MAX_SEEDS: usize = 100_000;

/// Most work items in one plan.
pub const MAX_ITEMS: usize = 1_000_000;

/// Why a sweep cannot be planned.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("--seeds {0}: give 1 to {MAX_SEEDS}")]
    Seeds(usize),
    #[error(
        "the sweep has {0} items (scenarios x grid points x seeds), at most {MAX_ITEMS} are allowed"
    )]
    TooMany(u128),
    /// An override the scenario refuses (a wrong key, a value out of range).
    #[error("--vary {setting}: {error}")]
    Override {
        setting: String,
        error: ScenarioError,
    },
    /// A grid point whose scenario the controller's configuration refuses (what
    /// `ugv-sim check` refuses): every run of it would error.
    #[error("--vary {setting}: {file}: the controller's configuration for it: {error}")]
    Controller {
        setting: String,
        /// The file with the settings.
        file: String,
        error: FieldError,
    },
    /// The same field swept twice: its grid points would repeat.
    #[error("--vary {0} is given twice: sweep each field once, with all its values")]
    RepeatedKey(String),
}

/// What `ugv-sim check` checks of a scenario beyond its own fields: the controller's
/// configuration derived from it (the default follower, as `check` derives it).
pub fn check_controller(scenario: &Scenario) -> Result<(), FieldError> {
    checked_controller_config(scenario, FollowerKind::Optimal, None).map(|_| ())
}

/// The scenario of a grid point: the file's `text` with the `point`'s settings,
/// checked as `ugv-sim check` checks a file (its fields, then the controller's
/// configuration); the error names the grid point and the field.
fn grid_scenario(text: &str, file: &str, point: &[Setting]) -> Result<Scenario, SweepError> {
    let join = |sep: &str| {
        point
            .iter()
            .map(Setting::to_string)
            .collect::<Vec<_>>()
            .join(sep)
    };
    let scenario = scenario_with(text, file, point).map_err(|error| SweepError::Override {
        setting: join(" "),
        error,
    })?;
    check_controller(&scenario).map_err(|error| SweepError::Controller {
        setting: join(" "),
        file: format!("{file} with {}", join(", ")),
        error,
    })?;
    Ok(scenario)
}

/// A scenario file with one grid point's settings applied.
#[derive(Clone, Debug)]
pub struct Group {
    pub file: PathBuf,
    /// The file's name in its folder, as summaries and shard files name it.
    pub file_name: String,
    pub point: Vec<Setting>,
    /// The scenario with the settings, or why the file itself could not be read.
    pub scenario: Result<Scenario, String>,
}

/// One run: a group with one seed.
#[derive(Clone, Debug)]
pub struct Item {
    /// Its place in the plan.
    pub index: usize,
    pub group: usize,
    /// Which of the scenario's seeds (0: its own).
    pub seed_index: usize,
    /// The seed (`None` when the scenario could not be read).
    pub seed: Option<u64>,
    /// `STEM[@KEY=VALUE...][#SEED_INDEX]`: unique in the plan.
    pub id: String,
}

/// Every item of a sweep, in order: files, then grid points, then seeds.
#[derive(Clone, Debug)]
pub struct Plan {
    pub seeds: usize,
    pub vary: Vec<Vary>,
    pub groups: Vec<Group>,
    pub items: Vec<Item>,
}

/// What identifies a plan in shard files, so that only shards of one sweep merge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanInfo {
    pub files: Vec<String>,
    pub seeds: usize,
    pub vary: Vec<String>,
    /// The runs' settings that are not in the files (mode, follower, model).
    pub settings: Vec<String>,
    /// Every item's id, in plan order.
    pub items: Vec<String>,
    /// A digest of each group's scenario as its items run it (files x grid points, in
    /// plan order): a scenario file edited between two shards' runs makes another plan.
    pub scenarios: Vec<String>,
    /// The digest of all the fields above ([`PlanInfo::digest`]): the same in every
    /// shard of one sweep, and what a merge checks each shard's fields against, so a
    /// shard file whose plan was edited by hand is refused. FNV-1a, not a cryptographic
    /// hash: it tells sweeps apart and catches edits, not a forger who recomputes it.
    pub fingerprint: String,
}

impl PlanInfo {
    /// The digest of the plan's fields (all but the fingerprint).
    pub fn digest(&self) -> String {
        let fields = (
            &self.files,
            self.seeds,
            &self.vary,
            &self.settings,
            &self.items,
            &self.scenarios,
        );
        digest(
            serde_json::to_string(&fields)
                .unwrap_or_default()
                .as_bytes(),
        )
    }
}

/// FNV-1a (64 bits) of `bytes`, in hex: stable across builds and platforms.
fn digest(bytes: &[u8]) -> String {
    let hash = bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("{hash:016x}")
}

/// An item's id: `STEM[@KEY=VALUE...][#SEED_INDEX]` (the seed index when the plan has
/// several seeds).
pub fn item_id(stem: &str, point: &[String], seeds: usize, seed_index: usize) -> String {
    let point: String = point.iter().map(|s| format!("@{s}")).collect();
    let suffix = if seeds > 1 {
        format!("#{seed_index}")
    } else {
        String::new()
    };
    format!("{stem}{point}{suffix}")
}

/// `n` seeds of a scenario whose own seed is `base`: `base` first (so one seed runs
/// the suite as written), then the outputs of a ChaCha8 generator keyed by `base`.
pub fn derived_seeds(base: u64, n: usize) -> Vec<u64> {
    let mut rng = ChaCha8Rng::seed_from_u64(base);
    std::iter::once(base)
        .chain(std::iter::repeat_with(|| rng.next_u64()))
        .take(n)
        .collect()
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

impl Plan {
    /// The suite as written: each file once with its own seed.
    pub fn of_files(files: &[PathBuf]) -> Plan {
        let groups = files
            .iter()
            .map(|f| Group {
                file: f.clone(),
                file_name: file_name(f),
                point: Vec::new(),
                scenario: Scenario::load(f).map_err(|e| e.to_string()),
            })
            .collect();
        Plan::with_groups(groups, 1, Vec::new())
    }

    /// Every file at every point of the grid `vary` spans, with `seeds` seeds each. A
    /// file that cannot be read is an item that fails (as in a plain suite); a setting
    /// a readable scenario refuses is an error.
    pub fn new(files: &[PathBuf], seeds: usize, vary: &[Vary]) -> Result<Plan, SweepError> {
        if !(1..=MAX_SEEDS).contains(&seeds) {
            return Err(SweepError::Seeds(seeds));
        }
        let points: u128 = vary.iter().map(|v| v.values.len() as u128).product();
        let total = files.len() as u128 * points * seeds as u128;
        if total > MAX_ITEMS as u128 {
            return Err(SweepError::TooMany(total));
        }
        for (i, v) in vary.iter().enumerate() {
            if vary[..i].iter().any(|w| w.key == v.key) {
                return Err(SweepError::RepeatedKey(v.key.to_string()));
            }
        }
        if vary.is_empty() {
            let mut plan = Plan::of_files(files);
            plan = Plan::with_groups(plan.groups, seeds, Vec::new());
            return Ok(plan);
        }
        // The grid's points, the first --vary outermost.
        let mut grid: Vec<Vec<Setting>> = vec![Vec::new()];
        for v in vary {
            grid = grid
                .iter()
                .flat_map(|p| {
                    v.values.iter().map(move |value| {
                        let mut point = p.clone();
                        point.push(Setting {
                            key: v.key.clone(),
                            value: value.clone(),
                        });
                        point
                    })
                })
                .collect();
        }
        let mut groups = Vec::with_capacity(files.len() * grid.len());
        for f in files {
            let name = f.display().to_string();
            let text = ugv_fields::read_file(f);
            // The file as written must pass `ugv-sim check`; then every grid point must.
            let base = text.as_ref().map_err(ToString::to_string).and_then(|t| {
                let sc = Scenario::from_toml(t, &name).map_err(|e| e.to_string())?;
                check_controller(&sc)
                    .map_err(|e| format!("{name}: the controller's configuration for it: {e}"))
            });
            for point in &grid {
                let scenario = match (&base, &text) {
                    (Ok(()), Ok(t)) => Ok(grid_scenario(t, &name, point)?),
                    (Err(e), _) => Err(e.clone()),
                    (Ok(_), Err(e)) => Err(e.to_string()),
                };
                groups.push(Group {
                    file: f.clone(),
                    file_name: file_name(f),
                    point: point.clone(),
                    scenario,
                });
            }
        }
        Ok(Plan::with_groups(groups, seeds, vary.to_vec()))
    }

    fn with_groups(groups: Vec<Group>, seeds: usize, vary: Vec<Vary>) -> Plan {
        let mut items = Vec::with_capacity(groups.len() * seeds);
        for (g, group) in groups.iter().enumerate() {
            let seeds_of = match &group.scenario {
                Ok(sc) => derived_seeds(sc.sim.seed, seeds)
                    .into_iter()
                    .map(Some)
                    .collect(),
                Err(_) => vec![None; seeds],
            };
            let point: Vec<String> = group.point.iter().map(Setting::to_string).collect();
            for (k, seed) in seeds_of.into_iter().enumerate() {
                items.push(Item {
                    index: items.len(),
                    group: g,
                    seed_index: k,
                    seed,
                    id: item_id(&stem(&group.file), &point, seeds, k),
                });
            }
        }
        Plan {
            seeds,
            vary,
            groups,
            items,
        }
    }

    /// The scenario an item runs: its group's, with its seed.
    pub fn scenario(&self, item: &Item) -> Result<Scenario, String> {
        let mut sc = self.groups[item.group].scenario.clone()?;
        if let Some(seed) = item.seed {
            sc.sim.seed = seed;
        }
        Ok(sc)
    }

    /// What an item is expected to cost: its scenario's time limit (simulated seconds,
    /// which bounds the run), 1 for a file that cannot be read (it fails at once).
    pub fn cost(&self, item: &Item) -> f64 {
        self.groups[item.group]
            .scenario
            .as_ref()
            .map_or(1.0, |sc| sc.sim.time_limit_s)
    }

    /// The indices of the items shard `shard` runs, in plan order.
    pub fn shard_items(&self, shard: Shard) -> Vec<usize> {
        let costs: Vec<f64> = self.items.iter().map(|i| self.cost(i)).collect();
        assign(&costs, shard.count)
            .into_iter()
            .enumerate()
            .filter(|(_, s)| *s == shard.index)
            .map(|(i, _)| i)
            .collect()
    }

    /// The plan as shard files record it; `settings` are the runs' other settings.
    pub fn info(&self, settings: Vec<String>) -> PlanInfo {
        let mut files: Vec<String> = self.groups.iter().map(|g| g.file_name.clone()).collect();
        files.dedup();
        let scenarios = self
            .groups
            .iter()
            .map(|g| match &g.scenario {
                Ok(sc) => serde_json::to_string(sc).unwrap_or_else(|e| e.to_string()),
                Err(e) => format!("error: {e}"),
            })
            .map(|text| digest(text.as_bytes()))
            .collect();
        let mut info = PlanInfo {
            files,
            seeds: self.seeds,
            vary: self.vary.iter().map(|v| v.spec.clone()).collect(),
            settings,
            items: self.items.iter().map(|i| i.id.clone()).collect(),
            scenarios,
            fingerprint: String::new(),
        };
        info.fingerprint = info.digest();
        info
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn suite() -> Vec<PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite");
        crate::suite::scenario_files(&dir).unwrap()
    }

    #[test]
    fn the_first_seed_is_the_scenarios_own_and_the_rest_are_stable_and_distinct() {
        let s = derived_seeds(7, 50);
        assert_eq!(s[0], 7);
        assert_eq!(s, derived_seeds(7, 50));
        assert_eq!(derived_seeds(7, 3), s[..3]);
        let mut d = s.clone();
        d.sort_unstable();
        d.dedup();
        assert_eq!(d.len(), 50);
        assert_ne!(derived_seeds(8, 2)[1], s[1]);
    }

    #[test]
    fn a_plan_crosses_files_grid_points_and_seeds_in_order() {
        let files = &suite()[..2];
        let vary: Vec<Vary> = [
            "steering.dead_time_s=0.02,0.1",
            "throttle.dead_time_s=0:0.1:0.05",
        ]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
        let plan = Plan::new(files, 3, &vary).unwrap();
        assert_eq!(plan.items.len(), 2 * 2 * 3 * 3);
        assert_eq!(plan.groups.len(), 12);
        assert_eq!(
            plan.items[0].id,
            "01-paper@steering.dead_time_s=0.02@throttle.dead_time_s=0.0#0"
        );
        assert_eq!(
            plan.items[4].id,
            "01-paper@steering.dead_time_s=0.02@throttle.dead_time_s=0.05#1"
        );
        let sc = plan.scenario(&plan.items[4]).unwrap();
        assert_eq!(
            (sc.steering.dead_time_s, sc.throttle.dead_time_s),
            (0.02, 0.05)
        );
        assert_eq!(sc.sim.seed, derived_seeds(1, 2)[1]);
        let mut ids: Vec<&str> = plan.items.iter().map(|i| i.id.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), plan.items.len(), "ids are unique");
    }

    #[test]
    fn one_seed_and_no_grid_is_the_suite_as_written() {
        let files = suite();
        let plan = Plan::new(&files, 1, &[]).unwrap();
        for (item, f) in plan.items.iter().zip(&files) {
            assert_eq!(plan.scenario(item).unwrap(), Scenario::load(f).unwrap());
            assert_eq!(item.id, stem(f));
        }
        // The override path reads a file exactly as the loader does.
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            assert_eq!(
                scenario_with(&text, "f", &[]).unwrap(),
                Scenario::load(f).unwrap()
            );
        }
    }

    #[test]
    fn a_grid_point_the_controller_refuses_is_an_error_naming_it_and_the_field() {
        let files = &suite()[..1];
        let vary = vec!["vehicle.max_speed=3,0.5".parse::<Vary>().unwrap()];
        let e = Plan::new(files, 1, &vary).unwrap_err().to_string();
        assert!(e.starts_with("--vary vehicle.max_speed=0.5: "), "{e}");
        assert!(
            e.ends_with(
                "01-paper.toml with vehicle.max_speed=0.5: the controller's configuration \
                 for it: planner.passage_speed: 1 exceeds vehicle.max_speed 0.5"
            ),
            "{e}"
        );
    }

    #[test]
    fn a_field_swept_twice_is_an_error() {
        let vary: Vec<Vary> = ["steering.dead_time_s=0.02", "steering.dead_time_s=0.1"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let e = Plan::new(&suite()[..1], 1, &vary).unwrap_err().to_string();
        assert_eq!(
            e,
            "--vary steering.dead_time_s is given twice: sweep each field once, with all its values"
        );
    }

    #[test]
    fn a_setting_a_scenario_refuses_is_an_error_naming_it() {
        let files = &suite()[..1];
        let vary = vec!["steering.dead_time_s=0.1,7".parse::<Vary>().unwrap()];
        let e = Plan::new(files, 1, &vary).unwrap_err().to_string();
        assert!(e.starts_with("--vary steering.dead_time_s=7: "), "{e}");
        assert!(
            e.contains("01-paper.toml with steering.dead_time_s=7"),
            "{e}"
        );
        assert!(e.contains("must be within"), "{e}");
        assert!(
            Plan::new(files, 0, &[])
                .unwrap_err()
                .to_string()
                .contains("--seeds 0")
        );
        let huge = vec![
            "x=0:9999:1".parse::<Vary>().unwrap(),
            "y=0:9999:1".parse::<Vary>().unwrap(),
        ];
        assert!(matches!(
            Plan::new(files, 100, &huge),
            Err(SweepError::TooMany(_))
        ));
    }
}
