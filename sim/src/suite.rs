//! A scenario suite: every scenario file of a folder run in SIL (or HIL, one run per
//! CAN interface at a time), in parallel, judged by its own success criteria,
//! summarised as Markdown, JSON and JUnit XML (for CI). A sweep ([`crate::sweep`])
//! runs each scenario with several seeds and grid points; a shard runs part of one
//! and records its items (`items.json`), which [`merge`] joins into one summary.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use ugv_controller::config::ControllerConfig;

use crate::mission::controller_config;
use crate::mode::Mode;
use crate::scenario::Scenario;
use crate::sil::{Hook, run_sil_recorded};
use crate::sweep::{Percentiles, Plan, PlanInfo, Shard, wilson95};
use crate::verdict::Verdict;

mod merge;
pub use merge::{MergeError, merge, read_shards};

/// One item's result.
#[derive(Clone, Debug)]
pub struct SuiteEntry {
    /// The item's place in its plan and its id there.
    pub index: usize,
    pub id: String,
    pub file: PathBuf,
    pub name: String,
    /// The grid point's settings (`KEY=VALUE`), empty without `--vary`.
    pub point: Vec<String>,
    pub seed_index: usize,
    pub seed: Option<u64>,
    /// Wall-clock seconds the run took.
    pub wall_s: f64,
    pub verdict: Option<Verdict>,
    /// Why the scenario could not run at all (a bad file, a controller error).
    pub error: Option<String>,
}

impl SuiteEntry {
    pub fn passed(&self) -> bool {
        self.verdict.as_ref().is_some_and(|v| v.passed)
    }
}

/// The scenario files of a folder (`*.toml`), in name order.
pub fn scenario_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    Ok(files)
}

/// Runs one item (its id, its scenario) on worker `slot` (0..jobs) and judges it.
pub type Runner<'a> = dyn Fn(&str, &Scenario, usize) -> Result<Verdict, String> + Sync + 'a;

fn run_one(plan: &Plan, index: usize, slot: usize, runner: &Runner<'_>) -> SuiteEntry {
    let started = Instant::now();
    let item = &plan.items[index];
    let group = &plan.groups[item.group];
    let name = group
        .file
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let result = plan
        .scenario(item)
        .and_then(|sc| runner(&item.id, &sc, slot));
    let (verdict, error) = match result {
        Ok(v) => (Some(v), None),
        Err(e) => (None, Some(e)),
    };
    SuiteEntry {
        index,
        id: item.id.clone(),
        file: group.file.clone(),
        name: verdict.as_ref().map_or(name, |v| v.report.scenario.clone()),
        point: group.point.iter().map(ToString::to_string).collect(),
        seed_index: item.seed_index,
        seed: item.seed,
        wall_s: started.elapsed().as_secs_f64(),
        verdict,
        error,
    }
}

/// An item's id as the name of its folder (and of a HIL run's services and
/// namespace): letters, digits, `-` and `_` kept, anything else `_`.
pub fn item_dir_name(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The SIL runner: the controller library in lockstep, configured by `tune`.
pub fn sil_runner<'a>(
    tune: &'a (dyn Fn(&Scenario) -> ControllerConfig + Sync),
) -> impl Fn(&str, &Scenario, usize) -> Result<Verdict, String> + Sync + 'a {
    sil_runner_recording(tune, None)
}

/// [`sil_runner`], each run recorded (see [`crate::record`]) in a folder of its own
/// under `record` when given, named by [`item_dir_name`].
pub fn sil_runner_recording<'a>(
    tune: &'a (dyn Fn(&Scenario) -> ControllerConfig + Sync),
    record: Option<&'a Path>,
) -> impl Fn(&str, &Scenario, usize) -> Result<Verdict, String> + Sync + 'a {
    move |id, sc, _| {
        let cfg = tune(sc);
        let dir = match record {
            Some(root) => {
                let dir = root.join(item_dir_name(id));
                std::fs::create_dir_all(&dir)
                    .map_err(|e| format!("creating {}: {e}", dir.display()))?;
                Some(dir)
            }
            None => None,
        };
        let run = run_sil_recorded(sc.clone(), &cfg, |_, _| Hook::Continue, dir.as_deref())
            .map_err(|e| e.to_string())?;
        Ok(Verdict::judge(
            Mode::Sil,
            sc,
            run.sim.report(run.outcome),
            Some(&run.trace),
        ))
    }
}

