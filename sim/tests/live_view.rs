//! `ugv-sim run --live`: the run's channels over the Foxglove WebSocket protocol, read
//! by a client that is not the Foxglove SDK (sim/tests/live_client.py, Python's
//! `websockets`, pinned in scripts/install-deps.sh): what is advertised, the laser's
//! rate over a wall-clock window with SIL paced at real time, the recording alongside,
//! `--no-record`, and the addresses `--live` refuses. Every server here listens on
//! 127.0.0.1 only. A missing `websockets` fails the tests with the install command.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use serde_json::Value;

mod child_common;

const CLIENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/live_client.py");

fn python() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_owned())
}

/// A port free on 127.0.0.1 a moment ago.
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The simulator, killed if a test ends before it does.
struct Sim(Option<Child>);

impl Sim {
    fn start(args: &[&str], dir: &Path) -> Sim {
        let child = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
            .args(args)
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        Sim(Some(child))
    }

    /// Its exit code and stderr, waiting at most `limit`.
    fn finish(mut self, limit: Duration) -> (Option<i32>, String) {
        let mut child = self.0.take().unwrap();
        child_common::exit_and_stderr(&mut child, limit, "ugv-sim")
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        if let Some(c) = &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Run the Python client with `args`; its JSON report.
fn client(args: &[&str]) -> Value {
    let out: Output = Command::new(python())
        .arg(CLIENT)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("running {} (set PYTHON to choose another): {e}", python()));
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(3) {
        panic!(
            "the websockets package is not installed for {py}: run `{py} -m pip install \
             websockets==15.0.1` (scripts/install-deps.sh installs it)",
            py = python()
        );
    }
    assert!(
        out.status.success(),
        "live_client.py {args:?}: {:?}: {stderr}",
        out.status
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("client output {:?}: {e}", out.stdout))
}

/// The advertised channels as (topic, schema name, encoding).
fn channels(report: &Value) -> Vec<(String, String, String)> {
    report["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let s = |k: &str| c[k].as_str().unwrap_or_default().to_owned();
            (s("topic"), s("schemaName"), s("encoding"))
        })
        .collect()
}

fn assert_advertised(report: &Value) {
    let got = channels(report);
    for (topic, schema, encoding) in [
        ("/laser/scan", "foxglove.LaserScan", "protobuf"),
        ("/gps/fix", "foxglove.LocationFix", "protobuf"),
        ("/tf", "foxglove.FrameTransform", "protobuf"),
        ("/vehicle/pose", "foxglove.PoseInFrame", "protobuf"),
        ("/world/obstacles", "foxglove.SceneUpdate", "protobuf"),
        ("/can/raw", "", "json"),
        ("/can/decoded", "", "json"),
        ("/gps/nmea", "", "json"),
        ("/controller/state", "", "json"),
    ] {
        assert!(
            got.iter()
                .any(|(t, s, e)| t == topic && s == schema && e == encoding),
            "{topic} ({schema}, {encoding}) not advertised: {got:?}"
        );
    }
}

#[test]
fn a_sil_run_serves_its_channels_live_at_the_lasers_rate_in_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let url = format!("ws://{addr}");
    let sim = Sim::start(
        &[
            "run",
            "--sil",
            "--live",
            &addr,
            "--time-limit",
            "8",
            "--results",
            "results",
        ],
        dir.path(),
    );
    let report = client(&[&url, "--window", "2"]);
    // The subprotocol the SDK 0.30 speaks; the older name alone is refused.
    assert_eq!(report["subprotocol"], "foxglove.sdk.v1", "{report}");
    let refused = client(&[
        &url,
        "--subprotocol",
        "foxglove.websocket.v1",
        "--expect-refused",
    ]);
    assert_eq!(refused["refused"], true, "{refused}");
    assert_eq!(refused["status"], 400, "{refused}");
    let (code, stderr) = sim.finish(Duration::from_secs(60));

    assert_eq!(report["server"]["name"], "ugv-sim", "{report}");
    assert_advertised(&report);
    // The LMS111's 50 Hz, seen over 2 s of wall-clock time: paced at real time (an
    // unpaced SIL run goes tens of times faster), and the simulated time the messages
    // carry advances with the wall clock.
    let count = report["count"].as_f64().unwrap();
    let window = report["window_s"].as_f64().unwrap();
    let rate = count / window;
    assert!((35.0..=65.0).contains(&rate), "{rate} scans/s: {report}");
    let span = report["log_span_s"].as_f64().unwrap();
    assert!(
        (1.5..=2.5).contains(&span),
        "log time span {span} s: {report}"
    );

    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(code, Some(4), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "live view on {url}: in Foxglove, Open connection -> Foxglove WebSocket -> {url}"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("SIL paced at real time for the live view"),
        "{stderr}"
    );
    // The recording is made alongside, with every scan.
    assert!(
        dir.path()
            .join("results/run.mcap")
            .metadata()
            .unwrap()
            .len()
            > 100_000,
        "{stderr}"
    );
    let scans: u64 = stderr
        .split(" laser scans in results")
        .next()
        .and_then(|head| head.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no recording summary: {stderr}"));
    assert!(scans >= 395, "{scans} scans recorded in 8 s: {stderr}");
}

#[test]
fn with_no_record_the_channels_are_still_served_and_no_file_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let addr = format!("127.0.0.1:{}", free_port());
    let sim = Sim::start(
        &[
            "run",
            "--sil",
            "--no-record",
            "--live",
            &addr,
            "--time-limit",
            "4",
            "--results",
            "results",
        ],
        dir.path(),
    );
    let report = client(&[&format!("ws://{addr}"), "--window", "1"]);
    let (code, stderr) = sim.finish(Duration::from_secs(60));
    assert_advertised(&report);
    let count = report["count"].as_u64().unwrap();
    assert!((35..=65).contains(&count), "{count} scans in 1 s: {report}");
    assert_ne!(code, Some(4), "{stderr}");
    for file in ["run.mcap", "bus.log", "gps.nmea"] {
        assert!(!dir.path().join("results").join(file).exists(), "{file}");
    }
    assert!(!stderr.contains("recorded "), "{stderr}");
}

#[test]
fn bad_live_addresses_are_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    for bad in [
        "example.com:8765",
        "192.168.1.300:8765",
        "10.0.0.1",
        "0.0.0.0:99999",
        "ws://127.0.0.1:8765",
    ] {
        let sim = Sim::start(&["run", "--sil", "--live", bad], dir.path());
        let (code, stderr) = sim.finish(Duration::from_secs(20));
        assert_eq!(code, Some(2), "--live {bad}: {stderr}");
        assert!(
            stderr.contains("--live")
                && stderr.contains(&format!("'{bad}' is not an IP address and port"))
                && stderr.contains("127.0.0.1:8765"),
            "--live {bad}: {stderr}"
        );
        assert!(
            !stderr.contains("ugv-sim: scenario"),
            "a run started: {stderr}"
        );
    }
    // A scenario file taken for the address says how to write it.
    let sim = Sim::start(&["run", "--sil", "--live", "paper.toml"], dir.path());
    let (code, stderr) = sim.finish(Duration::from_secs(20));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("put the scenario before --live"),
        "{stderr}"
    );

    // An address in use: refused with the address and the system's reason.
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let sim = Sim::start(&["run", "--sil", "--live", &addr], dir.path());
    let (code, stderr) = sim.finish(Duration::from_secs(20));
    assert_eq!(code, Some(4), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "starting the live view's WebSocket server on {addr}"
        )),
        "{stderr}"
    );
}
