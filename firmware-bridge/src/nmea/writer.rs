//! The simulator side: typed fixes to NMEA 0183 sentences, the schedule of which
//! sentences go out, and the serial-line budget.

use std::fmt::Write as _;
use std::time::Duration;

use chrono::{DateTime, Datelike, TimeDelta, Timelike, Utc};
use serde::{Deserialize, Serialize};

use super::NmeaError;
use super::framing::{MAX_SENTENCE_LEN, checksum};
use super::types::{
    Accuracy, FixQuality, GpsFix, HeadingMode, NavStatus, SentenceKind, SentenceSet, Talker,
};
use crate::geodesy::normalize_deg_360;

/// Bits on the line per byte for 8N1: start bit, 8 data bits, stop bit.
pub const BITS_PER_BYTE_8N1: u32 = 10;

/// Knots per metre per second (1 knot = 1852 m/h).
pub(crate) const KNOTS_PER_MPS: f64 = 3600.0 / 1852.0;

/// How long one byte occupies a serial line at `baud` (8N1); zero baud gives zero.
pub fn byte_time(baud: u32) -> Duration {
    transmit_time(1, baud)
}

/// How long `bytes` bytes occupy a serial line at `baud` (8N1); zero baud gives zero.
pub fn transmit_time(bytes: usize, baud: u32) -> Duration {
    if baud == 0 {
        return Duration::ZERO;
    }
    let bits = (bytes as u128) * u128::from(BITS_PER_BYTE_8N1);
    let nanos = bits * 1_000_000_000 / u128::from(baud);
    Duration::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
}

/// Which sentences go out: each is sent every n-th epoch (1 = every epoch, 0 = never).
/// Within an epoch they go out in [`SentenceKind::ALL`] order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Schedule {
    pub gga: u32,
    pub rmc: u32,
    pub vtg: u32,
    pub gst: u32,
    pub hdt: u32,
    pub ths: u32,
    pub zda: u32,
}

impl Default for Schedule {
    /// GGA, RMC, VTG, GST, HDT and ZDA every epoch; THS off.
    fn default() -> Self {
        Self {
            gga: 1,
            rmc: 1,
            vtg: 1,
            gst: 1,
            hdt: 1,
            ths: 0,
            zda: 1,
        }
    }
}

impl Schedule {
    /// Every kind of `set` every epoch, the others never.
    pub fn every_epoch(set: SentenceSet) -> Self {
        let on = |k| u32::from(set.contains(k));
        Self {
            gga: on(SentenceKind::Gga),
            rmc: on(SentenceKind::Rmc),
            vtg: on(SentenceKind::Vtg),
            gst: on(SentenceKind::Gst),
            hdt: on(SentenceKind::Hdt),
            ths: on(SentenceKind::Ths),
            zda: on(SentenceKind::Zda),
        }
    }

    /// The decimation of a kind (0 = never).
    pub fn every(&self, kind: SentenceKind) -> u32 {
        match kind {
            SentenceKind::Gga => self.gga,
            SentenceKind::Rmc => self.rmc,
            SentenceKind::Vtg => self.vtg,
            SentenceKind::Gst => self.gst,
            SentenceKind::Hdt => self.hdt,
            SentenceKind::Ths => self.ths,
            SentenceKind::Zda => self.zda,
        }
    }

    /// The kinds sent at epoch number `epoch` (counting from 0, which sends all).
    pub fn due(&self, epoch: u64) -> SentenceSet {
        SentenceKind::ALL
            .into_iter()
            .filter(|k| {
                let n = self.every(*k);
                n > 0 && epoch.is_multiple_of(u64::from(n))
            })
            .fold(SentenceSet::EMPTY, SentenceSet::with)
    }

    /// Every kind ever sent (what goes out at epoch 0).
    pub fn enabled(&self) -> SentenceSet {
        self.due(0)
    }
}

/// Writer configuration (a TOML table in the simulator's GPS device).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WriterConfig {
    pub talker: Talker,
    /// Epochs per second.
    pub rate_hz: f64,
    /// Serial line rate the output must fit (8N1).
    pub baud: u32,
    /// Decimals of the minutes of latitude and longitude (4-9; see the module docs).
    pub minute_decimals: u8,
    pub schedule: Schedule,
}

