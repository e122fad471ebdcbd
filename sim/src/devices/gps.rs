//! The simulated RTK GPS receiver.
//!
//! - [`GpsConfig`] (`[gps]` in a scenario): antenna offset, rate and baud, talker and
//!   sentences, dual-antenna heading, fix state over time ([`FixEvent`]s), the error
//!   model of each fix state.
//! - [`GpsDevice`]: at epochs `k / rate_hz` of sim time, the antenna's true position
//!   and velocity from the rear-axle [`VehicleState`] plus seeded errors, as a
//!   [`GpsFix`] in WGS-84 around the scenario's datum, written as NMEA 0183 by
//!   firmware-bridge's [`NmeaWriter`].
//! - [`Pacer`]: the serial line's timing on sim time (byte `k` of an epoch leaves at
//!   `epoch time + k * byte time`); [`GpsPort`]: the pty the controller opens, fed by a
//!   pacer from the tick loop, logging what the controller writes back.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use ugv_sim::devices::gps::{GpsDevice, GpsPort};
//! let scenario = ugv_sim::Scenario::paper()?;
//! let mut gps = scenario.gps_device()?;
//! let mut port = GpsPort::open(Some("/tmp/ugv-gps".as_ref()), scenario.gps.baud)?;
//! let vehicle = ugv_sim::vehicle::VehicleState::at(&scenario.start);
//! for tick in 0..200u32 {
//!     let now = f64::from(tick) * 0.005;
//!     port.tick(&mut gps, now, &vehicle)?; // an epoch every 100 ms, paced at 115200 baud
//! }
//! # Ok(())
//! # }
//! ```
//!
//! # Model
//!
//! The antenna sits at (`antenna_x`, `antenna_y`) in the vehicle frame (x forward, y
//! left, from the rear axle), rotated by `theta`; its velocity is the rear axle's
//! plus `omega x r` with `omega = v tan(phi) / wheelbase`. Latitude and longitude are
//! those of the ENU point (east, north, `antenna_z` + error) in the datum's tangent
//! frame; the ellipsoidal height is `datum altitude + antenna_z + vertical error`
//! (level ground follows the Earth, not the tangent plane). Speed and course come
//! from the antenna's velocity plus white Doppler noise; course is degrees clockwise
//! from true North. The dual-antenna heading is `theta` as a compass heading plus
//! white noise (`heading_sigma_deg`), present whenever there is a position fix.
//! Position errors: see [`ErrorModel`] and [`FixModel`]; GST reports the model's
//! sigmas. A state sampled at a tick after the epoch time is moved back to the
//! epoch time along its arc, so epochs are exact whatever the physics rate.

mod config;
mod noise;
mod pacer;
mod port;

use std::time::Duration;

use chrono::{DateTime, Utc};
use firmware_bridge::geodesy::{
    GeodesyError, LocalFrame, course_of_velocity_deg, normalize_deg_360, theta_to_course_deg,
};
use firmware_bridge::nmea::{Accuracy, GpsFix, NmeaError, NmeaWriter, SentenceSet, UtcClock};
use firmware_bridge::{Enu, Geodetic};

pub use config::{
    BAUD_RANGE, FixEvent, FixKind, FixModel, FloatModel, GpsConfig, HeadingSentence, RATE_RANGE_HZ,
    RtkModel, Sentences, SingleModel,
};
pub use noise::{EpochError, ErrorModel, GPS_STREAM};
pub use pacer::Pacer;
pub use port::{GpsPort, INPUT_LOG_LINES, InputLog};

use super::FieldError;
use crate::scenario::schema::{Datum, SimConfig};
use crate::vehicle::VehicleState;
use ugv_fields::FieldPath;

/// Slack for deciding that an epoch is due, seconds.
const EPS_S: f64 = 1e-9;

