//! `ColaServer` and `ColaClient` on loopback TCP: the driver receives exactly the frames
//! published, several clients, a slow client that never reads, clients that send
//! garbage, every command's answer, login and the one controlling client, connection
//! loss and reconnect.
//!
//! Waits are bounded by a generous `WAIT` only so that a broken build fails instead of
//! hanging; nothing asserts how fast anything is.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::mpsc;
use std::time::Duration;

use firmware_bridge::cola::{
    ClientConfig, ColaClient, ColaError, ColaServer, Message, ScanData, ScanKind, ServerConfig,
    SopasError, TelegramDecoder,
};
use firmware_bridge::laser::{LaserFrame, MAX_BEAMS};

const WAIT: Duration = Duration::from_secs(20);

/// A synthetic frame of `count` beams whose stamp has nanoseconds below the
/// microsecond, which the telegram drops.
fn make_frame(seq: u64, count: usize) -> LaserFrame {
    let mut f = LaserFrame::synthetic(seq, count);
    f.stamp_ns += 123_456;
    f
}

/// The driver's frame is the published one: sequence, stamp to the µs, angles to the
/// telegram's 1/10000°, ranges to the half millimetre, inf and NaN kept, intensities.
fn assert_same(got: &LaserFrame, sent: &LaserFrame) {
    assert_eq!(got.sequence, sent.sequence);
    assert_eq!(got.count, sent.count);
    assert_eq!(got.stamp_ns, sent.stamp_ns / 1000 * 1000);
    let tick = (1e-4f32).to_radians();
    assert!((got.angle_min - sent.angle_min).abs() <= tick);
    assert!((got.angle_increment - sent.angle_increment).abs() <= tick);
    assert_eq!(
        (got.range_min, got.range_max),
        (sent.range_min, sent.range_max)
    );
    assert!((got.scan_time - sent.scan_time).abs() < 1e-6);
    for (i, (&g, &s)) in got.ranges().iter().zip(sent.ranges()).enumerate() {
        if s.is_nan() {
            assert!(g.is_nan(), "beam {i}: {g}");
        } else if s.is_infinite() {
            assert_eq!(g, f32::INFINITY, "beam {i}");
        } else {
            assert!((g - s).abs() <= 0.000_501, "beam {i}: sent {s}, got {g}");
        }
    }
    assert_eq!(got.intensities(), sent.intensities());
    got.validate().unwrap();
}

fn server(config: ServerConfig) -> ColaServer {
    ColaServer::bind("127.0.0.1:0", config).unwrap()
}

fn driver(addr: SocketAddr) -> ColaClient {
    let config = ClientConfig {
        connect_timeout: WAIT,
        reply_timeout: WAIT,
        ..ClientConfig::default()
    };
    ColaClient::connect(&addr.to_string(), config).unwrap()
}

/// A driver that only reads (no login): any number of them may connect.
fn reader(addr: SocketAddr) -> ColaClient {
    let config = ClientConfig {
        connect_timeout: WAIT,
        reply_timeout: WAIT,
        login: false,
        ..ClientConfig::default()
    };
    ColaClient::connect(&addr.to_string(), config).unwrap()
}

