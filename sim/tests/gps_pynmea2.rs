//! Cross-check of every sentence the simulated receiver writes against pynmea2
//! (PyPI, pinned in scripts/install-deps.sh), an independent NMEA parser: checksums,
//! field counts and typed fields (times, dates, latitude/longitude, quality, heights,
//! speeds, GST sigmas), for every fix state (RTK fixed, float, single, none), both
//! heading sentences and two talkers. pynmea2 1.19 has no THS: the peer script checks
//! its framing and checksum itself. gpsd (gps_gpsd.rs) checks the RTK-fixed stream as
//! a receiver consumer; this checks each sentence, including the no-fix ones gpsd
//! would silently ignore. A missing pynmea2 fails the test with the install command.

mod gps_common;

use std::io::Write as _;
use std::process::{Command, Stdio};

use anyhow::{Context as _, Result, bail, ensure};
use gps_common::{device, vehicle};
use serde_json::Value;
use ugv_sim::devices::gps::{FixEvent, FixKind, GpsConfig, GpsEpoch, HeadingSentence};

/// The peer: one JSON object per input line, with pynmea2's parsed fields or an error.
const PEER: &str = r#"import datetime, json, sys
try:
    import pynmea2
except ImportError:
    sys.stderr.write("pynmea2 is not installed\n")
    sys.exit(3)

def plain(v):
    # Times of day without pynmea2's UTC tzinfo, always with microseconds.
    if isinstance(v, datetime.time):
        return v.replace(tzinfo=None).isoformat(timespec="microseconds")
    return v

for raw in sys.stdin:
    line = raw.rstrip("\r\n")
    if not line:
        continue
    rec = {"line": line}
    try:
        if line[3:6] == "THS":
            # pynmea2 1.19 has no THS: check its framing and checksum here.
            body, _, cs = line[1:].partition("*")
            calc = 0
            for ch in body:
                calc ^= ord(ch)
            if len(cs) != 2 or int(cs, 16) != calc:
                raise ValueError("THS checksum %s, computed %02X" % (cs, calc))
            f = body.split(",")
            if len(f) != 3:
                raise ValueError("THS has %d fields" % len(f))
            rec.update(type="THS", fields={"heading": f[1], "mode": f[2]})
        else:
            m = pynmea2.parse(line, check=True)
            if len(m.data) != len(m.fields):
                raise ValueError("%d fields, pynmea2 expects %d" % (len(m.data), len(m.fields)))
            rec.update(type=m.sentence_type, talker=m.talker,
                       fields={name: plain(getattr(m, name)) for _, name, *_ in m.fields})
            if getattr(m, "lat", ""):
                rec.update(latitude=m.latitude, longitude=m.longitude)
    except Exception as e:
        rec["error"] = "%s: %s" % (type(e).__name__, e)
    print(json.dumps(rec, default=str))
"#;

const KNOTS_PER_MPS: f64 = 3600.0 / 1852.0;

fn python() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_owned())
}

/// pynmea2's view of each line of `text`.
fn parse_with_pynmea2(text: &str) -> Result<Vec<Value>> {
    let mut child = Command::new(python())
        .args(["-c", PEER])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("running {} (set PYTHON to choose another)", python()))?;
    child
        .stdin
        .take()
        .context("peer stdin")?
        .write_all(text.as_bytes())?;
    let out = child.wait_with_output()?;
    if out.status.code() == Some(3) {
        bail!(
            "pynmea2 is not installed for {}: run `{} -m pip install pynmea2==1.19.0` \
             (scripts/install-deps.sh installs it)",
            python(),
            python()
        );
    }
    ensure!(
        out.status.success(),
        "pynmea2 peer failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)?
        .lines()
        .map(|l| serde_json::from_str(l).with_context(|| format!("peer output {l:?}")))
        .collect()
}

fn num(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.parse().ok(),
        _ => None,
    }
}

fn field<'a>(rec: &'a Value, name: &str) -> &'a Value {
    &rec["fields"][name]
}

fn close(got: Option<f64>, want: f64, tol: f64) -> bool {
    got.is_some_and(|g| (g - want).abs() <= tol)
}

fn angle_close(got: Option<f64>, want: f64, tol: f64) -> bool {
    got.is_some_and(|g| ((g - want + 540.0).rem_euclid(360.0) - 180.0).abs() <= tol)
}

