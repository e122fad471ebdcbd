//! `ugv-controller`: the golf car's navigation firmware.
//!
//! ```text
//! ugv-controller run --config mission.toml --gps /dev/ttyUSB0 --laser SERVICE --can can0
//! ugv-controller run ... --record logs/today   and record its ports (replay: ugv-sim replay)
//! ugv-controller run ... --training-csv t.csv  and write the ANFIS training data
//! ugv-controller run ... --lockstep ugv-hil/RUN/clock   on the simulator's clock
//! ugv-controller plan [problem.json]        one planning step, JSON in and out
//! ugv-controller anfis train --data runs.csv --target steer_cmd --output model.json
//! ugv-controller check-config mission.toml
//! ```
//!
//! Exit codes of `run`: 0 mission complete (arrived and stopped), 1 safety stop
//! (estop: ended by a signal while in estop, or a port lost, after the estop went
//! out), 3 ended by a signal, 4 error (including the CAN port failing mid-run).

use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use firmware_bridge::CanPort;
use firmware_bridge::can::gated::GatedSocket;
use firmware_bridge::clock::{Clock, WallClock};
use firmware_bridge::laser::LaserSubscriber;
use firmware_bridge::nmea::{NmeaLink, ReaderConfig, open_serial};
use firmware_bridge::realtime;
use ugv_controller::config::{ControllerConfig, FollowerKind};
use ugv_controller::control::{COMMAND_PERIOD, Controller, Mode};
use ugv_controller::lockstep::{GatedGps, SimClock};
use ugv_controller::record::{Mounts, RunInfo, Writer};
use ugv_controller::runtime::{Exit, GpsInput, LaserInput, Runtime, SIMULATOR_PID_ENV};
use ugv_controller::trace::TraceWriter;

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
    /// One planning step of the bare method (docs/controller.md, "The plan
    /// subcommand"): a JSON problem from a file or stdin, the JSON result on stdout.
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
    /// Baud rate of the GPS line (300 to 4,000,000).
    #[arg(long, default_value_t = 115_200, value_parser = clap::value_parser!(u32).range(300..=4_000_000))]
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
    /// Write the run's trace (samples, plans, obstacles, mode) as JSON Lines while it
    /// drives (flushed every second and at every change of mode).
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Write the follower's ANFIS training data (CSV: e_y, e_theta, phi_ref,
    /// steer_cmd) while it drives, for `anfis train --data`.
    #[arg(long, value_name = "FILE")]
    training_csv: Option<PathBuf>,
    /// Record what crosses the controller's ports into this directory (created if
    /// missing) as it drives: run.mcap (every input at the tick that took it, every
    /// frame sent, the controller's state and paths), bus.log (candump -l) and
    /// gps.nmea (the raw line), for Foxglove and for `ugv-sim replay`.
    //
    // `--log DIR`, its name before issue 33, is taken for one more release, out of the
    // help; `--record FILE.csv`, what it meant then, is refused (`recording_dir`).
    #[arg(long, value_name = "DIR", alias = "log", value_parser = recording_dir)]
    record: Option<PathBuf>,
    /// Seconds between status lines (0: none).
    #[arg(long, default_value_t = 1.0)]
    status_every: f64,
    /// SCHED_FIFO priority of the command loop, 0 (ordinary scheduling) to 99; needs
    /// root or CAP_SYS_NICE, and runs on without it, saying so. The planning thread
    /// stays ordinary, so the loop preempts it.
    #[arg(long, default_value_t = realtime::DEFAULT_PRIORITY, value_parser = realtime::parse_priority)]
    rt_priority: u8,
    /// Run on the simulator's clock (lockstep HIL): take its ticks from this iceoryx2
    /// service (`ugv-hil/<run id>/clock`, wires.json's `clock_service`) and
    /// acknowledge each; the planning runs in the loop, as in SIL, so a run is
    /// deterministic. docs/wire-contract.md, "Lockstep".
    #[arg(long, value_name = "SERVICE")]
    lockstep: Option<String>,
}

