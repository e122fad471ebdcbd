//! Recordings checked by readers that are not ours: the Python `mcap` package opens
//! run.mcap of a SIL run and finds the Foxglove schemas and the message counts the
//! verdict implies; `ugv-can decode` (can-dbc's CLI) reads bus.log; a SIL recording
//! replays into the controller byte for byte; a simulator killed with SIGKILL leaves
//! an MCAP readable up to about a second before the kill, which replays as recorded
//! up to the cut; a damaged recording is refused with its own exit code.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use ugv_controller::config::FollowerKind;
use ugv_controller::trace::{Trace, TraceWriter};
use ugv_e2e_tests::workspace_bin;
use ugv_sim::Scenario;
use ugv_sim::mission::controller_config;
use ugv_sim::record::replay::{DAMAGED_EXIT, Recorded, Tolerance, replay};
use ugv_sim::record::{BUS_LOG, MCAP_FILE, NMEA_FILE, RecordMode, RunInfo, topics};
use ugv_sim::sil::{Hook, SilRun, run_sil_recorded, run_sil_with};
use ugv_sim::verdict::Verdict;

fn mcap_summary(path: &Path) -> Value {
    ugv_e2e_tests::mcap_summary(path).unwrap()
}

/// The paper's scenario, recorded in SIL into `dir`, to its goal or for `limit` s.
fn recorded_paper_run(dir: &Path, limit: Option<f64>) -> (Scenario, SilRun) {
    let mut sc = Scenario::paper().unwrap();
    if let Some(limit) = limit {
        sc.sim.time_limit_s = limit;
    }
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    let run = run_sil_recorded(sc.clone(), &cfg, |_, _| Hook::Continue, Some(dir)).unwrap();
    (sc, run)
}

fn count(summary: &Value, topic: &str) -> u64 {
    summary["topics"][topic]["count"]
        .as_u64()
        .unwrap_or_else(|| panic!("no topic {topic} in {summary}"))
}