/// Every sentence of `e` as pynmea2 read it agrees with the fix sent.
fn check_epoch(e: &GpsEpoch, recs: &[Value], talker: &str) -> Result<()> {
    let f = &e.fix;
    let valid = f.quality.has_position();
    let time = e.utc.format("%H:%M:%S%.6f").to_string();
    for r in recs {
        let what = format!("t {}: {}", e.time_s, r["line"]);
        if let Some(err) = r["error"].as_str() {
            bail!("{what}: pynmea2: {err}");
        }
        let ty = r["type"].as_str().context("type")?;
        if ty != "THS" {
            ensure!(r["talker"] == talker, "{what}: talker");
        }
        let ts = field(r, "timestamp").as_str().unwrap_or("");
        ensure!(
            ts.is_empty() || ts == time,
            "{what}: time {ts}, want {time}"
        );
        let lat_ok = !valid
            || (close(r["latitude"].as_f64(), f.lat_deg, 1e-8)
                && close(r["longitude"].as_f64(), f.lon_deg, 1e-8));
        match ty {
            "GGA" => check_gga(e, r, lat_ok, &what)?,
            "RMC" => check_rmc(e, r, lat_ok, &what)?,
            "VTG" => check_vtg(e, r, &what)?,
            "GST" => check_gst(e, r, &what)?,
            "HDT" | "THS" => match f.heading_deg {
                Some(h) => ensure!(angle_close(num(field(r, "heading")), h, 6e-4), "{what}"),
                None => ensure!(
                    num(field(r, "heading")).is_none(),
                    "{what}: heading without fix"
                ),
            },
            "ZDA" => check_zda(e, r, &what)?,
            other => bail!("{what}: unexpected sentence {other}"),
        }
    }
    Ok(())
}

/// pynmea2's GGA `r` (`what`, in messages) agrees with `e`'s fix: quality, satellites,
/// HDOP, and with a fix the position (`lat_ok`), heights, correction age and station.
fn check_gga(e: &GpsEpoch, r: &Value, lat_ok: bool, what: &str) -> Result<()> {
    let f = &e.fix;
    ensure!(
        num(field(r, "gps_qual")) == Some(f64::from(f.quality.gga_digit())),
        "{what}"
    );
    ensure!(
        num(field(r, "num_sats")) == Some(f64::from(f.satellites)),
        "{what}"
    );
    ensure!(
        close(num(field(r, "horizontal_dil")), f.hdop, 0.006),
        "{what}"
    );
    if f.quality.has_position() {
        ensure!(lat_ok, "{what}: position");
        ensure!(
            close(num(field(r, "altitude")), f.altitude_msl_m(), 6e-4),
            "{what}"
        );
        ensure!(
            close(num(field(r, "geo_sep")), f.geoid_separation_m, 6e-4),
            "{what}"
        );
        match f.correction_age_s {
            Some(age) => {
                ensure!(close(num(field(r, "age_gps_data")), age, 0.06), "{what}")
            }
            None => ensure!(field(r, "age_gps_data") == "", "{what}: age"),
        }
        let station = f.station_id.map(|s| format!("{s:04}")).unwrap_or_default();
        ensure!(
            field(r, "ref_station_id") == station.as_str(),
            "{what}: station"
        );
    } else {
        ensure!(
            field(r, "lat") == "" && field(r, "altitude").is_null(),
            "{what}"
        );
    }
    Ok(())
}

/// pynmea2's RMC `r` agrees with `e`: status, date and mode, and with a fix the
/// position (`lat_ok`), speed and course.
fn check_rmc(e: &GpsEpoch, r: &Value, lat_ok: bool, what: &str) -> Result<()> {
    let f = &e.fix;
    let valid = f.quality.has_position();
    ensure!(
        field(r, "status") == if valid { "A" } else { "V" },
        "{what}: status"
    );
    ensure!(
        field(r, "datestamp").as_str() == Some(&e.utc.format("%Y-%m-%d").to_string()),
        "{what}: date"
    );
    let mode = f.quality.mode().as_char().to_string();
    ensure!(field(r, "mode_indicator") == mode.as_str(), "{what}: mode");
    if valid {
        ensure!(lat_ok, "{what}: position");
        let knots = f.speed_mps * KNOTS_PER_MPS;
        ensure!(
            close(num(field(r, "spd_over_grnd")), knots, 6e-4),
            "{what}: speed"
        );
        ensure!(
            angle_close(num(field(r, "true_course")), f.course_deg, 0.006),
            "{what}"
        );
    }
    Ok(())
}

