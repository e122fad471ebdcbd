//! The GPS out on a serial device instead of the pty: the simulator's GpsPort opens a
//! tty with serialport at the baud rate (here one end of a null-modem pair of ptys,
//! standing in for a USB-serial adapter and its cable), the controller's reader opens
//! the far end as it would on its board, gets every paced fix at the simulated
//! position, and what it writes back reaches the simulator. No vcan needed.

use std::io::Write as _;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, ensure};
use firmware_bridge::nmea::{FixQuality, NmeaLink, ReadEvent, ReaderConfig, checksum, open_serial};
use ugv_e2e_tests::NullModem;
use ugv_sim::Scenario;
use ugv_sim::devices::gps::GpsPort;
use ugv_sim::vehicle::VehicleState;

#[test]
fn fixes_cross_a_serial_cable_to_the_controller_and_its_input_comes_back() -> Result<()> {
    let cable = NullModem::new()?;
    let sc = Scenario::paper()?;
    let baud = 115_200;
    let mut dev = sc.gps_device()?;
    let mut port = GpsPort::serial(&cable.a, baud)?;
    ensure!(port.path() == cable.a);

    let serial = open_serial(&cable.b, baud, Duration::from_millis(20))?;
    let mut ctl = NmeaLink::new(
        serial,
        ReaderConfig {
            complete_when: sc.gps.sentence_set(),
            ..ReaderConfig::default()
        },
    );
    let mut car = VehicleState::at(&sc.start);
    car.x = 12.5;
    car.y = -3.25;
    let mut epochs = Vec::new();
    let mut readings = Vec::new();
    let read = |ctl: &mut NmeaLink<_>, readings: &mut Vec<_>| -> Result<()> {
        for ev in ctl.poll()? {
            if let ReadEvent::Fix(f) = ev {
                readings.push(f);
            }
        }
        Ok(())
    };
    // One simulated second at 5 ms ticks: ten epochs complete.
    for k in 0..=200u32 {
        if let Some(e) = port.tick(&mut dev, f64::from(k) * 0.005, &car)? {
            epochs.push(e);
        }
        if k % 4 == 0 {
            read(&mut ctl, &mut readings)?;
        }
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while readings.len() < 10 && Instant::now() < deadline {
        read(&mut ctl, &mut readings)?;
    }
    ensure!(epochs.len() == 11, "{} epochs", epochs.len());
    ensure!(readings.len() == 10, "{} readings", readings.len());
    ensure!(ctl.stats().errors() == 0, "{:?}", ctl.stats());
    ensure!(port.dropped_bytes() == 0);
    for (r, e) in readings.iter().zip(&epochs) {
        ensure!(r.quality == Some(FixQuality::RtkFixed));
        ensure!(r.time == Some(e.utc.time()), "{:?} vs {}", r.time, e.utc);
        let enu = r.enu(dev.frame()).context("position")?;
        let d = (enu.east_m - e.truth.enu.east_m).hypot(enu.north_m - e.truth.enu.north_m);
        ensure!(d < 0.1, "epoch {}: {d} m from the antenna", e.index);
    }

    // The controller's GGA for NTRIP goes back up the cable.
    let body = "GPGGA,140001.00,3712.0000,N,07724.0000,W,4,12,0.7,30.0,M,-33.0,M,1.0,0001";
    let line = format!("${body}*{:02X}\r\n", checksum(body.as_bytes()));
    ctl.write_all(line.as_bytes())?;
    let deadline = Instant::now() + Duration::from_secs(5);
    while port.input().count() == 0 && Instant::now() < deadline {
        port.pace(1.0)?;
        std::thread::sleep(Duration::from_millis(5));
    }
    ensure!(port.input().count() == 1, "{:?}", port.input());
    ensure!(port.input().last() == Some(line.trim_end()));
    Ok(())
}