#[test]
fn python_mcap_finds_the_foxglove_schemas_and_the_counts_the_verdict_implies() {
    let dir = tempfile::tempdir().unwrap();
    let (sc, run) = recorded_paper_run(dir.path(), None);
    let verdict = Verdict::judge(
        ugv_sim::Mode::Sil,
        &sc,
        run.sim.report(run.outcome.clone()),
        Some(&run.trace),
    );
    assert!(verdict.passed, "{:?}", verdict.failures);
    let rec = run.recording.as_ref().expect("a recording");
    assert_eq!(rec.error, None);
    let s = mcap_summary(&dir.path().join(MCAP_FILE));
    assert_eq!(s["complete"], true, "{s}");
    assert_eq!(s["metadata"], serde_json::json!(["ugv-hil run"]));
    assert_eq!(s["attachments"], serde_json::json!(["controller.toml"]));
    for (topic, schema) in [
        (topics::LASER, "foxglove.LaserScan"),
        (topics::FIX, "foxglove.LocationFix"),
        (topics::TF, "foxglove.FrameTransform"),
        (topics::POSE, "foxglove.PoseInFrame"),
        (topics::OBSTACLES, "foxglove.SceneUpdate"),
        (topics::PLANS, "foxglove.SceneUpdate"),
    ] {
        let t = &s["topics"][topic];
        assert_eq!(t["schema"], schema, "{topic}: {t}");
        assert_eq!(t["message_encoding"], "protobuf", "{topic}: {t}");
    }
    for topic in [
        topics::CAN_RAW,
        topics::CAN_DECODED,
        topics::NMEA,
        topics::CONTROLLER_STATE,
    ] {
        assert_eq!(
            s["topics"][topic]["message_encoding"], "json",
            "{topic}: {s}"
        );
    }
    for (topic, t) in s["topics"].as_object().unwrap() {
        assert_eq!(t["monotonic"], true, "{topic}: {t}");
    }
    // The run lasted T simulated seconds (its ticks 0..=T): the laser at 50 Hz and
    // the GPS at its rate, each from t = 0.
    let t_end = verdict.time();
    let steps = (t_end * sc.sim.physics_hz).round() as u64;
    let per = |hz: f64| (steps as f64 / (sc.sim.physics_hz / hz)).floor() as u64 + 1;
    assert_eq!(sc.laser.spec().rate_hz, 50.0);
    assert_eq!(count(&s, topics::LASER), per(50.0), "T = {t_end}");
    assert_eq!(count(&s, topics::FIX), per(sc.gps.rate_hz), "T = {t_end}");
    let epoch = sc.sim.epoch.unix_ns();
    let last = s["topics"][topics::LASER]["last_ns"].as_u64().unwrap();
    assert!(
        last <= epoch + (t_end * 1e9) as u64 + 1
            && last + 20_000_000 > epoch + (t_end * 1e9) as u64
    );
    // Every NMEA sentence as sent: one message per line of gps.nmea.
    let nmea = std::fs::read_to_string(dir.path().join(NMEA_FILE)).unwrap();
    assert_eq!(count(&s, topics::NMEA), nmea.lines().count() as u64);
    assert!(nmea.lines().all(|l| l.starts_with('$')), "{}", &nmea[..200]);
    // Every CAN frame: one raw message per line of bus.log, one decoded per frame of
    // the DBC; the ECUs' reports are the frames the verdict says they sent; the
    // controller's frames are what each ECU received minus the other ECU's reports,
    // plus at most the last tick's (sent after the ECUs last read the bus).
    let bus = std::fs::read_to_string(dir.path().join(BUS_LOG)).unwrap();
    let frames = count(&s, topics::CAN_RAW);
    assert_eq!(frames, bus.lines().count() as u64);
    assert_eq!(count(&s, topics::CAN_DECODED), frames);
    assert_eq!(frames, rec.can_frames);
    let of = |id: &str| {
        bus.lines()
            .filter(|l| l.contains(&format!(" {id}#")))
            .count() as u64
    };
    let (st, th) = (&verdict.report.steering_can, &verdict.report.throttle_can);
    assert_eq!(of("101"), st.sent);
    assert_eq!(of("111"), th.sent);
    let controller = of("080") + of("100") + of("110");
    assert_eq!(
        controller + of("101") + of("111"),
        frames,
        "no other frames"
    );
    // The steering ECU's port saw the controller and the throttle ECU, except what
    // was sent in the last step (at most one throttle report, a heartbeat and two
    // commands); the ECU itself took only its node's messages: the heartbeat and its
    // commands, the throttle's went past its acceptance filter.
    let heard = st.e2e.accepted + st.e2e.rejected() + st.undecodable;
    let seen = heard + st.overheard - th.sent;
    assert!(
        (seen..=seen + 4).contains(&controller),
        "controller frames {controller}, the steering ECU's port saw {}",
        heard + st.overheard
    );
    let for_steering = of("080") + of("100");
    assert!(
        (heard..=heard + 2).contains(&for_steering),
        "heartbeats and steering commands {for_steering}, the steering ECU heard {heard}"
    );
    assert!(st.overheard + 2 >= of("110") + th.sent, "{st:?}");
    // The throttle ECU's endpoint filters on the memory bus itself: nothing reached it
    // to pass over.
    assert_eq!(th.overheard, 0, "{th:?}");
}

#[test]
fn ugv_can_decode_reads_bus_log_frame_for_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = recorded_paper_run(dir.path(), Some(6.0));
    let frames = run.recording.unwrap().can_frames;
    let out = Command::new(workspace_bin("ugv-can").unwrap())
        .args(["decode", "--json"])
        .arg(dir.path().join(BUS_LOG))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{frames} frames, 0 rejected by E2E, 0 malformed lines"
        )),
        "{stderr}"
    );
    let lines: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len() as u64, frames);
    assert!(
        lines
            .iter()
            .all(|l| l["e2e"] == "ok" && l["interface"] == "vcan0")
    );
    // Simulated time on the scenario's epoch, rising.
    let stamps: Vec<f64> = lines
        .iter()
        .map(|l| l["timestamp"].as_str().unwrap().parse().unwrap())
        .collect();
    let epoch = Scenario::paper().unwrap().sim.epoch.unix_s();
    assert!((stamps[0] - epoch).abs() < 1e-6, "{} vs {epoch}", stamps[0]);
    assert!(stamps.windows(2).all(|w| w[1] >= w[0]));
}

