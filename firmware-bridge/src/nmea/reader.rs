//! The controller side: bytes to typed GPS readings, one per receiver epoch.

use std::collections::VecDeque;
use std::collections::vec_deque::Drain;

use chrono::{NaiveDate, NaiveDateTime, NaiveTime};
use nmea::sentences::FixType;
use serde::{Deserialize, Serialize};

use super::SentenceError;
use super::framing::{Framed, LineFramer, MAX_SENTENCE_LEN, checksum};
use super::types::{
    Accuracy, FixQuality, HeadingMode, NavStatus, PositioningMode, SentenceKind, SentenceSet,
    Talker,
};
use super::writer::{KNOTS_PER_MPS, Schedule};
use crate::geodesy::{Enu, Geodetic, LocalFrame};

/// Reader configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReaderConfig {
    /// An epoch is emitted as soon as all of these kinds arrived for it (set it to
    /// what the receiver sends every epoch); otherwise when the next epoch starts.
    pub complete_when: SentenceSet,
    /// Longest accepted sentence, `$` through checksum.
    pub max_line_len: usize,
}

impl Default for ReaderConfig {
    /// Complete on what the default writer sends; the nmea crate's length limit.
    fn default() -> Self {
        Self {
            complete_when: Schedule::default().enabled(),
            max_line_len: MAX_SENTENCE_LEN,
        }
    }
}

/// One receiver epoch as the controller sees it. Fields are `None` when no sentence
/// of the epoch carried them (or carried them empty).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct GpsReading {
    /// Talker of the first sentence of the epoch.
    pub talker: Option<Talker>,
    /// UTC time of day (GGA, RMC, GST or ZDA).
    pub time: Option<NaiveTime>,
    /// UTC date (ZDA, else RMC).
    pub date: Option<NaiveDate>,
    /// GGA quality; without GGA, from the RMC or VTG mode indicator or RMC status.
    pub quality: Option<FixQuality>,
    /// WGS-84 latitude, degrees (GGA, else RMC).
    pub lat_deg: Option<f64>,
    /// WGS-84 longitude, degrees (GGA, else RMC).
    pub lon_deg: Option<f64>,
    /// Height above mean sea level, metres (GGA).
    pub altitude_msl_m: Option<f64>,
    /// Geoid height above the ellipsoid, metres (GGA).
    pub geoid_separation_m: Option<f64>,
    pub satellites: Option<u8>,
    pub hdop: Option<f64>,
    /// Age of differential corrections, seconds (GGA).
    pub correction_age_s: Option<f64>,
    /// Differential station (GGA).
    pub station_id: Option<u16>,
    /// Speed over ground, m/s (RMC, else VTG).
    pub speed_mps: Option<f64>,
    /// Course over ground, degrees clockwise from true North (RMC, else VTG).
    pub course_deg: Option<f64>,
    /// Mode indicator (RMC, else VTG).
    pub mode: Option<PositioningMode>,
    /// RMC navigational status.
    pub nav_status: Option<NavStatus>,
    /// True heading, degrees clockwise from North (THS unless its mode is V, else HDT).
    pub heading_deg: Option<f64>,
    /// THS mode.
    pub heading_mode: Option<HeadingMode>,
    /// GST statistics (when all seven fields are present).
    pub accuracy: Option<Accuracy>,
    /// The kinds that made up this reading.
    pub sentences: SentenceSet,
}

impl GpsReading {
    /// UTC date and time, when both are known.
    pub fn utc(&self) -> Option<NaiveDateTime> {
        Some(NaiveDateTime::new(self.date?, self.time?))
    }

    /// Height above the WGS-84 ellipsoid, metres.
    pub fn ellipsoid_height_m(&self) -> Option<f64> {
        Some(self.altitude_msl_m? + self.geoid_separation_m?)
    }

    /// The position, when latitude, longitude and height are all known.
    pub fn geodetic(&self) -> Option<Geodetic> {
        Some(Geodetic {
            lat_deg: self.lat_deg?,
            lon_deg: self.lon_deg?,
            height_m: self.ellipsoid_height_m()?,
        })
    }

    /// The position in a local world frame.
    pub fn enu(&self, frame: &LocalFrame) -> Option<Enu> {
        Some(frame.to_enu(self.geodetic()?))
    }
}

