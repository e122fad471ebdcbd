//! The CAN gateway's cost: added latency per frame and throughput.
//!
//! Latency, one frame in flight at a time (ping-pong), monotonic clock in one process:
//! - direct: send on the simulator's interface, receive on another socket of the same
//!   interface (the kernel's vcan loopback alone);
//! - through the gateway: send on the simulator's interface, receive on the physical
//!   one, STEERING_CMD forwarded by an in-process gateway (STEERING_ECU physical).
//!
//! The difference is what the gateway adds (one receive, one routing decision, one
//! transmit, and the second loopback). Also printed: the gateway's own measurement
//! (kernel receive timestamp to the end of its transmit call).
//!
//! Throughput: a sender blasts frames as fast as the socket takes them, the receiver
//! counts them, one direction and then both at once; lost must be 0.
//!
//! Needs two CAN interfaces that are up: `UGV_BENCH_SIM` (default vcan0) and
//! `UGV_BENCH_PHYS` (default vcan1). On a host without CAN:
//! `cargo bench -p firmware-bridge --bench gateway --no-run`, then
//! `vcan-setup vm --iface vcan1 -- target/release/deps/gateway-<hash>`.
//! `UGV_BENCH_PINGS` (default 5000) and `UGV_BENCH_FRAMES` (default 100000) set the
//! sample sizes.

use std::os::fd::AsRawFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use firmware_bridge::gateway::{Gateway, GatewayConfig, GatewayHandle};
use nix::errno::Errno;
use nix::sys::socket::{self, MsgFlags, sockopt};
use socketcan::{CanSocket, Socket};

const STEERING_CMD: u32 = 0x100;
const STEERING_REPORT: u32 = 0x101;
const IDLE: Duration = Duration::from_secs(20);
/// Frames in flight in the windowed throughput runs (about 3 MB of socket queue, far
/// below the gateway's; deep enough that the sender seldom waits).
const WINDOW: u32 = 4096;
/// The unpaced burst each way.
const BURST: u32 = 20_000;

struct Node {
    sock: CanSocket,
}

impl Node {
    fn open(iface: &str) -> Result<Node> {
        let sock = CanSocket::open(iface).with_context(|| {
            format!("opening {iface} (create it: vcan-setup up {iface}, or vcan-setup vm --iface {iface})")
        })?;
        // Best effort: a deep queue for the receiver of a blast (needs CAP_NET_ADMIN).
        let _ = socket::setsockopt(&sock, sockopt::RcvBufForce, &(32usize << 20));
        sock.set_read_timeout(Duration::from_millis(200))?;
        Ok(Node { sock })
    }

    fn send(&self, id: u32, seq: u32) -> Result<()> {
        let mut bytes = [0u8; 16];
        bytes[..4].copy_from_slice(&id.to_ne_bytes());
        bytes[4] = 8;
        bytes[8..12].copy_from_slice(&seq.to_le_bytes());
        loop {
            match socket::send(self.sock.as_raw_fd(), &bytes, MsgFlags::empty()) {
                Ok(_) => return Ok(()),
                Err(Errno::ENOBUFS | Errno::EAGAIN | Errno::EINTR) => {
                    std::thread::sleep(Duration::from_micros(50));
                }
                Err(e) => bail!("send: {e}"),
            }
        }
    }

