//! Laser frame publish-to-receive latency across two processes, with the subscriber
//! asleep in its event listener between frames:
//! `cargo bench -p firmware-bridge --bench laser_latency`.
//!
//! This process subscribes and re-executes itself as the publisher. The publisher
//! stamps each frame with CLOCK_REALTIME just before `publish` (a 541-beam frame,
//! validated, copied into shared memory, then the event notified); the subscriber reads
//! the clock when `recv_timeout` returns. Both run on the same host clock.

use std::process::Command;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use firmware_bridge::laser::{LaserFrame, LaserPublisher, LaserSubscriber, service_name};

const CHILD_ENV: &str = "UGV_LASER_BENCH_PUBLISHER";
const WARM_UP: u64 = 1 << 62;

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// Child: publish `n` frames at `rate_hz` once the subscriber is connected.
fn publisher(service: &str, n: u64, rate_hz: f64) -> Result<(), Box<dyn std::error::Error>> {
    let p = LaserPublisher::new(service)?;
    let mut f = LaserFrame::synthetic(0, 541);
    f.sequence = WARM_UP;
    while p.publish(&f)? == 0 {
        std::thread::sleep(Duration::from_millis(5));
    }
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let start = Instant::now() + period;
    let mut publish_ns = Vec::with_capacity(n as usize);
    for k in 0..n {
        let due = start + period * k as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        f.sequence = k;
        let t0 = Instant::now();
        f.stamp_ns = now_ns();
        p.publish(&f)?;
        publish_ns.push(t0.elapsed().as_nanos() as u64);
    }
    publish_ns.sort_unstable();
    let pct =
        |q: f64| publish_ns[((publish_ns.len() - 1) as f64 * q).round() as usize] as f64 / 1e3;
    println!(
        "  publish() call: p50 {:.1} us, p99 {:.1} us",
        pct(0.5),
        pct(0.99)
    );
    // Stay until the subscriber has drained (it exits after the last frame).
    std::thread::sleep(Duration::from_millis(200));
    Ok(())
}

fn run(n: u64, rate_hz: f64) -> Result<(), Box<dyn std::error::Error>> {
    let service = service_name(&format!("bench-{}-{rate_hz}", std::process::id()));
    let sub = LaserSubscriber::new(&service)?;
    let mut child = Command::new(std::env::current_exe()?)
        .env(CHILD_ENV, format!("{service}|{n}|{rate_hz}"))
        .spawn()?;
    let mut latencies = Vec::with_capacity(n as usize);
    let mut lost = 0;
    let mut next = 0;
    while next < n {
        let Some(f) = sub.recv_timeout(Duration::from_secs(10))? else {
            break;
        };
        let at = now_ns();
        if f.sequence == WARM_UP {
            continue;
        }
        lost += f.sequence - next;
        next = f.sequence + 1;
        latencies.push(at.saturating_sub(f.stamp_ns));
    }
    child.wait()?;
    latencies.sort_unstable();
    if latencies.is_empty() {
        return Err("no frames received".into());
    }
    let pct = |q: f64| latencies[((latencies.len() - 1) as f64 * q).round() as usize] as f64 / 1e3;
    println!(
        "{n} frames at {rate_hz} Hz, publish-to-receive: p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us, lost {lost}",
        pct(0.5),
        pct(0.9),
        pct(0.99),
        pct(1.0)
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    if let Ok(spec) = std::env::var(CHILD_ENV) {
        let parts: Vec<&str> = spec.split('|').collect();
        let [service, n, rate] = parts.as_slice() else {
            return Err(format!("bad {CHILD_ENV}: {spec}").into());
        };
        return publisher(service, n.parse()?, rate.parse()?);
    }
    run(500, 50.0)?;
    run(2000, 1000.0)?;
    Ok(())
}
