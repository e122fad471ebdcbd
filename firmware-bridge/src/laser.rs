//! The laser wire: a versioned `#[repr(C)]` scan frame with ROS `sensor_msgs/LaserScan`
//! semantics, published over iceoryx2 shared memory.
//!
//! # The frame
//!
//! [`LaserFrame`] holds up to [`MAX_BEAMS`] (1081: a 270° scanner at 0.25°) beams;
//! `count` says how many are in use. Beam `i` points at
//! `angle_min + i * angle_increment` radians, counter-clockwise from the scanner's
//! forward axis (x forward, y left, as REP 103), and was measured at
//! `stamp_ns + i * time_increment`. `stamp_ns` is nanoseconds since the UNIX epoch,
//! UTC, of the first beam.
//!
//! # No-return convention (REP 117)
//!
//! - `f32::INFINITY`: no return within `range_max` (nothing there, as far as the scanner
//!   can tell). A target closer than `range_min` is also reported as no return.
//! - `f32::NAN`: a dropout: no echo although something may be there (dark or glancing
//!   surfaces, rain, sun).
//!
//! Readers must treat both as "no measurement", and like ROS also discard finite
//! values outside `[range_min, range_max]`; [`LaserFrame::valid_beams`] does exactly
//! that. Negative ranges (including `-inf`) are malformed and refused by
//! [`LaserFrame::validate`].
//!
//! # Transport
//!
//! [`LaserPublisher`] and [`LaserSubscriber`] share the iceoryx2 publish-subscribe
//! service named by [`service_name`] (`ugv-hil/<run_id>/laser`), plus an event service
//! of the same name: the publisher notifies after each frame so a subscriber sleeps in
//! the kernel until a frame arrives (no polling). The service keeps a history of one
//! frame, so a subscriber that connects late still gets the latest scan, and a buffer of
//! [`SUBSCRIBER_BUFFER`] frames per subscriber, the oldest overwritten first.
//!
//! # Example
//!
//! ```
//! use firmware_bridge::laser::{LaserFrame, MAX_BEAMS};
//!
//! let mut frame = LaserFrame::default();
//! frame.count = 3;
//! frame.angle_min = -0.1;
//! frame.angle_increment = 0.1;
//! frame.range_min = 0.5;
//! frame.range_max = 20.0;
//! frame.ranges[..3].copy_from_slice(&[1.0, f32::INFINITY, f32::NAN]);
//! frame.validate().unwrap();
//! let beams: Vec<(f32, f32)> = frame.valid_beams().collect();
//! assert_eq!(beams, vec![(-0.1, 1.0)]);
//! assert!(MAX_BEAMS >= 541);
//! ```

mod frame;
mod ipc;

use std::fmt;

use iceoryx2::service::service_name::ServiceNameError;
use serde::ser::{Serialize, SerializeStruct, Serializer};

pub use frame::LaserFrame;
pub use ipc::{LaserPublisher, LaserSubscriber, SUBSCRIBER_BUFFER};

/// The layout version of [`LaserFrame`]; bumped on any change to the struct.
pub const LASER_FRAME_VERSION: u32 = 1;

/// Capacity of a frame: 1081 beams (270° at 0.25°).
pub const MAX_BEAMS: usize = 1081;

/// The laser service of a run: `ugv-hil/<run_id>/laser`.
pub fn service_name(run_id: &str) -> String {
    format!("ugv-hil/{run_id}/laser")
}

