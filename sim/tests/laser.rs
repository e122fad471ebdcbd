//! The simulated laser against geometry worked out by hand: ray-circle and ray-polygon
//! intersections (posts, rotated boxes, walls) with noise off; the noise's statistics
//! for a fixed seed; determinism; dropouts; range limits; configuration.

use firmware_bridge::laser::LaserFrame;
use ugv_sim::Scenario;
use ugv_sim::devices::laser::{LaserConfig, LaserProfile};
use ugv_sim::scenario::{Motion, Obstacle};
use ugv_sim::world::World;

/// 2026-05-04T14:00:00Z, the default `sim.epoch`.
const EPOCH_NS: u64 = 1_777_903_200 * 1_000_000_000;
/// rapier works in f32: ranges of up to 20 m agree to better than this.
const TOL: f64 = 2e-4;

fn noiseless(mut cfg: LaserConfig) -> LaserConfig {
    cfg.range_noise_sigma = Some(0.0);
    cfg
}

/// The scenario's laser (a macro, so the `expect` sits in the test itself).
macro_rules! device {
    ($s:expr) => {
        $s.laser_device().expect("valid laser configuration")
    };
}

/// The scanner's world pose, computed here independently of the device.
fn scanner(cfg: &LaserConfig, x: f64, y: f64, theta: f64) -> (f64, f64, f64) {
    let (mx, my) = (cfg.mount_x, cfg.mount_y);
    (
        x + mx * theta.cos() - my * theta.sin(),
        y + mx * theta.sin() + my * theta.cos(),
        theta + cfg.mount_yaw_deg.to_radians(),
    )
}

/// Beam angles of a LMS111-like scan: -135 deg to +135 deg in 0.5 deg steps.
fn beam_angle(i: usize) -> f64 {
    (-135.0 + 0.5 * i as f64).to_radians()
}

/// First intersection of the ray `o + t d` (t > 0) with a circle, and how close the
/// ray came to grazing it (|disc|, to skip tangent rays whose hit/miss is a rounding call).
fn ray_circle(o: (f64, f64), d: (f64, f64), c: (f64, f64), r: f64) -> (Option<f64>, f64) {
    let (ox, oy) = (o.0 - c.0, o.1 - c.1);
    let b = ox * d.0 + oy * d.1;
    let disc = b * b - (ox * ox + oy * oy - r * r);
    if disc < 0.0 {
        return (None, disc.abs());
    }
    let t = -b - disc.sqrt();
    ((t > 0.0).then_some(t), disc.abs())
}

