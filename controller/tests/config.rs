//! The controller's configuration is range-checked at load, every field of it, with
//! the file, line and field named (issue 11, finding 1: a NaN laser yaw passed
//! `check-config` and `run`, and the car drove the paper scenario blind).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ugv_controller::config::{ConfigError, ControllerConfig};
use ugv_controller::control::{Controller, ControllerError};

/// Every floating-point field of the configuration, as its dotted path.
fn float_fields() -> Vec<Vec<String>> {
    fn walk(prefix: &[String], table: &toml::Table, out: &mut Vec<Vec<String>>) {
        for (k, v) in table {
            let mut path = prefix.to_vec();
            path.push(k.clone());
            match v {
                toml::Value::Float(_) => out.push(path),
                toml::Value::Table(t) => walk(&path, t, out),
                _ => {}
            }
        }
    }
    let text = toml::to_string(&ControllerConfig::default()).expect("default encodes");
    let table: toml::Table = toml::from_str(&text).expect("default decodes");
    let mut out = Vec::new();
    walk(&[], &table, &mut out);
    out
}

/// A file that sets `path` to `value` (a TOML literal) on line 3.
fn file_setting(path: &[String], value: &str) -> String {
    let (key, tables) = path.split_last().expect("a path");
    format!("# test\n[{}]\n{key} = {value}\n", tables.join("."))
}

fn refused(text: &str) -> ugv_fields::LocatedError {
    match ControllerConfig::from_toml(text, "c.toml") {
        Err(ConfigError::Invalid(e)) => e,
        other => panic!("expected a refusal of\n{text}\ngot {other:?}"),
    }
}