/// Why a laser frame or endpoint failed.
#[derive(Debug, thiserror::Error)]
pub enum LaserError {
    #[error("laser frame version {found}, this build reads version {expected}")]
    WrongVersion { found: u32, expected: u32 },
    #[error("laser frame has {count} beams, must be 1 to {max}", max = MAX_BEAMS)]
    BeamCount { count: u32 },
    #[error("laser frame field {field} = {value} is not a finite number")]
    NonFinite { field: &'static str, value: f32 },
    #[error("laser frame field {field} = {value} must not be negative")]
    Negative { field: &'static str, value: f32 },
    #[error("laser frame angle_increment is 0 with {count} beams")]
    ZeroIncrement { count: u32 },
    #[error("laser frame range_min {range_min} is not below range_max {range_max}")]
    RangeLimits { range_min: f32, range_max: f32 },
    #[error("laser frame ranges[{index}] = {value} (ranges are >= 0, inf or NaN)")]
    BadRange { index: usize, value: f32 },
    #[error("laser frame intensities[{index}] = {value} (intensities are finite and >= 0)")]
    BadIntensity { index: usize, value: f32 },
    #[error("laser frame needs {needed} beams, holds at most {max}", max = MAX_BEAMS)]
    TooManyBeams { needed: usize },
    /// iceoryx2 refused the service name.
    #[error("laser service name {name:?}: {source:?}")]
    ServiceName {
        name: String,
        #[source]
        source: ServiceNameError,
    },
    /// An iceoryx2 call failed: the operation, and iceoryx2's error as the source (one
    /// of its error types, which depends on `op`: downcast to inspect it). The message
    /// shows the error's `Debug` form: some iceoryx2 `Display`s print `Self::Variant`.
    #[error("laser service {service}: {op}: {source:?}")]
    Ipc {
        service: String,
        op: IpcOp,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// The iceoryx2 operation behind a [`LaserError::Ipc`], and the iceoryx2 error type
/// its source then has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IpcOp {
    /// `NodeName::new`: `SemanticStringError`.
    NameNode,
    /// `NodeBuilder::create`: `NodeCreationFailure`.
    CreateNode,
    /// Opening or creating the publish-subscribe service: `PublishSubscribeOpenOrCreateError`
    /// (`PublishSubscribeOpenError` from `LaserSubscriber::open_existing`).
    OpenFrameService,
    /// Opening or creating the event service: `EventOpenOrCreateError` (`EventOpenError`
    /// from `LaserSubscriber::open_existing`).
    OpenEventService,
    /// `PublisherCreateError`.
    CreatePublisher,
    /// `NotifierCreateError`.
    CreateNotifier,
    /// `SubscriberCreateError`.
    CreateSubscriber,
    /// `ListenerCreateError`.
    CreateListener,
    /// `Publisher::send_copy`: `SendError`.
    SendFrame,
    /// `Notifier::notify`: `NotifierNotifyError`.
    Notify,
    /// `Publisher::update_connections`: `ConnectionFailure`.
    UpdateConnections,
    /// `Subscriber::receive`: `ReceiveError`.
    Receive,
    /// `Listener::timed_wait`: `ListenerWaitError`.
    WaitForFrame,
}

impl fmt::Display for IpcOp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NameNode => "name the node",
            Self::CreateNode => "create the node",
            Self::OpenFrameService => "open the frame service",
            Self::OpenEventService => "open the event service",
            Self::CreatePublisher => "create the publisher",
            Self::CreateNotifier => "create the notifier",
            Self::CreateSubscriber => "create the subscriber",
            Self::CreateListener => "create the listener",
            Self::SendFrame => "send a frame",
            Self::Notify => "notify the subscribers",
            Self::UpdateConnections => "update connections",
            Self::Receive => "receive",
            Self::WaitForFrame => "wait for a frame",
        })
    }
}

impl LaserFrame {
    /// The beams in use (`count` of them, at most [`MAX_BEAMS`]).
    pub fn len(&self) -> usize {
        (self.count as usize).min(MAX_BEAMS)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The ranges in use.
    pub fn ranges(&self) -> &[f32] {
        &self.ranges[..self.len()]
    }

    /// The intensities in use.
    pub fn intensities(&self) -> &[f32] {
        &self.intensities[..self.len()]
    }

    /// The angle of beam `i`, radians from the scanner's forward axis.
    pub fn angle(&self, i: usize) -> f32 {
        (f64::from(self.angle_min) + i as f64 * f64::from(self.angle_increment)) as f32
    }

    /// The angle of the last beam in use (`angle_max` of a ROS LaserScan).
    pub fn angle_max(&self) -> f32 {
        self.angle(self.len().saturating_sub(1))
    }

    /// Whether a range is a measurement: finite and within `[range_min, range_max]`.
    pub fn is_measurement(&self, range: f32) -> bool {
        range.is_finite() && range >= self.range_min && range <= self.range_max
    }

    /// `(angle, range)` of every beam that is a measurement, in beam order; `INFINITY`
    /// (no return), `NAN` (dropout) and out-of-limits values are skipped.
    pub fn valid_beams(&self) -> impl Iterator<Item = (f32, f32)> + '_ {
        self.ranges()
            .iter()
            .enumerate()
            .filter(|(_, r)| self.is_measurement(**r))
            .map(|(i, r)| (self.angle(i), *r))
    }

