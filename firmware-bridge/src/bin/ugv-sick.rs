//! `ugv-sick`: drive a SICK laser scanner (LMS1xx, LMS5xx, TiM) over Ethernet (CoLa-A)
//! and publish its scans on the laser's iceoryx2 service, exactly as the simulator
//! publishes its simulated scans, so the controller cannot tell the difference.
//!
//! ```text
//! ugv-sick --address 192.168.0.1:2111 --service ugv-hil/<run_id>/laser
//! ugv-sick --address 127.0.0.1:2111 --service ugv-hil/bench/laser --range-max 80 --host-stamps
//! ```
//!
//! It logs in as authorized client, reads the device identity, asks for streamed
//! scans (`sEN LMDscandata 1`) and publishes each as a `LaserFrame` (conventions in
//! `firmware_bridge::cola`). A scanner takes one controlling client at a time on the
//! simulator's emulation (its own driver, when it runs one): a second `ugv-sick` there
//! reads with `--no-login`. Every `--report-interval` seconds it logs scans/s, lost
//! scans and bad telegrams. When the connection drops it reconnects once per second
//! (or exits with status 1 with `--no-reconnect`). Ctrl-C or SIGTERM end it with
//! status 0. Errors name the scanner's address or the service.

use std::process::ExitCode;
use std::sync::mpsc::channel;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Parser;
use firmware_bridge::cli::{number_f32, seconds};
use firmware_bridge::cola::driver::{DriverConfig, DriverEvent, DriverStats, drive, retry};
use firmware_bridge::cola::{ClientConfig, ColaClient, DecodeOptions};
use firmware_bridge::laser::LaserPublisher;

/// Publish a SICK scanner's scans (CoLa-A over TCP) on an iceoryx2 laser service.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// The scanner, `host:port` (SICK's CoLa-A port is 2111).
    #[arg(long, value_name = "HOST:PORT")]
    address: String,
    /// The iceoryx2 laser service, `ugv-hil/<run_id>/laser`.
    #[arg(long)]
    service: String,
    /// The frames' range_min, metres (the scanner does not send it), 0 to 1000.
    #[arg(long, value_name = "M", default_value_t = 0.5, value_parser = number_f32(0.0, 1000.0, "m"))]
    range_min: f32,
    /// The frames' range_max, metres (LMS111: 20, LMS511: 80), 0 to 1000.
    #[arg(long, value_name = "M", default_value_t = 20.0, value_parser = number_f32(0.0, 1000.0, "m"))]
    range_max: f32,
    /// Do not log in: read only (scans, DeviceIdent). A scanner serves any number of
    /// reading clients, and one that logs in.
    #[arg(long)]
    no_login: bool,
    /// Send LMCstartmeas and Run before streaming (a scanner left stopped; needs the
    /// login).
    #[arg(long, conflicts_with = "no_login")]
    start_measurement: bool,
    /// Stamp scans with this host's clock even when the scanner sends a time stamp.
    #[arg(long)]
    host_stamps: bool,
    /// Seconds allowed for connecting and for each answer, 0.001 to 3600.
    #[arg(long, value_name = "SECONDS", default_value = "5", value_parser = seconds(0.001, 3600.0))]
    connect_timeout: Duration,
    /// Warn when no scan arrives for this many seconds, 0.001 to 3600.
    #[arg(long, value_name = "SECONDS", default_value = "2", value_parser = seconds(0.001, 3600.0))]
    frame_timeout: Duration,
    /// Seconds between the scans/s log lines, 0.001 to 86400.
    #[arg(long, value_name = "SECONDS", default_value = "5", value_parser = seconds(0.001, 86_400.0))]
    report_interval: Duration,
    /// Exit with status 1 when the connection fails or drops, instead of retrying.
    #[arg(long)]
    no_reconnect: bool,
    /// Exit after publishing this many scans (at least 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    count: Option<u64>,
}

