//! A scenario suite: every scenario file of a folder run in SIL (or HIL, one run per
//! CAN interface at a time), in parallel, judged by its own success criteria,
//! summarised as Markdown, JSON and JUnit XML (for CI).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde::Serialize;
use ugv_controller::config::ControllerConfig;

use crate::mission::controller_config;
use crate::scenario::Scenario;
use crate::sil::run_sil;
use crate::verdict::Verdict;

/// One scenario's result.
#[derive(Clone, Debug, Serialize)]
pub struct SuiteEntry {
    pub file: PathBuf,
    pub name: String,
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

/// Runs one scenario on worker `slot` (0..jobs) and judges it.
pub type Runner<'a> = dyn Fn(&Path, &Scenario, usize) -> Result<Verdict, String> + Sync + 'a;

fn run_one(file: &Path, slot: usize, runner: &Runner<'_>) -> SuiteEntry {
    let started = Instant::now();
    let name = file
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let result = Scenario::load(file)
        .map_err(|e| e.to_string())
        .and_then(|sc| runner(file, &sc, slot));
    let (verdict, error) = match result {
        Ok(v) => (Some(v), None),
        Err(e) => (None, Some(e)),
    };
    SuiteEntry {
        file: file.to_path_buf(),
        name: verdict.as_ref().map_or(name, |v| v.report.scenario.clone()),
        wall_s: started.elapsed().as_secs_f64(),
        verdict,
        error,
    }
}

/// The SIL runner: the controller library in lockstep, configured by `tune`.
pub fn sil_runner<'a>(
    tune: &'a (dyn Fn(&Scenario) -> ControllerConfig + Sync),
) -> impl Fn(&Path, &Scenario, usize) -> Result<Verdict, String> + Sync + 'a {
    move |_, sc, _| {
        let cfg = tune(sc);
        let run = run_sil(sc.clone(), &cfg).map_err(|e| e.to_string())?;
        Ok(Verdict::judge(
            "sil",
            sc,
            run.sim.report(run.outcome),
            Some(&run.trace),
        ))
    }
}

/// Run every file in SIL on `jobs` threads; `progress` sees each entry as it finishes
/// (with the count done so far). `tune` makes the controller configuration.
pub fn run_suite(
    files: &[PathBuf],
    jobs: usize,
    tune: &(dyn Fn(&Scenario) -> ControllerConfig + Sync),
    progress: &(dyn Fn(usize, &SuiteEntry) + Sync),
) -> Vec<SuiteEntry> {
    run_suite_with(files, jobs, &sil_runner(tune), progress)
}

/// Run every file with `runner` on `jobs` worker threads (worker `j` passes slot `j`,
/// so a HIL runner can give each worker a CAN interface of its own).
pub fn run_suite_with(
    files: &[PathBuf],
    jobs: usize,
    runner: &Runner<'_>,
    progress: &(dyn Fn(usize, &SuiteEntry) + Sync),
) -> Vec<SuiteEntry> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<SuiteEntry>>> = Mutex::new(vec![None; files.len()]);
    std::thread::scope(|scope| {
        for slot in 0..jobs.clamp(1, files.len().max(1)) {
            let (next, done, results) = (&next, &done, &results);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(file) = files.get(i) else { break };
                    let entry = run_one(file, slot, runner);
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

fn outcome_text(e: &SuiteEntry) -> String {
    match (&e.verdict, &e.error) {
        (Some(v), _) if v.passed => "passed".to_owned(),
        (Some(v), _) => format!("FAILED: {}", v.failures.join("; ")),
        (None, Some(err)) => format!("ERROR: {err}"),
        (None, None) => "ERROR".to_owned(),
    }
}

/// A Markdown table of the suite.
pub fn markdown(entries: &[SuiteEntry]) -> String {
    let passed = entries.iter().filter(|e| e.passed()).count();
    let mode = entries
        .iter()
        .find_map(|e| e.verdict.as_ref().map(|v| v.mode.to_uppercase()))
        .unwrap_or_else(|| "SIL".to_owned());
    let mut out = format!(
        "# Scenario suite ({mode})\n\n{passed} of {} passed.\n\n| scenario | result | time s | path m | min clearance m | max steer ° | tracking RMS m |\n|---|---|---|---|---|---|---|\n",
        entries.len()
    );
    for e in entries {
        let (t, path, clear, steer, rms) = match &e.verdict {
            Some(v) => (
                format!("{:.1}", v.time()),
                format!("{:.1}", v.report.path_length),
                v.report
                    .min_clearance
                    .iter()
                    .cloned()
                    .reduce(f64::min)
                    .map_or("-".to_owned(), |c| format!("{c:.2}")),
                format!("{:.1}", v.report.max_steer_deg),
                v.controller
                    .as_ref()
                    .map_or("-".to_owned(), |c| format!("{:.3}", c.tracking_error_rms)),
            ),
            None => Default::default(),
        };
        out.push_str(&format!(
            "| {} | {} | {t} | {path} | {clear} | {steer} | {rms} |\n",
            e.name,
            outcome_text(e)
        ));
    }
    out
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// JUnit XML: one test case per scenario.
pub fn junit(entries: &[SuiteEntry]) -> String {
    let failures = entries.iter().filter(|e| !e.passed()).count();
    let total: f64 = entries.iter().map(|e| e.wall_s).sum();
    let mut out = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<testsuites>\n<testsuite name=\"ugv-sim suite\" tests=\"{}\" failures=\"{failures}\" errors=\"0\" time=\"{total:.3}\">\n",
        entries.len()
    );
    for e in entries {
        out.push_str(&format!(
            "  <testcase classname=\"ugv-sim.{}\" name=\"{}\" time=\"{:.3}\">",
            e.verdict.as_ref().map_or("sil", |v| v.mode.as_str()),
            xml_escape(&e.name),
            e.wall_s
        ));
        if e.passed() {
            out.push_str("</testcase>\n");
        } else {
            out.push_str(&format!(
                "\n    <failure message=\"{}\"/>\n  </testcase>\n",
                xml_escape(&outcome_text(e))
            ));
        }
    }
    out.push_str("</testsuite>\n</testsuites>\n");
    out
}
