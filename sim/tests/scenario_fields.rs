//! Scenario files are range-checked at load, every field, with the file, line and
//! field named (issue 11, findings 1 and 9): non-finite numbers, values beyond f32
//! (which gave false collisions at t = 0), and what `run` refused while `check`
//! accepted it.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ugv_controller::config::FollowerKind;
use ugv_sim::ScenarioError;
use ugv_sim::mission::checked_controller_config;
use ugv_sim::scenario::Scenario;

/// Every floating-point field of the paper's scenario (the defaults and a post)
/// written out, as a path of keys and array indices.
fn float_fields(value: &toml::Value, path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    match value {
        toml::Value::Float(_) => out.push(path.clone()),
        toml::Value::Table(t) => {
            for (k, v) in t {
                path.push(k.clone());
                float_fields(v, path, out);
                path.pop();
            }
        }
        toml::Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                // Keys name tables; an element index attaches to its array.
                let last = path.pop().unwrap_or_default();
                path.push(format!("{last}[{i}]"));
                float_fields(v, path, out);
                path.pop();
                path.push(last);
            }
        }
        _ => {}
    }
}

fn set(value: &mut toml::Value, path: &[String], to: f64) {
    let Some((first, rest)) = path.split_first() else {
        *value = toml::Value::Float(to);
        return;
    };
    let (key, index) = match first.split_once('[') {
        Some((k, i)) => (k, i.trim_end_matches(']').parse::<usize>().ok()),
        None => (first.as_str(), None),
    };
    let mut next = &mut value[key];
    if let Some(i) = index {
        next = &mut next[i];
    }
    set(next, rest, to);
}

fn paper_table() -> toml::Value {
    let text = toml::to_string(&Scenario::paper().expect("the paper's scenario")).expect("encodes");
    toml::from_str(&text).expect("decodes")
}

