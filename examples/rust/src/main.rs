//! A golf car controller of one's own on ugv-sim's wires (docs/wire-contract.md), in
//! Rust, with the project's crates doing the wire work: firmware-bridge opens the GPS
//! line (NMEA decoded into epochs), the laser's iceoryx2 service and the CAN port, whose
//! frames golf-car-can's codecs encode and decode with the E2E counter and CRC filled in
//! and checked; ugv-controller reads the run's controller.toml. What is left here is
//! the enable sequence and, at each GPS epoch, arcs of constant curvature scored by
//! their clearance to the laser's points and by the heading towards the goal at their end.
//!
//! `ugv-example-rust RESULTS_DIR` (the --results of `ugv-sim run --wait-for-controller`),
//! or `ugv-sim run --controller ugv-example-rust`, which gives it `run --config DIR/...`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use firmware_bridge::geodesy::{LocalFrame, course_deg_to_theta, normalize_rad_pi};
use firmware_bridge::nmea::{NmeaLink, ReaderConfig, open_serial};
use firmware_bridge::{CanPort, GpsReading, LaserFrame, LaserSubscriber, Received};
use golf_car_can::{CanMessage, ControllerHeartbeat, ControllerHeartbeatState as Hb};
use golf_car_can::{FaultReport, GolfCarMessage as Msg, SteeringCmd, SteeringReport};
use golf_car_can::{ThrottleCmd, ThrottleCmdGear, ThrottleReport};
use ugv_controller::config::{ControllerConfig, Vehicle};

const SPEED: f64 = 1.8; // cruise, m/s
const LOOK: f64 = 8.0; // length of the arcs scored, m
const CLEAR: f64 = 1.6; // rear-axle line to a laser point, at least, m (half width 0.6 m + margin)
const ARCS: usize = 15; // curvatures scored, -max to +max
const SETUP: Duration = Duration::from_secs(60); // ugv-sim's wait for the heartbeat
type Pose = (f64, f64, f64); // the rear axle, east/north at the datum (m), theta (rad)
type Point = (f64, f64); // in the car's frame: x forward, y left (m)

/// wires.json: where the simulator's ends of the wires are.
#[derive(Debug, serde::Deserialize)]
struct Wires {
    version: u32,
    gps_link: PathBuf,
    gps_baud: u32,
    laser_service: String,
    can: String,
}

/// The results directory: the argument, or --config's folder.
fn results_dir() -> Result<PathBuf> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let config = args.iter().position(|a| a == "--config");
    match (config.map(|i| args.get(i + 1)), args.as_slice()) {
        (Some(Some(file)), _) => Ok(Path::new(file).parent().unwrap_or(Path::new(".")).into()),
        (None, [dir]) if !dir.starts_with('-') => Ok(dir.into()),
        _ => bail!("usage: ugv-example-rust RESULTS_DIR (examples/rust/README.md)"),
    }
}

