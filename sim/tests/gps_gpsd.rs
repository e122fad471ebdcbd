//! Cross-check against an independent NMEA implementation: Debian's gpsd reads the
//! simulated receiver's pty (through its link path, as it would /dev/ttyUSB0) and must
//! report a 3D RTK fix at the simulated antenna position, with the GST sigmas, speed,
//! track and heading the simulator sent.
//!
//! gpsd runs in the foreground as this test's child: `-N` (no daemon), `-n` (poll the
//! device without waiting for a client), `-b` (read-only: never write to the device),
//! `-S PORT` (its own TCP port, so tests run in parallel), `-F SOCKET` (its own control
//! socket). No `-G` (loopback is enough) and no root needed beyond reading the pty.
//! The test talks gpsd's JSON on TCP after `?WATCH={"enable":true,"json":true}`.
//! A missing gpsd fails the test: `apt-get install gpsd` (scripts/install-deps.sh).

mod gps_common;

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader, ErrorKind, Write as _};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail, ensure};
use chrono::{DateTime, Utc};
use firmware_bridge::Geodetic;
use gps_common::{device, vehicle};
use serde_json::Value;
use ugv_sim::devices::gps::{GpsConfig, GpsEpoch, GpsPort};

/// gpsd lives in /usr/sbin, which a non-root PATH may lack.
fn find_gpsd() -> Result<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/usr/local/sbin", "/sbin"].map(PathBuf::from))
        .map(|d| d.join("gpsd"))
        .find(|p| p.is_file())
        .context(
            "gpsd is not installed (looked in PATH, /usr/sbin, /usr/local/sbin, /sbin): \
             this cross-check needs it; run `apt-get install gpsd` \
             (scripts/install-deps.sh installs it)",
        )
}

/// The gpsd child, killed and reaped when the test ends however it ends.
struct Gpsd {
    child: Child,
    log: PathBuf,
}

impl Gpsd {
    fn start(link: &Path, port: u16, dir: &Path) -> Result<Gpsd> {
        let log = dir.join("gpsd.log");
        let child = Command::new(find_gpsd()?)
            .args(["-N", "-n", "-b", "-D", "2"])
            .arg("-S")
            .arg(port.to_string())
            .arg("-F")
            .arg(dir.join("gpsd.sock"))
            .arg(link)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log)?)
            .spawn()
            .context("starting gpsd")?;
        Ok(Gpsd { child, log })
    }

    fn log(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(30)..].join("\n")
    }
}

impl Drop for Gpsd {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn free_port() -> Result<u16> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// The number after `"key":` in a JSON-ish line.
fn json_number(line: &str, key: &str) -> Option<f64> {
    let rest = line.split(&format!("\"{key}\":")).nth(1)?;
    let end = rest.find([',', '}', '"']).unwrap_or(rest.len());
    rest[..end].trim().parse().ok()
}

fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + 540.0).rem_euclid(360.0) - 180.0
}

/// Metres between two positions, locally flat.
fn horizontal_m(a: &Geodetic, lat: f64, lon: f64) -> f64 {
    let dn = (lat - a.lat_deg).to_radians() * 6_371_000.0;
    let de = (lon - a.lon_deg).to_radians() * 6_371_000.0 * a.lat_deg.to_radians().cos();
    dn.hypot(de)
}

/// What gpsd reported. It reports a cycle's fix as it assembles it: a TPV after GGA (no
/// speed or track yet), then another once RMC/VTG are in. The last TPV of an epoch is its
/// report; an epoch is complete once a TPV of a later epoch has arrived.
#[derive(Default)]
struct Reported {
    /// The 3D TPVs by time, each with the epoch sent at that time.
    tpvs: BTreeMap<DateTime<Utc>, (Value, GpsEpoch)>,
    gst: Option<Value>,
    /// The heading of the ATT reports.
    att_heading: Option<f64>,
    /// TPVs without a time.
    untimed: usize,
}

impl Reported {
    /// Epochs whose report is complete.
    fn completed(&self) -> usize {
        self.tpvs.len().saturating_sub(1)
    }

    /// Take a line of gpsd's JSON, its TPVs matched with the epochs `sent`.
    fn take(&mut self, line: &str, sent: &BTreeMap<DateTime<Utc>, GpsEpoch>) -> Result<()> {
        if line.starts_with("{\"class\":\"ATT\"") {
            // gpsd 3.22 writes malformed ATT JSON from HDT (`,,` and a
            // missing comma); take its heading from the text.
            self.att_heading = Some(json_number(line, "heading").context(line.to_owned())?);
            return Ok(());
        }
        let v: Value =
            serde_json::from_str(line.trim()).with_context(|| format!("gpsd JSON {line:?}"))?;
        match v["class"].as_str() {
            Some("TPV") if v["mode"].as_i64() == Some(3) => {
                let Some(time) = v["time"].as_str() else {
                    // gpsd reports a cycle before it has the date (ZDA, RMC).
                    self.untimed += 1;
                    ensure!(self.untimed < 5, "TPVs without time: {v}");
                    return Ok(());
                };
                let time = DateTime::parse_from_rfc3339(time)?.to_utc();
                let epoch = sent
                    .iter()
                    .find(|(t, _)| (**t - time).num_milliseconds().abs() < 5)
                    .map(|(_, e)| e.clone())
                    .with_context(|| format!("TPV at {time} matches no epoch sent"))?;
                self.tpvs.insert(time, (v, epoch));
            }
            Some("GST") => self.gst = Some(v),
            _ => {}
        }
        Ok(())
    }
}