/// pynmea2's VTG `r` agrees with `e`'s fix: the mode, and with a fix track and speed.
fn check_vtg(e: &GpsEpoch, r: &Value, what: &str) -> Result<()> {
    let f = &e.fix;
    let mode = f.quality.mode().as_char().to_string();
    ensure!(field(r, "faa_mode") == mode.as_str(), "{what}: mode");
    if f.quality.has_position() {
        ensure!(
            angle_close(num(field(r, "true_track")), f.course_deg, 0.006),
            "{what}"
        );
        ensure!(
            close(num(field(r, "spd_over_grnd_kmph")), f.speed_mps * 3.6, 6e-4),
            "{what}: speed"
        );
    }
    Ok(())
}

/// pynmea2's GST `r` agrees with `e`'s fix: its sigmas with a fix, none without.
fn check_gst(e: &GpsEpoch, r: &Value, what: &str) -> Result<()> {
    let f = &e.fix;
    match (f.quality.has_position(), f.accuracy) {
        (true, Some(a)) => {
            for (name, want) in [
                ("rms", a.rms_m),
                ("std_dev_major", a.semi_major_m),
                ("std_dev_minor", a.semi_minor_m),
                ("std_dev_latitude", a.lat_sigma_m),
                ("std_dev_longitude", a.lon_sigma_m),
                ("std_dev_altitude", a.alt_sigma_m),
            ] {
                ensure!(close(num(field(r, name)), want, 6e-4), "{what}: {name}");
            }
        }
        _ => ensure!(
            num(field(r, "std_dev_latitude")).is_none(),
            "{what}: GST without fix"
        ),
    }
    Ok(())
}

/// pynmea2's ZDA `r` carries `e`'s date.
fn check_zda(e: &GpsEpoch, r: &Value, what: &str) -> Result<()> {
    let date = e.utc.format("%d %m %Y").to_string();
    let got = ["day", "month", "year"]
        .map(|k| num(field(r, k)).map_or(-1, |v| v as i64))
        .map(|v| v.to_string());
    let want: Vec<String> = date
        .split(' ')
        .map(|s| s.parse::<i64>().map_or(-2, |v| v).to_string())
        .collect();
    ensure!(got.as_slice() == want.as_slice(), "{what}: date {got:?}");
    Ok(())
}

#[test]
fn every_sentence_parses_in_pynmea2_and_agrees_with_the_fix() -> Result<()> {
    let events = vec![
        FixEvent {
            at_s: 0.5,
            fix: FixKind::Float,
        },
        FixEvent {
            at_s: 1.0,
            fix: FixKind::Single,
        },
        FixEvent {
            at_s: 1.5,
            fix: FixKind::None,
        },
        FixEvent {
            at_s: 2.0,
            fix: FixKind::Rtk,
        },
    ];
    let mut hdt = GpsConfig {
        events: events.clone(),
        ..GpsConfig::default()
    };
    hdt.geoid_separation_m = -33.2;
    hdt.station_id = 42;
    let mut ths = GpsConfig {
        events,
        ..GpsConfig::default()
    };
    ths.sentences.heading = HeadingSentence::Ths;
    ths.talker = firmware_bridge::nmea::Talker::GP;
    ths.rate_hz = 20.0;
    let mut checked = 0;
    for (cfg, talker) in [(hdt, "GN"), (ths, "GP")] {
        let mut dev = device(cfg.clone())?;
        let scenario = gps_common::scenario(cfg.clone());
        let wheelbase = scenario.vehicle.wheelbase;
        // Reversing on a curve south-west of the datum: negative coordinates, all courses.
        let mut s = vehicle(-120.0, -80.0, 200.0, -1.2, 25.0);
        let mut epochs = Vec::new();
        for k in 0..=500u32 {
            if k > 0 {
                s.step(wheelbase, -1.2, 25f64.to_radians(), 0.005);
            }
            if let Some(e) = dev.poll(f64::from(k) * 0.005, &s)? {
                epochs.push(e);
            }
        }
        let text: String = epochs.iter().map(|e| e.text.as_str()).collect();
        let recs = parse_with_pynmea2(&text)?;
        ensure!(recs.len() == text.lines().count(), "{} records", recs.len());
        let mut i = 0;
        for e in &epochs {
            let n = e.text.lines().count();
            check_epoch(e, recs.get(i..i + n).context("records")?, talker)?;
            i += n;
            checked += n;
        }
        for kind in [FixKind::Rtk, FixKind::Float, FixKind::Single, FixKind::None] {
            ensure!(
                epochs.iter().any(|e| e.fix_kind == kind),
                "no {kind:?} epoch"
            );
        }
    }
    eprintln!("pynmea2 agreed with {checked} sentences");
    Ok(())
}