/// Wait until the server has `n` clients (it noticed the others leave).
fn wait_clients(server: &ColaServer, n: usize) {
    let deadline = std::time::Instant::now() + WAIT;
    while server.client_count() != n {
        assert!(
            std::time::Instant::now() < deadline,
            "{} clients",
            server.client_count()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

const LOGIN: &str = "sMN SetAccessMode 03 F4724744";

/// A raw CoLa-A connection for sending anything and reading answers telegram by telegram.
struct Raw {
    stream: TcpStream,
    decoder: TelegramDecoder,
}

impl Raw {
    fn connect(addr: SocketAddr) -> Raw {
        let stream = TcpStream::connect(addr).unwrap();
        stream.set_read_timeout(Some(WAIT)).unwrap();
        Raw {
            stream,
            decoder: TelegramDecoder::new(1 << 20),
        }
    }

    fn send(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).unwrap();
    }

    fn command(&mut self, text: &str) {
        self.send(format!("\x02{text}\x03").as_bytes());
    }

    /// The next telegram's content, as text.
    fn answer(&mut self) -> String {
        let mut buf = [0u8; 65536];
        loop {
            if let Some(item) = self.decoder.next_telegram() {
                return String::from_utf8(item.unwrap()).unwrap();
            }
            let n = self.stream.read(&mut buf).expect("an answer within WAIT");
            assert!(n > 0, "the server closed the connection");
            self.decoder.push(&buf[..n]);
        }
    }

    fn ask(&mut self, text: &str) -> String {
        self.command(text);
        self.answer()
    }

    /// Whether the server closes the connection (reads until EOF or an error).
    fn closed_by_server(&mut self) -> bool {
        let mut buf = [0u8; 4096];
        loop {
            match self.stream.read(&mut buf) {
                Ok(0) => return true,
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return true,
                Err(_) => return false,
            }
        }
    }
}

#[test]
fn driver_receives_exactly_the_frames_published() {
    let server = server(ServerConfig::lms111().with_serial_number(0x1234_5678));
    let mut client = driver(server.local_addr());
    assert_eq!(client.device_ident().name, "LMS111");
    assert_eq!(server.streaming_clients(), 1);
    for seq in 0..40 {
        let count = [541, MAX_BEAMS, 181, 1][seq as usize % 4];
        let frame = make_frame(seq, count);
        assert_eq!(server.publish(&frame).unwrap(), 1);
        let got = client
            .next_frame(WAIT)
            .unwrap()
            .expect("a frame within WAIT");
        assert_same(&got, &frame);
    }
    let stats = server.stats();
    assert_eq!((stats.frames_published, stats.frames_dropped), (40, 0));
    assert_eq!(stats.bad_telegrams, 0);
    let c = client.stats();
    assert_eq!((c.frames, c.lost_scans, c.bad_telegrams), (40, 0, 0));
}

#[test]
fn several_clients_each_receive_every_frame() {
    let server = server(ServerConfig::lms511());
    // One logs in (the controlling client), the others only read.
    let mut clients: Vec<ColaClient> = (0..4)
        .map(|i| {
            if i == 0 {
                driver(server.local_addr())
            } else {
                reader(server.local_addr())
            }
        })
        .collect();
    assert!(clients.iter().all(|c| c.device_ident().name == "LMS511"));
    assert_eq!(server.client_count(), 4);
    for seq in 100..120 {
        let frame = make_frame(seq, 541);
        assert_eq!(server.publish(&frame).unwrap(), 4);
        for c in &mut clients {
            assert_same(&c.next_frame(WAIT).unwrap().unwrap(), &frame);
        }
    }
    assert_eq!(server.stats().frames_dropped, 0);
    drop(clients.pop());
    // The server notices the departure and serves the others.
    let frame = make_frame(120, 541);
    server.publish(&frame).unwrap();
    for c in &mut clients {
        assert_same(&c.next_frame(WAIT).unwrap().unwrap(), &frame);
    }
}

#[test]
fn a_slow_client_loses_frames_counted_and_blocks_no_one() {
    let server = server(ServerConfig {
        queue_len: 2,
        ..ServerConfig::lms111()
    });
    // A client that asks for scans and never reads them.
    let mut slow = Raw::connect(server.local_addr());
    assert_eq!(slow.ask("sEN LMDscandata 1"), "sEA LMDscandata 1");
    let mut fast = driver(server.local_addr());
    assert_eq!(server.streaming_clients(), 2);
    // 3000 frames of 1081 beams (about 26 MB) overflow any socket buffer of the slow
    // client; publishing runs in its own thread so a blocking publish fails the test.
    let (done_tx, done_rx) = mpsc::channel();
    let (frame_tx, frame_rx) = mpsc::sync_channel::<u64>(0);
    let publisher = std::thread::spawn(move || {
        for seq in 0..3000 {
            server.publish(&make_frame(seq, MAX_BEAMS)).unwrap();
            // Lockstep with the fast client: it must get every frame.
            if frame_tx.send(seq).is_err() {
                break;
            }
        }
        done_tx.send(server.stats()).unwrap();
        server
    });
    for seq in 0..3000 {
        assert_eq!(frame_rx.recv_timeout(WAIT).unwrap(), seq);
        let got = fast.next_frame(WAIT).unwrap().unwrap();
        assert_eq!(got.sequence, seq);
    }
    let stats = done_rx
        .recv_timeout(WAIT)
        .expect("publish never waits for the slow client");
    let server = publisher.join().unwrap();
    let slow_info = stats
        .clients
        .iter()
        .find(|c| c.peer == slow.stream.local_addr().unwrap())
        .unwrap();
    let fast_info = stats
        .clients
        .iter()
        .find(|c| c.peer != slow.stream.local_addr().unwrap())
        .unwrap();
    assert!(slow_info.frames_dropped > 0, "{stats:?}");
    assert_eq!(fast_info.frames_dropped, 0);
    assert_eq!(stats.frames_dropped, slow_info.frames_dropped);
    assert_eq!(stats.frames_published, 3000);
    // The slow client's losses are only its own; the server still answers it.
    drop(slow);
    let frame = make_frame(3000, 541);
    server.publish(&frame).unwrap();
    assert_same(&fast.next_frame(WAIT).unwrap().unwrap(), &frame);
}

#[test]
fn clients_sending_garbage_get_errors_and_the_server_goes_on() {
    let server = server(ServerConfig {
        max_consecutive_errors: 16,
        ..ServerConfig::lms111()
    });
    let mut raw = Raw::connect(server.local_addr());
    raw.send(b"hello\x02garbage\x03\x02sRN DeviceIdent\x03");
    assert_eq!(raw.answer(), "sFA C");
    let ident = raw.answer();
    assert!(ident.starts_with("sRA DeviceIdent 6 LMS111 "), "{ident}");
    // Oversize (the server takes 4096 bytes), then a telegram cut off by the next STX.
    let mut big = vec![0x02];
    big.extend(std::iter::repeat_n(b'A', 5000));
    big.extend_from_slice(b"\x03\x02sRN LMD\x02sRN SCdevicestate\x03");
    raw.send(&big);
    assert_eq!(raw.answer(), "sFA 7");
    assert_eq!(raw.answer(), "sFA 8");
    assert_eq!(raw.answer(), "sRA SCdevicestate 1");
    assert_eq!(raw.ask("sRN LMDscandata"), "sFA 4", "no scan yet");
    assert_eq!(raw.ask("sEN LMDscandata 7"), "sFA 10");
    assert_eq!(raw.ask("sMN SetAccessMode 03"), "sFA 8");
    assert_eq!(raw.ask("sMN SetAccessMode 03 XYZ"), "sFA 11");
    assert_eq!(raw.ask("sRN DeviceIdent extra"), "sFA 5");

    // A client that sends only bad telegrams is disconnected after 16 in a row.
    let mut spammer = Raw::connect(server.local_addr());
    for _ in 0..40 {
        if spammer.stream.write_all(b"\x02???\x03").is_err() {
            break;
        }
    }
    assert!(spammer.closed_by_server());

    // Everyone else is served as before.
    let mut client = driver(server.local_addr());
    let frame = make_frame(7, 541);
    server.publish(&frame).unwrap();
    assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);
    let polled = raw.ask("sRN LMDscandata");
    let (kind, scan) = ScanData::parse(polled.as_bytes()).unwrap();
    assert_eq!((kind, scan.scan_counter), (ScanKind::Polled, 7));
    let stats = server.stats();
    assert_eq!(stats.garbage_bytes, 5, "hello");
    assert_eq!(stats.clients_dropped_for_errors, 1);
    assert_eq!(stats.bad_telegrams, 7 + 16, "{stats:?}");
}

#[test]
fn commands_are_answered_as_a_sick_scanner_does() {
    let server = server(ServerConfig::lms111());
    let mut raw = Raw::connect(server.local_addr());
    assert_eq!(raw.ask(LOGIN), "sAN SetAccessMode 1");
    assert_eq!(
        raw.ask("sMN SetAccessMode 03 12345678"),
        "sAN SetAccessMode 0"
    );
    assert_eq!(
        raw.ask("sMN SetAccessMode 02 B21ACE26"),
        "sAN SetAccessMode 1"
    );
    match Message::parse(raw.ask("sRN DeviceIdent").as_bytes()).unwrap() {
        Message::DeviceIdent { name, version } => {
            assert_eq!(name, "LMS111");
            assert!(version.contains("ugv-hil"));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(raw.ask("sRN SCdevicestate"), "sRA SCdevicestate 1");
    assert_eq!(raw.ask("sMN Run"), "sAN Run 1");

    assert_eq!(raw.ask("sRN LMDscandata"), "sFA 4");
    server.publish(&make_frame(1, 541)).unwrap();
    let (kind, scan) = ScanData::parse(raw.ask("sRN LMDscandata").as_bytes()).unwrap();
    assert_eq!(
        (kind, scan.scan_counter, scan.serial_number),
        (ScanKind::Polled, 1, 0x89_A27F)
    );
    assert!(scan.time.is_some());

    assert_eq!(raw.ask("sEN LMDscandata 1"), "sEA LMDscandata 1");
    server.publish(&make_frame(2, 541)).unwrap();
    let (kind, scan) = ScanData::parse(raw.answer().as_bytes()).unwrap();
    assert_eq!((kind, scan.scan_counter), (ScanKind::Streamed, 2));

    // `Run` ended the login: stopping needs it again.
    assert_eq!(raw.ask("sMN LMCstopmeas"), "sFA 1");
    assert_eq!(raw.ask(LOGIN), "sAN SetAccessMode 1");
    assert_eq!(raw.ask("sMN LMCstopmeas"), "sAN LMCstopmeas 0");
    assert!(!server.is_measuring());
    assert_eq!(server.publish(&make_frame(3, 541)).unwrap(), 0);
    assert_eq!(raw.ask("sMN LMCstartmeas"), "sAN LMCstartmeas 0");
    assert!(server.is_measuring());
    server.publish(&make_frame(4, 541)).unwrap();
    let (_, scan) = ScanData::parse(raw.answer().as_bytes()).unwrap();
    assert_eq!(scan.scan_counter, 4, "scan 3 came while stopped");
    assert_eq!(server.stats().frames_while_stopped, 1);

    assert_eq!(raw.ask("sEN LMDscandata 0"), "sEA LMDscandata 0");
    server.publish(&make_frame(5, 541)).unwrap();
    // Not streamed any more: the next telegram is the answer to the next request.
    assert_eq!(raw.ask("sRN LMPscancfg"), "sFA 3");
    assert_eq!(raw.ask("sWN LMDscandatacfg 01 00 1"), "sWA LMDscandatacfg");
    assert_eq!(raw.ask("sWN NoSuchVariable 1"), "sFA 3");
    assert_eq!(raw.ask("sMN mLMPsetscancfg +5000 +1"), "sFA 4");
    assert_eq!(raw.ask("sMN NoSuchMethod"), "sFA 2");
    assert_eq!(raw.ask("sEN LIDoutputstate 1"), "sFA F");
    assert_eq!(raw.ask("sXX Whatever"), "sFA C");
    assert_eq!(
        raw.ask("sRA SCdevicestate 1"),
        "sFA C",
        "an answer is not a request"
    );
}

#[test]
fn methods_need_the_login_a_real_scanner_asks_for() {
    let server = server(ServerConfig::lms111());
    let mut raw = Raw::connect(server.local_addr());
    assert_eq!(raw.ask("sMN LMCstartmeas"), "sFA 1");
    assert_eq!(raw.ask("sMN Run"), "sFA 1");
    assert_eq!(raw.ask("sWN LMDscandatacfg 01 00 1"), "sFA A");
    assert_eq!(raw.ask("sMN mLMPsetscancfg +5000 +1"), "sFA 1");
    assert_eq!(raw.ask(LOGIN), "sAN SetAccessMode 1");
    assert_eq!(raw.ask("sMN LMCstartmeas"), "sAN LMCstartmeas 0");
    drop(raw);
    wait_clients(&server, 0);

    let no_login = ClientConfig {
        login: false,
        start_measurement: true,
        reply_timeout: WAIT,
        ..ClientConfig::default()
    };
    match ColaClient::connect(&server.local_addr().to_string(), no_login) {
        Err(ColaError::Device { request, error }) => {
            assert_eq!(
                (request.as_str(), error),
                ("sMN LMCstartmeas", SopasError(1))
            );
        }
        other => panic!("{other:?}"),
    }
    let login = ClientConfig {
        start_measurement: true,
        reply_timeout: WAIT,
        ..ClientConfig::default()
    };
    let mut client = ColaClient::connect(&server.local_addr().to_string(), login).unwrap();
    let frame = make_frame(9, 541);
    server.publish(&frame).unwrap();
    assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);
    assert_eq!(server.stats().access_denied, 5);
}

#[test]
fn unauthenticated_stop_and_a_second_controller_are_refused_over_tcp() {
    let server = server(ServerConfig::lms111());
    let addr = server.local_addr();
    // The simulator's driver (or ugv-sick) logs in and controls the scanner.
    let mut controller = driver(addr);
    // A client without login cannot stop the laser for everyone.
    let mut intruder = Raw::connect(addr);
    assert_eq!(intruder.ask("sMN LMCstopmeas"), "sFA 1");
    assert!(server.is_measuring());
    // Nor can it log in while the controller is connected, at any level.
    assert_eq!(intruder.ask(LOGIN), "sAN SetAccessMode 0");
    assert_eq!(
        intruder.ask("sMN SetAccessMode 04 81BE23AA"),
        "sAN SetAccessMode 0"
    );
    assert_eq!(intruder.ask("sMN LMCstopmeas"), "sFA 1");
    assert!(server.is_measuring());
    // A second driver that logs in is refused; one that only reads is served.
    match ColaClient::connect(&addr.to_string(), ClientConfig::default()) {
        Err(ColaError::AccessDenied { level: 3 }) => {}
        other => panic!("{other:?}"),
    }
    let mut second_reader = reader(addr);
    let frame = make_frame(21, 541);
    assert_eq!(server.publish(&frame).unwrap(), 2);
    assert_same(&controller.next_frame(WAIT).unwrap().unwrap(), &frame);
    assert_same(&second_reader.next_frame(WAIT).unwrap().unwrap(), &frame);
    let stats = server.stats();
    assert_eq!(
        (stats.access_denied, stats.logins_refused),
        (2, 3),
        "{stats:?}"
    );
    // When the controller leaves, another client may take control.
    drop(controller);
    wait_clients(&server, 2);
    assert_eq!(intruder.ask(LOGIN), "sAN SetAccessMode 1");
    assert_eq!(intruder.ask("sMN LMCstopmeas"), "sAN LMCstopmeas 0");
    assert!(!server.is_measuring());
}

#[test]
fn polling_returns_the_latest_scan_while_streaming() {
    let server = server(ServerConfig::lms111());
    let mut client = driver(server.local_addr());
    let frame = make_frame(5, 541);
    server.publish(&frame).unwrap();
    // The streamed copy may arrive before the poll's answer: it is kept, not lost.
    assert_same(&client.poll_frame().unwrap(), &frame);
    assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);
}

#[test]
fn sequence_numbers_unwrap_past_16_bits_and_gaps_count_as_lost() {
    let server = server(ServerConfig::lms111());
    let mut client = driver(server.local_addr());
    for seq in [65_534, 65_535, 65_536, 65_537, 65_540] {
        let frame = make_frame(seq, 181);
        server.publish(&frame).unwrap();
        assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);
    }
    assert_eq!(client.stats().lost_scans, 2);
}

