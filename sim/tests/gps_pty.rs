//! The GPS port over a real pseudo-terminal: the simulator's GpsPort writes paced NMEA
//! to a pty behind a user-named link, the controller opens the link with
//! firmware-bridge's `open_serial` (as it would /dev/ttyUSB0) and gets fixes; what the
//! controller writes back is read and logged.

mod gps_common;

use std::io::Write as _;
use std::time::Duration;

use anyhow::{Context as _, Result, ensure};
use firmware_bridge::nmea::{FixQuality, NmeaLink, ReadEvent, ReaderConfig, checksum, open_serial};
use gps_common::{TICK_S, device, vehicle};
use ugv_sim::devices::gps::{GpsConfig, GpsPort};

#[test]
fn controller_reads_paced_fixes_through_the_link_and_its_input_is_logged() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let link = dir.path().join("ugv-gps-pty-roundtrip");
    let cfg = GpsConfig::default();
    let mut dev = device(cfg.clone())?;
    let mut port = GpsPort::open(Some(&link), cfg.baud)?;
    ensure!(port.path() == link);
    ensure!(std::fs::read_link(&link)? == port.slave_path());

    // The controller's side, exactly as on the car.
    let serial = open_serial(&link, cfg.baud, Duration::from_millis(50))?;
    let mut ctl = NmeaLink::new(
        serial,
        ReaderConfig {
            complete_when: cfg.sentence_set(),
            ..ReaderConfig::default()
        },
    );

    let s = vehicle(10.0, -5.0, 120.0, 1.5, 0.0);
    let mut epochs = Vec::new();
    let mut readings = Vec::new();
    // One simulated second, ticked as fast as the pty goes.
    for k in 0..=200u32 {
        let now = f64::from(k) * TICK_S;
        if let Some(e) = port.tick(&mut dev, now, &s)? {
            epochs.push(e);
        }
        if port.pacer().released() > 0 && k % 4 == 0 {
            for ev in ctl.poll()? {
                if let ReadEvent::Fix(f) = ev {
                    readings.push(f);
                }
            }
        }
    }
    // Let the last complete epochs arrive.
    for _ in 0..5 {
        for ev in ctl.poll()? {
            if let ReadEvent::Fix(f) = ev {
                readings.push(f);
            }
        }
    }
    ensure!(epochs.len() == 11);
    // Epochs 0-9 are complete by t = 1.0; epoch 10 has only begun.
    ensure!(
        readings.len() == 10,
        "{} readings: {readings:?}",
        readings.len()
    );
    ensure!(ctl.stats().errors() == 0, "{:?}", ctl.stats());
    ensure!(port.dropped_bytes() == 0);
    ensure!(port.written() == port.pacer().released());
    for (r, e) in readings.iter().zip(&epochs) {
        ensure!(r.quality == Some(FixQuality::RtkFixed));
        ensure!(r.time == Some(e.utc.time()), "{:?} vs {}", r.time, e.utc);
        let enu = r.enu(dev.frame()).context("position")?;
        let d = (enu.east_m - e.truth.enu.east_m).hypot(enu.north_m - e.truth.enu.north_m);
        ensure!(d < 0.1, "epoch {}: {d} m from the antenna", e.index);
    }

    // The controller writes back: a GGA for NTRIP and a configuration command.
    let sentence = |body: &str| format!("${body}*{:02X}", checksum(body.as_bytes()));
    let gga = sentence(
        "GPGGA,140001.00,3713.8420000,N,07725.1820000,W,4,20,0.60,41.800,M,0.000,M,1.0,0000",
    );
    let cfg_cmd = sentence("PUBX,41,1,0007,0003,115200,0");
    let (gga, cfg_cmd) = (gga.as_str(), cfg_cmd.as_str());
    ctl.write_all(format!("{gga}\r\n{cfg_cmd}\r\n").as_bytes())?;
    ctl.flush()?;
    let mut now = 1.0;
    for _ in 0..200 {
        port.pace(now)?;
        if port.input().count() >= 2 {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
        now += TICK_S;
    }
    let lines: Vec<&str> = port.input().lines().collect();
    ensure!(lines == [gga, cfg_cmd], "logged {lines:?}");
    ensure!(port.input().count() == 2 && port.input().errors() == 0);
    ensure!(port.input().last() == Some(cfg_cmd));

    // The link goes with the port.
    drop(port);
    ensure!(
        std::fs::symlink_metadata(&link).is_err(),
        "link left behind"
    );
    Ok(())
}

