//! Scenario files: `Scenario::from_toml`, what `ugv-sim check` and `ugv-sim run` load.

use ugv_controller::config::{ControllerConfig, FollowerKind};
use ugv_sim::Scenario;
use ugv_sim::mission::controller_config;

/// `scenario_toml`: the bytes as a scenario file (read as UTF-8 text, then
/// `Scenario::from_toml`, which `Scenario::load` calls for `ugv-sim check` and `run`).
///
/// Invariants of a scenario that loads: the controller configuration the simulator
/// derives from it (`mission::controller_config`) prints as the CONTROLLER.toml the
/// HIL run writes (`toml::to_string_pretty`) and that text parses back as a
/// configuration (TOML and types; whether its values pass the controller's checks is
/// the controller's business) that prints the same.
pub fn scenario_toml(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(scenario) = Scenario::from_toml(text, "fuzz.toml") else {
        return;
    };
    for follower in [FollowerKind::Optimal, FollowerKind::Anfis] {
        let cfg = controller_config(&scenario, follower);
        let printed = match toml::to_string_pretty(&cfg) {
            Ok(t) => t,
            Err(e) => panic!("CONTROLLER.toml of a valid scenario does not print: {e}"),
        };
        let again: ControllerConfig = match toml::from_str(&printed) {
            Ok(c) => c,
            Err(e) => panic!("CONTROLLER.toml of a valid scenario does not parse: {e}\n{printed}"),
        };
        match toml::to_string_pretty(&again) {
            Ok(t) => assert_eq!(t, printed, "CONTROLLER.toml changes when reloaded"),
            Err(e) => panic!("a reloaded CONTROLLER.toml does not print: {e}"),
        }
    }
}