#[test]
fn connection_loss_is_a_typed_error_and_reconnect_resumes() {
    let first = server(ServerConfig::lms111());
    let addr = first.local_addr();
    let mut client = driver(addr);
    let frame = make_frame(10, 541);
    first.publish(&frame).unwrap();
    assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);

    drop(first);
    match client.next_frame(WAIT) {
        Err(ColaError::ConnectionLost { address }) => assert_eq!(address, addr.to_string()),
        other => panic!("{other:?}"),
    }
    assert!(!client.is_connected());
    // Every later call says the same until reconnect.
    assert!(matches!(
        client.next_frame(WAIT),
        Err(ColaError::ConnectionLost { .. })
    ));

    let second = ColaServer::bind(addr, ServerConfig::lms111()).unwrap();
    client.reconnect().unwrap();
    assert_eq!(client.stats().connects, 2);
    let frame = make_frame(11, 541);
    second.publish(&frame).unwrap();
    assert_same(&client.next_frame(WAIT).unwrap().unwrap(), &frame);
}

#[test]
fn connecting_to_nothing_names_the_address() {
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let address = format!("127.0.0.1:{port}");
    let err = ColaClient::connect(&address, ClientConfig::default()).unwrap_err();
    assert!(matches!(err, ColaError::Connect { .. }), "{err:?}");
    assert!(err.to_string().contains(&address), "{err}");
    let err = ColaClient::connect("127.0.0.1:99999", ClientConfig::default()).unwrap_err();
    assert!(matches!(err, ColaError::Address { .. }), "{err:?}");
    assert!(err.to_string().contains("127.0.0.1:99999"), "{err}");
}

