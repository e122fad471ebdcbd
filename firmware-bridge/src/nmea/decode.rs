//! One sentence to typed fields, stateless: checks the characters, the checksum and
//! the address, then decodes the fields of GGA, RMC, VTG, GST, HDT, THS and ZDA.
//! Grouping the sentences of an epoch is the reader's ([`super::NmeaReader`]).
//!
//! # Field rules
//!
//! Every field is read in full (no prefix parsing: `12.5x` is malformed, not 12.5) and
//! a field that is present but malformed is a [`SentenceError::MalformedField`] naming
//! the sentence, the field's number (the address is field 0) and why. An empty field
//! is `None`, except the few a sentence cannot do without (GGA's fix quality, RMC's
//! status, THS's mode, HDT's `T`). Fields past the last one a sentence needs may be
//! absent (pre-2.3 RMC and VTG have no mode indicator, pre-4.1 RMC no navigational
//! status, a short GGA no age and station); a sentence shorter than that is malformed
//! at its first missing field. Fields after the last known one are ignored.
//!
//! - time `hhmmss` or `hhmmss.s…` (hour < 24, minute < 60, second < 60; fractions
//!   beyond nanoseconds are cut);
//! - date `ddmmyy` (RMC; years 83-99 are 19xx, the rest 20xx, as gpsd and the nmea
//!   crate read them) and ZDA's day, month and four-digit year;
//! - latitude `ddmm.m…` with `N`/`S` and longitude `dddmm.m…` with `E`/`W`: all four
//!   fields empty, or all four given (minutes below 60, within ±90° and ±180°);
//! - numbers: decimal (sign, fraction and exponent allowed), finite and within
//!   ±3.4e38, the range of the f32 the nmea crate used to read them, so no reading
//!   the controller can get is larger than before;
//! - satellites a count up to 255, GGA's station 0-1023, units (`M`, `T`, `N`, `K`)
//!   empty or that letter, modes and statuses one of their letters.
//!
//! This replaced the nmea crate (0.8), whose serde_with pin kept the Foxglove SDK's
//! WebSocket server out of the workspace; it reads what the crate read, with these
//! differences: a malformed field is always an error naming that field (the crate
//! accepted trailing garbage after some fields, `12.5x`, a seven-digit time or minutes
//! of 60 and more), numbers keep f64 precision (the crate's f32 cut 545.445 to
//! 545.44498), and VTG's speed falls back to the km/h field when the knots field is
//! empty (the crate never read the km/h field).

use chrono::{NaiveDate, NaiveTime};

use super::SentenceError;
use super::framing::checksum;
use super::types::{
    Accuracy, FixQuality, HeadingMode, NavStatus, PositioningMode, SentenceKind, Talker,
};
use super::writer::KNOTS_PER_MPS;

/// The fields of a GGA sentence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Gga {
    pub(super) time: Option<NaiveTime>,
    pub(super) quality: FixQuality,
    pub(super) lat: Option<f64>,
    pub(super) lon: Option<f64>,
    pub(super) alt: Option<f64>,
    pub(super) geoid: Option<f64>,
    pub(super) sats: Option<u8>,
    pub(super) hdop: Option<f64>,
    pub(super) age: Option<f64>,
    pub(super) station: Option<u16>,
}

/// The fields of an RMC sentence (speed in m/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Rmc {
    pub(super) time: Option<NaiveTime>,
    pub(super) valid: bool,
    pub(super) lat: Option<f64>,
    pub(super) lon: Option<f64>,
    pub(super) speed_mps: Option<f64>,
    pub(super) course: Option<f64>,
    pub(super) date: Option<NaiveDate>,
    pub(super) mode: Option<PositioningMode>,
    pub(super) nav: Option<NavStatus>,
}

/// The fields of a VTG sentence (speed in m/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Vtg {
    pub(super) course: Option<f64>,
    pub(super) speed_mps: Option<f64>,
    pub(super) mode: Option<PositioningMode>,
}

/// The fields of a THS sentence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Ths {
    pub(super) heading: Option<f64>,
    pub(super) mode: HeadingMode,
}

/// One decoded sentence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Decoded {
    Gga(Gga),
    Rmc(Rmc),
    Vtg(Vtg),
    Gst(Option<NaiveTime>, Option<Accuracy>),
    Hdt(Option<f64>),
    Ths(Ths),
    Zda(Option<NaiveTime>, Option<NaiveDate>),
}