fn run(args: &Args) -> anyhow::Result<()> {
    if !(args.range_min.is_finite()
        && args.range_max.is_finite()
        && args.range_min >= 0.0
        && args.range_min < args.range_max)
    {
        bail!(
            "--range-min {} --range-max {}: need 0 <= range-min < range-max, in metres",
            args.range_min,
            args.range_max
        );
    }
    let timeout = args.connect_timeout;
    let config = ClientConfig {
        connect_timeout: timeout,
        reply_timeout: timeout,
        login: !args.no_login,
        start_measurement: args.start_measurement,
        decode: DecodeOptions {
            range_min: args.range_min,
            range_max: args.range_max,
            ..DecodeOptions::default()
        },
        host_stamps: args.host_stamps,
        ..ClientConfig::default()
    };

    let (stop_tx, stop) = channel();
    ctrlc::set_handler(move || {
        let _ = stop_tx.send(());
    })
    .context("installing the Ctrl-C handler")?;

    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let publisher = LaserPublisher::new(&args.service)
        .with_context(|| format!("opening the laser service {}", args.service))?;

    let scanner = || format!("scanner at {}", args.address);
    let connect = || ColaClient::connect(&args.address, config.clone());
    let mut client = if args.no_reconnect {
        connect().with_context(scanner)?
    } else {
        let mut connected = None;
        let attempt = || connect().map(|c| connected = Some(c));
        if !retry(&stop, attempt, |e| {
            tracing::warn!("{}: {e}; retrying in 1 s", scanner())
        }) {
            return Ok(());
        }
        connected.with_context(|| format!("{}: not connected", scanner()))?
    };
    tracing::info!(
        address = %args.address,
        device = %client.device_ident().name,
        version = %client.device_ident().version,
        service = %args.service,
        "publishing scans"
    );

    let driver = DriverConfig {
        poll: Duration::from_millis(250).min(args.frame_timeout),
        reconnect: !args.no_reconnect,
        frame_timeout: args.frame_timeout,
        count: args.count,
    };
    // Published scans at the start of the report window.
    let mut window = (Instant::now(), 0u64);
    let watch = |event: &DriverEvent<'_>, stats: &DriverStats| {
        match event {
            DriverEvent::PublishFailed { sequence, error } => {
                let n = stats.publish_errors;
                if n <= 10 || n.is_power_of_two() {
                    tracing::warn!(
                        "scan {sequence} not published on {} ({n} so far): {error}",
                        args.service
                    );
                }
            }
            DriverEvent::Silent { since } => {
                tracing::warn!(
                    "no scan from {} for {:.1} s",
                    args.address,
                    since.as_secs_f64()
                );
            }
            DriverEvent::Bad(e) => {
                // One bad telegram: say why; the loop goes on with the next.
                let n = stats.bad;
                if n <= 10 || n.is_power_of_two() {
                    tracing::warn!("{}: bad scan ({n} so far): {e}", scanner());
                }
            }
            DriverEvent::Lost(e) => tracing::warn!("{e}; reconnecting"),
            DriverEvent::ReconnectFailed(e) => {
                tracing::warn!("{}: {e}; retrying in 1 s", scanner());
            }
            DriverEvent::Published { .. } | DriverEvent::Idle | DriverEvent::Reconnected => {}
        }
        let elapsed = window.0.elapsed();
        if elapsed >= args.report_interval {
            tracing::info!(
                "{:.1} scans/s, {} published, {} lost by the scanner or network, {} bad telegrams, {} publish errors",
                (stats.published - window.1) as f64 / elapsed.as_secs_f64(),
                stats.published,
                stats.client.lost_scans,
                stats.bad,
                stats.publish_errors,
            );
            window = (Instant::now(), stats.published);
        }
    };
    let stats = drive(&mut client, &publisher, &driver, &stop, watch).with_context(scanner)?;
    tracing::info!(
        published = stats.published,
        lost = stats.client.lost_scans,
        bad = stats.bad,
        "stopped"
    );
    Ok(())
}

fn main() -> ExitCode {
    let args = Args::parse();
    // Its scans/s report lines are info; RUST_LOG=warn for only the trouble.
    firmware_bridge::cli::init_logging("info");
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ugv-sick: {e:#}");
            ExitCode::FAILURE
        }
    }
}
