//! `ugv-sim check` makes the checks `run` makes (issue 11, finding 9: a goal 0.3 m from
//! the start passed `check` and was refused by `run`).

use std::process::Command;

use anyhow::{Context, Result, ensure};

fn sim(args: &[&str], file: &std::path::Path) -> Result<(Option<i32>, String)> {
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .args(args)
        .arg(file)
        .output()
        .context("running ugv-sim")?;
    Ok((
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

#[test]
fn check_and_run_refuse_a_goal_a_step_from_the_start_alike() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let file = dir.path().join("near.toml");
    std::fs::write(
        &file,
        "name = \"near\"\n\n[start]\nx = 0\ny = 0\n\n[goal]\nx = 0.3\ny = 0\n",
    )?;
    let (code, check) = sim(&["check"], &file)?;
    ensure!(code == Some(1), "check exit {code:?}: {check}");
    ensure!(
        check.contains("near.toml:7: goal: the goal must be at least 1 m"),
        "{check}"
    );
    let results = dir.path().join("results");
    let (code, run) = sim(
        &[
            "run",
            "--sil",
            "--results",
            results.to_str().context("utf-8")?,
        ],
        &file,
    )?;
    ensure!(code == Some(4), "run exit {code:?}: {run}");
    ensure!(
        run.contains("near.toml:7: goal: the goal must be at least 1 m"),
        "{run}"
    );
    Ok(())
}

#[test]
fn check_passes_the_shipped_suite() -> Result<()> {
    let suite = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite");
    let first = std::fs::read_dir(&suite)?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "toml"))
        .context("a suite scenario")?;
    let (code, err) = sim(&["check"], &first)?;
    ensure!(code == Some(0), "{err}");
    Ok(())
}