/// A reader that stops reading (issue 16, item 5): the pty fills, and the receiver's
/// transmit buffer drops whole sentences, never part of one, so what the reader gets
/// when it reads again is whole sentences with good checksums, none spliced from two;
/// every sentence sent was either read or counted as dropped.
#[test]
fn a_stalled_reader_loses_whole_sentences_never_parts() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let link = dir.path().join("ugv-gps-stall");
    let cfg = GpsConfig {
        rate_hz: 20.0,
        baud: 460_800,
        ..GpsConfig::default()
    };
    let mut dev = device(cfg.clone())?;
    let mut port = GpsPort::open(Some(&link), cfg.baud)?;
    let mut reader = open_serial(&link, cfg.baud, Duration::from_millis(1))?;
    let mut received = Vec::new();
    fn drain(reader: &mut impl std::io::Read, received: &mut Vec<u8>) {
        let mut buf = [0u8; 4096];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 {
                break;
            }
            received.extend_from_slice(&buf[..n]);
        }
    }
    let s = vehicle(0.0, 0.0, 0.0, 1.0, 0.0);
    let mut sent = 0usize;
    let mut now = 0.0;
    let mut stalled_for = 0.0;
    let mut k = 0u32;
    // Read for 1 s; stall until the line has dropped sentences for a second (at most
    // 60 s of sentences); read again for 2 s.
    let mut phase = 0;
    let mut resumed_at = 0.0;
    while phase < 3 {
        now = f64::from(k) * TICK_S;
        k += 1;
        if let Some(e) = port.tick(&mut dev, now, &s)? {
            sent += e.text.matches('\n').count();
        }
        match phase {
            0 => {
                drain(&mut reader, &mut received);
                if now >= 1.0 {
                    phase = 1;
                }
            }
            1 => {
                if port.dropped_sentences() > 0 {
                    stalled_for += TICK_S;
                }
                ensure!(now < 60.0, "60 s of sentences and nothing dropped");
                if stalled_for >= 1.0 {
                    phase = 2;
                    resumed_at = now;
                }
            }
            _ => {
                drain(&mut reader, &mut received);
                if now - resumed_at >= 2.0 {
                    phase = 3;
                }
            }
        }
    }
    // Let what is queued go out and be read.
    for _ in 0..2000 {
        now += TICK_S;
        port.pace(now)?;
        drain(&mut reader, &mut received);
        if port.pacer().pending() == 0
            && port.written() == port.pacer().released() - port.dropped_bytes()
        {
            break;
        }
    }
    drain(&mut reader, &mut received);
    let text = String::from_utf8(received).context("the NMEA is ASCII")?;
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    for line in &lines {
        let body = line
            .strip_prefix('$')
            .and_then(|l| l.strip_suffix("\r\n"))
            .with_context(|| format!("not a whole sentence: {line:?}"))?;
        let (body, sum) = body
            .rsplit_once('*')
            .with_context(|| format!("no checksum: {line:?}"))?;
        ensure!(
            u8::from_str_radix(sum, 16).ok() == Some(checksum(body.as_bytes())),
            "a sentence spliced from two (its checksum fails): {line:?}"
        );
    }
    let dropped = port.dropped_sentences() as usize;
    eprintln!(
        "{sent} sentences sent, {} read, {dropped} dropped whole ({} bytes)",
        lines.len(),
        port.dropped_bytes()
    );
    ensure!(dropped > 0, "the stall dropped nothing");
    ensure!(
        lines.len() + dropped == sent,
        "{} read + {dropped} dropped != {sent} sent",
        lines.len()
    );
    Ok(())
}