/// Why the GPS device could not be built or could not produce an epoch.
#[derive(Debug, thiserror::Error)]
pub enum GpsError {
    #[error("{0}")]
    Config(FieldError),
    #[error("datum: {0}")]
    Datum(#[from] GeodesyError),
    #[error("sim time {0} is not a finite number")]
    Time(f64),
    #[error("vehicle wheelbase {0} is not a positive number")]
    Wheelbase(f64),
    #[error(transparent)]
    Nmea(#[from] NmeaError),
}

/// The antenna's true state at an epoch (before errors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AntennaTruth {
    /// World (ENU) position, metres; `up_m` is `antenna_z`.
    pub enu: Enu,
    /// WGS-84 position as the device converts it (height: datum altitude + antenna_z).
    pub geodetic: Geodetic,
    pub v_east_mps: f64,
    pub v_north_mps: f64,
    /// Speed over ground, m/s.
    pub speed_mps: f64,
    /// Course over ground, degrees clockwise from true North (0 at standstill).
    pub course_deg: f64,
    /// The vehicle's heading, degrees clockwise from true North.
    pub heading_deg: f64,
}

/// One receiver epoch: what was sent and what was true.
#[derive(Clone, Debug, PartialEq)]
pub struct GpsEpoch {
    /// Epoch number, from 0 at t = 0.
    pub index: u64,
    /// Sim time of the epoch, `index / rate_hz`, seconds.
    pub time_s: f64,
    pub utc: DateTime<Utc>,
    pub fix_kind: FixKind,
    pub fix: GpsFix,
    pub truth: AntennaTruth,
    /// The errors drawn for this epoch (zero without a fix).
    pub error: EpochError,
    pub sentences: SentenceSet,
    /// The epoch's NMEA sentences, CR LF terminated.
    pub text: String,
}

/// The simulated receiver: epochs on absolute sim times, seeded errors, NMEA out.
#[derive(Debug)]
pub struct GpsDevice {
    config: GpsConfig,
    frame: LocalFrame,
    datum_altitude_m: f64,
    wheelbase_m: f64,
    clock: UtcClock,
    writer: NmeaWriter,
    noise: ErrorModel,
    next_index: u64,
    missed: u64,
    /// Injected faults (`[[faults]]`): the fix kind forced, and an offset of the
    /// reported position (a jump, multipath), east and north metres.
    fix_override: Option<FixKind>,
    offset_m: (f64, f64),
}

impl GpsDevice {
    /// A receiver for `config` on a world around `datum`, with `sim`'s epoch (UTC at
    /// t = 0) and seed, on a vehicle of `wheelbase_m`.
    pub fn new(
        config: &GpsConfig,
        datum: &Datum,
        sim: &SimConfig,
        wheelbase_m: f64,
    ) -> Result<GpsDevice, GpsError> {
        config
            .validate()
            .map_err(|e| GpsError::Config(e.under(&FieldPath::of(&["gps"]))))?;
        if !(wheelbase_m.is_finite() && wheelbase_m > 0.0) {
            return Err(GpsError::Wheelbase(wheelbase_m));
        }
        let frame = LocalFrame::new(datum.geodetic())?;
        Ok(GpsDevice {
            config: config.clone(),
            frame,
            datum_altitude_m: datum.altitude,
            wheelbase_m,
            clock: UtcClock::new(sim.epoch.utc()),
            writer: NmeaWriter::new(config.writer_config())?,
            noise: ErrorModel::new(sim.seed),
            next_index: 0,
            missed: 0,
            fix_override: None,
            offset_m: (0.0, 0.0),
        })
    }

    pub fn config(&self) -> &GpsConfig {
        &self.config
    }

    /// The world frame's geodesy.
    pub fn frame(&self) -> &LocalFrame {
        &self.frame
    }

    /// The UTC clock (scenario epoch + sim time).
    pub fn clock(&self) -> &UtcClock {
        &self.clock
    }

    /// Sim time of epoch `index`.
    pub fn epoch_time(&self, index: u64) -> f64 {
        index as f64 / self.config.rate_hz
    }

    /// Sim time of the next epoch to be produced.
    pub fn next_epoch_time(&self) -> f64 {
        self.epoch_time(self.next_index)
    }

    /// Force the fix kind the receiver reports (`None`: the configured one again).
    pub fn set_fix_override(&mut self, fix: Option<FixKind>) {
        self.fix_override = fix;
    }

    /// Offset the reported position by `east_m`, `north_m` (zero: none).
    pub fn set_position_offset(&mut self, east_m: f64, north_m: f64) {
        self.offset_m = (east_m, north_m);
    }

    /// Epochs skipped because `poll` was called too rarely.
    pub fn missed_epochs(&self) -> u64 {
        self.missed
    }