/// First intersection of a ray with the segment a-b, if any.
fn ray_segment(o: (f64, f64), d: (f64, f64), a: (f64, f64), b: (f64, f64)) -> Option<f64> {
    let e = (b.0 - a.0, b.1 - a.1);
    let den = d.0 * e.1 - d.1 * e.0;
    if den.abs() < 1e-12 {
        return None;
    }
    let w = (a.0 - o.0, a.1 - o.1);
    let t = (w.0 * e.1 - w.1 * e.0) / den;
    let u = (w.0 * d.1 - w.1 * d.0) / den;
    (t > 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
}

/// The corners of a rectangle centred at c, length along `heading`, width across.
fn rectangle(c: (f64, f64), length: f64, width: f64, heading: f64) -> Vec<(f64, f64)> {
    let (s, k) = heading.sin_cos();
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .map(|(a, b)| {
            let (lx, ly) = (a * length / 2.0, b * width / 2.0);
            (c.0 + lx * k - ly * s, c.1 + lx * s + ly * k)
        })
        .collect()
}

/// Distance from the ray's line to a point (to skip rays that graze a corner).
fn ray_point_distance(o: (f64, f64), d: (f64, f64), p: (f64, f64)) -> f64 {
    ((p.0 - o.0) * d.1 - (p.1 - o.1) * d.0).abs()
}

#[test]
fn ranges_match_ray_circle_intersections_with_noise_off() {
    // The paper's post: (19, 8), radius 3.
    let s = Scenario {
        laser: noiseless(LaserConfig {
            mount_x: 2.0,
            mount_y: 0.3,
            mount_yaw_deg: 10.0,
            ..LaserConfig::default()
        }),
        ..Scenario::paper().expect("the paper's scenario")
    };
    let world = World::new(&s.obstacles);
    let mut dev = device!(&s);
    let (x, y, theta) = (9.0, 6.0, 0.3);
    let f = dev.scan(&world, 0.0, x, y, theta);
    f.validate().expect("a valid frame");
    assert_eq!(f.count, 541);
    let (sx, sy, heading) = scanner(&s.laser, x, y, theta);
    let mut hits = 0;
    for i in 0..541 {
        let a = heading + beam_angle(i);
        let d = (a.cos(), a.sin());
        let (t, graze) = ray_circle((sx, sy), d, (19.0, 8.0), 3.0);
        if graze < 1e-2 {
            continue;
        }
        let r = f64::from(f.ranges[i]);
        match t {
            Some(t) if t <= 20.0 => {
                assert!((r - t).abs() < TOL, "beam {i}: {r} vs analytic {t}");
                assert_eq!(f.intensities[i], 200.0, "beam {i}: a post's intensity");
                hits += 1;
            }
            _ => {
                assert_eq!(r, f64::INFINITY, "beam {i} has no target");
                assert_eq!(f.intensities[i], 0.0);
            }
        }
    }
    // The post (radius 3 at ~8 m) subtends ~44 degrees: ~88 beams.
    assert!(hits > 70, "only {hits} beams hit the post");
}

#[test]
fn ranges_match_ray_segment_intersections_on_boxes_and_walls_with_noise_off() {
    let s = Scenario {
        obstacles: vec![
            Obstacle::Box {
                x: 15.0,
                y: 3.0,
                length: 2.0,
                width: 6.0,
                heading_deg: 30.0,
                motion: None,
            },
            Obstacle::Wall {
                points: vec![[-5.0, 9.0], [12.0, 13.0]],
                thickness: 0.4,
            },
            Obstacle::Box {
                x: -3.0,
                y: -6.0,
                length: 1.0,
                width: 1.5,
                heading_deg: 0.0,
                motion: None,
            },
        ],
        laser: noiseless(LaserConfig {
            mount_yaw_deg: -5.0,
            ..LaserConfig::default()
        }),
        ..Scenario::default()
    };
    let polygons: Vec<(Vec<(f64, f64)>, f32)> = vec![
        (rectangle((15.0, 3.0), 2.0, 6.0, 30f64.to_radians()), 150.0),
        (
            rectangle((3.5, 11.0), 17.0f64.hypot(4.0), 0.4, 4f64.atan2(17.0)),
            100.0,
        ),
        (rectangle((-3.0, -6.0), 1.0, 1.5, 0.0), 150.0),
    ];
    let world = World::new(&s.obstacles);
    let mut dev = device!(&s);
    let (x, y, theta) = (0.0, 0.0, 0.2);
    let f = dev.scan(&world, 0.0, x, y, theta);
    f.validate().expect("a valid frame");
    let (sx, sy, heading) = scanner(&s.laser, x, y, theta);
    let (mut hits, mut misses) = (0, 0);
    'beams: for i in 0..541 {
        let a = heading + beam_angle(i);
        let d = (a.cos(), a.sin());
        let mut nearest: Option<(f64, f32)> = None;
        for (corners, intensity) in &polygons {
            for k in 0..corners.len() {
                if ray_point_distance((sx, sy), d, corners[k]) < 1e-2 {
                    continue 'beams;
                }
                let edge = (corners[k], corners[(k + 1) % corners.len()]);
                if let Some(t) = ray_segment((sx, sy), d, edge.0, edge.1)
                    && nearest.is_none_or(|(best, _)| t < best)
                {
                    nearest = Some((t, *intensity));
                }
            }
        }
        let r = f64::from(f.ranges[i]);
        match nearest {
            Some((t, intensity)) if (0.5..=20.0).contains(&t) => {
                assert!((r - t).abs() < TOL, "beam {i}: {r} vs analytic {t}");
                assert_eq!(f.intensities[i], intensity, "beam {i}");
                hits += 1;
            }
            _ => {
                assert_eq!(r, f64::INFINITY, "beam {i} has no target");
                misses += 1;
            }
        }
    }
    assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses");
}

