//! The simulated sensors: the RTK GPS receiver (NMEA over a pty) and the laser
//! scanner (frames over iceoryx2), each configured from the scenario.

pub mod cola_driver;
pub mod gps;
pub mod laser;
pub mod map;

/// A field of a device's configuration that failed validation: its name within the
/// device's section and why.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    pub field: &'static str,
    pub message: String,
}

impl FieldError {
    pub fn new(field: &'static str, message: impl Into<String>) -> FieldError {
        FieldError {
            field,
            message: message.into(),
        }
    }
}
