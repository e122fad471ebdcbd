//! The laser frame as it lies in shared memory.
//!
//! iceoryx2's `#[derive(ZeroCopySend)]` implements its marker trait (the promise that
//! the type is self-contained: no pointers, no heap, the same layout in every process).
//! The derive's expansion is not flagged by the workspace's `unsafe_code = "deny"`, so
//! no lint is allowed and no `unsafe` is written here.

use iceoryx2::prelude::ZeroCopySend;

use super::{LASER_FRAME_VERSION, MAX_BEAMS};

/// One scan, with the semantics of ROS `sensor_msgs/LaserScan`; see the
/// [module documentation](super) for the conventions.
//
// Why ZeroCopySend holds: every field is a plain integer,
// float or array of floats, the layout is `repr(C)` with no pointers or references, so
// the bytes mean the same in every process that maps them. The type name carries the
// version, so iceoryx2 refuses to connect endpoints of different frame layouts.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ugv_hil::LaserFrame::v1")]
pub struct LaserFrame {
    /// [`LASER_FRAME_VERSION`] of the writer.
    pub version: u32,
    /// Number of beams in use, `1..=MAX_BEAMS`; entries past it are ignored (zero).
    pub count: u32,
    /// Scan counter of the publisher, +1 per scan (gaps mean lost scans).
    pub sequence: u64,
    /// Acquisition time of the first beam: nanoseconds since the UNIX epoch, UTC.
    pub stamp_ns: u64,
    /// Angle of the first beam, radians, counter-clockwise, 0 = the scanner's forward axis.
    pub angle_min: f32,
    /// Angle between consecutive beams, radians (positive: counter-clockwise sweep).
    pub angle_increment: f32,
    /// Time between consecutive beams, seconds.
    pub time_increment: f32,
    /// Time between scans, seconds.
    pub scan_time: f32,
    /// Shortest and longest range the scanner reports, metres.
    pub range_min: f32,
    pub range_max: f32,
    /// Metres; `f32::INFINITY` = no return within `range_max`, `f32::NAN` = dropout.
    pub ranges: [f32; MAX_BEAMS],
    /// Echo strength, device-specific units (0 where there is no return).
    pub intensities: [f32; MAX_BEAMS],
}

impl Default for LaserFrame {
    /// A frame of the current version with no beams (not valid until filled).
    fn default() -> Self {
        LaserFrame {
            version: LASER_FRAME_VERSION,
            count: 0,
            sequence: 0,
            stamp_ns: 0,
            angle_min: 0.0,
            angle_increment: 0.0,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: 0.0,
            range_max: 0.0,
            ranges: [0.0; MAX_BEAMS],
            intensities: [0.0; MAX_BEAMS],
        }
    }
}
