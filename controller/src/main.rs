//! `ugv-controller`: the golf car's navigation firmware.
//!
//! ```text
//! ugv-controller run --config mission.toml --gps /dev/ttyUSB0 --laser SERVICE --can can0
//! ugv-controller plan [problem.json]        one planning step, JSON in and out
//! ugv-controller anfis train --data runs.csv --target steer_cmd --output model.json
//! ugv-controller check-config mission.toml
//! ```
//!
//! Exit codes of `run`: 0 mission complete (arrived and stopped), 1 safety stop
//! (estop), 3 ended by a signal, 4 error.

use std::io::{IsTerminal, Read};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use chrono::Timelike;
use clap::{Args, Parser, Subcommand};
use firmware_bridge::CanPort;
use firmware_bridge::clock::{Clock, WallClock, monotonic_ns};
use firmware_bridge::laser::LaserSubscriber;
use firmware_bridge::nmea::{NmeaLink, ReadEvent, ReaderConfig, open_serial};
use ugv_controller::config::{ControllerConfig, FollowerKind};
use ugv_controller::core::{COMMAND_PERIOD, Controller, Mode, scan_of};
use ugv_controller::trace::{FixTiming, Trace};

#[derive(Parser, Debug)]
#[command(
    name = "ugv-controller",
    version,
    about = "Navigation controller of the autonomous golf car"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Drive the mission: GPS from a serial port, laser frames from iceoryx2, the
    /// steering and throttle ECUs over SocketCAN.
    Run(RunArgs),
    /// One planning step of the bare method (README: "The plan subcommand"): a JSON
    /// problem from a file or stdin, the JSON result on stdout.
    Plan {
        /// Problem file; stdin when absent or `-`.
        input: Option<PathBuf>,
    },
    /// ANFIS models for the follower.
    Anfis {
        #[command(subcommand)]
        command: AnfisCommand,
    },
    /// Check a configuration file and print it with every default filled in.
    CheckConfig { config: PathBuf },
}

#[derive(Args, Debug)]
struct RunArgs {
    /// Configuration (TOML); defaults: the seed paper's mission.
    #[arg(long)]
    config: Option<PathBuf>,
    /// GPS serial device or pty link.
    #[arg(long)]
    gps: PathBuf,
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// iceoryx2 service of the laser frames.
    #[arg(long)]
    laser: String,
    /// SocketCAN interface of the actuators.
    #[arg(long, default_value = "vcan0")]
    can: String,
    /// Override the follower (optimal or anfis).
    #[arg(long, value_enum)]
    follower: Option<FollowerKind>,
    /// Override the ANFIS model file.
    #[arg(long)]
    anfis_model: Option<PathBuf>,
    /// Write the run's trace (samples, plans, obstacles, mode) as JSON at exit.
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Write the follower's training data (CSV: e_y, e_theta, phi_ref, steer_cmd) at exit.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Seconds between status lines (0: none).
    #[arg(long, default_value_t = 1.0)]
    status_every: f64,
}