#[test]
fn a_sil_recording_replays_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = recorded_paper_run(dir.path(), Some(6.0));
    let rec = Recorded::read(&dir.path().join(MCAP_FILE)).unwrap();
    assert_eq!(rec.truncated, None);
    // The replayed controller's trace, as `ugv-sim replay --trace` writes it.
    let trace_path = dir.path().join("replay-trace.jsonl");
    let writer = TraceWriter::new(Some(std::fs::File::create(&trace_path).unwrap()), None);
    let report = replay(&rec, Tolerance::EXACT, Some(writer.unwrap())).unwrap();
    assert_eq!(report.divergence, None, "{report:?}");
    for name in ["CONTROLLER_HEARTBEAT", "STEERING_CMD", "THROTTLE_CMD"] {
        let m = &report.messages[name];
        assert!(m.recorded >= 300, "{name}: {m:?}");
        assert_eq!((m.replayed, m.matched), (m.recorded, m.recorded), "{name}");
    }
    assert!(report.controller_exit.is_none(), "{report:?}");
    assert_eq!(report.trace_error, None);
    // It planned the run's paths at the run's instants and steered as the run did.
    let replayed = Trace::from_jsonl(&std::fs::read_to_string(&trace_path).unwrap()).unwrap();
    assert!(run.trace.plans.len() >= 10, "{}", run.trace.plans.len());
    assert_eq!(
        serde_json::to_value(&replayed.plans).unwrap(),
        serde_json::to_value(&run.trace.plans).unwrap()
    );
    assert_eq!(replayed.samples.len(), run.trace.samples.len());
    assert_eq!(
        serde_json::to_value(&replayed.samples).unwrap(),
        serde_json::to_value(&run.trace.samples).unwrap()
    );
    // The command line writes the same trace, and names a trace it cannot create.
    let cli = |trace: &Path| {
        Command::new(workspace_bin("ugv-sim").unwrap())
            .arg("replay")
            .arg(dir.path().join(MCAP_FILE))
            .arg("--trace")
            .arg(trace)
            .output()
            .unwrap()
    };
    let cli_trace = dir.path().join("cli-trace.jsonl");
    let out = cli(&cli_trace);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert_eq!(
        std::fs::read_to_string(&cli_trace).unwrap(),
        std::fs::read_to_string(&trace_path).unwrap()
    );
    let out = cli(&dir.path().join("absent/trace.jsonl"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("absent/trace.jsonl") && !stderr.contains("panicked"),
        "{stderr}"
    );
}