/// The wires and the configuration, once the simulator has written them all
/// (controller.toml last).
fn wires_and_config(dir: &Path) -> Result<(Wires, ControllerConfig)> {
    let (config, deadline) = (dir.join("controller.toml"), Instant::now() + SETUP);
    while !config.is_file() {
        let missing = config.display();
        ensure!(
            Instant::now() < deadline,
            "no {missing} after 60 s: is ugv-sim running?"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let path = dir.join("wires.json");
    let shown = path.display();
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {shown}"))?;
    let wires: Wires = serde_json::from_str(&text).with_context(|| format!("{shown}"))?;
    let v = wires.version;
    ensure!(v == 1, "{shown}: version {v}, this example reads 1");
    Ok((wires, ControllerConfig::load(&config)?))
}

/// The curvature to drive and the clearance it keeps (None: every arc is blocked).
fn plan(pose: Pose, points: &[Point], cfg: &ControllerConfig) -> Option<(f64, f64)> {
    let ((x, y, th), v, m) = (pose, &cfg.vehicle, &cfg.mission);
    let kmax = v.max_steer_deg.min(30.0).to_radians().tan() / v.wheelbase;
    let look = (m.goal_x - x).hypot(m.goal_y - y).clamp(2.0, LOOK);
    let mut best: Option<(f64, f64, f64)> = None;
    for k in (0..ARCS).map(|i| kmax * (2.0 * i as f64 / (ARCS - 1) as f64 - 1.0)) {
        let r = if k.abs() < 1e-6 { 1e6 } else { 1.0 / k }; // a straight line: a huge circle
        let clear = (points.iter())
            .filter(|&&(px, py)| (-0.5..look).contains(&((px / r).atan2((r - py) / r) * r)))
            .map(|&(px, py)| (px.hypot(py - r) - r.abs()).abs()) // distance off the arc
            .fold(f64::INFINITY, f64::min);
        if clear < CLEAR {
            continue;
        }
        let (ex, ey) = ((look / r).sin() * r, (1.0 - (look / r).cos()) * r);
        let (s, c) = th.sin_cos();
        let (wx, wy) = (x + ex * c - ey * s, y + ex * s + ey * c);
        let cost = normalize_rad_pi((m.goal_y - wy).atan2(m.goal_x - wx) - th - look / r).abs();
        if best.is_none_or(|(least, ..)| cost < least) {
            best = Some((cost, k, clear));
        }
    }
    best.map(|(_, k, clear)| (k, clear))
}

/// The enable sequence (docs/wire-contract.md).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum State {
    #[default]
    Wait,
    Auto,
    Edge,
    Drive,
}

/// What the controller has seen of the car and what it does.
#[derive(Default)]
struct Car {
    pose: Option<Pose>,
    points: Option<Vec<Point>>, // the newest scan
    steering: Option<SteeringReport>,
    throttle: Option<ThrottleReport>,
    last_report: Option<Instant>,
    state: State,
    since: Option<Instant>,
    k: f64,
    speed: f64,
}

impl Car {
    /// An epoch: the antenna's position (GGA) and heading (HDT) as the rear axle's
    /// pose, and the arc to drive from it.
    fn fix(&mut self, fix: &GpsReading, frame: &LocalFrame, cfg: &ControllerConfig) {
        let (good, v) = (fix.quality.is_some_and(|q| q.has_position()), &cfg.vehicle);
        if let (true, Some(hdt), Some(p)) = (good, fix.heading_deg, fix.enu(frame)) {
            let th = course_deg_to_theta(hdt);
            let (s, c) = th.sin_cos();
            let x = p.east_m - c * v.antenna_x + s * v.antenna_y;
            self.pose = Some((x, p.north_m - s * v.antenna_x - c * v.antenna_y, th));
            self.drive(cfg);
        }
    }

    /// A scan's measurements within 10 m, as points in the car's frame.
    fn scan(&mut self, f: &LaserFrame, v: &Vehicle) {
        let to_car = |(a, r): (f32, f32)| {
            let (a, r) = (f64::from(a) + v.laser_yaw_deg.to_radians(), f64::from(r));
            (v.laser_x + r * a.cos(), v.laser_y + r * a.sin())
        };
        let near = f.valid_beams().filter(|&(_, r)| r < 10.0);
        self.points = Some(near.map(to_car).collect());
    }

    /// The ECUs' reports; the port checks E2E and counts what it rejects.
    fn receive(&mut self, can: &mut CanPort, now: Instant) {
        while let Some(received) = can.try_recv() {
            match received {
                Received::Message(Msg::SteeringReport(r)) => self.steering = Some(r),
                Received::Message(Msg::ThrottleReport(r)) => self.throttle = Some(r),
                other => {
                    eprintln!("ugv-example-rust: CAN {other:?}"); // a FAULT_REPORT, a rejection
                    continue;
                }
            }
            self.last_report = Some(now);
        }
    }

    /// Heartbeat idle until GPS, laser and both reports are there, then auto, then at
    /// least one auto heartbeat later the Enable 0 -> 1 edge; again if an ECU drops out.
    fn step(&mut self, now: Instant) {
        let (st, th) = (self.steering, self.throttle);
        let enabled = st.is_some_and(|r| r.enabled) && th.is_some_and(|r| r.enabled);
        let ready = self.pose.is_some() && self.points.is_some() && st.is_some() && th.is_some();
        let waited = self.since.map_or(Duration::ZERO, |t| now - t);
        let next = match self.state {
            State::Wait if ready => State::Auto,
            State::Auto if waited > Duration::from_millis(60) => State::Edge,
            State::Edge if enabled => {
                eprintln!("ugv-example-rust: both ECUs enabled, driving");
                State::Drive
            }
            State::Edge | State::Drive if !enabled && waited > Duration::from_secs(1) => {
                let faults = (st.map(|r| r.fault), th.map(|r| r.fault));
                eprintln!("ugv-example-rust: ECUs not enabled (faults {faults:?}), enabling again");
                State::Auto
            }
            _ => return,
        };
        (self.state, self.since, self.k, self.speed) = (next, Some(now), 0.0, 0.0);
    }

    /// At a new fix while driving: the arc to follow, and how fast.
    fn drive(&mut self, cfg: &ControllerConfig) {
        let (Some((x, y, th)), State::Drive) = (self.pose, self.state) else {
            return;
        };
        let arc = plan((x, y, th), self.points.as_deref().unwrap_or_default(), cfg);
        let m = &cfg.mission;
        let near = (m.goal_x - x).hypot(m.goal_y - y) < m.goal_tolerance;
        (self.k, self.speed) = match arc {
            Some((k, clear)) if !near => (k, if clear > 2.5 { SPEED } else { 1.0 }),
            _ => (0.0, 0.0),
        };
    }

    /// A 10 ms tick's commands, and the heartbeat every second tick.
    fn send(&self, can: &mut CanPort, tick: u64, wheelbase: f64) -> Result<()> {
        let enable = matches!(self.state, State::Edge | State::Drive);
        if tick.is_multiple_of(2) {
            let state = if self.state == State::Wait {
                Hb::Idle
            } else {
                Hb::Auto
            };
            can.send(&ControllerHeartbeat { state })?;
        }
        let (k, v) = (self.k, self.speed); // 0 but while driving
        let target_angle = (k * wheelbase).atan().to_degrees();
        can.send(&SteeringCmd {
            enable,
            target_angle,
            max_rate: 0.0,
        })?;
        let brake = if v > 0.0 { 0.0 } else { 100.0 };
        let gear = ThrottleCmdGear::Forward;
        can.send(&ThrottleCmd {
            enable,
            gear,
            brake,
            target_speed: v,
            accel_limit: 0.0,
        })?;
        if let (0, Some((x, y, th))) = (tick % 100, self.pose) {
            let (state, hdg) = (self.state, th.to_degrees());
            eprintln!("ugv-example-rust: {state:?} x={x:.2} y={y:.2} hdg={hdg:.0} v={v:.1}");
        }
        Ok(())
    }
}

/// Drive until the run is over: the GPS line closes, or the ECUs' reports stop (or a
/// signal); what ended it.
fn run(cfg: &ControllerConfig, wires: &Wires, car: &mut Car, stop: &AtomicBool) -> Result<String> {
    let port = open_serial(&wires.gps_link, wires.gps_baud, Duration::ZERO)?;
    let mut gps = NmeaLink::new(port, ReaderConfig::default());
    let laser = LaserSubscriber::new(&wires.laser_service)?; // the simulator's service, with its QoS
    let mut can = CanPort::open(&wires.can)?;
    can.accept_only(&[SteeringReport::ID, ThrottleReport::ID, FaultReport::ID])?;
    let frame = LocalFrame::new(cfg.mission.datum.geodetic())?;
    let (mut tick, mut next_tick) = (0, Instant::now());
    eprintln!("ugv-example-rust: {wires:?}");
    let end = 'run: loop {
        let now = Instant::now();
        match gps.next_fix(Duration::ZERO) {
            Ok(Some(fix)) => car.fix(&fix, &frame, cfg),
            Ok(None) => {}
            Err(e) => break 'run format!("the GPS line closed ({e})"),
        }
        if let Some(scan) = laser.try_recv_latest()? {
            car.scan(&scan, &cfg.vehicle);
        }
        car.receive(&mut can, now);
        let silent = car
            .last_report
            .is_some_and(|t| now - t > Duration::from_millis(500));
        if silent {
            break "the ECUs' reports stopped".to_owned();
        }
        if stop.load(Ordering::Relaxed) {
            break "stopped by a signal".to_owned();
        }
        car.step(now);
        if now >= next_tick {
            car.send(&mut can, tick, cfg.vehicle.wheelbase)?;
            tick += 1;
            next_tick =
                (next_tick + Duration::from_millis(10)).max(now - Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let rejected = can.stats().rejected();
    if stop.load(Ordering::Relaxed) {
        let idle = Car::default(); // leave the ECUs disabled, braking
        (0..3).try_for_each(|_| idle.send(&mut can, 0, cfg.vehicle.wheelbase))?;
    }
    Ok(format!("{end}; rejected {rejected}"))
}

fn main() -> Result<()> {
    firmware_bridge::cli::init_logging("warn"); // the crates' warnings; iceoryx2's errors only
    let dir = results_dir()?;
    let (wires, cfg) = wires_and_config(&dir)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))?;
    let mut car = Car::default();
    let end = run(&cfg, &wires, &mut car, &stop)?;
    let pose = car.pose;
    eprintln!("ugv-example-rust: run over: {end}; last pose {pose:?}");
    Ok(())
}
