//! Helpers shared by the GPS device tests (sim/tests/gps_*.rs).
#![allow(dead_code)]

use anyhow::{Context as _, Result};
use firmware_bridge::nmea::{GpsReading, NmeaReader, ReadEvent, ReaderConfig};
use ugv_sim::devices::gps::{GpsConfig, GpsDevice, GpsEpoch};
use ugv_sim::scenario::Scenario;
use ugv_sim::vehicle::VehicleState;

/// The simulator's tick.
pub const TICK_S: f64 = 0.005;

/// The default scenario (datum at Petersburg VA, epoch 2026-05-04T14:00:00Z, seed 1)
/// with `gps` as its receiver.
pub fn scenario(gps: GpsConfig) -> Scenario {
    Scenario {
        gps,
        ..Scenario::default()
    }
}

pub fn device(gps: GpsConfig) -> Result<GpsDevice> {
    Ok(scenario(gps).gps_device()?)
}

/// A vehicle state: rear axle at (x, y), heading `theta_deg` counter-clockwise from
/// East, speed `v`, road-wheel angle `phi_deg`.
pub fn vehicle(x: f64, y: f64, theta_deg: f64, v: f64, phi_deg: f64) -> VehicleState {
    VehicleState {
        x,
        y,
        theta: theta_deg.to_radians(),
        v,
        phi: phi_deg.to_radians(),
        odometer: 0.0,
    }
}

/// A configuration without any error (for exact geometry checks).
pub fn noiseless() -> GpsConfig {
    let mut c = GpsConfig {
        heading_sigma_deg: 0.0,
        ..GpsConfig::default()
    };
    for m in [
        (
            &mut c.rtk.horizontal_sigma_m,
            &mut c.rtk.vertical_sigma_m,
            &mut c.rtk.velocity_sigma_mps,
        ),
        (
            &mut c.float.horizontal_sigma_m,
            &mut c.float.vertical_sigma_m,
            &mut c.float.velocity_sigma_mps,
        ),
        (
            &mut c.single.horizontal_sigma_m,
            &mut c.single.vertical_sigma_m,
            &mut c.single.velocity_sigma_mps,
        ),
    ] {
        *m.0 = 0.0;
        *m.1 = 0.0;
        *m.2 = 0.0;
    }
    c
}

/// A reader that completes an epoch on the sentences `gps` sends.
pub fn reader(gps: &GpsConfig) -> NmeaReader {
    NmeaReader::new(ReaderConfig {
        complete_when: gps.sentence_set(),
        ..ReaderConfig::default()
    })
}

/// The one reading of an epoch's text.
pub fn read_one(reader: &mut NmeaReader, text: &str) -> Result<GpsReading> {
    let mut fixes = Vec::new();
    for e in reader.feed(text.as_bytes()) {
        match e {
            ReadEvent::Fix(f) => fixes.push(f),
            ReadEvent::Error(e) => anyhow::bail!("reader error {e} in {text:?}"),
        }
    }
    anyhow::ensure!(fixes.len() == 1, "{} readings from {text:?}", fixes.len());
    fixes.pop().context("one reading")
}

/// Tick at 200 Hz from 0 to `until_s` (inclusive) with the vehicle state `at(t)`,
/// collecting the epochs.
pub fn run(
    dev: &mut GpsDevice,
    until_s: f64,
    mut at: impl FnMut(f64) -> VehicleState,
) -> Result<Vec<GpsEpoch>> {
    let ticks = (until_s / TICK_S).round() as u64;
    let mut out = Vec::new();
    for k in 0..=ticks {
        let t = k as f64 * TICK_S;
        if let Some(e) = dev.poll(t, &at(t))? {
            out.push(e);
        }
    }
    Ok(out)
}
