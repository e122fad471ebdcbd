//! Fault injection (issue 16): the fault suite in SIL, the plan's validation, and the
//! injected frames agreeing with what the controller's receiver rejected.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used)]

use ugv_controller::config::FollowerKind;
use ugv_sim::faults::plan::{PlanFile, kind_names};
use ugv_sim::scenario::Scenario;
use ugv_sim::sil::{Hook, run_sil_with};
use ugv_sim::suite;

fn fault_files() -> Vec<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/faults");
    suite::scenario_files(&dir).expect("fault suite folder")
}

#[test]
fn the_fault_suite_passes_in_sil_and_covers_every_kind() {
    let files = fault_files();
    assert!(files.len() >= 30, "{} fault scenarios", files.len());
    let entries = suite::run_suite(
        &files,
        2,
        &suite::default_tune(FollowerKind::Optimal),
        &|_, _| {},
    );
    assert_eq!(entries.len(), files.len());
    let mut kinds = std::collections::BTreeSet::new();
    for e in &entries {
        let v = e
            .verdict
            .as_ref()
            .unwrap_or_else(|| panic!("{}: {:?}", e.name, e.error));
        assert!(v.passed, "{}: {:?}", e.name, v.failures);
        assert!(!v.report.faults.is_empty(), "{}: no fault injected", e.name);
        for f in &v.report.faults {
            let start = f
                .started_s
                .unwrap_or_else(|| panic!("{}: never started", e.name));
            assert!(
                f.injected > 0,
                "{}: {} altered nothing",
                e.name,
                f.fault.kind.name()
            );
            // A detection comes after the fault, never before.
            if let Some(d) = f.detected_s {
                assert!(
                    d + 1e-9 >= start,
                    "{}: detected at {d} before {start}",
                    e.name
                );
            }
            kinds.insert(f.fault.kind.name());
        }
    }
    let missing: Vec<_> = kind_names()
        .into_iter()
        .filter(|k| !kinds.contains(k))
        .collect();
    assert!(missing.is_empty(), "kinds no scenario injects: {missing:?}");
}

/// A scenario's text with a fault table appended.
fn with_fault(table: &str) -> String {
    format!(
        "name = \"t\"\n[start]\nx = 0.0\ny = 0.0\nheading_deg = 0.0\n[goal]\nx = 20.0\ny = 0.0\n{table}"
    )
}

#[test]
fn bad_fault_plans_are_refused_with_file_line_and_field() {
    let cases = [
        (
            "[[faults]]\nkind = \"gps_teleport\"\nat_s = 1.0\n",
            "t.toml:10: faults[0].kind: \"gps_teleport\" is not a fault kind",
        ),
        (
            "[[faults]]\nkind = \"gps_outage\"\nat_s = 1.0\nnode = \"steering\"\n",
            "t.toml:12: faults[0].node: gps_outage takes no node",
        ),
        (
            "[[faults]]\nkind = \"gps_outage\"\nduration_s = 1.0\n",
            "faults[0].at_s: missing",
        ),
        (
            "[[faults]]\nkind = \"gps_outage\"\nat_s = 1.0\nafter_m = 3.0\n",
            "t.toml:12: faults[0].after_m: give at_s or after_m, not both",
        ),
        (
            "[[faults]]\nkind = \"can_corrupt_crc\"\nat_s = 1.0\nnode = \"controller\"\n",
            "t.toml:12: faults[0].node: can_corrupt_crc rewrites the frames an ECU sends",
        ),
        (
            "[[faults]]\nkind = \"can_drop\"\nat_s = 1.0\nnode = \"steering\"\nprobability = 1.5\n",
            "t.toml:13: faults[0].probability:",
        ),
        (
            "[[faults]]\nkind = \"controller_stop\"\nat_s = 1.0\n",
            "faults[0].duration_s: missing: controller_stop needs a duration",
        ),
        (
            "[[faults]]\nkind = \"controller_kill\"\nat_s = 1.0\nduration_s = 2.0\n",
            "t.toml:12: faults[0].duration_s: controller_kill lasts to the end of the run",
        ),
        (
            "[[faults]]\nkind = \"gps_jump\"\nat_s = 1.0\neast_m = nan\nnorth_m = 0.0\n",
            "t.toml:12: faults[0].east_m:",
        ),
        (
            "[[faults]]\nkind = \"laser_occluded\"\nat_s = 1.0\nfrom_deg = 10.0\nto_deg = -10.0\n",
            "t.toml:13: faults[0].to_deg:",
        ),
        (
            "[expect]\nsafe_within_s = 1.0\necus_stay_enabled = true\n",
            "t.toml:11: expect.ecus_stay_enabled: contradicts safe_within_s",
        ),
    ];
    for (table, want) in cases {
        let text = with_fault(table);
        let err = Scenario::from_toml(&text, "t.toml")
            .expect_err(table)
            .to_string();
        assert!(err.contains(want), "{table}\n got: {err}\nwant: {want}");
    }
    // Unknown keys are refused by the parser, with their line.
    let err = Scenario::from_toml(
        &with_fault("[[faults]]\nkind = \"gps_outage\"\nat_s = 1.0\nwhen = 2\n"),
        "t.toml",
    )
    .expect_err("unknown key")
    .to_string();
    assert!(err.contains("when"), "{err}");
    // A plan file is checked the same way, under its own name.
    let err = PlanFile::from_toml("[[faults]]\nkind = \"laser_blackout\"\n", "plan.toml")
        .expect_err("no start")
        .to_string();
    assert!(
        err.contains("plan.toml:1: faults[0].at_s: missing"),
        "{err}"
    );
}