impl Decoded {
    /// The sentence kind.
    pub(super) fn kind(&self) -> SentenceKind {
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

    /// The UTC time of day, for the kinds that carry one (GGA, RMC, GST, ZDA).
    pub(super) fn time(&self) -> Option<NaiveTime> {
        match self {
            Self::Gga(g) => g.time,
            Self::Rmc(r) => r.time,
            Self::Gst(t, _) | Self::Zda(t, _) => *t,
            Self::Vtg(_) | Self::Hdt(_) | Self::Ths(_) => None,
        }
    }
}

/// Decode one framed line (`$` through checksum, no terminator).
pub(super) fn decode_line(line: &[u8]) -> Result<(Talker, Decoded), SentenceError> {
    if let Some((position, &byte)) = line
        .iter()
        .enumerate()
        .find(|(_, b)| !(0x20..0x7f).contains(*b))
    {
        return Err(SentenceError::InvalidCharacter { position, byte });
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
        address,
        fields: &fields,
    };
    let decoded = match kind {
        SentenceKind::Gga => cx.gga()?,
        SentenceKind::Rmc => cx.rmc()?,
        SentenceKind::Vtg => cx.vtg()?,
        SentenceKind::Gst => cx.gst()?,
        SentenceKind::Hdt => cx.hdt()?,
        SentenceKind::Ths => cx.ths()?,
        SentenceKind::Zda => cx.zda()?,
    };
    Ok((talker, decoded))
}

fn clip(s: &str) -> String {
    s.chars().take(16).collect()
}

/// The largest magnitude a number field may have: f32's range, the nmea crate's.
const NUMBER_LIMIT: f64 = f32::MAX as f64;

/// One sentence being decoded: its address and fields (0 is the address).
struct Ctx<'a> {
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

    /// The sentence has fields 0 through `last` (the later ones may be empty).
    fn require(&self, last: usize) -> Result<(), SentenceError> {
        if self.fields.len() > last {
            Ok(())
        } else {
            Err(self.malformed(self.fields.len(), "missing field"))
        }
    }

    /// Field `i` through `parse` unless it is empty; its error names the field.
    fn opt<T>(
        &self,
        i: usize,
        parse: impl Fn(&str) -> Result<T, &'static str>,
    ) -> Result<Option<T>, SentenceError> {
        match self.field(i) {
            "" => Ok(None),
            f => parse(f)
                .map(Some)
                .map_err(|reason| self.malformed(i, reason)),
        }
    }

    fn number(&self, i: usize) -> Result<Option<f64>, SentenceError> {
        self.opt(i, parse_number)
    }

    fn time(&self, i: usize) -> Result<Option<NaiveTime>, SentenceError> {
        self.opt(i, parse_time)
    }

