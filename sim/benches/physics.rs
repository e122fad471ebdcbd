//! Physics steps per second: the world, the vehicle and both simulated ECUs (with
//! their CAN reports on the memory bus) stepped in lockstep, on the paper's scene and
//! on a scene of 200 posts. `cargo bench -p ugv-sim --bench physics`.

use std::time::Instant;

use firmware_bridge::CanPort;
use firmware_bridge::can::membus::MemBus;
use ugv_sim::Sim;
use ugv_sim::scenario::{Obstacle, Scenario};

fn steps_per_second(scenario: Scenario, steps: u64) -> anyhow::Result<f64> {
    let bus = MemBus::new();
    let mut sim = Sim::new(
        scenario,
        CanPort::new(bus.endpoint(), "mem"),
        CanPort::new(bus.endpoint(), "mem"),
    );
    let start = Instant::now();
    for k in 0..steps {
        let t = k as f64 * sim.dt();
        if sim.step(t, 0.0)?.is_some() {
            anyhow::bail!("the run ended at step {k}");
        }
    }
    Ok(steps as f64 / start.elapsed().as_secs_f64())
}

fn main() -> anyhow::Result<()> {
    let mut paper = Scenario::paper()?;
    paper.sim.time_limit_s = 1e9;
    paper.success.reach_goal = false;
    let mut crowded = paper.clone();
    crowded.obstacles = (0..200)
        .map(|i| Obstacle::Circle {
            x: 10.0 + f64::from(i % 20) * 5.0,
            y: -50.0 + f64::from(i / 20) * 10.0,
            radius: 0.5,
            motion: None,
        })
        .collect();
    for (name, sc) in [("paper", paper), ("200_posts", crowded)] {
        let rate = steps_per_second(sc, 20_000)?;
        println!(
            "physics scene={name} steps_per_second={rate:.0} realtime_factor_at_200Hz={:.1}",
            rate / 200.0
        );
    }
    Ok(())
}