/// `--record DIR`: a folder for the recording. A file name ending in `.csv` is what
/// `--record` meant before it named the recording: the training CSV, now
/// `--training-csv`.
fn recording_dir(value: &str) -> Result<PathBuf, String> {
    if Path::new(value)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
    {
        return Err(format!(
            "{value} looks like a CSV file: --record DIR now records the controller's \
             ports into a folder; the ANFIS training data (what --record FILE wrote \
             before) is --training-csv FILE"
        ));
    }
    Ok(PathBuf::from(value))
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
        /// Membership functions per input (one value for every input, or one per
        /// input), each 1 to 32, at most 1024 rules (their product over the inputs).
        #[arg(long, value_delimiter = ',', default_value = "3")]
        mfs: Vec<usize>,
        /// Epochs, 1 to 100000.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Jang's initial step size, normalised units, above 0 and at most 1.
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
    // The tracing events of the libraries (firmware-bridge's) on stderr: warnings, or
    // what RUST_LOG asks for (firmware_bridge=debug: each NMEA sentence rejected).
    firmware_bridge::cli::init_logging("warn");
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
                .context("the planning problem (see docs/controller.md for its schema)")?;
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
            // The library's bounds, said in the command line's words.
            args.validate().map_err(|e| match e {
                ugv_controller::anfis::AnfisError::InvalidConfig { field, reason } => {
                    anyhow::anyhow!("anfis train --{}: {reason}", field.replace('_', "-"))
                }
                other => other.into(),
            })?;
            let report = ugv_controller::anfis::train_command(&args)?;
            eprintln!("ugv-controller: model written to {}", output.display());
            println!("{}", serde_json::to_string_pretty(&report)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::CheckConfig { config } => {
            let cfg = ControllerConfig::load(&config)?;
            // Exactly what `run` builds before it opens a port.
            Controller::new(&cfg)?;
            print!("{}", toml::to_string_pretty(&cfg)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Run(args) => drive(args),
    }
}

/// `ugv-controller run`: drive the mission on the real ports until it ends, is stopped
/// or a port fails; the exit code says which.
fn drive(args: RunArgs) -> Result<ExitCode> {
    let cfg = run_config(&args)?;
    // The same checks as check-config: the configuration's, then the controller's own.
    let ctl = Controller::new(&cfg)?;
    let mut lockstep = args
        .lockstep
        .as_deref()
        .map(SimClock::open)
        .transpose()
        .context("--lockstep")?;
    // In lockstep the planning runs in the loop, as in SIL: the same inputs give the
    // same plans at the same ticks.
    let ctl = match lockstep {
        Some(_) => ctl,
        None => ctl
            .with_planning_thread()
            .context("starting the planning thread")?,
    };
    let trace = trace_writer(&args)?;
    let (can, gps, laser) = open_ports(&args, &cfg, lockstep.as_ref())?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    end_with_simulator()?;

    let mut rt = Runtime::new(ctl, gps, laser, can);
    if lockstep.is_none() {
        // Latencies on the machine's clock: real time only.
        rt = rt.with_fix_timing();
    }
    if let Some(w) = trace {
        // In lockstep, each tick's records are in the file before it is acknowledged.
        rt = rt.with_trace(match lockstep {
            Some(_) => w.flushing_every_update(),
            None => w,
        });
    }
    // After the planning thread started, so that it stays an ordinary thread.
    let rt_sched = realtime::promote(args.rt_priority);
    eprintln!(
        "{}",
        rt_sched.promotion.describe("ugv-controller: command loop")
    );
    if let Some(dir) = &args.record {
        rt = with_recording(rt, dir, &args, &cfg)?;
    }
    let mut log = LoopLog::new(args.status_every);
    let exit = match &mut lockstep {
        Some(clock) => {
            let exit = drive_on(&mut rt, clock, &stop, &mut log);
            clock.acknowledge_end(exit.code());
            exit
        }
        None => drive_on(
            &mut rt,
            &mut WallClock::new(COMMAND_PERIOD),
            &stop,
            &mut log,
        ),
    };
    if log.tty {
        eprintln!();
    }
    report_end(&mut rt, &exit);
    Ok(ExitCode::from(exit.code()))
}

/// The loop on `clock` until it ends, its lines on stderr.
fn drive_on<G: GpsInput, L: LaserInput, B: embedded_can::nb::Can>(
    rt: &mut Runtime<G, L, B>,
    clock: &mut impl Clock,
    stop: &AtomicBool,
    log: &mut LoopLog,
) -> Exit {
    rt.run(clock, stop, |k, now, rt| {
        log.tick(k, now, rt.controller());
    })
}

/// The configuration `ugv-controller run` drives with: the file's (the paper's mission
/// without one) with the command line's follower and model; `--status-every` checked.
fn run_config(args: &RunArgs) -> Result<ControllerConfig> {
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
    anyhow::ensure!(
        args.status_every.is_finite() && (0.0..=3600.0).contains(&args.status_every),
        "--status-every must be within [0, 3600] s, is {}",
        args.status_every
    );
    Ok(cfg)
}

/// The writer of `--trace` and `--training-csv`, their files created (none without
/// either).
fn trace_writer(args: &RunArgs) -> Result<Option<TraceWriter>> {
    let create =
        |p: &PathBuf| std::fs::File::create(p).with_context(|| format!("creating {}", p.display()));
    Ok(match (&args.trace, &args.training_csv) {
        (None, None) => None,
        (trace, training_csv) => Some(
            TraceWriter::new(
                trace.as_ref().map(create).transpose()?,
                training_csv.as_ref().map(create).transpose()?,
            )
            .context("writing the trace")?,
        ),
    })
}

/// The controller's ports, opened: the actuators' CAN bus (with its acceptance
/// filter), the GPS line and the laser service, in lockstep with `lockstep` when
/// given; said on stderr.
fn open_ports(
    args: &RunArgs,
    cfg: &ControllerConfig,
    lockstep: Option<&SimClock>,
) -> Result<(
    CanPort<GatedSocket>,
    GatedGps<NmeaLink<impl Read + Write + use<>>>,
    LaserSubscriber,
)> {
    let can = CanPort::open_gated(&args.can, lockstep.map(SimClock::can_gate))?;
    ugv_controller::runtime::accept_controller_ids(&can)?;
    let port = open_serial(&args.gps, args.baud, Duration::ZERO)?;
    let gps = NmeaLink::new(port, ReaderConfig::default());
    let gps = match lockstep {
        Some(clock) => clock.gate_gps(gps),
        None => GatedGps::new(gps, None),
    };
    let laser = LaserSubscriber::new(&args.laser)?;
    eprintln!(
        "ugv-controller: GPS {} at {} baud, laser {}, CAN {}, follower {:?}, clock {}",
        args.gps.display(),
        args.baud,
        args.laser,
        args.can,
        cfg.follower.kind,
        args.lockstep.as_deref().unwrap_or("wall")
    );
    Ok((can, gps, laser))
}

/// `rt` recording its ports into `dir` (`--record`), the folder created; the
/// recording's start is now, the loop's t = 0.
fn with_recording<G: GpsInput, L: LaserInput, B: embedded_can::nb::Can>(
    rt: Runtime<G, L, B>,
    dir: &Path,
    args: &RunArgs,
    cfg: &ControllerConfig,
) -> Result<Runtime<G, L, B>> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("--record: creating {}", dir.display()))?;
    let info = RunInfo::field(
        args.config.as_ref().map_or_else(
            || "the paper's mission (default configuration)".to_owned(),
            |p| p.display().to_string(),
        ),
        // The loop's t = 0: its clock starts next.
        firmware_bridge::clock::unix_ns(std::time::SystemTime::now()),
        args.can.clone(),
        ReaderConfig::default().complete_when,
        args.baud,
        cfg,
    )?;
    let writer = Writer::create(Some(dir), foxglove::Context::new(), info)
        .with_context(|| format!("--record: recording into {}", dir.display()))?
        .with_mounts(Mounts::of(&cfg.vehicle));
    rt.with_recorder(writer)
        .context("--record: starting the recorder's thread")
}

