//! [`ScanData`] to and from [`LaserFrame`]: the angle, range, intensity and time
//! conventions of the [parent module](super) in code.

use chrono::{Datelike, NaiveDate, Timelike};

use super::fields::EncodeError;
use super::scandata::{Channel, DeviceTime, ScanData, check_flex_text};
use crate::laser::{LaserError, LaserFrame, MAX_BEAMS};

/// Raw distance values below this are SICK's codes for invalid measurements.
pub const FIRST_VALID_RAW: u16 = 16;
/// The raw distance written for "no echo" (and read as `f32::INFINITY`).
pub const RAW_NO_ECHO: u16 = 0;
/// The raw distance written for a dropout (SICK: "dazzled"; read as `f32::NAN`).
pub const RAW_DROPOUT: u16 = 1;
/// SICK's angle of the scanner's forward axis, degrees.
pub const SICK_FORWARD_DEG: f64 = 90.0;

/// How intensities travel in the scan telegram.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RssiChannel {
    /// No remission channel: the driver's frames have intensity 0.
    None,
    /// `RSSI1` as an 8-bit channel, as LMS1xx and TiM5xx send it (0..=255).
    #[default]
    Bits8,
    /// `RSSI1` as a 16-bit channel, as LMS5xx send it (0..=65535).
    Bits16,
}

/// Device-side settings for turning a frame into a scan telegram.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeOptions {
    /// The telegram's device number.
    pub device_number: u16,
    /// The telegram's serial number.
    pub serial_number: u32,
    /// Millimetres per raw distance unit: 1.0 (LMS1xx, TiM), 2.0 (LMS5xx long range).
    pub scale_factor: f32,
    /// Whether and how intensities are sent.
    pub rssi: RssiChannel,
    /// Write the time-stamp block (the frame's `stamp_ns` as UTC, µs resolution).
    pub time_stamp: bool,
    /// Write the device-name block with this name.
    pub device_name: Option<String>,
}

impl Default for EncodeOptions {
    /// An LMS111 as the simulator's laser: mm, 8-bit RSSI, with the time stamp.
    fn default() -> Self {
        EncodeOptions {
            device_number: 1,
            serial_number: 0x0089_A27F,
            scale_factor: 1.0,
            rssi: RssiChannel::Bits8,
            time_stamp: true,
            device_name: None,
        }
    }
}

/// Driver-side settings for turning a scan telegram into a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodeOptions {
    /// The frame's `range_min`, metres (the telegram does not carry it).
    pub range_min: f32,
    /// The frame's `range_max`, metres.
    pub range_max: f32,
    /// The distance channel to read (`DIST1`: the first echo).
    pub distance_channel: String,
    /// The remission channel to read (`RSSI1`), 16- or 8-bit; absent means intensity 0.
    pub intensity_channel: String,
}

impl Default for DecodeOptions {
    /// An LMS111: 0.5 to 20 m, first echo.
    fn default() -> Self {
        DecodeOptions {
            range_min: 0.5,
            range_max: 20.0,
            distance_channel: "DIST1".into(),
            intensity_channel: "RSSI1".into(),
        }
    }
}