    /// A unit field: empty or exactly `unit`.
    fn unit(&self, i: usize, unit: &'static str) -> Result<(), SentenceError> {
        match self.field(i) {
            "" => Ok(()),
            f if f == unit => Ok(()),
            _ => Err(self.malformed(i, format!("not the unit '{unit}'"))),
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

    /// A one-letter field that must be present.
    fn req_char<T>(
        &self,
        i: usize,
        what: &str,
        from: impl Fn(char) -> Option<T>,
    ) -> Result<T, SentenceError> {
        self.opt_char(i, what, from)?
            .ok_or_else(|| self.malformed(i, format!("empty {what}")))
    }

    fn heading(&self, i: usize) -> Result<Option<f64>, SentenceError> {
        match self.number(i)? {
            Some(h) if !(0.0..=360.0).contains(&h) => {
                Err(self.malformed(i, "outside 0-360 degrees"))
            }
            h => Ok(h),
        }
    }

    /// Latitude and longitude from fields `first` to `first + 3` (value, N/S, value,
    /// E/W): all four empty, or all four valid.
    fn lat_lon(&self, first: usize) -> Result<(Option<f64>, Option<f64>), SentenceError> {
        let (lat_i, ns_i, lon_i, ew_i) = (first, first + 1, first + 2, first + 3);
        if [lat_i, ns_i, lon_i, ew_i]
            .iter()
            .all(|i| self.field(*i).is_empty())
        {
            return Ok((None, None));
        }
        let lat = self
            .opt(lat_i, |f| parse_angle(f, 2, "latitude ddmm.mmmm"))?
            .ok_or_else(|| self.malformed(lat_i, "empty latitude beside a position"))?;
        let south = self.req_char(ns_i, "hemisphere (N, S)", |c| match c {
            'N' => Some(false),
            'S' => Some(true),
            _ => None,
        })?;
        let lon = self
            .opt(lon_i, |f| parse_angle(f, 3, "longitude dddmm.mmmm"))?
            .ok_or_else(|| self.malformed(lon_i, "empty longitude beside a latitude"))?;
        let west = self.req_char(ew_i, "hemisphere (E, W)", |c| match c {
            'E' => Some(false),
            'W' => Some(true),
            _ => None,
        })?;
        if lat > 90.0 {
            return Err(self.malformed(lat_i, "latitude beyond 90 degrees"));
        }
        if lon > 180.0 {
            return Err(self.malformed(lon_i, "longitude beyond 180 degrees"));
        }
        Ok((
            Some(if south { -lat } else { lat }),
            Some(if west { -lon } else { lon }),
        ))
    }

    /// GGA: `time,lat,N,lon,E,quality,sats,hdop,alt,M,geoid,M[,age[,station]]`.
    fn gga(&self) -> Result<Decoded, SentenceError> {
        self.require(12)?;
        let time = self.time(1)?;
        let (lat, lon) = self.lat_lon(2)?;
        let quality = self.req_char(6, "fix quality (0-8)", |c| {
            c.to_digit(10)
                .and_then(|d| u8::try_from(d).ok())
                .and_then(FixQuality::from_gga_digit)
        })?;
        let sats = self.opt(7, |f| {
            if !all_digits(f) {
                Err("not a satellite count")
            } else {
                f.parse::<u8>().map_err(|_| "too many satellites")
            }
        })?;
        let hdop = self.number(8)?;
        let alt = self.number(9)?;
        self.unit(10, "M")?;
        let geoid = self.number(11)?;
        self.unit(12, "M")?;
        let age = self.number(13)?;
        let station = self.opt(14, |f| {
            f.parse::<u16>()
                .ok()
                .filter(|id| all_digits(f) && *id <= 1023)
                .ok_or("station ID not in 0-1023")
        })?;
        Ok(Decoded::Gga(Gga {
            time,
            quality,
            lat,
            lon,
            alt,
            geoid,
            sats,
            hdop,
            age,
            station,
        }))
    }

    /// RMC: `time,status,lat,N,lon,E,knots,course,ddmmyy,magvar,E[,mode[,nav]]`.
    fn rmc(&self) -> Result<Decoded, SentenceError> {
        self.require(11)?;
        let time = self.time(1)?;
        let valid = self.req_char(2, "status (A, D, V)", |c| match c {
            'A' | 'D' => Some(true),
            'V' => Some(false),
            _ => None,
        })?;
        let (lat, lon) = self.lat_lon(3)?;
        let speed_mps = self.number(7)?.map(|kn| kn / KNOTS_PER_MPS);
        let course = self.number(8)?;
        let date = self.opt(9, parse_ddmmyy)?;
        // Magnetic variation: read for its validity only.
        let variation = self.number(10)?;
        let variation_dir = self.opt_char(11, "variation direction (E, W)", |c| {
            matches!(c, 'E' | 'W').then_some(c)
        })?;
        if variation.is_some() && variation_dir.is_none() {
            return Err(self.malformed(11, "empty variation direction (E, W)"));
        }
        Ok(Decoded::Rmc(Rmc {
            time,
            valid,
            lat,
            lon,
            speed_mps,
            course,
            date,
            mode: self.opt_char(12, "mode indicator", PositioningMode::from_char)?,
            nav: self.opt_char(13, "navigational status (S, C, U, V)", NavStatus::from_char)?,
        }))
    }

    /// VTG: `course,T,magnetic,M,knots,N,kmh,K[,mode]`.
    fn vtg(&self) -> Result<Decoded, SentenceError> {
        self.require(7)?;
        let course = self.number(1)?;
        self.unit(2, "T")?;
        self.number(3)?;
        self.unit(4, "M")?;
        let knots = self.number(5)?;
        self.unit(6, "N")?;
        let kmh = self.number(7)?;
        self.unit(8, "K")?;
        let speed_mps = knots.map(|kn| kn / KNOTS_PER_MPS).or(kmh.map(|k| k / 3.6));
        Ok(Decoded::Vtg(Vtg {
            course,
            speed_mps,
            mode: self.opt_char(9, "mode indicator", PositioningMode::from_char)?,
        }))
    }

    /// GST: `time,rms,semi-major,semi-minor,orientation,lat sigma,lon sigma,alt sigma`;
    /// an accuracy only when all seven are given.
    fn gst(&self) -> Result<Decoded, SentenceError> {
        self.require(8)?;
        let time = self.time(1)?;
        let accuracy = match (
            self.number(2)?,
            self.number(3)?,
            self.number(4)?,
            self.number(5)?,
            self.number(6)?,
            self.number(7)?,
            self.number(8)?,
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
        Ok(Decoded::Gst(time, accuracy))
    }

    /// HDT: `heading,T`.
    fn hdt(&self) -> Result<Decoded, SentenceError> {
        self.require(2)?;
        let heading = self.heading(1)?;
        if self.field(2) != "T" {
            return Err(self.malformed(2, "not the true-heading marker 'T'"));
        }
        Ok(Decoded::Hdt(heading))
    }

    /// THS: true heading and mode (NMEA 3.0).
    fn ths(&self) -> Result<Decoded, SentenceError> {
        self.require(2)?;
        let heading = self.heading(1)?;
        let mode = self.req_char(2, "THS mode (A, E, M, S, V)", HeadingMode::from_char)?;
        Ok(Decoded::Ths(Ths { heading, mode }))
    }

    /// ZDA: `time,dd,mm,yyyy,zone hours,zone minutes`; a date only when all three of
    /// its fields are given, and they must then make a calendar date.
    fn zda(&self) -> Result<Decoded, SentenceError> {
        self.require(6)?;
        let time = self.time(1)?;
        let day = self.opt(2, |f| parse_uint_in(f, 2, 1, 31, "not a day 01-31"))?;
        let month = self.opt(3, |f| parse_uint_in(f, 2, 1, 12, "not a month 01-12"))?;
        let year = self.opt(4, |f| match f.len() {
            4 => parse_uint_in(f, 4, 0, 9999, "not a year yyyy"),
            _ => Err("not a year yyyy"),
        })?;
        self.opt(5, |f| {
            let digits = f.strip_prefix('-').unwrap_or(f);
            parse_uint_in(digits, 2, 0, 13, "not a zone offset -13 to 13 hours")
        })?;
        self.opt(6, |f| parse_uint_in(f, 2, 0, 59, "not zone minutes 00-59"))?;
        let date = match (day, month, year) {
            (None, None, None) => None,
            (Some(d), Some(m), Some(y)) => Some(
                i32::try_from(y)
                    .ok()
                    .and_then(|y| NaiveDate::from_ymd_opt(y, m, d))
                    .ok_or_else(|| self.malformed(2, "not a calendar date"))?,
            ),
            _ => return Err(self.malformed(2, "not a calendar date (day, month or year empty)")),
        };
        Ok(Decoded::Zda(time, date))
    }
}

fn all_digits(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

/// The value of 1 to 9 ASCII digits.
fn digits_value(s: &str) -> Option<u32> {
    if !all_digits(s) || s.len() > 9 {
        return None;
    }
    Some(
        s.bytes()
            .fold(0u32, |v, b| v * 10 + u32::from(b.wrapping_sub(b'0'))),
    )
}

/// An unsigned number of 1 to `max_digits` digits within `min..=max`.
fn parse_uint_in(
    s: &str,
    max_digits: usize,
    min: u32,
    max: u32,
    what: &'static str,
) -> Result<u32, &'static str> {
    digits_value(s)
        .filter(|v| s.len() <= max_digits && (min..=max).contains(v))
        .ok_or(what)
}

/// A decimal number, finite and within ±[`NUMBER_LIMIT`].
fn parse_number(s: &str) -> Result<f64, &'static str> {
    // Rust's float syntax, less its words (inf, NaN): digits, sign, point, exponent.
    if !s
        .bytes()
        .all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'e' | b'E'))
    {
        return Err("not a number");
    }
    match s.parse::<f64>() {
        Ok(v) if v.abs() <= NUMBER_LIMIT => Ok(v),
        Ok(_) => Err("beyond ±3.4e38"),
        Err(_) => Err("not a number"),
    }
}