    /// The sequence number of the next frame of `id`, `None` after IDLE without one.
    fn recv(&self, id: u32) -> Result<Option<u32>> {
        let deadline = Instant::now() + IDLE;
        loop {
            match self.sock.read_raw_frame() {
                Ok(f) if f.can_id == id => {
                    return Ok(Some(u32::from_le_bytes([
                        f.data[0], f.data[1], f.data[2], f.data[3],
                    ])));
                }
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    if Instant::now() >= deadline {
                        return Ok(None);
                    }
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
}

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn quantile_us(sorted: &[Duration], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i].as_secs_f64() * 1e6
}

/// Ping-pong latencies, microseconds at p50 and p99.
fn ping_pong(tx: &Node, rx: &Node, pings: u32) -> Result<(f64, f64)> {
    // Warm up (page faults, caches, the gateway's first frames).
    for seq in 0..100 {
        tx.send(STEERING_CMD, seq)?;
        rx.recv(STEERING_CMD)?.context("warm-up frame lost")?;
    }
    let mut lat = Vec::with_capacity(pings as usize);
    for seq in 0..pings {
        let t0 = Instant::now();
        tx.send(STEERING_CMD, seq)?;
        loop {
            match rx.recv(STEERING_CMD)? {
                Some(s) if s == seq => break,
                Some(_) => {}
                None => bail!("ping {seq} lost"),
            }
        }
        lat.push(t0.elapsed());
    }
    lat.sort_unstable();
    Ok((quantile_us(&lat, 0.5), quantile_us(&lat, 0.99)))
}

/// Send `n` frames of `id` from `tx` as fast as the socket takes them (with
/// `window`: at most that many not yet received), count them at `rx`: (received,
/// seconds from the first send to the last receive).
fn blast(tx: Arc<Node>, rx: Arc<Node>, id: u32, n: u32, window: Option<u32>) -> Result<(u32, f64)> {
    let start = Instant::now();
    let received = Arc::new(AtomicU32::new(0));
    let receiver = {
        let received = Arc::clone(&received);
        std::thread::spawn(move || -> Result<Instant> {
            let mut last = Instant::now();
            while received.load(Ordering::Relaxed) < n {
                match rx.recv(id)? {
                    Some(_) => {
                        received.fetch_add(1, Ordering::Relaxed);
                        last = Instant::now();
                    }
                    None => break,
                }
            }
            Ok(last)
        })
    };
    for seq in 0..n {
        if let Some(w) = window {
            let waited = Instant::now();
            while seq - received.load(Ordering::Relaxed) >= w {
                ensure!(waited.elapsed() < IDLE, "frames stopped arriving");
                std::thread::sleep(Duration::from_micros(100));
            }
        }
        tx.send(id, seq)?;
    }
    let last = receiver
        .join()
        .map_err(|_| anyhow::anyhow!("receiver panicked"))??;
    Ok((
        received.load(Ordering::Relaxed),
        last.duration_since(start).as_secs_f64(),
    ))
}

fn gateway(sim: &str, phys: &str) -> Result<GatewayHandle> {
    Ok(Gateway::spawn(GatewayConfig {
        sim_iface: sim.to_owned(),
        physical_iface: phys.to_owned(),
        physical_nodes: vec!["STEERING_ECU".to_owned()],
        ..GatewayConfig::default()
    })?)
}

fn main() -> Result<()> {
    // `cargo bench` passes --bench; nothing to parse.
    let sim: String = env_or("UGV_BENCH_SIM", "vcan0".to_owned());
    let phys: String = env_or("UGV_BENCH_PHYS", "vcan1".to_owned());
    let pings: u32 = env_or("UGV_BENCH_PINGS", 5000);
    let frames: u32 = env_or("UGV_BENCH_FRAMES", 100_000);

    // 1. Latency without the gateway: two sockets on the simulator's interface.
    let (d50, d99) = {
        let a = Node::open(&sim)?;
        let b = Node::open(&sim)?;
        ping_pong(&a, &b, pings)?
    };
    // 2. The same path through the gateway.
    let gw = gateway(&sim, &phys)?;
    let (g50, g99) = {
        let a = Node::open(&sim)?;
        let c = Node::open(&phys)?;
        ping_pong(&a, &c, pings)?
    };
    let own = gw.stop();
    println!(
        "gateway latency sim={sim} phys={phys} pings={pings}: direct p50 {d50:.1} us p99 {d99:.1} us; through the gateway p50 {g50:.1} us p99 {g99:.1} us; added p50 {:.1} us p99 {:.1} us; gateway's own (kernel rx stamp -> sent) p50 {:.1} us p99 {:.1} us, handling p50 {:.1} us p99 {:.1} us",
        g50 - d50,
        g99 - d99,
        own.to_physical.latency.p50_us,
        own.to_physical.latency.p99_us,
        own.to_physical.handling.p50_us,
        own.to_physical.handling.p99_us,
    );

    // 3. Throughput, at most WINDOW frames in flight (a deeper backlog than any
    // socket queue can hold would be lost by the kernel: see 5 and 6).
    let a = Arc::new(Node::open(&sim)?);
    let b = Arc::new(Node::open(&sim)?);
    let (got, secs) = blast(Arc::clone(&a), b, STEERING_CMD, frames, Some(WINDOW))?;
    println!(
        "direct throughput on {sim}: {frames} frames, window {WINDOW}: {:.0} frames/s, lost {}",
        f64::from(got) / secs,
        frames - got
    );
    let c = Arc::new(Node::open(&phys)?);
    let one_way = |n: u32, window: Option<u32>| -> Result<()> {
        let gw = gateway(&sim, &phys)?;
        let (got, secs) = blast(Arc::clone(&a), Arc::clone(&c), STEERING_CMD, n, window)?;
        let st = gw.stop();
        let d = &st.to_physical;
        println!(
            "gateway {sim}->{phys}: {n} frames, window {}: {:.0} frames/s forwarded, lost {}; gateway forwarded {} tx retries {} dropped {} rx overflow {}",
            window.map_or("none".to_owned(), |w| w.to_string()),
            f64::from(got) / secs,
            n - got,
            d.forwarded,
            d.tx_retries,
            d.tx_dropped,
            d.rx_overflow
        );
        ensure!(
            u64::from(n - got) == d.rx_overflow + d.tx_dropped,
            "lost frames the gateway did not count"
        );
        Ok(())
    };
    let both_ways = |n: u32, window: Option<u32>| -> Result<u32> {
        let gw = gateway(&sim, &phys)?;
        let out = {
            let (a, c) = (Arc::clone(&a), Arc::clone(&c));
            std::thread::spawn(move || blast(a, c, STEERING_CMD, n, window))
        };
        let (got_in, secs_in) = blast(Arc::clone(&c), Arc::clone(&a), STEERING_REPORT, n, window)?;
        let (got_out, secs_out) = out
            .join()
            .map_err(|_| anyhow::anyhow!("sender panicked"))??;
        let st = gw.stop();
        let (o, i) = (&st.to_physical, &st.to_sim);
        println!(
            "gateway both ways at once: {n} frames each way, window {}: {:.0} frames/s in total ({:.0} out, {:.0} in), lost {} out {} in; tx retries {}/{}, dropped {}/{}, rx overflow {}/{}",
            window.map_or("none".to_owned(), |w| w.to_string()),
            f64::from(got_out + got_in) / secs_out.max(secs_in),
            f64::from(got_out) / secs_out,
            f64::from(got_in) / secs_in,
            n - got_out,
            n - got_in,
            o.tx_retries,
            i.tx_retries,
            o.tx_dropped,
            i.tx_dropped,
            o.rx_overflow,
            i.rx_overflow,
        );
        ensure!(
            u64::from(n - got_out) == o.rx_overflow + o.tx_dropped
                && u64::from(n - got_in) == i.rx_overflow + i.tx_dropped,
            "lost frames the gateway did not count"
        );
        Ok(2 * n - got_out - got_in)
    };
    // 4. One direction, then both at once, windowed: must lose nothing.
    one_way(frames, Some(WINDOW))?;
    ensure!(both_ways(frames, Some(WINDOW))? == 0, "frames lost");
    // 5. An unpaced burst of BURST frames each way at once (what the test suite
    // checks): the sockets' queues absorb it, nothing lost.
    ensure!(both_ways(BURST, None)? == 0, "frames lost in the burst");
    // 6. An unpaced blast far longer than the queues: what is lost is counted.
    one_way(frames, None)?;
    Ok(())
}
