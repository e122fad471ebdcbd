//! `ugv-bridge`: the CAN gateway between the simulator's bus and a physical one, so a
//! physical ECU (or the physical controller) takes a simulated one's place.
//!
//! ```text
//! ugv-bridge --sim vcan0 --physical can0 --node STEERING_ECU
//! ugv-bridge --sim vcan0 --physical can0 --node STEERING_ECU --node THROTTLE_ECU \
//!     --log forwarded.log --stats stats.json
//! ```
//!
//! Prints the routing table and a stats line every `--interval` seconds on stderr;
//! on Ctrl-C or SIGTERM it stops, prints the JSON summary on stdout and writes it to
//! `--stats`. Exit code 0 after a clean stop, 1 on an error (the summary is still
//! printed when the gateway had started), 2 on bad arguments.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Parser;
use firmware_bridge::gateway::{DirectionStats, Gateway, GatewayConfig, GatewayStats};

/// Forward CAN frames between the simulator's bus and a physical one, routed by
/// golf_car.dbc: a frame crosses iff its sender lives on the side it was read from
/// and one of its receivers on the other side. Bytes cross verbatim (E2E is checked
/// by the endpoints).
#[derive(Debug, Parser)]
// `ugv-sick 0.1.0 (firmware-bridge)`: the binary's own name, its crate's version and name.
#[command(
    name = env!("CARGO_BIN_NAME"),
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("CARGO_PKG_NAME"), ")")
)]
struct Args {
    /// The simulator's interface.
    #[arg(long, value_name = "IFACE", default_value = "vcan0")]
    sim: String,
    /// The physical interface (can0, a USB adapter; a vcan in tests).
    #[arg(long, value_name = "IFACE", default_value = "can0")]
    physical: String,
    /// A DBC node that is physical (repeat for several): CONTROLLER, STEERING_ECU or
    /// THROTTLE_ECU.
    #[arg(long = "node", value_name = "NODE", required = true)]
    nodes: Vec<String>,
    /// Log the forwarded frames to this file in `candump -l -x` format (R: as read,
    /// T: as sent).
    #[arg(long, value_name = "FILE")]
    log: Option<PathBuf>,
    /// Write the JSON summary to this file on exit.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// Seconds between stats lines on stderr, 0.001 to 86400 (0: none).
    #[arg(long, value_name = "SECONDS", default_value = "5", value_parser = firmware_bridge::cli::seconds_or_zero(0.001, 86_400.0))]
    // Fully qualified: the parser yields the Option itself (0 is none), so clap must
    // not treat the field as an optional argument of Duration.
    interval: ::std::option::Option<Duration>,
    /// Milliseconds a frame waits for a full transmit queue before it is given up
    /// (and counted as dropped), 0 to 60000.
    #[arg(
        long,
        value_name = "MS",
        default_value_t = GatewayConfig::default().tx_give_up_ms,
        value_parser = clap::value_parser!(u64).range(0..=60_000)
    )]
    tx_give_up_ms: u64,
    /// SCHED_FIFO priority of the forwarding threads, 0 (ordinary) to 99: a frame
    /// the gateway holds up is late at the ECU behind it.
    #[arg(long, default_value_t = firmware_bridge::realtime::DEFAULT_PRIORITY, value_parser = firmware_bridge::realtime::parse_priority)]
    rt_priority: u8,
}

fn direction_line(d: &DirectionStats) -> String {
    format!(
        "{}->{} forwarded {} local {} (malformed {}) retries {} dropped {} overflow {} latency p50 {:.0} us p99 {:.0} us",
        d.from,
        d.to,
        d.forwarded,
        d.local.total(),
        d.local.malformed(),
        d.tx_retries,
        d.tx_dropped,
        d.rx_overflow,
        d.latency.p50_us,
        d.latency.p99_us
    )
}

fn stats_line(s: &GatewayStats) -> String {
    format!(
        "ugv-bridge: {:.1} s | {} | {}",
        s.uptime_s,
        direction_line(&s.to_physical),
        direction_line(&s.to_sim)
    )
}

fn run(args: Args) -> anyhow::Result<()> {
    let interval = args.interval;
    let (stop_tx, stop_rx) = mpsc::channel::<()>();
    ctrlc::set_handler(move || {
        let _ = stop_tx.send(());
    })
    .context("installing the Ctrl-C/SIGTERM handler")?;
    let gateway = Gateway::spawn(GatewayConfig {
        sim_iface: args.sim.clone(),
        physical_iface: args.physical.clone(),
        physical_nodes: args.nodes.clone(),
        log: args.log.clone(),
        tx_give_up_ms: args.tx_give_up_ms,
        rt_priority: args.rt_priority,
        ..GatewayConfig::default()
    })?;
    let table = gateway.routing();
    eprintln!(
        "ugv-bridge: forwarding between {} (simulated: {}) and {} (physical: {})",
        args.sim,
        table.sim_nodes().join(", "),
        args.physical,
        table.physical_nodes().join(", ")
    );
    for line in table.describe() {
        eprintln!("ugv-bridge:   {line}");
    }
    let tick = interval.map_or(Duration::from_millis(200), |i| {
        i.min(Duration::from_millis(200))
    });
    let mut next_line = interval.map(|i| Instant::now() + i);
    loop {
        match stop_rx.recv_timeout(tick) {
            Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
        if !gateway.is_running() {
            break;
        }
        if let (Some(due), Some(i)) = (next_line, interval)
            && Instant::now() >= due
        {
            eprintln!("{}", stats_line(&gateway.stats()));
            next_line = Some(due + i);
        }
    }
    let stats = gateway.stop();
    let json = serde_json::to_string_pretty(&stats).context("serialising the stats")?;
    println!("{json}");
    if let Some(path) = &args.stats {
        std::fs::write(path, format!("{json}\n"))
            .with_context(|| format!("writing the stats to {}", path.display()))?;
    }
    eprintln!("{}", stats_line(&stats));
    if let Some(error) = &stats.error {
        bail!("the gateway stopped on an error: {error}");
    }
    Ok(())
}

fn main() -> ExitCode {
    let args = Args::parse();
    // Warnings of the gateway (frames given up, receive errors) on stderr; RUST_LOG
    // for more.
    firmware_bridge::cli::init_logging("warn");
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ugv-bridge: {e:#}");
            ExitCode::FAILURE
        }
    }
}