/// A closed room of walls around the scanner: every beam hits at 7-11 m.
fn room() -> Scenario {
    let mut s = Scenario {
        obstacles: vec![Obstacle::Wall {
            points: vec![
                [-8.0, -8.0],
                [8.0, -8.0],
                [8.0, 8.0],
                [-8.0, 8.0],
                [-8.0, -8.0],
            ],
            thickness: 0.2,
        }],
        ..Scenario::default()
    };
    s.start.heading_deg = 0.0;
    s.success.reach_goal = false;
    s
}

#[test]
fn range_noise_has_zero_mean_and_the_configured_sigma_for_a_fixed_seed() {
    let noisy = room();
    let mut clean = room();
    clean.laser = noiseless(clean.laser);
    let world = World::new(&noisy.obstacles);
    let (mut a, mut b) = (device!(&noisy), device!(&clean));
    let mut residuals = Vec::new();
    for k in 0..200 {
        let (x, y, theta) = (-2.0 + 0.01 * k as f64, 0.5, 0.1 * k as f64);
        let fa = a.scan(&world, 0.0, x, y, theta);
        let fb = b.scan(&world, 0.0, x, y, theta);
        for (ra, rb) in fa.ranges().iter().zip(fb.ranges()) {
            assert!(rb.is_finite(), "the room is closed");
            residuals.push(f64::from(*ra) - f64::from(*rb));
        }
    }
    let n = residuals.len() as f64; // 108 200
    let mean = residuals.iter().sum::<f64>() / n;
    let sd = (residuals.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let sigma = 0.012;
    // Five standard errors: sigma / sqrt(n) = 0.036 mm for the mean, sigma / sqrt(2n) =
    // 0.026 mm for the standard deviation of a normal sample. A false failure is a
    // 1-in-a-million event, and the seed is fixed anyway.
    assert!(mean.abs() < 5.0 * sigma / n.sqrt(), "mean {mean}");
    assert!(
        (sd - sigma).abs() < 5.0 * sigma / (2.0 * n).sqrt(),
        "sd {sd}"
    );
    // Gaussian shape: 68.27 % within one sigma (binomial standard error 0.14 %).
    let within = residuals.iter().filter(|r| r.abs() < sigma).count() as f64 / n;
    assert!(
        (within - 0.6827).abs() < 5.0 * (0.6827f64 * 0.3173 / n).sqrt(),
        "{within}"
    );
    // Neighbouring beams (each a stream of its own) uncorrelated: the lag-1
    // correlation's standard error is 1 / sqrt(n).
    let lag1 = residuals
        .windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / ((n - 1.0) * sd * sd);
    assert!(lag1.abs() < 5.0 / n.sqrt(), "lag-1 correlation {lag1}");
}

#[test]
fn a_beams_noise_is_the_same_whatever_the_other_beams_hit() {
    let mut s = room();
    s.laser.dropout_probability = 0.05;
    let mut cluttered = s.clone();
    // A post 3 m ahead hides some of the wall from the second device.
    cluttered.obstacles.push(Obstacle::Circle {
        x: 5.0,
        y: 0.5,
        radius: 0.3,
        motion: None,
    });
    let (bare, post) = (World::new(&s.obstacles), World::new(&cluttered.obstacles));
    let (mut a, mut b) = (device!(&s), device!(&cluttered));
    let (mut same, mut hidden) = (0, 0);
    for k in 0..3 {
        let fa = a.scan(&bare, 0.0, -1.0, 0.5, 0.1 * f64::from(k));
        let fb = b.scan(&post, 0.0, -1.0, 0.5, 0.1 * f64::from(k));
        for (ra, rb) in fa.ranges().iter().zip(fb.ranges()) {
            if ra.to_bits() == rb.to_bits() {
                same += 1;
            } else {
                // Only the beams the post stops change, and they come out shorter.
                assert!(rb < ra || rb.is_nan() || ra.is_nan(), "{ra} -> {rb}");
                hidden += 1;
            }
        }
    }
    assert!(hidden > 0, "the post hid nothing");
    assert!(same > 10 * hidden, "{same} beams alike, {hidden} changed");
}

fn bits_equal(a: &LaserFrame, b: &LaserFrame) -> bool {
    a.bit_eq(b)
}

#[test]
fn the_same_seed_gives_identical_frames_and_another_seed_does_not() {
    let mut s = room();
    s.laser.dropout_probability = 0.05;
    let world = World::new(&s.obstacles);
    let (mut a, mut b) = (device!(&s), device!(&s));
    let mut other = s.clone();
    other.sim.seed = 2;
    let mut c = device!(&other);
    for k in 0..3 {
        let t = 0.02 * k as f64;
        let fa = a.scan(&world, t, 1.0, -1.0, 0.4);
        let fb = b.scan(&world, t, 1.0, -1.0, 0.4);
        let fc = c.scan(&world, t, 1.0, -1.0, 0.4);
        assert!(bits_equal(&fa, &fb), "scan {k} differs for the same seed");
        assert!(
            !bits_equal(&fa, &fc),
            "scan {k} is the same for another seed"
        );
        assert_eq!(fa.sequence, k);
        assert_eq!(fa.stamp_ns, EPOCH_NS + k * 20_000_000);
    }
}

#[test]
fn dropouts_are_nan_at_the_configured_rate_and_only_on_targets() {
    let mut s = room();
    s.laser.dropout_probability = 0.2;
    let world = World::new(&s.obstacles);
    let mut dev = device!(&s);
    let (mut nan, mut total) = (0usize, 0usize);
    for k in 0..20 {
        let f = dev.scan(&world, 0.0, 0.0, 0.0, 0.05 * k as f64);
        f.validate().expect("NaN is a valid range");
        nan += f.ranges().iter().filter(|r| r.is_nan()).count();
        total += f.ranges().len();
        assert!(f.ranges().iter().all(|r| r.is_nan() || r.is_finite()));
    }
    let p = nan as f64 / total as f64;
    // Binomial standard error sqrt(0.2 * 0.8 / 10 820) = 0.38 %; five of them.
    assert!((p - 0.2).abs() < 0.02, "dropout rate {p}");

    // Open space: beams without a target stay "no return", never dropouts.
    let mut open = Scenario::default();
    open.laser.dropout_probability = 1.0;
    let world = World::new(&open.obstacles);
    let f = device!(&open).scan(&world, 0.0, 0.0, 0.0, std::f64::consts::PI);
    assert!(f.ranges().iter().all(|r| *r == f32::INFINITY));
}

#[test]
fn targets_closer_than_range_min_are_no_return() {
    // A thin post 0.3 m ahead of the scanner (mounted 2 m ahead of the rear axle).
    let mut s = Scenario {
        obstacles: vec![Obstacle::Circle {
            x: 2.4,
            y: 0.0,
            radius: 0.1,
            motion: None,
        }],
        ..Scenario::default()
    };
    s.success.reach_goal = false;
    s.laser = noiseless(s.laser);
    let world = World::new(&s.obstacles);
    let f = device!(&s).scan(&world, 0.0, 0.0, 0.0, 0.0);
    assert_eq!(
        f.ranges[270],
        f32::INFINITY,
        "0.3 m is below range_min 0.5 m"
    );
    // With range_min lowered the same post is measured.
    s.laser.range_min = Some(0.1);
    let f = device!(&s).scan(&world, 0.0, 0.0, 0.0, 0.0);
    assert!((f.ranges[270] - 0.3).abs() < 1e-4, "{}", f.ranges[270]);
}

#[test]
fn moving_obstacles_are_seen_where_they_are_at_scan_time() {
    let mut s = Scenario::default();
    s.obstacles = vec![Obstacle::Circle {
        x: 12.0,
        y: -10.0,
        radius: 0.5,
        motion: Some(Motion::Velocity { vx: 0.0, vy: 2.0 }),
    }];
    s.laser = noiseless(s.laser);
    let mut world = World::new(&s.obstacles);
    let mut dev = device!(&s);
    assert_eq!(
        dev.scan(&world, 0.0, 0.0, 0.0, 0.0).ranges[270],
        f32::INFINITY
    );
    world.set_time(5.0);
    let f = dev.scan(&world, 5.0, 0.0, 0.0, 0.0);
    // Straight ahead from (2, 0): the post is at (12, 0), its near side at 9.5 m.
    assert!((f.ranges[270] - 9.5).abs() < 1e-4, "{}", f.ranges[270]);
    assert_eq!(f.stamp_ns, EPOCH_NS + 5_000_000_000);
}

#[test]
fn frame_header_follows_the_lms111_defaults() {
    let s = Scenario::default();
    let world = World::new(&s.obstacles);
    let f = device!(&s).scan(&world, 0.0, 0.0, 0.0, 0.0);
    assert_eq!((f.version, f.count), (1, 541));
    assert!((f64::from(f.angle_min) + 135f64.to_radians()).abs() < 1e-6);
    assert!((f64::from(f.angle_max()) - 135f64.to_radians()).abs() < 1e-5);
    assert!((f64::from(f.angle_increment) - 0.5f64.to_radians()).abs() < 1e-7);
    assert_eq!((f.scan_time, f.range_min, f.range_max), (0.02, 0.5, 20.0));
    assert!((f64::from(f.time_increment) - 0.02 / 720.0).abs() < 1e-9);
    assert!(f.ranges[541..].iter().all(|r| *r == 0.0));
}

fn with_laser(section: &str) -> Result<Scenario, ugv_sim::ScenarioError> {
    let text = format!(
        "{}\n[laser]\n{section}\n",
        ugv_sim::scenario::PAPER_SCENARIO
    );
    Scenario::from_toml(&text, "test.toml")
}

#[test]
fn the_lms291_profile_and_overrides_load_from_toml() {
    let s = with_laser("profile = \"lms291\"\nrange_max = 30.0\nmount_yaw_deg = 1.5").unwrap();
    assert_eq!(s.laser.profile, LaserProfile::Lms291);
    let spec = s.laser.spec();
    assert_eq!(
        (spec.beams(), spec.fov_deg, spec.range_max),
        (361, 180.0, 30.0)
    );
    assert_eq!(
        s.laser.mount_x, 2.0,
        "unset mount fields keep their defaults"
    );
    let world = World::new(&s.obstacles);
    let f = device!(&s).scan(&world, 0.0, 0.0, 0.0, 0.0);
    assert_eq!(f.count, 361);
    assert!((f64::from(f.angle_min) + 90f64.to_radians()).abs() < 1e-6);
}

#[test]
fn bad_laser_fields_are_refused_with_their_name_and_line() {
    let err = |section: &str| match with_laser(section) {
        Ok(_) => panic!("accepted: {section}"),
        Err(e) => e.to_string(),
    };
    let e = err("dropout_probability = 1.5");
    assert!(e.contains("laser.dropout_probability"), "{e}");
    let e = err("resolution_deg = 0.1");
    assert!(
        e.contains("laser.resolution_deg") && e.contains("2701 beams"),
        "{e}"
    );
    let e = err("range_min = 25.0");
    assert!(
        e.contains("laser.range_min") && e.contains("lms111 profile"),
        "{e}"
    );
    let e = err("range_noise_sigma = -0.01");
    assert!(e.contains("laser.range_noise_sigma"), "{e}");
    let e = err("fov_deg = 400.0");
    assert!(e.contains("laser.fov_deg"), "{e}");
    let e = err("profile = \"lms511\"");
    assert!(e.contains("lms511"), "{e}");
    let e = err("beams = 541");
    assert!(e.contains("beams"), "unknown fields are refused: {e}");
    // The error names the line: the paper's file has 24 lines, then a blank one,
    // `[laser]` on 26, a blank one, and the bad field on 28.
    let e = err("\nrate_hz = 0.0");
    assert!(e.contains("test.toml:28: laser.rate_hz"), "{e}");
}
