//! CAN throughput of one process on a SocketCAN interface: one endpoint sends
//! E2E-protected STEERING_CMD frames as fast as the socket takes them, another
//! endpoint of the same process receives and checks them.
//!
//! `UGV_BENCH_IFACE` (default vcan0) must exist and be up; on a host without CAN:
//! `vcan-setup vm -- cargo bench -p firmware-bridge --bench can_throughput`.
//! `UGV_BENCH_FRAMES` sets the number of frames (default 200000).

use std::time::{Duration, Instant};

use firmware_bridge::{CanPort, Received};
use golf_car_can::SteeringCmd;

fn main() -> anyhow::Result<()> {
    let iface = std::env::var("UGV_BENCH_IFACE").unwrap_or_else(|_| "vcan0".to_owned());
    let frames: u64 = std::env::var("UGV_BENCH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let mut rx = CanPort::open(&iface)?;
    let mut tx = CanPort::open(&iface)?;
    let receiver = std::thread::spawn(move || -> anyhow::Result<(u64, u64, Duration)> {
        let (mut ok, mut bad) = (0u64, 0u64);
        let mut first: Option<Instant> = None;
        let mut last = Instant::now();
        while ok + bad < frames {
            match rx.recv(Duration::from_secs(5))? {
                Some(Received::Message(_)) => ok += 1,
                Some(_) => bad += 1,
                None => break,
            }
            last = Instant::now();
            first.get_or_insert(last);
        }
        Ok((ok, bad, last.duration_since(first.unwrap_or(last))))
    });
    let cmd = SteeringCmd {
        enable: true,
        target_angle: 12.5,
        max_rate: 60.0,
    };
    let start = Instant::now();
    for _ in 0..frames {
        tx.send(&cmd)?;
    }
    let sent_in = start.elapsed();
    let (ok, bad, recv_in) = receiver
        .join()
        .map_err(|_| anyhow::anyhow!("receiver thread panicked"))??;
    println!(
        "can_throughput iface={iface} frames={frames} send={:.0} frames/s receive={:.0} frames/s received={ok} rejected={bad} lost={}",
        frames as f64 / sent_in.as_secs_f64(),
        ok as f64 / recv_in.as_secs_f64().max(1e-9),
        frames - ok - bad
    );
    Ok(())
}
