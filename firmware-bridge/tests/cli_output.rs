//! What the binaries print about themselves: `--version` names the binary, its
//! version and its crate (four binaries of this crate used to say only
//! "firmware-bridge 0.1.0"), and log lines carry ANSI colour only on a terminal and
//! never with `NO_COLOR` set. The log line comes from `ugv-sick` retrying a scanner
//! that is not there (a tracing warning); the terminal is a pty made by util-linux's
//! `script`.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

const BINARIES: [(&str, &str); 4] = [
    ("ugv-laser-echo", env!("CARGO_BIN_EXE_ugv-laser-echo")),
    ("ugv-laser-synth", env!("CARGO_BIN_EXE_ugv-laser-synth")),
    ("ugv-sick", env!("CARGO_BIN_EXE_ugv-sick")),
    ("ugv-bridge", env!("CARGO_BIN_EXE_ugv-bridge")),
];

#[test]
fn each_binary_reports_its_own_name_version_and_crate() {
    for (name, exe) in BINARIES {
        let out = Command::new(exe).arg("--version").output().expect("runs");
        assert!(out.status.success(), "{name}: {out:?}");
        assert_eq!(
            String::from_utf8_lossy(&out.stdout),
            format!("{name} {} (firmware-bridge)\n", env!("CARGO_PKG_VERSION")),
        );
    }
}

/// A port on loopback nobody listens on (bound, then let go).
fn closed_port() -> std::io::Result<u16> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(listener.local_addr()?.port())
}

/// The first line `ugv-sick` logs while retrying a scanner that is not there, read
/// from `command` (which runs it): on its stdout when `script` runs it on a pty, on
/// its stderr when it runs plain.
fn first_log_line(mut command: Command, through_script: bool) -> std::io::Result<String> {
    let (out, err) = match through_script {
        true => (Stdio::piped(), Stdio::null()),
        false => (Stdio::null(), Stdio::piped()),
    };
    let mut child = command.stdout(out).stderr(err).spawn()?;
    let mut line = String::new();
    if let Some(out) = child.stdout.take() {
        let _ = BufReader::new(out).read_line(&mut line);
    }
    if let Some(err) = child.stderr.take() {
        let _ = BufReader::new(err).read_line(&mut line);
    }
    let _ = child.kill();
    let _ = child.wait();
    Ok(line)
}

fn sick_args(tag: &str) -> std::io::Result<Vec<String>> {
    Ok(vec![
        "--address".to_owned(),
        format!("127.0.0.1:{}", closed_port()?),
        "--service".to_owned(),
        format!("ugv-hil/colour-{tag}-{}/laser", std::process::id()),
    ])
}

/// `ugv-sick` run on a pty by `script`, with `NO_COLOR` as given.
fn on_a_terminal(no_color: Option<&str>, tag: &str) -> std::io::Result<String> {
    let exe = env!("CARGO_BIN_EXE_ugv-sick");
    let mut command = Command::new("script");
    command
        .args([
            "-qfec",
            &format!("{exe} {}", sick_args(tag)?.join(" ")),
            "/dev/null",
        ])
        .stdin(Stdio::null())
        .env_remove("NO_COLOR");
    if let Some(v) = no_color {
        command.env("NO_COLOR", v);
    }
    first_log_line(command, true)
}

#[test]
fn log_lines_are_plain_in_a_pipe_coloured_on_a_terminal_and_plain_with_no_color()
-> std::io::Result<()> {
    let mut piped = Command::new(env!("CARGO_BIN_EXE_ugv-sick"));
    piped.args(sick_args("pipe")?).env_remove("NO_COLOR");
    let line = first_log_line(piped, false)?;
    assert!(line.contains("retrying"), "{line:?}");
    assert!(!line.contains('\x1b'), "colour in a pipe: {line:?}");

    let line = on_a_terminal(None, "tty")?;
    assert!(line.contains("retrying"), "{line:?}");
    assert!(line.contains("\x1b["), "no colour on a terminal: {line:?}");

    let line = on_a_terminal(Some("1"), "nocolor")?;
    assert!(line.contains("retrying"), "{line:?}");
    assert!(!line.contains('\x1b'), "colour with NO_COLOR=1: {line:?}");
    Ok(())
}