impl Default for WriterConfig {
    fn default() -> Self {
        Self {
            talker: Talker::GN,
            rate_hz: 10.0,
            baud: 115_200,
            minute_decimals: 7,
            schedule: Schedule::default(),
        }
    }
}

/// How a configuration uses its serial line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkBudget {
    /// Longest possible epoch (all enabled sentences at their widest), bytes.
    pub bytes_per_epoch: usize,
    /// Time to send that epoch at the baud rate.
    pub burst: Duration,
    /// Time between epochs.
    pub period: Duration,
    /// `burst / period`.
    pub utilisation: f64,
}

/// Check that the widest epoch of `config` fits between two epochs at its baud rate.
pub fn link_budget(config: &WriterConfig) -> Result<LinkBudget, NmeaError> {
    check_config(config)?;
    let enabled = config.schedule.enabled();
    let bytes_per_epoch: usize = enabled
        .iter()
        .map(|k| max_sentence_len(k, config.minute_decimals))
        .sum();
    let burst = transmit_time(bytes_per_epoch, config.baud);
    let period_s = 1.0 / config.rate_hz;
    let burst_s = burst.as_secs_f64();
    if burst_s > period_s {
        let min_baud = ((bytes_per_epoch as f64) * f64::from(BITS_PER_BYTE_8N1) * config.rate_hz)
            .ceil() as u64;
        return Err(NmeaError::BaudTooLow {
            sentences: enabled,
            rate_hz: config.rate_hz,
            baud: config.baud,
            bytes_per_epoch,
            burst_ms: burst_s * 1e3,
            period_ms: period_s * 1e3,
            min_baud,
        });
    }
    Ok(LinkBudget {
        bytes_per_epoch,
        burst,
        period: Duration::from_secs_f64(period_s),
        utilisation: burst_s / period_s,
    })
}

fn check_config(config: &WriterConfig) -> Result<(), NmeaError> {
    if !(config.rate_hz.is_finite() && config.rate_hz > 0.0 && config.rate_hz <= 100.0) {
        return Err(NmeaError::InvalidConfig {
            field: "rate_hz",
            reason: format!("{} is outside (0, 100]", config.rate_hz),
        });
    }
    if config.baud == 0 {
        return Err(NmeaError::InvalidConfig {
            field: "baud",
            reason: "must be positive".into(),
        });
    }
    if !(4..=9).contains(&config.minute_decimals) {
        return Err(NmeaError::InvalidConfig {
            field: "minute_decimals",
            reason: format!("{} is outside 4..=9", config.minute_decimals),
        });
    }
    if config.schedule.enabled().is_empty() {
        return Err(NmeaError::InvalidConfig {
            field: "schedule",
            reason: "no sentence is enabled".into(),
        });
    }
    Ok(())
}

/// The widest fix the validation admits, for the link budget.
fn widest_fix() -> GpsFix {
    GpsFix {
        lat_deg: -89.5,
        lon_deg: -179.5,
        ellipsoid_height_m: -1200.0,
        geoid_separation_m: -200.0,
        quality: FixQuality::RtkFixed,
        satellites: 99,
        hdop: 99.99,
        speed_mps: MAX_SPEED_MPS,
        course_deg: 359.0,
        heading_deg: Some(359.0),
        accuracy: Some(Accuracy {
            rms_m: 9999.0,
            semi_major_m: 9999.0,
            semi_minor_m: 9999.0,
            orientation_deg: 179.0,
            lat_sigma_m: 9999.0,
            lon_sigma_m: 9999.0,
            alt_sigma_m: 9999.0,
        }),
        correction_age_s: Some(999.0),
        station_id: Some(1023),
        nav_status: NavStatus::Caution,
    }
}

/// Longest sentence of a kind, bytes including CR LF.
pub fn max_sentence_len(kind: SentenceKind, minute_decimals: u8) -> usize {
    let utc = DateTime::<Utc>::UNIX_EPOCH;
    let f = Formatter {
        talker: Talker::GN,
        minute_decimals,
    };
    f.sentence(kind, &widest_fix(), utc).len()
}

