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
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Parser;
use firmware_bridge::cli::{number_f32, seconds};
use firmware_bridge::cola::driver::{DriverConfig, DriverEvent, DriverStats, drive, retry};
use firmware_bridge::cola::{ClientConfig, ColaClient, DecodeOptions};
use firmware_bridge::laser::LaserPublisher;

/// Publish a SICK scanner's scans (CoLa-A over TCP) on an iceoryx2 laser service.
#[derive(Debug, Parser)]
// `ugv-sick 0.1.0 (firmware-bridge)`: the binary's own name, its crate's version and name.
#[command(
    name = env!("CARGO_BIN_NAME"),
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("CARGO_PKG_NAME"), ")")
)]
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
    let config = client_config(args)?;
    let (stop_tx, stop) = channel();
    ctrlc::set_handler(move || {
        let _ = stop_tx.send(());
    })
    .context("installing the Ctrl-C handler")?;

    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let publisher = LaserPublisher::new(&args.service)
        .with_context(|| format!("opening the laser service {}", args.service))?;

    let Some(mut client) = connect(args, &config, &stop)? else {
        return Ok(());
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
    let mut watcher = Watcher {
        args,
        window: (Instant::now(), 0),
    };
    let stats = drive(&mut client, &publisher, &driver, &stop, |event, stats| {
        watcher.watch(event, stats)
    })
    .with_context(|| scanner(args))?;
    tracing::info!(
        published = stats.published,
        lost = stats.client.lost_scans,
        bad = stats.bad,
        "stopped"
    );
    Ok(())
}

/// The scanner, as errors and warnings name it.
fn scanner(args: &Args) -> String {
    format!("scanner at {}", args.address)
}

/// The client's configuration from the arguments (the range limits checked).
fn client_config(args: &Args) -> anyhow::Result<ClientConfig> {
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
    Ok(ClientConfig {
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
    })
}

/// Connect to the scanner: once with `--no-reconnect`, otherwise once a second until
/// it answers; `None` when stopped first.
fn connect(
    args: &Args,
    config: &ClientConfig,
    stop: &Receiver<()>,
) -> anyhow::Result<Option<ColaClient>> {
    let connect = || ColaClient::connect(&args.address, config.clone());
    if args.no_reconnect {
        return Ok(Some(connect().with_context(|| scanner(args))?));
    }
    let mut connected = None;
    let attempt = || connect().map(|c| connected = Some(c));
    if !retry(stop, attempt, |e| {
        tracing::warn!("{}: {e}; retrying in 1 s", scanner(args))
    }) {
        return Ok(None);
    }
    Ok(Some(connected.with_context(|| {
        format!("{}: not connected", scanner(args))
    })?))
}

/// What the driver's events make known: warnings (publish errors and bad telegrams
/// the first ten times and at every power of two), and the scans/s line every
/// `--report-interval`.
struct Watcher<'a> {
    args: &'a Args,
    /// Published scans at the start of the report window.
    window: (Instant, u64),
}

impl Watcher<'_> {
    fn watch(&mut self, event: &DriverEvent<'_>, stats: &DriverStats) {
        let args = self.args;
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
                    tracing::warn!("{}: bad scan ({n} so far): {e}", scanner(args));
                }
            }
            DriverEvent::Lost(e) => tracing::warn!("{e}; reconnecting"),
            DriverEvent::ReconnectFailed(e) => {
                tracing::warn!("{}: {e}; retrying in 1 s", scanner(args));
            }
            DriverEvent::Published { .. } | DriverEvent::Idle | DriverEvent::Reconnected => {}
        }
        self.report(stats);
    }

    /// The scans/s line, when the report window is over.
    fn report(&mut self, stats: &DriverStats) {
        let elapsed = self.window.0.elapsed();
        if elapsed >= self.args.report_interval {
            tracing::info!(
                "{:.1} scans/s, {} published, {} lost by the scanner or network, {} bad telegrams, {} publish errors",
                (stats.published - self.window.1) as f64 / elapsed.as_secs_f64(),
                stats.published,
                stats.client.lost_scans,
                stats.bad,
                stats.publish_errors,
            );
            self.window = (Instant::now(), stats.published);
        }
    }
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