    /// Copy ranges and intensities in (same length, at most [`MAX_BEAMS`]), set `count`
    /// and zero the unused tail.
    pub fn set_beams(&mut self, ranges: &[f32], intensities: &[f32]) -> Result<(), LaserError> {
        let n = ranges.len().max(intensities.len());
        if n > MAX_BEAMS {
            return Err(LaserError::TooManyBeams { needed: n });
        }
        self.ranges = [0.0; MAX_BEAMS];
        self.intensities = [0.0; MAX_BEAMS];
        self.ranges[..ranges.len()].copy_from_slice(ranges);
        self.intensities[..intensities.len()].copy_from_slice(intensities);
        self.count = n as u32;
        Ok(())
    }

    /// Check a received (or about to be sent) frame: version, beam count, the angle, time
    /// and range fields, and every range and intensity in use.
    pub fn validate(&self) -> Result<(), LaserError> {
        if self.version != LASER_FRAME_VERSION {
            return Err(LaserError::WrongVersion {
                found: self.version,
                expected: LASER_FRAME_VERSION,
            });
        }
        if self.count == 0 || self.count as usize > MAX_BEAMS {
            return Err(LaserError::BeamCount { count: self.count });
        }
        for (field, value) in [
            ("angle_min", self.angle_min),
            ("angle_increment", self.angle_increment),
            ("time_increment", self.time_increment),
            ("scan_time", self.scan_time),
            ("range_min", self.range_min),
            ("range_max", self.range_max),
        ] {
            if !value.is_finite() {
                return Err(LaserError::NonFinite { field, value });
            }
        }
        for (field, value) in [
            ("time_increment", self.time_increment),
            ("scan_time", self.scan_time),
            ("range_min", self.range_min),
        ] {
            if value < 0.0 {
                return Err(LaserError::Negative { field, value });
            }
        }
        if self.count > 1 && self.angle_increment == 0.0 {
            return Err(LaserError::ZeroIncrement { count: self.count });
        }
        if self.range_min >= self.range_max {
            return Err(LaserError::RangeLimits {
                range_min: self.range_min,
                range_max: self.range_max,
            });
        }
        // NaN compares false, so `< 0.0` refuses exactly the negative values and -inf.
        let bad_range = |r: &f32| *r < 0.0;
        let bad_intensity = |v: &f32| !(v.is_finite() && *v >= 0.0);
        // Whole slices first, without early exit (the compiler vectorises them); the
        // index only for a frame that has a bad value.
        if self
            .ranges()
            .iter()
            .fold(false, |bad, r| bad | bad_range(r))
            && let Some((index, &value)) =
                self.ranges().iter().enumerate().find(|(_, r)| bad_range(r))
        {
            return Err(LaserError::BadRange { index, value });
        }
        if self
            .intensities()
            .iter()
            .fold(false, |bad, v| bad | bad_intensity(v))
            && let Some((index, &value)) = self
                .intensities()
                .iter()
                .enumerate()
                .find(|(_, v)| bad_intensity(v))
        {
            return Err(LaserError::BadIntensity { index, value });
        }
        Ok(())
    }

    /// The nearest measurement and headline counts, for logs and `ugv-laser-echo`.
    pub fn summary(&self) -> ScanSummary {
        let mut s = ScanSummary {
            beams: self.len(),
            valid: 0,
            no_return: 0,
            dropouts: 0,
            nearest: None,
        };
        for (i, &r) in self.ranges().iter().enumerate() {
            if self.is_measurement(r) {
                s.valid += 1;
                if s.nearest.is_none_or(|(_, best)| r < best) {
                    s.nearest = Some((self.angle(i), r));
                }
            } else if r.is_nan() {
                s.dropouts += 1;
            } else {
                s.no_return += 1;
            }
        }
        s
    }

