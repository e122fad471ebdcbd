//! Numbers in the arguments of `ugv-sick`, `ugv-laser-echo` and `ugv-bridge` never
//! panic or abort: a value outside its range exits with a clear error that names the
//! argument and the allowed range (issue 11, item 8).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous: a binary that does not refuse its arguments would go on running (waiting
/// for a scanner or frames); it is killed after this and the test fails.
const WAIT: Duration = Duration::from_secs(20);

/// Run `bin` with `args`; its exit code (None: killed by a signal) and stderr.
fn run(bin: &str, args: &[&str]) -> (Option<i32>, String) {
    let mut child = Command::new(bin)
        .args(args)
        .env_remove("RUST_LOG")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + WAIT;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{bin} {args:?} did not refuse its arguments: still running after {WAIT:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (status.code(), stderr)
}

/// `bin args` exits with an error (not 0, not a panic's 101, not a signal), names
/// `argument` in what it says, and does not panic.
fn assert_refused(bin: &str, args: &[&str], argument: &str) {
    let (code, stderr) = run(bin, args);
    assert!(
        matches!(code, Some(c) if c != 0 && c != 101),
        "{args:?}: exit {code:?}: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(stderr.contains(argument), "{args:?}: {stderr}");
    assert!(stderr.len() < 4096, "{args:?}: a short message: {stderr}");
}

#[test]
fn ugv_sick_connect_timeout_1e300_and_other_numbers_are_refused_not_a_panic() {
    let bin = env!("CARGO_BIN_EXE_ugv-sick");
    let base = ["--address", "127.0.0.1:9", "--service", "cli-bounds/laser"];
    let cases: [(&[&str], &str); 11] = [
        (&["--connect-timeout", "1e300"], "--connect-timeout"),
        (&["--connect-timeout", "0"], "--connect-timeout"),
        (&["--connect-timeout", "NaN"], "--connect-timeout"),
        (&["--frame-timeout", "1e20"], "--frame-timeout"),
        (&["--frame-timeout=-1"], "--frame-timeout"),
        (&["--report-interval", "inf"], "--report-interval"),
        (&["--range-max", "1e39"], "--range-max"),
        (&["--range-min=-0.5"], "--range-min"),
        (&["--count", "0"], "--count"),
        (&["--count", "18446744073709551616"], "--count"),
        (
            &["--no-login", "--start-measurement"],
            "--start-measurement",
        ),
    ];
    for (extra, argument) in cases {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        assert_refused(bin, &args, argument);
    }
    let (_, stderr) = run(bin, &[&base[..], &["--connect-timeout", "1e300"]].concat());
    assert!(
        stderr.contains("0.001..=3600"),
        "the range is named: {stderr}"
    );
}

#[test]
fn ugv_laser_echo_timeout_1e300_and_count_are_refused_not_a_panic() {
    let bin = env!("CARGO_BIN_EXE_ugv-laser-echo");
    let cases: [(&[&str], &str); 5] = [
        (&["--timeout", "1e300"], "--timeout"),
        (&["--timeout", "0"], "--timeout"),
        (&["--timeout=-3"], "--timeout"),
        (&["--count", "0"], "--count"),
        (&["--count=-1"], "--count"),
    ];
    for (extra, argument) in cases {
        let args: Vec<&str> = ["cli-bounds/echo"].iter().chain(extra).copied().collect();
        assert_refused(bin, &args, argument);
    }
    let (_, stderr) = run(bin, &["cli-bounds/echo", "--timeout", "1e300"]);
    assert!(
        stderr.contains("0.001..=86400"),
        "the range is named: {stderr}"
    );
}

#[test]
fn ugv_bridge_interval_and_give_up_time_are_bounded() {
    let bin = env!("CARGO_BIN_EXE_ugv-bridge");
    let base = [
        "--sim",
        "vcan0",
        "--physical",
        "can0",
        "--node",
        "STEERING_ECU",
    ];
    let cases: [(&[&str], &str); 5] = [
        (&["--interval", "1e300"], "--interval"),
        (&["--interval=-1"], "--interval"),
        (&["--interval", "NaN"], "--interval"),
        (
            &["--tx-give-up-ms", "18446744073709551615"],
            "--tx-give-up-ms",
        ),
        (&["--tx-give-up-ms=-1"], "--tx-give-up-ms"),
    ];
    for (extra, argument) in cases {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        assert_refused(bin, &args, argument);
    }
}
