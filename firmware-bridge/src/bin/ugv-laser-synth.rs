//! `ugv-laser-synth`: publish synthetic laser frames ([`LaserFrame::synthetic`]) on an
//! iceoryx2 laser service, one per line of stdin: a subscriber's other end in another
//! process, without the simulator (firmware-bridge/tests/laser_ipc.rs drives it; so can
//! a person trying `ugv-laser-echo`).
//!
//! ```text
//! ugv-laser-synth ugv-hil/<run_id>/laser                          # then type "0 541"
//! ugv-laser-synth ugv-hil/<run_id>/laser --expect-subscribers 1
//! ```
//!
//! Each line `SEQUENCE BEAMS` publishes `LaserFrame::synthetic(SEQUENCE, BEAMS)` and
//! prints `published SEQUENCE` on stdout; `quit` ends with status 0. `ready` is printed
//! once the service is open. With `--expect-subscribers N`, a frame that reaches
//! another number of subscribers ends the run with status 1, and so does stdin closing
//! before `quit`.

use std::io::{BufRead, Write};

use anyhow::{Context, bail, ensure};
use clap::Parser;
use firmware_bridge::laser::{LaserFrame, LaserPublisher};

/// Publish synthetic laser frames on an iceoryx2 service, as stdin asks.
#[derive(Debug, Parser)]
// `ugv-sick 0.1.0 (firmware-bridge)`: the binary's own name, its crate's version and name.
#[command(
    name = env!("CARGO_BIN_NAME"),
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("CARGO_PKG_NAME"), ")")
)]
struct Args {
    /// The service, `ugv-hil/<run_id>/laser`.
    service: String,
    /// Fail when a frame reaches a different number of subscribers.
    #[arg(long, value_name = "N")]
    expect_subscribers: Option<usize>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    // iceoryx2 warns on stderr when no config file exists; IOX2_LOG_LEVEL overrides.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let publisher = LaserPublisher::new(&args.service)
        .with_context(|| format!("opening the laser service {}", args.service))?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")?;
    out.flush()?;
    for line in std::io::stdin().lock().lines() {
        let line = line.context("reading stdin")?;
        let line = line.trim();
        if line == "quit" {
            return Ok(());
        }
        let (sequence, beams) = line
            .split_once(' ')
            .and_then(|(s, b)| Some((s.parse::<u64>().ok()?, b.trim().parse::<usize>().ok()?)))
            .with_context(|| format!("{line:?}: want \"SEQUENCE BEAMS\" or \"quit\""))?;
        let reached = publisher
            .publish(&LaserFrame::synthetic(sequence, beams))
            .with_context(|| format!("publishing frame {sequence} on {}", args.service))?;
        if let Some(n) = args.expect_subscribers {
            ensure!(
                reached == n,
                "frame {sequence} reached {reached} subscribers, not {n}"
            );
        }
        writeln!(out, "published {sequence}")?;
        out.flush()?;
    }
    bail!("stdin closed before quit")
}