/// UTC time of day, `hhmmss` or `hhmmss.s…`.
fn parse_time(s: &str) -> Result<NaiveTime, &'static str> {
    const WHAT: &str = "not a time hhmmss.ss";
    let (hms, fraction) = match s.split_once('.') {
        Some((hms, fraction)) => (hms, Some(fraction)),
        None => (s, None),
    };
    if hms.len() != 6 {
        return Err(WHAT);
    }
    let part = |r: std::ops::Range<usize>| hms.get(r).and_then(digits_value).ok_or(WHAT);
    let (h, m, sec) = (part(0..2)?, part(2..4)?, part(4..6)?);
    if h >= 24 {
        return Err("hour beyond 23");
    }
    if m >= 60 {
        return Err("minute beyond 59");
    }
    if sec >= 60 {
        return Err("second beyond 59");
    }
    let nanos = match fraction {
        None | Some("") => 0,
        Some(f) => fraction_nanos(f).ok_or(WHAT)?,
    };
    NaiveTime::from_hms_nano_opt(h, m, sec, nanos).ok_or(WHAT)
}

/// The digits after a decimal point as nanoseconds (digits past the ninth are cut).
fn fraction_nanos(f: &str) -> Option<u32> {
    if !all_digits(f) {
        return None;
    }
    let nine = f.get(..f.len().min(9))?;
    let scale = 10u32.checked_pow(u32::try_from(9 - nine.len()).ok()?)?;
    Some(digits_value(nine)? * scale)
}

/// RMC's date, `ddmmyy`.
fn parse_ddmmyy(s: &str) -> Result<NaiveDate, &'static str> {
    const WHAT: &str = "not a date ddmmyy";
    if s.len() != 6 {
        return Err(WHAT);
    }
    let part = |r: std::ops::Range<usize>| s.get(r).and_then(digits_value).ok_or(WHAT);
    let (d, m, y) = (part(0..2)?, part(2..4)?, part(4..6)?);
    let year = i32::try_from(y).map_err(|_| WHAT)?;
    let year = if (83..=99).contains(&year) {
        1900 + year
    } else {
        2000 + year
    };
    NaiveDate::from_ymd_opt(year, m, d).ok_or("not a calendar date")
}