const MAX_SPEED_MPS: f64 = 500.0;
const ALT_RANGE: (f64, f64) = (-1000.0, 20_000.0);

fn check(
    field: &'static str,
    value: f64,
    min: f64,
    max: f64,
    range: &'static str,
) -> Result<(), NmeaError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(())
    } else {
        Err(NmeaError::InvalidFix {
            field,
            value,
            range,
        })
    }
}

/// Check that a fix can be written (finite values within the sentence fields' widths).
pub(crate) fn validate_fix(fix: &GpsFix) -> Result<(), NmeaError> {
    check("lat_deg", fix.lat_deg, -90.0, 90.0, "[-90, 90]")?;
    check("lon_deg", fix.lon_deg, -180.0, 180.0, "[-180, 180]")?;
    check(
        "geoid_separation_m",
        fix.geoid_separation_m,
        -200.0,
        200.0,
        "[-200, 200]",
    )?;
    check(
        "ellipsoid_height_m",
        fix.ellipsoid_height_m,
        -1e6,
        1e6,
        "finite",
    )?;
    check(
        "altitude_msl_m (ellipsoid_height_m - geoid_separation_m)",
        fix.altitude_msl_m(),
        ALT_RANGE.0,
        ALT_RANGE.1,
        "[-1000, 20000]",
    )?;
    check(
        "satellites",
        f64::from(fix.satellites),
        0.0,
        99.0,
        "[0, 99]",
    )?;
    check("hdop", fix.hdop, 0.0, 99.99, "[0, 99.99]")?;
    check("speed_mps", fix.speed_mps, 0.0, MAX_SPEED_MPS, "[0, 500]")?;
    check("course_deg", fix.course_deg, -1e6, 1e6, "finite")?;
    if let Some(h) = fix.heading_deg {
        check("heading_deg", h, -1e6, 1e6, "finite")?;
    }
    if let Some(a) = fix.accuracy {
        for (field, v) in [
            ("accuracy.rms_m", a.rms_m),
            ("accuracy.semi_major_m", a.semi_major_m),
            ("accuracy.semi_minor_m", a.semi_minor_m),
            ("accuracy.lat_sigma_m", a.lat_sigma_m),
            ("accuracy.lon_sigma_m", a.lon_sigma_m),
            ("accuracy.alt_sigma_m", a.alt_sigma_m),
        ] {
            check(field, v, 0.0, 9999.999, "[0, 9999.999]")?;
        }
        check(
            "accuracy.orientation_deg",
            a.orientation_deg,
            -1e6,
            1e6,
            "finite",
        )?;
    }
    if let Some(age) = fix.correction_age_s {
        check("correction_age_s", age, 0.0, 999.9, "[0, 999.9]")?;
    }
    if let Some(id) = fix.station_id {
        check("station_id", f64::from(id), 0.0, 1023.0, "[0, 1023]")?;
    }
    Ok(())
}

/// ZDA carries a four-digit year.
fn validate_utc(utc: DateTime<Utc>) -> Result<(), NmeaError> {
    let year = round_centis(utc).year();
    if (0..=9999).contains(&year) {
        Ok(())
    } else {
        Err(NmeaError::InvalidFix {
            field: "utc (year)",
            value: f64::from(year),
            range: "[0, 9999]",
        })
    }
}

