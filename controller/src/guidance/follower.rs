//! The path follower: what it sees against the planned path ([`FollowInputs`]), and
//! the steering law that turns that into a road-wheel angle ([`SteeringLaw`]): the
//! paper's optimal law, or an ANFIS model loaded from the configuration.

use super::error::GuidanceError;
use crate::anfis::AnfisModel;
use crate::config::{ControllerConfig, FollowerKind};

/// What the follower sees: errors against the path at the vehicle's position.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FollowInputs {
    /// Signed lateral error (left of the path positive), metres.
    pub e_y: f64,
    /// Heading error, radians.
    pub e_theta: f64,
    /// The path's steering angle at this point (the optimal law's feed-forward), radians.
    pub phi_ref: f64,
    /// Speed, m/s.
    pub v: f64,
}

impl FollowInputs {
    /// The inputs an ANFIS follower takes, in this order.
    pub const NAMES: [&'static str; 3] = ["e_y", "e_theta", "phi_ref"];
}

/// The steering law.
#[derive(Debug, Clone)]
pub enum SteeringLaw {
    /// phi = phi_ref - k_y e_y - k_theta e_theta, gains scheduled on speed so the
    /// lateral error has natural frequency omega and damping zeta.
    Optimal {
        omega: f64,
        zeta: f64,
        wheelbase: f64,
    },
    Anfis(Box<AnfisModel>),
}

impl SteeringLaw {
    /// The law the configuration asks for: the ANFIS model of its file (which must take
    /// the follower's inputs by name, [`FollowInputs::NAMES`] in this order: they are
    /// fed by position) for the ANFIS follower with a model, else the optimal law.
    pub fn from_config(cfg: &ControllerConfig) -> Result<SteeringLaw, GuidanceError> {
        Ok(match (&cfg.follower.kind, &cfg.follower.anfis_model) {
            (FollowerKind::Anfis, Some(path)) => {
                let model = AnfisModel::load(path)
                    .and_then(|m| m.check_input_names(&FollowInputs::NAMES).map(|()| m))
                    .map_err(|source| GuidanceError::Anfis {
                        path: path.display().to_string(),
                        source,
                    })?;
                SteeringLaw::Anfis(Box::new(model))
            }
            _ => SteeringLaw::Optimal {
                omega: cfg.follower.omega,
                zeta: cfg.follower.zeta,
                wheelbase: cfg.vehicle.wheelbase,
            },
        })
    }

    /// The steering angle to command, radians (before the actuator limit).
    pub fn steer(&self, i: &FollowInputs) -> f64 {
        match self {
            SteeringLaw::Optimal {
                omega,
                zeta,
                wheelbase,
            } => {
                let v = i.v.abs().max(0.5);
                let k_y = omega * omega * wheelbase / (v * v);
                let k_theta = 2.0 * zeta * omega * wheelbase / v;
                i.phi_ref - k_y * i.e_y - k_theta * i.e_theta
            }
            // A model that cannot evaluate (it validated at load) falls back to the
            // feed-forward alone rather than to a wild command.
            SteeringLaw::Anfis(m) => m
                .predict(&[i.e_y, i.e_theta, i.phi_ref])
                .unwrap_or(i.phi_ref),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model of one bell per input and one rule, its inputs named `names`.
    fn model_file(dir: &std::path::Path, names: &[&str]) -> std::path::PathBuf {
        let inputs: Vec<serde_json::Value> = names
            .iter()
            .map(|n| {
                serde_json::json!({"name": n, "range": [-1.0, 1.0],
                                   "mfs": [{"a": 1.0, "b": 2.0, "c": 0.0}]})
            })
            .collect();
        let model = serde_json::json!({
            "format": "ugv-anfis", "version": 1, "inputs": inputs, "output": "phi",
            "rules": [{"antecedent": vec![0; names.len()], "p": vec![0.0; names.len()], "r": 0.0}],
        });
        let path = dir.join(format!("{}.json", names.join("-")));
        std::fs::write(&path, model.to_string()).unwrap();
        path
    }

    #[test]
    fn an_anfis_model_must_take_the_followers_inputs_by_name_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let load = |names: &[&str]| {
            let mut cfg = ControllerConfig::default();
            cfg.follower.kind = FollowerKind::Anfis;
            cfg.follower.anfis_model = Some(model_file(dir.path(), names));
            SteeringLaw::from_config(&cfg).map_err(|e| e.to_string())
        };
        assert!(matches!(
            load(&["e_y", "e_theta", "phi_ref"]),
            Ok(SteeringLaw::Anfis(_))
        ));
        for (names, says) in [
            (
                &["e_y", "phi_ref", "e_theta"][..],
                "e_y-phi_ref-e_theta.json: invalid ANFIS model: inputs[1].name: is \"phi_ref\" \
                 where \"e_theta\" is fed; the inputs must be (e_y, e_theta, phi_ref), in this order",
            ),
            (
                &["x", "y", "z"][..],
                "inputs[0].name: is \"x\" where \"e_y\" is fed",
            ),
            (
                &["e_y", "e_theta"][..],
                "invalid ANFIS model: inputs: the model takes 2 inputs (e_y, e_theta); they must be \
                 (e_y, e_theta, phi_ref), in this order",
            ),
        ] {
            let e = load(names).err().unwrap_or_default();
            assert!(e.contains(says), "{names:?}\n got: {e}\nwant: {says}");
        }
    }

    #[test]
    fn optimal_law_corrects_towards_the_path() {
        let law = SteeringLaw::Optimal {
            omega: 0.9,
            zeta: 0.8,
            wheelbase: 1.65,
        };
        let base = FollowInputs {
            e_y: 0.0,
            e_theta: 0.0,
            phi_ref: 0.1,
            v: 2.0,
        };
        assert_eq!(law.steer(&base), 0.1, "on the path: the feed-forward alone");
        assert!(
            law.steer(&FollowInputs { e_y: 0.5, ..base }) < 0.1,
            "left of the path: steer right"
        );
        assert!(
            law.steer(&FollowInputs {
                e_theta: -0.1,
                ..base
            }) > 0.1
        );
    }
}