#[test]
fn every_float_field_refuses_nan_infinities_and_values_beyond_f32() {
    let base = paper_table();
    let mut fields = Vec::new();
    float_fields(&base, &mut Vec::new(), &mut fields);
    assert!(fields.len() > 60, "found only {} fields", fields.len());
    let mut wrong = Vec::new();
    for path in &fields {
        let name = path.join(".");
        // Fields that are points of a polyline: each coordinate, element by element.
        for to in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e39, -1e39] {
            let mut v = base.clone();
            set(&mut v, path, to);
            let text = toml::to_string(&v).expect("encodes");
            match Scenario::from_toml(&text, "s.toml") {
                Err(ScenarioError::Invalid(e)) => {
                    let line = text.lines().nth(e.line - 1).unwrap_or_default();
                    let key = path.last().map(|k| k.split('[').next().unwrap_or(k));
                    let key = key.unwrap_or_default();
                    if e.file != "s.toml" || e.field != name || !line.contains(key) {
                        wrong.push(format!("{name} = {to}: {e} (line: {line:?})"));
                    }
                }
                // A parse error names its line itself (an integer field given a float).
                Err(ScenarioError::Parse { .. }) => {}
                other => wrong.push(format!("{name} = {to}: accepted ({})", other.is_ok())),
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "{} wrong:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}

fn invalid(text: &str) -> ugv_fields::LocatedError {
    match Scenario::from_toml(text, "bad.toml") {
        Err(ScenarioError::Invalid(e)) => e,
        other => panic!("expected a refusal of\n{text}\ngot {other:?}"),
    }
}

#[test]
fn a_goal_a_step_from_the_start_is_refused_by_the_scenario_itself() {
    // `ugv-sim check` accepted it and `run` refused it (the controller's rule).
    let e = invalid("[start]\nx = 0\ny = 0\nheading_deg = 0\n\n[goal]\nx = 0.3\ny = 0\n");
    assert_eq!((e.field.as_str(), e.line), ("goal", 6), "{e}");
    assert!(e.message.contains("at least 1 m"), "{e}");
}

#[test]
fn route_waypoints_and_the_perception_range_are_refused_with_their_line() {
    let route = "[start]\nx = 0\ny = 0\n\n[goal]\nx = 40\ny = 0\n\n[[waypoints]]\nx = 20\ny = 0\n\n[[waypoints]]\nx = 20.4\ny = 0\n";
    let e = invalid(route);
    assert_eq!((e.field.as_str(), e.line), ("waypoints[1].x", 14), "{e}");
    assert!(e.message.contains("at least 1 m"), "{e}");
    let e = invalid("[[waypoints]]\nx = 20\ny = 0\nspeed_limit = -1\n");
    assert_eq!(
        (e.field.as_str(), e.line),
        ("waypoints[0].speed_limit", 4),
        "{e}"
    );
    let e = invalid("[controller]\ndetection_radius = 50.0\n");
    assert_eq!(
        (e.field.as_str(), e.line),
        ("controller.detection_radius", 2),
        "{e}"
    );
    assert!(Scenario::from_toml("[controller]\ndetection_radius = 16.0\n", "ok.toml").is_ok());
}

/// Values no golf car has (issue: item 6), each refused with its field, its line, the
/// range and the range's source.
#[test]
fn values_no_golf_car_has_are_refused_with_the_range_and_its_source() {
    for (text, field, line, says) in [
        (
            "[vehicle]\nwheelbase = 1e-9\n",
            "vehicle.wheelbase",
            2,
            "must be within [0.5, 5] m, is 1e-9 (the golf car's is 1.6-1.7 m",
        ),
        (
            "[throttle]\nbrake_decel = 1e-9\n",
            "throttle.brake_decel",
            2,
            "must be within [1, 10] m/s^2, is 1e-9 (the golf car brakes at about 4 m/s^2",
        ),
        (
            "[laser]\nrate_hz = 1e-9\n",
            "laser.rate_hz",
            2,
            "must be within [1, 100] Hz, is 1e-9 (the LMS111 scans at 25 or 50 Hz",
        ),
        (
            "[[obstacles]]\nkind = \"circle\"\nx = 19\ny = 8\nradius = 1e-300\n",
            "obstacles[0].radius",
            5,
            "must be within [0.01, 100] m, is 1e-300 (",
        ),
        (
            "[gps]\nantenna_z = 1e300\n",
            "gps.antenna_z",
            2,
            "must be within [0, 5] m above ground, is 1e300 (on the roof",
        ),
        (
            "[gps.float]\nhorizontal_sigma_m = 1e300\n",
            "gps.float.horizontal_sigma_m",
            2,
            "must be within [0, 100] m, is 1e300",
        ),
        (
            "[steering]\ntime_constant_s = 1e-9\n",
            "steering.time_constant_s",
            2,
            "must be within [0.001, 2] s, is 1e-9 (the golf car's is 0.08 s",
        ),
        (
            "[sim]\nphysics_hz = 1e-9\n",
            "sim.physics_hz",
            2,
            "must be within [10, 2000] Hz, is 1e-9",
        ),
    ] {
        let e = invalid(text);
        assert_eq!((e.field.as_str(), e.line), (field, line), "{e}");
        assert!(e.message.starts_with(says), "{e}");
    }
    let e = invalid("[[obstacles]]\nkind = \"circle\"\nx = 19\ny = 8\nradius = 1e-300\n");
    assert!(
        e.message.ends_with(
            "(the suite's posts, trees and carts are 0.2-3 m; 1 cm is a wire, 100 m a building)"
        ),
        "{e}"
    );
}

#[test]
fn a_goal_reached_at_the_start_is_refused_naming_the_tolerance() {
    let scenario = |tolerance: f64| {
        format!("[start]\nx = 0\ny = 0\n\n[goal]\nx = 3\ny = 4\ntolerance = {tolerance:?}\n")
    };
    for tolerance in [6.0, 5.0] {
        let e = invalid(&scenario(tolerance));
        assert_eq!(
            e.to_string(),
            format!(
                "bad.toml:8: goal.tolerance: {tolerance} m reaches the start: the goal is 5.000 m from it, so it would be reached at t = 0 with a path of 0 m; it must be below the start-to-goal distance"
            )
        );
    }
    assert!(Scenario::from_toml(&scenario(4.9), "ok.toml").is_ok());
}

#[test]
fn an_obstacle_beyond_f32_is_refused_not_collided_with() {
    let e = invalid("[[obstacles]]\nkind = \"circle\"\nx = 1e39\ny = 0\nradius = 1\n");
    assert_eq!(
        e.to_string(),
        "bad.toml:3: obstacles[0].x: must be within [-100000, 100000] m from the origin, is 1000000000000000000000000000000000000000"
    );
    let e = invalid(
        "[[obstacles]]\nkind = \"wall\"\npoints = [[0, 50], [10, 50], [20, 1e300]]\nthickness = 0.2\n",
    );
    assert_eq!(
        (e.field.as_str(), e.line),
        ("obstacles[0].points[2]", 3),
        "{e}"
    );
}

#[test]
fn the_epoch_is_parsed_at_load_with_its_line() {
    for epoch in [
        "99999999999-01-01T00:00:00Z",
        "2026-05-04T14:00:00+99999:00",
        "2026-13-01T00:00:00Z",
    ] {
        let text = format!("name = \"e\"\n\n[sim]\nepoch = \"{epoch}\"\n");
        match Scenario::from_toml(&text, "e.toml") {
            Err(ScenarioError::Parse { message, .. }) => {
                assert!(message.contains("line 4"), "{message}");
                assert!(
                    message.contains("RFC 3339") || message.contains("outside"),
                    "{message}"
                );
            }
            other => panic!("{epoch}: {other:?}"),
        }
    }
}

#[test]
fn the_shipped_scenarios_still_load() {
    // Every one within the plausible ranges, and its controller configuration too
    // (what `ugv-sim check` checks).
    for dir in ["scenarios", "scenarios/suite", "scenarios/faults"] {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
        let mut n = 0;
        for f in std::fs::read_dir(&dir).expect("scenario folder") {
            let p = f.expect("entry").path();
            if p.extension().is_some_and(|e| e == "toml") {
                let s = Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"));
                checked_controller_config(&s, FollowerKind::Optimal, None)
                    .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                n += 1;
            }
        }
        assert!(n > 0, "no scenarios in {}", dir.display());
    }
}

#[test]
fn obstacles_default_to_none_and_the_paper_states_its_post() {
    let bare = Scenario::from_toml("name = \"bare\"\n", "bare.toml").expect("loads");
    assert!(bare.obstacles.is_empty(), "{:?}", bare.obstacles);
    assert_eq!(Scenario::default().obstacles, Vec::new());
    // The paper's scenario is the defaults with its post: the one place it is defined.
    let paper = Scenario::paper().expect("the paper's scenario");
    assert_eq!(
        paper.obstacles,
        vec![ugv_sim::scenario::Obstacle::Circle {
            x: 19.0,
            y: 8.0,
            radius: 3.0,
            motion: None,
        }]
    );
    let defaults = Scenario {
        name: paper.name.clone(),
        description: paper.description.clone(),
        obstacles: paper.obstacles.clone(),
        ..Scenario::default()
    };
    assert_eq!(paper, defaults);
}