/// Expectations that could not fail are refused at load: a `detected_by` that is no
/// reaction code (the old substring match let `""` or `"e"` pass every fault), and an
/// expectation about faults in a scenario without any.
#[test]
fn expectations_that_could_not_fail_are_refused_at_load() {
    let outage = "[[faults]]\nkind = \"gps_outage\"\nat_s = 1.0\n";
    for (table, want) in [
        (
            format!("{outage}[expect]\ndetected_by = \"\"\n"),
            "t.toml:13: expect.detected_by: \"\" is not a reaction code",
        ),
        (
            format!("{outage}[expect]\ndetected_by = \"e\"\n"),
            "t.toml:13: expect.detected_by: \"e\" is not a reaction code",
        ),
        (
            format!("{outage}[expect]\ndetected_by = \"controller: FAULT_REPORT gps_lost\"\n"),
            "t.toml:13: expect.detected_by: \"controller: FAULT_REPORT gps_lost\" is not a reaction code",
        ),
        (
            "[expect]\ndetected_within_s = 0.3\n".to_owned(),
            "t.toml:10: expect.detected_within_s: an expectation about faults, and no [[faults]]",
        ),
        (
            "[expect]\necus_stay_enabled = true\n".to_owned(),
            "t.toml:10: expect.ecus_stay_enabled: an expectation about faults, and no [[faults]]",
        ),
    ] {
        let err = Scenario::from_toml(&with_fault(&table), "t.toml")
            .expect_err(&table)
            .to_string();
        assert!(err.contains(want), "{table}\n got: {err}\nwant: {want}");
    }
    // The codes are listed, and a code the DBC defines loads.
    let err = Scenario::from_toml(
        &with_fault(&format!("{outage}[expect]\ndetected_by = \"e\"\n")),
        "t.toml",
    )
    .expect_err("e")
    .to_string();
    assert!(
        err.contains("gps_lost") && err.contains("command_timeout"),
        "{err}"
    );
    Scenario::from_toml(
        &with_fault(&format!("{outage}[expect]\ndetected_by = \"gps_lost\"\n")),
        "t.toml",
    )
    .expect("gps_lost is a reaction code");
    // A plan file's [expect] may be about the scenario's faults; the scenario with the
    // plan is checked as a whole.
    let plan = PlanFile::from_toml("[expect]\nsafe_within_s = 0.5\n", "plan.toml")
        .expect("a plan of expectations alone");
    let err = Scenario::from_toml(&with_fault(""), "t.toml")
        .expect("no faults")
        .with_overrides(ugv_sim::scenario::Overrides {
            faults: Some(plan),
            ..Default::default()
        })
        .expect_err("expectation without faults")
        .to_string();
    assert!(
        err.contains("expect.safe_within_s: an expectation about faults, and no [[faults]]"),
        "{err}"
    );
}

