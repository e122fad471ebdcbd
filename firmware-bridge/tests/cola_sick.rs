//! `ugv-sick` end to end: a `ColaServer` (or a hand-made scanner) on loopback TCP,
//! the `ugv-sick` binary driving it, and a `LaserSubscriber` receiving on iceoryx2 the
//! frames the server was given. Every test uses its own service name.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use firmware_bridge::cola::{
    ColaServer, EncodeOptions, Message, ScanKind, ServerConfig, TelegramDecoder, frame_telegram,
    scan_from_frame,
};
use firmware_bridge::laser::{LaserFrame, LaserSubscriber};

/// Generous: only bounds a broken build, nothing here is timed.
const WAIT: Duration = Duration::from_secs(30);

fn unique_service(test: &str) -> String {
    common::unique_service("cola", test)
}

fn make_frame(seq: u64) -> LaserFrame {
    LaserFrame::synthetic(seq, 541)
}

fn assert_same(got: &LaserFrame, sent: &LaserFrame) {
    assert_eq!(got.sequence, sent.sequence);
    assert_eq!(got.count, sent.count);
    assert_eq!(got.stamp_ns, sent.stamp_ns);
    for (i, (&g, &s)) in got.ranges().iter().zip(sent.ranges()).enumerate() {
        if s.is_nan() {
            assert!(g.is_nan(), "beam {i}");
        } else if s.is_infinite() {
            assert_eq!(g, f32::INFINITY, "beam {i}");
        } else {
            assert!((g - s).abs() <= 0.000_501, "beam {i}: sent {s}, got {g}");
        }
    }
    assert_eq!(got.intensities(), sent.intensities());
}

/// `ugv-sick` with stderr collected line by line.
struct Sick {
    child: Child,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Sick {
    fn start(args: &[&str]) -> Sick {
        let mut child = Command::new(env!("CARGO_BIN_EXE_ugv-sick"))
            .args(args)
            .env("RUST_LOG", "info")
            .env_remove("IOX2_LOG_LEVEL")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Sick {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Wait for a stderr line containing `text`.
    fn wait_for_line(&mut self, text: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(l) = self.seen.iter().find(|l| l.contains(text)) {
                return l.clone();
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(_) => panic!("no line with {text:?} on stderr; got {:#?}", self.seen),
            }
        }
    }

    /// Wait for the exit; the status and all of stderr.
    fn wait(mut self) -> (ExitStatus, String) {
        let deadline = Instant::now() + WAIT;
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            assert!(Instant::now() < deadline, "ugv-sick did not exit");
            std::thread::sleep(Duration::from_millis(20));
        };
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.seen.push(line);
        }
        (status, self.seen.join("\n"))
    }
}

