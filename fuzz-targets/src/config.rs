//! The controller configuration: `ControllerConfig::from_toml`, what `ugv-controller
//! run --config` and `check-config` load.

use ugv_controller::config::ControllerConfig;
use ugv_controller::control::Controller;

/// `controller_config`: the bytes as a configuration file (read as UTF-8 text, then
/// `ControllerConfig::from_toml`, which parses and validates).
///
/// Invariants of a configuration that loads: what `check-config` prints
/// (`toml::to_string_pretty`) loads again and prints the same (the simulator writes
/// CONTROLLER.toml the same way); the controller builds from it (`Controller::new`, as
/// `run` does next) or refuses it with an error. `follower.anfis_model` names a file,
/// which the fuzzer must not make the target open (it could be /dev/zero): it is
/// cleared before `Controller::new`; the model loader has a target of its own.
pub fn controller_config(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(cfg) = ControllerConfig::from_toml(text, "fuzz.toml") else {
        return;
    };
    let printed = match toml::to_string_pretty(&cfg) {
        Ok(t) => t,
        Err(e) => panic!("a loaded configuration does not print as TOML: {e}: {cfg:?}"),
    };
    let again = match ControllerConfig::from_toml(&printed, "printed.toml") {
        Ok(c) => c,
        Err(e) => panic!("the printed configuration does not load: {e}\n{printed}"),
    };
    match toml::to_string_pretty(&again) {
        Ok(t) => assert_eq!(
            t, printed,
            "the printed configuration changes when reloaded"
        ),
        Err(e) => panic!("a reloaded configuration does not print: {e}"),
    }
    let mut cfg = cfg;
    cfg.follower.anfis_model = None;
    cfg.follower.kind = ugv_controller::config::FollowerKind::Optimal;
    let _ = Controller::new(&cfg);
}