/// Degrees and decimal minutes (`ddmm.m…`, `dddmm.m…` with `degree_digits` 3) as
/// degrees; minutes below 60.
fn parse_angle(s: &str, degree_digits: usize, what: &'static str) -> Result<f64, &'static str> {
    let degrees = s.get(..degree_digits).and_then(digits_value).ok_or(what)?;
    let minutes = s.get(degree_digits..).ok_or(what)?;
    let (whole, fraction) = match minutes.split_once('.') {
        Some((w, f)) => (w, f),
        None => (minutes, ""),
    };
    if !all_digits(whole) || !(fraction.is_empty() || all_digits(fraction)) {
        return Err(what);
    }
    let minutes: f64 = minutes.parse().map_err(|_| what)?;
    if minutes >= 60.0 {
        return Err("minutes beyond 59.999");
    }
    Ok(f64::from(degrees) + minutes / 60.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A framed line (`$` through checksum, no terminator) with a correct checksum.
    fn line(body: &str) -> String {
        format!("${body}*{:02X}", checksum(body.as_bytes()))
    }

    /// Found by fuzzing (nmea_stream): the nmea crate parsed its f32 fields without a
    /// bound, so 44 digits came out as an infinite course, speed, height, HDOP or sigma,
    /// and the reading carried it on to the localiser (an infinite course is a NaN
    /// heading). Each such field is a malformed sentence naming it (numbers stay within
    /// f32's range now that this decoder reads them as f64).
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
            let decoded = decode_line(line(&body).as_bytes());
            assert!(
                matches!(
                    &decoded,
                    Err(SentenceError::MalformedField { field: f, .. }) if *f == field
                ),
                "{body}: {decoded:?}"
            );
        }
    }

    fn decode(body: &str) -> Result<Decoded, SentenceError> {
        decode_line(line(body).as_bytes()).map(|(_, d)| d)
    }

    fn time(h: u32, m: u32, s: u32, nano: u32) -> Option<NaiveTime> {
        NaiveTime::from_hms_nano_opt(h, m, s, nano)
    }

    /// The field number of a malformed-field error, else a description of what came.
    fn malformed_field(r: &Result<Decoded, SentenceError>) -> Result<usize, String> {
        match r {
            Err(SentenceError::MalformedField { field, .. }) => Ok(*field),
            other => Err(format!("{other:?}")),
        }
    }

    #[test]
    fn times_are_hhmmss_with_any_fraction() {
        let ok = [
            ("123519", time(12, 35, 19, 0)),
            ("123519.", time(12, 35, 19, 0)),
            ("123519.5", time(12, 35, 19, 500_000_000)),
            ("000000.00", time(0, 0, 0, 0)),
            ("235959.99", time(23, 59, 59, 990_000_000)),
            ("083559.123456789", time(8, 35, 59, 123_456_789)),
            // Past nanoseconds the digits are cut, not rounded into the next second.
            ("235959.9999999999", time(23, 59, 59, 999_999_999)),
        ];
        for (s, want) in ok {
            assert_eq!(parse_time(s).ok(), want, "{s}");
        }
        for s in [
            "",
            "12351",
            "1235190",
            "12351.9",
            "243519",
            "126019",
            "123560",
            "12x519",
            "123519.x",
            "123519.5.5",
            "+12351",
            "-12351",
            "123519 ",
            " 123519",
            "1e3519",
        ] {
            assert!(parse_time(s).is_err(), "{s:?}");
        }
        assert_eq!(parse_time("243519"), Err("hour beyond 23"));
        assert_eq!(parse_time("126019"), Err("minute beyond 59"));
        assert_eq!(parse_time("123560"), Err("second beyond 59"));
    }

    #[test]
    fn dates_are_ddmmyy_in_1983_to_2082() {
        let ymd = NaiveDate::from_ymd_opt;
        assert_eq!(parse_ddmmyy("030624"), Ok(ymd(2024, 6, 3).unwrap()));
        assert_eq!(parse_ddmmyy("091202"), Ok(ymd(2002, 12, 9).unwrap()));
        assert_eq!(parse_ddmmyy("191194"), Ok(ymd(1994, 11, 19).unwrap()));
        assert_eq!(parse_ddmmyy("010183"), Ok(ymd(1983, 1, 1).unwrap()));
        assert_eq!(parse_ddmmyy("311282"), Ok(ymd(2082, 12, 31).unwrap()));
        assert_eq!(parse_ddmmyy("290224"), Ok(ymd(2024, 2, 29).unwrap()));
        assert_eq!(parse_ddmmyy("290223"), Err("not a calendar date"));
        for s in [
            "", "0306", "0306245", "000624", "031324", "320624", "3a0624", "03-624", "+30624",
        ] {
            assert!(parse_ddmmyy(s).is_err(), "{s:?}");
        }
    }

    #[test]
    fn angles_are_degrees_and_decimal_minutes() {
        let close = |s: &str, digits: usize, want: f64| {
            let got = parse_angle(s, digits, "angle");
            assert!(
                got.is_ok_and(|v| (v - want).abs() < 1e-12),
                "{s}: {got:?} != {want}"
            );
        };
        close("4807.038", 2, 48.0 + 7.038 / 60.0);
        close("4807.0381234", 2, 48.0 + 7.038_123_4 / 60.0);
        close("4807", 2, 48.0 + 7.0 / 60.0);
        close("4807.", 2, 48.0 + 7.0 / 60.0);
        close("0000.0000", 2, 0.0);
        close("01131.324", 3, 11.0 + 31.324 / 60.0);
        close("17959.9999999", 3, 179.0 + 59.999_999_9 / 60.0);
        for (s, digits) in [
            ("", 2),
            ("48", 2),
            ("4", 2),
            ("48.5", 2),
            ("4860.0", 2),
            ("4899", 2),
            ("-4807.0", 2),
            ("4807.0e1", 2),
            ("48O7.0", 2),
            ("4807.0.1", 2),
            ("4807.-1", 2),
            ("11.5", 3),
            ("011", 3),
        ] {
            assert!(parse_angle(s, digits, "angle").is_err(), "{s:?}");
        }
        assert_eq!(
            parse_angle("4860.0", 2, "angle"),
            Err("minutes beyond 59.999")
        );
    }

    #[test]
    fn numbers_are_whole_finite_decimals_within_f32_range() {
        for (s, want) in [
            ("1.5", 1.5),
            ("-2", -2.0),
            ("+3", 3.0),
            ("1e3", 1000.0),
            ("2.5E-1", 0.25),
            (".5", 0.5),
            ("5.", 5.0),
            ("000.0", 0.0),
            ("545.445", 545.445),
        ] {
            assert_eq!(parse_number(s), Ok(want), "{s}");
        }
        for s in [
            "inf", "-inf", "NaN", "infinity", "1.0x", "1,0", " 1", "1 ", "--1", "1e", "e1", ".",
            "0x10", "1e39", "-1e39",
        ] {
            assert!(parse_number(s).is_err(), "{s:?}");
        }
        assert_eq!(parse_number("3.4e38"), Ok(3.4e38));
    }

    /// Published GGA examples, a single fix and an RTK one, field by field.
    fn published_gga_decodes_field_by_field() {
        let Ok(Decoded::Gga(g)) =
            decode("GPGGA,092725.00,4717.11399,N,00833.91590,E,1,08,1.01,499.6,M,48.0,M,,")
        else {
            panic!("GGA");
        };
        assert_eq!(g.time, time(9, 27, 25, 0));
        assert_eq!(g.quality, FixQuality::Single);
        assert_eq!(g.lat, Some(47.0 + 17.11399 / 60.0));
        assert_eq!(g.lon, Some(8.0 + 33.9159 / 60.0));
        assert_eq!(
            (g.sats, g.hdop, g.alt, g.geoid),
            (Some(8), Some(1.01), Some(499.6), Some(48.0))
        );
        assert_eq!((g.age, g.station), (None, None));

        let Ok(Decoded::Gga(g)) = decode(
            "GNGGA,123519.00,3345.1234567,S,07012.7654321,W,4,17,0.62,545.445,M,-46.900,M,1.5,0042",
        ) else {
            panic!("RTK GGA");
        };
        assert_eq!(g.quality, FixQuality::RtkFixed);
        assert_eq!(g.lat, Some(-(33.0 + 45.123_456_7 / 60.0)));
        assert_eq!(g.lon, Some(-(70.0 + 12.765_432_1 / 60.0)));
        assert_eq!((g.alt, g.geoid), (Some(545.445), Some(-46.9)));
        assert_eq!((g.age, g.station), (Some(1.5), Some(42)));
    }

    /// Published RMC examples (NMEA 4.1 too, and an empty one), field by field.
    fn published_rmc_decodes_field_by_field() {
        let Ok(Decoded::Rmc(r)) =
            decode("GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3,E,A")
        else {
            panic!("RMC");
        };
        assert_eq!(r.time, time(22, 54, 46, 330_000_000));
        assert!(r.valid);
        assert_eq!(r.lat, Some(49.0 + 16.45 / 60.0));
        assert_eq!(r.lon, Some(-(123.0 + 11.12 / 60.0)));
        assert_eq!(r.speed_mps, Some(0.5 / KNOTS_PER_MPS));
        assert_eq!(r.course, Some(54.7));
        assert_eq!(r.date, NaiveDate::from_ymd_opt(1994, 11, 19));
        assert_eq!((r.mode, r.nav), (Some(PositioningMode::Autonomous), None));

        // NMEA 4.1 with navigational status; 'D' status is valid, 'V' is not.
        let Ok(Decoded::Rmc(r)) =
            decode("GNRMC,123519.00,D,4807.038,N,01131.000,E,0.5,54.7,030624,,,R,S")
        else {
            panic!("RMC 4.1");
        };
        assert!(r.valid);
        assert_eq!(r.mode, Some(PositioningMode::RtkFixed));
        assert_eq!(r.nav, Some(NavStatus::Safe));
        let Ok(Decoded::Rmc(r)) = decode("GPRMC,,V,,,,,,,,,") else {
            panic!("empty RMC");
        };
        assert_eq!(
            (
                r.time,
                r.valid,
                r.lat,
                r.lon,
                r.speed_mps,
                r.course,
                r.date,
                r.mode
            ),
            (None, false, None, None, None, None, None, None)
        );
    }

    #[test]
    fn published_sentences_decode_field_by_field() {
        published_gga_decodes_field_by_field();
        published_rmc_decodes_field_by_field();

        let Ok(Decoded::Vtg(v)) = decode("GPVTG,77.52,T,,M,0.004,N,0.008,K,A") else {
            panic!("VTG");
        };
        assert_eq!(v.course, Some(77.52));
        assert_eq!(v.speed_mps, Some(0.004 / KNOTS_PER_MPS));
        assert_eq!(v.mode, Some(PositioningMode::Autonomous));
        // Without the knots, the km/h field; pre-2.3 without a mode.
        let Ok(Decoded::Vtg(v)) = decode("GPVTG,360.0,T,348.7,M,,N,36.0,K") else {
            panic!("VTG km/h");
        };
        assert_eq!(
            (v.course, v.speed_mps, v.mode),
            (Some(360.0), Some(10.0), None)
        );

        assert_eq!(
            decode("GPGST,182141.000,15.5,15.3,7.2,21.8,0.9,0.5,0.8"),
            Ok(Decoded::Gst(
                time(18, 21, 41, 0),
                Some(Accuracy {
                    rms_m: 15.5,
                    semi_major_m: 15.3,
                    semi_minor_m: 7.2,
                    orientation_deg: 21.8,
                    lat_sigma_m: 0.9,
                    lon_sigma_m: 0.5,
                    alt_sigma_m: 0.8,
                })
            ))
        );
        assert_eq!(
            decode("GPGST,082356.00,1.8,,,,1.7,1.3,2.2"),
            Ok(Decoded::Gst(time(8, 23, 56, 0), None))
        );
        assert_eq!(decode("HEHDT,274.07,T"), Ok(Decoded::Hdt(Some(274.07))));
        assert_eq!(decode("GPHDT,,T"), Ok(Decoded::Hdt(None)));
        assert_eq!(
            decode("GPZDA,082710.00,16,09,2002,00,00"),
            Ok(Decoded::Zda(
                time(8, 27, 10, 0),
                NaiveDate::from_ymd_opt(2002, 9, 16)
            ))
        );
        assert_eq!(decode("GPZDA,,,,,-05,30"), Ok(Decoded::Zda(None, None)));
    }

    /// `sentence` with its field `i` replaced by `text`.
    fn with_field(sentence: &str, i: usize, text: &str) -> String {
        let mut f: Vec<&str> = sentence.split(',').collect();
        f[i] = text;
        f.join(",")
    }

    /// Sentences each with one malformed field, beside that field's number.
    fn malformed_fields() -> Vec<(String, usize)> {
        const GGA: &str =
            "GNGGA,123519.00,4807.0381234,N,01131.0000009,E,4,17,0.62,545.445,M,46.900,M,1.0,0042";
        const RMC: &str = "GNRMC,123519.00,A,4807.038,N,01131.000,E,0.5,54.7,030624,1.5,E,R,S";
        const VTG: &str = "GNVTG,54.70,T,50.0,M,0.972,N,1.800,K,R";
        const GST: &str = "GNGST,123519.00,0.012,0.010,0.008,33.5,0.009,0.008,0.021";
        const ZDA: &str = "GNZDA,123519.00,03,06,2024,00,00";
        let gga = |i: usize, text: &str| with_field(GGA, i, text);
        let rmc = |i: usize, text: &str| with_field(RMC, i, text);
        let vtg = |i: usize, text: &str| with_field(VTG, i, text);
        let gst = |i: usize, text: &str| with_field(GST, i, text);
        let zda = |i: usize, text: &str| with_field(ZDA, i, text);
        vec![
            (gga(1, "1235"), 1),
            (gga(1, "253519.00"), 1),
            (gga(2, "48x7.0"), 2),
            (gga(2, "4875.0"), 2),
            (gga(2, "9100.0"), 2),
            (gga(2, ""), 2),
            (gga(3, "X"), 3),
            (gga(3, ""), 3),
            (gga(3, "NN"), 3),
            (gga(4, "011"), 4),
            (gga(4, "18100.0"), 4),
            (gga(4, ""), 4),
            (gga(5, "N"), 5),
            (gga(5, ""), 5),
            (gga(6, ""), 6),
            (gga(6, "9"), 6),
            (gga(6, "44"), 6),
            (gga(7, "256"), 7),
            (gga(7, "1x"), 7),
            (gga(7, "-1"), 7),
            (gga(8, "0.6.2"), 8),
            (gga(8, "NaN"), 8),
            (gga(9, "545.445m"), 9),
            (gga(9, "inf"), 9),
            (gga(10, "F"), 10),
            (gga(11, "4 6"), 11),
            (gga(12, "MM"), 12),
            (gga(13, "x"), 13),
            (gga(14, "1024"), 14),
            (gga(14, "+42"), 14),
            (rmc(1, "12x519.00"), 1),
            (rmc(2, ""), 2),
            (rmc(2, "X"), 2),
            (rmc(3, "4807.0x"), 3),
            (rmc(4, "E"), 4),
            (rmc(5, ""), 5),
            (rmc(6, "S"), 6),
            (rmc(7, "fast"), 7),
            (rmc(8, "1e99"), 8),
            (rmc(9, "300224"), 9),
            (rmc(9, "0306"), 9),
            (rmc(10, "1.5W"), 10),
            (rmc(11, "N"), 11),
            (rmc(11, ""), 11),
            (rmc(12, "Q"), 12),
            (rmc(12, "RR"), 12),
            (rmc(13, "Q"), 13),
            (vtg(1, "54.7T"), 1),
            (vtg(2, "M"), 2),
            (vtg(3, "x"), 3),
            (vtg(4, "T"), 4),
            (vtg(5, "0.9.7"), 5),
            (vtg(6, "K"), 6),
            (vtg(7, "1.8.0"), 7),
            (vtg(8, "N"), 8),
            (vtg(9, "Z"), 9),
            (gst(1, "1235.19"), 1),
            (gst(2, "a"), 2),
            (gst(5, "33.5deg"), 5),
            (gst(7, "-"), 7),
            (zda(1, "12:35:19"), 1),
            (zda(2, "32"), 2),
            (zda(2, "00"), 2),
            (zda(2, "31"), 2),
            (zda(3, "13"), 3),
            (zda(3, ""), 2),
            (zda(4, "24"), 4),
            (zda(4, "20245"), 4),
            (zda(5, "14"), 5),
            (zda(5, "-"), 5),
            (zda(6, "60"), 6),
            ("HEHDT,361.0,T".into(), 1),
            ("HEHDT,-1.0,T".into(), 1),
            ("HEHDT,1.0,M".into(), 2),
            ("HEHDT,1.0,".into(), 2),
            ("GNTHS,12.0,".into(), 2),
        ]
    }

    #[test]
    fn each_malformed_field_is_named() {
        let cases = malformed_fields();
        for (body, field) in cases {
            let decoded = decode(&body);
            assert_eq!(malformed_field(&decoded), Ok(field), "{body}");
            let message = decoded.map(|_| ()).unwrap_err().to_string();
            let address = body.get(..5).unwrap_or("");
            assert!(
                message.starts_with(&format!("{address} field {field} malformed")),
                "{body}: {message}"
            );
        }
    }

    #[test]
    fn short_sentences_are_malformed_at_their_first_missing_field() {
        for (body, field) in [
            (
                "GPGGA,092725.00,4717.11399,N,00833.91590,E,1,08,1.01,499.6,M,48.0",
                12,
            ),
            ("GPGGA", 1),
            (
                "GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3",
                11,
            ),
            ("GPVTG,77.52,T,,M,0.004,N", 7),
            ("GPGST,082356.00,1.8,,,,1.7,1.3", 8),
            ("HEHDT,341.8", 2),
            ("GNTHS,12.0", 2),
            ("GPZDA,082710.00,16,09,2002,00", 6),
        ] {
            let decoded = decode(body);
            assert_eq!(malformed_field(&decoded), Ok(field), "{body}");
            assert!(
                decoded
                    .map(|_| ())
                    .unwrap_err()
                    .to_string()
                    .contains("missing field"),
                "{body}"
            );
        }
        // Optional trailing fields: GGA without age and station, RMC and VTG without
        // mode (pre-2.3), a ZDA without zone minutes' comma is short, but extra fields
        // after the known ones are ignored.
        assert!(decode("GPGGA,092725.00,,,,,0,00,,,,,").is_ok());
        assert!(decode("GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,,").is_ok());
        assert!(decode("GPVTG,77.52,T,,M,0.004,N,0.008").is_ok());
        assert!(decode("GPHDT,1.0,T,extra").is_ok());
    }

    proptest::proptest! {
        /// No input panics, and every error of a known sentence names a field within it
        /// (or the first one past its end).
        #[test]
        fn any_fields_decode_or_name_the_bad_one(
            kind in proptest::sample::select(vec!["GGA", "RMC", "VTG", "GST", "HDT", "THS", "ZDA"]),
            fields in proptest::collection::vec("[0-9.,+eENSWTMKAVDR-]{0,12}", 0..16),
        ) {
            let body = format!("GN{kind},{}", fields.join(","));
            match decode(&body) {
                Ok(d) => proptest::prop_assert_eq!(d.kind().formatter(), kind),
                Err(SentenceError::MalformedField { sentence, field, .. }) => {
                    proptest::prop_assert_eq!(sentence, format!("GN{kind}"));
                    proptest::prop_assert!(field <= body.split(',').count(), "{}: {}", body, field);
                }
                Err(e) => proptest::prop_assert!(false, "{}: {}", body, e),
            }
        }
    }
}