/// Run every file once in SIL on `jobs` threads; `progress` sees each entry as it
/// finishes (with the count done so far). `tune` makes the controller configuration.
pub fn run_suite(
    files: &[PathBuf],
    jobs: usize,
    tune: &(dyn Fn(&Scenario) -> ControllerConfig + Sync),
    progress: &(dyn Fn(usize, &SuiteEntry) + Sync),
) -> Vec<SuiteEntry> {
    let plan = Plan::of_files(files);
    let all: Vec<usize> = (0..plan.items.len()).collect();
    run_items(&plan, &all, jobs, &sil_runner(tune), progress)
}

/// Run the plan's items `indices` with `runner` on `jobs` worker threads (worker `j`
/// passes slot `j`, so a HIL runner can give each worker a CAN interface of its own);
/// the entries come back in the order of `indices`.
pub fn run_items(
    plan: &Plan,
    indices: &[usize],
    jobs: usize,
    runner: &Runner<'_>,
    progress: &(dyn Fn(usize, &SuiteEntry) + Sync),
) -> Vec<SuiteEntry> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<SuiteEntry>>> = Mutex::new(vec![None; indices.len()]);
    std::thread::scope(|scope| {
        for slot in 0..jobs.clamp(1, indices.len().max(1)) {
            let (next, done, results) = (&next, &done, &results);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = indices.get(i) else { break };
                    let entry = run_one(plan, index, slot, runner);
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, &entry);
                    if let Ok(mut r) = results.lock() {
                        r[i] = Some(entry);
                    }
                }
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect()
}

/// The default tuning: the scenario's mission with the given follower.
pub fn default_tune(
    follower: ugv_controller::config::FollowerKind,
) -> impl Fn(&Scenario) -> ControllerConfig + Sync {
    move |sc| controller_config(sc, follower)
}

/// What the summaries show of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// "sil" or "hil".
    pub mode: Mode,
    pub goal_reached: bool,
    /// When the run ended, simulated seconds.
    pub time_s: Option<f64>,
    pub path_m: Option<f64>,
    /// The smallest footprint clearance to any obstacle (none without obstacles).
    pub clearance_m: Option<f64>,
    pub max_steer_deg: Option<f64>,
    pub tracking_rms_m: Option<f64>,
}

/// One item's result as summaries and shard files hold it: no wall-clock time, so
/// the summaries of a sweep are the same however it was split and run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ItemRecord {
    pub index: usize,
    pub id: String,
    /// The scenario file's name in its folder.
    pub file: String,
    pub name: String,
    pub point: Vec<String>,
    pub seed_index: usize,
    pub seed: Option<u64>,
    pub passed: bool,
    /// `passed`, `FAILED: ...` or `ERROR: ...`.
    pub outcome: String,
    pub metrics: Option<Metrics>,
    /// The whole verdict.
    pub verdict: Option<serde_json::Value>,
    pub error: Option<String>,
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn outcome_text(e: &SuiteEntry) -> String {
    match (&e.verdict, &e.error) {
        (Some(v), _) if v.passed => "passed".to_owned(),
        (Some(v), _) => format!("FAILED: {}", v.failures.join("; ")),
        (None, Some(err)) => format!("ERROR: {err}"),
        (None, None) => "ERROR".to_owned(),
    }
}