/// What the reader yields.
#[derive(Debug, Clone, PartialEq)]
pub enum ReadEvent {
    /// A complete epoch.
    Fix(GpsReading),
    /// Bad input (also counted in [`ReaderStats`]).
    Error(SentenceError),
}

/// Counters of a reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ReaderStats {
    pub bytes: u64,
    /// Sentences decoded and merged into an epoch.
    pub sentences: u64,
    /// Readings emitted.
    pub fixes: u64,
    pub garbage_bytes: u64,
    pub truncated: u64,
    pub too_long: u64,
    pub invalid_character: u64,
    pub missing_checksum: u64,
    pub bad_checksum: u64,
    pub bad_address: u64,
    pub unknown_sentence: u64,
    pub malformed: u64,
    /// Timed sentences of an epoch already emitted (dropped).
    pub late: u64,
}

impl ReaderStats {
    /// All error counts together (garbage counted once per run, not per byte).
    pub fn errors(&self) -> u64 {
        self.truncated
            + self.too_long
            + self.invalid_character
            + self.missing_checksum
            + self.bad_checksum
            + self.bad_address
            + self.unknown_sentence
            + self.malformed
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Gga {
    time: Option<NaiveTime>,
    quality: FixQuality,
    lat: Option<f64>,
    lon: Option<f64>,
    alt: Option<f64>,
    geoid: Option<f64>,
    sats: Option<u8>,
    hdop: Option<f64>,
    age: Option<f64>,
    station: Option<u16>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Rmc {
    time: Option<NaiveTime>,
    valid: bool,
    lat: Option<f64>,
    lon: Option<f64>,
    speed_mps: Option<f64>,
    course: Option<f64>,
    date: Option<NaiveDate>,
    mode: Option<PositioningMode>,
    nav: Option<NavStatus>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Vtg {
    course: Option<f64>,
    speed_mps: Option<f64>,
    mode: Option<PositioningMode>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Ths {
    heading: Option<f64>,
    mode: HeadingMode,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Decoded {
    Gga(Gga),
    Rmc(Rmc),
    Vtg(Vtg),
    Gst(Option<NaiveTime>, Option<Accuracy>),
    Hdt(Option<f64>),
    Ths(Ths),
    Zda(Option<NaiveTime>, Option<NaiveDate>),
}

impl Decoded {
    fn kind(&self) -> SentenceKind {
        match self {
            Self::Gga(_) => SentenceKind::Gga,
            Self::Rmc(_) => SentenceKind::Rmc,
            Self::Vtg(_) => SentenceKind::Vtg,
            Self::Gst(..) => SentenceKind::Gst,
            Self::Hdt(_) => SentenceKind::Hdt,
            Self::Ths(_) => SentenceKind::Ths,
            Self::Zda(..) => SentenceKind::Zda,
        }
    }

    fn time(&self) -> Option<NaiveTime> {
        match self {
            Self::Gga(g) => g.time,
            Self::Rmc(r) => r.time,
            Self::Gst(t, _) | Self::Zda(t, _) => *t,
            Self::Vtg(_) | Self::Hdt(_) | Self::Ths(_) => None,
        }
    }
}

/// The sentences of one epoch so far.
#[derive(Debug, Clone, Default)]
struct Epoch {
    talker: Option<Talker>,
    time: Option<NaiveTime>,
    gga: Option<Gga>,
    rmc: Option<Rmc>,
    vtg: Option<Vtg>,
    gst: Option<Option<Accuracy>>,
    hdt: Option<Option<f64>>,
    ths: Option<Ths>,
    zda_date: Option<NaiveDate>,
    seen: SentenceSet,
}

impl Epoch {
    fn merge(&mut self, talker: Talker, d: Decoded) {
        self.talker.get_or_insert(talker);
        self.seen.insert(d.kind());
        if self.time.is_none() {
            self.time = d.time();
        }
        match d {
            Decoded::Gga(g) => self.gga = Some(g),
            Decoded::Rmc(r) => self.rmc = Some(r),
            Decoded::Vtg(v) => self.vtg = Some(v),
            Decoded::Gst(_, a) => self.gst = Some(a),
            Decoded::Hdt(h) => self.hdt = Some(h),
            Decoded::Ths(t) => self.ths = Some(t),
            Decoded::Zda(_, date) => self.zda_date = date,
        }
    }

    fn reading(&self) -> GpsReading {
        let gga = self.gga;
        let rmc = self.rmc;
        let vtg = self.vtg;
        let quality = gga.map(|g| g.quality).or_else(|| {
            rmc.and_then(|r| {
                r.mode.map(PositioningMode::quality).or(Some(if r.valid {
                    FixQuality::Single
                } else {
                    FixQuality::Invalid
                }))
            })
            .or_else(|| vtg.and_then(|v| v.mode).map(PositioningMode::quality))
        });
        let (heading_deg, heading_mode) = match (self.ths, self.hdt) {
            (Some(t), _) if t.mode != HeadingMode::NotValid && t.heading.is_some() => {
                (t.heading, Some(t.mode))
            }
            (t, Some(h)) => (h, t.map(|t| t.mode)),
            (Some(t), None) => (None, Some(t.mode)),
            (None, None) => (None, None),
        };
        GpsReading {
            talker: self.talker,
            time: self.time,
            date: self.zda_date.or_else(|| rmc.and_then(|r| r.date)),
            quality,
            lat_deg: gga.and_then(|g| g.lat).or_else(|| rmc.and_then(|r| r.lat)),
            lon_deg: gga.and_then(|g| g.lon).or_else(|| rmc.and_then(|r| r.lon)),
            altitude_msl_m: gga.and_then(|g| g.alt),
            geoid_separation_m: gga.and_then(|g| g.geoid),
            satellites: gga.and_then(|g| g.sats),
            hdop: gga.and_then(|g| g.hdop),
            correction_age_s: gga.and_then(|g| g.age),
            station_id: gga.and_then(|g| g.station),
            speed_mps: rmc
                .and_then(|r| r.speed_mps)
                .or_else(|| vtg.and_then(|v| v.speed_mps)),
            course_deg: rmc
                .and_then(|r| r.course)
                .or_else(|| vtg.and_then(|v| v.course)),
            mode: rmc
                .and_then(|r| r.mode)
                .or_else(|| vtg.and_then(|v| v.mode)),
            nav_status: rmc.and_then(|r| r.nav),
            heading_deg,
            heading_mode,
            accuracy: self.gst.flatten(),
            sentences: self.seen,
        }
    }
}

/// Bytes in, typed readings out.
///
/// # Epoch rule
///
/// GGA, RMC, GST and ZDA carry the UTC time of day; VTG, HDT and THS do not. The
/// reader collects sentences into the open epoch and emits it as one [`GpsReading`]
/// when
/// 1. every kind of [`ReaderConfig::complete_when`] has arrived for it (no latency
///    when the set matches what the receiver sends), or
/// 2. a timed sentence with a different time arrives (the next epoch has begun), or
/// 3. [`NmeaReader::flush`] is called (end of stream, or a caller's timeout).
///
/// Untimed sentences join the open epoch; if none is open they open one that takes
/// the time of the next timed sentence. A later sentence of a kind already in the
/// epoch replaces it. A timed sentence carrying the time of the epoch just emitted
/// arrived too late: it is counted in [`ReaderStats::late`] and dropped. Epochs are
/// emitted whatever they contain (a reading without GGA or RMC has no position).
///
/// Sentences are decoded individually (never through the nmea crate's merged
/// navigation state, which downgrades an RTK fix to GPS when an RMC follows): GGA,
/// RMC, VTG, GST, HDT and ZDA with `nmea::parse_str`, plus the fields it skips (GGA
/// age and station, the RMC and VTG mode indicators, the RMC navigational status);
/// THS, which the nmea crate does not know, by this module.
#[derive(Debug, Clone)]
pub struct NmeaReader {
    config: ReaderConfig,
    framer: LineFramer,
    framed: Vec<Framed>,
    open: Option<Epoch>,
    last_emitted: Option<NaiveTime>,
    events: VecDeque<ReadEvent>,
    stats: ReaderStats,
}

impl Default for NmeaReader {
    fn default() -> Self {
        Self::new(ReaderConfig::default())
    }
}

impl NmeaReader {
    pub fn new(config: ReaderConfig) -> Self {
        Self {
            config,
            framer: LineFramer::new(config.max_line_len),
            framed: Vec::new(),
            open: None,
            last_emitted: None,
            events: VecDeque::new(),
            stats: ReaderStats::default(),
        }
    }

    pub fn config(&self) -> &ReaderConfig {
        &self.config
    }

    pub fn stats(&self) -> &ReaderStats {
        &self.stats
    }

    /// Feed received bytes (any chunking); returns the events they completed.
    pub fn feed(&mut self, bytes: &[u8]) -> Drain<'_, ReadEvent> {
        self.stats.bytes += bytes.len() as u64;
        self.framed.clear();
        let mut framed = std::mem::take(&mut self.framed);
        self.framer.push(bytes, &mut framed);
        self.process(&mut framed);
        self.framed = framed;
        self.events.drain(..)
    }

    /// Emit the open epoch, if any, without waiting for the next one; report a
    /// partial line as truncated. For the end of a stream, or when the caller has
    /// waited long enough.
    pub fn flush(&mut self) -> Drain<'_, ReadEvent> {
        let mut framed = Vec::new();
        self.framer.finish(&mut framed);
        self.process(&mut framed);
        self.emit_open();
        self.events.drain(..)
    }

    fn process(&mut self, framed: &mut Vec<Framed>) {
        for f in framed.drain(..) {
            match f {
                Framed::Line(line) => match decode_line(&line) {
                    Ok((talker, d)) => self.accept(talker, d),
                    Err(e) => self.error(e),
                },
                Framed::Error(e) => self.error(e),
            }
        }
    }

    fn error(&mut self, e: SentenceError) {
        let s = &mut self.stats;
        match &e {
            SentenceError::Garbage { bytes } => s.garbage_bytes += *bytes as u64,
            SentenceError::Truncated { .. } => s.truncated += 1,
            SentenceError::LineTooLong { .. } => s.too_long += 1,
            SentenceError::InvalidCharacter { .. } => s.invalid_character += 1,
            SentenceError::MissingChecksum { .. } => s.missing_checksum += 1,
            SentenceError::BadChecksum { .. } => s.bad_checksum += 1,
            SentenceError::BadAddress { .. } => s.bad_address += 1,
            SentenceError::UnknownSentence { .. } => s.unknown_sentence += 1,
            SentenceError::MalformedField { .. } => s.malformed += 1,
        }
        tracing::debug!(error = %e, "NMEA input rejected");
        self.events.push_back(ReadEvent::Error(e));
    }

    fn accept(&mut self, talker: Talker, d: Decoded) {
        self.stats.sentences += 1;
        if let Some(t) = d.time() {
            match self.open.as_ref().and_then(|e| e.time) {
                Some(open_t) if open_t != t => self.emit_open(),
                Some(_) => {}
                None => {
                    if self.last_emitted == Some(t) {
                        self.stats.late += 1;
                        tracing::debug!(kind = %d.kind(), time = %t, "late NMEA sentence dropped");
                        return;
                    }
                }
            }
        }
        let epoch = self.open.get_or_insert_with(Epoch::default);
        epoch.merge(talker, d);
        if epoch.seen.is_superset(self.config.complete_when) {
            self.emit_open();
        }
    }

    fn emit_open(&mut self) {
        if let Some(epoch) = self.open.take() {
            self.last_emitted = epoch.time;
            self.stats.fixes += 1;
            self.events.push_back(ReadEvent::Fix(epoch.reading()));
        }
    }
}

/// Decode one framed line (`$` through checksum, no terminator).
fn decode_line(line: &[u8]) -> Result<(Talker, Decoded), SentenceError> {
    if let Some(position) = line.iter().position(|b| !(0x20..0x7f).contains(b)) {
        return Err(SentenceError::InvalidCharacter {
            position,
            byte: line[position],
        });
    }
    // All printable ASCII from here on.
    let text = std::str::from_utf8(line).map_err(|_| SentenceError::InvalidCharacter {
        position: 0,
        byte: 0,
    })?;
    let inner = text.get(1..).unwrap_or("");
    let address = inner.split([',', '*']).next().unwrap_or("");
    let Some((body, sum)) = inner.rsplit_once('*') else {
        return Err(SentenceError::MissingChecksum {
            sentence: clip(address),
        });
    };
    let computed = checksum(body.as_bytes());
    let found = u8::from_str_radix(sum, 16).ok().filter(|_| sum.len() == 2);
    if found != Some(computed) {
        return Err(SentenceError::BadChecksum {
            sentence: clip(address),
            computed,
            found: clip(sum),
        });
    }
    if address.starts_with('P') {
        // Proprietary ($PUBX, $PSTI, ...): nothing this reader decodes.
        return Err(SentenceError::UnknownSentence {
            address: clip(address),
        });
    }
    if address.len() != 5
        || !address
            .bytes()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit())
    {
        return Err(SentenceError::BadAddress {
            address: clip(address),
        });
    }
    let (talker_s, formatter) = address.split_at(2);
    let talker = Talker::new(talker_s).map_err(|_| SentenceError::BadAddress {
        address: clip(address),
    })?;
    let Some(kind) = SentenceKind::from_formatter(formatter) else {
        return Err(SentenceError::UnknownSentence {
            address: clip(address),
        });
    };
    let fields: Vec<&str> = body.split(',').collect();
    let cx = Ctx {
        text,
        address,
        fields: &fields,
    };
    let decoded = match kind {
        SentenceKind::Ths => cx.ths()?,
        _ => cx.with_nmea_crate(kind)?,
    };
    Ok((talker, decoded))
}

fn clip(s: &str) -> String {
    s.chars().take(16).collect()
}

/// One sentence being decoded: its text, address and fields (0 is the address).
struct Ctx<'a> {
    text: &'a str,
    address: &'a str,
    fields: &'a [&'a str],
}

impl Ctx<'_> {
    fn malformed(&self, field: usize, reason: impl Into<String>) -> SentenceError {
        SentenceError::MalformedField {
            sentence: self.address.to_owned(),
            field,
            text: clip(self.fields.get(field).copied().unwrap_or("")),
            reason: reason.into(),
        }
    }