    /// Bit-for-bit equality of the header and the beams in use (`==` says NaN != NaN).
    pub fn bit_eq(&self, other: &LaserFrame) -> bool {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        self.version == other.version
            && self.count == other.count
            && self.sequence == other.sequence
            && self.stamp_ns == other.stamp_ns
            && [
                self.angle_min,
                self.angle_increment,
                self.time_increment,
                self.scan_time,
                self.range_min,
                self.range_max,
            ]
            .map(f32::to_bits)
                == [
                    other.angle_min,
                    other.angle_increment,
                    other.time_increment,
                    other.scan_time,
                    other.range_min,
                    other.range_max,
                ]
                .map(f32::to_bits)
            && bits(self.ranges()) == bits(other.ranges())
            && bits(self.intensities()) == bits(other.intensities())
    }
}

impl LaserFrame {
    /// A made-up LMS111-like scan for tests and benchmarks, every field a function of
    /// `sequence` and `beams` (clamped to `1..=MAX_BEAMS`): beams spread evenly over
    /// 270° (0.5° steps at 541 beams), 50 Hz, range limits 0.5-20 m, stamped
    /// `2026-05-04T14:00:00Z + sequence * 20 ms` (whole microseconds, as CoLa-A
    /// carries). Every 9th beam is a no return (`INFINITY`) and the one after it a
    /// dropout (`NAN`), shifting with the sequence; the others lie within
    /// `[0.5, 20)` m with whole-number intensities of at most 255 (an 8-bit RSSI
    /// channel carries them unchanged), 0 where there is no measurement.
    pub fn synthetic(sequence: u64, beams: usize) -> LaserFrame {
        let beams = beams.clamp(1, MAX_BEAMS);
        let mut f = LaserFrame {
            count: beams as u32,
            sequence,
            stamp_ns: 1_777_903_200_000_000_000 + sequence * 20_000_000,
            angle_min: -135f32.to_radians(),
            angle_increment: 270f32.to_radians() / (beams.max(2) - 1) as f32,
            time_increment: 0.02 / 720.0,
            scan_time: 0.02,
            range_min: 0.5,
            range_max: 20.0,
            ..LaserFrame::default()
        };
        for (i, (r, q)) in f.ranges[..beams]
            .iter_mut()
            .zip(&mut f.intensities[..beams])
            .enumerate()
        {
            (*r, *q) = match (i as u64 + sequence) % 9 {
                0 => (f32::INFINITY, 0.0),
                1 => (f32::NAN, 0.0),
                k => {
                    let range =
                        0.5 + (sequence as f32 * 0.37 + i as f32 * 0.0113 + k as f32) % 19.5;
                    (range, (2000.0 / range).round().min(255.0))
                }
            };
        }
        f
    }
}

/// Headline numbers of one scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanSummary {
    /// Beams in use.
    pub beams: usize,
    /// Beams with a measurement.
    pub valid: usize,
    /// Beams with no return (inf, or finite but outside the range limits).
    pub no_return: usize,
    /// Beams with a dropout (NaN).
    pub dropouts: usize,
    /// `(angle, range)` of the nearest measurement.
    pub nearest: Option<(f32, f32)>,
}

impl fmt::Debug for LaserFrame {
    /// The header and the beams in use (not the unused tail of the arrays).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LaserFrame")
            .field("version", &self.version)
            .field("count", &self.count)
            .field("sequence", &self.sequence)
            .field("stamp_ns", &self.stamp_ns)
            .field("angle_min", &self.angle_min)
            .field("angle_increment", &self.angle_increment)
            .field("time_increment", &self.time_increment)
            .field("scan_time", &self.scan_time)
            .field("range_min", &self.range_min)
            .field("range_max", &self.range_max)
            .field("ranges", &self.ranges())
            .field("intensities", &self.intensities())
            .finish()
    }
}

