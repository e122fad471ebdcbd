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
    /// the follower's 3 inputs) for the ANFIS follower with a model, else the optimal
    /// law.
    pub fn from_config(cfg: &ControllerConfig) -> Result<SteeringLaw, GuidanceError> {
        Ok(match (&cfg.follower.kind, &cfg.follower.anfis_model) {
            (FollowerKind::Anfis, Some(path)) => {
                let model = AnfisModel::load(path).map_err(|source| GuidanceError::Anfis {
                    path: path.display().to_string(),
                    source,
                })?;
                if model.n_inputs() != 3 {
                    return Err(GuidanceError::AnfisInputs {
                        path: path.display().to_string(),
                        found: model.n_inputs(),
                    });
                }
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
