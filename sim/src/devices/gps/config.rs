//! `[gps]`: the receiver's configuration, with defaults and validation.

use firmware_bridge::nmea::{
    FixQuality, NmeaError, Schedule, SentenceKind, SentenceSet, Talker, WriterConfig, link_budget,
};
use serde::{Deserialize, Serialize};

use super::super::{FieldError, invalid};

/// Slowest and fastest epoch rates, Hz (what RTK receivers offer): the controller's
/// `safety.gps_rate_hz` range.
pub const RATE_RANGE_HZ: (f64, f64) = (
    ugv_controller::ranges::GPS_RATE.lo,
    ugv_controller::ranges::GPS_RATE.hi,
);
/// Serial rates accepted, baud (8N1).
pub const BAUD_RANGE: (u32, u32) = (1200, 4_000_000);

/// A fix state the receiver can be in (`fix = "rtk"` in TOML).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FixKind {
    /// RTK with fixed ambiguities (GGA quality 4).
    #[default]
    Rtk,
    /// RTK float (GGA quality 5).
    Float,
    /// Autonomous single-point fix (GGA quality 1).
    Single,
    /// No fix (GGA quality 0): empty position fields.
    None,
}

impl FixKind {
    /// The GGA fix quality.
    pub fn quality(self) -> FixQuality {
        match self {
            FixKind::Rtk => FixQuality::RtkFixed,
            FixKind::Float => FixQuality::RtkFloat,
            FixKind::Single => FixQuality::Single,
            FixKind::None => FixQuality::Invalid,
        }
    }

    /// Whether RTK corrections are in use (GGA carries their age and station).
    pub fn uses_corrections(self) -> bool {
        matches!(self, FixKind::Rtk | FixKind::Float)
    }
}

/// A change of fix state during a run (`[[gps.events]] at_s = 20.0, fix = "float"`):
/// from `at_s` on (inclusive) the receiver reports `fix`, until the next event.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixEvent {
    /// Simulation time, seconds.
    pub at_s: f64,
    pub fix: FixKind,
}

/// Which sentence carries the dual-antenna heading.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadingSentence {
    /// `$--HDT` (true heading).
    #[default]
    Hdt,
    /// `$--THS` (true heading and status, NMEA 3.0+).
    Ths,
    /// No heading sentence.
    None,
}

/// The sentences of each epoch (`[gps.sentences]`); all go out every epoch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Sentences {
    pub gga: bool,
    pub rmc: bool,
    pub vtg: bool,
    pub gst: bool,
    pub zda: bool,
    /// Sent only when `dual_antenna` is on.
    pub heading: HeadingSentence,
}

impl Default for Sentences {
    /// GGA, RMC, VTG, GST, HDT and ZDA.
    fn default() -> Self {
        Sentences {
            gga: true,
            rmc: true,
            vtg: true,
            gst: true,
            zda: true,
            heading: HeadingSentence::Hdt,
        }
    }
}

/// The error model and the constellation figures of one fix state (`[gps.rtk]`,
/// `[gps.float]`, `[gps.single]`), each with its own defaults.
///
/// Position error per axis (east, north, up) is the sum of a first-order
/// Gauss-Markov process (variance `(1 - white_fraction) sigma^2`, time constant
/// `time_constant_s`: the slowly wandering multipath, atmosphere and
/// ambiguity-related error) and white noise (variance `white_fraction sigma^2`:
/// receiver noise). So `horizontal_sigma_m` and `vertical_sigma_m` are the total 1-sigma
/// errors, and GST reports exactly them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixModel {
    /// 1-sigma error of each horizontal axis (east, north), metres.
    pub horizontal_sigma_m: f64,
    /// 1-sigma vertical error, metres (receivers: about twice the horizontal).
    pub vertical_sigma_m: f64,
    /// Correlation time of the Gauss-Markov part, seconds.
    pub time_constant_s: f64,
    /// Share of the variance that is white (epoch to epoch), 0-1.
    pub white_fraction: f64,
    /// 1-sigma white error of each horizontal velocity axis, m/s (Doppler).
    pub velocity_sigma_mps: f64,
    /// Satellites used (GGA).
    pub satellites: u8,
    /// Horizontal dilution of precision (GGA).
    pub hdop: f64,
}

