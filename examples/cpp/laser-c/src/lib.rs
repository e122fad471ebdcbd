//! The laser wire for C and C++ (`ugv_laser.h`): firmware-bridge's laser subscriber
//! behind a C ABI, for the C++ example (examples/cpp/README.md says why: iceoryx2 0.10
//! has no C or C++ binding in the registries this project builds from).
//!
//! The subscriber opens the simulator's services and never creates them
//! ([`LaserSubscriber::open_existing`]), with the wire's settings; each call hands the
//! newest frame over by copy, so no sample is held between calls. The frame is
//! firmware-bridge's [`LaserFrame`], whose `#[repr(C)]` layout `ugv_laser.h` spells out
//! in C (this crate's tests hold the two together).

// A C ABI needs `#[unsafe(no_mangle)]` and one `CStr::from_ptr`; nothing else here is
// unsafe. The pointers C hands over are references and boxes on this side (`Option`
// for NULL), which Rust guarantees to have a C pointer's ABI.
#![allow(unsafe_code)]

use std::ffi::{CStr, c_char, c_int};

use firmware_bridge::{LaserFrame, LaserSubscriber};

/// `ugv_laser` in C: one subscriber, opaque to the caller.
#[derive(Debug)]
pub struct UgvLaser(LaserSubscriber);

/// `ugv_laser_open`: 0 and `*out` set, 1 while the service does not exist, -1 on an
/// error (written on stderr).
///
/// # Safety
/// `service` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ugv_laser_open(
    service: *const c_char,
    out: Option<&mut Option<Box<UgvLaser>>>,
) -> c_int {
    // iceoryx2 logs errors only (its start-up warning of no configuration file is not
    // one); IOX2_LOG_LEVEL and RUST_LOG override, as in the project's binaries.
    firmware_bridge::cli::init_logging("warn");
    let Some(out) = out else {
        eprintln!("ugv_laser_open: out is NULL");
        return -1;
    };
    if service.is_null() {
        eprintln!("ugv_laser_open: service is NULL");
        return -1;
    }
    // SAFETY: not NULL, and NUL-terminated by the caller's promise.
    let Ok(service) = unsafe { CStr::from_ptr(service) }.to_str() else {
        eprintln!("ugv_laser_open: the service name is not UTF-8");
        return -1;
    };
    match LaserSubscriber::open_existing(service) {
        Ok(Some(subscriber)) => {
            *out = Some(Box::new(UgvLaser(subscriber)));
            0
        }
        Ok(None) => 1,
        Err(e) => {
            eprintln!("ugv_laser_open: {e}");
            -1
        }
    }
}

/// `ugv_laser_latest`: 1 and `*frame` set to the newest frame, 0 when none came since
/// the last call, -1 on an error (written on stderr).
#[unsafe(no_mangle)]
pub extern "C" fn ugv_laser_latest(
    laser: Option<&UgvLaser>,
    frame: Option<&mut LaserFrame>,
) -> c_int {
    let (Some(UgvLaser(subscriber)), Some(frame)) = (laser, frame) else {
        eprintln!("ugv_laser_latest: a NULL argument");
        return -1;
    };
    match subscriber.try_recv_latest() {
        Ok(Some(latest)) => {
            *frame = latest;
            1
        }
        Ok(None) => 0,
        Err(e) => {
            eprintln!("ugv_laser_latest: {e}");
            -1
        }
    }
}

/// `ugv_laser_close`: drops the subscriber (NULL does nothing).
#[unsafe(no_mangle)]
pub extern "C" fn ugv_laser_close(laser: Option<Box<UgvLaser>>) {
    drop(laser);
}

#[cfg(test)]
mod tests {
    use std::mem::{align_of, offset_of, size_of};

    use firmware_bridge::LaserPublisher;
    use firmware_bridge::laser::{LASER_FRAME_VERSION, MAX_BEAMS};
    use iceoryx2::prelude::ZeroCopySend;

    use super::*;

    const HEADER: &str = include_str!("../ugv_laser.h");

    /// The header's `/* offset: */` comment of `field`, and its `#define`s, against the
    /// Rust struct (the C++ example asserts size and alignment at compile time).
    #[test]
    fn the_header_spells_out_the_rust_frame() {
        let offset = |field: &str| {
            let line = HEADER
                .lines()
                .find(|l| l.contains(&format!(" {field};")) || l.contains(&format!(" {field}[")))
                .unwrap_or_else(|| panic!("no {field} in ugv_laser.h"));
            let comment = line.split("/*").nth(1).expect("a comment");
            comment
                .split(':')
                .next()
                .expect("an offset")
                .trim()
                .parse::<usize>()
                .expect("a number")
        };
        let fields = [
            ("version", offset_of!(LaserFrame, version)),
            ("count", offset_of!(LaserFrame, count)),
            ("sequence", offset_of!(LaserFrame, sequence)),
            ("stamp_ns", offset_of!(LaserFrame, stamp_ns)),
            ("angle_min", offset_of!(LaserFrame, angle_min)),
            ("angle_increment", offset_of!(LaserFrame, angle_increment)),
            ("time_increment", offset_of!(LaserFrame, time_increment)),
            ("scan_time", offset_of!(LaserFrame, scan_time)),
            ("range_min", offset_of!(LaserFrame, range_min)),
            ("range_max", offset_of!(LaserFrame, range_max)),
            ("ranges", offset_of!(LaserFrame, ranges)),
            ("intensities", offset_of!(LaserFrame, intensities)),
        ];
        for (field, rust) in fields {
            assert_eq!(offset(field), rust, "{field}");
        }
        for define in [
            format!("#define UGV_LASER_MAX_BEAMS {MAX_BEAMS} "),
            format!("#define UGV_LASER_FRAME_VERSION {LASER_FRAME_VERSION}u"),
            // SAFETY: type_name only reads the name the derive gave the type.
            format!("#define UGV_LASER_TYPE_NAME {:?}", unsafe {
                <LaserFrame as ZeroCopySend>::type_name()
            }),
            format!(
                "sizeof {}, alignof {}.",
                size_of::<LaserFrame>(),
                align_of::<LaserFrame>()
            ),
        ] {
            assert!(HEADER.contains(&define), "{define}");
        }
    }

    /// Through the C functions: nothing to open before the publisher, then the newest
    /// frame of two, then none.
    #[test]
    fn the_c_functions_open_only_and_hand_over_the_newest_frame() {
        let service = format!("ugv-hil/laser-c-test-{}/laser", std::process::id());
        let name = std::ffi::CString::new(service.clone()).expect("a C string");
        let mut laser = None;
        // SAFETY: a NUL-terminated string.
        assert_eq!(
            unsafe { ugv_laser_open(name.as_ptr(), Some(&mut laser)) },
            1
        );
        let publisher = LaserPublisher::new(&service).expect("a publisher");
        // SAFETY: as above.
        assert_eq!(
            unsafe { ugv_laser_open(name.as_ptr(), Some(&mut laser)) },
            0
        );
        let mut frame = LaserFrame::default();
        for seq in [1, 2] {
            publisher
                .publish(&LaserFrame::synthetic(seq, 541))
                .expect("published");
        }
        assert_eq!(ugv_laser_latest(laser.as_deref(), Some(&mut frame)), 1);
        assert!(frame.bit_eq(&LaserFrame::synthetic(2, 541)));
        assert_eq!(ugv_laser_latest(laser.as_deref(), Some(&mut frame)), 0);
        assert_eq!(ugv_laser_latest(None, Some(&mut frame)), -1);
        ugv_laser_close(laser);
        ugv_laser_close(None);
    }
}
