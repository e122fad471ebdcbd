//! Helpers shared by the laser and CoLa-A tests.

use std::time::{SystemTime, UNIX_EPOCH};

use firmware_bridge::laser::service_name;

/// A laser service of this test's own (`kind`, the process and the time in it), so
/// tests run in parallel.
pub fn unique_service(kind: &str, test: &str) -> String {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    service_name(&format!("{kind}-{}-{nanos}-{test}", std::process::id()))
}
