//! `ugv-sim`: the golf car's simulator.
//!
//! ```text
//! ugv-sim run [SCENARIO] --controller target/release/ugv-controller   HIL, the real wires
//! ugv-sim run [SCENARIO] --wait-for-controller                        HIL, your controller
//! ugv-sim run [SCENARIO] --sil                                        lockstep, in-process
//! ugv-sim suite DIR                                                   a folder of scenarios
//! ugv-sim ecu steering --can vcan1                                    one ECU, standalone
//! ugv-sim check SCENARIO...                                           validate scenario files
//! ugv-sim way-through WORLD...                                       is there a way through at all
//! ```
//!
//! Exit codes of `run`, `suite` and `merge` ([`ugv_sim::exit`], shown by their
//! `--help`): 0 passed, 1 failed its criteria, 2 usage error, 3 stopped (Ctrl-C, the
//! controller exited), 4 setup or run error, 5 time limit; a suite's is its most
//! severe item's.

use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use firmware_bridge::CanPort;
use firmware_bridge::can::timed::Horizon;
use firmware_bridge::cli::number;
use firmware_bridge::clock::WallClock;
use firmware_bridge::realtime;
use ugv_controller::config::{ControllerConfig, FollowerKind};
use ugv_controller::trace::TraceWriter;
use ugv_sim::devices::map::DeviceMap;
use ugv_sim::ecu::EcuKind;
use ugv_sim::ecu::station::run_standalone;
use ugv_sim::exit::{self, Exit};
use ugv_sim::hil::{self, Endpoints, HilOptions};
use ugv_sim::mission::{checked_controller_config, controller_config};
use ugv_sim::record::live::{self, LiveView};
use ugv_sim::run::Snapshot;
use ugv_sim::scenario::Overrides;
use ugv_sim::sil::Hook;
use ugv_sim::sweep::{Plan, PlanInfo, Shard};
use ugv_sim::verdict::{RunEnd, judge_and_write};
use ugv_sim::{Mode, Scenario};

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
    /// Run a scenario: in real time on the real wires (HIL; the default), or with the
    /// controller library in lockstep (--sil).
    #[command(after_help = exit::RUN_HELP)]
    Run(RunArgs),
    /// Run every scenario of a folder in SIL, in parallel (with --seeds and --vary: a
    /// sweep; with --shard: a part of it), and write summary.md, summary.json,
    /// junit.xml and items.json. Exit codes below: one per way an item ends, the most
    /// severe item's.
    #[command(after_help = exit::SUITE_HELP)]
    Suite(SuiteArgs),
    /// Join the shards of one suite or sweep (each folder's items.json) into one
    /// summary.md, summary.json and junit.xml; refuses missing or doubled items (exit
    /// code 4). Exit codes as `suite`'s, of the merged items.
    #[command(after_help = exit::SUITE_HELP)]
    Merge {
        /// Shard result folders (or their items.json files).
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        /// Where the merged summaries (and the merged items.json) go.
        #[arg(long)]
        out: PathBuf,
    },
    /// Run one simulated ECU alone on a CAN interface, in real time, as a stand-in for
    /// the hardware on a bench (for example on the physical side of ugv-bridge).
    Ecu {
        #[arg(value_enum)]
        kind: EcuKind,
        /// The CAN interface to sit on.
        #[arg(long)]
        can: String,
        /// The ECU's parameters come from this scenario (the paper's when absent).
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Seconds between status lines, 0.001 to 3600.
        #[arg(long, default_value_t = 1.0, value_parser = number(0.001, 3600.0, "seconds"))]
        status_every: f64,
        /// SCHED_FIFO priority of the ECU's loop, 0 (ordinary scheduling) to 99; needs
        /// root or CAP_SYS_NICE, and runs on without it, saying so.
        #[arg(long, default_value_t = realtime::DEFAULT_PRIORITY, value_parser = realtime::parse_priority)]
        rt_priority: u8,
    },
    /// Replay a recording (run.mcap) into the controller library in lockstep and
    /// compare its commands with the recorded ones: exactly for a SIL recording,
    /// within the HIL tolerance for a HIL one (see docs/recording.md). Prints the report as
    /// JSON. Exit code 0 when they agree, 1 at a divergence, 3 when the recording is
    /// damaged or invalid (a record fails its CRC or its lengths, a message's time lies
    /// outside the run, a channel or metadata the replay needs is missing or invalid:
    /// the error names the file and the byte offset), 4 on any other error. A
    /// recording cut by a kill is replayed up to the cut.
    Replay {
        /// The recording (run.mcap of a run's results).
        recording: PathBuf,
        /// Write the replayed controller's trace here (JSON lines, the format of
        /// `ugv-controller --trace`: its samples, plans and states), to set beside
        /// the recorded controller-trace.jsonl.
        #[arg(long, value_name = "FILE")]
        trace: Option<PathBuf>,
    },
    /// Validate scenario files: parse, check every field, and report the first error
    /// of each with its file, line and field.
    Check {
        #[arg(required = true)]
        scenarios: Vec<PathBuf>,
    },
    /// Whether each world has a way through for the car at all: the manoeuvre planner
    /// run offline on the whole world, at a fine resolution, until every pose it can
    /// reach is expanded. Prints one line per file and the totals; exit code 0 when
    /// every world was decided, 1 when a search reached its bound of expansions, 4 on
    /// an error.
    WayThrough(WayThroughArgs),
}

