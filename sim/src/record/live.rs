//! The live view (`ugv-sim run --live [ADDR]`): the recorder's channels served over
//! the Foxglove WebSocket protocol while the run goes, by the Foxglove SDK's server on
//! the same [`Context`] the recorder logs through. The topics and schemas are those of
//! run.mcap ([`super::topics`]); with `--no-record` the channels are still created, for
//! the live view alone.
//!
//! The server runs on the SDK's own tokio runtime (its worker threads, started here,
//! before a HIL tick loop raises its priority or enters a private network namespace).
//! Logging never waits for a client: each client has a bounded queue
//! ([`BACKLOG`] messages) that the logging thread fills with a non-blocking send,
//! dropping the oldest message when it is full, and a client too slow for its control
//! queue is disconnected (the SDK's `send_lossy`, tested below with a client that
//! stops reading).
//!
//! The SDK (0.30) speaks the protocol under the WebSocket subprotocol names
//! `foxglove.sdk.v1` and `foxglove.sdk.v1.1`; a client offering only the older name
//! `foxglove.websocket.v1` (the same protocol) is refused with HTTP 400. The Foxglove
//! app offers the new names.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;

use foxglove::{Context, WebSocketServer, WebSocketServerHandle};

/// Where `--live` without a value serves.
pub const DEFAULT_ADDR: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 8765);
/// [`DEFAULT_ADDR`] as the command line's default text.
pub const DEFAULT_ADDR_TEXT: &str = "127.0.0.1:8765";
/// Messages queued per client before the oldest are dropped (the SDK's default: about
/// a second of the run's topics).
pub const BACKLOG: usize = 1024;

/// Why the live view could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("starting the live view's WebSocket server on {addr}: {source}")]
    Start {
        addr: SocketAddr,
        #[source]
        source: foxglove::FoxgloveError,
    },
}

/// `--live`'s value: an IP address and port, `127.0.0.1:8765` or `[::1]:8765` (port 0:
/// any free port). Host names are not resolved, so the address served is the one
/// written.
pub fn parse_addr(text: &str) -> Result<SocketAddr, String> {
    text.parse::<SocketAddr>().map_err(|_| {
        let hint = if text.ends_with(".toml") || text.contains('/') {
            " (a scenario file? --live takes an optional address: put the scenario before --live, or write --live=ADDR)"
        } else {
            ""
        };
        format!(
            "'{text}' is not an IP address and port such as {DEFAULT_ADDR_TEXT} or [::1]:8765 (host names are not resolved){hint}"
        )
    })
}

/// The live view's server on its own [`Context`], which the recorder logs through.
pub struct LiveView {
    ctx: Arc<Context>,
    handle: WebSocketServerHandle,
    addr: SocketAddr,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.addr)
            .field("clients", &self.handle.client_count())
            .finish_non_exhaustive()
    }
}

impl LiveView {
    /// Start serving on `addr` (port 0: any free port, see [`LiveView::addr`]).
    pub fn start(addr: SocketAddr) -> Result<LiveView, LiveError> {
        let ctx = Context::new();
        let host = match addr.ip() {
            IpAddr::V4(ip) => ip.to_string(),
            IpAddr::V6(ip) => format!("[{ip}]"),
        };
        let handle = WebSocketServer::new()
            .name("ugv-sim")
            .context(&ctx)
            .message_backlog_size(BACKLOG)
            .bind(host, addr.port())
            .start_blocking()
            .map_err(|source| LiveError::Start { addr, source })?;
        Ok(LiveView {
            ctx,
            addr: SocketAddr::new(addr.ip(), handle.port()),
            handle,
        })
    }

    /// The address served (with the port the system chose for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// `ws://ADDR`, what a viewer connects to.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// The context the recorder's channels are created in.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Clients connected now.
    pub fn client_count(&self) -> usize {
        self.handle.client_count()
    }

    /// Where to connect and how, for stderr.
    pub fn how_to_connect(&self) -> String {
        let url = self.url();
        let mut text = format!(
            "live view on {url}: in Foxglove, Open connection -> Foxglove WebSocket -> {url}"
        );
        if !self.addr.ip().is_loopback() {
            text.push_str(&format!(
                " (serving on {}, not loopback: anyone who can reach it sees the run)",
                self.addr.ip()
            ));
        }
        text
    }

    /// Stop serving: the clients are disconnected.
    pub fn stop(self) {
        drop(self.handle.stop());
    }
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::sync::mpsc;
    use std::time::{Duration, Instant};

    use firmware_bridge::laser::LaserFrame;

    use super::super::{Outputs, RecordMode, Recorder, run_info, topics};
    use super::*;
    use crate::scenario::Scenario;

    #[test]
    fn addresses_are_ip_and_port_and_bad_ones_say_what_is_wanted() {
        assert_eq!(parse_addr("127.0.0.1:8765"), Ok(DEFAULT_ADDR));
        assert_eq!(parse_addr(DEFAULT_ADDR_TEXT), Ok(DEFAULT_ADDR));
        assert_eq!(
            parse_addr("[::1]:9000").map(|a| (a.ip().is_loopback(), a.port())),
            Ok((true, 9000))
        );
        for bad in [
            "localhost:8765",
            "example.com:8765",
            "999.1.1.1:8765",
            "127.0.0.1",
            "127.0.0.1:99999",
            "8765",
            "",
            "ws://127.0.0.1:8765",
        ] {
            let e = parse_addr(bad).unwrap_err();
            assert!(
                e.contains(&format!("'{bad}' is not an IP address and port"))
                    && e.contains("127.0.0.1:8765"),
                "{bad}: {e}"
            );
        }
        assert!(
            parse_addr("sim/scenarios/paper.toml")
                .unwrap_err()
                .contains("put the scenario before --live")
        );
    }

