//! The simulated GPS receiver: geometry at known poses through the NMEA wire and back,
//! epoch timing and UTC, fix-quality events, determinism, and the `[gps]` section.

mod gps_common;

use anyhow::{Context as _, Result, ensure};
use chrono::{NaiveDate, TimeDelta};
use firmware_bridge::nmea::{FixQuality, SentenceKind};
use gps_common::{TICK_S, device, noiseless, read_one, reader, run, scenario, vehicle};
use ugv_sim::Scenario;
use ugv_sim::devices::gps::{FixEvent, FixKind, GpsConfig, HeadingSentence};
use ugv_sim::vehicle::VehicleState;

/// The antenna's world position by hand: the offset rotated by theta.
fn antenna_of(s: &VehicleState, ax: f64, ay: f64) -> (f64, f64) {
    (
        s.x + ax * s.theta.cos() - ay * s.theta.sin(),
        s.y + ax * s.theta.sin() + ay * s.theta.cos(),
    )
}

/// Equal to the GST's precision (the nmea crate parses its fields as f32).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + 540.0).rem_euclid(360.0) - 180.0
}

#[test]
fn fixes_at_known_poses_round_trip_through_the_reader() -> Result<()> {
    let mut cfg = noiseless();
    cfg.antenna_x = 0.5;
    cfg.antenna_y = 0.3;
    cfg.antenna_z = 1.8;
    let scn = scenario(cfg.clone());
    let wheelbase = scn.vehicle.wheelbase;
    // (x, y, theta deg CCW from East, v, phi deg)
    let poses = [
        (0.0, 0.0, 0.0, 0.0, 0.0),
        (12.5, -40.0, 90.0, 2.0, 0.0),
        (-300.0, 250.0, 180.0, 3.0, 0.0),
        (30.0, 15.0, -135.0, -1.5, 0.0),
        (5.0, 5.0, 45.0, 2.5, 20.0),
        (800.0, -600.0, 170.0, 1.0, -30.0),
    ];
    for (x, y, th, v, phi) in poses {
        let s = vehicle(x, y, th, v, phi);
        let mut dev = scn.gps_device()?;
        let epoch = dev.poll(0.0, &s)?.context("an epoch at t = 0")?;
        let reading = read_one(&mut reader(&cfg), &epoch.text)?;
        let what = format!("pose {x} {y} {th} {v} {phi}");
        ensure!(reading.quality == Some(FixQuality::RtkFixed), "{what}");

        // Position: the offset rotated by theta, back through WGS-84 and the wire.
        let (ae, an) = antenna_of(&s, 0.5, 0.3);
        let enu = reading.enu(dev.frame()).context("position")?;
        let d = (enu.east_m - ae).hypot(enu.north_m - an);
        ensure!(d < 1e-3, "{what}: antenna off by {d} m");
        let h = reading.ellipsoid_height_m().context("height")?;
        let want_h = scn.datum.altitude + 1.8;
        ensure!(
            (h - want_h).abs() < 1e-3,
            "{what}: height {h}, want {want_h}"
        );

        // Speed and course: finite differences of the antenna along the exact arc.
        let dt = 1e-4;
        let (mut a, mut b) = (s, s);
        a.step(wheelbase, v, phi.to_radians(), -dt);
        b.step(wheelbase, v, phi.to_radians(), dt);
        let (pa, pb) = (antenna_of(&a, 0.5, 0.3), antenna_of(&b, 0.5, 0.3));
        let (ve, vn) = ((pb.0 - pa.0) / (2.0 * dt), (pb.1 - pa.1) / (2.0 * dt));
        let speed = reading.speed_mps.context("speed")?;
        ensure!(
            (speed - ve.hypot(vn)).abs() < 1e-3,
            "{what}: speed {speed}, want {}",
            ve.hypot(vn)
        );
        if v != 0.0 {
            let course = reading.course_deg.context("course")?;
            let want = ve.atan2(vn).to_degrees().rem_euclid(360.0);
            ensure!(
                angle_diff(course, want).abs() < 0.01,
                "{what}: course {course}, want {want}"
            );
        }
        // Heading: theta as a compass heading.
        let heading = reading.heading_deg.context("heading")?;
        let want = (90.0 - th).rem_euclid(360.0);
        ensure!(
            angle_diff(heading, want).abs() < 0.001,
            "{what}: heading {heading}, want {want}"
        );
        ensure!(
            reading.utc()
                == NaiveDate::from_ymd_opt(2026, 5, 4).and_then(|d| d.and_hms_opt(14, 0, 0))
        );
    }
    Ok(())
}