#[derive(clap::Args, Debug)]
struct WayThroughArgs {
    #[arg(required = true)]
    scenarios: Vec<PathBuf>,
    /// Clearance between the car's rectangle and every obstacle, metres.
    #[arg(long, default_value_t = 0.0, value_parser = number(0.0, 2.0, "m"))]
    margin: f64,
    /// The share of the steering lock the search may use.
    #[arg(long, default_value_t = 1.0, value_parser = number(0.2, 1.0, "of the lock"))]
    steer_usage: f64,
    /// Side of a search cell, metres.
    #[arg(long, default_value_t = 0.1, value_parser = number(0.02, 1.0, "m"))]
    xy_res: f64,
    /// Heading cells in a full turn.
    #[arg(long, default_value_t = 144, value_parser = clap::value_parser!(u16).range(8..=720))]
    heading_bins: u16,
    /// Expansions before a world is called undecided.
    #[arg(long, default_value_t = 4_000_000, value_parser = clap::value_parser!(u32).range(1..))]
    expansions: u32,
    /// Parallel searches (each may take a few GB at the default bound).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
    jobs: u16,
    /// Write the stems of the worlds with no way through here, one per line (for
    /// scripts/barn.py --exclude-list).
    #[arg(long, value_name = "FILE")]
    list: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct SuiteArgs {
    /// The folder of scenario files (*.toml).
    dir: PathBuf,
    /// Where the summaries go (and, in HIL, each run's results in a folder of its own).
    #[arg(long, default_value = "results/suite")]
    results: PathBuf,
    /// Parallel runs in SIL; default: the number of cores. In HIL one run per --can
    /// interface at a time, or N isolated runs (--isolate; default 1).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1024))]
    jobs: Option<usize>,
    #[arg(long, value_enum, default_value_t = FollowerKind::Optimal)]
    follower: FollowerKind,
    #[arg(long)]
    anfis_model: Option<PathBuf>,
    /// Run each scenario in HIL, in real time on the wires, with the controller binary.
    #[arg(long)]
    hil: bool,
    /// With --hil: in lockstep (the simulator and the controller binary wait on each
    /// other's ticks over the clock wire): deterministic, as fast as both go.
    #[arg(long, requires = "hil")]
    lockstep: bool,
    /// The controller binary for --hil; default: ugv-controller beside ugv-sim.
    #[arg(long, value_name = "BINARY")]
    controller: Option<PathBuf>,
    /// CAN interfaces for --hil (repeatable): each one carries one run at a time, so
    /// N interfaces run N scenarios in parallel. Default: each scenario's own.
    #[arg(long = "can")]
    cans: Vec<String>,
    /// With --hil: each run in a private network namespace of its own, its CAN
    /// interface created there, so no other process can open it (needs root); runs
    /// then never share a bus, and --jobs N runs N at a time.
    #[arg(long)]
    isolate: bool,
    /// Record every run (run.mcap, bus.log, gps.nmea) in a folder of its own under
    /// --results.
    #[arg(long)]
    record: bool,
    /// With --hil: do not draw each run (figure.svg, figure.png in its folder). SIL
    /// runs of a suite write no per-run files but their recordings (--record).
    #[arg(long, requires = "hil")]
    no_figures: bool,
    /// Run every scenario (and grid point) with this many seeds, 1 to 100000: the
    /// scenario's own, then seeds derived from it.
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100_000))]
    seeds: usize,
    /// Sweep a scenario field: KEY=a,b,c or KEY=lo:hi:step (repeatable; the grid is
    /// crossed with the seeds), e.g. steering.dead_time_s=0:0.3:0.05.
    #[arg(long = "vary", value_name = "KEY=SPEC")]
    vary: Vec<ugv_sim::sweep::Vary>,
    /// Run shard I of N (I from 0) of the items, balanced by their time limits;
    /// default: JOB_COMPLETION_INDEX of JOB_COMPLETIONS when set (a Kubernetes
    /// Indexed Job), else all.
    #[arg(long, value_name = "I/N")]
    shard: Option<ugv_sim::sweep::Shard>,
    /// Print the ids of the items this shard would run, one per line, and run none.
    #[arg(long)]
    list: bool,
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Scenario file (TOML); the seed paper's scenario when absent.
    scenario: Option<PathBuf>,
    /// Lockstep software-in-the-loop with the built-in controller library: no wires,
    /// deterministic, faster than real time (so no --controller, --controller-arg or
    /// --wait-for-controller, which are for HIL).
    #[arg(long, conflicts_with_all = ["controller", "controller_args", "wait_for_controller"])]
    sil: bool,
    /// CAN interface of the simulated ECUs (overrides the scenario's can.interface).
    #[arg(long)]
    can: Option<String>,
    /// A bench file: a `[devices]` section saying which devices are physical and
    /// where (overrides the scenario's); see docs/devices.md.
    #[arg(long, value_name = "FILE")]
    devices: Option<PathBuf>,
    /// End the run after this many seconds, 0.001 to 86400 (overrides
    /// sim.time_limit_s).
    #[arg(long, value_parser = number(0.001, 86_400.0, "seconds"))]
    time_limit: Option<f64>,
    /// Directory for the run's results: verdict.json, trace.json, training.csv,
    /// figure.svg and figure.png (not with --no-figures), and the recording run.mcap,
    /// bus.log and gps.nmea (not with --no-record); HIL adds controller.toml,
    /// controller-trace.jsonl and wires.json. See docs/simulator.md.
    #[arg(long, default_value = "results")]
    results: PathBuf,
    /// Start this controller binary with the wire locations (HIL); see
    /// docs/wire-contract.md for the command line it is given.
    #[arg(long, value_name = "BINARY")]
    controller: Option<PathBuf>,
    /// Extra arguments for the controller binary (repeatable).
    #[arg(long = "controller-arg", allow_hyphen_values = true)]
    controller_args: Vec<String>,
    /// Have the controller started with --controller record its own ports into
    /// RESULTS/controller (`ugv-controller run --record`), a recording that replays byte
    /// for byte; off by default, since it adds the controller's share of encoding and
    /// writing to the machine.
    #[arg(long, requires = "controller")]
    controller_log: bool,
    /// The follower the controller uses (written into its configuration).
    #[arg(long, value_enum, default_value_t = FollowerKind::Optimal)]
    follower: FollowerKind,
    /// The ANFIS model for --follower anfis.
    #[arg(long)]
    anfis_model: Option<PathBuf>,
    /// Wait (up to 60 s) for a controller started separately: the clock starts at its
    /// first heartbeat.
    #[arg(long)]
    wait_for_controller: bool,
    /// HIL in lockstep: the simulator publishes each controller tick on the clock wire
    /// (wires.json's clock_service) and waits for the controller's acknowledgement, so
    /// the run is deterministic and as fast as both go (not real time). The controller
    /// started here gets `--lockstep SERVICE`; one started separately must be given it.
    #[arg(long, conflicts_with = "sil")]
    lockstep: bool,
    /// Path of the GPS link (a symlink to the pty) the controller opens.
    #[arg(long)]
    gps_link: Option<PathBuf>,
    /// Names this run's iceoryx2 services and default GPS link.
    #[arg(long)]
    run_id: Option<String>,
    /// Seconds between status lines, 0.001 to 3600.
    #[arg(long, default_value_t = 0.5, value_parser = number(0.001, 3600.0, "seconds"))]
    status_every: f64,
    /// HIL: SCHED_FIFO priority of the tick loop, 0 (ordinary scheduling) to 99;
    /// needs root or CAP_SYS_NICE, and runs on without it, saying so. The controller
    /// it starts sets its own (`ugv-controller run --rt-priority`).
    #[arg(long, default_value_t = realtime::DEFAULT_PRIORITY, value_parser = realtime::parse_priority)]
    rt_priority: u8,
    /// HIL in a private network namespace (ugv-RUN_ID): the CAN interface is created
    /// there, with the simulator and the controller, and no other process can open it
    /// (needs root). Look in with `sudo ip netns exec ugv-RUN_ID candump IFACE`.
    #[arg(long)]
    isolate: bool,
    /// A fault plan (`[[faults]]` and `[expect]`, as in a scenario) added to the
    /// scenario's own; see docs/faults.md.
    #[arg(long, value_name = "FILE")]
    faults: Option<PathBuf>,
    /// Do not record the run (by default run.mcap, bus.log and gps.nmea go into the
    /// results directory; see docs/recording.md).
    #[arg(long)]
    no_record: bool,
    /// Do not draw the run (by default figure.svg and figure.png go into the results
    /// directory); the verdict and the traces are written all the same.
    #[arg(long)]
    no_figures: bool,
    /// SIL only: at most this many times faster than real time (1: real time), 0.01
    /// to 10000; for watching a run as it goes, or stopping it midway.
    #[arg(long, value_parser = number(0.01, 10_000.0, "times real time"))]
    pace: Option<f64>,
    /// Serve the run live over the Foxglove WebSocket protocol on ADDR, an IP address
    /// and port (127.0.0.1:8765 when no ADDR is given): the topics of run.mcap, with
    /// --no-record too. In Foxglove: Open connection -> Foxglove WebSocket ->
    /// ws://ADDR. In SIL it implies --pace 1 (real time) unless --pace is given.
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        default_missing_value = live::DEFAULT_ADDR_TEXT,
        value_parser = live::parse_addr
    )]
    live: Option<SocketAddr>,
}