    /// The antenna's true state for a vehicle state.
    pub fn antenna(&self, s: &VehicleState) -> AntennaTruth {
        let c = &self.config;
        let (cos, sin) = (s.theta.cos(), s.theta.sin());
        let (ax, ay) = (c.antenna_x, c.antenna_y);
        let east = s.x + ax * cos - ay * sin;
        let north = s.y + ax * sin + ay * cos;
        let omega = s.v * s.phi.tan() / self.wheelbase_m;
        let v_east = s.v * cos - omega * (ax * sin + ay * cos);
        let v_north = s.v * sin + omega * (ax * cos - ay * sin);
        let enu = Enu {
            east_m: east,
            north_m: north,
            up_m: c.antenna_z,
        };
        let mut geodetic = self.frame.to_geodetic(enu);
        geodetic.height_m = self.datum_altitude_m + c.antenna_z;
        AntennaTruth {
            enu,
            geodetic,
            v_east_mps: v_east,
            v_north_mps: v_north,
            speed_mps: v_east.hypot(v_north),
            course_deg: course_of_velocity_deg(v_east, v_north),
            heading_deg: theta_to_course_deg(s.theta),
        }
    }

    /// The epoch due by sim time `now`, if one is: the latest epoch time at or
    /// before `now` not yet produced (earlier ones skipped are counted in
    /// [`Self::missed_epochs`]). `vehicle` is the state at `now`; it is moved back
    /// to the epoch time with its speed and steering held.
    pub fn poll(&mut self, now: f64, vehicle: &VehicleState) -> Result<Option<GpsEpoch>, GpsError> {
        if !now.is_finite() {
            return Err(GpsError::Time(now));
        }
        if now + EPS_S < self.next_epoch_time() {
            return Ok(None);
        }
        // now >= 0 here; the float-to-int conversion saturates.
        let due = ((now + EPS_S) * self.config.rate_hz).floor() as u64;
        let index = due.max(self.next_index);
        self.missed += index - self.next_index;
        self.next_index = index.saturating_add(1);
        let t = self.epoch_time(index);
        let mut at_epoch = *vehicle;
        let back = t - now;
        if back != 0.0 {
            at_epoch.step(self.wheelbase_m, vehicle.v, vehicle.phi, back);
            at_epoch.odometer = vehicle.odometer;
        }
        self.epoch(index, t, &at_epoch).map(Some)
    }

    fn epoch(&mut self, index: u64, t: f64, s: &VehicleState) -> Result<GpsEpoch, GpsError> {
        let c = &self.config;
        let truth = self.antenna(s);
        let fix_kind = self.fix_override.unwrap_or_else(|| c.fix_at(t));
        let model = c.model(fix_kind);
        let error = self.noise.epoch(t, model.as_ref(), c.heading_sigma_deg);
        let fix = match model {
            None => GpsFix {
                geoid_separation_m: c.geoid_separation_m,
                ..GpsFix::default()
            },
            Some(m) => {
                let up = c.antenna_z + error.up_m;
                let mut g = self.frame.to_geodetic(Enu {
                    east_m: truth.enu.east_m + error.east_m + self.offset_m.0,
                    north_m: truth.enu.north_m + error.north_m + self.offset_m.1,
                    up_m: up,
                });
                g.height_m = self.datum_altitude_m + up;
                let (ve, vn) = (
                    truth.v_east_mps + error.v_east_mps,
                    truth.v_north_mps + error.v_north_mps,
                );
                let (h, v) = (m.horizontal_sigma_m, m.vertical_sigma_m);
                let corrections = fix_kind.uses_corrections();
                GpsFix {
                    lat_deg: g.lat_deg,
                    lon_deg: g.lon_deg,
                    ellipsoid_height_m: g.height_m,
                    geoid_separation_m: c.geoid_separation_m,
                    quality: fix_kind.quality(),
                    satellites: m.satellites,
                    hdop: m.hdop,
                    speed_mps: ve.hypot(vn),
                    course_deg: course_of_velocity_deg(ve, vn),
                    heading_deg: c
                        .dual_antenna
                        .then(|| normalize_deg_360(truth.heading_deg + error.heading_deg)),
                    accuracy: Some(Accuracy {
                        rms_m: ((2.0 * h * h + v * v) / 3.0).sqrt(),
                        semi_major_m: h,
                        semi_minor_m: h,
                        orientation_deg: 0.0,
                        lat_sigma_m: h,
                        lon_sigma_m: h,
                        alt_sigma_m: v,
                    }),
                    correction_age_s: corrections.then_some(c.correction_age_s),
                    station_id: corrections.then_some(c.station_id),
                    ..GpsFix::default()
                }
            }
        };
        let sim_time = Duration::try_from_secs_f64(t).map_err(|_| GpsError::Time(t))?;
        let utc = self.clock.at(sim_time)?;
        let mut text = String::new();
        let sentences = self.writer.write_epoch(&fix, utc, &mut text)?;
        Ok(GpsEpoch {
            index,
            time_s: t,
            utc,
            fix_kind,
            fix,
            truth,
            error,
            sentences,
            text,
        })
    }
}