#[test]
fn reversing_east_reports_course_west_and_heading_east() -> Result<()> {
    let cfg = noiseless();
    let mut dev = device(cfg.clone())?;
    let e = dev
        .poll(0.0, &vehicle(0.0, 0.0, 0.0, -2.0, 0.0))?
        .context("epoch")?;
    let r = read_one(&mut reader(&cfg), &e.text)?;
    ensure!(angle_diff(r.course_deg.context("course")?, 270.0).abs() < 0.01);
    ensure!(angle_diff(r.heading_deg.context("heading")?, 90.0).abs() < 0.001);
    Ok(())
}

#[test]
fn rtk_fixes_stay_within_noise_and_report_consistent_gst() -> Result<()> {
    let cfg = GpsConfig::default();
    let mut dev = device(cfg.clone())?;
    let mut rd = reader(&cfg);
    let wheelbase = Scenario::default().vehicle.wheelbase;
    // Driving a circle at 3 m/s for 20 s.
    let mut s = vehicle(0.0, 0.0, 30.0, 3.0, 15.0);
    let mut epochs = Vec::new();
    for k in 0..=4000u32 {
        let t = f64::from(k) * TICK_S;
        if k > 0 {
            s.step(wheelbase, 3.0, 15f64.to_radians(), TICK_S);
        }
        if let Some(e) = dev.poll(t, &s)? {
            epochs.push((e, s));
        }
    }
    ensure!(
        epochs.len() == 201,
        "{} epochs in 20 s at 10 Hz",
        epochs.len()
    );
    for (e, _) in &epochs {
        let r = read_one(&mut rd, &e.text)?;
        let enu = r.enu(dev.frame()).context("position")?;
        // 5 sigma of RTK fixed: 1.5 cm per horizontal axis, 3 cm vertical.
        let (de, dn) = (
            enu.east_m - e.truth.enu.east_m,
            enu.north_m - e.truth.enu.north_m,
        );
        ensure!(
            de.abs() < 0.075 && dn.abs() < 0.075,
            "t {}: error {de} {dn}",
            e.time_s
        );
        let dh = r.ellipsoid_height_m().context("height")? - e.truth.geodetic.height_m;
        ensure!(dh.abs() < 0.15, "t {}: height error {dh}", e.time_s);
        let dhead = angle_diff(r.heading_deg.context("heading")?, e.truth.heading_deg);
        ensure!(dhead.abs() < 0.5, "t {}: heading error {dhead}", e.time_s);
        let dspeed = r.speed_mps.context("speed")? - e.truth.speed_mps;
        ensure!(dspeed.abs() < 0.15, "t {}: speed error {dspeed}", e.time_s);
        let dcourse = angle_diff(r.course_deg.context("course")?, e.truth.course_deg);
        ensure!(
            dcourse.abs() < 3.0,
            "t {}: course error {dcourse}",
            e.time_s
        );
        let acc = r.accuracy.context("GST")?;
        // GST as written (mm) and parsed (the nmea crate's f32).
        for (got, want) in [
            (acc.lat_sigma_m, 0.015),
            (acc.lon_sigma_m, 0.015),
            (acc.alt_sigma_m, 0.03),
            (acc.semi_major_m, 0.015),
            (acc.semi_minor_m, 0.015),
        ] {
            ensure!(close(got, want), "GST {acc:?}");
        }
        ensure!(r.quality == Some(FixQuality::RtkFixed));
        ensure!(r.satellites == Some(20) && r.hdop.is_some_and(|h| close(h, 0.6)));
        ensure!(r.correction_age_s == Some(1.0) && r.station_id == Some(0));
    }
    Ok(())
}

