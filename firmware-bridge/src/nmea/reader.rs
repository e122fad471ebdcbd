//! The controller side: bytes to typed GPS readings, one per receiver epoch. This is
//! the stateful part (framing, grouping the sentences of an epoch into one reading,
//! counting); each sentence is decoded on its own by the `decode` module.

use std::collections::VecDeque;
use std::collections::vec_deque::Drain;

use chrono::{NaiveDate, NaiveDateTime, NaiveTime};
use serde::{Deserialize, Serialize};

use super::SentenceError;
use super::decode::{Decoded, Gga, Rmc, Ths, Vtg, decode_line};
use super::framing::{Framed, LineFramer, MAX_SENTENCE_LEN};
use super::types::{
    Accuracy, FixQuality, HeadingMode, NavStatus, PositioningMode, SentenceSet, Talker,
};
use super::writer::Schedule;
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
    /// Complete on what the default writer sends; [`MAX_SENTENCE_LEN`] (102).
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
/// Sentences are decoded individually by this crate (see `decode.rs` for the field
/// rules), every field of GGA, RMC, VTG, GST, HDT, THS and ZDA that a reading carries,
/// including those the nmea crate used here before skipped (GGA age and station, the
/// RMC and VTG mode indicators, the RMC navigational status) and THS, which it did not
/// know; never through a merged navigation state like the nmea crate's, which
/// downgrades an RTK fix to GPS when an RMC follows.
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