/// The command loop's lines on stderr. Every change of mode, and of stopping or moving
/// on, is logged as it happens, status lines or not: the log of a controller on its own
/// board says when and why it stopped. A stop reason whose wording changes (a distance
/// in it) is logged again at most once a second.
#[derive(Debug)]
struct LoopLog {
    /// Ticks between status lines (0: none).
    status_ticks: u64,
    /// Stderr is a terminal: the status line is redrawn in place.
    tty: bool,
    /// The mode, stop reason and time last logged.
    logged: Option<(Mode, Option<String>, f64)>,
}

impl LoopLog {
    /// A status line every `status_every` seconds (0: none).
    fn new(status_every: f64) -> LoopLog {
        LoopLog {
            status_ticks: (status_every / COMMAND_PERIOD).round() as u64,
            tty: std::io::stderr().is_terminal(),
            logged: None,
        }
    }

    /// Tick `k` at `now`: a change of `ctl`'s mode or stop, then the status line when
    /// one is due.
    fn tick(&mut self, k: u64, now: f64, ctl: &Controller) {
        self.changes(now, ctl);
        if self.status_ticks == 0 || !k.is_multiple_of(self.status_ticks) {
            return;
        }
        self.status(now, ctl);
    }

    /// Log the mode and stop reason when they changed since last logged.
    fn changes(&mut self, now: f64, ctl: &Controller) {
        let clear = if self.tty { "\r\x1b[2K" } else { "" };
        let reason = ctl.stop_reason();
        if self.logged.as_ref().is_none_or(|(mode, was, at)| {
            mode != ctl.mode()
                || was.is_some() != reason.is_some()
                || (was.as_deref() != reason && now - at >= 1.0)
        }) {
            eprintln!(
                "{clear}ugv-controller: t={now:7.2}s {:?}{}",
                ctl.mode(),
                reason
                    .map(|r| format!(", stopped: {r}"))
                    .unwrap_or_default()
            );
            self.logged = Some((ctl.mode().clone(), reason.map(str::to_owned), now));
        }
    }