/// The controller's own recording (`ugv-controller run --record`), made by the library's
/// loop in a SIL run that replans on the binary's planning thread: SIL's ticks take
/// microseconds, so the thread's paths come back a varying number of ticks later, as
/// they do on a loaded machine. The recording keeps every input at the tick that
/// took it and the tick each replanning was taken at, so the replay is byte for byte
/// all the same.
#[test]
fn the_controllers_own_recording_replays_byte_for_byte_despite_its_planning_thread() {
    let dir = tempfile::tempdir().unwrap();
    let sc = Scenario::paper().unwrap();
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    let info = RunInfo::field(
        "the paper's scenario, SIL with the planning thread".to_owned(),
        sc.sim.epoch.unix_ns(),
        "can0".to_owned(),
        sc.gps.sentence_set(),
        sc.gps.baud,
        &cfg,
    )
    .unwrap();
    let mut writer = Some(
        ugv_controller::record::Writer::create(Some(dir.path()), foxglove::Context::new(), info)
            .unwrap(),
    );
    let run = run_sil_with(sc, &cfg, |_, rt| {
        if let Some(w) = writer.take() {
            rt.controller_mut().start_planning_thread().unwrap();
            rt.record_into(w).unwrap();
        }
        Hook::Continue
    })
    .unwrap();
    assert!(run.trace.plans.len() >= 5, "{}", run.trace.plans.len());
    let path = dir.path().join(MCAP_FILE);
    let s = mcap_summary(&path);
    assert!(count(&s, topics::CONTROLLER_PLANNING) >= run.trace.plans.len() as u64);
    assert!(count(&s, topics::LASER) >= 350, "{s}");
    // Each path was taken a tick or more after it was asked for, from the thread; a
    // few later than the next tick (typically 1 to 6 of 38 here, where replaying
    // them at the next tick, as for a HIL recording, would differ).
    let taken: Vec<f64> = mcap::MessageStream::new(&std::fs::read(&path).unwrap())
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == topics::CONTROLLER_PLANNING)
        .map(|m| (m.log_time - run.sim.scenario.sim.epoch.unix_ns()) as f64 * 1e-9)
        .collect();
    let tick = ugv_controller::control::COMMAND_PERIOD;
    let delays: Vec<f64> = run
        .trace
        .plans
        .iter()
        .zip(&taken)
        .map(|(p, t)| t - p.time)
        .collect();
    assert_eq!(delays.len(), run.trace.plans.len());
    assert!(delays.iter().all(|d| *d > tick - 1e-6), "{delays:?}");
    let late = delays.iter().filter(|d| **d > 1.5 * tick).count();
    eprintln!(
        "{late} of {} paths taken later than the next tick",
        taken.len()
    );
    let rec = Recorded::read(&path).unwrap();
    assert_eq!(rec.info.mode, RecordMode::Field);
    assert_eq!(Tolerance::for_mode(rec.info.mode), Tolerance::EXACT);
    let report = replay(&rec, Tolerance::EXACT, None).unwrap();
    assert_eq!(report.divergence, None, "{report:?}");
    for name in ["CONTROLLER_HEARTBEAT", "STEERING_CMD", "THROTTLE_CMD"] {
        let m = &report.messages[name];
        assert!(m.recorded >= 300, "{name}: {m:?}");
        assert_eq!((m.replayed, m.matched), (m.recorded, m.recorded), "{name}");
    }
    // So does the command line, which says so with exit 0.
    let out = Command::new(workspace_bin("ugv-sim").unwrap())
        .arg("replay")
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["mode"], "field", "{report}");
    assert_eq!(report["divergence"], Value::Null, "{report}");
}

#[test]
fn a_changed_controller_diverges_and_the_replay_says_where() {
    let dir = tempfile::tempdir().unwrap();
    recorded_paper_run(dir.path(), Some(6.0));
    let mut rec = Recorded::read(&dir.path().join(MCAP_FILE)).unwrap();
    // Another controller (a slower steering loop): its steering commands differ.
    rec.config.follower.omega *= 0.5;
    let report = replay(&rec, Tolerance::EXACT, None).unwrap();
    let d = report.divergence.expect("a divergence");
    assert_eq!(d.message, "STEERING_CMD", "{d:?}");
    assert!(d.signal.is_some() && d.recorded != d.replayed, "{d:?}");
    assert!(d.time_s > 0.0, "{d:?}");
}

/// The HIL tolerance is no blanket: replayed within it, the paper's recording agrees
/// with itself, and a controller whose steering loop is half as fast is caught once
/// the controller has settled. (A HIL recording replayed within it is tested in the
/// VM, tests/tests/vcan_record.rs.)
#[test]
fn the_hil_tolerance_still_catches_a_changed_controller() {
    let dir = tempfile::tempdir().unwrap();
    recorded_paper_run(dir.path(), Some(12.0));
    let mut rec = Recorded::read(&dir.path().join(MCAP_FILE)).unwrap();
    let report = replay(&rec, Tolerance::HIL, None).unwrap();
    assert_eq!(report.divergence, None, "{report:#?}");
    rec.config.follower.omega *= 0.5;
    let report = replay(&rec, Tolerance::HIL, None).unwrap();
    let d = report.divergence.expect("a changed controller diverges");
    assert_eq!(d.message, "STEERING_CMD", "{d:?}");
    assert!(d.time_s >= Tolerance::HIL.settle_s, "{d:?}");
}