#[test]
fn every_float_field_refuses_nan_and_infinities_naming_file_line_and_field() {
    let fields = float_fields();
    assert!(fields.len() > 60, "found only {} fields", fields.len());
    let mut wrong = Vec::new();
    for path in &fields {
        for value in ["nan", "inf", "-inf"] {
            let text = file_setting(path, value);
            let e = refused(&text);
            if (e.file.as_str(), e.field.clone(), e.line) != ("c.toml", path.join("."), 3) {
                wrong.push(format!("{} = {value}: {e}", path.join(".")));
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn every_float_field_refuses_values_beyond_f32() {
    // 1e39 is finite in f64 and infinite in f32; 1e300 far beyond any plausible bound.
    let mut wrong = Vec::new();
    for path in float_fields() {
        for value in ["1e39", "-1e39", "1e300"] {
            let text = file_setting(&path, value);
            let e = refused(&text);
            if e.field != path.join(".") {
                wrong.push(format!("{} = {value}: {e}", path.join(".")));
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn the_fields_named_in_the_issue_are_refused() {
    for (section, key, value) in [
        ("vehicle", "laser_yaw_deg", "nan"),
        ("vehicle", "steer_rate_deg_s", "nan"),
        ("vehicle", "steer_rate_deg_s", "inf"),
        ("follower", "accel_limit", "nan"),
        ("planner", "final_approach", "inf"),
        ("follower", "max_lateral_accel", "nan"),
        ("planner", "safety_margin", "-0.5"),
    ] {
        let text = format!("[{section}]\n{key} = {value}\n");
        let e = refused(&text);
        assert_eq!(e.field, format!("{section}.{key}"));
        assert_eq!(e.line, 2);
        assert!(
            e.to_string()
                .starts_with(&format!("c.toml:2: {section}.{key}: ")),
            "{e}"
        );
    }
}

/// Values no golf car has (issue: item 6): each refused with its field, its line, the
/// range and the range's source.
#[test]
fn values_no_golf_car_has_are_refused_with_the_range_and_its_source() {
    for (text, field, says) in [
        (
            "[vehicle]\nwheelbase = 1e-9\n",
            "vehicle.wheelbase",
            "must be within [0.5, 5] m, is 1e-9 (the golf car's is 1.6-1.7 m",
        ),
        (
            "[vehicle]\nwheelbase = 1e300\n",
            "vehicle.wheelbase",
            "must be within [0.5, 5] m, is 1e300",
        ),
        (
            "[vehicle]\nbrake_decel = 1e-9\n",
            "vehicle.brake_decel",
            "must be within [1, 10] m/s^2, is 1e-9 (the golf car brakes at about 4 m/s^2",
        ),
        (
            "[vehicle]\nsteer_time_constant_s = 1e-9\n",
            "vehicle.steer_time_constant_s",
            "must be within [0.001, 2] s, is 1e-9 (the golf car's is 0.08 s",
        ),
        (
            "[vehicle]\nmax_steer_deg = 50\n",
            "vehicle.max_steer_deg",
            "must be within [10, 45] degrees, is 50 (the DBC's STEERING_CMD.TargetAngle is +-45 degrees",
        ),
        (
            "[safety]\ngps_rate_hz = 1e-9\n",
            "safety.gps_rate_hz",
            "must be within [1, 20] Hz, is 1e-9 (RTK receivers offer 1-20 Hz epochs)",
        ),
        (
            "[planner]\nreplan_period_s = 1e-9\n",
            "planner.replan_period_s",
            "must be within [0.05, 5] s, is 1e-9 (the paper's T_s",
        ),
        (
            "[follower]\ndecel = 1e-9\n",
            "follower.decel",
            "must be within [0.1, 10] m/s^2, is 1e-9 (about 1 g",
        ),
    ] {
        let e = refused(text);
        assert_eq!((e.field.as_str(), e.line), (field, 2), "{e}");
        assert!(e.message.starts_with(says), "{e}");
    }
}

#[test]
fn a_goal_reached_at_the_start_is_refused_naming_the_tolerance() {
    let mission = |tolerance: f64| {
        format!(
            "[mission]\nstart_x = 0.0\nstart_y = 0.0\ngoal_x = 3.0\ngoal_y = 4.0\ngoal_tolerance = {tolerance:?}\n"
        )
    };
    for tolerance in [6.0, 5.0] {
        let e = refused(&mission(tolerance));
        assert_eq!(
            e.to_string(),
            format!(
                "c.toml:6: mission.goal_tolerance: {tolerance} m reaches the start: the goal is 5.000 m from it, so it would be reached at t = 0 with a path of 0 m; it must be below the start-to-goal distance"
            )
        );
    }
    assert!(ControllerConfig::from_toml(&mission(4.9), "c.toml").is_ok());
}

#[test]
fn array_elements_are_named_by_index() {
    let e = refused("[planner]\npace_fractions = [1.0, 0.5, nan]\n");
    assert_eq!(e.field, "planner.pace_fractions[2]");
    assert_eq!(e.line, 2);
}

#[test]
fn perception_tuning_is_checked_at_load_as_the_controller_checks_it() {
    // Perception's own checks ran only when `run` built the controller, so
    // `check-config` passed files `run` refused.
    let e = refused("[perception]\nmin_points = 0\n");
    assert_eq!(e.field, "perception.min_points");
    assert_eq!(e.line, 2);
    let e = refused("[perception]\ndetection_radius = 1000\n");
    assert_eq!(e.field, "perception.detection_radius");
}

#[test]
fn the_controller_refuses_a_configuration_that_bypassed_the_loader() {
    let mut cfg = ControllerConfig::default();
    cfg.vehicle.laser_yaw_deg = f64::NAN;
    match Controller::new(&cfg) {
        Err(ControllerError::Config(e)) => assert_eq!(e.path.to_string(), "vehicle.laser_yaw_deg"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_default_configuration_and_a_full_file_pass() {
    ControllerConfig::default()
        .validate()
        .expect("the default is valid");
    let text = toml::to_string(&ControllerConfig::default()).expect("encodes");
    ControllerConfig::from_toml(&text, "full.toml").expect("the default written out is valid");
}

#[test]
fn the_recovery_fields_are_bounded() {
    for (key, value) in [
        ("recover_after_s", "0.0"),
        ("reverse_distance_m", "-1.0"),
        ("reverse_distance_m", "12.0"),
        ("reverse_speed", "0.0"),
        ("max_reversals", "11"),
        ("reversal_reset_m", "0.0"),
        ("reversal_reset_m", "nan"),
    ] {
        let e = refused(&format!("[planner]\n{key} = {value}\n"));
        assert_eq!(e.field, format!("planner.{key}"), "{e}");
    }
    // Backing faster than the car may drive at all.
    let e = refused(
        "[vehicle]\nmax_speed = 0.4\n[planner]\nreverse_speed = 0.5\ncruise_speed = 0.3\nalign_speed = 0.3\npassage_speed = 0.3\n",
    );
    assert_eq!(e.field, "planner.reverse_speed", "{e}");
    assert!(e.to_string().contains("exceeds vehicle.max_speed"), "{e}");
    // Recovery off is allowed.
    assert!(ControllerConfig::from_toml("[planner]\nmax_reversals = 0\n", "c.toml").is_ok());
}
