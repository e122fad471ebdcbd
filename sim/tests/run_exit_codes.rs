//! `ugv-sim run`'s exit codes are distinct and listed in `run --help` (issue 35 item
//! 4): 0 passed, 1 failed its criteria, 2 usage error, 3 stopped, 4 setup or run
//! error, 5 time limit. Before, a usage error and the time limit both exited 2, and a
//! goal reached exited 0 whatever the verdict said. Each case but 3 (Ctrl-C or the
//! controller's exit; tests/tests/vcan_controller_kill.rs) is a SIL run or a refusal.

use std::path::Path;
use std::process::Command;

/// `ugv-sim run ARGS --sil --no-record` in `dir`: its exit code, stdout and stderr.
fn run(dir: &Path, args: &[&str]) -> std::io::Result<(Option<i32>, String, String)> {
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .arg("run")
        .args(args)
        .args(["--sil", "--no-record", "--results"])
        .arg(dir.join("results"))
        .current_dir(dir)
        .output()?;
    Ok((
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

/// The verdict's `passed` from a run's stdout.
fn passed(stdout: &str) -> Option<bool> {
    serde_json::from_str::<serde_json::Value>(stdout)
        .ok()?
        .get("passed")?
        .as_bool()
}

#[test]
fn each_end_of_a_run_has_its_own_exit_code() -> std::io::Result<()> {
    let dir = tempfile::tempdir()?;
    let d = dir.path();

    let (code, out, err) = run(d, &[])?;
    assert_eq!(code, Some(0), "the paper's scenario passes: {err}");
    assert_eq!(passed(&out), Some(true));

    // The goal is reached, but the scenario asks for more clearance than the car keeps.
    let paper = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/paper.toml"),
    )?;
    let strict = d.join("strict.toml");
    std::fs::write(
        &strict,
        format!("{paper}\n[success]\nmin_clearance = 5.0\n"),
    )?;
    let (code, out, err) = run(d, &[&strict.to_string_lossy()])?;
    assert_eq!(code, Some(1), "goal reached, criteria failed: {err}");
    assert_eq!(passed(&out), Some(false));
    assert!(out.contains("\"goal_reached\": true"), "{out}");

    let (code, _, err) = run(d, &["--no-such-option"])?;
    assert_eq!(code, Some(2), "a usage error: {err}");

    let (code, _, err) = run(d, &["no-such-scenario.toml"])?;
    assert_eq!(code, Some(4), "a setup error: {err}");

    let (code, out, err) = run(d, &["--time-limit", "3"])?;
    assert_eq!(code, Some(5), "the time limit: {err}");
    assert_eq!(passed(&out), Some(false));
    Ok(())
}

#[test]
fn run_help_lists_the_exit_codes() -> std::io::Result<()> {
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .args(["run", "--help"])
        .output()?;
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for line in [
        "Exit codes:",
        "0  passed",
        "1  failed its criteria",
        "2  usage error",
        "3  stopped",
        "4  setup or run error",
        "5  time limit",
    ] {
        assert!(
            help.contains(line),
            "{line:?} missing from run --help:\n{help}"
        );
    }
    Ok(())
}
