//! Planning time per replanning across the suite, natively: every scenario of
//! sim/scenarios/suite runs in SIL, and at each tick where the controller replans,
//! the same request (the navigator's, from the same pose and obstacles) is built and
//! solved once more under a clock. Prints p50 and p99 per scenario and over all
//! replannings, and the same for the replannings that ran a manoeuvre search; the
//! BARN worlds too with `UGV_BARN_WORLDS=DIR`.
//! `cargo bench -p ugv-sim --bench replan`.

use std::path::Path;
use std::time::Instant;

use ugv_controller::config::FollowerKind;
use ugv_controller::control::Mode;
use ugv_controller::guidance::solve;
use ugv_sim::mission::checked_controller_config;
use ugv_sim::scenario::Scenario;
use ugv_sim::sil::{Hook, run_sil_with};

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

/// Planning times (ms) of one scenario's replannings, and of those among them that ran
/// a manoeuvre search (a new manoeuvre planned, or none found where one was looked
/// for).
fn replan_times(file: &Path) -> anyhow::Result<(String, Vec<f64>, Vec<f64>)> {
    let scenario = Scenario::load(file)?;
    let name = scenario.name.clone();
    let cfg = checked_controller_config(&scenario, FollowerKind::Optimal, None)?;
    let (mut times, mut searches) = (Vec::new(), Vec::new());
    run_sil_with(scenario, &cfg, |now, rt| {
        let ctl = rt.controller();
        if *ctl.mode() == Mode::Auto
            && let Some(pose) = ctl.pose(now)
            && ctl.nav.replan_due(now, &pose)
        {
            let req = ctl.nav.request(now, &pose, ctl.obstacles());
            let start = Instant::now();
            let outcome = solve(&req);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            times.push(ms);
            let searched = matches!(&outcome.result,
                Ok((_, r)) if r.manoeuvre.as_ref().is_some_and(|m| m.expansions > 0));
            if searched {
                searches.push(ms);
            }
            std::hint::black_box(outcome);
        }
        Hook::Continue
    })?;
    times.sort_by(f64::total_cmp);
    searches.sort_by(f64::total_cmp);
    Ok((name, times, searches))
}

/// The scenario files of `dir`, every `every`-th.
fn files(dir: &Path, every: usize) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let mut files: Vec<_> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    Ok(files.into_iter().step_by(every.max(1)).collect())
}

fn row(name: &str, times: &[f64], searches: &[f64]) {
    println!(
        "| {name} | {} | {:.3} | {:.3} | {} | {:.2} | {:.2} |",
        times.len(),
        percentile(times, 0.5),
        percentile(times, 0.99),
        searches.len(),
        percentile(searches, 0.5),
        percentile(searches, 0.99)
    );
}

/// The suite per scenario, then (with `UGV_BARN_WORLDS` set to a
/// folder of BARN worlds, every `UGV_BARN_EVERY`-th, default 5) the BARN worlds in
/// total.
fn main() -> anyhow::Result<()> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut folders = vec![("suite", here.join("scenarios/suite"), 1)];
    if let Ok(barn) = std::env::var("UGV_BARN_WORLDS") {
        let every = std::env::var("UGV_BARN_EVERY")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(5);
        folders.push(("barn", barn.into(), every));
    }
    println!("| scenario | replans | p50 ms | p99 ms | searches | search p50 ms | search p99 ms |");
    println!("|---|---|---|---|---|---|---|");
    let (mut all, mut all_searches) = (Vec::new(), Vec::new());
    for (label, dir, every) in folders {
        let (mut times, mut searches) = (Vec::new(), Vec::new());
        for file in files(&dir, every)? {
            let (name, t, s) = replan_times(&file)?;
            if label != "barn" {
                row(&name, &t, &s);
            }
            times.extend(t);
            searches.extend(s);
        }
        times.sort_by(f64::total_cmp);
        searches.sort_by(f64::total_cmp);
        row(&format!("all of {label}"), &times, &searches);
        all.extend(times);
        all_searches.extend(searches);
    }
    all.sort_by(f64::total_cmp);
    all_searches.sort_by(f64::total_cmp);
    row("all", &all, &all_searches);
    Ok(())
}
