//! The lockstep clock wire's handshake, per tick: the leader publishes a tick and
//! waits for its acknowledgement; the follower (another thread) waits for the tick and
//! acknowledges it at once. `cargo bench -p firmware-bridge --bench clock_wire`.
//!
//! The round trip is what lockstep adds to every controller tick beyond the work of
//! both sides (the CAN frames' and GPS bytes' own delivery come on top: microseconds on
//! vcan and a pty).

use std::time::{Duration, Instant};

use firmware_bridge::lockstep::{
    ClockAck, ClockFollower, ClockLeader, ClockTick, clock_service_name,
};

const TICKS: u64 = 20_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let service = clock_service_name(&format!("bench-{}", std::process::id()));
    let leader = ClockLeader::new(&service)?;
    let follower_service = service.clone();
    let follower = std::thread::spawn(move || -> Result<(), String> {
        let f = ClockFollower::new(&follower_service).map_err(|e| e.to_string())?;
        for k in 0..TICKS {
            let tick = f
                .wait_tick(k, Duration::from_secs(10))
                .map_err(|e| e.to_string())?
                .ok_or("no tick")?;
            f.ack(ClockAck {
                tick: tick.tick,
                ..ClockAck::default()
            })
            .map_err(|e| e.to_string())?;
        }
        Ok(())
    });
    let mut round_trips = Vec::with_capacity(TICKS as usize);
    let start = Instant::now();
    for k in 0..TICKS {
        let t0 = Instant::now();
        leader.publish(ClockTick {
            tick: k,
            ..ClockTick::default()
        })?;
        leader
            .wait_ack(k, Duration::from_secs(10))?
            .ok_or_else(|| format!("no acknowledgement of tick {k}"))?;
        round_trips.push(t0.elapsed().as_nanos() as u64);
    }
    let total = start.elapsed();
    follower.join().map_err(|_| "the follower panicked")??;
    round_trips.sort_unstable();
    let pct =
        |q: f64| round_trips[((round_trips.len() - 1) as f64 * q).round() as usize] as f64 / 1e3;
    println!(
        "clock wire, {TICKS} ticks: round trip p50 {:.1} us, p99 {:.1} us, max {:.1} us; {:.0} ticks/s ({:.0}x real time at 100 ticks per simulated second, handshake alone)",
        pct(0.5),
        pct(0.99),
        pct(1.0),
        TICKS as f64 / total.as_secs_f64(),
        TICKS as f64 / total.as_secs_f64() / 100.0
    );
    Ok(())
}