impl ItemRecord {
    pub fn of(e: &SuiteEntry) -> ItemRecord {
        let metrics = e.verdict.as_ref().map(|v| Metrics {
            mode: v.mode,
            goal_reached: v.goal_reached,
            time_s: finite(v.time()),
            path_m: finite(v.report.path_length),
            clearance_m: v
                .report
                .min_clearance
                .iter()
                .copied()
                .reduce(f64::min)
                .and_then(finite),
            max_steer_deg: finite(v.report.max_steer_deg),
            tracking_rms_m: v
                .controller
                .as_ref()
                .and_then(|c| finite(c.tracking_error_rms)),
        });
        ItemRecord {
            index: e.index,
            id: e.id.clone(),
            file: e.file.file_name().map_or_else(
                || e.file.display().to_string(),
                |f| f.to_string_lossy().into_owned(),
            ),
            name: e.name.clone(),
            point: e.point.clone(),
            seed_index: e.seed_index,
            seed: e.seed,
            passed: e.passed(),
            outcome: outcome_text(e),
            metrics,
            verdict: e
                .verdict
                .as_ref()
                .map(|v| serde_json::to_value(v).unwrap_or_default()),
            error: e.error.clone(),
        }
    }

    /// The scenario's name, then what sets this item apart in a sweep (`@KEY=VALUE`
    /// per setting, `#N` for the seed).
    pub fn label(&self) -> String {
        let stem = self.file.strip_suffix(".toml").unwrap_or(&self.file);
        format!("{}{}", self.name, self.id.strip_prefix(stem).unwrap_or(""))
    }

    fn mode(&self) -> Option<&str> {
        self.metrics.as_ref().map(|m| m.mode.as_str())
    }
}

/// A scenario at one grid point, over its seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupStats {
    pub file: String,
    pub name: String,
    pub point: Vec<String>,
    pub runs: usize,
    pub passed: usize,
    pub success_rate: f64,
    /// The 95 % Wilson score interval of the success rate.
    pub success_wilson95: [f64; 2],
    /// The runs' smallest footprint clearances, metres.
    pub clearance_m: Option<Percentiles>,
    /// The times of the runs that reached the goal, seconds.
    pub time_to_goal_s: Option<Percentiles>,
}

/// A suite's results, in plan order: what summary.md, summary.json and junit.xml say.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub groups: Vec<GroupStats>,
    pub items: Vec<ItemRecord>,
}

impl Summary {
    /// The summary of records (sorted into plan order here).
    pub fn of(mut items: Vec<ItemRecord>) -> Summary {
        items.sort_by_key(|r| r.index);
        let mut keys: Vec<(String, Vec<String>)> = Vec::new();
        let mut members: HashMap<(String, Vec<String>), Vec<&ItemRecord>> = HashMap::new();
        for r in &items {
            let key = (r.file.clone(), r.point.clone());
            let slot = members.entry(key.clone()).or_default();
            if slot.is_empty() {
                keys.push(key);
            }
            slot.push(r);
        }
        let groups = keys
            .iter()
            .map(|key| {
                let rs = &members[key];
                let passed = rs.iter().filter(|r| r.passed).count();
                let metrics = || rs.iter().filter_map(|r| r.metrics.as_ref());
                GroupStats {
                    file: key.0.clone(),
                    name: rs[0].name.clone(),
                    point: key.1.clone(),
                    runs: rs.len(),
                    passed,
                    success_rate: passed as f64 / rs.len() as f64,
                    success_wilson95: wilson95(passed, rs.len()).unwrap_or([0.0, 1.0]),
                    clearance_m: Percentiles::of(metrics().filter_map(|m| m.clearance_m)),
                    time_to_goal_s: Percentiles::of(
                        metrics()
                            .filter(|m| m.goal_reached)
                            .filter_map(|m| m.time_s),
                    ),
                }
            })
            .collect();
        Summary { groups, items }
    }

    /// A sweep: some scenario ran more than once, or at a grid point.
    fn sweep(&self) -> bool {
        self.items
            .iter()
            .any(|r| r.seed_index > 0 || !r.point.is_empty())
    }

