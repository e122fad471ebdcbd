//! The GPS wire, controller side: bytes from the serial port into `NmeaReader::feed`.

use firmware_bridge::nmea::{GpsReading, NmeaReader, ReadEvent, ReaderConfig};
use ugv_controller::config::ControllerConfig;
use ugv_controller::localisation::Localiser;

/// `nmea_stream`: the bytes as a stream of serial reads, fed to the reader the
/// controller uses (`NmeaLink::poll` calls `NmeaReader::feed` with what each read gave,
/// `ReaderConfig::default()`), then flushed as at the end of the stream.
///
/// Invariants: the events do not depend on how the stream was cut (the same bytes in
/// one piece give the same events); the byte count is exact; every reading's numbers
/// are finite and within their ranges (latitude, longitude, heading); the controller's
/// localiser takes every reading (`Localiser::on_fix`, as `Controller::on_gps` does).
pub fn nmea_stream(data: &[u8]) {
    let Some((_, stream)) = data.split_first() else {
        return;
    };
    let mut chunked = NmeaReader::new(ReaderConfig::default());
    let mut events: Vec<ReadEvent> = Vec::new();
    for chunk in crate::chunks(data) {
        events.extend(chunked.feed(chunk));
    }
    events.extend(chunked.flush());

    let mut whole = NmeaReader::new(ReaderConfig::default());
    let mut reference: Vec<ReadEvent> = whole.feed(stream).collect();
    reference.extend(whole.flush());

    // Compared as Debug text when `==` fails: a NaN (which the checks below refuse)
    // must not report a difference that is only NaN != NaN.
    if events != reference {
        assert_eq!(
            format!("{events:?}"),
            format!("{reference:?}"),
            "the events depend on how the stream was cut"
        );
    }
    assert_eq!(chunked.stats(), whole.stats());
    assert_eq!(chunked.stats().bytes, stream.len() as u64);
    let fixes = events
        .iter()
        .filter(|e| matches!(e, ReadEvent::Fix(_)))
        .count();
    assert_eq!(chunked.stats().fixes, fixes as u64);

    let cfg = ControllerConfig::default();
    let Ok(mut localiser) = Localiser::new(&cfg) else {
        panic!("the default configuration's datum is refused");
    };
    let mut now = 0.0;
    for event in &events {
        if let ReadEvent::Fix(reading) = event {
            check_reading(reading);
            now += 0.1;
            localiser.on_fix(now, reading);
            if let Some(pose) = localiser.predict(now) {
                assert!(
                    pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite(),
                    "a reading gave a non-finite pose {pose:?} from {reading:?}"
                );
            }
        }
    }
}

fn check_reading(r: &GpsReading) {
    let finite = [
        ("lat_deg", r.lat_deg),
        ("lon_deg", r.lon_deg),
        ("altitude_msl_m", r.altitude_msl_m),
        ("geoid_separation_m", r.geoid_separation_m),
        ("hdop", r.hdop),
        ("correction_age_s", r.correction_age_s),
        ("speed_mps", r.speed_mps),
        ("course_deg", r.course_deg),
        ("heading_deg", r.heading_deg),
    ];
    for (field, value) in finite {
        if let Some(v) = value {
            assert!(v.is_finite(), "reading {field} = {v}: {r:?}");
        }
    }
    if let Some(a) = &r.accuracy {
        for v in [
            a.rms_m,
            a.semi_major_m,
            a.semi_minor_m,
            a.orientation_deg,
            a.lat_sigma_m,
            a.lon_sigma_m,
            a.alt_sigma_m,
        ] {
            assert!(v.is_finite(), "reading accuracy {a:?}");
        }
    }
    if let Some(lat) = r.lat_deg {
        assert!((-90.0..=90.0).contains(&lat), "latitude {lat}");
    }
    if let Some(lon) = r.lon_deg {
        assert!((-180.0..=180.0).contains(&lon), "longitude {lon}");
    }
    if let Some(h) = r.heading_deg {
        assert!((0.0..=360.0).contains(&h), "heading {h}");
    }
}
