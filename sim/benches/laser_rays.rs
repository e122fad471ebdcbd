//! Laser ray casting throughput, one core: `cargo bench -p ugv-sim --bench laser_rays`.
//!
//! For each scene: raw `World::cast_ray` calls per second (one ray against every
//! shape, no broad phase), and whole LMS111 scans (541 beams through the scan's broad
//! phase, noise draws included) per second, as rays per second.

use std::hint::black_box;
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
use ugv_sim::Scenario;
use ugv_sim::scenario::Obstacle;
use ugv_sim::world::World;

const RUN: Duration = Duration::from_secs(2);

/// 200 posts and boxes scattered over 100 m x 100 m around the vehicle at the origin.
fn crowded() -> Scenario {
    let mut rng = ChaCha8Rng::seed_from_u64(200);
    let mut s = Scenario::default();
    while s.obstacles.len() < 200 {
        let (x, y): (f64, f64) = (rng.random_range(-50.0..50.0), rng.random_range(-50.0..50.0));
        if x.hypot(y) < 6.0 {
            continue;
        }
        s.obstacles.push(if s.obstacles.len() % 2 == 0 {
            Obstacle::Circle {
                x,
                y,
                radius: rng.random_range(0.2..1.5),
                motion: None,
            }
        } else {
            Obstacle::Box {
                x,
                y,
                length: rng.random_range(0.5..4.0),
                width: rng.random_range(0.5..2.0),
                heading_deg: rng.random_range(0.0..180.0),
                motion: None,
            }
        });
    }
    s.start.x = 0.0;
    s.start.y = 0.0;
    s.success.reach_goal = false;
    s
}

fn bench(name: &str, s: &Scenario, x: f64, y: f64, theta: f64) {
    let world = World::new(&s.obstacles);
    let mut dev = match s.laser_device() {
        Ok(d) => d,
        Err(e) => {
            eprintln!("{name}: {e}");
            return;
        }
    };
    let beams = dev.spec().beams();
    let range_max = dev.spec().range_max;
    let pose = dev.scanner_pose(x, y, theta);
    let (sx, sy, heading) = (pose.x, pose.y, pose.heading_rad);

    // Raw ray casts, beams swept like a scan.
    let step = dev.spec().resolution_deg.to_radians();
    let start = Instant::now();
    let (mut rays, mut hits) = (0u64, 0u64);
    while start.elapsed() < RUN {
        for i in 0..beams {
            let a = heading + dev.spec().angle_min() + i as f64 * step;
            if black_box(world.cast_ray(sx, sy, a, range_max)).is_some() {
                hits += 1;
            }
        }
        rays += beams as u64;
    }
    let raw = rays as f64 / start.elapsed().as_secs_f64();

    // Whole scans through the device.
    let start = Instant::now();
    let mut scans = 0u64;
    let mut frame = firmware_bridge::laser::LaserFrame::default();
    while start.elapsed() < RUN {
        dev.scan_into(&world, 0.0, x, y, theta, &mut frame);
        black_box(&frame);
        scans += 1;
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{name:<28} {:>3} obstacles, {:>4.0} % beams hit: cast_ray {:>6.2} M rays/s; scan {:>6.2} M rays/s = {:>7.0} scans/s ({:.1} us/scan)",
        s.obstacles.len(),
        100.0 * hits as f64 / rays as f64,
        raw / 1e6,
        (scans * beams as u64) as f64 / secs / 1e6,
        scans as f64 / secs,
        secs / scans as f64 * 1e6,
    );
}

fn main() -> Result<(), ugv_sim::ScenarioError> {
    let paper = Scenario::paper()?;
    let start = &paper.start;
    bench(
        "paper (start pose)",
        &paper,
        start.x,
        start.y,
        start.heading(),
    );
    bench("paper (facing the post)", &paper, 8.0, 8.0, 0.0);
    // Two scenes of the suite at their start poses: 25 posts, and walls.
    for (name, file) in [
        ("25 posts (route-south)", "30-route-south.toml"),
        ("walls (corridor)", "11-corridor.toml"),
    ] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenarios/suite")
            .join(file);
        match Scenario::load(&path) {
            Ok(s) => bench(name, &s, s.start.x, s.start.y, s.start.heading()),
            Err(e) => eprintln!("{name}: {e}"),
        }
    }
    let crowded = crowded();
    bench("200 obstacles", &crowded, 0.0, 0.0, 0.0);
    Ok(())
}