/// `v` in decimal, zero-padded to at least `width` digits, onto `out` (what
/// `{v:0width$}` writes, without the formatting machinery: a GPS epoch writes some
/// forty numbers).
fn push_padded(out: &mut String, v: u64, width: usize) {
    let mut digits = [0u8; 20];
    let (mut n, mut k) = (v, digits.len());
    loop {
        k -= 1;
        digits[k] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    for _ in digits.len() - k..width {
        out.push('0');
    }
    out.extend(digits[k..].iter().map(|&d| char::from(d)));
}

/// `units` as a decimal of `decimals` decimals (`units / 10^decimals`) onto `out`.
fn push_decimal(out: &mut String, units: u64, decimals: u32) {
    let p = 10u64.pow(decimals);
    push_padded(out, units / p, 0);
    if decimals > 0 {
        out.push('.');
        push_padded(out, units % p, decimals as usize);
    }
}

/// Fixed-point decimal of a finite, bounded value (`-0.000` prints as `0.000`).
fn fixed(v: f64, decimals: u32) -> String {
    let p = 10u64.pow(decimals);
    let units = (v.abs() * p as f64).round() as u64;
    let mut out = String::with_capacity(24);
    if v < 0.0 && units > 0 {
        out.push('-');
    }
    push_decimal(&mut out, units, decimals);
    out
}

/// An angle in `[0, 360)` with `decimals` decimals, wrapping after rounding
/// (359.9996 with 3 decimals is 0.000, not 360.000).
fn angle(deg: f64, decimals: u32) -> String {
    let p = 10u64.pow(decimals);
    let units = (normalize_deg_360(deg) * p as f64).round() as u64 % (360 * p);
    let mut out = String::with_capacity(24);
    push_decimal(&mut out, units, decimals);
    out
}

/// Degrees and decimal minutes, `ddmm.mmmm` (`width` 2) or `dddmm.mmmm` (3), rounded
/// in integer units so that minutes never read 60.
fn deg_min(deg: f64, width: usize, decimals: u8) -> String {
    let d = u32::from(decimals);
    let p = 10u64.pow(d);
    let total = (deg.abs() * 60.0 * p as f64).round() as u64;
    let whole = total / (60 * p);
    let rem = total % (60 * p);
    let mut out = String::with_capacity(24);
    push_padded(&mut out, whole, width);
    push_padded(&mut out, rem / p, 2);
    out.push('.');
    push_padded(&mut out, rem % p, d as usize);
    out
}

/// Time of day `hhmmss.ss`, rounded to the centisecond.
fn hms(utc: DateTime<Utc>) -> String {
    let t = round_centis(utc);
    let cs = (t.nanosecond() / 10_000_000).min(99);
    let mut out = String::with_capacity(9);
    for v in [t.hour(), t.minute(), t.second()] {
        push_padded(&mut out, u64::from(v), 2);
    }
    out.push('.');
    push_padded(&mut out, u64::from(cs), 2);
    out
}

fn round_centis(utc: DateTime<Utc>) -> DateTime<Utc> {
    let ns = i64::from(utc.nanosecond() % 1_000_000_000);
    let rem = ns % 10_000_000;
    let delta = if rem >= 5_000_000 {
        10_000_000 - rem
    } else {
        -rem
    };
    utc.checked_add_signed(TimeDelta::nanoseconds(delta))
        .unwrap_or(utc)
}

struct Formatter {
    talker: Talker,
    minute_decimals: u8,
}

impl Formatter {
    fn sentence(&self, kind: SentenceKind, fix: &GpsFix, utc: DateTime<Utc>) -> String {
        let mut body = String::with_capacity(MAX_SENTENCE_LEN);
        body.push_str(self.talker.as_str());
        body.push_str(kind.formatter());
        body.push(',');
        let valid = fix.quality.has_position();
        // Writing to a String cannot fail.
        let _ = match kind {
            SentenceKind::Gga => self.gga(&mut body, fix, utc, valid),
            SentenceKind::Rmc => self.rmc(&mut body, fix, utc, valid),
            SentenceKind::Vtg => {
                if valid {
                    write!(
                        body,
                        "{},T,,M,{},N,{},K,{}",
                        angle(fix.course_deg, 2),
                        fixed(fix.speed_mps * KNOTS_PER_MPS, 3),
                        fixed(fix.speed_mps * 3.6, 3),
                        fix.quality.mode().as_char()
                    )
                } else {
                    write!(body, ",T,,M,,N,,K,N")
                }
            }
            SentenceKind::Gst => {
                let _ = write!(body, "{}", hms(utc));
                match (fix.accuracy, valid) {
                    (Some(a), true) => write!(
                        body,
                        ",{},{},{},{},{},{},{}",
                        fixed(a.rms_m, 3),
                        fixed(a.semi_major_m, 3),
                        fixed(a.semi_minor_m, 3),
                        fixed(normalize_deg_360(a.orientation_deg) % 180.0, 2),
                        fixed(a.lat_sigma_m, 3),
                        fixed(a.lon_sigma_m, 3),
                        fixed(a.alt_sigma_m, 3)
                    ),
                    _ => write!(body, ",,,,,,,"),
                }
            }
            SentenceKind::Hdt => match fix.heading_deg {
                Some(h) => write!(body, "{},T", angle(h, 3)),
                None => write!(body, ",T"),
            },
            SentenceKind::Ths => match fix.heading_deg {
                Some(h) => write!(
                    body,
                    "{},{}",
                    angle(h, 3),
                    HeadingMode::Autonomous.as_char()
                ),
                None => write!(body, ",{}", HeadingMode::NotValid.as_char()),
            },
            SentenceKind::Zda => {
                let t = round_centis(utc);
                write!(
                    body,
                    "{},{:02},{:02},{:04},00,00",
                    hms(utc),
                    t.day(),
                    t.month(),
                    t.year()
                )
            }
        };
        let sum = checksum(body.as_bytes());
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        let mut out = String::with_capacity(body.len() + 6);
        out.push('$');
        out.push_str(&body);
        out.push('*');
        out.push(char::from(HEX[usize::from(sum >> 4)]));
        out.push(char::from(HEX[usize::from(sum & 0xf)]));
        out.push_str("\r\n");
        out
    }

    fn lat_lon(&self, body: &mut String, fix: &GpsFix) -> std::fmt::Result {
        write!(
            body,
            "{},{},{},{}",
            deg_min(fix.lat_deg, 2, self.minute_decimals),
            if fix.lat_deg < 0.0 { 'S' } else { 'N' },
            deg_min(fix.lon_deg, 3, self.minute_decimals),
            if fix.lon_deg < 0.0 { 'W' } else { 'E' }
        )
    }

    fn gga(
        &self,
        body: &mut String,
        fix: &GpsFix,
        utc: DateTime<Utc>,
        valid: bool,
    ) -> std::fmt::Result {
        write!(body, "{},", hms(utc))?;
        if valid {
            self.lat_lon(body, fix)?;
        } else {
            body.push_str(",,,");
        }
        write!(
            body,
            ",{},{:02},{},",
            fix.quality.gga_digit(),
            fix.satellites,
            fixed(fix.hdop, 2)
        )?;
        if valid {
            write!(
                body,
                "{},M,{},M,",
                fixed(fix.altitude_msl_m(), 3),
                fixed(fix.geoid_separation_m, 3)
            )?;
            if let Some(age) = fix.correction_age_s {
                body.push_str(&fixed(age, 1));
            }
            body.push(',');
            if let Some(id) = fix.station_id {
                write!(body, "{id:04}")?;
            }
            Ok(())
        } else {
            write!(body, ",,,,,")
        }
    }

    fn rmc(
        &self,
        body: &mut String,
        fix: &GpsFix,
        utc: DateTime<Utc>,
        valid: bool,
    ) -> std::fmt::Result {
        let t = round_centis(utc);
        write!(body, "{},{},", hms(utc), if valid { 'A' } else { 'V' })?;
        if valid {
            self.lat_lon(body, fix)?;
            write!(
                body,
                ",{},{},",
                fixed(fix.speed_mps * KNOTS_PER_MPS, 3),
                angle(fix.course_deg, 2)
            )?;
        } else {
            body.push_str(",,,,,,");
        }
        write!(
            body,
            "{:02}{:02}{:02},,,{},{}",
            t.day(),
            t.month(),
            t.year().rem_euclid(100),
            fix.quality.mode().as_char(),
            fix.nav_status.as_char()
        )
    }
}

/// The UTC clock of a run: a UTC epoch plus the simulation time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UtcClock {
    pub epoch: DateTime<Utc>,
}