impl Drop for Sick {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Wait until the server streams to `n` clients (ugv-sick finished its handshake).
fn wait_streaming(server: &ColaServer, n: usize) {
    let deadline = Instant::now() + WAIT;
    while server.streaming_clients() < n {
        assert!(Instant::now() < deadline, "ugv-sick never asked for scans");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn ugv_sick_publishes_the_servers_frames_on_iceoryx2() {
    let service = unique_service("e2e");
    let subscriber = LaserSubscriber::new(&service).unwrap();
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111()).unwrap();
    let addr = server.local_addr().to_string();
    let mut sick = Sick::start(&["--address", &addr, "--service", &service, "--count", "26"]);
    wait_streaming(&server, 1);
    let line = sick.wait_for_line("publishing scans");
    assert!(line.contains("LMS111"), "{line}");
    for seq in 0..25 {
        let frame = make_frame(seq);
        server.publish(&frame).unwrap();
        let got = subscriber
            .recv_timeout(WAIT)
            .unwrap()
            .expect("a frame within WAIT");
        assert_same(&got, &frame);
    }
    // The 26th ends it (a publisher that exits takes its unread samples along, so the
    // checked frames are all read while it runs).
    server.publish(&make_frame(25)).unwrap();
    let (status, stderr) = sick.wait();
    assert!(status.success(), "{status}: {stderr}");
    assert!(stderr.contains("stopped"), "{stderr}");
    assert_eq!(server.stats().frames_dropped, 0);
}

#[test]
fn ugv_sick_exits_cleanly_on_ctrl_c() {
    let service = unique_service("sigint");
    let subscriber = LaserSubscriber::new(&service).unwrap();
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms511()).unwrap();
    let addr = server.local_addr().to_string();
    let sick = Sick::start(&[
        "--address",
        &addr,
        "--service",
        &service,
        "--range-max",
        "80",
        "--report-interval",
        "0.05",
    ]);
    wait_streaming(&server, 1);
    let frame = make_frame(3);
    server.publish(&frame).unwrap();
    let got = subscriber.recv_timeout(WAIT).unwrap().unwrap();
    assert_eq!((got.sequence, got.range_max), (3, 80.0));
    let mut sick = sick;
    sick.wait_for_line("scans/s");
    let pid = nix::unistd::Pid::from_raw(sick.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let (status, stderr) = sick.wait();
    assert!(status.success(), "{status}: {stderr}");
    assert!(stderr.contains("scans/s"), "{stderr}");
    assert!(stderr.contains("stopped"), "{stderr}");
    // It said goodbye: the server no longer streams to anyone.
    let deadline = Instant::now() + WAIT;
    while server.client_count() > 0 {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn ugv_sick_says_what_is_wrong() {
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let nowhere = format!("127.0.0.1:{port}");
    let service = unique_service("errors");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "--address",
                &nowhere,
                "--service",
                &service,
                "--no-reconnect",
            ],
            "cannot connect to the scanner at",
        ),
        (
            vec![
                "--address",
                &nowhere,
                "--service",
                &service,
                "--range-min",
                "5",
                "--range-max",
                "1",
            ],
            "--range-min 5 --range-max 1",
        ),
        (
            vec!["--address", &nowhere, "--service", "", "--no-reconnect"],
            "opening the laser service",
        ),
    ];
    for (args, expected) in cases {
        let (status, stderr) = Sick::start(&args).wait();
        assert_eq!(status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        if expected.starts_with("cannot connect") {
            assert!(stderr.contains(&nowhere), "{stderr}");
        }
    }
}

/// A scanner that answers the handshake, then sends what the test gives it.
fn fake_scanner(after_handshake: Vec<Vec<u8>>) -> (SocketAddr, std::thread::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let thread = std::thread::spawn(move || {
        let Ok((mut stream, _)) = listener.accept() else {
            return;
        };
        let mut decoder = TelegramDecoder::default();
        let mut buf = [0u8; 4096];
        loop {
            let Ok(n) = stream.read(&mut buf) else { return };
            if n == 0 {
                return;
            }
            decoder.push(&buf[..n]);
            while let Some(Ok(payload)) = decoder.next_telegram() {
                let answer = match Message::parse(&payload) {
                    Ok(Message::SetAccessMode { .. }) => Message::AccessModeAck(true),
                    Ok(Message::ReadDeviceIdent) => Message::DeviceIdent {
                        name: "TiM551".into(),
                        version: "V2.5".into(),
                    },
                    Ok(Message::StreamScans(on)) => Message::StreamScansAck(on),
                    _ => continue,
                };
                let _ = stream.write_all(&answer.to_telegram().unwrap());
                if matches!(answer, Message::StreamScansAck(true)) {
                    for telegram in &after_handshake {
                        let _ = stream.write_all(telegram);
                    }
                }
            }
        }
    });
    (addr, thread)
}

#[test]
fn ugv_sick_skips_bad_telegrams_and_survives_a_scanner_that_talks_nonsense() {
    let service = unique_service("bad");
    let subscriber = LaserSubscriber::new(&service).unwrap();
    let good = make_frame(41);
    let scan = scan_from_frame(&good, &EncodeOptions::default()).unwrap();
    let mut stream = Vec::new();
    stream.extend_from_slice(b"\x02sSN LMDscandata 1 1 X\x03 noise \x02sSN LMDscandata\x03");
    frame_telegram(&scan.encode(ScanKind::Streamed).unwrap(), &mut stream);
    let (addr, scanner) = fake_scanner(vec![stream]);
    let addr = addr.to_string();
    let mut sick = Sick::start(&["--address", &addr, "--service", &service]);
    let got = subscriber
        .recv_timeout(WAIT)
        .unwrap()
        .expect("the good scan");
    assert_same(&got, &good);
    let bad = sick.wait_for_line("bad scan");
    assert!(bad.contains("serial number"), "{bad}");
    let pid = nix::unistd::Pid::from_raw(sick.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let (status, stderr) = sick.wait();
    assert!(status.success(), "{status}: {stderr}");
    assert!(stderr.contains("TiM551"), "{stderr}");
    let _ = scanner.join();

    // A "scanner" that answers nothing sensible: a clear error, no panic.
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let nonsense = std::thread::spawn(move || {
        if let Ok((mut s, _)) = listener.accept() {
            let _ = s.write_all(b"\x02sRA Nonsense 1\x03\xff\xfe garbage");
            let mut buf = [0u8; 1024];
            while matches!(s.read(&mut buf), Ok(n) if n > 0) {}
        }
    });
    let (status, stderr) = Sick::start(&[
        "--address",
        &addr,
        "--service",
        &service,
        "--no-reconnect",
        "--connect-timeout",
        "1",
    ])
    .wait();
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("no answer to sMN SetAccessMode"),
        "{stderr}"
    );
    assert!(stderr.contains(&addr), "{stderr}");
    let _ = nonsense.join();
}