#[test]
fn replay_refuses_what_is_not_a_recording_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("notes.mcap");
    std::fs::write(&text, "not an mcap file at all").unwrap();
    let e = Recorded::read(&text).unwrap_err().to_string();
    assert!(
        e.contains("notes.mcap") && e.contains("not an MCAP file"),
        "{e}"
    );
    let missing = Recorded::read(&dir.path().join("absent.mcap"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("absent.mcap"), "{missing}");
    // A valid MCAP from someone else: no run metadata.
    let foreign = dir.path().join("foreign.mcap");
    {
        let ctx = foxglove::Context::new();
        let w = ctx
            .mcap_writer()
            .create_new_buffered_file(&foreign)
            .unwrap();
        ctx.channel_builder("/x")
            .build::<foxglove::schemas::Log>()
            .log(&foxglove::schemas::Log::default());
        w.close().unwrap();
    }
    let e = Recorded::read(&foreign).unwrap_err().to_string();
    assert!(e.contains("not a ugv-hil recording"), "{e}");
    // The command line says the same, exit code 4, no panic.
    let out = Command::new(workspace_bin("ugv-sim").unwrap())
        .arg("replay")
        .arg(&text)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("not an MCAP file") && !stderr.contains("panicked"),
        "{stderr}"
    );
}

/// SIGKILL ugv-sim in the middle of a SIL run paced at real time: the MCAP (without
/// its summary) is readable by the Python reader up to about a second before the
/// kill, and so are bus.log and gps.nmea; the replay reads it too, and says where
/// it was cut.
#[test]
fn a_killed_simulator_leaves_its_recording_readable_to_a_second_before() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(workspace_bin("ugv-sim").unwrap())
        .args(["run", "--sil", "--pace", "1", "--results"])
        .arg(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The run starts right after this line.
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    while !line.contains("scenario") {
        line.clear();
        assert!(
            stderr.read_line(&mut line).unwrap() > 0,
            "ugv-sim ended early"
        );
    }
    let started = Instant::now();
    std::thread::sleep(Duration::from_millis(3000));
    child.kill().unwrap(); // SIGKILL
    let ran = started.elapsed().as_secs_f64();
    child.wait().unwrap();
    let s = mcap_summary(&dir.path().join(MCAP_FILE));
    assert_eq!(s["complete"], false, "{s}");
    let epoch = Scenario::paper().unwrap().sim.epoch.unix_ns();
    let last_s = |topic: &str| {
        (s["topics"][topic]["last_ns"].as_u64().unwrap_or(epoch) - epoch) as f64 * 1e-9
    };
    // Paced at real time, the run had simulated about `ran` seconds at the kill.
    for topic in [topics::LASER, topics::CAN_RAW, topics::NMEA, topics::TF] {
        let last = last_s(topic);
        assert!(
            last >= ran - 1.5 && last <= ran + 0.1,
            "{topic}: {last} s of {ran} s"
        );
    }
    assert!(count(&s, topics::LASER) as f64 >= (ran - 1.5) * 50.0);
    let bus = std::fs::read_to_string(dir.path().join(BUS_LOG)).unwrap();
    assert!(
        bus.lines().count() as f64 >= (ran - 1.5) * 200.0,
        "{} lines",
        bus.lines().count()
    );
    let nmea = std::fs::read_to_string(dir.path().join(NMEA_FILE)).unwrap();
    assert!(!nmea.is_empty());
    let rec = Recorded::read(&dir.path().join(MCAP_FILE)).unwrap();
    let why = rec.truncated.clone().unwrap();
    assert!(why.starts_with("cut at byte "), "{why}");
    let report = replay(&rec, Tolerance::EXACT, None).unwrap();
    assert!(report.replayed_s >= ran - 1.5, "{report:?}");
    // Up to the last instant the file holds whole, the commands are the recorded ones
    // (the tick the kill cut into is not compared).
    assert_eq!(report.divergence, None, "{report:#?}");
    let until = report.compared_until_s.unwrap();
    assert!(report.replayed_s < until, "{report:?}");
    // So says the command line, exit 0.
    let out = Command::new(workspace_bin("ugv-sim").unwrap())
        .arg("replay")
        .arg(dir.path().join(MCAP_FILE))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("ends early (cut at byte "), "{stderr}");
}