#[test]
fn epochs_fall_on_absolute_times_whatever_the_tick() -> Result<()> {
    let cfg = noiseless();
    // A straight run at 2 m/s heading 30 deg: the antenna's position at any time is known.
    let at = |t: f64| {
        let th = 30f64.to_radians();
        vehicle(2.0 * t * th.cos(), 2.0 * t * th.sin(), 30.0, 2.0, 0.0)
    };
    for (rate, tick) in [
        (10.0f64, 0.005f64),
        (10.0, 1.0 / 150.0),
        (20.0, 1.0 / 150.0),
        (4.0, 0.003),
    ] {
        let mut c = cfg.clone();
        c.rate_hz = rate;
        let mut dev = device(c.clone())?;
        let mut epochs = Vec::new();
        let ticks = (3.0 / tick).round() as u64;
        for k in 0..=ticks {
            let t = k as f64 * tick;
            if let Some(e) = dev.poll(t, &at(t))? {
                epochs.push(e);
            }
        }
        ensure!(dev.missed_epochs() == 0);
        let expected = (3.0 * rate) as usize + 1;
        ensure!(
            epochs.len() == expected,
            "rate {rate} tick {tick}: {} epochs",
            epochs.len()
        );
        let start = chrono::DateTime::parse_from_rfc3339("2026-05-04T14:00:00Z")?.to_utc();
        for (k, e) in epochs.iter().enumerate() {
            ensure!(e.index == k as u64);
            ensure!((e.time_s - k as f64 / rate).abs() < 1e-12);
            let want = start + TimeDelta::microseconds((k as f64 / rate * 1e6).round() as i64);
            ensure!(e.utc == want, "epoch {k}: utc {} want {want}", e.utc);
            // The state at the tick was moved back to the epoch time.
            let s = at(e.time_s);
            let (ae, an) = antenna_of(&s, c.antenna_x, c.antenna_y);
            let d = (e.truth.enu.east_m - ae).hypot(e.truth.enu.north_m - an);
            ensure!(
                d < 1e-9,
                "rate {rate} tick {tick} epoch {k}: {d} m off the epoch-time pose"
            );
            let r = read_one(&mut reader(&c), &e.text)?;
            let want_time = want.time();
            ensure!(r.time == Some(want_time), "{:?} vs {want_time}", r.time);
        }
    }
    Ok(())
}

#[test]
fn skipped_epochs_are_counted_and_the_latest_is_sent() -> Result<()> {
    let mut dev = device(noiseless())?;
    let s = vehicle(0.0, 0.0, 0.0, 0.0, 0.0);
    ensure!(dev.poll(0.0, &s)?.map(|e| e.index) == Some(0));
    ensure!(dev.poll(0.05, &s)?.is_none());
    ensure!(dev.poll(0.35, &s)?.map(|e| e.index) == Some(3));
    ensure!(dev.missed_epochs() == 2);
    ensure!((dev.next_epoch_time() - 0.4).abs() < 1e-12);
    ensure!(dev.poll(f64::NAN, &s).is_err());
    Ok(())
}

