//! What the workspace's binaries share on their command lines: their log set-up
//! ([`init_logging`]), and bounded number parsers as clap value parsers.
//!
//! A number outside its range is refused at parse time with the range
//! in the message, clap names the argument (`invalid value '1e300' for
//! '--connect-timeout <SECONDS>': must be within 0.001..=3600 seconds`), and
//! nothing downstream meets a number that makes it panic (`Duration::from_secs_f64`
//! on 1e300) or allocate without bound.
//!
//! ```
//! use clap::Parser;
//! use std::time::Duration;
//!
//! #[derive(Parser)]
//! struct Args {
//!     #[arg(long, value_parser = firmware_bridge::cli::seconds(0.001, 3600.0))]
//!     timeout: Duration,
//! }
//! assert!(Args::try_parse_from(["x", "--timeout", "1e300"]).is_err());
//! let args = Args::try_parse_from(["x", "--timeout", "2.5"]).unwrap();
//! assert_eq!(args.timeout, Duration::from_millis(2500));
//! ```

use std::time::Duration;

use tracing_subscriber::EnvFilter;

/// Write the `tracing` events of the binary and of the libraries it runs
/// (firmware-bridge's warnings among them) to stderr, at the levels `RUST_LOG` names
/// (`RUST_LOG=info`, `RUST_LOG=firmware_bridge=debug`), else at `default` and above.
/// Once per process: later calls keep the first set-up.
/// Colour ([`colour`]) only when stderr is a terminal and `NO_COLOR` is not set.
/// iceoryx2, which logs through a logger of its own, logs errors only (`IOX2_LOG_LEVEL`
/// overrides): its warning that no configuration file was found, printed when the
/// first iceoryx2 node of the process starts, stays out of every run.
pub fn init_logging(default: &str) {
    use std::io::IsTerminal;
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    let ansi = colour(
        std::io::stderr().is_terminal(),
        std::env::var_os("NO_COLOR").as_deref(),
    );
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .with_env_filter(filter)
        .try_init();
}

/// Whether log lines carry ANSI colour codes: only on a terminal (a log written to a
/// file or a pipe stays plain text), and never while `NO_COLOR` is set to a non-empty
/// value (<https://no-color.org>).
pub fn colour(is_terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    is_terminal && no_color.is_none_or(|v| v.is_empty())
}

/// A number within `min..=max` (finite), `unit` named in the error.
pub fn number(
    min: f64,
    max: f64,
    unit: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text: &str| {
        let value: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("not a number (give one within {min}..={max} {unit})"))?;
        if value.is_finite() && (min..=max).contains(&value) {
            Ok(value)
        } else {
            Err(format!("must be within {min}..={max} {unit}"))
        }
    }
}

/// As [`number`], as an `f32` (the bounds are checked on the value given, then it is
/// rounded to `f32`).
pub fn number_f32(
    min: f32,
    max: f32,
    unit: &'static str,
) -> impl Fn(&str) -> Result<f32, String> + Clone + Send + Sync + 'static {
    let check = number(f64::from(min), f64::from(max), unit);
    move |text: &str| check(text).map(|v| v as f32)
}

/// A number of seconds within `min..=max` (with `0 < min`), as a [`Duration`].
pub fn seconds(
    min: f64,
    max: f64,
) -> impl Fn(&str) -> Result<Duration, String> + Clone + Send + Sync + 'static {
    let check = number(min, max, "seconds");
    move |text: &str| {
        let value = check(text)?;
        Duration::try_from_secs_f64(value).map_err(|e| format!("not a duration: {e}"))
    }
}

/// A number of seconds within `min..=max`, or 0 (meaning "never" or "none", as the
/// argument says): `None` for 0.
pub fn seconds_or_zero(
    min: f64,
    max: f64,
) -> impl Fn(&str) -> Result<Option<Duration>, String> + Clone + Send + Sync + 'static {
    let check = seconds(min, max);
    move |text: &str| match text.trim().parse::<f64>() {
        Ok(0.0) => Ok(None),
        _ => check(text)
            .map(Some)
            .map_err(|e| format!("{e}, or 0 for none")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        use std::ffi::OsStr;
        assert!(colour(true, None));
        assert!(
            colour(true, Some(OsStr::new(""))),
            "an empty NO_COLOR is unset"
        );
        assert!(!colour(true, Some(OsStr::new("1"))));
        assert!(!colour(false, None), "a file or a pipe");
        assert!(!colour(false, Some(OsStr::new("1"))));
    }

    #[test]
    fn numbers_outside_their_range_are_refused_with_the_range() {
        let p = number(0.5, 20.0, "m");
        assert_eq!(p("2.5"), Ok(2.5));
        assert_eq!(p("20"), Ok(20.0));
        for bad in ["1e300", "-1", "NaN", "inf", "0.4", "twenty", ""] {
            let e = p(bad).unwrap_err();
            assert!(e.contains("0.5..=20 m"), "{bad}: {e}");
        }
    }

    #[test]
    fn seconds_never_panic_on_huge_or_odd_values() {
        let p = seconds(0.001, 3600.0);
        assert_eq!(p("1.5"), Ok(Duration::from_millis(1500)));
        for bad in ["1e300", "1e20", "0", "-0", "-5", "NaN", "inf", "1e-9"] {
            assert!(p(bad).is_err(), "{bad}");
        }
        let z = seconds_or_zero(0.001, 3600.0);
        assert_eq!(z("0"), Ok(None));
        assert_eq!(z("2"), Ok(Some(Duration::from_secs(2))));
        assert!(z("1e300").unwrap_err().contains("or 0 for none"));
    }
}
