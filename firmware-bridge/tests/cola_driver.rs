//! The driver loop (`cola::driver::drive`, behind `ugv-sick` and the simulator's CoLa-A
//! laser) against a `ColaServer` on loopback TCP: scans reach the iceoryx2 service, a
//! restarted scanner is reconnected to, `--no-reconnect`'s loop ends with the error,
//! and the stop ends it. Every test uses its own service name.
//!
//! Waits are bounded by a generous `WAIT` only so that a broken build fails instead of
//! hanging; nothing asserts how fast anything is.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::net::SocketAddr;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use firmware_bridge::cola::driver::{DriverConfig, DriverEvent, DriverStats, drive};
use firmware_bridge::cola::{ClientConfig, ColaClient, ColaError, ColaServer, ServerConfig};
use firmware_bridge::laser::{LaserFrame, LaserPublisher, LaserSubscriber};

const WAIT: Duration = Duration::from_secs(20);

fn unique_service(test: &str) -> String {
    common::unique_service("driver", test)
}

/// What a driver thread saw: each event as text (errors with their message).
type Seen = mpsc::Receiver<String>;

/// `drive` on a thread against the scanner at `addr`, publishing on `service`; drop the
/// returned sender to stop it.
fn start(
    addr: SocketAddr,
    service: &str,
    config: DriverConfig,
) -> (
    mpsc::Sender<()>,
    Seen,
    JoinHandle<Result<DriverStats, ColaError>>,
) {
    let mut client = ColaClient::connect(&addr.to_string(), ClientConfig::default()).unwrap();
    let publisher = LaserPublisher::new(service).unwrap();
    let (stop_tx, stop) = mpsc::channel();
    let (seen_tx, seen) = mpsc::channel();
    let thread = std::thread::spawn(move || {
        drive(&mut client, &publisher, &config, &stop, |event, _| {
            let text = match (event, event.error()) {
                (DriverEvent::Idle, _) => return,
                (_, Some(e)) => format!("{event:?}: {e}"),
                (_, None) => format!("{event:?}"),
            };
            let _ = seen_tx.send(text);
        })
    });
    (stop_tx, seen, thread)
}

/// Publish `frame` on the server until a streaming client has it queued.
fn serve(server: &ColaServer, frame: &LaserFrame) {
    let deadline = Instant::now() + WAIT;
    while server.streaming_clients() == 0 {
        assert!(
            Instant::now() < deadline,
            "the driver never asked for scans"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(server.publish(frame).unwrap(), 1);
}

/// The next event that is not a `Silent`.
fn next_event(seen: &Seen) -> String {
    loop {
        let e = seen.recv_timeout(WAIT).expect("an event within WAIT");
        if !e.starts_with("Silent") {
            return e;
        }
    }
}

#[test]
fn the_driver_publishes_scans_and_reconnects_to_a_restarted_scanner() {
    let service = unique_service("restart");
    let subscriber = LaserSubscriber::new(&service).unwrap();
    let first = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111()).unwrap();
    let addr = first.local_addr();
    let (stop, seen, thread) = start(addr, &service, DriverConfig::default());

    let frame = LaserFrame::synthetic(1, 541);
    serve(&first, &frame);
    let got = subscriber.recv_timeout(WAIT).unwrap().expect("scan 1");
    assert_eq!((got.sequence, got.len()), (1, 541));
    assert_eq!(next_event(&seen), "Published { sequence: 1 }");

    drop(first);
    let lost = next_event(&seen);
    assert!(lost.starts_with("Lost"), "{lost}");
    assert!(lost.contains(&addr.to_string()), "{lost}");
    let second = ColaServer::bind(addr, ServerConfig::lms111()).unwrap();
    serve(&second, &LaserFrame::synthetic(2, 541));
    let got = subscriber.recv_timeout(WAIT).unwrap().expect("scan 2");
    assert_eq!(got.sequence, 2);
    let rest: Vec<String> = std::iter::from_fn(|| Some(next_event(&seen)))
        .take_while(|e| !e.starts_with("Published"))
        .collect();
    assert_eq!(
        rest.last().map(String::as_str),
        Some("Reconnected"),
        "{rest:?}"
    );
    assert!(
        rest.iter()
            .all(|e| e == "Reconnected" || e.starts_with("ReconnectFailed")),
        "{rest:?}"
    );

    drop(stop);
    let stats = thread.join().unwrap().unwrap();
    assert_eq!(
        (stats.published, stats.publish_errors, stats.bad),
        (2, 0, 0)
    );
    assert_eq!(stats.client.connects, 2);
}

#[test]
fn without_reconnect_a_dropped_connection_ends_the_loop_with_its_error() {
    let service = unique_service("noreconnect");
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111()).unwrap();
    let addr = server.local_addr();
    let config = DriverConfig {
        reconnect: false,
        ..DriverConfig::default()
    };
    let (_stop, _seen, thread) = start(addr, &service, config);
    serve(&server, &LaserFrame::synthetic(1, 541));
    drop(server);
    match thread.join().unwrap() {
        Err(ColaError::ConnectionLost { address }) => assert_eq!(address, addr.to_string()),
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_driver_stops_after_count_scans() {
    let service = unique_service("count");
    let subscriber = LaserSubscriber::new(&service).unwrap();
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111()).unwrap();
    let config = DriverConfig {
        count: Some(2),
        ..DriverConfig::default()
    };
    let (_stop, _seen, thread) = start(server.local_addr(), &service, config);
    for seq in 0..2 {
        serve(&server, &LaserFrame::synthetic(seq, 181));
        assert_eq!(
            subscriber.recv_timeout(WAIT).unwrap().unwrap().sequence,
            seq
        );
    }
    let stats = thread.join().unwrap().unwrap();
    assert_eq!(stats.published, 2);
}
