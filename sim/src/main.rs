//! `ugv-sim`: the golf car's simulator.
//!
//! ```text
//! ugv-sim run [SCENARIO] --controller target/release/ugv-controller   HIL, the real wires
//! ugv-sim run [SCENARIO] --wait-for-controller                        HIL, your controller
//! ugv-sim run [SCENARIO] --sil                                        lockstep, in-process
//! ugv-sim check SCENARIO...                                           validate scenario files
//! ```
//!
//! Exit codes of `run`: 0 goal reached, 1 collision, 2 time limit, 3 stopped (Ctrl-C),
//! 4 error.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use firmware_bridge::CanPort;
use ugv_controller::config::FollowerKind;
use ugv_sim::hil::{Wires, run_hil, spawn_controller, wait_for_controller};
use ugv_sim::mission::controller_config;
use ugv_sim::run::Snapshot;
use ugv_sim::verdict::{Verdict, write_results};
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
    /// Run a scenario: in real time on the real wires (HIL; the default), or with the
    /// controller library in lockstep (--sil).
    Run(RunArgs),
    /// Run every scenario of a folder in SIL, in parallel, and write summary.md,
    /// summary.json and junit.xml. Exit code 0 when all pass, 1 otherwise.
    Suite {
        /// The folder of scenario files (*.toml).
        dir: PathBuf,
        /// Where the summaries go.
        #[arg(long, default_value = "results/suite")]
        results: PathBuf,
        /// Parallel runs; default: the number of cores.
        #[arg(long)]
        jobs: Option<usize>,
        #[arg(long, value_enum, default_value_t = FollowerKind::Optimal)]
        follower: FollowerKind,
        #[arg(long)]
        anfis_model: Option<PathBuf>,
    },
    /// Validate scenario files: parse, check every field, and report the first error
    /// of each with its file, line and field.
    Check {
        #[arg(required = true)]
        scenarios: Vec<PathBuf>,
    },
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Scenario file (TOML); the seed paper's scenario when absent.
    scenario: Option<PathBuf>,
    /// Lockstep software-in-the-loop with the built-in controller library: no wires,
    /// deterministic, faster than real time.
    #[arg(long)]
    sil: bool,
    /// CAN interface of the simulated ECUs (overrides the scenario's can.interface).
    #[arg(long)]
    can: Option<String>,
    /// End the run after this many seconds (overrides sim.time_limit_s).
    #[arg(long)]
    time_limit: Option<f64>,
    /// Directory for verdict.json, trace.json, figure.svg and figure.png.
    #[arg(long, default_value = "results")]
    results: PathBuf,
    /// Start this controller binary with the wire locations (HIL); see the README
    /// for the command line it is given.
    #[arg(long, value_name = "BINARY")]
    controller: Option<PathBuf>,
    /// Extra arguments for the controller binary (repeatable).
    #[arg(long = "controller-arg", allow_hyphen_values = true)]
    controller_args: Vec<String>,
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
    /// Path of the GPS link (a symlink to the pty) the controller opens.
    #[arg(long)]
    gps_link: Option<PathBuf>,
    /// Names this run's iceoryx2 services and default GPS link.
    #[arg(long)]
    run_id: Option<String>,
    /// Seconds between status lines.
    #[arg(long, default_value_t = 0.5)]
    status_every: f64,
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
        Command::Run(args) => run_scenario(args),
        Command::Suite {
            dir,
            results,
            jobs,
            follower,
            anfis_model,
        } => run_suite(&dir, &results, jobs, follower, anfis_model),
    }
}

fn exit_code(outcome: &Outcome) -> u8 {
    match outcome {
        Outcome::GoalReached { .. } => 0,
        Outcome::Collision { .. } => 1,
        Outcome::TimeLimit { .. } => 2,
        Outcome::Stopped { .. } => 3,
    }
}

