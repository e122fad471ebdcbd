//! The GPS serial line's pacing on simulated time: over one second at 10 Hz and
//! 115200 baud, driven from a 200 Hz tick loop, byte k of each epoch leaves at
//! epoch time + k * byte time (released in the first tick at or after it), never
//! earlier, and the line never carries more than its baud allows.

mod gps_common;

use anyhow::{Result, ensure};
use gps_common::{TICK_S, device, vehicle};
use ugv_sim::devices::gps::{GpsConfig, Pacer};

#[test]
fn one_second_at_10_hz_and_115200_baud_keeps_the_byte_schedule() -> Result<()> {
    let cfg = GpsConfig::default();
    ensure!(cfg.rate_hz == 10.0 && cfg.baud == 115_200);
    let mut dev = device(cfg.clone())?;
    let mut pacer = Pacer::new(cfg.baud);
    let bt = pacer.byte_time_s();
    ensure!((bt - 10.0 / 115_200.0).abs() < 1e-15, "8N1 byte time {bt}");

    let s = vehicle(3.0, 4.0, 20.0, 2.0, 5.0);
    // (epoch time, when its first byte leaves, its bytes)
    let mut epochs: Vec<(f64, f64, Vec<u8>)> = Vec::new();
    // (tick time, bytes released in that tick)
    let mut ticks: Vec<(f64, Vec<u8>)> = Vec::new();
    for k in 0..=200u32 {
        let now = f64::from(k) * TICK_S;
        if let Some(e) = dev.poll(now, &s)? {
            let start = pacer.enqueue(e.time_s, e.text.as_bytes());
            epochs.push((e.time_s, start, e.text.into_bytes()));
        }
        let mut out = Vec::new();
        pacer.release(now, &mut out);
        ticks.push((now, out));
    }
    ensure!(epochs.len() == 11, "{} epochs from 0 to 1 s", epochs.len());

    // Each epoch starts on its own epoch time (the line is idle by then) and is over
    // well before the next one.
    for (i, (t, start, bytes)) in epochs.iter().enumerate() {
        ensure!((t - i as f64 * 0.1).abs() < 1e-12, "epoch {i} at {t}");
        ensure!(start == t, "epoch {i} starts at {start}, not its time {t}");
        let last = t + (bytes.len() - 1) as f64 * bt;
        ensure!(
            last < t + 0.1,
            "epoch {i}: {} bytes overrun the period",
            bytes.len()
        );
    }

    // The schedule: by tick time `now`, exactly the bytes with t_e + k * bt <= now.
    let expected_by = |now: f64| -> usize {
        epochs
            .iter()
            .map(|(t, _, bytes)| {
                if now + 1e-9 < *t {
                    0
                } else {
                    (((now - t + 1e-9) / bt).floor() as usize + 1).min(bytes.len())
                }
            })
            .sum()
    };
    let mut released = 0;
    for (now, out) in &ticks {
        released += out.len();
        ensure!(
            released == expected_by(*now),
            "by {now:.3} s: {released} bytes released, schedule says {}",
            expected_by(*now)
        );
    }
    // 5 ms of 115200 baud is 57.6 byte times: a tick never releases more than 58 bytes.
    let max_tick = ticks.iter().map(|(_, o)| o.len()).max().unwrap_or(0);
    ensure!(max_tick <= 58, "a tick released {max_tick} bytes");
    // Over any window of ticks the line never runs faster than its baud.
    let mut cum = vec![0usize];
    for (_, o) in &ticks {
        cum.push(cum.last().copied().unwrap_or(0) + o.len());
    }
    for i in 0..ticks.len() {
        for j in i + 1..ticks.len() {
            let span = ticks[j].0 - ticks[i].0;
            let bytes = cum[j + 1] - cum[i + 1];
            ensure!(
                bytes as f64 <= span / bt + 1.0,
                "{bytes} bytes in ({:.3}, {:.3}] s",
                ticks[i].0,
                ticks[j].0
            );
        }
    }
    // Byte-exact, in order.
    let sent: Vec<u8> = ticks.iter().flat_map(|(_, o)| o.iter().copied()).collect();
    let all: Vec<u8> = epochs
        .iter()
        .flat_map(|(_, _, b)| b.iter().copied())
        .collect();
    // The last epoch (t = 1.0) has only begun by the last tick.
    ensure!(all.starts_with(&sent) && sent.len() == expected_by(1.0));
    ensure!(pacer.pending() == all.len() - sent.len());
    // Its next byte is due one byte time after the last released one.
    let t_last = epochs.last().map_or(0.0, |e| e.0);
    let next = pacer.next_release().unwrap_or(f64::NAN);
    let k = sent.len() - (all.len() - epochs.last().map_or(0, |e| e.2.len()));
    ensure!(
        (next - (t_last + k as f64 * bt)).abs() < 1e-12,
        "next byte at {next}"
    );
    ensure!(pacer.queued() as usize == all.len() && pacer.released() as usize == sent.len());
    Ok(())
}

#[test]
fn a_slow_line_delays_the_next_epoch_instead_of_overlapping() {
    // 4800 baud: 2 ms per byte; a 120-byte burst at 0 runs to 0.24 s.
    let mut p = Pacer::new(4800);
    let burst = vec![b'x'; 120];
    assert_eq!(p.enqueue(0.0, &burst), 0.0);
    let start = p.enqueue(0.2, b"$next");
    assert!((start - 0.25).abs() < 1e-12, "starts at {start}");
    let mut out = Vec::new();
    p.release(0.2499, &mut out);
    assert_eq!(out.len(), 120);
    p.release(0.25, &mut out);
    assert_eq!(out.last(), Some(&b'$'));
}