    /// The status line: the mode, the pose and the obstacles at `now`.
    fn status(&self, now: f64, ctl: &Controller) {
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
        if self.tty {
            eprint!("\r\x1b[2K{line}");
        } else {
            eprintln!("{line}");
        }
    }
}

/// How the run ended, on stderr: the exit, the mode, the CAN and input counts, and the
/// trace's and the recording's state.
fn report_end<G: GpsInput, L: LaserInput, B: embedded_can::nb::Can>(
    rt: &mut Runtime<G, L, B>,
    exit: &Exit,
) {
    eprintln!(
        "ugv-controller: {exit:?}; {:?}; CAN {:?}; inputs {:?}; ticks skipped late {}",
        rt.controller().mode(),
        rt.can().stats(),
        rt.stats,
        rt.skipped_ticks
    );
    if let Some(e) = rt.trace_error() {
        eprintln!("ugv-controller: the trace is incomplete: {e}");
    }
    if let Some(summary) = rt.finish_recording() {
        eprintln!(
            "ugv-controller: {}",
            ugv_controller::record::describe(&summary)
        );
    }
}

/// A controller the simulator started (its pid in [`SIMULATOR_PID_ENV`]) ends with it:
/// the kernel sends it SIGTERM when that process dies, which stops the loop as Ctrl-C
/// does (estop heartbeats, then exit), so no orphan keeps talking on the bus. If the
/// simulator is gone already (it died between the fork and here), it does not start.
fn end_with_simulator() -> anyhow::Result<()> {
    let Some(value) = std::env::var_os(SIMULATOR_PID_ENV) else {
        return Ok(());
    };
    let pid: i32 = value
        .to_str()
        .and_then(|v| v.parse().ok())
        .with_context(|| format!("{SIMULATOR_PID_ENV}={value:?}: not a process id"))?;
    nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM)
        .context("asking for SIGTERM when the simulator ends")?;
    let parent = nix::unistd::getppid().as_raw();
    anyhow::ensure!(
        parent == pid,
        "started by the simulator (pid {pid}), which is gone (the parent is now pid {parent})"
    );
    Ok(())
}
