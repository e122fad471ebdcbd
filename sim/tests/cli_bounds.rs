//! Every number on the `ugv-sim` command line is bounded: a value outside its range is
//! refused at once, naming the argument and the range, never a panic or a run of
//! unbounded length (issue 11, item 8).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::{Command, Stdio};
use std::time::Duration;

mod child_common;

/// Generous: a number that is not refused starts a run (or an ECU) that goes on; it
/// is killed after this and the test fails.
const WAIT: Duration = Duration::from_secs(20);

fn assert_refused(args: &[&str], argument: &str, range: &str) {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .args(args)
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (code, stderr) = child_common::exit_and_stderr(
        &mut child,
        WAIT,
        &format!("ugv-sim {args:?} was not refused"),
    );
    assert_eq!(code, Some(2), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(stderr.contains(argument), "{args:?}: {stderr}");
    assert!(stderr.contains(range), "{args:?}: {stderr}");
}

#[test]
fn ugv_sim_numbers_out_of_range_are_refused_naming_the_argument() {
    let cases: [(&[&str], &str, &str); 10] = [
        (
            &["run", "--sil", "--time-limit", "1e300"],
            "--time-limit",
            "0.001..=86400",
        ),
        (
            &["run", "--sil", "--time-limit=-1"],
            "--time-limit",
            "0.001..=86400",
        ),
        (
            &["run", "--sil", "--time-limit", "NaN"],
            "--time-limit",
            "0.001..=86400",
        ),
        (
            &["run", "--sil", "--status-every", "1e300"],
            "--status-every",
            "0.001..=3600",
        ),
        (
            &["run", "--sil", "--status-every", "0"],
            "--status-every",
            "0.001..=3600",
        ),
        (
            &["ecu", "steering", "--can", "vcan9", "--status-every", "inf"],
            "--status-every",
            "0.001..=3600",
        ),
        (&["suite", ".", "--jobs", "0"], "--jobs", "1..=1024"),
        (
            &["suite", ".", "--jobs", "18446744073709551615"],
            "--jobs",
            "1..=1024",
        ),
        (
            &["suite", ".", "--jobs", "18446744073709551616"],
            "--jobs",
            "invalid value",
        ),
        (&["suite", ".", "--jobs=-1"], "--jobs", "invalid value"),
    ];
    for (args, argument, range) in cases {
        assert_refused(args, argument, range);
    }
}

/// `run --sil` drives the built-in controller library: a controller binary to start
/// or wait for is a usage error, not silently ignored.
#[test]
fn run_sil_refuses_the_arguments_of_an_external_controller() {
    for (args, argument) in [
        (&["--controller", "/bin/true"][..], "--controller <BINARY>"),
        (&["--wait-for-controller"][..], "--wait-for-controller"),
        (&["--controller-arg", "-v"][..], "--controller-arg"),
    ] {
        let mut all = vec!["run", "--sil"];
        all.extend(args);
        assert_refused(&all, argument, "cannot be used with");
        // Either order.
        let mut sil_last = vec!["run"];
        sil_last.extend(args);
        sil_last.push("--sil");
        assert_refused(&sil_last, "--sil", "cannot be used with");
    }
}
