//! The laser frame's validation: every malformed header or beam is refused with an
//! error that names the cause, and well-formed frames (including inf and NaN beams) pass.

use firmware_bridge::laser::{LASER_FRAME_VERSION, LaserError, LaserFrame, MAX_BEAMS};
use proptest::prelude::*;

fn good() -> LaserFrame {
    let mut f = LaserFrame {
        count: 541,
        sequence: 7,
        stamp_ns: 1_777_903_200_000_000_000,
        angle_min: (-135.0f32).to_radians(),
        angle_increment: 0.5f32.to_radians(),
        time_increment: 0.02 / 720.0,
        scan_time: 0.02,
        range_min: 0.5,
        range_max: 20.0,
        ..LaserFrame::default()
    };
    for i in 0..541 {
        f.ranges[i] = match i % 3 {
            0 => 1.0 + i as f32 * 0.01,
            1 => f32::INFINITY,
            _ => f32::NAN,
        };
        f.intensities[i] = if i % 3 == 0 { 100.0 } else { 0.0 };
    }
    f
}

#[test]
fn a_well_formed_frame_with_inf_and_nan_beams_validates() {
    let f = good();
    f.validate().unwrap();
    assert_eq!(f.version, LASER_FRAME_VERSION);
    let s = f.summary();
    assert_eq!(
        (s.beams, s.valid, s.no_return, s.dropouts),
        (541, 181, 180, 180)
    );
    assert_eq!(f.valid_beams().count(), 181);
    // The last beam of a 270 degree, 541-beam scan is at +135 degrees.
    assert!((f.angle_max().to_degrees() - 135.0).abs() < 1e-3);
}

#[test]
fn a_single_beam_frame_may_have_zero_increment() {
    let mut f = good();
    f.count = 1;
    f.angle_increment = 0.0;
    f.validate().unwrap();
}

/// The error of a good frame after `edit` (None: it validated).
fn refused(edit: impl FnOnce(&mut LaserFrame)) -> Option<LaserError> {
    let mut f = good();
    edit(&mut f);
    f.validate().err()
}

#[test]
fn malformed_frames_are_refused_with_their_cause() {
    assert!(matches!(
        refused(|f| f.version = 2),
        Some(LaserError::WrongVersion {
            found: 2,
            expected: 1
        })
    ));
    assert!(matches!(
        refused(|f| f.version = 0),
        Some(LaserError::WrongVersion { found: 0, .. })
    ));
    assert!(matches!(
        refused(|f| f.count = 0),
        Some(LaserError::BeamCount { count: 0 })
    ));
    let too_many = MAX_BEAMS as u32 + 1;
    assert!(matches!(
        refused(|f| f.count = too_many),
        Some(LaserError::BeamCount { count }) if count == too_many
    ));
    for (name, edit) in [
        (
            "angle_min",
            (|f: &mut LaserFrame| f.angle_min = f32::NAN) as fn(&mut LaserFrame),
        ),
        ("angle_increment", |f| f.angle_increment = f32::INFINITY),
        ("time_increment", |f| f.time_increment = f32::NAN),
        ("scan_time", |f| f.scan_time = f32::NEG_INFINITY),
        ("range_min", |f| f.range_min = f32::NAN),
        ("range_max", |f| f.range_max = f32::INFINITY),
    ] {
        assert!(
            matches!(refused(edit), Some(LaserError::NonFinite { field, .. }) if field == name),
            "{name}"
        );
    }
    assert!(matches!(
        refused(|f| f.scan_time = -0.02),
        Some(LaserError::Negative {
            field: "scan_time",
            ..
        })
    ));
    assert!(matches!(
        refused(|f| f.range_min = -1.0),
        Some(LaserError::Negative {
            field: "range_min",
            ..
        })
    ));
    assert!(matches!(
        refused(|f| f.angle_increment = 0.0),
        Some(LaserError::ZeroIncrement { count: 541 })
    ));
    assert!(matches!(
        refused(|f| f.range_min = 20.0),
        Some(LaserError::RangeLimits { .. })
    ));
    assert!(matches!(
        refused(|f| f.range_max = 0.1),
        Some(LaserError::RangeLimits { .. })
    ));
    assert!(matches!(
        refused(|f| f.ranges[17] = -0.5),
        Some(LaserError::BadRange { index: 17, .. })
    ));
    assert!(matches!(
        refused(|f| f.ranges[540] = f32::NEG_INFINITY),
        Some(LaserError::BadRange { index: 540, .. })
    ));
    assert!(matches!(
        refused(|f| f.intensities[3] = f32::NAN),
        Some(LaserError::BadIntensity { index: 3, .. })
    ));
    assert!(matches!(
        refused(|f| f.intensities[4] = -1.0),
        Some(LaserError::BadIntensity { index: 4, .. })
    ));
}

#[test]
fn errors_name_the_field_and_value() {
    let e = refused(|f| f.range_max = f32::INFINITY)
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("range_max") && e.contains("inf"), "{e}");
    let e = refused(|f| f.version = 9)
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("version 9") && e.contains("version 1"), "{e}");
}

#[test]
fn garbage_past_count_is_ignored() {
    let mut f = good();
    f.ranges[600] = -3.0;
    f.intensities[700] = f32::NAN;
    f.validate().unwrap();
}

proptest! {
    /// Validation never panics, whatever the bytes say, and accepts only frames whose
    /// beams in use are all >= 0, inf or NaN.
    #[test]
    fn validate_never_panics_and_checks_every_beam_in_use(
        version in 0u32..3,
        count in 0u32..1200,
        angle_min in proptest::num::f32::ANY,
        angle_increment in proptest::num::f32::ANY,
        range_min in proptest::num::f32::ANY,
        range_max in proptest::num::f32::ANY,
        beams in proptest::collection::vec(proptest::num::f32::ANY, 0..64),
    ) {
        let mut f = LaserFrame {
            version, count, angle_min, angle_increment, range_min, range_max,
            ..LaserFrame::default()
        };
        for (i, b) in beams.iter().enumerate() {
            f.ranges[i] = *b;
        }
        if f.validate().is_ok() {
            prop_assert!(f.ranges().iter().all(|r| r.is_nan() || *r >= 0.0));
            prop_assert!(f.range_min < f.range_max);
            prop_assert!(f.valid_beams().all(|(a, r)| a.is_finite() || r.is_finite()));
        }
    }
}
