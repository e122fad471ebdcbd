//! The typed vocabulary of the GPS wire: fix quality, mode indicators, talkers,
//! sentence kinds and sets, and the fix the simulator writes.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::NmeaError;

/// GGA fix quality (field 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FixQuality {
    /// 0: no fix.
    Invalid,
    /// 1: autonomous single-point fix.
    Single,
    /// 2: differential (DGPS/SBAS).
    Dgps,
    /// 3: PPS.
    Pps,
    /// 4: RTK with fixed integer ambiguities.
    RtkFixed,
    /// 5: RTK float.
    RtkFloat,
    /// 6: estimated (dead reckoning).
    Estimated,
    /// 7: manual input.
    Manual,
    /// 8: simulator.
    Simulator,
}

impl FixQuality {
    /// The GGA digit.
    pub fn gga_digit(self) -> u8 {
        match self {
            Self::Invalid => 0,
            Self::Single => 1,
            Self::Dgps => 2,
            Self::Pps => 3,
            Self::RtkFixed => 4,
            Self::RtkFloat => 5,
            Self::Estimated => 6,
            Self::Manual => 7,
            Self::Simulator => 8,
        }
    }

    /// From the GGA digit.
    pub fn from_gga_digit(d: u8) -> Option<Self> {
        Some(match d {
            0 => Self::Invalid,
            1 => Self::Single,
            2 => Self::Dgps,
            3 => Self::Pps,
            4 => Self::RtkFixed,
            5 => Self::RtkFloat,
            6 => Self::Estimated,
            7 => Self::Manual,
            8 => Self::Simulator,
            _ => return None,
        })
    }

    /// Whether the fix carries a position.
    pub fn has_position(self) -> bool {
        self != Self::Invalid
    }

    /// The NMEA 4.x mode indicator that goes with this quality (RMC, VTG).
    pub fn mode(self) -> PositioningMode {
        match self {
            Self::Invalid => PositioningMode::NotValid,
            Self::Single => PositioningMode::Autonomous,
            Self::Dgps => PositioningMode::Differential,
            Self::Pps => PositioningMode::Precise,
            Self::RtkFixed => PositioningMode::RtkFixed,
            Self::RtkFloat => PositioningMode::RtkFloat,
            Self::Estimated => PositioningMode::Estimated,
            Self::Manual => PositioningMode::Manual,
            Self::Simulator => PositioningMode::Simulator,
        }
    }
}

/// NMEA 2.3+/4.x positioning mode indicator (RMC field 12, VTG field 9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PositioningMode {
    /// A
    Autonomous,
    /// D
    Differential,
    /// E
    Estimated,
    /// F
    RtkFloat,
    /// M
    Manual,
    /// N
    NotValid,
    /// P
    Precise,
    /// R
    RtkFixed,
    /// S
    Simulator,
}

impl PositioningMode {
    pub fn as_char(self) -> char {
        match self {
            Self::Autonomous => 'A',
            Self::Differential => 'D',
            Self::Estimated => 'E',
            Self::RtkFloat => 'F',
            Self::Manual => 'M',
            Self::NotValid => 'N',
            Self::Precise => 'P',
            Self::RtkFixed => 'R',
            Self::Simulator => 'S',
        }
    }

    pub fn from_char(c: char) -> Option<Self> {
        Some(match c {
            'A' => Self::Autonomous,
            'D' => Self::Differential,
            'E' => Self::Estimated,
            'F' => Self::RtkFloat,
            'M' => Self::Manual,
            'N' => Self::NotValid,
            'P' => Self::Precise,
            'R' => Self::RtkFixed,
            'S' => Self::Simulator,
            _ => return None,
        })
    }

    /// The fix quality a mode indicator implies (used when an epoch has no GGA).
    pub fn quality(self) -> FixQuality {
        match self {
            Self::Autonomous => FixQuality::Single,
            Self::Differential => FixQuality::Dgps,
            Self::Estimated => FixQuality::Estimated,
            Self::RtkFloat => FixQuality::RtkFloat,
            Self::Manual => FixQuality::Manual,
            Self::NotValid => FixQuality::Invalid,
            Self::Precise => FixQuality::Pps,
            Self::RtkFixed => FixQuality::RtkFixed,
            Self::Simulator => FixQuality::Simulator,
        }
    }
}

