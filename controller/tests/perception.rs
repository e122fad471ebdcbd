//! Perception on synthetic scans: ranges are computed analytically (ray-circle and
//! ray-segment intersections) for an LMS111-like scanner (270 degrees, 0.5 degree steps,
//! 0.5-20 m), with seeded Gaussian range noise (sigma 12 mm) from an inline generator.
//!
//! Everything sits in `mod perception` so that `cargo test -p ugv-controller perception`
//! selects these tests too.

mod perception {
    use std::f64::consts::{FRAC_PI_2, PI};

    use proptest::prelude::*;
    use ugv_controller::perception::{
        ObstacleKind, Perception, PerceptionConfig, PerceptionError, PerceptionOutput, Pose2, Scan,
        TrackedObstacle, ValidScan, cover_segment, detect, scan_points,
    };

    const SIGMA: f64 = 0.012;
    const RATE: f64 = 50.0;

    // ---------------------------------------------------------------- noise

    /// SplitMix64 with Box-Muller normals.
    struct Rng(u64);

    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn uniform(&mut self) -> f64 {
            ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u1, u2) = (self.uniform(), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
        }
    }

    // ---------------------------------------------------------------- the world

    #[derive(Clone, Copy, Debug)]
    enum Shape {
        Circle { c: [f64; 2], r: f64 },
        Segment { a: [f64; 2], b: [f64; 2] },
    }

    fn cross(u: [f64; 2], v: [f64; 2]) -> f64 {
        u[0] * v[1] - u[1] * v[0]
    }

    /// Distance along the ray o + t d (d unit) to the shape, if hit ahead.
    fn intersect(shape: &Shape, o: [f64; 2], d: [f64; 2]) -> Option<f64> {
        match *shape {
            Shape::Circle { c, r } => {
                let f = [o[0] - c[0], o[1] - c[1]];
                let b = f[0] * d[0] + f[1] * d[1];
                let cc = f[0] * f[0] + f[1] * f[1] - r * r;
                let disc = b * b - cc;
                if disc < 0.0 {
                    return None;
                }
                let t = -b - disc.sqrt();
                (t > 0.0).then_some(t)
            }
            Shape::Segment { a, b } => {
                let e = [b[0] - a[0], b[1] - a[1]];
                let denom = cross(d, e);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let ao = [a[0] - o[0], a[1] - o[1]];
                let t = cross(ao, e) / denom;
                let s = cross(ao, d) / denom;
                (t > 0.0 && (0.0..=1.0).contains(&s)).then_some(t)
            }
        }
    }

    struct Scanner {
        angle_min: f64,
        angle_increment: f64,
        beams: usize,
        range_min: f64,
        range_max: f64,
    }

    const LMS111: Scanner = Scanner {
        angle_min: -135.0 * PI / 180.0,
        angle_increment: 0.5 * PI / 180.0,
        beams: 541,
        range_min: 0.5,
        range_max: 20.0,
    };

    impl Scanner {
        #[allow(clippy::expect_used)]
        fn scan<'a>(&self, stamp: f64, ranges: &'a [f32]) -> ValidScan<'a> {
            Scan {
                stamp,
                angle_min: self.angle_min,
                angle_increment: self.angle_increment,
                range_min: self.range_min,
                range_max: self.range_max,
                ranges,
            }
            .validate()
            .expect("a valid scan")
        }

        /// Ranges seen from the laser mounted at `mount` on the vehicle at `pose`.
        fn ranges(
            &self,
            world: &[Shape],
            pose: &Pose2,
            mount: &Pose2,
            rng: &mut Rng,
            sigma: f64,
        ) -> Vec<f32> {
            let laser = pose.compose(mount);
            (0..self.beams)
                .map(|i| {
                    let a = laser.yaw + self.angle_min + i as f64 * self.angle_increment;
                    let d = [a.cos(), a.sin()];
                    let hit = world
                        .iter()
                        .filter_map(|s| intersect(s, [laser.x, laser.y], d))
                        .min_by(f64::total_cmp);
                    let noise = rng.normal() * sigma;
                    match hit {
                        Some(t) if t >= self.range_min && t <= self.range_max => (t + noise) as f32,
                        _ => f32::INFINITY,
                    }
                })
                .collect()
        }
    }

    impl Scanner {
        /// One scan of `world` from the laser at `mount` on the vehicle at `pose`,
        /// stamped `t`, given to `p`: what it tracks then.
        #[allow(clippy::expect_used)]
        fn track(
            &self,
            p: &mut Perception,
            world: &[Shape],
            pose: &Pose2,
            mount: &Pose2,
            t: f64,
            rng: &mut Rng,
        ) -> PerceptionOutput {
            let ranges = self.ranges(world, pose, mount, rng, SIGMA);
            p.update(&self.scan(t, &ranges), mount, pose)
                .expect("valid")
        }
    }

    fn default_mount() -> Pose2 {
        Pose2::new(2.0, 0.0, 0.0)
    }

    fn posts(obstacles: &[TrackedObstacle], kind: ObstacleKind) -> Vec<TrackedObstacle> {
        obstacles
            .iter()
            .copied()
            .filter(|o| o.kind == kind)
            .collect()
    }

    fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    // ---------------------------------------------------------------- frames

    #[test]
    fn transform_with_mount_and_heading_matches_hand_computation() {
        // Mount yaw 90 degrees and heading 90 degrees: exact by hand.
        // Beam 0 (angle 0, 2 m): laser (2, 0) -> vehicle R90 (2, 0) + (1.5, 0.3) = (1.5, 2.3)
        //   -> world R90 (1.5, 2.3) + (5, -2) = (-2.3 + 5, 1.5 - 2) = (2.7, -0.5).
        // Beam 1 (angle 90 degrees, 1 m): laser (0, 1) -> vehicle (-1, 0) + (1.5, 0.3) =
        //   (0.5, 0.3) -> world (-0.3 + 5, 0.5 - 2) = (4.7, -1.5).
        let ranges = [2.0f32, 1.0, f32::INFINITY, f32::NAN];
        let scan = Scan {
            stamp: 0.0,
            angle_min: 0.0,
            angle_increment: FRAC_PI_2,
            range_min: 0.1,
            range_max: 20.0,
            ranges: &ranges,
        }
        .validate()
        .expect("valid scan");
        let mount = Pose2::new(1.5, 0.3, FRAC_PI_2);
        let pose = Pose2::new(5.0, -2.0, FRAC_PI_2);
        let pts = scan_points(&scan, &mount, &pose).expect("finite mount and pose");
        assert_eq!(pts.len(), 2, "the inf and NaN beams give no point");
        let close = |a: [f64; 2], b: [f64; 2]| dist(a, b) < 1e-12;
        assert!(close(pts[0].laser, [2.0, 0.0]));
        assert!(close(pts[0].vehicle, [1.5, 2.3]), "{:?}", pts[0].vehicle);
        assert!(close(pts[0].world, [2.7, -0.5]), "{:?}", pts[0].world);
        assert!(close(pts[1].vehicle, [0.5, 0.3]), "{:?}", pts[1].vehicle);
        assert!(close(pts[1].world, [4.7, -1.5]), "{:?}", pts[1].world);

        // Mount (1, 0, 30 deg), heading 60 deg, beam 0 at 2 m:
        // vehicle = (1 + 2 cos 30, 2 sin 30) = (2.7320508, 1.0);
        // world = (2.7320508 * 0.5 - 1.0 * 0.8660254, 2.7320508 * 0.8660254 + 1.0 * 0.5)
        //       = (0.5, 2.8660254).
        let ranges = [2.0f32];
        let scan = Scan {
            ranges: &ranges,
            ..*scan
        }
        .validate()
        .expect("valid scan");
        let pts = scan_points(
            &scan,
            &Pose2::new(1.0, 0.0, 30f64.to_radians()),
            &Pose2::new(0.0, 0.0, 60f64.to_radians()),
        )
        .expect("valid scan");
        assert!(
            dist(pts[0].vehicle, [2.732_050_8, 1.0]) < 1e-7,
            "{:?}",
            pts[0].vehicle
        );
        assert!(
            dist(pts[0].world, [0.5, 2.866_025_4]) < 1e-7,
            "{:?}",
            pts[0].world
        );
    }

    proptest! {
        /// Every world point lies at its range from the laser's world position, in the
        /// direction laser yaw + beam angle, whatever the mount and the pose.
        #[test]
        fn world_points_are_range_and_bearing_from_the_laser(
            mx in -3.0f64..3.0, my in -2.0f64..2.0, myaw in -PI..PI,
            x in -100.0f64..100.0, y in -100.0f64..100.0, theta in -PI..PI,
            r in 0.5f32..20.0, beam in 0usize..541,
        ) {
            let mut ranges = vec![f32::INFINITY; 541];
            ranges[beam] = r;
            let scan = LMS111.scan(0.0, &ranges);
            let mount = Pose2::new(mx, my, myaw);
            let pose = Pose2::new(x, y, theta);
            let pts = scan_points(&scan, &mount, &pose).expect("valid scan");
            prop_assert_eq!(pts.len(), 1);
            let laser = [x + mx * theta.cos() - my * theta.sin(), y + mx * theta.sin() + my * theta.cos()];
            let bearing = theta + myaw + LMS111.angle_min + beam as f64 * LMS111.angle_increment;
            let expected = [laser[0] + f64::from(r) * bearing.cos(), laser[1] + f64::from(r) * bearing.sin()];
            prop_assert!(dist(pts[0].world, expected) < 1e-9);
        }
    }

    // ---------------------------------------------------------------- posts

    /// The seed paper's obstacle: a post of radius 3 m at (19, 8).
    const PAPER_POST: Shape = Shape::Circle {
        c: [19.0, 8.0],
        r: 3.0,
    };

    #[test]
    fn paper_post_seen_from_several_poses() {
        let cfg = PerceptionConfig::default();
        let views = [
            (Pose2::new(10.0, 8.0, 0.0), default_mount()),
            (Pose2::new(14.0, 2.0, 45f64.to_radians()), default_mount()),
            (Pose2::new(26.0, 12.0, 200f64.to_radians()), default_mount()),
            (Pose2::new(19.0, -2.0, FRAC_PI_2), default_mount()),
            (
                Pose2::new(12.0, 14.0, -60f64.to_radians()),
                Pose2::new(1.5, 0.4, 30f64.to_radians()),
            ),
        ];
        let (mut worst_c, mut worst_r) = (0.0f64, 0.0f64);
        for (v, (pose, mount)) in views.iter().enumerate() {
            // Single scans.
            for seed in 0..10 {
                let mut rng = Rng(1000 * v as u64 + seed);
                let ranges = LMS111.ranges(&[PAPER_POST], pose, mount, &mut rng, SIGMA);
                let det = detect(&LMS111.scan(0.0, &ranges), mount, pose, &cfg).expect("valid");
                assert!(det.segments.is_empty(), "view {v}: {:?}", det.segments);
                assert_eq!(det.circles.len(), 1, "view {v}: {:?}", det.circles);
                let c = det.circles[0];
                assert_eq!(c.kind, ObstacleKind::Post);
                worst_c = worst_c.max(dist(c.centre, [19.0, 8.0]));
                worst_r = worst_r.max((c.radius - 3.0).abs());
            }
            // Tracked: confirmed, within the detection radius, static.
            let mut p = Perception::new(cfg.clone()).expect("config");
            let mut rng = Rng(77 + v as u64);
            let mut out = None;
            for k in 0..10 {
                let ranges = LMS111.ranges(&[PAPER_POST], pose, mount, &mut rng, SIGMA);
                out = Some(
                    p.update(&LMS111.scan(k as f64 / RATE, &ranges), mount, pose)
                        .expect("valid"),
                );
            }
            let out = out.expect("ten scans");
            assert_eq!(out.obstacles.len(), 1, "view {v}: {:?}", out.obstacles);
            let o = out.obstacles[0];
            assert_eq!(o.kind, ObstacleKind::Post);
            assert!(
                dist([o.disc.x, o.disc.y], [19.0, 8.0]) < 0.15,
                "view {v}: {o:?}"
            );
            assert!((o.disc.radius - 3.0).abs() < 0.15, "view {v}: {o:?}");
            assert_eq!((o.disc.vx, o.disc.vy), (0.0, 0.0));
            assert_eq!(
                out.planner_obstacles(),
                vec![o.disc],
                "the planner takes the disc"
            );
        }
        eprintln!(
            "paper post, 5 views x 10 scans: worst centre error {worst_c:.4} m, worst radius error {worst_r:.4} m"
        );
        assert!(worst_c < 0.15 && worst_r < 0.15);
    }

    /// Ranges of the paper post seen from a laser at `d` from its centre with only an arc
    /// of `arc` radians (centred on the side facing the laser) returning; other beams
    /// see nothing.
    fn partial_arc_ranges(d: f64, arc: f64, bearing: f64, rng: &mut Rng) -> (Pose2, Vec<f32>) {
        let [cx, cy] = [19.0, 8.0];
        // Laser on the ray from the centre at `bearing`, looking at the centre.
        let laser = [cx + d * bearing.cos(), cy + d * bearing.sin()];
        let yaw = bearing + PI;
        let mount = default_mount();
        // Vehicle pose such that the laser (mounted 2 m ahead) sits at `laser`.
        let pose = Pose2::new(laser[0] - 2.0 * yaw.cos(), laser[1] - 2.0 * yaw.sin(), yaw);
        let ranges = LMS111
            .ranges(&[PAPER_POST], &pose, &mount, rng, SIGMA)
            .into_iter()
            .enumerate()
            .map(|(i, r)| {
                if !r.is_finite() {
                    return r;
                }
                // Noise-free hit point's polar angle around the centre vs the facing side.
                let a = yaw + LMS111.angle_min + i as f64 * LMS111.angle_increment;
                let t = intersect(&PAPER_POST, laser, [a.cos(), a.sin()]).unwrap_or(f64::INFINITY);
                let p = [laser[0] + t * a.cos(), laser[1] + t * a.sin()];
                let phi = (p[1] - cy).atan2(p[0] - cx);
                let off = (phi - bearing + PI).rem_euclid(2.0 * PI) - PI;
                if off.abs() <= arc / 2.0 {
                    r
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        (pose, ranges)
    }

    #[test]
    fn paper_post_partial_arcs_at_6_to_8_m() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        for arc_deg in [60.0f64, 90.0] {
            for surface_range in [6.0, 7.0, 8.0] {
                let (mut worst_c, mut worst_r, mut sum_r2, mut n) = (0.0f64, 0.0f64, 0.0, 0);
                for seed in 0..40u64 {
                    let mut rng = Rng(seed * 7919 + arc_deg as u64);
                    let bearing = (seed as f64) * 0.7;
                    let (pose, ranges) = partial_arc_ranges(
                        3.0 + surface_range,
                        arc_deg.to_radians(),
                        bearing,
                        &mut rng,
                    );
                    let det =
                        detect(&LMS111.scan(0.0, &ranges), &mount, &pose, &cfg).expect("valid");
                    assert_eq!(
                        det.circles.len(),
                        1,
                        "{arc_deg} deg at {surface_range} m seed {seed}: {det:?}"
                    );
                    let c = det.circles[0];
                    assert_eq!(
                        c.kind,
                        ObstacleKind::Post,
                        "{arc_deg} deg at {surface_range} m seed {seed}"
                    );
                    worst_c = worst_c.max(dist(c.centre, [19.0, 8.0]));
                    worst_r = worst_r.max((c.radius - 3.0).abs());
                    sum_r2 += (c.radius - 3.0).powi(2);
                    n += 1;
                }
                eprintln!(
                    "arc {arc_deg} deg at {surface_range} m, 40 seeds: worst centre error {worst_c:.4} m, worst radius error {worst_r:.4} m, radius RMS {:.4} m",
                    (sum_r2 / n as f64).sqrt()
                );
                assert!(
                    worst_c < 0.15,
                    "{arc_deg} deg at {surface_range} m: centre {worst_c}"
                );
                assert!(
                    worst_r < 0.15,
                    "{arc_deg} deg at {surface_range} m: radius {worst_r}"
                );
            }
        }
    }

    #[test]
    fn two_nearby_posts_are_separated() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let back_wall = Shape::Segment {
            a: [14.0, -5.0],
            b: [14.0, 5.0],
        };
        let cases = [
            // Side by side, 0.4 m between the surfaces, a wall seen through the gap.
            [[8.0, 0.7], [8.0, -0.7]],
            // Staggered: the far post partly hidden behind the near one.
            [[6.0, 0.3], [7.5, -0.6]],
        ];
        for (k, centres) in cases.iter().enumerate() {
            let world = [
                Shape::Circle {
                    c: centres[0],
                    r: 0.5,
                },
                Shape::Circle {
                    c: centres[1],
                    r: 0.5,
                },
                back_wall,
            ];
            for seed in 0..10 {
                let mut rng = Rng(500 + seed);
                let ranges = LMS111.ranges(&world, &pose, &mount, &mut rng, SIGMA);
                let det = detect(&LMS111.scan(0.0, &ranges), &mount, &pose, &cfg).expect("valid");
                let found: Vec<_> = det
                    .circles
                    .iter()
                    .filter(|c| c.kind == ObstacleKind::Post)
                    .collect();
                assert_eq!(found.len(), 2, "case {k} seed {seed}: {:?}", det.circles);
                for c in centres {
                    let best = found
                        .iter()
                        .min_by(|a, b| dist(a.centre, *c).total_cmp(&dist(b.centre, *c)))
                        .expect("two posts");
                    assert!(
                        dist(best.centre, *c) < 0.15,
                        "case {k} seed {seed}: {best:?} vs {c:?}"
                    );
                    assert!(
                        (best.radius - 0.5).abs() < 0.15,
                        "case {k} seed {seed}: {best:?}"
                    );
                }
                assert!(!det.segments.is_empty(), "the back wall is a segment");
            }
        }
    }

    // ---------------------------------------------------------------- walls

    #[test]
    fn oblique_wall_segment_and_its_circle_chain() {
        let (a, b) = ([13.0, -3.0], [15.0, 5.0]);
        let world = [Shape::Segment { a, b }];
        let mount = default_mount();
        let pose = Pose2::new(9.0, 0.0, 0.0);
        let true_angle = (b[1] - a[1]).atan2(b[0] - a[0]);
        for r0 in [2.0, 0.0] {
            let cfg = PerceptionConfig {
                vehicle_radius: r0,
                ..PerceptionConfig::default()
            };
            let mut p = Perception::new(cfg.clone()).expect("config");
            let mut rng = Rng(42);
            let mut out = PerceptionOutput {
                stamp: 0.0,
                obstacles: Vec::new(),
                segments: Vec::new(),
            };
            let mut det = None;
            for k in 0..5 {
                let ranges = LMS111.ranges(&world, &pose, &mount, &mut rng, SIGMA);
                let scan = LMS111.scan(k as f64 / RATE, &ranges);
                let d = detect(&scan, &mount, &pose, &cfg).expect("valid");
                out = p.update_detections(&d, &pose).expect("valid");
                det = Some(d);
            }
            let det = det.expect("five scans");
            assert!(det.circles.is_empty(), "{:?}", det.circles);
            assert_eq!(out.segments.len(), 1, "{:?}", out.segments);
            let s = out.segments[0];
            let (e0, e1) = (
                dist(s.p0, a).min(dist(s.p0, b)),
                dist(s.p1, a).min(dist(s.p1, b)),
            );
            let angle = (s.p1[1] - s.p0[1]).atan2(s.p1[0] - s.p0[0]);
            let angle_err = ((angle - true_angle + PI / 2.0).rem_euclid(PI) - PI / 2.0).abs();
            eprintln!(
                "oblique wall: endpoint errors {e0:.4} m, {e1:.4} m, direction error {:.3} deg, half thickness {:.4} m",
                angle_err.to_degrees(),
                s.half_thickness
            );
            assert!(e0 < 0.2 && e1 < 0.2, "{s:?}");
            assert!(angle_err < 1f64.to_radians(), "{s:?}");

            let chain: Vec<_> = posts(&out.obstacles, ObstacleKind::WallPiece);
            assert!(chain.len() >= 2);
            assert!(
                chain
                    .iter()
                    .all(|c| c.id == s.id && c.disc.vx == 0.0 && c.disc.vy == 0.0)
            );
            assert_eq!(out.obstacles.len(), chain.len());
            let (radius, centres) = cover_segment(s.p0, s.p1, s.half_thickness, &cfg);
            assert_eq!(centres.len(), chain.len());
            // Every point within h + r0 of the segment is inside some circle grown by r0.
            let h = s.half_thickness;
            let len = dist(s.p0, s.p1);
            let d = [(s.p1[0] - s.p0[0]) / len, (s.p1[1] - s.p0[1]) / len];
            let n = [-d[1], d[0]];
            for i in 0..=400 {
                let t = len * i as f64 / 400.0;
                for j in -10..=10 {
                    let off = (h + r0) * j as f64 / 10.0;
                    let q = [
                        s.p0[0] + t * d[0] + off * n[0],
                        s.p0[1] + t * d[1] + off * n[1],
                    ];
                    let covered = chain
                        .iter()
                        .any(|c| dist([c.disc.x, c.disc.y], q) <= c.disc.radius + r0 + 1e-9);
                    assert!(covered, "r0 {r0}: {q:?} not covered");
                }
            }
            // Without r0 the circles themselves cover every hit of the wall.
            for pt in det.points.iter().filter(|_| r0 == 0.0) {
                assert!(
                    chain
                        .iter()
                        .any(|c| dist([c.disc.x, c.disc.y], pt.world) <= radius + 1e-9),
                    "{pt:?}"
                );
            }
        }
    }

    // ---------------------------------------------------------------- tracking

    #[test]
    fn crossing_post_velocity_converges_within_a_second() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let mut p = Perception::new(cfg).expect("config");
        let mut rng = Rng(2024);
        let (v_post, heading, speed) = ([0.0, 1.5], 0.2f64, 2.0);
        let (mut worst_after_1s, mut err_at_half_s) = (0.0f64, f64::NAN);
        let mut ids = Vec::new();
        for k in 0..=100 {
            let t = k as f64 / RATE;
            let centre = [7.0 + v_post[0] * t, -4.0 + v_post[1] * t];
            let pose = Pose2::new(
                speed * t * heading.cos(),
                speed * t * heading.sin(),
                heading,
            );
            let ranges = LMS111.ranges(
                &[Shape::Circle { c: centre, r: 0.4 }],
                &pose,
                &mount,
                &mut rng,
                SIGMA,
            );
            let out = p
                .update(&LMS111.scan(t, &ranges), &mount, &pose)
                .expect("valid");
            if k < 5 {
                continue;
            }
            assert_eq!(
                out.obstacles.len(),
                1,
                "k {k}: {:?}\n{:?}",
                out.obstacles,
                p.all_tracks()
            );
            let o = out.obstacles[0];
            ids.push(o.id);
            let err = (o.disc.vx - v_post[0]).hypot(o.disc.vy - v_post[1]);
            if k == 25 {
                err_at_half_s = err;
            }
            if k >= 50 {
                worst_after_1s = worst_after_1s.max(err);
                assert!(
                    err < 0.2,
                    "k {k}: velocity ({}, {}) error {err}",
                    o.disc.vx,
                    o.disc.vy
                );
                assert!(
                    dist([o.disc.x, o.disc.y], centre) < 0.1,
                    "k {k}: {o:?} vs {centre:?}"
                );
                assert!((o.disc.radius - 0.4).abs() < 0.1, "k {k}: {o:?}");
            }
        }
        ids.dedup();
        assert_eq!(ids.len(), 1, "one track all along");
        eprintln!(
            "crossing post 1.5 m/s: velocity error {err_at_half_s:.4} m/s at 0.5 s, worst {worst_after_1s:.4} m/s over 1-2 s"
        );
    }

    #[test]
    fn a_slow_walker_crossing_is_reported_moving_and_stays_moving() {
        // A walker (0.5 m radius) crossing at 0.5 m/s, 8 m ahead of a car driving at
        // 2 m/s: its estimate's own covariance puts 0.5 m/s right at the significance
        // threshold. It must be reported moving within 1.5 s and stay so, not flicker
        // back to a post (the planner then takes it for a post and the car drives into
        // its way).
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mount = default_mount();
        let mut rng = Rng(7);
        let v_walker = [0.0, 0.5];
        let mut first_moving = None;
        let mut static_after = 0;
        for k in 0..=(4.0 * RATE) as usize {
            let t = k as f64 / RATE;
            let centre = [12.0 + v_walker[0] * t, -3.0 + v_walker[1] * t];
            let pose = Pose2::new(2.0 * t, 0.0, 0.0);
            let world = [Shape::Circle { c: centre, r: 0.5 }];
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            let Some(o) = out
                .obstacles
                .iter()
                .find(|o| dist([o.disc.x, o.disc.y], centre) < 0.5)
            else {
                continue;
            };
            let moving = o.disc.vx != 0.0 || o.disc.vy != 0.0;
            match first_moving {
                None if moving => first_moving = Some(t),
                Some(_) if !moving => static_after += 1,
                _ => {}
            }
        }
        let first = first_moving.expect("reported moving");
        eprintln!("walker at 0.5 m/s: moving from {first:.2} s, static {static_after} scans after");
        assert!(first <= 1.5, "moving from {first} s");
        assert_eq!(static_after, 0, "reported static again after moving");
    }

    /// The four sides of a box centred at `c`, `length` along x and `width` along y.
    fn box_sides(c: [f64; 2], length: f64, width: f64) -> [Shape; 4] {
        let (hl, hw) = (0.5 * length, 0.5 * width);
        let corner = |sx: f64, sy: f64| [c[0] + sx * hl, c[1] + sy * hw];
        [
            (corner(-1.0, -1.0), corner(1.0, -1.0)),
            (corner(1.0, -1.0), corner(1.0, 1.0)),
            (corner(1.0, 1.0), corner(-1.0, 1.0)),
            (corner(-1.0, 1.0), corner(-1.0, -1.0)),
        ]
        .map(|(a, b)| Shape::Segment { a, b })
    }

    #[test]
    fn an_oncoming_cart_seen_as_wall_segments_is_reported_moving() {
        // A cart (2.4 x 1.2 m box) coming at 1.5 m/s, head on and on a line offset
        // 1.6 m, while the vehicle drives towards it at 2 m/s: its faces are wall
        // segments, and their normal motion gives its velocity.
        let mount = default_mount();
        for (offset, label) in [(0.0, "head on"), (1.6, "offset")] {
            let mut p = Perception::new(PerceptionConfig {
                detection_radius: 16.0,
                ..PerceptionConfig::default()
            })
            .expect("config");
            let mut rng = Rng(77);
            let mut worst = 0.0f64;
            for k in 0..=100 {
                let t = k as f64 / RATE;
                let pose = Pose2::new(2.0 * t, 0.0, 0.0);
                let cart = box_sides([14.0 - 1.5 * t, offset], 2.4, 1.2);
                let out = LMS111.track(&mut p, &cart, &pose, &mount, t, &mut rng);
                let pieces = posts(&out.obstacles, ObstacleKind::WallPiece);
                if k >= 60 {
                    assert!(!pieces.is_empty(), "{label} k {k}: {:?}", out.obstacles);
                    for o in &pieces {
                        // Head on only the front face is seen: its normal speed is
                        // the whole velocity. Offset, the side adds nothing across.
                        let err = (o.disc.vx + 1.5).hypot(o.disc.vy);
                        worst = worst.max(err);
                        assert!(err < 0.3, "{label} k {k}: ({}, {})", o.disc.vx, o.disc.vy);
                    }
                }
            }
            eprintln!("oncoming cart, {label}: worst velocity error over 1.2-2 s {worst:.3} m/s");
        }
    }

    #[test]
    fn static_obstacles_report_zero_velocity_while_the_vehicle_drives() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let world = [
            Shape::Circle {
                c: [9.0, 2.5],
                r: 0.3,
            },
            Shape::Circle {
                c: [11.0, -2.5],
                r: 0.5,
            },
            Shape::Segment {
                a: [6.0, 5.0],
                b: [14.0, 5.5],
            },
        ]
        .into_iter()
        .chain(box_sides([13.0, -5.0], 2.4, 1.2))
        .collect::<Vec<_>>();
        let mut p = Perception::new(cfg).expect("config");
        let mut rng = Rng(9);
        let (mut reported_nonzero, mut reports, mut worst_raw, mut walls) = (0, 0, 0.0f64, 0);
        for k in 0..=150 {
            let t = k as f64 / RATE;
            // Driving at 3 m/s along a gentle arc.
            let theta = 0.1 * t;
            let pose = Pose2::new(3.0 * t, 0.15 * t * t, theta);
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            if k < 10 {
                continue;
            }
            for o in posts(&out.obstacles, ObstacleKind::Post) {
                reports += 1;
                if o.disc.vx != 0.0 || o.disc.vy != 0.0 {
                    reported_nonzero += 1;
                }
                if k >= 25 {
                    worst_raw = worst_raw.max(o.velocity_estimate[0].hypot(o.velocity_estimate[1]));
                }
            }
            for o in posts(&out.obstacles, ObstacleKind::WallPiece) {
                walls += 1;
                assert_eq!((o.disc.vx, o.disc.vy), (0.0, 0.0), "k {k}: {o:?}");
            }
        }
        eprintln!(
            "static posts from a moving vehicle: {reported_nonzero} of {reports} reports non-zero, worst filter speed after 0.5 s {worst_raw:.4} m/s"
        );
        assert!(reports > 200);
        assert!(walls > 200, "the wall and the box's faces are wall pieces");
        assert_eq!(reported_nonzero, 0);
        assert!(worst_raw < 0.15);
    }

    #[test]
    fn obstacles_beyond_the_detection_radius_are_not_reported() {
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        // Nearest points from the rear axle: 7.76 m and 11.59 m.
        let world = [
            Shape::Circle {
                c: [8.2, 1.0],
                r: 0.5,
            },
            Shape::Circle {
                c: [12.0, -1.5],
                r: 0.5,
            },
        ];
        let near = |o: &TrackedObstacle| o.disc.x.hypot(o.disc.y) - o.disc.radius;
        for (radius, expected) in [(8.0, 1), (12.5, 2), (5.0, 0)] {
            let cfg = PerceptionConfig {
                detection_radius: radius,
                ..PerceptionConfig::default()
            };
            let mut p = Perception::new(cfg).expect("config");
            let mut rng = Rng(3);
            let mut out = None;
            for k in 0..6 {
                let ranges = LMS111.ranges(&world, &pose, &mount, &mut rng, SIGMA);
                out = Some(
                    p.update(&LMS111.scan(k as f64 / RATE, &ranges), &mount, &pose)
                        .expect("valid"),
                );
            }
            let out = out.expect("six scans");
            assert_eq!(
                out.obstacles.len(),
                expected,
                "radius {radius}: {:?}",
                out.obstacles
            );
            assert!(out.obstacles.iter().all(|o| near(o) <= radius));
            assert_eq!(p.all_tracks().len(), 2, "both tracked whatever the radius");
        }
        assert_eq!(PerceptionConfig::default().detection_radius, 8.0);
    }

    // ---------------------------------------------------------------- degenerate scans

    #[test]
    fn nan_and_infinite_beams_are_ignored() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(10.0, 8.0, 0.0);
        let mut rng = Rng(11);
        let mut ranges = LMS111.ranges(&[PAPER_POST], &pose, &mount, &mut rng, SIGMA);
        let hits_before = ranges.iter().filter(|r| r.is_finite()).count();
        // Isolated dropouts on the post (every third hit, never two in a row).
        let mut n = 0;
        for r in ranges.iter_mut().filter(|r| r.is_finite()) {
            n += 1;
            if n % 3 == 0 {
                *r = f32::NAN;
            }
        }
        let scan = LMS111.scan(0.0, &ranges);
        let det = detect(&scan, &mount, &pose, &cfg).expect("valid");
        assert_eq!(det.points.len(), hits_before - hits_before / 3);
        assert_eq!(det.circles.len(), 1, "{:?}", det.circles);
        assert!(dist(det.circles[0].centre, [19.0, 8.0]) < 0.15);
        assert!((det.circles[0].radius - 3.0).abs() < 0.15);

        // Nothing but NaN and inf: no points, no obstacles, no error.
        let ranges: Vec<f32> = (0..541)
            .map(|i| if i % 2 == 0 { f32::NAN } else { f32::INFINITY })
            .collect();
        let mut p = Perception::new(cfg.clone()).expect("config");
        for k in 0..5 {
            let out = p
                .update(&LMS111.scan(k as f64, &ranges), &mount, &pose)
                .expect("valid");
            assert!(out.obstacles.is_empty() && out.segments.is_empty());
        }
        let det = detect(&LMS111.scan(0.0, &ranges), &mount, &pose, &cfg).expect("valid");
        assert!(det.points.is_empty() && det.clusters.is_empty());
    }

    #[test]
    fn empty_scan_gives_no_obstacles() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let det = detect(&LMS111.scan(0.0, &[]), &mount, &pose, &cfg).expect("valid");
        assert!(det.points.is_empty() && det.circles.is_empty() && det.segments.is_empty());
        let mut p = Perception::new(cfg).expect("config");
        for k in 0..3 {
            let out = p
                .update(&LMS111.scan(k as f64, &[]), &mount, &pose)
                .expect("valid");
            assert!(out.obstacles.is_empty() && out.segments.is_empty());
        }
    }

    #[test]
    fn tracks_coast_then_die_when_the_obstacle_disappears() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut p = Perception::new(cfg.clone()).expect("config");
        let mut rng = Rng(5);
        let world = [Shape::Circle {
            c: [6.0, 0.0],
            r: 0.4,
        }];
        let mut k = 0;
        for _ in 0..10 {
            let out = LMS111.track(&mut p, &world, &pose, &mount, k as f64 / RATE, &mut rng);
            k += 1;
            if k < cfg.birth_hits as usize {
                assert!(
                    out.obstacles.is_empty(),
                    "not confirmed before {} hits",
                    cfg.birth_hits
                );
            }
        }
        let empty = vec![f32::INFINITY; 541];
        for miss in 1..=cfg.delete_misses {
            let out = p
                .update(&LMS111.scan(k as f64 / RATE, &empty), &mount, &pose)
                .expect("valid");
            k += 1;
            if miss < cfg.delete_misses {
                assert_eq!(out.obstacles.len(), 1, "coasting after {miss} misses");
                assert_eq!(out.obstacles[0].misses, miss);
            } else {
                assert!(out.obstacles.is_empty(), "deleted after {miss} misses");
            }
        }
    }

    #[test]
    fn a_post_driven_past_stays_where_it_is_while_remembered() {
        // Driving past a post at 2 m/s, it leaves the field of view (270 degrees);
        // then the car stands for 20 s with the post behind it. The filter's velocity
        // estimate is never quite zero, and must not carry the remembered post along.
        let mount = default_mount();
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mut rng = Rng(31);
        let post = [6.0, -2.5];
        let world = [Shape::Circle { c: post, r: 0.35 }];
        let mut last = None;
        for k in 0..=1300 {
            let t = k as f64 / RATE;
            let pose = Pose2::new((2.0 * t).min(12.0), 0.0, 0.0);
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            if k >= 20 {
                let o = out
                    .obstacles
                    .iter()
                    .find(|o| dist([o.disc.x, o.disc.y], post) < 0.5)
                    .unwrap_or_else(|| panic!("k {k}: the post is lost: {:?}", out.obstacles));
                last = Some(*o);
            }
        }
        let o = last.expect("reported");
        eprintln!(
            "remembered post after 20 s out of sight: {:.3} m from where it is",
            dist([o.disc.x, o.disc.y], post)
        );
        assert!(dist([o.disc.x, o.disc.y], post) < 0.1, "{o:?}");
        assert_eq!((o.disc.vx, o.disc.vy), (0.0, 0.0));
    }

    #[test]
    fn a_walker_overtaken_goes_on_at_its_pace_out_of_sight_and_is_then_forgotten() {
        // A walker at 0.7 m/s 2 m right of the car's line, overtaken at 2 m/s: it
        // leaves the field of view (270 degrees) behind the car. It goes on being
        // reported moving where its pace takes it for `moving_memory_s`, then is
        // dropped; with no such memory it is lost as it leaves the view.
        let mount = default_mount();
        for memory in [5.0, 0.0] {
            let mut p = Perception::new(PerceptionConfig {
                moving_memory_s: memory,
                ..PerceptionConfig::default()
            })
            .expect("config");
            let mut rng = Rng(41);
            let (mut out_of_view, mut worst, mut gone) = (None::<f64>, 0.0f64, None::<f64>);
            for k in 0..=750 {
                let t = k as f64 / RATE;
                let walker = [8.0 + 0.7 * t, -2.0];
                let pose = Pose2::new(2.0 * t, 0.0, 0.0);
                let world = [Shape::Circle { c: walker, r: 0.3 }];
                let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
                // Behind the laser's field of view: bearing beyond 135 degrees.
                let bearing = (walker[1] - pose.y).atan2(walker[0] - (pose.x + 2.0));
                if bearing.abs() > 0.76 * std::f64::consts::PI {
                    out_of_view.get_or_insert(t);
                }
                let seen = out
                    .obstacles
                    .iter()
                    .find(|o| dist([o.disc.x, o.disc.y], walker) < 2.0 && o.disc.vx > 0.3);
                match (seen, out_of_view) {
                    (Some(o), Some(_)) => worst = worst.max(dist([o.disc.x, o.disc.y], walker)),
                    (None, Some(_)) => {
                        gone.get_or_insert(t);
                    }
                    (Some(_), None) => gone = None,
                    (None, None) => {}
                }
            }
            let (left, gone) = (out_of_view.expect("overtaken"), gone.expect("forgotten"));
            eprintln!(
                "walker overtaken, memory {memory} s: out of view at {left:.2} s, reported until {gone:.2} s, at most {worst:.2} m off"
            );
            if memory > 0.0 {
                assert!(gone - left > memory - 1.5, "reported only until {gone} s");
                assert!(gone - left < memory + 1.0, "reported until {gone} s");
                assert!(worst < 1.5, "{worst}");
            } else {
                assert!(gone - left < 0.5, "reported until {gone} s");
            }
        }
    }

    #[test]
    fn a_walker_leaving_the_view_slowly_keeps_its_velocity_and_is_not_missed_at_the_edge() {
        // A walker at 0.7 m/s 2.3 m right of the car's line, passed slowly (1.1 m/s):
        // for about a second the edge of the field of view cuts it, the last scans
        // seeing two to five hits of its front. Those must neither bend its velocity
        // (blob centres at the visible part's end made it 0.92 m/s, turning towards
        // the line, and its coasting disc ran ahead into the view and was dropped there)
        // nor count as misses: it goes on out of sight where it is.
        let mount = default_mount();
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mut rng = Rng(7);
        let (mut out_of_view, mut worst_v, mut worst_at) = (None::<f64>, 0.0f64, 0.0f64);
        for k in 0..=(13.0 * RATE) as usize {
            let t = k as f64 / RATE;
            let walker = [3.0 + 0.7 * t, -2.3];
            let pose = Pose2::new(1.1 * t, 0.0, 0.0);
            let world = [Shape::Circle { c: walker, r: 0.3 }];
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            let bearing = (walker[1] - pose.y).atan2(walker[0] - (pose.x + 2.0));
            if bearing.abs() > 0.76 * std::f64::consts::PI {
                out_of_view.get_or_insert(t);
            }
            let Some(left) = out_of_view else { continue };
            if t - left > 4.0 {
                break;
            }
            let o = out
                .obstacles
                .iter()
                .find(|o| dist([o.disc.x, o.disc.y], walker) < 2.0)
                .unwrap_or_else(|| {
                    panic!("walker dropped {:.2} s after leaving the view", t - left)
                });
            worst_v = worst_v.max(dist([o.disc.vx, o.disc.vy], [0.7, 0.0]));
            worst_at = worst_at.max(dist([o.disc.x, o.disc.y], walker));
        }
        assert!(out_of_view.is_some(), "the walker never left the view");
        eprintln!(
            "walker out of view: velocity at most {worst_v:.3} m/s off, position {worst_at:.2} m"
        );
        assert!(worst_v < 0.15, "velocity {worst_v} m/s off");
        assert!(worst_at < 0.4, "position {worst_at} m off");
    }

    #[test]
    fn a_hedge_driven_along_keeps_the_stretch_behind_the_scanner() {
        // A 30 m hedge 2.5 m to the left; the car drives along it at 2 m/s for 10 s.
        // The scanner's blind 90 degrees behind it hide all of the hedge more than
        // 2.5 m behind the laser, and the local map keeps it: the wall's segment still
        // starts where the hedge does, not at the edge of the field of view.
        let mount = default_mount();
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mut rng = Rng(41);
        let world = [Shape::Segment {
            a: [0.0, 2.5],
            b: [30.0, 2.5],
        }];
        let mut worst_start = 0.0f64;
        for k in 0..=500 {
            let t = k as f64 / RATE;
            let pose = Pose2::new(-3.0 + 2.0 * t, 0.0, 0.0);
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            if k < 25 {
                continue;
            }
            let hedge = out
                .segments
                .iter()
                .filter(|s| (s.p0[1] - 2.5).abs() < 0.2 && (s.p1[1] - 2.5).abs() < 0.2)
                .map(|s| s.p0[0].min(s.p1[0]))
                .min_by(f64::total_cmp);
            let start = hedge.unwrap_or_else(|| panic!("k {k}: no hedge: {:?}", out.segments));
            worst_start = worst_start.max(start.abs());
            assert!(
                start.abs() < 0.3,
                "k {k}: the hedge starts at x = {start:.2}"
            );
            // Its pieces out to the detection radius go to the planner, behind too.
            let laser_x = pose.x + mount.x;
            assert!(
                out.obstacles.iter().any(|o| o.disc.x < laser_x - 4.0) || laser_x < 5.0,
                "k {k}: nothing behind the laser: {:?}",
                out.obstacles
            );
        }
        eprintln!("hedge driven along: its remembered start at most {worst_start:.3} m off");
    }

    #[test]
    fn a_gate_in_a_fence_stays_as_wide_as_it_is() {
        // A 0.2 m fence across the route at x = 20 with a 2.0 m gate (car width +
        // 0.8 m) from y = -1 to 1, approached at the passage speed. The fence's ends,
        // seen edge-on, make clusters of their own, blobs that come and go: missed, one
        // stays where it was seen (it once coasted on its velocity estimate right
        // across the gate). No circle may reach into the opening by more than 20 cm
        // (the passage has 30 cm to spare; the blobs' enclosing circles take about
        // 14 cm of it).
        let mount = default_mount();
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mut rng = Rng(5);
        let world: Vec<Shape> = box_sides([20.0, 13.0], 0.2, 24.0)
            .into_iter()
            .chain(box_sides([20.0, -13.0], 0.2, 24.0))
            .collect();
        let mut worst = f64::INFINITY;
        for k in 0..=800 {
            let t = k as f64 / RATE;
            let pose = Pose2::new(2.0 + 1.0 * t, 0.05, 0.0);
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            for o in out
                .obstacles
                .iter()
                .filter(|o| (o.disc.x - 20.0).abs() < 1.0)
            {
                let open = o.disc.y.abs() - o.disc.radius;
                worst = worst.min(open);
                assert!(open > 0.8, "k {k}: {o:?} reaches into the gate");
            }
        }
        eprintln!("gate of 2.0 m: the nearest circle edge {worst:.3} m from its middle");
        assert!(worst < 1.05, "the fence's ends are reported: {worst}");
    }

    #[test]
    fn the_gap_between_parked_carts_stays_open_from_afar() {
        // Two pairs of carts (2.4 x 1.2 m) parked end to end either side of the route,
        // 2.6 m apart, seen from 20 m down to 14 m with the laser's full 16 m. Their
        // ends face the laser: 1.2 m flat faces a few noisy hits wide, through which
        // a circle metres wide once fitted (a "post" of radius 3.2 m straddling the
        // route, so the car turned off to go round the whole row). No circle may
        // reach into the gap by more than its wall chain's 0.35 m.
        let mount = default_mount();
        let world: Vec<Shape> = [[18.0, 1.9], [18.0, -1.9], [21.0, 1.9], [21.0, -1.9]]
            .into_iter()
            .flat_map(|c| box_sides(c, 2.4, 1.2))
            .collect();
        let mut worst = f64::INFINITY;
        for seed in 0..8 {
            let mut p = Perception::new(PerceptionConfig {
                detection_radius: 16.0,
                ..PerceptionConfig::default()
            })
            .expect("config");
            let mut rng = Rng(100 + seed);
            for k in 0..=150 {
                let t = k as f64 / RATE;
                let pose = Pose2::new(2.0 * t - 4.0, 0.02 * (seed as f64 - 4.0), 0.0);
                let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
                for o in out.obstacles.iter().filter(|o| o.disc.x > 14.0) {
                    let open = o.disc.y.abs() - o.disc.radius;
                    worst = worst.min(open);
                    assert!(open > 0.95, "seed {seed} k {k}: {o:?} reaches into the gap");
                }
            }
        }
        eprintln!("gap of 2.6 m: the nearest circle edge {worst:.3} m from its middle");
    }

    #[test]
    fn a_post_out_of_sight_is_remembered_within_the_memory_radius_and_then_forgotten() {
        let cfg = PerceptionConfig {
            detection_radius: 30.0,
            ..PerceptionConfig::default()
        };
        let mount = default_mount();
        let mut p = Perception::new(cfg.clone()).expect("config");
        let mut rng = Rng(7);
        let world = [Shape::Circle {
            c: [6.0, 0.0],
            r: 0.4,
        }];
        let mut k = 0;
        let mut step = |p: &mut Perception, pose: &Pose2, ranges: &[f32]| -> PerceptionOutput {
            let out = p
                .update(&LMS111.scan(k as f64 / RATE, ranges), &mount, pose)
                .expect("valid");
            k += 1;
            out
        };
        let ahead = Pose2::new(0.0, 0.0, 0.0);
        for _ in 0..10 {
            let ranges = LMS111.ranges(&world, &ahead, &mount, &mut rng, SIGMA);
            assert!(step(&mut p, &ahead, &ranges).obstacles.len() <= 1);
        }
        // Facing away (the post in the 90 degrees behind the scanner): no return at
        // all, yet the post is kept far beyond `delete_misses` scans, with no miss.
        let away = Pose2::new(0.0, 0.0, PI);
        let empty = vec![f32::INFINITY; 541];
        for _ in 0..(3 * cfg.delete_misses) {
            let out = step(&mut p, &away, &empty);
            assert_eq!(out.obstacles.len(), 1, "remembered");
            assert_eq!(out.obstacles[0].misses, 0);
            assert!(
                dist(
                    [out.obstacles[0].disc.x, out.obstacles[0].disc.y],
                    [6.0, 0.0]
                ) < 0.1
            );
        }
        // In view again with nothing there: it was moved, so it is missed and deleted.
        let mut gone = false;
        for _ in 0..=cfg.delete_misses {
            gone = step(&mut p, &ahead, &empty).obstacles.is_empty();
        }
        assert!(gone, "a post in sight that returns nothing is deleted");
        // Seen again, then left behind farther than the memory radius: forgotten.
        for _ in 0..10 {
            let ranges = LMS111.ranges(&world, &ahead, &mount, &mut rng, SIGMA);
            step(&mut p, &ahead, &ranges);
        }
        let far = Pose2::new(-cfg.memory_radius - 1.0, 0.0, PI);
        assert!(step(&mut p, &far, &empty).obstacles.is_empty(), "forgotten");
        // Behind a nearer return it is hidden, not missed.
        let mut p = Perception::new(cfg.clone()).expect("config");
        for _ in 0..10 {
            let ranges = LMS111.ranges(&world, &ahead, &mount, &mut rng, SIGMA);
            step(&mut p, &ahead, &ranges);
        }
        let screen = [Shape::Segment {
            a: [3.5, -2.0],
            b: [3.5, 2.0],
        }];
        for _ in 0..(3 * cfg.delete_misses) {
            let ranges = LMS111.ranges(&screen, &ahead, &mount, &mut rng, SIGMA);
            let out = step(&mut p, &ahead, &ranges);
            assert!(
                out.obstacles
                    .iter()
                    .any(|o| dist([o.disc.x, o.disc.y], [6.0, 0.0]) < 0.1 && o.misses == 0),
                "the hidden post is kept"
            );
        }
        // With no memory (the paper's behaviour), or seen in fewer than
        // `memory_min_hits` scans (no evidence enough to keep): coasting, then deleted
        // after `delete_misses` scans.
        let forgetful = [
            PerceptionConfig {
                memory_radius: 0.0,
                ..cfg.clone()
            },
            PerceptionConfig {
                memory_min_hits: 11,
                ..cfg.clone()
            },
        ];
        for config in forgetful {
            let mut p = Perception::new(config).expect("config");
            for _ in 0..10 {
                let ranges = LMS111.ranges(&world, &ahead, &mount, &mut rng, SIGMA);
                step(&mut p, &ahead, &ranges);
            }
            let mut out = step(&mut p, &away, &empty);
            assert_eq!(out.obstacles.len(), 1, "coasting");
            for _ in 1..cfg.delete_misses {
                out = step(&mut p, &away, &empty);
            }
            assert!(out.obstacles.is_empty(), "not remembered");
        }
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let ranges = vec![5.0f32; 541];
        let good = LMS111.scan(1.0, &ranges);
        // Poses (the scans' own checks: the two tests below).
        let e = detect(&good, &Pose2::new(f64::NAN, 0.0, 0.0), &pose, &cfg).expect_err("mount");
        assert!(matches!(
            e,
            PerceptionError::NonFinite {
                field: "mount.x",
                ..
            }
        ));
        let e =
            detect(&good, &mount, &Pose2::new(0.0, 0.0, f64::INFINITY), &cfg).expect_err("pose");
        assert!(matches!(
            e,
            PerceptionError::NonFinite {
                field: "pose.yaw",
                ..
            }
        ));

        // Stamps must increase; a refused scan leaves the tracker usable.
        let mut p = Perception::new(cfg.clone()).expect("config");
        p.update(&good, &mount, &pose).expect("first");
        let e = p.update(&good, &mount, &pose).expect_err("same stamp");
        assert!(matches!(e, PerceptionError::StampNotIncreasing { .. }));
        let earlier = Scan {
            stamp: 0.5,
            ..*good
        }
        .validate()
        .expect("valid");
        assert!(p.update(&earlier, &mount, &pose).is_err());
        let later = Scan {
            stamp: 1.02,
            ..*good
        }
        .validate()
        .expect("valid");
        assert!(p.update(&later, &mount, &pose).is_ok());

        // Configuration.
        for bad in [
            PerceptionConfig {
                detection_radius: -1.0,
                ..cfg.clone()
            },
            PerceptionConfig {
                detection_radius: f64::NAN,
                ..cfg.clone()
            },
            PerceptionConfig {
                birth_hits: 6,
                ..cfg.clone()
            },
            PerceptionConfig {
                birth_window: 40,
                ..cfg.clone()
            },
            PerceptionConfig {
                circle_radius_max: 0.01,
                ..cfg.clone()
            },
        ] {
            let e = Perception::new(bad.clone()).expect_err("invalid config");
            assert!(matches!(e, PerceptionError::InvalidConfig { .. }), "{e}");
            assert!(detect(&good, &mount, &pose, &bad).is_err());
        }
    }

    /// A scan with a non-finite or zero angle increment, angle_min or stamp is refused,
    /// the field named.
    #[test]
    fn malformed_scan_fields_are_errors() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let ranges = vec![5.0f32; 541];
        let good = LMS111.scan(1.0, &ranges);
        // Refused where it is checked, once: before perception takes it.
        let check = |scan: Scan<'_>, what: &str| {
            let err = scan
                .validate()
                .and_then(|scan| detect(&scan, &mount, &pose, &cfg))
                .expect_err(what);
            eprintln!("{what}: {err}");
            err
        };
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = check(
                Scan {
                    angle_increment: bad,
                    ..*good
                },
                "non-finite angle_increment",
            );
            assert!(matches!(
                e,
                PerceptionError::NonFinite {
                    field: "angle_increment",
                    ..
                }
            ));
        }
        assert!(matches!(
            check(
                Scan {
                    angle_increment: 0.0,
                    ..*good
                },
                "zero increment"
            ),
            PerceptionError::ZeroAngleIncrement { beams: 541 }
        ));
        assert!(matches!(
            check(
                Scan {
                    angle_min: f64::NAN,
                    ..*good
                },
                "NaN angle_min"
            ),
            PerceptionError::NonFinite {
                field: "angle_min",
                ..
            }
        ));
        assert!(matches!(
            check(
                Scan {
                    stamp: f64::NAN,
                    ..*good
                },
                "NaN stamp"
            ),
            PerceptionError::NonFinite { field: "stamp", .. }
        ));
    }

    /// A scan with range limits out of order or negative, or more beams than its
    /// increment allows, is refused; a full revolution is not.
    #[test]
    fn scan_range_limits_and_beam_counts_are_checked() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let ranges = vec![5.0f32; 541];
        let good = LMS111.scan(1.0, &ranges);
        // Refused where it is checked, once: before perception takes it.
        let check = |scan: Scan<'_>, what: &str| {
            let err = scan
                .validate()
                .and_then(|scan| detect(&scan, &mount, &pose, &cfg))
                .expect_err(what);
            eprintln!("{what}: {err}");
            err
        };
        assert!(matches!(
            check(
                Scan {
                    range_min: 5.0,
                    range_max: 1.0,
                    ..*good
                },
                "range limits"
            ),
            PerceptionError::InvalidRangeLimits { .. }
        ));
        assert!(matches!(
            check(
                Scan {
                    range_min: -1.0,
                    ..*good
                },
                "negative range_min"
            ),
            PerceptionError::InvalidRangeLimits { .. }
        ));
        // 800 ranges at 0.5 degrees: 399.5 degrees, more beams than the increment allows.
        let long = vec![5.0f32; 800];
        assert!(matches!(
            check(
                Scan {
                    ranges: &long,
                    ..*good
                },
                "ranges vs increment"
            ),
            PerceptionError::BeamCountMismatch { beams: 800, .. }
        ));
        // A full revolution is fine: 720 beams of 0.5 degrees.
        let full = vec![5.0f32; 720];
        let full = Scan {
            ranges: &full,
            ..*good
        }
        .validate()
        .expect("a full revolution");
        assert!(detect(&full, &mount, &pose, &cfg).is_ok());
    }

    #[test]
    fn config_serde_defaults_and_unknown_fields() {
        let cfg = PerceptionConfig::default();
        let json = serde_json::to_string(&cfg).expect("serialise");
        let back: PerceptionConfig = serde_json::from_str(&json).expect("parse");
        assert_eq!(back, cfg);
        let partial: PerceptionConfig =
            serde_json::from_str(r#"{"detection_radius": 10.0}"#).expect("parse");
        assert_eq!(partial.detection_radius, 10.0);
        assert_eq!(partial.min_points, cfg.min_points);
        assert!(serde_json::from_str::<PerceptionConfig>(r#"{"detection_radiu": 10.0}"#).is_err());
    }

    #[test]
    fn moving_obstacles_are_reported_out_to_the_moving_detection_radius() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut p = Perception::new(cfg.clone()).expect("config");
        let mut rng = Rng(17);
        let mut last = None;
        // A pedestrian 13 m ahead walking towards the car, and a post 12 m ahead.
        for k in 0..=60 {
            let t = k as f64 / RATE;
            let world = [
                Shape::Circle {
                    c: [13.0 - 0.8 * t, 1.0],
                    r: 0.35,
                },
                Shape::Circle {
                    c: [12.0, -3.0],
                    r: 0.4,
                },
            ];
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            if k < 20 {
                assert!(
                    out.obstacles.is_empty(),
                    "k {k}: nothing within 8 m, no velocity confirmed yet: {:?}",
                    out.obstacles
                );
            }
            last = Some(out);
        }
        let out = last.expect("scans");
        assert_eq!(out.obstacles.len(), 1, "{:?}", out.obstacles);
        let o = out.obstacles[0];
        assert!(o.disc.x > 8.0 && (o.disc.vx + 0.8).abs() < 0.2, "{o:?}");
        assert_eq!(p.all_tracks().len(), 2);
        // With the moving radius at the static one, neither is reported.
        let mut narrow = Perception::new(PerceptionConfig {
            moving_detection_radius: cfg.detection_radius,
            ..cfg
        })
        .expect("config");
        let world = [Shape::Circle {
            c: [13.0, 1.0],
            r: 0.35,
        }];
        for k in 0..10 {
            let out = LMS111.track(
                &mut narrow,
                &world,
                &pose,
                &mount,
                k as f64 / RATE,
                &mut rng,
            );
            assert!(out.obstacles.is_empty());
        }
    }

    #[test]
    fn a_jump_of_the_vehicle_position_does_not_make_a_post_move() {
        let cfg = PerceptionConfig::default();
        let mount = default_mount();
        let mut p = Perception::new(cfg).expect("config");
        let mut rng = Rng(23);
        let post = [Shape::Circle {
            c: [6.0, 0.5],
            r: 0.5,
        }];
        let mut nonzero = 0;
        for k in 0..=100 {
            let t = k as f64 / RATE;
            let truth = Pose2::new(0.0, 0.0, 0.0);
            let ranges = LMS111.ranges(&post, &truth, &mount, &mut rng, SIGMA);
            // From 0.5 s on the pose estimate is 0.3 m off (RTK fixed to float): every
            // obstacle jumps by that much in the world frame.
            let believed = if k >= 25 {
                Pose2::new(0.3, -0.1, 0.0)
            } else {
                truth
            };
            let out = p
                .update(&LMS111.scan(t, &ranges), &mount, &believed)
                .expect("valid");
            for o in &out.obstacles {
                if o.disc.vx != 0.0 || o.disc.vy != 0.0 {
                    nonzero += 1;
                }
            }
            if k > 10 {
                assert_eq!(out.obstacles.len(), 1, "k {k}: {:?}", out.obstacles);
            }
        }
        assert_eq!(nonzero, 0, "the jump was never reported as motion");
    }

    // ---------------------------------------------------------------- clutter

    /// The obstacles of a ugv-sim scenario file: circles, and walls as the two long
    /// faces of their rectangle (their ends are under the posts BARN puts there).
    #[allow(clippy::expect_used, clippy::panic)]
    fn scenario_world(text: &str) -> Vec<Shape> {
        let scenario: toml::Value = toml::from_str(text).expect("scenario");
        let num = |v: &toml::Value, key: &str| v[key].as_float().expect("number");
        let mut shapes = Vec::new();
        for o in scenario["obstacles"].as_array().expect("obstacles") {
            match o["kind"].as_str() {
                Some("circle") => shapes.push(Shape::Circle {
                    c: [num(o, "x"), num(o, "y")],
                    r: num(o, "radius"),
                }),
                Some("wall") => {
                    let points = o["points"].as_array().expect("points");
                    let point = |i: usize| {
                        let p = points[i].as_array().expect("point");
                        [p[0].as_float().expect("x"), p[1].as_float().expect("y")]
                    };
                    let (a, b) = (point(0), point(1));
                    let h = 0.5 * num(o, "thickness") / dist(a, b);
                    let n = [-(b[1] - a[1]) * h, (b[0] - a[0]) * h];
                    for s in [1.0, -1.0] {
                        shapes.push(Shape::Segment {
                            a: [a[0] + s * n[0], a[1] + s * n[1]],
                            b: [b[0] + s * n[0], b[1] + s * n[1]],
                        });
                    }
                }
                other => panic!("obstacle kind {other:?}"),
            }
        }
        shapes
    }

    /// The poses (t, x, y, heading) of a drive, one a line, `#` comments.
    #[allow(clippy::expect_used)]
    fn drive(text: &str) -> Vec<(f64, Pose2)> {
        text.lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let f: Vec<f64> = l.split(',').map(|x| x.parse().expect("number")).collect();
                (f[0], Pose2::new(f[1], f[2], f[3]))
            })
            .collect()
    }

    #[test]
    fn a_barn_world_driven_through_shows_no_static_obstacle_moving_and_its_walker_and_cart_moving()
    {
        // BARN world 37 (posts of 0.21 m on a 0.42 m lattice, scaled for the car), the
        // car's own drive through it in SIL, and beyond the clutter a walker crossing at
        // 0.5 m/s and a cart at 1.3 m/s. Seen through the lattice, pieces of posts and
        // walls show and hide as the car moves: windows onto a wall slide, clusters
        // split and merge, a track takes a neighbour's fragment. None may be reported
        // moving; the walker and the cart must be.
        let mut world = scenario_world(include_str!("fixtures/barn-037.toml"));
        let statics = world.len();
        let path = drive(include_str!("fixtures/barn-037-drive.csv"));
        let walker = |t: f64| [31.0, -12.0 + 0.5 * t];
        let cart = |t: f64| [35.0, -40.0 + 1.3 * t];
        let mount = default_mount();
        let mut p = Perception::new(PerceptionConfig::default()).expect("config");
        let mut rng = Rng(37);
        let (mut phantoms, mut walker_moving, mut cart_moving, mut late) = (0, 0, 0, 0);
        for (t, pose) in path {
            world.truncate(statics);
            world.push(Shape::Circle {
                c: walker(t),
                r: 0.5,
            });
            world.extend(box_sides(cart(t), 1.2, 2.4));
            let out = LMS111.track(&mut p, &world, &pose, &mount, t, &mut rng);
            let near = |o: &TrackedObstacle, c: [f64; 2]| dist([o.disc.x, o.disc.y], c) < 1.5;
            for o in out
                .obstacles
                .iter()
                .filter(|o| o.disc.vx != 0.0 || o.disc.vy != 0.0)
            {
                if !near(o, walker(t)) && !near(o, cart(t)) {
                    phantoms += 1;
                    eprintln!("t {t:.2}: static obstacle reported moving: {o:?}");
                }
            }
            if t < 23.0 {
                continue;
            }
            late += 1;
            let moving = |c: [f64; 2], v: [f64; 2]| {
                out.obstacles
                    .iter()
                    .any(|o| near(o, c) && (o.disc.vx - v[0]).hypot(o.disc.vy - v[1]) < 0.3)
            };
            walker_moving += usize::from(moving(walker(t), [0.0, 0.5]));
            cart_moving += usize::from(moving(cart(t), [0.0, 1.3]));
        }
        eprintln!(
            "BARN 37: {phantoms} static reports moving; from 23 s walker moving {walker_moving}, cart {cart_moving} of {late} scans"
        );
        assert_eq!(phantoms, 0, "static obstacles reported moving");
        assert!(late > 100);
        assert!(
            walker_moving * 10 >= late * 8,
            "walker {walker_moving} of {late}"
        );
        assert!(cart_moving * 10 >= late * 8, "cart {cart_moving} of {late}");
    }
}
