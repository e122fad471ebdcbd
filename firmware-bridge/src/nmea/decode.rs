//! One sentence to typed fields, stateless: checks the characters, the checksum and
//! the address, then decodes GGA, RMC, VTG, GST, HDT and ZDA with `nmea::parse_str`
//! plus the fields it skips (GGA age and station, the RMC and VTG mode indicators, the
//! RMC navigational status), and THS, which the nmea crate does not know. Grouping the
//! sentences of an epoch is the reader's ([`super::NmeaReader`]).

use chrono::{NaiveDate, NaiveTime};
use nmea::sentences::FixType;

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

    /// A framed line (`$` through checksum, no terminator) with a correct checksum.
    fn line(body: &str) -> String {
        format!("${body}*{:02X}", checksum(body.as_bytes()))
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
}