/// NMEA 4.1 navigational status (RMC field 13).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NavStatus {
    /// S
    Safe,
    /// C
    Caution,
    /// U
    Unsafe,
    /// V: not valid, or the equipment gives no status (what most receivers send).
    #[default]
    NotValid,
}

impl NavStatus {
    pub fn as_char(self) -> char {
        match self {
            Self::Safe => 'S',
            Self::Caution => 'C',
            Self::Unsafe => 'U',
            Self::NotValid => 'V',
        }
    }

    pub fn from_char(c: char) -> Option<Self> {
        Some(match c {
            'S' => Self::Safe,
            'C' => Self::Caution,
            'U' => Self::Unsafe,
            'V' => Self::NotValid,
            _ => return None,
        })
    }
}

/// THS mode indicator (field 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadingMode {
    /// A
    Autonomous,
    /// E
    Estimated,
    /// M
    Manual,
    /// S
    Simulator,
    /// V
    NotValid,
}

impl HeadingMode {
    pub fn as_char(self) -> char {
        match self {
            Self::Autonomous => 'A',
            Self::Estimated => 'E',
            Self::Manual => 'M',
            Self::Simulator => 'S',
            Self::NotValid => 'V',
        }
    }

    pub fn from_char(c: char) -> Option<Self> {
        Some(match c {
            'A' => Self::Autonomous,
            'E' => Self::Estimated,
            'M' => Self::Manual,
            'S' => Self::Simulator,
            'V' => Self::NotValid,
            _ => return None,
        })
    }
}

/// A two-character NMEA talker ID ("GP", "GN", "GL", "GA", "GB", ...).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Talker([u8; 2]);

impl Talker {
    /// GPS.
    pub const GP: Self = Self(*b"GP");
    /// Multi-constellation GNSS.
    pub const GN: Self = Self(*b"GN");
    /// GLONASS.
    pub const GL: Self = Self(*b"GL");
    /// Galileo.
    pub const GA: Self = Self(*b"GA");
    /// BeiDou.
    pub const GB: Self = Self(*b"GB");

    /// Two ASCII upper-case letters or digits, not starting with 'P' (proprietary).
    pub fn new(s: &str) -> Result<Self, NmeaError> {
        let b = s.as_bytes();
        let ok = b.len() == 2
            && b[0] != b'P'
            && b.iter()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit());
        if ok {
            Ok(Self([b[0], b[1]]))
        } else {
            Err(NmeaError::InvalidTalker {
                talker: s.to_owned(),
            })
        }
    }

    pub fn as_str(&self) -> &str {
        // Both bytes are ASCII by construction.
        std::str::from_utf8(&self.0).unwrap_or("??")
    }
}

impl Default for Talker {
    fn default() -> Self {
        Self::GN
    }
}

impl fmt::Debug for Talker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Talker({})", self.as_str())
    }
}

impl fmt::Display for Talker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl TryFrom<String> for Talker {
    type Error = NmeaError;
    fn try_from(s: String) -> Result<Self, NmeaError> {
        Self::new(&s)
    }
}

impl From<Talker> for String {
    fn from(t: Talker) -> String {
        t.as_str().to_owned()
    }
}

/// The sentences this crate writes and reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum SentenceKind {
    Gga,
    Rmc,
    Vtg,
    Gst,
    Hdt,
    Ths,
    Zda,
}

impl SentenceKind {
    /// All kinds, in the order the writer emits them within an epoch.
    pub const ALL: [SentenceKind; 7] = [
        Self::Gga,
        Self::Rmc,
        Self::Vtg,
        Self::Gst,
        Self::Hdt,
        Self::Ths,
        Self::Zda,
    ];

    /// The three-letter formatter.
    pub fn formatter(self) -> &'static str {
        match self {
            Self::Gga => "GGA",
            Self::Rmc => "RMC",
            Self::Vtg => "VTG",
            Self::Gst => "GST",
            Self::Hdt => "HDT",
            Self::Ths => "THS",
            Self::Zda => "ZDA",
        }
    }

    pub fn from_formatter(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.formatter() == s)
    }

    /// Whether the sentence carries a UTC time of day (used to group epochs).
    pub fn is_timed(self) -> bool {
        matches!(self, Self::Gga | Self::Rmc | Self::Gst | Self::Zda)
    }

    fn bit(self) -> u8 {
        1 << (self as u8)
    }
}