/// gpsd's TPV `v` agrees with the epoch `e` sent: position, height, RTK status, speed
/// and track.
fn check_tpv(v: &Value, e: &GpsEpoch) -> Result<()> {
    let what = format!("TPV {v}");
    let lat = v["lat"].as_f64().context("lat")?;
    let lon = v["lon"].as_f64().context("lon")?;
    // gpsd's position is the one sent (9 decimals of a degree: 0.1 mm)...
    let d_sent = horizontal_m(
        &Geodetic {
            lat_deg: e.fix.lat_deg,
            lon_deg: e.fix.lon_deg,
            height_m: 0.0,
        },
        lat,
        lon,
    );
    ensure!(d_sent < 0.002, "{what}: {d_sent} m from the fix sent");
    // ...which is the simulated antenna within RTK noise (5 sigma of 1.5 cm per axis).
    let d_true = horizontal_m(&e.truth.geodetic, lat, lon);
    ensure!(
        d_true < 0.075 * std::f64::consts::SQRT_2,
        "{what}: {d_true} m from the antenna"
    );
    // Heights: HAE (MSL + geoid separation) within 5 sigma of 3 cm.
    let hae = v["altHAE"].as_f64().context("altHAE")?;
    ensure!(
        (hae - e.truth.geodetic.height_m).abs() < 0.15,
        "{what}: altHAE {hae}"
    );
    // gpsd's status 2 is DGPS, 3 RTK fixed, 4 RTK float.
    ensure!(
        v["status"].as_i64() == Some(3),
        "{what}: status is not RTK fixed"
    );
    let speed = v["speed"].as_f64().context("speed")?;
    ensure!((speed - 2.0).abs() < 0.1, "{what}: speed {speed}");
    let track = v["track"].as_f64().context("track")?;
    ensure!(angle_diff(track, 60.0).abs() < 3.0, "{what}: track {track}");
    Ok(())
}

#[test]
fn gpsd_reports_a_3d_rtk_fix_at_the_simulated_position() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let link = dir.path().join("ugv-gps-gpsd");
    let cfg = GpsConfig::default();
    let mut dev = device(cfg.clone())?;
    let mut port = GpsPort::open(Some(&link), cfg.baud)?;
    let tcp = free_port()?;
    let gpsd = Gpsd::start(&link, tcp, dir.path())?;

    // Driving straight at 2 m/s, heading 30 deg (course 60).
    let th = 30f64.to_radians();
    let at = |t: f64| {
        vehicle(
            5.0 + 2.0 * t * th.cos(),
            -8.0 + 2.0 * t * th.sin(),
            30.0,
            2.0,
            0.0,
        )
    };

    let start = Instant::now();
    let mut client: Option<BufReader<TcpStream>> = None;
    let mut sent: BTreeMap<DateTime<Utc>, GpsEpoch> = BTreeMap::new();
    let mut got = Reported::default();
    let mut line = String::new();
    while got.completed() < 10 || got.gst.is_none() || got.att_heading.is_none() {
        let elapsed = start.elapsed().as_secs_f64();
        if elapsed > 30.0 {
            bail!(
                "after 30 s gpsd gave {} complete matching 3D epochs (GST: {}, ATT: {}); its log:\n{}",
                got.completed(),
                got.gst.is_some(),
                got.att_heading.is_some(),
                gpsd.log()
            );
        }
        // The simulator's tick, on the wall clock (HIL).
        if let Some(e) = port.tick(&mut dev, elapsed, &at(elapsed))? {
            sent.insert(e.utc, e);
        }
        let Some(c) = client.as_mut() else {
            if let Ok(mut s) = TcpStream::connect(("127.0.0.1", tcp)) {
                s.write_all(b"?WATCH={\"enable\":true,\"json\":true};\n")?;
                s.set_read_timeout(Some(Duration::from_millis(5)))?;
                client = Some(BufReader::new(s));
            } else {
                std::thread::sleep(Duration::from_millis(5));
            }
            continue;
        };
        match c.read_line(&mut line) {
            Ok(0) => bail!("gpsd closed the connection; its log:\n{}", gpsd.log()),
            Ok(_) if line.ends_with('\n') => {
                got.take(&line, &sent)?;
                line.clear();
            }
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => return Err(e.into()),
        }
    }

    let Reported {
        mut tpvs,
        gst,
        att_heading,
        ..
    } = got;
    // The latest epoch may still be incomplete.
    tpvs.pop_last();
    eprintln!(
        "first complete TPV: {}",
        tpvs.first_key_value()
            .map(|t| t.1.0.to_string())
            .unwrap_or_default()
    );
    eprintln!("gpsd log tail:\n{}", gpsd.log());
    ensure!(tpvs.len() >= 10, "{} complete epochs", tpvs.len());
    for (v, e) in tpvs.values() {
        check_tpv(v, e)?;
    }
    let gst = gst.context("GST")?;
    for (key, want) in [("lat", 0.015), ("lon", 0.015), ("alt", 0.03)] {
        let got = gst[key]
            .as_f64()
            .with_context(|| format!("GST {key}: {gst}"))?;
        ensure!((got - want).abs() < 1e-6, "GST {key} {got}, want {want}");
    }
    // The dual-antenna heading (HDT) is the vehicle's, 60 deg, within 5 sigma of 0.1 deg.
    let heading = att_heading.context("ATT heading")?;
    ensure!(
        angle_diff(heading, 60.0).abs() < 0.5,
        "ATT heading {heading}"
    );
    ensure!(
        port.dropped_bytes() == 0 && port.input().count() == 0,
        "gpsd -b wrote to the port"
    );
    Ok(())
}