#[test]
fn dropping_the_server_closes_its_clients() {
    let server = server(ServerConfig::lms111());
    let mut raw = Raw::connect(server.local_addr());
    assert_eq!(raw.ask("sEN LMDscandata 1"), "sEA LMDscandata 1");
    drop(server);
    assert!(raw.closed_by_server());
}

fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

#[test]
fn without_a_device_time_stamp_the_driver_stamps_with_the_host_clock() {
    // A scanner that sends no time-stamp block, as most do by default.
    let mut config = ServerConfig::lms111();
    config.encode.time_stamp = false;
    let server = server(config);
    let mut client = driver(server.local_addr());
    let frame = make_frame(1, 541);
    let before = wall_ns();
    server.publish(&frame).unwrap();
    let got = client.next_frame(WAIT).unwrap().unwrap();
    let after = wall_ns();
    // Received between `before` and `after`, back-dated by the scanner's own delay from
    // the start of the scan to its transmission: the scan time, 20 ms.
    let delay = 20_000_000;
    assert!(
        got.stamp_ns >= before - delay,
        "{} < {}",
        got.stamp_ns,
        before - delay
    );
    assert!(
        got.stamp_ns <= after - delay,
        "{} > {}",
        got.stamp_ns,
        after - delay
    );
    assert_eq!(got.sequence, 1);

    // With a time stamp, `host_stamps` still prefers the host clock.
    let server = self::server(ServerConfig::lms111());
    let config = ClientConfig {
        host_stamps: true,
        ..ClientConfig::default()
    };
    let mut client = ColaClient::connect(&server.local_addr().to_string(), config).unwrap();
    let before = wall_ns();
    server.publish(&frame).unwrap();
    let got = client.next_frame(WAIT).unwrap().unwrap();
    assert!(got.stamp_ns >= before - delay && got.stamp_ns <= wall_ns() - delay);
    assert_ne!(got.stamp_ns, frame.stamp_ns / 1000 * 1000);
}
