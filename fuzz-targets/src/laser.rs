//! Laser frames from shared memory: `LaserSubscriber::try_recv` copies the `repr(C)`
//! frame out of the sample and calls `LaserFrame::validate`; the controller then reads
//! it as a scan, checked once (`ValidScan::from_frame`), into perception.

use firmware_bridge::laser::{LASER_FRAME_VERSION, LaserFrame, MAX_BEAMS};
use ugv_controller::perception::{Perception, PerceptionConfig, Pose2, ValidScan};

/// Bytes of the `repr(C)` frame: version, count (u32), sequence, stamp_ns (u64), six
/// f32 fields, then the ranges and the intensities.
pub const FRAME_BYTES: usize = 4 + 4 + 8 + 8 + 6 * 4 + 2 * 4 * MAX_BEAMS;

/// The frame whose memory holds `data` (native byte order, zeros past the end), as
/// another process's sample would lay it in shared memory. Safe code, field by field:
/// the same bytes a `transmute` would give, as the layout has no padding.
pub fn frame_of_bytes(data: &[u8]) -> LaserFrame {
    let mut bytes = [0u8; FRAME_BYTES];
    let n = data.len().min(FRAME_BYTES);
    bytes[..n].copy_from_slice(&data[..n]);
    let mut at = 0;
    let mut take = |len: usize| {
        let s = &bytes[at..at + len];
        at += len;
        s
    };
    let u32_ = |s: &[u8]| u32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
    let u64_ = |s: &[u8]| u64::from_ne_bytes([s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]]);
    let f32_ = |s: &[u8]| f32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
    let mut frame = LaserFrame {
        version: u32_(take(4)),
        count: u32_(take(4)),
        sequence: u64_(take(8)),
        stamp_ns: u64_(take(8)),
        angle_min: f32_(take(4)),
        angle_increment: f32_(take(4)),
        time_increment: f32_(take(4)),
        scan_time: f32_(take(4)),
        range_min: f32_(take(4)),
        range_max: f32_(take(4)),
        ..LaserFrame::default()
    };
    for r in frame.ranges.iter_mut() {
        *r = f32_(take(4));
    }
    for i in frame.intensities.iter_mut() {
        *i = f32_(take(4));
    }
    frame
}

/// `laser_frame`: the bytes laid into a frame's memory, then `LaserFrame::validate`.
///
/// Invariants of a frame that validates: the version is this build's, 1 to
/// [`MAX_BEAMS`] beams; its beams split into measurements, no-returns and dropouts
/// (`summary`); every measurement (`valid_beams`) is finite, within the range limits
/// and has a finite angle; `bit_eq` holds with itself; perception
/// (`ValidScan::from_frame`, then `Perception::update`, as
/// `Controller::on_laser_frame` does) takes it or refuses it with an error.
pub fn laser_frame(data: &[u8]) {
    let frame = frame_of_bytes(data);
    if frame.validate().is_err() {
        return;
    }
    assert_eq!(frame.version, LASER_FRAME_VERSION);
    let n = frame.len();
    assert!((1..=MAX_BEAMS).contains(&n));
    assert_eq!(n, frame.count as usize);
    let s = frame.summary();
    assert_eq!(s.beams, n);
    assert_eq!(s.valid + s.no_return + s.dropouts, n, "{s:?}");
    let mut valid = 0;
    for (angle, range) in frame.valid_beams() {
        assert!(range.is_finite() && range >= frame.range_min && range <= frame.range_max);
        // An angle beyond f32 (huge angle_min and increment) is what perception sees;
        // it must refuse such a scan, not trip on it.
        let _ = angle;
        valid += 1;
    }
    assert_eq!(valid, s.valid);
    if let Some((_, nearest)) = s.nearest {
        assert!(frame.is_measurement(nearest));
    }
    assert!(frame.bit_eq(&frame));

    let Ok(mut perception) = Perception::new(PerceptionConfig::default()) else {
        panic!("the default perception configuration is refused");
    };
    let mount = Pose2::new(1.2, 0.0, 0.0);
    let pose = Pose2::new(5.0, 3.0, 0.7);
    let Ok(scan) = ValidScan::from_frame(&frame, 1.0) else {
        return;
    };
    if let Ok(out) = perception.update(&scan, &mount, &pose) {
        for o in out.obstacles.iter().map(|o| &o.disc) {
            assert!(
                o.x.is_finite() && o.y.is_finite() && o.radius.is_finite(),
                "perception reported a non-finite obstacle {o:?}"
            );
            assert!(o.vx.is_finite() && o.vy.is_finite(), "{o:?}");
        }
    }
}