impl UtcClock {
    pub fn new(epoch: DateTime<Utc>) -> Self {
        Self { epoch }
    }

    /// UTC at simulation time `sim_time` after the epoch.
    pub fn at(&self, sim_time: Duration) -> Result<DateTime<Utc>, NmeaError> {
        let err = || NmeaError::TimeOutOfRange {
            sim_time_s: sim_time.as_secs_f64(),
        };
        let delta = TimeDelta::from_std(sim_time).map_err(|_| err())?;
        self.epoch.checked_add_signed(delta).ok_or_else(err)
    }
}

/// Writes the scheduled sentences of each epoch.
#[derive(Debug, Clone)]
pub struct NmeaWriter {
    config: WriterConfig,
    budget: LinkBudget,
    epoch: u64,
}

impl NmeaWriter {
    /// A writer for `config`; refuses a configuration whose widest epoch does not fit
    /// its baud rate (see [`link_budget`]).
    pub fn new(config: WriterConfig) -> Result<Self, NmeaError> {
        let budget = link_budget(&config)?;
        Ok(Self {
            config,
            budget,
            epoch: 0,
        })
    }

    pub fn config(&self) -> &WriterConfig {
        &self.config
    }

    pub fn budget(&self) -> LinkBudget {
        self.budget
    }