    fn field(&self, i: usize) -> &str {
        self.fields.get(i).copied().unwrap_or("")
    }

    fn opt_f64(&self, i: usize) -> Result<Option<f64>, SentenceError> {
        let f = self.field(i);
        if f.is_empty() {
            return Ok(None);
        }
        match f.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            _ => Err(self.malformed(i, "not a number")),
        }
    }

    /// A number the nmea crate parsed as f32: beyond f32 it comes out infinite (a field
    /// of 40 digits is enough), which the reading must not carry.
    fn finite_f32(&self, i: usize, v: Option<f32>) -> Result<Option<f64>, SentenceError> {
        match v {
            Some(x) if !x.is_finite() => Err(self.malformed(i, "not a finite number")),
            v => Ok(v.map(f64::from)),
        }
    }

    fn opt_char<T>(
        &self,
        i: usize,
        what: &str,
        from: impl Fn(char) -> Option<T>,
    ) -> Result<Option<T>, SentenceError> {
        let f = self.field(i);
        let mut chars = f.chars();
        match (chars.next(), chars.next()) {
            (None, _) => Ok(None),
            (Some(c), None) => from(c)
                .map(Some)
                .ok_or_else(|| self.malformed(i, format!("not a {what}"))),
            _ => Err(self.malformed(i, format!("not a {what}"))),
        }
    }

    fn heading(&self, i: usize) -> Result<Option<f64>, SentenceError> {
        match self.opt_f64(i)? {
            Some(h) if !(0.0..=360.0).contains(&h) => {
                Err(self.malformed(i, "outside 0-360 degrees"))
            }
            h => Ok(h),
        }
    }

    fn lat_lon(
        &self,
        lat_field: usize,
        lat: Option<f64>,
        lon: Option<f64>,
    ) -> Result<(Option<f64>, Option<f64>), SentenceError> {
        if lat.is_some_and(|v| !(-90.0..=90.0).contains(&v)) {
            return Err(self.malformed(lat_field, "latitude beyond 90 degrees"));
        }
        if lon.is_some_and(|v| !(-180.0..=180.0).contains(&v)) {
            return Err(self.malformed(lat_field + 2, "longitude beyond 180 degrees"));
        }
        Ok((lat, lon))
    }

    /// THS: true heading and mode (not in the nmea crate).
    fn ths(&self) -> Result<Decoded, SentenceError> {
        if self.fields.len() < 3 {
            return Err(self.malformed(self.fields.len(), "missing field"));
        }
        let heading = self.heading(1)?;
        let mode = self
            .opt_char(2, "THS mode (A, E, M, S, V)", HeadingMode::from_char)?
            .ok_or_else(|| self.malformed(2, "empty mode"))?;
        Ok(Decoded::Ths(Ths { heading, mode }))
    }

    /// Map an nmea crate error to the field it failed in.
    fn crate_error(&self, e: &nmea::Error<'_>) -> SentenceError {
        match e {
            nmea::Error::ParsingError(nom::Err::Error(inner) | nom::Err::Failure(inner)) => {
                let off = inner
                    .input
                    .as_ptr()
                    .addr()
                    .wrapping_sub(self.text.as_ptr().addr());
                let field = if off <= self.text.len() {
                    self.text.as_bytes()[..off]
                        .iter()
                        .filter(|b| **b == b',')
                        .count()
                } else {
                    0
                };
                self.malformed(
                    field,
                    format!("rejected by the nmea parser ({:?})", inner.code),
                )
            }
            other => self.malformed(0, format!("rejected by the nmea parser: {other}")),
        }
    }

    fn with_nmea_crate(&self, kind: SentenceKind) -> Result<Decoded, SentenceError> {
        let parsed = nmea::parse_str(self.text).map_err(|e| self.crate_error(&e))?;
        let decoded = match (kind, parsed) {
            (SentenceKind::Gga, nmea::ParseResult::GGA(g)) => {
                let quality = match g.fix_type {
                    Some(t) => quality_of(t),
                    None => FixQuality::Invalid,
                };
                let (lat, lon) = self.lat_lon(2, g.latitude, g.longitude)?;
                let sats = match g.fix_satellites {
                    Some(n) => Some(
                        u8::try_from(n).map_err(|_| self.malformed(7, "too many satellites"))?,
                    ),
                    None => None,
                };
                let age = self.opt_f64(13)?;
                let station = match self.field(14) {
                    "" => None,
                    s => Some(
                        s.parse::<u16>()
                            .ok()
                            .filter(|id| *id <= 1023)
                            .ok_or_else(|| self.malformed(14, "station ID not in 0-1023"))?,
                    ),
                };
                Decoded::Gga(Gga {
                    time: g.fix_time,
                    quality,
                    lat,
                    lon,
                    alt: self.finite_f32(9, g.altitude)?,
                    geoid: self.finite_f32(11, g.geoid_separation)?,
                    sats,
                    hdop: self.finite_f32(8, g.hdop)?,
                    age,
                    station,
                })
            }
            (SentenceKind::Rmc, nmea::ParseResult::RMC(r)) => {
                let (lat, lon) = self.lat_lon(3, r.lat, r.lon)?;
                Decoded::Rmc(Rmc {
                    time: r.fix_time,
                    valid: r.status_of_fix != nmea::sentences::rmc::RmcStatusOfFix::Invalid,
                    lat,
                    lon,
                    speed_mps: self
                        .finite_f32(7, r.speed_over_ground)?
                        .map(|kn| kn / KNOTS_PER_MPS),
                    course: self.finite_f32(8, r.true_course)?,
                    date: r.fix_date,
                    mode: self.opt_char(12, "mode indicator", PositioningMode::from_char)?,
                    nav: self.opt_char(
                        13,
                        "navigational status (S, C, U, V)",
                        NavStatus::from_char,
                    )?,
                })
            }
            (SentenceKind::Vtg, nmea::ParseResult::VTG(v)) => Decoded::Vtg(Vtg {
                course: self.finite_f32(1, v.true_course)?,
                speed_mps: self
                    .finite_f32(5, v.speed_over_ground)?
                    .map(|kn| kn / KNOTS_PER_MPS),
                mode: self.opt_char(9, "mode indicator", PositioningMode::from_char)?,
            }),
            (SentenceKind::Gst, nmea::ParseResult::GST(g)) => {
                let accuracy = match (
                    self.finite_f32(2, g.rms_sd)?,
                    self.finite_f32(3, g.ellipse_semi_major_sd)?,
                    self.finite_f32(4, g.ellipse_semi_minor_sd)?,
                    self.finite_f32(5, g.err_ellipse_orientation)?,
                    self.finite_f32(6, g.lat_sd)?,
                    self.finite_f32(7, g.long_sd)?,
                    self.finite_f32(8, g.alt_sd)?,
                ) {
                    (
                        Some(rms_m),
                        Some(semi_major_m),
                        Some(semi_minor_m),
                        Some(orientation_deg),
                        Some(lat_sigma_m),
                        Some(lon_sigma_m),
                        Some(alt_sigma_m),
                    ) => Some(Accuracy {
                        rms_m,
                        semi_major_m,
                        semi_minor_m,
                        orientation_deg,
                        lat_sigma_m,
                        lon_sigma_m,
                        alt_sigma_m,
                    }),
                    _ => None,
                };
                Decoded::Gst(g.time, accuracy)
            }
            (SentenceKind::Hdt, nmea::ParseResult::HDT(h)) => {
                let heading = self.finite_f32(1, h.heading)?;
                if heading.is_some_and(|h| !(0.0..=360.0).contains(&h)) {
                    return Err(self.malformed(1, "outside 0-360 degrees"));
                }
                Decoded::Hdt(heading)
            }
            (SentenceKind::Zda, nmea::ParseResult::ZDA(z)) => {
                let date = z.utc_date();
                if date.is_none() && (z.day.is_some() || z.month.is_some() || z.year.is_some()) {
                    return Err(self.malformed(2, "not a calendar date"));
                }
                Decoded::Zda(z.utc_time, date)
            }
            (_, other) => {
                return Err(self.malformed(
                    0,
                    format!("decoded as {:?}", nmea::SentenceType::from(&other)),
                ));
            }
        };
        Ok(decoded)
    }
}

