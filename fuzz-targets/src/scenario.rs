//! Scenario files: what `ugv-sim check` does with each file (`Scenario::load`, that is
//! `Scenario::from_toml`, then `mission::checked_controller_config`), the checks
//! `ugv-sim run` makes before it starts anything.

use ugv_controller::config::{ControllerConfig, FollowerKind};
use ugv_sim::Scenario;
use ugv_sim::mission::checked_controller_config;

/// `scenario_toml`: the bytes as a scenario file (read as UTF-8 text, then the checks
/// of `ugv-sim check`).
///
/// Invariants of a scenario that passes them: the controller configuration derived
/// from it, printed as the CONTROLLER.toml a HIL run writes (`toml::to_string_pretty`),
/// is accepted by the controller binary (`ControllerConfig::from_toml`, what
/// `ugv-controller run --config` loads) and prints the same again; with either
/// follower (ANFIS with a model path, as `--follower anfis --anfis-model` gives).
pub fn scenario_toml(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(scenario) = Scenario::from_toml(text, "fuzz.toml") else {
        return;
    };
    for (follower, model) in [
        (FollowerKind::Optimal, None),
        (FollowerKind::Anfis, Some("anfis.json".into())),
    ] {
        let Ok(cfg) = checked_controller_config(&scenario, follower, model) else {
            continue;
        };
        let printed = match toml::to_string_pretty(&cfg) {
            Ok(t) => t,
            Err(e) => panic!("CONTROLLER.toml of a checked scenario does not print: {e}"),
        };
        let again = match ControllerConfig::from_toml(&printed, "CONTROLLER.toml") {
            Ok(c) => c,
            Err(e) => panic!(
                "the controller refuses the CONTROLLER.toml of a checked scenario: {e}\n{printed}"
            ),
        };
        match toml::to_string_pretty(&again) {
            Ok(t) => assert_eq!(t, printed, "CONTROLLER.toml changes when reloaded"),
            Err(e) => panic!("a reloaded CONTROLLER.toml does not print: {e}"),
        }
    }
}