/// A damaged recording is no divergence: `ugv-sim replay` exits 3 naming the file and
/// the byte offset of the damaged record (one bit flipped in a chunk's records: its
/// CRC), and says so in its help.
#[test]
fn a_damaged_recording_exits_3_naming_the_offset() {
    let dir = tempfile::tempdir().unwrap();
    recorded_paper_run(dir.path(), Some(3.0));
    let mut bytes = std::fs::read(dir.path().join(MCAP_FILE)).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x10;
    let damaged = dir.path().join("damaged.mcap");
    std::fs::write(&damaged, &bytes).unwrap();
    let e = Recorded::read(&damaged).unwrap_err();
    assert!(e.is_damaged(), "{e}");
    let sim = workspace_bin("ugv-sim").unwrap();
    let out = Command::new(&sim)
        .arg("replay")
        .arg(&damaged)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(i32::from(DAMAGED_EXIT)), "{stderr}");
    assert_eq!(DAMAGED_EXIT, 3);
    assert!(
        stderr.contains(&format!("{}: damaged at byte ", damaged.display()))
            && stderr.contains("fails its CRC")
            && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty(), "no report: {out:?}");
    let help = Command::new(&sim)
        .args(["replay", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("3 when the recording is"), "{help}");
}

/// gps.nmea is the byte stream gpsfake replays into gpsd (Debian's gpsd-clients):
/// gpsd reports a 3D RTK fix for every epoch, at the position of the epoch's GGA.
#[test]
fn gpsfake_feeds_gps_nmea_to_gpsd_which_reports_each_fix() {
    let dir = tempfile::tempdir().unwrap();
    recorded_paper_run(dir.path(), Some(3.0));
    let nmea = std::fs::read_to_string(dir.path().join(NMEA_FILE)).unwrap();
    // Each GGA's time and position, read off its fields (ddmm.mmmm).
    let degrees = |v: &str, hemi: &str, width: usize| {
        let d: f64 = v[..width].parse().unwrap();
        let m: f64 = v[width..].parse().unwrap();
        let x = d + m / 60.0;
        if hemi == "S" || hemi == "W" { -x } else { x }
    };
    let ggas: Vec<(String, f64, f64)> = nmea
        .lines()
        .filter(|l| l.contains("GGA,"))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let hms = format!("{}:{}:{}", &f[1][..2], &f[1][2..4], &f[1][4..]);
            (hms, degrees(f[2], f[3], 2), degrees(f[4], f[5], 3))
        })
        .collect();
    assert_eq!(ggas.len(), 31, "3 s at 10 Hz from t = 0");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
        .to_string();
    let mut fake = Command::new("gpsfake")
        .args(["-1", "-q", "-c", "0.02", "-P", &port])
        .arg(dir.path().join(NMEA_FILE))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| {
            panic!("running gpsfake (Debian package gpsd-clients, scripts/install-deps.sh): {e}")
        });
    // gpsd takes a moment to listen; gpspipe prints its JSON reports.
    let deadline = Instant::now() + Duration::from_secs(20);
    let reports = loop {
        let out = Command::new("gpspipe")
            .args(["-w", "-n", "200", "-x", "8", &format!("localhost:{port}")])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        if text.contains("\"TPV\"") || Instant::now() > deadline {
            break text;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let _ = fake.kill();
    let _ = fake.wait();
    let tpvs: Vec<Value> = reports
        .lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["class"] == "TPV" && v["lat"].is_number())
        .collect();
    assert!(!tpvs.is_empty(), "no TPV from gpsd: {reports}");
    // gpsd reports an epoch as it assembles it (a 2D TPV from an RMC before the GGA
    // brings the height, then the 3D one): each epoch is judged by its last TPV, and
    // the newest epoch, which may still have been assembling, not at all; nor the
    // oldest, which gpspipe may have joined after its 3D report (a 2D TPV alone).
    let mut last: std::collections::BTreeMap<String, &Value> = std::collections::BTreeMap::new();
    for tpv in &tpvs {
        if let Some(time) = tpv["time"].as_str() {
            last.insert(time.to_owned(), tpv);
        }
    }
    last.pop_last();
    last.pop_first();
    let mut matched = std::collections::BTreeSet::new();
    for tpv in last.values() {
        assert_eq!(tpv["mode"], 3, "{tpv}");
        assert_eq!(tpv["status"], 3, "RTK fixed: {tpv}");
        let time = tpv["time"].as_str().unwrap();
        let (_, lat, lon) = ggas
            .iter()
            .find(|(hms, _, _)| time.contains(&format!("T{hms}")))
            .unwrap_or_else(|| panic!("no GGA at {time}"));
        assert!(
            (tpv["lat"].as_f64().unwrap() - lat).abs() < 1e-8,
            "{tpv} vs {lat}"
        );
        assert!(
            (tpv["lon"].as_f64().unwrap() - lon).abs() < 1e-8,
            "{tpv} vs {lon}"
        );
        matched.insert(time.to_owned());
    }
    // gpspipe connects (and gpsd reports) while gpsfake is already sending, one
    // sentence per 20 ms: the first epochs may go by unreported (23 of 31 seen here).
    assert!(
        matched.len() >= 15,
        "{} of 31 epochs reported",
        matched.len()
    );
}

