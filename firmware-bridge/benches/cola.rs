//! CoLa-A laser: codec rate of a 541-beam LMS111 scan, and publish-to-receive latency
//! of `ColaServer` to `ColaClient` over loopback TCP:
//! `cargo bench -p firmware-bridge --bench cola`.
//!
//! Codec: the server's path (`scan_from_frame` + encode, 8-bit RSSI and the time stamp
//! as the server sends them) and the driver's path (parse + `frame_from_scan`), timed
//! over many iterations of the same frame.
//!
//! Latency: one process, a server and a driver on 127.0.0.1. The publishing thread
//! stamps each frame with CLOCK_REALTIME just before `publish`; the driver's thread
//! reads the clock when `next_frame` returns and subtracts the frame's stamp (which
//! travels in the telegram's time-stamp block, truncated to the µs, so figures are up to
//! 1 µs high). The time `publish` itself takes (encode once, queue per client; what the
//! simulator's loop pays) is reported too.

use std::hint::black_box;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use firmware_bridge::cola::{
    ClientConfig, ColaClient, ColaServer, DecodeOptions, EncodeOptions, ScanData, ScanKind,
    ServerConfig, frame_from_scan, scan_from_frame,
};
use firmware_bridge::laser::LaserFrame;

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// An LMS111 scan (541 beams over 270°, some no-returns and dropouts) stamped now.
fn frame() -> LaserFrame {
    LaserFrame {
        stamp_ns: now_ns(),
        ..LaserFrame::synthetic(0, 541)
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

fn codec() -> Result<(), Box<dyn std::error::Error>> {
    let f = frame();
    let opts = EncodeOptions::default();
    let decode = DecodeOptions::default();
    let telegram = scan_from_frame(&f, &opts)?.encode(ScanKind::Streamed)?;
    println!(
        "codec: one 541-beam LMS111 scan with 8-bit RSSI and time stamp is {} bytes",
        telegram.len() + 2
    );
    let n = 20_000;
    // Warm up.
    for _ in 0..1000 {
        black_box(scan_from_frame(black_box(&f), &opts)?.encode(ScanKind::Streamed)?);
    }
    let t = Instant::now();
    for _ in 0..n {
        black_box(scan_from_frame(black_box(&f), &opts)?.encode(ScanKind::Streamed)?);
    }
    let encode = t.elapsed().as_secs_f64() / f64::from(n);
    let t = Instant::now();
    for _ in 0..n {
        let (_, scan) = ScanData::parse(black_box(&telegram))?;
        black_box(frame_from_scan(&scan, &decode)?);
    }
    let parse = t.elapsed().as_secs_f64() / f64::from(n);
    println!(
        "codec: frame -> telegram {:.1} µs ({:.0} scans/s); telegram -> frame {:.1} µs ({:.0} scans/s); both {:.1} µs ({:.0} scans/s per core)",
        encode * 1e6,
        1.0 / encode,
        parse * 1e6,
        1.0 / parse,
        (encode + parse) * 1e6,
        1.0 / (encode + parse)
    );
    // publish() with nobody connected: the encoding and bookkeeping alone, back to back
    // (warm caches) and paced at 50 Hz (cold, as in the simulator's loop).
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111())?;
    let t = Instant::now();
    for _ in 0..n {
        server.publish(black_box(&f))?;
    }
    let back_to_back = t.elapsed().as_secs_f64() / f64::from(n) * 1e6;
    let mut paced = Vec::with_capacity(250);
    for _ in 0..250 {
        std::thread::sleep(Duration::from_millis(20));
        let t0 = Instant::now();
        server.publish(black_box(&f))?;
        paced.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    paced.sort_by(f64::total_cmp);
    println!(
        "codec: publish() without clients {back_to_back:.1} µs back to back; paced at 50 Hz p50 {:.1} µs, p99 {:.1} µs",
        percentile(&paced, 0.5),
        percentile(&paced, 0.99)
    );
    Ok(())
}

fn latency(rate_hz: f64, n: usize) -> Result<(), Box<dyn std::error::Error>> {
    let server = ColaServer::bind("127.0.0.1:0", ServerConfig::lms111())?;
    let mut client =
        ColaClient::connect(&server.local_addr().to_string(), ClientConfig::default())?;
    // Receives until the last scan, or until none comes for 2 s (the last was dropped).
    let receiver = std::thread::spawn(move || -> Result<Vec<f64>, String> {
        let mut latencies = Vec::with_capacity(n);
        let mut wait = Duration::from_secs(10);
        loop {
            match client.next_frame(wait) {
                Ok(Some(f)) => {
                    latencies.push((now_ns().saturating_sub(f.stamp_ns)) as f64 / 1e3);
                    wait = Duration::from_secs(2);
                    if f.sequence + 1 >= n as u64 {
                        return Ok(latencies);
                    }
                }
                Ok(None) if !latencies.is_empty() => return Ok(latencies),
                Ok(None) => return Err("no scan for 10 s".into()),
                Err(e) => return Err(e.to_string()),
            }
        }
    });
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let mut f = frame();
    let start = Instant::now() + period;
    let mut publish_us = Vec::with_capacity(n);
    for k in 0..n {
        let due = start + period * k as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        f.sequence = k as u64;
        f.stamp_ns = now_ns();
        let t0 = Instant::now();
        server.publish(&f)?;
        publish_us.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    let mut latencies = receiver.join().map_err(|_| "receiver panicked")??;
    latencies.sort_by(f64::total_cmp);
    publish_us.sort_by(f64::total_cmp);
    let stats = server.stats();
    println!(
        "latency at {rate_hz} Hz, {n} scans ({} received): publish -> next_frame p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs; publish() p50 {:.1} µs, p99 {:.1} µs; dropped {}",
        latencies.len(),
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.99),
        percentile(&latencies, 1.0),
        percentile(&publish_us, 0.5),
        percentile(&publish_us, 0.99),
        stats.frames_dropped
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; any other argument filters nothing here.
    codec()?;
    latency(50.0, 1000)?;
    latency(1000.0, 5000)?;
    Ok(())
}
