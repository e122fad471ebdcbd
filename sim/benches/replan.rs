//! Planning time per replanning across the suite, natively: every scenario of
//! sim/scenarios/suite runs in SIL, and at each tick where the controller replans,
//! the same request (the navigator's, from the same pose and obstacles) is built and
//! solved once more under a clock. Prints p50 and p99 per scenario and over all
//! replannings. `cargo bench -p ugv-sim --bench replan`.

use std::path::Path;
use std::time::Instant;

use ugv_controller::config::FollowerKind;
use ugv_controller::core::Mode;
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

fn main() -> anyhow::Result<()> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite");
    let mut files: Vec<_> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    let mut all = Vec::new();
    println!("| scenario | replans | p50 ms | p99 ms |");
    println!("|---|---|---|---|");
    for file in files {
        let scenario = Scenario::load(&file)?;
        let name = scenario.name.clone();
        let cfg = checked_controller_config(&scenario, FollowerKind::Optimal, None)?;
        let mut times = Vec::new();
        run_sil_with(scenario, &cfg, |now, rt| {
            let ctl = rt.controller();
            if *ctl.mode() == Mode::Auto
                && let Some(pose) = ctl.pose(now)
                && ctl.nav.replan_due(now, &pose)
            {
                let req = ctl.nav.request(now, &pose, ctl.obstacles());
                let start = Instant::now();
                let outcome = solve(&req);
                times.push(start.elapsed().as_secs_f64() * 1e3);
                std::hint::black_box(outcome);
            }
            Hook::Continue
        })?;
        times.sort_by(f64::total_cmp);
        println!(
            "| {name} | {} | {:.3} | {:.3} |",
            times.len(),
            percentile(&times, 0.5),
            percentile(&times, 0.99)
        );
        all.extend(times);
    }
    all.sort_by(f64::total_cmp);
    println!(
        "| all | {} | {:.3} | {:.3} |",
        all.len(),
        percentile(&all, 0.5),
        percentile(&all, 0.99)
    );
    Ok(())
}