    /// The Markdown summary: per scenario and grid point for a sweep, then per item.
    pub fn markdown(&self) -> String {
        let passed = self.items.iter().filter(|r| r.passed).count();
        let mode = self
            .items
            .iter()
            .find_map(|r| r.mode().map(str::to_uppercase))
            .unwrap_or_else(|| "SIL".to_owned());
        let mut out = format!(
            "# Scenario suite ({mode})\n\n{passed} of {} passed.\n\n",
            self.items.len()
        );
        let f =
            |x: Option<f64>, places: usize| x.map_or("-".to_owned(), |v| format!("{v:.places$}"));
        if self.sweep() {
            out.push_str(
                "## Per scenario and grid point\n\nSuccess rate with its 95 % Wilson interval; the smallest footprint clearance of each run, and the time to goal of the runs that reached it, as p5 / p50 / p95.\n\n| scenario | grid point | runs | passed | success rate (95 % CI) | clearance m p5 / p50 / p95 | time to goal s p5 / p50 / p95 (n) |\n|---|---|---|---|---|---|---|\n",
            );
            let pct = |p: &Option<Percentiles>, n: bool| match p {
                Some(p) => format!(
                    "{:.2} / {:.2} / {:.2}{}",
                    p.p5,
                    p.p50,
                    p.p95,
                    if n {
                        format!(" ({})", p.n)
                    } else {
                        String::new()
                    }
                ),
                None => "-".to_owned(),
            };
            for g in &self.groups {
                out.push_str(&format!(
                    "| {} | {} | {} | {} | {:.1} % ({:.1}-{:.1} %) | {} | {} |\n",
                    g.name,
                    if g.point.is_empty() {
                        "-".to_owned()
                    } else {
                        g.point.join(" ")
                    },
                    g.runs,
                    g.passed,
                    100.0 * g.success_rate,
                    100.0 * g.success_wilson95[0],
                    100.0 * g.success_wilson95[1],
                    pct(&g.clearance_m, false),
                    pct(&g.time_to_goal_s, true),
                ));
            }
            out.push_str("\n## Per run\n\n");
        }
        out.push_str("| scenario | result | time s | path m | min clearance m | max steer ° | tracking RMS m |\n|---|---|---|---|---|---|---|\n");
        for r in &self.items {
            let (t, path, clear, steer, rms) = match &r.metrics {
                Some(m) => (
                    f(m.time_s, 1),
                    f(m.path_m, 1),
                    f(m.clearance_m, 2),
                    f(m.max_steer_deg, 1),
                    f(m.tracking_rms_m, 3),
                ),
                None => Default::default(),
            };
            out.push_str(&format!(
                "| {} | {} | {t} | {path} | {clear} | {steer} | {rms} |\n",
                r.label(),
                r.outcome
            ));
        }
        out
    }

    /// summary.json: the groups' statistics and every item's record.
    pub fn json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// JUnit XML: one test case per item; a failed criterion is a failure, a run that
    /// could not happen an error.
    pub fn junit(&self) -> String {
        use quick_junit::{NonSuccessKind, Report, TestCase, TestCaseStatus, TestSuite};
        let mut suite = TestSuite::new("ugv-sim suite");
        for r in &self.items {
            let status = if r.passed {
                TestCaseStatus::success()
            } else {
                let kind = if r.metrics.is_some() {
                    NonSuccessKind::Failure
                } else {
                    NonSuccessKind::Error
                };
                let mut s = TestCaseStatus::non_success(kind);
                s.set_message(r.outcome.as_str());
                s
            };
            let mut case = TestCase::new(r.label(), status);
            case.set_classname(format!("ugv-sim.{}", r.mode().unwrap_or("sil")));
            suite.add_test_case(case);
        }
        let mut report = Report::new("ugv-sim");
        report.add_test_suite(suite);
        report
            .to_string()
            .unwrap_or_else(|e| format!("<!-- junit.xml could not be written: {e} -->\n"))
    }
}

/// A Markdown table of a suite's entries.
pub fn markdown(entries: &[SuiteEntry]) -> String {
    Summary::of(entries.iter().map(ItemRecord::of).collect()).markdown()
}