#[derive(Subcommand, Debug)]
enum AnfisCommand {
    /// Train a first-order Sugeno ANFIS (hybrid learning, Jang 1993) from CSV or JSON.
    Train {
        #[arg(long)]
        data: PathBuf,
        /// Input columns in model order (default: e_y, e_theta, phi_ref).
        #[arg(long, value_delimiter = ',', default_value = "e_y,e_theta,phi_ref")]
        inputs: Vec<String>,
        #[arg(long, default_value = "steer_cmd")]
        target: String,
        /// Membership functions per input.
        #[arg(long, value_delimiter = ',', default_value = "3")]
        mfs: Vec<usize>,
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        #[arg(long, default_value_t = 0.01)]
        step_size: f64,
        /// Checking data; the epoch with the lowest checking error is kept.
        #[arg(long)]
        checking: Option<PathBuf>,
        #[arg(long)]
        output: PathBuf,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ugv-controller: {e:#}");
            ExitCode::from(4)
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Plan { input } => {
            let mut text = String::new();
            match input.as_deref() {
                Some(p) if p.as_os_str() != "-" => {
                    text = std::fs::read_to_string(p)
                        .with_context(|| format!("reading {}", p.display()))?
                }
                _ => {
                    std::io::stdin()
                        .read_to_string(&mut text)
                        .context("reading stdin")?;
                }
            }
            let problem: ugv_controller::planner::PlanProblem = serde_json::from_str(&text)
                .context("the planning problem (see the README for its schema)")?;
            let result = ugv_controller::planner::plan(&problem)?;
            println!("{}", serde_json::to_string_pretty(&result)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Anfis {
            command:
                AnfisCommand::Train {
                    data,
                    inputs,
                    target,
                    mfs,
                    epochs,
                    step_size,
                    checking,
                    output,
                },
        } => {
            let mut args =
                ugv_controller::anfis::TrainArgs::new(data, inputs, target, output.clone());
            args.mfs = mfs;
            args.epochs = epochs;
            args.step_size = step_size;
            args.checking = checking;
            let report = ugv_controller::anfis::train_command(&args)?;
            eprintln!("ugv-controller: model written to {}", output.display());
            println!("{}", serde_json::to_string_pretty(&report)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::CheckConfig { config } => {
            let cfg = ControllerConfig::load(&config)?;
            print!("{}", toml::to_string_pretty(&cfg)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Run(args) => drive(args),
    }
}

fn drive(args: RunArgs) -> Result<ExitCode> {
    let mut cfg = match &args.config {
        Some(p) => ControllerConfig::load(p)?,
        None => ControllerConfig::default(),
    };
    if let Some(kind) = args.follower {
        cfg.follower.kind = kind;
    }
    if let Some(model) = &args.anfis_model {
        cfg.follower.anfis_model = Some(model.clone());
    }
    cfg.validate()
        .map_err(|(field, message)| anyhow::anyhow!("{field}: {message}"))?;
    let mut ctl = Controller::new(&cfg)?
        .with_planning_thread()
        .context("starting the planning thread")?;
    let mut can = CanPort::open(&args.can)?;
    let port = open_serial(&args.gps, args.baud, Duration::ZERO)?;
    let mut gps = NmeaLink::new(port, ReaderConfig::default());
    let laser = LaserSubscriber::new(&args.laser)?;
    eprintln!(
        "ugv-controller: GPS {} at {} baud, laser {}, CAN {}, follower {:?}",
        args.gps.display(),
        args.baud,
        args.laser,
        args.can,
        cfg.follower.kind
    );
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;

    let mut clock = WallClock::new(COMMAND_PERIOD);
    let status_ticks = (args.status_every / COMMAND_PERIOD).round() as u64;
    let tty = std::io::stderr().is_terminal();
    let mut k: u64 = 0;
    // Fixes read and not yet followed by a steering command: (UTC s of day, read ns).
    let mut unanswered: Vec<(f64, u64)> = Vec::new();
    let mut fix_timing = Vec::new();
    let code = loop {
        clock.wait_tick(k);
        let now = k as f64 * COMMAND_PERIOD;
        k += 1;
        while let Some(r) = can.try_recv() {
            ctl.on_can(now, &r);
        }
        for event in gps.poll()? {
            if let ReadEvent::Fix(reading) = event {
                if let Some(t) = reading.time {
                    unanswered.push((
                        f64::from(t.num_seconds_from_midnight()) + f64::from(t.nanosecond()) * 1e-9,
                        monotonic_ns(),
                    ));
                }
                ctl.on_gps(now, &reading);
            }
        }
        while let Some(frame) = laser.try_recv()? {
            ctl.on_scan(now, &scan_of(&frame, now));
        }
        for m in ctl.tick(now) {
            can.send_message(&m)?;
            if matches!(m, golf_car_can::GolfCarMessage::SteeringCmd(_)) {
                let sent = monotonic_ns();
                fix_timing.extend(unanswered.drain(..).map(|(utc_s, read_ns)| FixTiming {
                    utc_s,
                    read_ns,
                    command_ns: sent,
                }));
            }
        }
        if status_ticks > 0 && k % status_ticks == 0 {
            let line = match ctl.pose(now) {
                Some(p) => format!(
                    "t={now:7.2}s {:?} x={:7.2} y={:7.2} hdg={:6.1}° v={:4.2} obstacles={} {}",
                    ctl.mode(),
                    p.x,
                    p.y,
                    p.theta.to_degrees(),
                    p.v,
                    ctl.obstacles().len(),
                    ctl.stop_reason().unwrap_or("")
                ),
                None => format!("t={now:7.2}s {:?} (no position yet)", ctl.mode()),
            };
            if tty {
                eprint!("\r\x1b[2K{line}");
            } else {
                eprintln!("{line}");
            }
        }
        if ctl.finished() {
            break 0;
        }
        // In estop the heartbeat and FAULT_REPORT go on until a signal ends the process.
        if stop.load(Ordering::Relaxed) {
            // Leave the car safe: a few estop heartbeats before going.
            for _ in 0..5 {
                can.send(&golf_car_can::ControllerHeartbeat {
                    state: golf_car_can::ControllerHeartbeatState::Estop,
                })?;
                std::thread::sleep(Duration::from_millis(20));
            }
            break if matches!(ctl.mode(), Mode::Estop { .. }) {
                1
            } else {
                3
            };
        }
    };
    if tty {
        eprintln!();
    }
    eprintln!("ugv-controller: {:?}; CAN {:?}", ctl.mode(), can.stats());
    let mut trace = Trace::of(&ctl, clock.now());
    trace.fix_timing = fix_timing;
    if let Some(path) = &args.trace {
        std::fs::write(path, serde_json::to_string(&trace)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.record {
        std::fs::write(path, trace.training_csv())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ExitCode::from(code))
}