    #[test]
    fn an_address_in_use_is_an_error_naming_it() {
        let first = LiveView::start("127.0.0.1:0".parse().unwrap()).unwrap();
        let second = LiveView::start(first.addr()).unwrap_err();
        let text = second.to_string();
        assert!(
            text.contains(&first.addr().to_string()) && text.contains("live view"),
            "{text}"
        );
        assert!(first.how_to_connect().contains(&format!(
            "Open connection -> Foxglove WebSocket -> ws://{}",
            first.addr()
        )));
        first.stop();
    }

    fn frame() -> LaserFrame {
        let mut f = LaserFrame {
            count: 541,
            angle_min: (-135.0f32).to_radians(),
            angle_increment: 0.5f32.to_radians(),
            time_increment: 0.02 / 720.0,
            scan_time: 0.02,
            range_min: 0.05,
            range_max: 20.0,
            ..LaserFrame::default()
        };
        f.ranges[..541].fill(5.0);
        f.intensities[..541].fill(100.0);
        f
    }

    /// One WebSocket frame from the server (unmasked, not fragmented): opcode, payload.
    fn read_frame(s: &mut TcpStream) -> std::io::Result<(u8, Vec<u8>)> {
        let mut head = [0u8; 2];
        s.read_exact(&mut head)?;
        let len = match head[1] & 0x7f {
            126 => {
                let mut b = [0u8; 2];
                s.read_exact(&mut b)?;
                u64::from(u16::from_be_bytes(b))
            }
            127 => {
                let mut b = [0u8; 8];
                s.read_exact(&mut b)?;
                u64::from_be_bytes(b)
            }
            n => u64::from(n),
        };
        let mut payload = vec![0u8; usize::try_from(len).unwrap()];
        s.read_exact(&mut payload)?;
        Ok((head[0] & 0x0f, payload))
    }

    /// A masked text frame from the client.
    fn text_frame(text: &str) -> Vec<u8> {
        let payload = text.as_bytes();
        let mut out = vec![0x81];
        match payload.len() {
            n @ 0..=125 => out.push(0x80 | n as u8),
            n => {
                out.push(0x80 | 126);
                out.extend(u16::try_from(n).unwrap().to_be_bytes());
            }
        }
        let mask = [0x12, 0x34, 0x56, 0x78];
        out.extend(mask);
        out.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        out
    }

    /// A client that subscribes to the laser and then stops reading must not slow the
    /// logging thread: its queue fills and the oldest messages are dropped (a blocking
    /// send would hang the burst below once the socket buffers are full).
    #[test]
    fn a_client_that_stops_reading_never_blocks_the_logging_thread() {
        let live = LiveView::start("127.0.0.1:0".parse().unwrap()).unwrap();
        let sc = Scenario::paper().unwrap();
        let info = run_info(RecordMode::Sil, &sc, String::new());
        let mut rec = Recorder::create(
            Outputs {
                dir: None,
                live: Some(&live),
            },
            &sc,
            info,
        )
        .unwrap();

        let addr = live.addr();
        let (subscribed_tx, subscribed) = mpsc::channel();
        let (done_tx, done) = mpsc::channel::<()>();
        let client = std::thread::spawn(move || -> std::io::Result<()> {
            let mut s = TcpStream::connect(addr)?;
            s.set_read_timeout(Some(Duration::from_secs(20)))?;
            write!(
                s,
                "GET / HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
                 Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
                 Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
            )?;
            let mut response = Vec::new();
            while !response.ends_with(b"\r\n\r\n") {
                let mut b = [0u8; 1];
                s.read_exact(&mut b)?;
                response.push(b[0]);
            }
            assert!(response.starts_with(b"HTTP/1.1 101"), "{response:?}");
            // Advertisements until the laser's channel, then subscribe to it.
            let laser_id = loop {
                let (op, payload) = read_frame(&mut s)?;
                if op != 1 {
                    continue;
                }
                let v: serde_json::Value = serde_json::from_slice(&payload).unwrap();
                let laser = v["channels"].as_array().and_then(|cs| {
                    cs.iter()
                        .find(|c| c["topic"] == topics::LASER)
                        .and_then(|c| c["id"].as_u64())
                });
                if let Some(id) = laser {
                    break id;
                }
            };
            s.write_all(&text_frame(&format!(
                r#"{{"op":"subscribe","subscriptions":[{{"id":1,"channelId":{laser_id}}}]}}"#
            )))?;
            // The first message shows the subscription is in place; then stop reading.
            while read_frame(&mut s)?.0 != 2 {}
            let _ = subscribed_tx.send(());
            let _ = done.recv_timeout(Duration::from_secs(120));
            Ok(())
        });

        let start = Instant::now();
        let mut t = 0.0;
        while subscribed.try_recv().is_err() {
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "the client never got a message"
            );
            rec.w.laser(t, &frame());
            t += 0.02;
            std::thread::sleep(Duration::from_millis(10));
        }
        // About 44 MB of scans at once, far beyond the socket buffers and the queue.
        let burst = Instant::now();
        let mut slowest = Duration::ZERO;
        for _ in 0..5000 {
            let one = Instant::now();
            rec.w.laser(t, &frame());
            slowest = slowest.max(one.elapsed());
            t += 0.02;
        }
        let took = burst.elapsed();
        assert_eq!(live.client_count(), 1, "the stalled client is still there");
        let _ = done_tx.send(());
        client.join().unwrap().unwrap();
        assert!(
            took < Duration::from_secs(30) && slowest < Duration::from_secs(1),
            "5000 scans took {took:?} (slowest {slowest:?}) with a client not reading"
        );
        live.stop();
    }
}