impl fmt::Display for SentenceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.formatter())
    }
}

/// A set of [`SentenceKind`]s (serialised as a list such as `["GGA", "RMC"]`).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(from = "Vec<SentenceKind>", into = "Vec<SentenceKind>")]
pub struct SentenceSet(u8);

impl SentenceSet {
    pub const EMPTY: Self = Self(0);

    pub fn of(kinds: &[SentenceKind]) -> Self {
        kinds.iter().fold(Self::EMPTY, |s, k| s.with(*k))
    }

    #[must_use]
    pub fn with(self, k: SentenceKind) -> Self {
        Self(self.0 | k.bit())
    }

    pub fn insert(&mut self, k: SentenceKind) {
        self.0 |= k.bit();
    }

    pub fn contains(self, k: SentenceKind) -> bool {
        self.0 & k.bit() != 0
    }

    /// Whether every kind of `other` is in `self`.
    pub fn is_superset(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    pub fn iter(self) -> impl Iterator<Item = SentenceKind> {
        SentenceKind::ALL
            .into_iter()
            .filter(move |k| self.contains(*k))
    }
}

impl fmt::Debug for SentenceSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set().entries(self.iter()).finish()
    }
}

impl From<Vec<SentenceKind>> for SentenceSet {
    fn from(v: Vec<SentenceKind>) -> Self {
        Self::of(&v)
    }
}

impl From<SentenceSet> for Vec<SentenceKind> {
    fn from(s: SentenceSet) -> Self {
        s.iter().collect()
    }
}

/// GST error statistics, metres and degrees (1-sigma).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// RMS of the standard deviation of the range inputs, metres.
    pub rms_m: f64,
    /// Error ellipse semi-major axis, metres.
    pub semi_major_m: f64,
    /// Error ellipse semi-minor axis, metres.
    pub semi_minor_m: f64,
    /// Orientation of the semi-major axis, degrees clockwise from true North.
    pub orientation_deg: f64,
    /// Latitude error, metres.
    pub lat_sigma_m: f64,
    /// Longitude error, metres.
    pub lon_sigma_m: f64,
    /// Height error, metres.
    pub alt_sigma_m: f64,
}

/// One receiver epoch as the simulator knows it: what the writer turns into sentences.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GpsFix {
    /// WGS-84 latitude, degrees.
    pub lat_deg: f64,
    /// WGS-84 longitude, degrees.
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid, metres (what [`crate::geodesy`] gives).
    /// GGA carries `height - geoid_separation` (mean sea level) and the separation.
    pub ellipsoid_height_m: f64,
    /// Geoid height above the ellipsoid (GGA field 11), metres.
    pub geoid_separation_m: f64,
    pub quality: FixQuality,
    /// Satellites used, 0-99.
    pub satellites: u8,
    pub hdop: f64,
    /// Speed over ground, m/s.
    pub speed_mps: f64,
    /// Course over ground, degrees clockwise from true North.
    pub course_deg: f64,
    /// Dual-antenna true heading, degrees clockwise from true North (HDT, THS).
    pub heading_deg: Option<f64>,
    /// GST statistics.
    pub accuracy: Option<Accuracy>,
    /// Age of differential corrections, seconds (GGA field 13).
    pub correction_age_s: Option<f64>,
    /// Differential reference station ID, 0-1023 (GGA field 14).
    pub station_id: Option<u16>,
    /// RMC navigational status.
    pub nav_status: NavStatus,
}

impl GpsFix {
    /// Height above mean sea level (GGA field 9), metres.
    pub fn altitude_msl_m(&self) -> f64 {
        self.ellipsoid_height_m - self.geoid_separation_m
    }
}

impl Default for GpsFix {
    fn default() -> Self {
        Self {
            lat_deg: 0.0,
            lon_deg: 0.0,
            ellipsoid_height_m: 0.0,
            geoid_separation_m: 0.0,
            quality: FixQuality::Invalid,
            satellites: 0,
            hdop: 99.99,
            speed_mps: 0.0,
            course_deg: 0.0,
            heading_deg: None,
            accuracy: None,
            correction_age_s: None,
            station_id: None,
            nav_status: NavStatus::NotValid,
        }
    }
}
