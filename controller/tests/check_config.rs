//! `ugv-controller check-config` makes exactly the checks `run` makes before it opens a
//! port (issue 11, finding 1: the perception checks ran only in `run`, so
//! `check-config` passed files `run` refused, and a NaN laser yaw passed both).

use std::process::Command;

use anyhow::{Context, Result, ensure};

/// `ugv-controller ARGS` on a configuration with `text`: exit code and stderr.
fn controller(args: &[&str], text: &str) -> Result<(Option<i32>, String)> {
    let dir = tempfile::tempdir()?;
    let file = dir.path().join("mission.toml");
    std::fs::write(&file, text)?;
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-controller"))
        .args(args)
        .arg(&file)
        .output()
        .context("running ugv-controller")?;
    Ok((
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

#[test]
fn check_config_refuses_what_run_refuses_naming_file_line_and_field() -> Result<()> {
    for (text, field) in [
        (
            "# the laser\n[vehicle]\nlaser_yaw_deg = nan\n",
            "vehicle.laser_yaw_deg",
        ),
        (
            "# perception\n[perception]\nmin_points = 0\n",
            "perception.min_points",
        ),
        (
            "# margin\n[planner]\nsafety_margin = -1\n",
            "planner.safety_margin",
        ),
    ] {
        let (code, stderr) = controller(&["check-config"], text)?;
        ensure!(
            code == Some(4),
            "check-config exit {code:?} for\n{text}\n{stderr}"
        );
        ensure!(
            stderr.contains(&format!("mission.toml:3: {field}: ")),
            "{stderr}"
        );
        // `run` refuses it with the same words, before it opens anything (the ports
        // named here do not exist).
        let (code, run_err) = controller(
            &[
                "run",
                "--gps",
                "/nonexistent/gps",
                "--laser",
                "none",
                "--can",
                "none0",
                "--config",
            ],
            text,
        )?;
        ensure!(code == Some(4), "run exit {code:?}\n{run_err}");
        ensure!(
            run_err.contains(&format!("mission.toml:3: {field}: ")),
            "{run_err}"
        );
    }
    let (code, stdout_err) = controller(&["check-config"], "[planner]\nsafety_margin = 0.5\n")?;
    ensure!(code == Some(0), "a valid file passes: {stdout_err}");
    Ok(())
}

#[test]
fn run_refuses_a_baud_rate_out_of_range_naming_it() -> Result<()> {
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-controller"))
        .args([
            "run",
            "--gps",
            "/nonexistent",
            "--laser",
            "x",
            "--baud",
            "99999999999",
        ])
        .output()?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    ensure!(out.status.code() == Some(2), "{:?} {stderr}", out.status);
    ensure!(
        stderr.contains("--baud") && stderr.contains("300..=4000000"),
        "{stderr}"
    );
    Ok(())
}

/// `ugv-controller plan` refuses a problem whose wheelbase no car has (it planned with
/// 1e300 m), naming the field, the range and its source.
#[test]
fn plan_refuses_a_wheelbase_no_car_has() -> Result<()> {
    let problem = |wheelbase: &str| {
        format!(
            r#"{{"state": {{"x": 0, "y": 0, "theta": 0, "phi": 0}},
                "goal": {{"x": 30, "y": 0, "theta": 0, "phi": 0}},
                "line_start": {{"x0": 0, "y0": 0}}, "t_k": 0, "t_f": 15,
                "wheelbase": {wheelbase}, "vehicle_radius": 2, "obstacles": []}}"#
        )
    };
    let (code, err) = controller(&["plan"], &problem("1e300"))?;
    ensure!(code != Some(0), "plan accepted a 1e300 m wheelbase: {err}");
    ensure!(
        err.contains("wheelbase: must be within [0.5, 5] m, is 1e300")
            && err.contains("(the golf car's is 1.6-1.7 m"),
        "{err}"
    );
    let (code, err) = controller(&["plan"], &problem("1.65"))?;
    ensure!(code == Some(0), "plan refused a golf car: {err}");
    Ok(())
}