#[test]
fn fix_events_change_gga_quality_at_their_time() -> Result<()> {
    let cfg = GpsConfig {
        events: vec![
            FixEvent {
                at_s: 2.0,
                fix: FixKind::Float,
            },
            FixEvent {
                at_s: 3.0,
                fix: FixKind::Single,
            },
            FixEvent {
                at_s: 4.0,
                fix: FixKind::None,
            },
            FixEvent {
                at_s: 5.05,
                fix: FixKind::Rtk,
            },
        ],
        ..GpsConfig::default()
    };
    let mut dev = device(cfg.clone())?;
    let mut rd = reader(&cfg);
    let epochs = run(&mut dev, 6.0, |_| vehicle(10.0, 20.0, 45.0, 0.0, 0.0))?;
    ensure!(epochs.len() == 61);
    for e in &epochs {
        let t = e.time_s;
        let (want, kind) = if t < 2.0 {
            (FixQuality::RtkFixed, FixKind::Rtk)
        } else if t < 3.0 {
            (FixQuality::RtkFloat, FixKind::Float)
        } else if t < 4.0 {
            (FixQuality::Single, FixKind::Single)
        } else if t < 5.05 {
            (FixQuality::Invalid, FixKind::None)
        } else {
            (FixQuality::RtkFixed, FixKind::Rtk)
        };
        ensure!(e.fix_kind == kind, "t {t}: {:?}", e.fix_kind);
        let r = read_one(&mut rd, &e.text)?;
        ensure!(
            r.quality == Some(want),
            "t {t}: GGA quality {:?}, want {want:?}",
            r.quality
        );
        let gga = e
            .text
            .lines()
            .find(|l| l.starts_with("$GNGGA"))
            .context("GGA")?;
        let digit = gga.split(',').nth(6).context("GGA field 6")?;
        ensure!(digit == want.gga_digit().to_string(), "t {t}: {gga}");
        match kind {
            FixKind::None => {
                ensure!(r.lat_deg.is_none() && r.accuracy.is_none() && r.heading_deg.is_none());
            }
            FixKind::Single => {
                ensure!(r.correction_age_s.is_none() && r.station_id.is_none());
                ensure!(r.satellites == Some(12));
                ensure!(r.accuracy.is_some_and(|a| close(a.lat_sigma_m, 1.5)));
            }
            FixKind::Float => {
                ensure!(r.correction_age_s == Some(1.0) && r.satellites == Some(16));
                ensure!(r.accuracy.is_some_and(|a| close(a.alt_sigma_m, 0.5)));
            }
            FixKind::Rtk => ensure!(r.accuracy.is_some_and(|a| close(a.lat_sigma_m, 0.015))),
        }
    }
    Ok(())
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() -> Result<()> {
    let cfg = GpsConfig {
        events: vec![FixEvent {
            at_s: 1.0,
            fix: FixKind::Single,
        }],
        ..GpsConfig::default()
    };
    let drive = |seed: u64| -> Result<String> {
        let mut scn = scenario(cfg.clone());
        scn.sim.seed = seed;
        let mut dev = scn.gps_device()?;
        let wheelbase = scn.vehicle.wheelbase;
        let mut s = vehicle(0.0, 0.0, 0.0, 2.0, 10.0);
        let mut text = String::new();
        for k in 0..=400u32 {
            if k > 0 {
                s.step(wheelbase, 2.0, 10f64.to_radians(), TICK_S);
            }
            if let Some(e) = dev.poll(f64::from(k) * TICK_S, &s)? {
                text.push_str(&e.text);
            }
        }
        Ok(text)
    };
    let a = drive(7)?;
    ensure!(a == drive(7)?, "seed 7 twice gave different bytes");
    ensure!(a != drive(8)?, "seeds 7 and 8 gave the same bytes");
    ensure!(a.lines().count() == 21 * 6);
    Ok(())
}

#[test]
fn heading_sentence_choice_and_single_antenna() -> Result<()> {
    let mut cfg = GpsConfig::default();
    cfg.sentences.heading = HeadingSentence::Ths;
    let e = device(cfg.clone())?
        .poll(0.0, &vehicle(0.0, 0.0, 0.0, 0.0, 0.0))?
        .context("epoch")?;
    ensure!(e.text.contains("$GNTHS,") && !e.text.contains("HDT"));
    let r = read_one(&mut reader(&cfg), &e.text)?;
    ensure!(angle_diff(r.heading_deg.context("THS heading")?, 90.0).abs() < 0.5);

    cfg.dual_antenna = false;
    ensure!(!cfg.sentence_set().contains(SentenceKind::Ths));
    let e = device(cfg.clone())?
        .poll(0.0, &vehicle(0.0, 0.0, 0.0, 0.0, 0.0))?
        .context("epoch")?;
    ensure!(!e.text.contains("THS") && e.fix.heading_deg.is_none());
    ensure!(read_one(&mut reader(&cfg), &e.text)?.heading_deg.is_none());

    cfg.talker = firmware_bridge::nmea::Talker::GP;
    cfg.sentences.vtg = false;
    cfg.sentences.zda = false;
    let e = device(cfg.clone())?
        .poll(0.0, &vehicle(0.0, 0.0, 0.0, 0.0, 0.0))?
        .context("epoch")?;
    let kinds: Vec<&str> = e.text.lines().map(|l| l.get(1..6).unwrap_or("")).collect();
    ensure!(kinds == ["GPGGA", "GPRMC", "GPGST"], "{kinds:?}");
    Ok(())
}

// ---------------------------------------------------------------- the [gps] section

#[test]
fn gps_section_parses_with_events_and_partial_quality_tables() -> Result<()> {
    let text = r#"
[gps]
rate_hz = 5.0
baud = 38400
talker = "GP"
heading_sigma_deg = 0.2
fix = "float"
station_id = 42

[gps.sentences]
vtg = false
heading = "ths"

[gps.float]
horizontal_sigma_m = 0.2

[[gps.events]]
at_s = 20.0
fix = "rtk"

[[gps.events]]
at_s = 30.0
fix = "none"
"#;
    let s = Scenario::from_toml(text, "gps.toml")?;
    let g = &s.gps;
    ensure!(g.rate_hz == 5.0 && g.baud == 38_400 && g.talker.as_str() == "GP");
    ensure!(g.fix == FixKind::Float && g.station_id == 42);
    ensure!(!g.sentences.vtg && g.sentences.heading == HeadingSentence::Ths);
    // The rest of [gps.float] keeps float's defaults, not another quality's.
    ensure!(g.float.horizontal_sigma_m == 0.2 && g.float.vertical_sigma_m == 0.5);
    ensure!(g.float.satellites == 16 && g.rtk.horizontal_sigma_m == 0.015);
    ensure!(g.events.len() == 2 && g.events[1].fix == FixKind::None);
    ensure!(g.fix_at(19.9) == FixKind::Float && g.fix_at(20.0) == FixKind::Rtk);
    ensure!(g.fix_at(1e9) == FixKind::None);
    // Defaults kept.
    ensure!(g.antenna_x == 0.5 && g.antenna_z == 1.8 && g.dual_antenna);
    ensure!(GpsConfig::default().rate_hz == 10.0 && GpsConfig::default().baud == 115_200);
    Ok(())
}

fn refused(toml: &str) -> Result<String> {
    match Scenario::from_toml(toml, "bad.toml") {
        Ok(_) => anyhow::bail!("accepted: {toml}"),
        Err(e) => Ok(e.to_string()),
    }
}

#[test]
fn rate_and_baud_that_cannot_fit_are_refused_with_the_numbers() -> Result<()> {
    let e = refused("[gps]\nrate_hz = 20.0\nbaud = 38400\n")?;
    assert!(e.contains("gps.baud"), "{e}");
    assert!(e.contains("38400 baud") && e.contains("20 Hz"), "{e}");
    assert!(e.contains("needs at least"), "{e}");
    let e = refused("[gps]\nbaud = 9600\n")?;
    assert!(e.contains("9600") && e.contains("needs at least"), "{e}");
    // The same rate fits once the sentences are trimmed.
    let ok = "[gps]\nbaud = 9600\nrate_hz = 1.0\n";
    assert!(Scenario::from_toml(ok, "ok.toml").is_ok());
    let err = GpsConfig {
        rate_hz: 20.0,
        baud: 38_400,
        ..GpsConfig::default()
    }
    .validate()
    .expect_err("refused");
    assert_eq!(err.path.to_string(), "baud");
    Ok(())
}

#[test]
fn invalid_gps_fields_are_refused_by_name() -> Result<()> {
    for (toml, field) in [
        ("[gps]\nrate_hz = 25.0\n", "gps.rate_hz"),
        ("[gps]\nrate_hz = 0.5\n", "gps.rate_hz"),
        ("[gps]\nheading_sigma_deg = -1.0\n", "gps.heading_sigma_deg"),
        ("[gps]\nstation_id = 2000\n", "gps.station_id"),
        (
            "[gps.rtk]\nwhite_fraction = 1.5\n",
            "gps.rtk.white_fraction",
        ),
        (
            "[gps.single]\ntime_constant_s = 0.0\n",
            "gps.single.time_constant_s",
        ),
        (
            "[gps.sentences]\ngga = false\nrmc = false\n",
            "gps.sentences",
        ),
        (
            "[[gps.events]]\nat_s = 5.0\nfix = \"none\"\n[[gps.events]]\nat_s = 4.0\nfix = \"rtk\"\n",
            "gps.events",
        ),
    ] {
        let e = refused(toml)?;
        assert!(e.contains(field), "{toml}: {e}");
    }
    for toml in [
        "[gps]\nfix = \"dgps\"\n",
        "[gps]\nantena_x = 1.0\n",
        "[gps.rtk]\nsigma = 1.0\n",
        "[gps]\ntalker = \"PX\"\n",
    ] {
        let e = refused(toml)?;
        assert!(e.contains("bad.toml"), "{toml}: {e}");
    }
    Ok(())
}