/// Why a frame could not become a scan telegram, or a telegram a frame.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// The frame failed its own validation.
    #[error("laser frame: {0}")]
    Frame(#[from] LaserError),
    /// SICK scans counter-clockwise; a frame with a negative increment has no telegram.
    #[error("laser frame angle_increment {0} rad is negative; a SICK scan runs counter-clockwise")]
    Clockwise(f32),
    /// A value that does not fit its telegram field.
    #[error("{field} = {value} does not fit the scan telegram")]
    OutOfRange { field: &'static str, value: f64 },
    /// A scale factor that is zero, negative or not finite.
    #[error("{channel} scale factor {value} must be a positive finite number")]
    ScaleFactor { channel: String, value: f32 },
    /// A scale offset that is not finite.
    #[error("{channel} scale factor offset {value} is not finite")]
    ScaleOffset { channel: String, value: f32 },
    /// A stamp the time-stamp block cannot hold.
    #[error("stamp {0} ns since the epoch cannot be written as a date")]
    Stamp(u64),
    /// The scan lacks the distance channel.
    #[error("the scan has no 16-bit {0} channel (it has: {1})")]
    NoChannel(String, String),
    /// A channel with another number of values than the distances.
    #[error("channel {content} has {found} values, the distances {expected}")]
    ChannelLength {
        content: String,
        found: usize,
        expected: usize,
    },
    /// The distance channel is empty.
    #[error("the {0} channel has no values")]
    NoBeams(String),
    /// More beams than a frame holds.
    #[error("the scan has {0} beams, a laser frame holds at most {max}", max = MAX_BEAMS)]
    TooManyBeams(usize),
    /// The configured device name cannot be written.
    #[error(transparent)]
    Text(#[from] EncodeError),
}

fn fits<T: TryFrom<i64>>(field: &'static str, value: f64) -> Result<T, ConvertError> {
    let r = value.round();
    if !r.is_finite() || r < i64::MIN as f64 || r > i64::MAX as f64 {
        return Err(ConvertError::OutOfRange { field, value });
    }
    T::try_from(r as i64).map_err(|_| ConvertError::OutOfRange { field, value })
}

/// The raw distance of a range in metres; see the [parent module](super#ranges).
pub fn raw_distance(range: f32, range_min: f32, range_max: f32, mm_per_unit: f32) -> u16 {
    if range.is_nan() {
        return RAW_DROPOUT;
    }
    if !range.is_finite() || range < range_min || range > range_max {
        return RAW_NO_ECHO;
    }
    let raw = (f64::from(range) * 1000.0 / f64::from(mm_per_unit)).round();
    if raw < f64::from(FIRST_VALID_RAW) || raw > f64::from(u16::MAX) {
        RAW_NO_ECHO
    } else {
        raw as u16
    }
}

/// The range in metres of a raw distance; see the [parent module](super#ranges).
pub fn range_of_raw(raw: u16, scale_factor: f32, scale_offset: f32) -> f32 {
    if raw == RAW_NO_ECHO {
        return f32::INFINITY;
    }
    if raw < FIRST_VALID_RAW {
        return f32::NAN;
    }
    let mm = f64::from(raw) * f64::from(scale_factor) + f64::from(scale_offset);
    if mm >= 0.0 {
        (mm / 1000.0) as f32
    } else {
        f32::NAN
    }
}

/// The time-stamp block of a UNIX time in nanoseconds (UTC, truncated to µs).
pub fn device_time_of(stamp_ns: u64) -> Result<DeviceTime, ConvertError> {
    let secs =
        i64::try_from(stamp_ns / 1_000_000_000).map_err(|_| ConvertError::Stamp(stamp_ns))?;
    let nanos = (stamp_ns % 1_000_000_000) as u32;
    let t = chrono::DateTime::from_timestamp(secs, nanos).ok_or(ConvertError::Stamp(stamp_ns))?;
    Ok(DeviceTime {
        year: u16::try_from(t.year()).map_err(|_| ConvertError::Stamp(stamp_ns))?,
        month: t.month() as u8,
        day: t.day() as u8,
        hour: t.hour() as u8,
        minute: t.minute() as u8,
        second: t.second() as u8,
        microsecond: nanos / 1000,
    })
}

/// The UNIX time in nanoseconds of a time-stamp block, if it is a valid date and
/// time after 1970.
pub fn stamp_of_device_time(t: &DeviceTime) -> Option<u64> {
    let ns = NaiveDate::from_ymd_opt(i32::from(t.year), u32::from(t.month), u32::from(t.day))?
        .and_hms_micro_opt(
            u32::from(t.hour),
            u32::from(t.minute),
            u32::from(t.second),
            t.microsecond,
        )?
        .and_utc()
        .timestamp_nanos_opt()?;
    u64::try_from(ns).ok()
}

/// The scan telegram of a frame. Header fields the frame does not know get neutral
/// values a server overwrites: telegram and scan counter = `sequence` mod 2^16, time
/// since start-up = `stamp_ns` in µs mod 2^32, transmission = that plus `scan_time`.
pub fn scan_from_frame(frame: &LaserFrame, opts: &EncodeOptions) -> Result<ScanData, ConvertError> {
    frame.validate()?;
    let scale = opts.scale_factor;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(ConvertError::ScaleFactor {
            channel: "DIST1".into(),
            value: scale,
        });
    }
    let geometry = ScanGeometry::of(frame)?;
    let (channels16, channels8) = channels_of(frame, opts, &geometry);
    let name = match &opts.device_name {
        Some(n) => {
            let bytes: Vec<u8> = n.bytes().collect();
            check_flex_text("device name", &bytes)?;
            Some(bytes)
        }
        None => None,
    };
    let startup_us = (frame.stamp_ns / 1000) as u32;
    let scan_us = (f64::from(frame.scan_time) * 1e6).round() as u32;
    Ok(ScanData {
        version: 1,
        device_number: opts.device_number,
        serial_number: opts.serial_number,
        device_status: [0, 0],
        telegram_counter: frame.sequence as u16,
        scan_counter: frame.sequence as u16,
        time_since_startup_us: startup_us,
        time_of_transmission_us: startup_us.wrapping_add(scan_us),
        inputs: [0, 0],
        outputs: [0, 0],
        layer_angle: 0,
        scan_frequency: geometry.scan_frequency,
        measurement_frequency: geometry.measurement_frequency,
        encoders: Vec::new(),
        channels16,
        channels8,
        position: None,
        name,
        comment: None,
        time: if opts.time_stamp {
            Some(device_time_of(frame.stamp_ns)?)
        } else {
            None
        },
        event: None,
    })
}

/// A frame's angles and timing in the telegram's units.
struct ScanGeometry {
    /// 1/10000 degree, SICK's zero ahead.
    start_angle: i32,
    /// 1/10000 degree.
    angular_step: u32,
    /// 1/100 Hz; 0 when the frame has no scan time.
    scan_frequency: u32,
    /// 100 Hz; 0 when the frame has no time increment.
    measurement_frequency: u32,
}

impl ScanGeometry {
    /// The geometry of a counter-clockwise frame, each value within its field.
    fn of(frame: &LaserFrame) -> Result<ScanGeometry, ConvertError> {
        if frame.angle_increment < 0.0 {
            return Err(ConvertError::Clockwise(frame.angle_increment));
        }
        let start_angle: i32 = fits(
            "start angle (1/10000 deg)",
            (f64::from(frame.angle_min).to_degrees() + SICK_FORWARD_DEG) * 10_000.0,
        )?;
        let angular_step: u32 = fits(
            "angular step (1/10000 deg)",
            f64::from(frame.angle_increment).to_degrees() * 10_000.0,
        )?;
        let scan_frequency: u32 = if frame.scan_time > 0.0 {
            fits(
                "scan frequency (1/100 Hz)",
                100.0 / f64::from(frame.scan_time),
            )?
        } else {
            0
        };
        let measurement_frequency: u32 = if frame.time_increment > 0.0 {
            fits(
                "measurement frequency (100 Hz)",
                1.0 / (f64::from(frame.time_increment) * 100.0),
            )?
        } else {
            0
        };
        Ok(ScanGeometry {
            start_angle,
            angular_step,
            scan_frequency,
            measurement_frequency,
        })
    }

    /// A channel of `data` over the scan, unscaled.
    fn channel<T>(&self, content: &str, data: Vec<T>) -> Channel<T> {
        Channel {
            content: content.to_owned(),
            scale_factor: 1.0,
            scale_offset: 0.0,
            start_angle: self.start_angle,
            angular_step: self.angular_step,
            data,
        }
    }
}

/// The frame's 16-bit and 8-bit channels: the distances (DIST1, at the scale
/// factor), and the intensities (RSSI1) when asked for, clamped to their width.
fn channels_of(
    frame: &LaserFrame,
    opts: &EncodeOptions,
    geometry: &ScanGeometry,
) -> (Vec<Channel<u16>>, Vec<Channel<u8>>) {
    let scale = opts.scale_factor;
    let dist: Vec<u16> = frame
        .ranges()
        .iter()
        .map(|&r| raw_distance(r, frame.range_min, frame.range_max, scale))
        .collect();
    let mut channels16 = vec![Channel {
        scale_factor: scale,
        ..geometry.channel("DIST1", dist)
    }];
    let mut channels8 = Vec::new();
    let rssi = |max: f32| {
        frame
            .intensities()
            .iter()
            .map(move |&v| v.clamp(0.0, max).round())
    };
    match opts.rssi {
        RssiChannel::None => {}
        RssiChannel::Bits8 => {
            channels8.push(geometry.channel("RSSI1", rssi(255.0).map(|v| v as u8).collect()))
        }
        RssiChannel::Bits16 => {
            channels16.push(geometry.channel("RSSI1", rssi(65535.0).map(|v| v as u16).collect()))
        }
    }
    (channels16, channels8)
}

fn channel_names(scan: &ScanData) -> String {
    let names: Vec<&str> = scan
        .channels16
        .iter()
        .map(|c| c.content.as_str())
        .chain(scan.channels8.iter().map(|c| c.content.as_str()))
        .collect();
    if names.is_empty() {
        "no channels".into()
    } else {
        names.join(", ")
    }
}

fn check_scale<T>(ch: &Channel<T>) -> Result<(), ConvertError> {
    if !(ch.scale_factor.is_finite() && ch.scale_factor > 0.0) {
        return Err(ConvertError::ScaleFactor {
            channel: ch.content.clone(),
            value: ch.scale_factor,
        });
    }
    if !ch.scale_offset.is_finite() {
        return Err(ConvertError::ScaleOffset {
            channel: ch.content.clone(),
            value: ch.scale_offset,
        });
    }
    Ok(())
}

/// The laser frame of a scan telegram. `sequence` is the scan counter (16 bits; the
/// driver unwraps it); `stamp_ns` is the time-stamp block's time when the telegram has
/// a valid one, else 0 (the driver then stamps with the host clock).
pub fn frame_from_scan(scan: &ScanData, opts: &DecodeOptions) -> Result<LaserFrame, ConvertError> {
    let dist = scan.channel16(&opts.distance_channel).ok_or_else(|| {
        ConvertError::NoChannel(opts.distance_channel.clone(), channel_names(scan))
    })?;
    check_scale(dist)?;
    let n = dist.data.len();
    if n == 0 {
        return Err(ConvertError::NoBeams(dist.content.clone()));
    }
    if n > MAX_BEAMS {
        return Err(ConvertError::TooManyBeams(n));
    }
    let mut frame = LaserFrame {
        count: n as u32,
        sequence: u64::from(scan.scan_counter),
        stamp_ns: scan
            .time
            .as_ref()
            .and_then(stamp_of_device_time)
            .unwrap_or(0),
        angle_min: (f64::from(dist.start_angle) / 10_000.0 - SICK_FORWARD_DEG).to_radians() as f32,
        angle_increment: (f64::from(dist.angular_step) / 10_000.0).to_radians() as f32,
        range_min: opts.range_min,
        range_max: opts.range_max,
        ..LaserFrame::default()
    };
    if scan.scan_frequency > 0 {
        frame.scan_time = (100.0 / f64::from(scan.scan_frequency)) as f32;
    }
    if scan.measurement_frequency > 0 {
        // Some firmware reports Hz instead of 100 Hz (as sick_scan notes): nothing
        // measures faster than 1 MHz, so a larger number is taken as Hz.
        let hz = if scan.measurement_frequency > 10_000 {
            f64::from(scan.measurement_frequency)
        } else {
            f64::from(scan.measurement_frequency) * 100.0
        };
        frame.time_increment = (1.0 / hz) as f32;
    }
    for (slot, &raw) in frame.ranges.iter_mut().zip(&dist.data) {
        *slot = range_of_raw(raw, dist.scale_factor, dist.scale_offset);
    }
    let intensity = |raw: f64, factor: f32, offset: f32| {
        let v = (raw * f64::from(factor) + f64::from(offset)) as f32;
        if v.is_finite() && v >= 0.0 { v } else { 0.0 }
    };
    let want = opts.intensity_channel.as_str();
    if let Some(ch) = scan.channel16(want) {
        check_length(ch, n)?;
        for (slot, &raw) in frame.intensities.iter_mut().zip(&ch.data) {
            *slot = intensity(f64::from(raw), ch.scale_factor, ch.scale_offset);
        }
    } else if let Some(ch) = scan.channel8(want) {
        check_length(ch, n)?;
        for (slot, &raw) in frame.intensities.iter_mut().zip(&ch.data) {
            *slot = intensity(f64::from(raw), ch.scale_factor, ch.scale_offset);
        }
    }
    frame.validate()?;
    Ok(frame)
}

fn check_length<T>(ch: &Channel<T>, expected: usize) -> Result<(), ConvertError> {
    if ch.data.len() != expected {
        return Err(ConvertError::ChannelLength {
            content: ch.content.clone(),
            found: ch.data.len(),
            expected,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reserved_raw_values() {
        assert_eq!(range_of_raw(0, 1.0, 0.0), f32::INFINITY);
        assert!(range_of_raw(1, 1.0, 0.0).is_nan());
        assert!(range_of_raw(15, 1.0, 0.0).is_nan());
        assert_eq!(range_of_raw(16, 1.0, 0.0), 0.016);
        assert_eq!(range_of_raw(1000, 2.0, 0.0), 2.0);
        assert_eq!(raw_distance(f32::INFINITY, 0.5, 20.0, 1.0), 0);
        assert_eq!(raw_distance(f32::NAN, 0.5, 20.0, 1.0), 1);
        assert_eq!(raw_distance(20.5, 0.5, 20.0, 1.0), 0);
        assert_eq!(raw_distance(0.4, 0.5, 20.0, 1.0), 0);
        assert_eq!(raw_distance(0.010, 0.0, 80.0, 1.0), 0);
        assert_eq!(raw_distance(70.0, 0.0, 80.0, 1.0), 0);
        assert_eq!(raw_distance(70.0, 0.0, 80.0, 2.0), 35_000);
        assert_eq!(raw_distance(1.2345, 0.5, 20.0, 1.0), 1235);
    }

    #[test]
    fn device_time_round_trips_to_the_microsecond() {
        let stamp = 1_777_903_200_123_456_789;
        let t = device_time_of(stamp).unwrap();
        assert_eq!((t.year, t.month, t.day), (2026, 5, 4));
        assert_eq!(t.microsecond, 123_456);
        assert_eq!(stamp_of_device_time(&t), Some(stamp - 789));
        assert_eq!(stamp_of_device_time(&DeviceTime { month: 13, ..t }), None);
    }
}