fn main() -> ExitCode {
    // The tracing events of the libraries (firmware-bridge's) on stderr: warnings (the
    // CoLa-A server, the gateways), or what RUST_LOG asks for (info: the lines the
    // controller writes on the GPS port).
    firmware_bridge::cli::init_logging("warn");
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ugv-sim: {e:#}");
            ExitCode::from(Exit::Setup.code())
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
                // The checks `run` makes before it starts anything.
                let checked = Scenario::load(&path)
                    .map_err(anyhow::Error::from)
                    .and_then(|s| {
                        checked_controller_config(&s, FollowerKind::Optimal, None)
                            .map(|_| s)
                            .map_err(|e| {
                                anyhow::anyhow!(
                                    "{}: the controller's configuration for it: {e}",
                                    path.display()
                                )
                            })
                    });
                match checked {
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
        Command::Run(args) => run_scenario(args),
        Command::Ecu {
            kind,
            can,
            scenario,
            status_every,
            rt_priority,
        } => run_ecu(kind, &can, scenario.as_ref(), status_every, rt_priority),
        Command::Suite(args) => run_suite(args),
        Command::Replay { recording, trace } => replay(&recording, trace.as_deref()),
        Command::Merge { shards, out } => merge_shards(&shards, &out),
        Command::WayThrough(args) => way_through(&args),
    }
}

/// `ugv-sim way-through`: search each world, print what was found, write the list.
fn way_through(args: &WayThroughArgs) -> Result<ExitCode> {
    use ugv_sim::way_through::{Options, WayThrough};
    let opts = Options {
        margin: args.margin,
        steer_usage: args.steer_usage,
        xy_res: args.xy_res,
        heading_bins: usize::from(args.heading_bins),
        max_expansions: args.expansions as usize,
    };
    let results = ugv_sim::way_through::search_all(&args.scenarios, &opts, usize::from(args.jobs))?;
    let (mut none, mut undecided) = (Vec::new(), 0);
    for (path, found, wall) in &results {
        let stem = path.file_stem().unwrap_or_default().to_string_lossy();
        let what = match found {
            WayThrough::Found {
                length,
                cusps,
                expansions,
            } => format!("way through: {length:.2} m, {cusps} cusps ({expansions} expansions)"),
            WayThrough::None { expansions, why } => {
                none.push(stem.to_string());
                format!("NO way through: {why} ({expansions} expansions)")
            }
            WayThrough::Undecided { expansions } => {
                undecided += 1;
                format!("undecided: {expansions} expansions without the goal")
            }
        };
        println!("{stem}: {what} [{wall:.1} s]");
    }
    println!(
        "{} worlds: {} with a way through, {} with none, {undecided} undecided",
        results.len(),
        results.len() - none.len() - undecided,
        none.len()
    );
    if let Some(list) = &args.list {
        let text: String = none.iter().map(|s| format!("{s}\n")).collect();
        std::fs::write(list, text).with_context(|| format!("writing {}", list.display()))?;
    }
    Ok(if undecided > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// Ctrl-C and SIGTERM raise the returned flag.
fn stop_on_signal() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(stop)
}

fn run_ecu(
    kind: EcuKind,
    can: &str,
    scenario: Option<&PathBuf>,
    status_every: f64,
    rt_priority: u8,
) -> Result<ExitCode> {
    anyhow::ensure!(
        status_every > 0.0 && status_every.is_finite(),
        "--status-every must be positive"
    );
    let sc = Scenario::load_or_paper(scenario)?;
    // Read through a horizon, with a deep queue: a stalled host does not make it
    // miss the controller's frames (firmware_bridge::can::timed).
    let horizon = Horizon::new();
    let port = CanPort::open_timed(can, horizon.clone(), None, None)
        .with_context(|| format!("{kind:?} ECU on {can}"))?;
    port.accept_only(&kind.accepts())
        .with_context(|| format!("{kind:?} ECU's acceptance filter on {can}"))?;
    let stop = stop_on_signal()?;
    eprintln!(
        "ugv-sim: simulated {kind:?} ECU on {can} (parameters of scenario {:?}), {} Hz; Ctrl-C ends it",
        sc.name, sc.sim.physics_hz
    );
    let rt_sched = realtime::promote(rt_priority);
    eprintln!("ugv-sim: {}", rt_sched.promotion.describe("ECU loop"));
    let mut clock = WallClock::new(1.0 / sc.sim.physics_hz);
    let fin = run_standalone(
        kind,
        &sc.ecu_sections(),
        port,
        Some(&horizon),
        &mut clock,
        &stop,
        status_every,
        &mut |s| {
            let unit = match kind {
                EcuKind::Steering => "°",
                EcuKind::Throttle => " m/s",
            };
            eprintln!(
                "t={:8.2}s {}{} {:7.2}{unit} sent {} e2e ok {} rejected {}",
                s.time,
                if s.enabled { "enabled" } else { "disabled" },
                s.fault.map(|c| format!(" SAFE({c:?})")).unwrap_or_default(),
                s.value,
                s.stats.sent,
                s.stats.e2e.accepted,
                s.stats.e2e.rejected(),
            );
        },
    )?;
    println!("{}", serde_json::to_string_pretty(&fin)?);
    Ok(ExitCode::SUCCESS)
}

fn replay(path: &std::path::Path, trace: Option<&std::path::Path>) -> Result<ExitCode> {
    use ugv_sim::record::replay::{DAMAGED_EXIT, Recorded, Tolerance, replay};
    let started = std::time::Instant::now();
    let rec = match Recorded::read(path) {
        Ok(rec) => rec,
        Err(e) if e.is_damaged() => {
            eprintln!("ugv-sim: {e}");
            return Ok(ExitCode::from(DAMAGED_EXIT));
        }
        Err(e) => return Err(e.into()),
    };
    let trace = trace
        .map(|p| {
            let file = std::fs::File::create(p)
                .with_context(|| format!("creating the trace {}", p.display()))?;
            TraceWriter::new(Some(file), None)
                .with_context(|| format!("writing the trace {}", p.display()))
        })
        .transpose()?;
    if let Some(why) = &rec.truncated {
        eprintln!(
            "ugv-sim: {} ends early ({why}): replaying up to the last instant it holds whole",
            path.display()
        );
    }
    let report = replay(&rec, Tolerance::for_mode(rec.info.mode), trace)?;
    let wall = started.elapsed().as_secs_f64();
    let compared: u64 = report.messages.values().map(|m| m.replayed).sum();
    eprintln!(
        "ugv-sim: replayed {:.1} s of {:?} ({:?} recording) in {wall:.2} s ({:.0}x real time): {compared} commands, {}",
        report.replayed_s,
        report.scenario,
        report.mode,
        report.replayed_s / wall.max(1e-9),
        match &report.divergence {
            None => "all as recorded".to_owned(),
            Some(d) => format!(
                "first divergence at {:.3} s in {}{}: recorded {}, replayed {}",
                d.time_s,
                d.message,
                d.signal
                    .as_ref()
                    .map(|s| format!(".{s}"))
                    .unwrap_or_default(),
                d.recorded.as_deref().unwrap_or("nothing"),
                d.replayed.as_deref().unwrap_or("nothing"),
            ),
        }
    );
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(if report.identical() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `ugv-sim run`: the scenario with the command line's changes, in SIL or in HIL.
fn run_scenario(args: RunArgs) -> Result<ExitCode> {
    let (sc, cfg) = scenario_to_run(&args)?;
    anyhow::ensure!(
        !(args.sil && args.isolate),
        "--isolate is for HIL runs (SIL has no wires)"
    );
    anyhow::ensure!(
        args.sil || args.pace.is_none(),
        "--pace is for SIL runs (HIL runs in real time)"
    );
    // Started before anything else (in HIL before the endpoints, which may enter a
    // private network namespace): the server's threads and socket are the host's.
    let live = start_live(args.live)?;
    if args.sil {
        run_sil(&sc, &cfg, &args, live)
    } else {
        run_hil(&sc, &cfg, &args, live)
    }
}

/// The scenario `ugv-sim run` runs, with the command line's changes checked in it, and
/// the controller's configuration for it; the results folder is created.
fn scenario_to_run(args: &RunArgs) -> Result<(Scenario, ControllerConfig)> {
    let sc = Scenario::load_or_paper(args.scenario.as_ref())?;
    let faults = match &args.faults {
        Some(file) => Some(ugv_sim::faults::plan::PlanFile::load(file)?),
        None => None,
    };
    // A bench file is checked on its own first (its errors name its lines), against
    // the bus the run will have.
    let iface = args.can.as_deref().unwrap_or(&sc.can.interface);
    let devices = match &args.devices {
        Some(bench) => Some(DeviceMap::load(bench, iface)?),
        None => None,
    };
    // Every change is checked with the whole scenario it ends up in.
    let overrides = Overrides {
        can: args.can.clone(),
        devices,
        time_limit_s: args.time_limit,
        faults,
    };
    let sc = sc
        .with_overrides(overrides)
        .map_err(|e| anyhow::anyhow!("the scenario with the command line's changes: {e}"))?;
    let cfg = checked_controller_config(&sc, args.follower, args.anfis_model.clone())
        .map_err(|e| anyhow::anyhow!("the controller's configuration for the scenario: {e}"))?;
    std::fs::create_dir_all(&args.results)
        .with_context(|| format!("creating {}", args.results.display()))?;
    eprintln!("ugv-sim: scenario {:?}: {}", sc.name, sc.description);
    Ok((sc, cfg))
}

/// The live view `--live` asks for, started and said how to connect to (none without
/// `--live`).
fn start_live(addr: Option<SocketAddr>) -> Result<Option<Arc<LiveView>>> {
    Ok(match addr {
        Some(addr) => {
            let view = LiveView::start(addr)?;
            eprintln!("ugv-sim: {}", view.how_to_connect());
            Some(Arc::new(view))
        }
        None => None,
    })
}

/// `ugv-sim run --sil`: the scenario in lockstep with the controller library, paced as
/// asked; the verdict written and printed.
fn run_sil(
    sc: &Scenario,
    cfg: &ControllerConfig,
    args: &RunArgs,
    live: Option<Arc<LiveView>>,
) -> Result<ExitCode> {
    let started = std::time::Instant::now();
    let outputs = ugv_sim::record::Outputs {
        dir: (!args.no_record).then_some(args.results.as_path()),
        live: live.as_deref(),
    };
    // A viewer sees the run as it goes: real time unless --pace says otherwise.
    let pace = args.pace.or(live.as_ref().map(|_| 1.0));
    if live.is_some() && args.pace.is_none() {
        eprintln!("ugv-sim: SIL paced at real time for the live view (--pace X to change)");
    }
    let paced = move |t: f64, _: &mut ugv_sim::sil::SilController| {
        if let Some(due) = pace.map(|p| std::time::Duration::from_secs_f64(t / p)) {
            std::thread::sleep(due.saturating_sub(started.elapsed()));
        }
        Hook::Continue
    };
    let run = ugv_sim::sil::run_sil_outputs(sc.clone(), cfg, paced, outputs)?;
    let wall = started.elapsed().as_secs_f64();
    if let Some(s) = &run.recording {
        eprintln!("ugv-sim: {}", ugv_sim::record::describe(s));
    }
    let end = RunEnd {
        mode: Mode::Sil,
        report: run.sim.report(run.outcome.clone()),
        driven: &run.sim.trajectory,
        trace: Some(&run.trace),
    };
    let verdict = judge_and_write(
        sc,
        end,
        cfg.perception.detection_radius,
        &args.results,
        !args.no_figures,
        |_| {},
    )?;
    eprintln!(
        "ugv-sim: SIL {:.1} s simulated in {wall:.2} s ({:.0}x real time)",
        verdict.time(),
        verdict.time() / wall.max(1e-9)
    );
    println!("{}", serde_json::to_string_pretty(&verdict)?);
    Ok(ExitCode::from(
        Exit::of_run(&run.outcome, verdict.passed).code(),
    ))
}

/// `ugv-sim run` in HIL: the scenario in real time on the wires, with status lines as
/// it goes; the verdict printed.
fn run_hil(
    sc: &Scenario,
    cfg: &ControllerConfig,
    args: &RunArgs,
    live: Option<Arc<LiveView>>,
) -> Result<ExitCode> {
    let options = hil_options(sc, args, live);
    let stop = stop_on_signal()?;
    let tty = std::io::stderr().is_terminal();
    let mut log = |line: &str| {
        if tty {
            eprint!("\r\x1b[2K");
        }
        eprintln!("ugv-sim: {line}");
    };
    let endpoints = Endpoints::open(sc, &options, &mut log)?;
    let (verdict, outcome) =
        hil::run_scenario(sc, cfg, endpoints, &options, &stop, &mut log, &mut |s| {
            if tty {
                eprint!("\r\x1b[2K{}", status_line(s));
            } else {
                eprintln!("{}", status_line(s));
            }
        })?;
    if tty {
        eprintln!();
    }
    println!("{}", serde_json::to_string_pretty(&verdict)?);
    Ok(ExitCode::from(
        Exit::of_run(&outcome, verdict.passed).code(),
    ))
}

/// The HIL options of `ugv-sim run`'s command line; the run id is the scenario's name
/// and the process id unless `--run-id` gives one.
fn hil_options(sc: &Scenario, args: &RunArgs, live: Option<Arc<LiveView>>) -> HilOptions {
    let run_id = args
        .run_id
        .clone()
        .unwrap_or_else(|| format!("{}-{}", sc.name, std::process::id()));
    HilOptions {
        controller: args.controller.clone(),
        controller_args: args.controller_args.clone(),
        wait_for_controller: args.wait_for_controller,
        gps_link: args.gps_link.clone(),
        isolate: args.isolate.then(|| ugv_sim::isolate::netns_name(&run_id)),
        run_id,
        results: args.results.clone(),
        status_every: args.status_every,
        record: !args.no_record,
        figures: !args.no_figures,
        controller_log: args.controller_log,
        live,
        rt_priority: args.rt_priority,
        lockstep: args.lockstep,
    }
}

/// `ugv-sim suite`: this shard's items of the folder (or only their ids, with
/// `--list`), run in SIL or HIL, and the summaries written.
fn run_suite(args: SuiteArgs) -> Result<ExitCode> {
    use ugv_sim::suite;
    let files = suite_files(&args)?;
    let shard = suite_shard(args.shard)?;
    let plan = Plan::new(&files, args.seeds, &args.vary)?;
    let info = plan.info(suite_settings(&args));
    let mine = plan.shard_items(shard);
    if args.list {
        for &i in &mine {
            println!("{}", plan.items[i].id);
        }
        return Ok(ExitCode::SUCCESS);
    }
    let total = mine.len();
    let (follower, anfis_model) = (args.follower, args.anfis_model.clone());
    let tune = move |sc: &Scenario| {
        let mut cfg = controller_config(sc, follower);
        cfg.follower.anfis_model = anfis_model.clone();
        cfg
    };
    let sil = suite::sil_runner_recording(&tune, args.record.then_some(args.results.as_path()));
    let stop = stop_on_signal()?;
    let hil_suite = HilSuite {
        controller: match &args.controller {
            Some(c) => c.clone(),
            None => std::env::current_exe()?.with_file_name("ugv-controller"),
        },
        cans: &args.cans,
        isolate: args.isolate,
        lockstep: args.lockstep,
        record: args.record,
        figures: !args.no_figures,
        results: &args.results,
        stop: &stop,
    };
    let hil_runner = |id: &str, sc: &Scenario, slot: usize| hil_suite.run(id, sc, slot, &tune);
    let (runner, jobs): (&suite::Runner<'_>, usize) = if args.hil {
        anyhow::ensure!(
            hil_suite.controller.is_file(),
            "{} is not a file (--controller)",
            hil_suite.controller.display()
        );
        // Isolated runs each have a bus of their own; otherwise one per interface.
        let parallel = if args.isolate {
            args.jobs.unwrap_or(1)
        } else {
            args.cans.len().max(1)
        };
        (&hil_runner, parallel)
    } else {
        (
            &sil,
            args.jobs
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        )
    };
    if shard != Shard::ALL || plan.items.len() > files.len() {
        eprintln!(
            "ugv-sim: {} items ({} scenarios x {} grid points x {} seeds); shard {shard}: {total}",
            plan.items.len(),
            files.len(),
            plan.groups.len() / files.len(),
            args.seeds,
        );
    }
    let started = std::time::Instant::now();
    let entries = run_with_progress(&plan, &mine, jobs, runner);
    let wall = started.elapsed().as_secs_f64();
    finish_suite(&args.results, info, shard, &entries, wall)
}

/// The scenario files of `ugv-sim suite`'s folder, after the checks of its command
/// line: some files, and the HIL options only with `--hil`.
fn suite_files(args: &SuiteArgs) -> Result<Vec<PathBuf>> {
    let files = ugv_sim::suite::scenario_files(&args.dir)
        .with_context(|| format!("reading {}", args.dir.display()))?;
    anyhow::ensure!(
        !files.is_empty(),
        "no scenario files (*.toml) in {}",
        args.dir.display()
    );
    anyhow::ensure!(
        args.hil || (args.controller.is_none() && args.cans.is_empty()),
        "--controller and --can are for --hil runs"
    );
    anyhow::ensure!(
        args.hil || !args.isolate,
        "--isolate is for --hil runs (SIL has no wires)"
    );
    Ok(files)
}

/// The shard to run: `--shard`, else the one a Kubernetes Indexed Job's environment
/// names, else all.
fn suite_shard(shard: Option<Shard>) -> Result<Shard> {
    Ok(match shard {
        Some(s) => s,
        None => Shard::from_env(|k| std::env::var(k).ok())
            .map_err(anyhow::Error::msg)?
            .unwrap_or(Shard::ALL),
    })
}

/// The suite's settings for its plan's record (items.json): the mode, the follower
/// and the ANFIS model.
fn suite_settings(args: &SuiteArgs) -> Vec<String> {
    vec![
        format!("mode={}", if args.hil { "hil" } else { "sil" }),
        format!("follower={:?}", args.follower),
        format!(
            "anfis_model={}",
            args.anfis_model
                .as_ref()
                .map_or_else(|| "-".to_owned(), |m| m.display().to_string())
        ),
    ]
}

/// What every HIL run of `ugv-sim suite --hil` shares.
#[derive(Debug)]
struct HilSuite<'a> {
    /// The controller binary each run starts.
    controller: PathBuf,
    /// The CAN interface of each slot (`--can`); the scenario's own when none.
    cans: &'a [String],
    /// Each run in a private network namespace of its own (`--isolate`).
    isolate: bool,
    /// Each run in lockstep (`--lockstep`).
    lockstep: bool,
    /// Record each run (`--record`).
    record: bool,
    /// Draw each run (not `--no-figures`).
    figures: bool,
    /// The suite's results folder; each run's go in a folder of its own in it.
    results: &'a std::path::Path,
    /// Raised by Ctrl-C and SIGTERM.
    stop: &'a AtomicBool,
}

impl HilSuite<'_> {
    /// Item `id`'s scenario `sc` in HIL on slot `slot`'s interface, the controller
    /// configured by `tune`: its verdict, or what went wrong in words.
    fn run(
        &self,
        id: &str,
        sc: &Scenario,
        slot: usize,
        tune: &dyn Fn(&Scenario) -> ControllerConfig,
    ) -> Result<ugv_sim::verdict::Verdict, String> {
        let overrides = Overrides {
            can: self.cans.get(slot).cloned(),
            ..Overrides::default()
        };
        let sc = sc
            .clone()
            .with_overrides(overrides)
            .map_err(|e| format!("with --can: {e}"))?;
        // The item's id as a name for folders, services and namespaces.
        let slug = ugv_sim::suite::item_dir_name(id);
        let run_id = format!("suite-{slug}-{}", std::process::id());
        let options = HilOptions {
            controller: Some(self.controller.clone()),
            controller_args: Vec::new(),
            wait_for_controller: false,
            gps_link: None,
            isolate: self.isolate.then(|| ugv_sim::isolate::netns_name(&run_id)),
            run_id,
            results: self.results.join(&slug),
            status_every: 1.0,
            record: self.record,
            figures: self.figures,
            controller_log: false,
            live: None,
            rt_priority: realtime::DEFAULT_PRIORITY,
            lockstep: self.lockstep,
        };
        std::fs::create_dir_all(&options.results).map_err(|e| e.to_string())?;
        let endpoints = Endpoints::open(&sc, &options, &mut |_| {}).map_err(|e| e.to_string())?;
        hil::run_scenario(
            &sc,
            &tune(&sc),
            endpoints,
            &options,
            self.stop,
            &mut |_| {},
            &mut |_| {},
        )
        .map(|(verdict, _)| verdict)
        .map_err(|e| e.to_string())
    }
}

/// The items `mine` of `plan`, run `jobs` at a time by `runner`: a line on stderr as
/// each ends, and on a terminal a progress bar with the ETA.
fn run_with_progress(
    plan: &Plan,
    mine: &[usize],
    jobs: usize,
    runner: &ugv_sim::suite::Runner<'_>,
) -> Vec<ugv_sim::suite::SuiteEntry> {
    let total = mine.len();
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(total as u64),
        indicatif::ProgressDrawTarget::stderr(),
    );
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {per_sec} ETA {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let entries = ugv_sim::suite::run_items(plan, mine, jobs, runner, &|done, e| {
        let width = 30;
        let filled = done * width / total.max(1);
        // The line per item stays (CI logs); the bar, on a terminal only, gives the ETA.
        bar.suspend(|| {
            eprintln!(
                "[{}{}] {done}/{total} {}: {}",
                "#".repeat(filled),
                ".".repeat(width - filled),
                ugv_sim::suite::ItemRecord::of(e).label(),
                if e.passed() { "passed" } else { "FAILED" }
            );
        });
        bar.inc(1);
    });
    bar.finish_and_clear();
    entries
}

/// The suite's summaries written into `results` and its pace said (`wall` seconds for
/// the `entries`): the exit code of the most severe item ([`Exit::of_suite`]).
fn finish_suite(
    results: &std::path::Path,
    info: PlanInfo,
    shard: Shard,
    entries: &[ugv_sim::suite::SuiteEntry],
    wall: f64,
) -> Result<ExitCode> {
    use ugv_sim::suite;
    let simulated: f64 = entries
        .iter()
        .filter_map(|e| e.verdict.as_ref().map(|v| v.time()))
        .sum();
    let shard_file = suite::ShardFile::of(info, shard, entries);
    let summary = suite::Summary::of(shard_file.items.iter().map(|i| i.record.clone()).collect());
    write_summaries(results, &summary, &shard_file)?;
    eprintln!(
        "ugv-sim: {simulated:.1} s simulated in {wall:.2} s ({:.0}x real time, {:.1} items/s); summaries in {}",
        simulated / wall.max(1e-9),
        entries.len() as f64 / wall.max(1e-9),
        results.display()
    );
    Ok(ExitCode::from(Exit::of_suite(&summary).code()))
}

/// summary.md (also printed), summary.json, junit.xml and items.json in `dir`.
fn write_summaries(
    dir: &std::path::Path,
    summary: &ugv_sim::suite::Summary,
    shard: &ugv_sim::suite::ShardFile,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    let md = summary.markdown();
    write("summary.md", &md)?;
    write("summary.json", &summary.json())?;
    write("junit.xml", &summary.junit())?;
    // Last, and whole or not at all: a merge waiting for it never reads half a file.
    write("items.json.partial", &serde_json::to_string_pretty(shard)?)?;
    std::fs::rename(dir.join("items.json.partial"), dir.join("items.json"))
        .with_context(|| format!("writing {}", dir.join("items.json").display()))?;
    print!("{md}");
    Ok(())
}

fn merge_shards(shards: &[PathBuf], out: &std::path::Path) -> Result<ExitCode> {
    let files = ugv_sim::suite::read_shards(shards, out)?;
    let (summary, merged) = ugv_sim::suite::merge(&files)?;
    write_summaries(out, &summary, &merged)?;
    eprintln!(
        "ugv-sim: {} shards, {} items merged into {}",
        files.len(),
        merged.items.len(),
        out.display()
    );
    Ok(ExitCode::from(Exit::of_suite(&summary).code()))
}
