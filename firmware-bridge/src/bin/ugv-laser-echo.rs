//! `ugv-laser-echo`: print the laser frames of an iceoryx2 service, like `ros2 topic echo`.
//!
//! ```text
//! ugv-laser-echo ugv-hil/<run_id>/laser            # header and summary per frame
//! ugv-laser-echo ugv-hil/<run_id>/laser --json     # one JSON object per frame
//! ugv-laser-echo ugv-hil/<run_id>/laser --count 10 --timeout 5
//! ```

use std::io::Write;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Parser;
use firmware_bridge::laser::{LaserFrame, LaserSubscriber};

/// Print the laser frames published on an iceoryx2 service.
#[derive(Debug, Parser)]
// `ugv-sick 0.1.0 (firmware-bridge)`: the binary's own name, its crate's version and name.
#[command(
    name = env!("CARGO_BIN_NAME"),
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("CARGO_PKG_NAME"), ")")
)]
struct Args {
    /// The service, `ugv-hil/<run_id>/laser`.
    service: String,
    /// Print each whole frame as one JSON line (ranges and intensities of the beams in
    /// use; no return and dropouts, inf and NaN on the wire, are `null`).
    #[arg(long)]
    json: bool,
    /// Exit after this many frames (at least 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    count: Option<u64>,
    /// Fail if no frame arrives for this many seconds, 0.001 to 86400 (default: wait
    /// forever).
    #[arg(long, value_name = "SECONDS", value_parser = firmware_bridge::cli::seconds(0.001, 86_400.0))]
    timeout: Option<Duration>,
}

fn stamp_text(stamp_ns: u64) -> String {
    i64::try_from(stamp_ns)
        .map(chrono::DateTime::from_timestamp_nanos)
        .map(|t| t.to_rfc3339_opts(chrono::SecondsFormat::Nanos, true))
        .unwrap_or_else(|_| "out of range".to_owned())
}

fn print_summary(out: &mut impl Write, f: &LaserFrame) -> std::io::Result<()> {
    let s = f.summary();
    writeln!(out, "version: {}", f.version)?;
    writeln!(out, "sequence: {}", f.sequence)?;
    writeln!(out, "stamp: {} ({} ns)", stamp_text(f.stamp_ns), f.stamp_ns)?;
    writeln!(
        out,
        "angle_min: {:.4} rad ({:.2} deg), angle_max: {:.4} rad ({:.2} deg), angle_increment: {:.5} rad ({:.3} deg)",
        f.angle_min,
        f.angle_min.to_degrees(),
        f.angle_max(),
        f.angle_max().to_degrees(),
        f.angle_increment,
        f.angle_increment.to_degrees()
    )?;
    writeln!(
        out,
        "time_increment: {:.3e} s, scan_time: {:.4} s",
        f.time_increment, f.scan_time
    )?;
    writeln!(
        out,
        "range_min: {} m, range_max: {} m",
        f.range_min, f.range_max
    )?;
    writeln!(
        out,
        "beams: {}, valid: {}, no return: {}, dropouts: {}",
        s.beams, s.valid, s.no_return, s.dropouts
    )?;
    match s.nearest {
        Some((angle, range)) => writeln!(
            out,
            "nearest: {range:.3} m at {:.4} rad ({:.2} deg)",
            angle,
            angle.to_degrees()
        )?,
        None => writeln!(out, "nearest: none")?,
    }
    writeln!(out, "---")
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    // iceoryx2 warns on stderr when no config file exists; IOX2_LOG_LEVEL overrides.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let timeout = args.timeout;
    let subscriber = LaserSubscriber::new(&args.service)
        .with_context(|| format!("subscribing to {}", args.service))?;
    let stdout = std::io::stdout();
    let mut printed = 0u64;
    while args.count.is_none_or(|n| printed < n) {
        let wait = timeout.unwrap_or(Duration::from_secs(3600));
        let frame = match subscriber.recv_timeout(wait) {
            Ok(Some(frame)) => frame,
            Ok(None) if timeout.is_some() => {
                bail!("no frame on {} for {wait:?}", args.service)
            }
            Ok(None) => continue,
            // A malformed frame: say why and go on with the next one.
            Err(e @ firmware_bridge::LaserError::Ipc { .. }) => return Err(e.into()),
            Err(e) => {
                eprintln!("ugv-laser-echo: dropped a frame: {e}");
                continue;
            }
        };
        let mut out = stdout.lock();
        if args.json {
            serde_json::to_writer(&mut out, &frame)?;
            writeln!(out)?;
        } else {
            print_summary(&mut out, &frame)?;
        }
        out.flush()?;
        printed += 1;
    }
    Ok(())
}
