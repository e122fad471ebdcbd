//! The simulated sensors: the RTK GPS receiver (NMEA over a pty) and the laser
//! scanner (frames over iceoryx2), each configured from the scenario.

pub mod cola_driver;
pub mod gps;
pub mod laser;
pub mod map;

pub use ugv_fields::FieldError;
use ugv_fields::FieldPath;

/// The error of the field at `field` of a device's section, its keys joined by dots
/// (`rtk.hdop`); the scenario or bench file places the section with
/// [`FieldError::under`].
pub fn invalid(field: &'static str, message: impl Into<String>) -> FieldError {
    let path = field
        .split('.')
        .fold(FieldPath::root(), |path, key| path.key(key));
    FieldError::new(path, message)
}