fn quality_of(t: FixType) -> FixQuality {
    match t {
        FixType::Invalid => FixQuality::Invalid,
        FixType::Gps => FixQuality::Single,
        FixType::DGps => FixQuality::Dgps,
        FixType::Pps => FixQuality::Pps,
        FixType::Rtk => FixQuality::RtkFixed,
        FixType::FloatRtk => FixQuality::RtkFloat,
        FixType::Estimated => FixQuality::Estimated,
        FixType::Manual => FixQuality::Manual,
        FixType::Simulation => FixQuality::Simulator,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sentence(body: &str) -> String {
        format!("${body}*{:02X}\r\n", checksum(body.as_bytes()))
    }

    fn read(text: &str) -> Vec<ReadEvent> {
        let mut reader = NmeaReader::default();
        let mut events: Vec<ReadEvent> = reader.feed(text.as_bytes()).collect();
        events.extend(reader.flush());
        events
    }

    /// Found by fuzzing (nmea_stream): the nmea crate parses its f32 fields without a
    /// bound, so 44 digits came out as an infinite course, speed, height, HDOP or sigma,
    /// and the reading carried it on to the localiser (an infinite course is a NaN
    /// heading). Each such field is now a malformed sentence naming it.
    #[test]
    fn numbers_beyond_f32_are_malformed_fields_not_infinite_readings() {
        let big = "9".repeat(40);
        let cases = [
            (format!("GPRMC,000000.00,A,,,,,0.004,{big},091202,,,A"), 8),
            (format!("GPRMC,000000.00,A,,,,,{big},77.52,091202,,,A"), 7),
            (format!("GPVTG,{big},T,,M,0.004,N,0.008,K,A"), 1),
            (format!("GPVTG,77.52,T,,M,{big},N,0.008,K,A"), 5),
            (format!("GPGGA,092725.00,,,,,1,08,1.01,{big},M,48.0,M,,"), 9),
            (
                format!("GPGGA,092725.00,,,,,1,08,1.01,499.6,M,{big},M,,"),
                11,
            ),
            (
                format!("GPGGA,092725.00,,,,,1,08,{big},499.6,M,48.0,M,,"),
                8,
            ),
            (format!("GPGST,082356.00,1.8,{big},1.0,30,1.7,1.3,2.2"), 3),
            (format!("GPGST,082356.00,1.8,1.0,1.0,30,1.7,1.3,{big}"), 8),
            (format!("HEHDT,{big},T"), 1),
        ];
        for (body, field) in cases {
            let events = read(&sentence(&body));
            assert!(
                matches!(
                    &events[..],
                    [ReadEvent::Error(SentenceError::MalformedField { field: f, .. })] if *f == field
                ),
                "{body}: {events:?}"
            );
        }
    }
}
