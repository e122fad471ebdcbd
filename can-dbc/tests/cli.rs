//! The `ugv-can` binary on its command line: `decode` reports a bad line (its number,
//! a cut excerpt) and decodes the rest, whatever the bytes (issue 11, item 7).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Write;
use std::process::{Command, Stdio};

/// `ugv-can args` with `input` on stdin: exit code, stdout, stderr.
fn ugv_can(args: &[&str], input: Vec<u8>) -> (Option<i32>, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ugv-can"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // Written from a thread so that a full stdout or stderr pipe cannot deadlock us.
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const FRAME: &[u8] = b"(1700000000.000001) vcan0 100#0000000000000000\n";

fn decoded(stdout: &str) -> usize {
    stdout
        .lines()
        .filter(|l| l.contains("STEERING_CMD"))
        .count()
}

#[test]
fn decode_reports_a_non_utf8_line_and_decodes_the_rest() {
    let mut input = FRAME.to_vec();
    input.extend_from_slice(b"(1700000000.000002) vcan0 100#00\xff\xfe00000000000000\n");
    input.extend_from_slice(FRAME);
    input.extend_from_slice(b"\xc3\x28 not text either\r\n");
    input.extend_from_slice(FRAME);
    let (code, stdout, stderr) = ugv_can(&["decode", "--no-e2e"], input);
    assert_eq!(code, Some(1), "malformed lines make exit code 1: {stderr}");
    assert_eq!(decoded(&stdout), 3, "every good line is decoded: {stdout}");
    assert!(stderr.contains("line 2: not UTF-8"), "{stderr}");
    assert!(stderr.contains("byte 0xff at offset 32"), "{stderr}");
    assert!(stderr.contains("line 4: not UTF-8"), "{stderr}");
    assert!(stderr.contains("3 frames"), "{stderr}");
    assert!(stderr.contains("2 malformed lines"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn decode_error_messages_cut_long_lines_with_a_marker() {
    // A malformed line of 3000 characters, then one of 20 MiB, then a good frame.
    let mut input = b"vcan0 ".to_vec();
    input.extend(std::iter::repeat_n(b'Z', 3000));
    input.extend_from_slice(b"#00\n");
    input.extend(std::iter::repeat_n(b'Q', 20 << 20));
    input.push(b'\n');
    input.extend_from_slice(FRAME);
    let (code, stdout, stderr) = ugv_can(&["decode", "--no-e2e"], input);
    assert_eq!(code, Some(1), "{stderr}");
    assert_eq!(
        decoded(&stdout),
        1,
        "the line after them is decoded: {stdout}"
    );
    assert!(
        stderr.len() < 2048,
        "{} bytes of stderr: {}",
        stderr.len(),
        &stderr[..stderr.len().min(2048)]
    );
    let first = stderr.lines().find(|l| l.contains("line 1:")).unwrap();
    assert!(first.contains("more characters)"), "{first}");
    assert!(first.contains(&"Z".repeat(40)), "{first}");
    let second = stderr.lines().find(|l| l.contains("line 2:")).unwrap();
    assert!(second.contains("20971520 bytes"), "{second}");
    assert!(second.contains("more characters)"), "{second}");
}

#[test]
fn encode_counter_out_of_range_is_refused_naming_the_argument() {
    for counter in ["16", "255", "18446744073709551616", "-1"] {
        let arg = format!("--counter={counter}");
        let (code, _, stderr) = ugv_can(&["encode", "STEERING_CMD", "Enable=1", &arg], Vec::new());
        assert_eq!(code, Some(2), "{counter}: {stderr}");
        assert!(!stderr.contains("panicked"), "{counter}: {stderr}");
        assert!(stderr.contains("--counter"), "{counter}: {stderr}");
    }
}

#[test]
fn decode_refuses_a_timestamp_that_is_no_time_and_a_second_frame_on_a_line() {
    let mut input = FRAME.to_vec();
    input.extend_from_slice(b"(nan) vcan0 100#0000000000000000\n");
    input.extend_from_slice(
        b"(1700000000.000003) vcan0 100#0000000000000000 (1700000000.000004) vcan0 101#0000000000000000\n",
    );
    input.extend_from_slice(b"vcan0 100#0000000000000000 101#0000000000000000\n");
    input.extend_from_slice(FRAME);
    let (code, stdout, stderr) = ugv_can(&["decode", "--no-e2e"], input);
    assert_eq!(code, Some(1), "{stderr}");
    assert_eq!(decoded(&stdout), 2, "only the good lines: {stdout}");
    for want in [
        "line 2: timestamp \"nan\" is neither seconds",
        "line 3: \"(1700000000.000004)\" after the frame: one frame per line",
        "line 4: \"101#0000000000000000\" after the frame: one frame per line",
        "3 malformed lines",
    ] {
        assert!(stderr.contains(want), "{want}: {stderr}");
    }
}

#[test]
fn encode_refuses_a_signal_given_twice() {
    let (code, stdout, stderr) = ugv_can(
        &[
            "encode",
            "STEERING_CMD",
            "TargetAngle=1",
            "Enable=1",
            "targetangle=2",
        ],
        Vec::new(),
    );
    assert_eq!(code, Some(2), "{stdout} {stderr}");
    assert!(
        stderr.contains(
            "TargetAngle is given twice (\"TargetAngle=1\" and \"targetangle=2\"): give each signal once"
        ),
        "{stderr}"
    );
    assert!(stdout.is_empty(), "{stdout}");
}