fn run_scenario(args: RunArgs) -> Result<ExitCode> {
    let mut sc = Scenario::load_or_paper(args.scenario.as_ref())?;
    if let Some(iface) = &args.can {
        sc.can.interface = iface.clone();
    }
    if let Some(limit) = args.time_limit {
        anyhow::ensure!(
            limit > 0.0 && limit.is_finite(),
            "--time-limit must be positive"
        );
        sc.sim.time_limit_s = limit;
    }
    let mut cfg = controller_config(&sc, args.follower);
    cfg.follower.anfis_model = args.anfis_model.clone();
    cfg.validate().map_err(|(field, message)| {
        anyhow::anyhow!("controller configuration: {field}: {message}")
    })?;
    std::fs::create_dir_all(&args.results)
        .with_context(|| format!("creating {}", args.results.display()))?;
    eprintln!("ugv-sim: scenario {:?}: {}", sc.name, sc.description);

    if args.sil {
        let started = std::time::Instant::now();
        let run = ugv_sim::sil::run_sil(sc.clone(), &cfg)?;
        let wall = started.elapsed().as_secs_f64();
        let report = run.sim.report(run.outcome.clone());
        let verdict = Verdict::judge("sil", &sc, report, Some(&run.trace));
        eprintln!(
            "ugv-sim: SIL {:.1} s simulated in {wall:.2} s ({:.0}x real time)",
            verdict.time(),
            verdict.time() / wall.max(1e-9)
        );
        write_results(
            &args.results,
            &sc,
            &verdict,
            &run.sim.trajectory,
            Some(&run.trace),
            cfg.perception.detection_radius,
        )?;
        println!("{}", serde_json::to_string_pretty(&verdict)?);
        return Ok(ExitCode::from(exit_code(&run.outcome)));
    }

    let iface = sc.can.interface.clone();
    let run_id = args
        .run_id
        .clone()
        .unwrap_or_else(|| format!("{}-{}", sc.name, std::process::id()));
    let gps_link = args
        .gps_link
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join(format!("ugv-hil-{run_id}-gps")));
    let steering = CanPort::open(&iface).context("steering ECU")?;
    let throttle = CanPort::open(&iface).context("throttle ECU")?;
    let mut sim = Sim::new(sc.clone(), steering, throttle).with_sensors()?;
    let mut wires = Wires::open(&sim, &gps_link, &run_id)?;
    eprintln!(
        "ugv-sim: wires: GPS {} ({} baud), laser iceoryx2 service {:?}, CAN {} (steering and throttle ECUs, golf_car.dbc)",
        wires.map.gps_link.display(),
        wires.map.gps_baud,
        wires.map.laser_service,
        wires.map.can
    );
    std::fs::write(
        args.results.join("wires.json"),
        serde_json::to_string_pretty(&wires.map)?,
    )?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;

    let mut controller = match &args.controller {
        Some(binary) => {
            let config = args.results.join("controller.toml");
            std::fs::write(&config, toml::to_string_pretty(&cfg)?)?;
            let trace = args.results.join("controller-trace.json");
            let _ = std::fs::remove_file(&trace);
            eprintln!(
                "ugv-sim: starting {} (configuration {})",
                binary.display(),
                config.display()
            );
            Some(spawn_controller(
                binary,
                &config,
                &wires.map,
                &trace,
                &args.controller_args,
            )?)
        }
        None => None,
    };
    if args.wait_for_controller && controller.is_none() {
        eprintln!("ugv-sim: waiting for a controller heartbeat on {iface}");
        if !wait_for_controller(&iface, Duration::from_secs(60), &stop)? {
            return Ok(ExitCode::from(3));
        }
    }
    eprintln!(
        "ugv-sim: physics {} Hz, time limit {} s; Ctrl-C ends the run",
        sc.sim.physics_hz, sc.sim.time_limit_s
    );
    let tty = std::io::stderr().is_terminal();
    let outcome = run_hil(
        &mut sim,
        &mut wires,
        controller.as_mut(),
        &stop,
        args.status_every,
        &mut |s| {
            if tty {
                eprint!("\r\x1b[2K{}", status_line(s));
            } else {
                eprintln!("{}", status_line(s));
            }
        },
    );
    if tty {
        eprintln!();
    }
    // Whatever happened, the controller is asked to finish and its trace collected.
    let trace = controller.as_mut().and_then(|c| {
        let status = c.finish(Duration::from_secs(5));
        eprintln!("ugv-sim: controller finished: {status:?}");
        std::fs::read_to_string(&c.trace)
            .ok()
            .and_then(|t| serde_json::from_str::<ugv_controller::trace::Trace>(&t).ok())
    });
    let outcome = outcome?;
    let (lines, last) = wires.gps_input();
    if lines > 0 {
        eprintln!("ugv-sim: the controller wrote {lines} lines to the GPS port (last: {last:?})");
    }
    let verdict = Verdict::judge("hil", &sc, sim.report(outcome.clone()), trace.as_ref());
    write_results(
        &args.results,
        &sc,
        &verdict,
        &sim.trajectory,
        trace.as_ref(),
        cfg.perception.detection_radius,
    )?;
    println!("{}", serde_json::to_string_pretty(&verdict)?);
    Ok(ExitCode::from(exit_code(&outcome)))
}

fn run_suite(
    dir: &std::path::Path,
    results: &std::path::Path,
    jobs: Option<usize>,
    follower: FollowerKind,
    anfis_model: Option<PathBuf>,
) -> Result<ExitCode> {
    use ugv_sim::suite;
    let files = suite::scenario_files(dir).with_context(|| format!("reading {}", dir.display()))?;
    anyhow::ensure!(
        !files.is_empty(),
        "no scenario files (*.toml) in {}",
        dir.display()
    );
    let jobs = jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let total = files.len();
    let tune = move |sc: &Scenario| {
        let mut cfg = controller_config(sc, follower);
        cfg.follower.anfis_model = anfis_model.clone();
        cfg
    };
    let started = std::time::Instant::now();
    let entries = suite::run_suite(&files, jobs, &tune, &|done, e| {
        let width = 30;
        let filled = done * width / total;
        eprintln!(
            "[{}{}] {done}/{total} {}: {}",
            "#".repeat(filled),
            ".".repeat(width - filled),
            e.name,
            if e.passed() { "passed" } else { "FAILED" }
        );
    });
    let wall = started.elapsed().as_secs_f64();
    let simulated: f64 = entries
        .iter()
        .filter_map(|e| e.verdict.as_ref().map(|v| v.time()))
        .sum();
    std::fs::create_dir_all(results).with_context(|| format!("creating {}", results.display()))?;
    let md = suite::markdown(&entries);
    std::fs::write(results.join("summary.md"), &md)?;
    std::fs::write(
        results.join("summary.json"),
        serde_json::to_string_pretty(&entries)?,
    )?;
    std::fs::write(results.join("junit.xml"), suite::junit(&entries))?;
    print!("{md}");
    eprintln!(
        "ugv-sim: {simulated:.1} s simulated in {wall:.2} s ({:.0}x real time); summaries in {}",
        simulated / wall.max(1e-9),
        results.display()
    );
    Ok(if entries.iter().all(|e| e.passed()) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
