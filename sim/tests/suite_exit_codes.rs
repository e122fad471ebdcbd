//! `ugv-sim suite`'s and `merge`'s exit codes are distinct and listed in their
//! `--help` (issue 35): 0 every item passed, 1 an item failed its criteria, 2 usage
//! error, 4 setup error (the folder, an argument's value, an item that could not
//! run), 5 only time limits; items that end differently give the first of 4, 3, 1, 5.
//! Before, every failure, a bad scenario file included, exited 1. 3 (an item stopped:
//! Ctrl-C or the controller's exit in HIL) is checked on the items' records
//! (`sim/src/exit.rs`).

use std::path::Path;
use std::process::Command;

/// An open field: the goal 8 m ahead, reached in a few simulated seconds.
const OPEN: &str = "name = \"open\"\n\n[start]\nx = 0.0\ny = 0.0\n\n[goal]\nx = 8.0\ny = 0.0\n";

fn ugv_sim(args: &[&str]) -> std::io::Result<(Option<i32>, String)> {
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .args(args)
        .output()?;
    Ok((
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

/// `ugv-sim suite DIR --results DIR/../NAME`: its exit code and stderr.
fn suite(dir: &Path, name: &str) -> std::io::Result<(Option<i32>, String)> {
    let results = dir.with_file_name(name);
    ugv_sim(&[
        "suite",
        &dir.to_string_lossy(),
        "--jobs",
        "2",
        "--results",
        &results.to_string_lossy(),
    ])
}

#[test]
fn each_way_a_suite_ends_has_its_own_exit_code() -> std::io::Result<()> {
    let tmp = tempfile::tempdir()?;
    let dir = tmp.path().join("suite");
    std::fs::create_dir_all(&dir)?;
    let write = |file: &str, text: &str| std::fs::write(dir.join(file), text);

    write("a-open.toml", OPEN)?;
    let (code, err) = suite(&dir, "passed")?;
    assert_eq!(code, Some(0), "every item passed: {err}");

    write(
        "b-late.toml",
        &format!(
            "{}\n[sim]\ntime_limit_s = 1.0\n",
            OPEN.replace("open", "late")
        ),
    )?;
    let (code, err) = suite(&dir, "late")?;
    assert_eq!(code, Some(5), "the only failure a time limit: {err}");

    // The goal reached, but closer to a post than the scenario allows.
    let strict = OPEN.replace("open", "strict")
        + "\n[[obstacles]]\nkind = \"circle\"\nx = 4.0\ny = 3.0\nradius = 0.5\n\n[success]\nmin_clearance = 5.0\n";
    write("c-strict.toml", &strict)?;
    let (code, err) = suite(&dir, "failed")?;
    assert_eq!(
        code,
        Some(1),
        "a criterion missed, with a time limit: {err}"
    );
    // A merge of that suite's one shard says the same.
    let merged = tmp.path().join("merged");
    let (code, err) = ugv_sim(&[
        "merge",
        &tmp.path().join("failed").to_string_lossy(),
        "--out",
        &merged.to_string_lossy(),
    ])?;
    assert_eq!(code, Some(1), "merge: {err}");

    write(
        "d-bad.toml",
        "name = \"bad\"\n\n[vehicle]\nwheelbase = 1e-9\n",
    )?;
    let (code, err) = suite(&dir, "bad")?;
    assert_eq!(code, Some(4), "an item that could not run: {err}");
    let summary = std::fs::read_to_string(tmp.path().join("bad/summary.json"))?;
    assert!(
        summary.contains("vehicle.wheelbase"),
        "the summaries are written, the bad file's error in them: {summary}"
    );

    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty)?;
    let (code, err) = suite(&empty, "none")?;
    assert_eq!(code, Some(4), "a folder without scenarios: {err}");
    let (code, err) = ugv_sim(&["suite", &dir.to_string_lossy(), "--jobs", "0"])?;
    assert_eq!(code, Some(2), "a usage error: {err}");
    Ok(())
}

#[test]
fn suite_and_merge_help_list_the_exit_codes() -> std::io::Result<()> {
    for command in ["suite", "merge"] {
        let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
            .args([command, "--help"])
            .output()?;
        assert!(out.status.success());
        let help = String::from_utf8_lossy(&out.stdout);
        for line in [
            "Exit codes",
            "0  passed",
            "1  failed its criteria",
            "2  usage error",
            "3  stopped",
            "4  setup error",
            "5  time limit",
            "first of 4, 3, 1, 5",
        ] {
            assert!(
                help.contains(line),
                "{line:?} missing from {command} --help:\n{help}"
            );
        }
    }
    Ok(())
}