/// JUnit XML of a suite's entries.
pub fn junit(entries: &[SuiteEntry]) -> String {
    Summary::of(entries.iter().map(ItemRecord::of).collect()).junit()
}

/// A shard's record of its items (`items.json`): the plan it ran part of, which part,
/// and each item's result with its wall-clock time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardFile {
    pub plan: PlanInfo,
    pub shard: Shard,
    pub items: Vec<ShardItem>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardItem {
    pub wall_s: f64,
    pub record: ItemRecord,
}

impl ShardFile {
    pub fn of(plan: PlanInfo, shard: Shard, entries: &[SuiteEntry]) -> ShardFile {
        ShardFile {
            plan,
            shard,
            items: entries
                .iter()
                .map(|e| ShardItem {
                    wall_s: e.wall_s,
                    record: ItemRecord::of(e),
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(index: usize, seed_index: usize, passed: bool, outcome: &str) -> ItemRecord {
        ItemRecord {
            index,
            id: format!("01-paper@x=1#{seed_index}"),
            file: "01-paper.toml".to_owned(),
            name: "paper".to_owned(),
            point: vec!["x=1".to_owned()],
            seed_index,
            seed: Some(seed_index as u64),
            passed,
            outcome: outcome.to_owned(),
            metrics: Some(Metrics {
                mode: Mode::Sil,
                goal_reached: passed,
                time_s: Some(20.0 + index as f64),
                path_m: Some(36.0),
                clearance_m: Some(1.0 + index as f64 / 10.0),
                max_steer_deg: Some(20.0),
                tracking_rms_m: Some(0.01),
            }),
            verdict: None,
            error: None,
        }
    }

    #[test]
    fn junit_carries_a_failure_message_with_control_characters_as_valid_xml() {
        let message =
            "FAILED: goal not reached\u{1b}[31m (3.2 m)\u{1b}[0m\u{0}\u{7}\u{8} & <wall> \"x\"";
        let s = Summary::of(vec![
            record(1, 1, false, message),
            record(0, 0, true, "passed"),
        ]);
        let xml = s.junit();
        let report = quick_junit::Report::deserialize_from_str(&xml)
            .map_err(|e| format!("{e}\n{xml}"))
            .unwrap();
        let cases = &report.test_suites[0].test_cases;
        assert_eq!(cases.len(), 2);
        assert_eq!(cases[0].name.as_str(), "paper@x=1#0", "in plan order");
        match &cases[1].status {
            quick_junit::TestCaseStatus::NonSuccess { kind, message, .. } => {
                assert_eq!(*kind, quick_junit::NonSuccessKind::Failure);
                assert_eq!(
                    message.as_ref().map(|m| m.as_str()),
                    Some("FAILED: goal not reached (3.2 m) & <wall> \"x\"")
                );
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_group_has_its_success_rate_interval_and_percentiles() {
        let items: Vec<ItemRecord> = (0..10)
            .map(|i| record(i, i, i < 8, if i < 8 { "passed" } else { "FAILED: x" }))
            .collect();
        let s = Summary::of(items);
        assert_eq!(s.groups.len(), 1);
        let g = &s.groups[0];
        assert_eq!((g.runs, g.passed), (10, 8));
        assert!((g.success_wilson95[0] - 0.4902).abs() < 1e-4, "{g:?}");
        assert!((g.success_wilson95[1] - 0.9433).abs() < 1e-4, "{g:?}");
        let t = g.time_to_goal_s.unwrap();
        assert_eq!(
            (t.n, t.p50),
            (8, 23.5),
            "only the runs that reached the goal"
        );
        assert_eq!(g.clearance_m.unwrap().n, 10);
        let md = s.markdown();
        assert!(
            md.contains("| paper | x=1 | 10 | 8 | 80.0 % (49.0-94.3 %) |"),
            "{md}"
        );
        let back: Summary = serde_json::from_str(&s.json()).unwrap();
        assert_eq!(back, s, "summary.json reads back as it was");
    }
}
