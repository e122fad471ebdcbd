//! What the controller's own recording (`ugv-controller run --record`) costs its loop,
//! natively: the paper's scenario in SIL, its controller's loop recording into a
//! temporary directory or not, alternately, five times each. Prints the wall time per
//! run, the extra per controller tick, and the recording's size per simulated minute.
//! `cargo bench --workspace --bench controller_record`.

use std::time::Instant;

use ugv_controller::config::FollowerKind;
use ugv_controller::control::COMMAND_PERIOD;
use ugv_controller::record::{MCAP_FILE, RunInfo, Writer};
use ugv_sim::mission::controller_config;
use ugv_sim::scenario::Scenario;
use ugv_sim::sil::{Hook, run_sil_with};

/// One run; its wall time, simulated time and (when recorded) run.mcap's size.
fn run(record: bool) -> anyhow::Result<(f64, f64, u64)> {
    let sc = Scenario::paper()?;
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    let dir = tempfile::tempdir()?;
    let mut writer = match record {
        true => Some(Writer::create(
            Some(dir.path()),
            foxglove::Context::new(),
            RunInfo::field(
                sc.name.clone(),
                sc.sim.epoch.unix_ns(),
                sc.can.interface.clone(),
                sc.gps.sentence_set(),
                sc.gps.baud,
                &cfg,
            )?,
        )?),
        false => None,
    };
    let start = Instant::now();
    let mut failed = None;
    let run = run_sil_with(sc, &cfg, |_, rt| {
        if let Some(w) = writer.take() {
            failed = rt.record_into(w).err();
        }
        Hook::Continue
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    // The recording was closed when the run's controller was dropped, inside (its
    // thread writes what is queued first).
    let wall = start.elapsed().as_secs_f64();
    let size = std::fs::metadata(dir.path().join(MCAP_FILE)).map_or(0, |m| m.len());
    Ok((wall, run.sim.time(), size))
}

fn main() -> anyhow::Result<()> {
    run(false)?;
    let (mut plain, mut recorded) = (Vec::new(), Vec::new());
    let (mut simulated, mut size) = (0.0, 0);
    for _ in 0..5 {
        plain.push(run(false)?.0);
        let (wall, t, bytes) = run(true)?;
        recorded.push(wall);
        (simulated, size) = (t, bytes);
    }
    plain.sort_by(f64::total_cmp);
    recorded.sort_by(f64::total_cmp);
    let (p, r) = (plain[2], recorded[2]);
    let ticks = simulated / COMMAND_PERIOD;
    println!(
        "paper SIL, {simulated:.2} s simulated: median {:.1} ms without the controller's recording, {:.1} ms with it ({:+.1} ms, {:.1} us a controller tick); run.mcap {:.2} MB, {:.1} MB per simulated minute",
        p * 1e3,
        r * 1e3,
        (r - p) * 1e3,
        (r - p) / ticks * 1e6,
        size as f64 / 1e6,
        size as f64 / 1e6 / simulated * 60.0
    );
    Ok(())
}