    /// Epochs written so far.
    pub fn epochs(&self) -> u64 {
        self.epoch
    }

    fn formatter(&self) -> Formatter {
        Formatter {
            talker: self.config.talker,
            minute_decimals: self.config.minute_decimals,
        }
    }

    /// Append the sentences due at this epoch (CR LF terminated) to `out` and advance
    /// to the next epoch; returns the kinds written. An invalid fix writes nothing
    /// and does not advance.
    pub fn write_epoch(
        &mut self,
        fix: &GpsFix,
        utc: DateTime<Utc>,
        out: &mut String,
    ) -> Result<SentenceSet, NmeaError> {
        validate_fix(fix)?;
        validate_utc(utc)?;
        let due = self.config.schedule.due(self.epoch);
        let f = self.formatter();
        for kind in due.iter() {
            out.push_str(&f.sentence(kind, fix, utc));
        }
        self.epoch += 1;
        Ok(due)
    }

    /// One sentence of any kind, CR LF terminated, regardless of the schedule.
    pub fn sentence(
        &self,
        kind: SentenceKind,
        fix: &GpsFix,
        utc: DateTime<Utc>,
    ) -> Result<String, NmeaError> {
        validate_fix(fix)?;
        validate_utc(utc)?;
        Ok(self.formatter().sentence(kind, fix, utc))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_point_formatting() {
        assert_eq!(fixed(-0.0004, 3), "0.000");
        assert_eq!(fixed(-1.2345, 3), "-1.235");
        assert_eq!(fixed(12.0, 1), "12.0");
        assert_eq!(angle(359.9996, 3), "0.000");
        assert_eq!(angle(-90.0, 2), "270.00");
    }

    #[test]
    fn numbers_are_padded_as_format_pads_them() {
        for v in [0u64, 1, 9, 10, 99, 100, 12_345, 999_999_999, u64::MAX] {
            for width in 0..22 {
                let mut out = String::from("x");
                push_padded(&mut out, v, width);
                assert_eq!(out, format!("x{v:0width$}"));
            }
        }
        for (v, d) in [
            (0.0, 2),
            (-12.5, 1),
            (7.25, 0),
            (1e6 + 0.001, 3),
            (-0.004, 2),
        ] {
            let p = 10u64.pow(d);
            let units = (f64::abs(v) * p as f64).round() as u64;
            let sign = if v < 0.0 && units > 0 { "-" } else { "" };
            let expected = if d == 0 {
                format!("{sign}{units}")
            } else {
                format!("{sign}{}.{:0w$}", units / p, units % p, w = d as usize)
            };
            assert_eq!(fixed(v, d), expected);
        }
    }

    #[test]
    fn minutes_never_read_sixty() {
        assert_eq!(deg_min(48.999_999_999_99, 2, 7), "4900.0000000");
        assert_eq!(deg_min(11.5, 3, 7), "01130.0000000");
        assert_eq!(deg_min(-33.25, 2, 4), "3315.0000");
    }

    #[test]
    fn widest_fix_is_valid() {
        assert!(validate_fix(&widest_fix()).is_ok());
        for k in SentenceKind::ALL {
            assert!(max_sentence_len(k, 9) <= MAX_SENTENCE_LEN + 2, "{k}");
        }
    }
}