macro_rules! fix_model_table {
    ($(#[$doc:meta])* $name:ident, $default:expr) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct $name {
            /// 1-sigma error of each horizontal axis (east, north), metres.
            pub horizontal_sigma_m: f64,
            /// 1-sigma vertical error, metres.
            pub vertical_sigma_m: f64,
            /// Correlation time of the Gauss-Markov part, seconds.
            pub time_constant_s: f64,
            /// Share of the variance that is white (epoch to epoch), 0-1.
            pub white_fraction: f64,
            /// 1-sigma white error of each horizontal velocity axis, m/s.
            pub velocity_sigma_mps: f64,
            /// Satellites used (GGA), 0-99.
            pub satellites: u8,
            /// Horizontal dilution of precision (GGA), (0, 99.99].
            pub hdop: f64,
        }

        impl Default for $name {
            fn default() -> Self {
                let m: FixModel = $default;
                $name {
                    horizontal_sigma_m: m.horizontal_sigma_m,
                    vertical_sigma_m: m.vertical_sigma_m,
                    time_constant_s: m.time_constant_s,
                    white_fraction: m.white_fraction,
                    velocity_sigma_mps: m.velocity_sigma_mps,
                    satellites: m.satellites,
                    hdop: m.hdop,
                }
            }
        }

        impl $name {
            /// The model as the device uses it.
            pub fn model(&self) -> FixModel {
                FixModel {
                    horizontal_sigma_m: self.horizontal_sigma_m,
                    vertical_sigma_m: self.vertical_sigma_m,
                    time_constant_s: self.time_constant_s,
                    white_fraction: self.white_fraction,
                    velocity_sigma_mps: self.velocity_sigma_mps,
                    satellites: self.satellites,
                    hdop: self.hdop,
                }
            }
        }
    };
}

fix_model_table!(
    /// `[gps.rtk]`: RTK fixed, 1.5 cm horizontal and 3 cm vertical (1-sigma), wandering
    /// over 30 s, 20 satellites, HDOP 0.6.
    RtkModel,
    FixModel {
        horizontal_sigma_m: 0.015,
        vertical_sigma_m: 0.03,
        time_constant_s: 30.0,
        white_fraction: 0.2,
        velocity_sigma_mps: 0.02,
        satellites: 20,
        hdop: 0.6,
    }
);

fix_model_table!(
    /// `[gps.float]`: RTK float, 0.25 m horizontal and 0.5 m vertical, over 60 s,
    /// 16 satellites, HDOP 0.8.
    FloatModel,
    FixModel {
        horizontal_sigma_m: 0.25,
        vertical_sigma_m: 0.5,
        time_constant_s: 60.0,
        white_fraction: 0.1,
        velocity_sigma_mps: 0.03,
        satellites: 16,
        hdop: 0.8,
    }
);

fix_model_table!(
    /// `[gps.single]`: autonomous, 1.5 m horizontal and 3 m vertical, over 120 s,
    /// 12 satellites, HDOP 1.1.
    SingleModel,
    FixModel {
        horizontal_sigma_m: 1.5,
        vertical_sigma_m: 3.0,
        time_constant_s: 120.0,
        white_fraction: 0.05,
        velocity_sigma_mps: 0.05,
        satellites: 12,
        hdop: 1.1,
    }
);

/// The GPS receiver's configuration (`[gps]` in a scenario). Every field has a
/// default: a dual-antenna RTK receiver at 10 Hz on a 115200-baud line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpsConfig {
    /// Antenna position in the vehicle frame (x forward, y left of the rear axle), metres.
    pub antenna_x: f64,
    pub antenna_y: f64,
    /// Antenna height above ground, metres.
    pub antenna_z: f64,
    /// Epochs per second, 1-20; epochs fall on multiples of 1/rate_hz of sim time.
    pub rate_hz: f64,
    /// Serial line rate the output is paced at (8N1); must carry an epoch per period.
    pub baud: u32,
    /// NMEA talker ("GN" multi-constellation, "GP" GPS only, ...).
    pub talker: Talker,
    pub sentences: Sentences,
    /// Dual-antenna heading (HDT/THS) along the vehicle's x axis.
    pub dual_antenna: bool,
    /// 1-sigma white heading error, degrees (about 0.1 deg for a 1 m baseline).
    pub heading_sigma_deg: f64,
    /// Fix state at t = 0 (and until the first event).
    pub fix: FixKind,
    /// Changes of fix state during the run, in time order.
    pub events: Vec<FixEvent>,
    pub rtk: RtkModel,
    pub float: FloatModel,
    pub single: SingleModel,
    /// Age of differential corrections in GGA with an RTK fix (fixed or float), seconds.
    pub correction_age_s: f64,
    /// Reference station ID in GGA with an RTK fix, 0-1023.
    pub station_id: u16,
    /// Geoid height above the ellipsoid at the datum (GGA field 11), metres; GGA's
    /// altitude is the ellipsoidal height minus it. 0 puts mean sea level on the ellipsoid.
    pub geoid_separation_m: f64,
}

