//! Fuzz targets: one `pub fn <target>(data: &[u8])` per parser on an input path.
//!
//! Each function feeds the bytes to the real parser exactly as the product does (the
//! same entry point, the same options, the same chunking a socket or a file gives),
//! then checks invariants that are cheap to check: what was parsed encodes and parses
//! back to the same thing, what was validated satisfies what validation promises, and
//! what the product does next with a parsed value (the controller's localiser, the
//! perception, the E2E receiver) does not panic. A panic is a finding.
//!
//! The same functions run twice: under libFuzzer in `fuzz/` (nightly, `cargo fuzz run
//! <target>`), and over the committed corpora in `tests/corpora.rs` (stable, part of the
//! README's test command). See RELIABILITY.md for the campaigns.
//!
//! Inputs are bounded where the product has no bound of its own and an input could
//! otherwise make one execution take seconds (the planner's obstacle count, the
//! trainer's data size); the bounds are documented at each target.

// A fuzz target reports a broken invariant by panicking: that is its whole job.
#![allow(clippy::panic)]

mod anfis;
mod can;
mod cola;
mod config;
mod laser;
mod nmea;
mod plan;
mod scenario;

pub use anfis::{anfis_csv, anfis_model};
pub use can::{candump_line, dbc_spec};
pub use cola::{cola_server, cola_telegrams};
pub use config::controller_config;
pub use laser::laser_frame;
pub use nmea::nmea_stream;
pub use plan::plan_json;
pub use scenario::scenario_toml;

/// A fuzz target: takes any bytes, panics on a finding.
pub type Target = fn(&[u8]);

/// Every target, by name (the `fuzz/fuzz_targets/<name>.rs` files and the
/// `fuzz/corpus/<name>/` folders).
pub const TARGETS: &[(&str, Target)] = &[
    ("nmea_stream", nmea_stream),
    ("cola_telegrams", cola_telegrams),
    ("cola_server", cola_server),
    ("candump_line", candump_line),
    ("dbc_spec", dbc_spec),
    ("scenario_toml", scenario_toml),
    ("controller_config", controller_config),
    ("plan_json", plan_json),
    ("anfis_model", anfis_model),
    ("anfis_csv", anfis_csv),
    ("laser_frame", laser_frame),
];

/// Splits `data` into chunks whose sizes come from the first byte (1 to 64 bytes,
/// cycling), so one input exercises a stream parser's state across read boundaries as
/// a socket's or a serial port's reads cut it. Returns the chunks of the rest.
pub(crate) fn chunks(data: &[u8]) -> Vec<&[u8]> {
    let Some((&seed, mut rest)) = data.split_first() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut k = usize::from(seed);
    while !rest.is_empty() {
        let size = (k % 64) + 1;
        let (head, tail) = rest.split_at(size.min(rest.len()));
        out.push(head);
        rest = tail;
        k = k.wrapping_mul(31).wrapping_add(7);
    }
    out
}

/// The input as text, as a file read with `read_to_string` gives it: not UTF-8 is the
/// reader's error, before any parser runs.
pub(crate) fn text(data: &[u8]) -> Option<&str> {
    std::str::from_utf8(data).ok()
}