/// A fault that never took effect (1 ns long; a drop of probability 0) fails the run,
/// with or without expectations.
#[test]
fn a_fault_that_injects_nothing_fails_the_run() {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite/01-paper.toml"),
    )
    .expect("paper scenario")
        + "\n[sim]\ntime_limit_s = 4.0\n[success]\nreach_goal = false\n\
           [[faults]]\nkind = \"can_drop\"\nnode = \"steering\"\nprobability = 0.0\nat_s = 1.0\n\
           [[faults]]\nkind = \"gps_outage\"\nat_s = 2.0\nduration_s = 1e-9\n";
    let sc = Scenario::from_toml(&text, "t.toml").expect("scenario");
    let cfg = ugv_sim::mission::controller_config(&sc, FollowerKind::Optimal);
    let run = ugv_sim::sil::run_sil(sc.clone(), &cfg).expect("run");
    let v = ugv_sim::verdict::Verdict::judge(
        ugv_sim::Mode::Sil,
        &sc,
        run.sim.report(run.outcome),
        Some(&run.trace),
    );
    assert!(!v.passed, "{:?}", v.failures);
    for want in [
        "faults[0] can_drop at 1.00 s: fault never injected",
        "faults[1] gps_outage at 2.00 s: fault never injected",
    ] {
        assert!(
            v.failures.iter().any(|f| f.starts_with(want)),
            "{want}: {:?}",
            v.failures
        );
    }
}

/// Each frame the injector corrupts is a frame the controller's receiver rejects, for
/// the reason injected (counted over the whole run, after the fault has ended).
#[test]
fn injected_frames_are_the_frames_the_controller_rejects() {
    for (table, rejected) in [
        (
            "kind = \"can_corrupt_crc\"\nnode = \"steering\"\n",
            (|s: &golf_car_can::E2eStats| s.bad_crc) as fn(&golf_car_can::E2eStats) -> u64,
        ),
        ("kind = \"can_dlc\"\nnode = \"throttle\"\ndlc = 3\n", |s| {
            s.wrong_dlc
        }),
        (
            "kind = \"can_counter\"\nnode = \"throttle\"\nmode = \"repeat\"\n",
            |s| s.repeated_counter,
        ),
    ] {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/suite/01-paper.toml"),
        )
        .expect("paper scenario")
            + &format!(
                "\n[sim]\ntime_limit_s = 8.0\n[success]\nreach_goal = false\n[[faults]]\n{table}at_s = 3.0\nduration_s = 0.5\n"
            );
        let sc = Scenario::from_toml(&text, "t.toml").expect(table);
        let cfg = suite::default_tune(FollowerKind::Optimal)(&sc);
        let mut stats = golf_car_can::E2eStats::default();
        let run = run_sil_with(sc, &cfg, |_, rt| {
            stats = rt.can().stats();
            Hook::Continue
        })
        .expect("SIL run");
        let faults = run.sim.fault_records();
        let injected = faults[0].injected;
        assert!(
            injected >= 20,
            "{table}: {injected} frames injected in 0.5 s"
        );
        assert_eq!(rejected(&stats), injected, "{table}: {stats:?}");
        // And the controller stopped the car for it.
        assert!(
            faults[0].steering_safe_ms.is_some() && faults[0].throttle_safe_ms.is_some(),
            "{table}: {:?}",
            faults[0]
        );
    }
}

#[test]
fn an_overloaded_bus_with_bit_timing_shows_as_late_frames_and_fails_unless_expected() {
    let file = fault_files()
        .into_iter()
        .find(|f| f.ends_with("43-can-bus-overload-arbitrated.toml"))
        .expect("the arbitrated overload scenario");
    let mut sc = Scenario::load(&file).expect("scenario");
    assert!(sc.can.bit_timing && sc.expect.bus_overloaded);
    let cfg = ugv_sim::mission::controller_config(&sc, FollowerKind::Optimal);
    let judge = |sc: &Scenario| {
        let run = ugv_sim::sil::run_sil(sc.clone(), &cfg).expect("run");
        ugv_sim::verdict::Verdict::judge(
            ugv_sim::Mode::Sil,
            sc,
            run.sim.report(run.outcome),
            Some(&run.trace),
        )
    };
    let v = judge(&sc);
    assert!(v.passed, "{:?}", v.failures);
    let a = v
        .report
        .bus_load
        .arbitration
        .clone()
        .expect("a bus with bit timing reports its arbitration");
    assert!(a.late > 100 && a.max_wait_ms > 100.0, "{a:?}");
    // The same schedule, not expected to overload the bus: the verdict says why.
    sc.expect.bus_overloaded = false;
    let v = judge(&sc);
    assert!(
        v.failures
            .iter()
            .any(|f| f.contains("could not carry the schedule")),
        "{:?}",
        v.failures
    );
    // The paper's schedule fits: nothing waits longer than a step.
    let mut paper = Scenario::paper().expect("paper");
    paper.can.bit_timing = true;
    let v = judge(&paper);
    let a = v.report.bus_load.arbitration.clone().expect("arbitration");
    assert!(
        v.passed && a.late == 0 && a.delivered > 1000,
        "{a:?} {:?}",
        v.failures
    );
}