impl Default for GpsConfig {
    fn default() -> Self {
        let car = ugv_controller::car::PAPER_CAR;
        GpsConfig {
            antenna_x: car.antenna[0],
            antenna_y: car.antenna[1],
            antenna_z: 1.8,
            rate_hz: 10.0,
            baud: 115_200,
            talker: Talker::GN,
            sentences: Sentences::default(),
            dual_antenna: true,
            heading_sigma_deg: 0.1,
            fix: FixKind::Rtk,
            events: Vec::new(),
            rtk: RtkModel::default(),
            float: FloatModel::default(),
            single: SingleModel::default(),
            correction_age_s: 1.0,
            station_id: 0,
            geoid_separation_m: 0.0,
        }
    }
}

impl GpsConfig {
    /// Every field checked: the physical ones within their ranges (the tables
    /// [`crate::scenario::ranges::GPS`] and [`crate::scenario::ranges::FIX_MODEL`],
    /// each range with its source), the events in time order, and a rate the baud
    /// cannot carry refused with the numbers.
    pub fn validate(&self) -> Result<(), FieldError> {
        use crate::scenario::ranges::{FIX_MODEL, GPS};
        ugv_fields::check_bounds(self, GPS)?;
        for (key, model) in [
            ("rtk", self.rtk.model()),
            ("float", self.float.model()),
            ("single", self.single.model()),
        ] {
            ugv_fields::check_bounds(&model, FIX_MODEL)
                .map_err(|e| e.under(&ugv_fields::FieldPath::of(&[key])))?;
        }
        let (lo, hi) = BAUD_RANGE;
        if !(lo..=hi).contains(&self.baud) {
            return Err(invalid(
                "baud",
                format!("must be within [{lo}, {hi}], is {}", self.baud),
            ));
        }
        let s = &self.sentences;
        if !(s.gga || s.rmc) {
            return Err(invalid(
                "sentences",
                "neither GGA nor RMC is enabled: no sentence would carry the position",
            ));
        }
        let mut last = f64::NEG_INFINITY;
        for (i, e) in self.events.iter().enumerate() {
            if !(e.at_s.is_finite() && e.at_s >= 0.0) {
                return Err(invalid(
                    "events",
                    format!("events[{i}].at_s must be a finite time >= 0, is {}", e.at_s),
                ));
            }
            if e.at_s < last {
                return Err(invalid(
                    "events",
                    format!(
                        "events[{i}].at_s = {} is before events[{}].at_s = {last}: list events in time order",
                        e.at_s,
                        i - 1
                    ),
                ));
            }
            last = e.at_s;
        }
        if self.station_id > 1023 {
            return Err(invalid(
                "station_id",
                format!("must be within [0, 1023], is {}", self.station_id),
            ));
        }
        link_budget(&self.writer_config()).map_err(|e| match e {
            NmeaError::BaudTooLow { .. } => invalid(
                "baud",
                format!("{} baud cannot carry {} Hz: {e}", self.baud, self.rate_hz),
            ),
            other => invalid("rate_hz", other.to_string()),
        })?;
        Ok(())
    }

    /// The sentences that go out every epoch (the heading sentence only with
    /// `dual_antenna`): what a reader's `complete_when` should be.
    pub fn sentence_set(&self) -> SentenceSet {
        let s = &self.sentences;
        let mut set = SentenceSet::EMPTY;
        for (on, kind) in [
            (s.gga, SentenceKind::Gga),
            (s.rmc, SentenceKind::Rmc),
            (s.vtg, SentenceKind::Vtg),
            (s.gst, SentenceKind::Gst),
            (s.zda, SentenceKind::Zda),
            (
                self.dual_antenna && s.heading == HeadingSentence::Hdt,
                SentenceKind::Hdt,
            ),
            (
                self.dual_antenna && s.heading == HeadingSentence::Ths,
                SentenceKind::Ths,
            ),
        ] {
            if on {
                set.insert(kind);
            }
        }
        set
    }

    /// The NMEA writer's configuration.
    pub fn writer_config(&self) -> WriterConfig {
        WriterConfig {
            talker: self.talker,
            rate_hz: self.rate_hz,
            baud: self.baud,
            schedule: Schedule::every_epoch(self.sentence_set()),
            ..WriterConfig::default()
        }
    }

    /// The fix state at sim time `t`: the last event at or before `t`, else `fix`.
    pub fn fix_at(&self, t: f64) -> FixKind {
        self.events
            .iter()
            .take_while(|e| e.at_s <= t)
            .last()
            .map_or(self.fix, |e| e.fix)
    }

    /// The error model of a fix state (`None` for no fix).
    pub fn model(&self, fix: FixKind) -> Option<FixModel> {
        match fix {
            FixKind::Rtk => Some(self.rtk.model()),
            FixKind::Float => Some(self.float.model()),
            FixKind::Single => Some(self.single.model()),
            FixKind::None => None,
        }
    }
}