impl Serialize for LaserFrame {
    /// The header and the beams in use, field names as in the struct (and as ROS
    /// LaserScan, plus `version`, `count`, `sequence` and `stamp_ns`). JSON has no
    /// infinity or NaN: serde_json writes both as `null`, i.e. "no measurement".
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut s = serializer.serialize_struct("LaserFrame", 12)?;
        s.serialize_field("version", &self.version)?;
        s.serialize_field("count", &self.count)?;
        s.serialize_field("sequence", &self.sequence)?;
        s.serialize_field("stamp_ns", &self.stamp_ns)?;
        s.serialize_field("angle_min", &self.angle_min)?;
        s.serialize_field("angle_increment", &self.angle_increment)?;
        s.serialize_field("time_increment", &self.time_increment)?;
        s.serialize_field("scan_time", &self.scan_time)?;
        s.serialize_field("range_min", &self.range_min)?;
        s.serialize_field("range_max", &self.range_max)?;
        s.serialize_field("ranges", self.ranges())?;
        s.serialize_field("intensities", self.intensities())?;
        s.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> LaserFrame {
        let mut f = LaserFrame {
            count: 4,
            angle_min: -0.3,
            angle_increment: 0.2,
            scan_time: 0.02,
            time_increment: 0.02 / 4.0,
            range_min: 0.5,
            range_max: 20.0,
            ..LaserFrame::default()
        };
        f.ranges[..4].copy_from_slice(&[1.0, f32::INFINITY, f32::NAN, 25.0]);
        f
    }

    #[test]
    fn valid_beams_skip_inf_nan_and_out_of_limits() {
        let f = frame();
        f.validate().unwrap();
        let v: Vec<_> = f.valid_beams().collect();
        assert_eq!(v, vec![(-0.3, 1.0)]);
        let s = f.summary();
        assert_eq!((s.beams, s.valid, s.no_return, s.dropouts), (4, 1, 2, 1));
        assert_eq!(s.nearest, Some((-0.3, 1.0)));
        assert!((f.angle_max() - 0.3).abs() < 1e-6);
    }

    #[test]
    fn json_has_only_beams_in_use_and_null_for_no_measurement() {
        let j = serde_json::to_value(frame()).unwrap();
        assert_eq!(j["ranges"], serde_json::json!([1.0, null, null, 25.0]));
        assert_eq!(j["intensities"].as_array().map(Vec::len), Some(4));
        assert_eq!(j["version"], 1);
    }

    #[test]
    fn a_synthetic_frame_is_a_valid_lms111_scan_with_no_returns_and_dropouts() {
        let f = LaserFrame::synthetic(3, 541);
        f.validate().unwrap();
        assert_eq!((f.sequence, f.len()), (3, 541));
        assert!((f.angle_min.to_degrees() + 135.0).abs() < 1e-4);
        assert!((f.angle_max().to_degrees() - 135.0).abs() < 1e-3);
        assert!((f.angle_increment.to_degrees() - 0.5).abs() < 1e-6);
        assert_eq!(f.stamp_ns % 1000, 0);
        let s = f.summary();
        assert_eq!((s.no_return, s.dropouts, s.valid), (60, 60, 421));
        assert!(
            f.intensities()
                .iter()
                .all(|q| q.fract() == 0.0 && *q <= 255.0)
        );
        assert!(LaserFrame::synthetic(3, 541).bit_eq(&f));
        assert!(!LaserFrame::synthetic(4, 541).bit_eq(&f));
        assert_eq!(LaserFrame::synthetic(0, 0).len(), 1);
        assert_eq!(LaserFrame::synthetic(0, MAX_BEAMS + 5).len(), MAX_BEAMS);
    }

    #[test]
    fn set_beams_refuses_more_than_max_beams() {
        let mut f = frame();
        let too_many = vec![1.0; MAX_BEAMS + 1];
        assert!(matches!(
            f.set_beams(&too_many, &[]),
            Err(LaserError::TooManyBeams { needed }) if needed == MAX_BEAMS + 1
        ));
        f.set_beams(&[2.0, 3.0], &[5.0, 6.0]).unwrap();
        assert_eq!(f.ranges(), &[2.0, 3.0]);
        assert_eq!(f.ranges[2], 0.0);
    }

    #[test]
    fn frame_layout_is_pinned() {
        // 4 + 4 + 8 + 8 + 6 * 4 + 2 * 1081 * 4 bytes, 8-aligned: a layout change needs a
        // new LASER_FRAME_VERSION and type_name.
        assert_eq!(std::mem::size_of::<LaserFrame>(), 8696);
        assert_eq!(std::mem::align_of::<LaserFrame>(), 8);
        assert_eq!(std::mem::offset_of!(LaserFrame, ranges), 48);
    }
}
