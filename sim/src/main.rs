//! `ugv-sim`: the golf car's simulator.
//!
//! ```text
//! ugv-sim run [SCENARIO] [--can vcan0]   world + simulated ECUs on the CAN interface
//! ugv-sim check SCENARIO...              validate scenario files
//! ```
//!
//! Exit codes of `run`: 0 goal reached, 1 collision, 2 time limit, 3 stopped (Ctrl-C),
//! 4 error.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use firmware_bridge::CanPort;
use ugv_sim::clock::WallClock;
use ugv_sim::run::Snapshot;
use ugv_sim::{Outcome, Scenario, Sim};

#[derive(Parser, Debug)]
#[command(
    name = "ugv-sim",
    version,
    about = "Hardware-in-the-loop simulator of an autonomous golf car"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a scenario in real time with the simulated ECUs on a CAN interface.
    Run {
        /// Scenario file (TOML); the seed paper's scenario when absent.
        scenario: Option<PathBuf>,
        /// CAN interface of the simulated ECUs (overrides the scenario's can.interface).
        #[arg(long)]
        can: Option<String>,
        /// End the run after this many seconds (overrides sim.time_limit_s).
        #[arg(long)]
        time_limit: Option<f64>,
        /// Write the run's report (JSON) here as well as to stdout.
        #[arg(long)]
        report: Option<PathBuf>,
        /// Seconds between status lines.
        #[arg(long, default_value_t = 0.5)]
        status_every: f64,
    },
    /// Validate scenario files: parse, check every field, and report the first error
    /// of each with its file, line and field.
    Check {
        #[arg(required = true)]
        scenarios: Vec<PathBuf>,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ugv-sim: {e:#}");
            ExitCode::from(4)
        }
    }
}

fn status_line(s: &Snapshot) -> String {
    let flag = |enabled: bool, fault: Option<ugv_sim::ecu::safety::Cause>| match (enabled, fault) {
        (true, _) => "on".to_owned(),
        (false, None) => "off".to_owned(),
        (false, Some(c)) => format!(
            "SAFE({})",
            serde_json::to_string(&c)
                .unwrap_or_default()
                .trim_matches('"')
        ),
    };
    format!(
        "t={:7.2}s x={:7.2} y={:7.2} hdg={:7.1}° v={:5.2}m/s steer={:6.1}° goal {:6.2} m | steering {} throttle {}",
        s.time,
        s.vehicle.x,
        s.vehicle.y,
        s.vehicle.theta.to_degrees(),
        s.vehicle.v,
        s.vehicle.phi.to_degrees(),
        s.distance_to_goal,
        flag(s.steering_enabled, s.steering_fault),
        flag(s.throttle_enabled, s.throttle_fault),
    )
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Check { scenarios } => {
            let mut failed = false;
            for path in scenarios {
                match Scenario::load(&path) {
                    Ok(s) => println!(
                        "{}: ok ({}, {} obstacles)",
                        path.display(),
                        s.name,
                        s.obstacles.len()
                    ),
                    Err(e) => {
                        failed = true;
                        eprintln!("{e}");
                    }
                }
            }
            Ok(if failed {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            })
        }
        Command::Run {
            scenario,
            can,
            time_limit,
            report,
            status_every,
        } => {
            let mut sc = Scenario::load_or_paper(scenario.as_ref())?;
            if let Some(iface) = can {
                sc.can.interface = iface;
            }
            if let Some(limit) = time_limit {
                anyhow::ensure!(
                    limit > 0.0 && limit.is_finite(),
                    "--time-limit must be positive"
                );
                sc.sim.time_limit_s = limit;
            }
            let iface = sc.can.interface.clone();
            let steering = CanPort::open(&iface).context("steering ECU")?;
            let throttle = CanPort::open(&iface).context("throttle ECU")?;
            eprintln!("ugv-sim: scenario {:?}: {}", sc.name, sc.description);
            eprintln!(
                "ugv-sim: CAN: steering ECU and throttle ECU on {iface} (golf_car.dbc, E2E protected)"
            );
            eprintln!(
                "ugv-sim: physics {} Hz, time limit {} s; Ctrl-C ends the run",
                sc.sim.physics_hz, sc.sim.time_limit_s
            );
            let stop = Arc::new(AtomicBool::new(false));
            let flag = Arc::clone(&stop);
            ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
                .context("installing the Ctrl-C handler")?;
            let dt = 1.0 / sc.sim.physics_hz;
            let mut sim = Sim::new(sc, steering, throttle);
            let mut clock = WallClock::new(dt);
            let tty = std::io::stderr().is_terminal();
            let outcome = sim.run(&mut clock, &stop, status_every, &mut |s| {
                if tty {
                    eprint!("\r\x1b[2K{}", status_line(s));
                } else {
                    eprintln!("{}", status_line(s));
                }
            })?;
            if tty {
                eprintln!();
            }
            let code = match outcome {
                Outcome::GoalReached { .. } => 0,
                Outcome::Collision { .. } => 1,
                Outcome::TimeLimit { .. } => 2,
                Outcome::Stopped { .. } => 3,
            };
            let json = serde_json::to_string_pretty(&sim.report(outcome))?;
            println!("{json}");
            if let Some(path) = report {
                std::fs::write(&path, &json)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            Ok(ExitCode::from(code))
        }
    }
}