/// The recording's arguments are checked before anything runs: `--pace` bounded and
/// for SIL only, `replay` of a missing file named.
#[test]
fn recording_arguments_are_refused_naming_what_is_wrong() {
    let sim = workspace_bin("ugv-sim").unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (args, code, says) in [
        (&["run", "--sil", "--pace", "0"][..], 2, "--pace"),
        (&["run", "--sil", "--pace", "nan"][..], 2, "--pace"),
        (
            &["run", "--pace", "1", "--time-limit", "1"][..],
            4,
            "--pace is for SIL runs",
        ),
        (&["replay", "absent.mcap"][..], 4, "absent.mcap"),
        (&["replay"][..], 2, "RECORDING"),
    ] {
        let out = Command::new(&sim)
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// The frame ids of `topic`'s messages in a [`ugv_e2e_tests::foxglove_panels`] report.
fn frames<'a>(panels: &'a Value, topic: &str) -> Vec<&'a str> {
    panels["frames"][topic]
        .as_array()
        .unwrap_or_else(|| panic!("no frames on {topic}: {panels}"))
        .iter()
        .filter_map(Value::as_str)
        .collect()
}

/// Both recordings of a SIL run of the paper's scenario, the simulator's (run.mcap)
/// and the controller's own (`ugv-controller run --record`, made by the library's loop
/// in the same run), read with the Python `mcap` package and the protobuf schemas in
/// the files, hold what Foxglove's 3D panel and map panel need (issue 35): the
/// Foxglove schemas by name, protobuf-encoded; the fix as `foxglove.LocationFix`
/// near the scenario's datum; world -> base_link, and the mounts base_link -> laser
/// and base_link -> gps, so every message's frame has a chain to `world`; and the
/// controller's estimate of the car ends where the simulator's car is.
#[test]
fn foxglove_3d_and_map_panels_find_every_frame_in_both_recordings() {
    use ugv_controller::record::{Mounts, Writer};
    let dir = tempfile::tempdir().unwrap();
    let own = dir.path().join("controller");
    std::fs::create_dir_all(&own).unwrap();
    let sc = Scenario::paper().unwrap();
    let cfg = controller_config(&sc, FollowerKind::Optimal);
    let info = RunInfo::field(
        "the paper's scenario, SIL".to_owned(),
        sc.sim.epoch.unix_ns(),
        "can0".to_owned(),
        sc.gps.sentence_set(),
        sc.gps.baud,
        &cfg,
    )
    .unwrap();
    let writer = Writer::create(Some(&own), foxglove::Context::new(), info).unwrap();
    let mut writer = Some(writer.with_mounts(Mounts::of(&cfg.vehicle)));
    let hook = |_: f64, rt: &mut ugv_sim::sil::SilController| {
        if let Some(w) = writer.take() {
            rt.record_into(w).unwrap();
        }
        Hook::Continue
    };
    run_sil_recorded(sc.clone(), &cfg, hook, Some(dir.path())).unwrap();
    let sim = ugv_e2e_tests::foxglove_panels(&dir.path().join(MCAP_FILE)).unwrap();
    let field = ugv_e2e_tests::foxglove_panels(&own.join(MCAP_FILE)).unwrap();
    let v = &cfg.vehicle;
    for (who, p, antenna_z) in [
        ("the simulator's", &sim, sc.gps.antenna_z),
        ("the controller's", &field, 0.0),
    ] {
        for (topic, schema) in [
            (topics::LASER, "foxglove.LaserScan"),
            (topics::FIX, "foxglove.LocationFix"),
            (topics::TF, "foxglove.FrameTransform"),
        ] {
            let t = &p["topics"][topic];
            assert_eq!(t["schema"], schema, "{who} {topic}: {t}");
            assert_eq!(
                (&t["schema_encoding"], &t["message_encoding"]),
                (&"protobuf".into(), &"protobuf".into()),
                "{who} {topic}: {t}"
            );
            assert!(t["count"].as_u64() > Some(100), "{who} {topic}: {t}");
        }
        assert_eq!(frames(p, topics::LASER), ["laser"], "{who}");
        assert_eq!(frames(p, topics::FIX), ["gps"], "{who}");
        assert_eq!(p["unreachable"], serde_json::json!([]), "{who}: {p}");
        assert_eq!(p["two_parents"], serde_json::json!([]), "{who}: {p}");
        let tf = &p["transforms"];
        for edge in [
            "world -> base_link",
            "base_link -> laser",
            "base_link -> gps",
        ] {
            assert_eq!(tf[edge]["unit_rotations"], true, "{who} {edge}: {tf}");
        }
        assert_eq!(
            tf["base_link -> laser"]["first"],
            serde_json::json!([v.laser_x, v.laser_y, 0.0]),
            "{who}"
        );
        assert_eq!(
            tf["base_link -> gps"]["last"],
            serde_json::json!([v.antenna_x, v.antenna_y, antenna_z]),
            "{who}"
        );
        // The map: fixes a few metres from the datum, spread over the drive (the goal
        // is 15 m north and 30 m east: 1.3e-4 and 3.4e-4 degrees).
        let fixes = &p["fixes"];
        let span = |key: &str, at: f64| {
            let r: Vec<f64> = fixes[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            assert!(
                (r[0] - at).abs() < 1e-3 && (r[1] - at).abs() < 1e-3,
                "{who} {key}: {fixes}"
            );
            r[1] - r[0]
        };
        assert!(span("lat", sc.datum.latitude) > 1e-4, "{who}: {fixes}");
        assert!(span("lon", sc.datum.longitude) > 3e-4, "{who}: {fixes}");
    }
    // The simulator's world: the car's pose and the obstacles in `world`.
    assert_eq!(frames(&sim, topics::POSE), ["world"]);
    assert_eq!(frames(&sim, topics::OBSTACLES), ["world"]);
    // The controller's estimate of the rear axle ends within centimetres of the true
    // one; it read each fix the receiver sent, but for the last epoch or two.
    let last = |p: &Value| -> Vec<f64> {
        let at = &p["transforms"]["world -> base_link"]["last"];
        (0..2).map(|i| at[i].as_f64().unwrap()).collect()
    };
    let (truth, estimate) = (last(&sim), last(&field));
    let off = (truth[0] - estimate[0]).hypot(truth[1] - estimate[1]);
    assert!(off < 0.2, "{truth:?} {estimate:?}");
    let (sent, read) = (&sim["fixes"]["count"], &field["fixes"]["count"]);
    let (sent, read) = (sent.as_u64().unwrap(), read.as_u64().unwrap());
    assert!(read <= sent && read + 2 >= sent, "{sent} sent, {read} read");
}
