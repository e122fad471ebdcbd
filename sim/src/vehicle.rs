//! The golf car: the kinematic bicycle model of the seed paper (eq. 1-3), reference
//! point at the rear axle, driven by the actuators' actual road-wheel angle and wheel
//! speed.
//!
//! x' = v cos(theta), y' = v sin(theta), theta' = v tan(phi) / L.
//!
//! Within one step v and phi are held, and the step is integrated exactly (an arc of
//! radius L / tan(phi), or a straight line), so the model has no integration error:
//! constant steering traces a circle of radius L / tan(phi) to rounding.

use crate::scenario::schema::{Pose, VehicleConfig};

/// The vehicle's state in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct VehicleState {
    /// Rear-axle centre, metres.
    pub x: f64,
    pub y: f64,
    /// Heading, radians, counter-clockwise from +x.
    pub theta: f64,
    /// Signed speed of the rear axle, m/s (negative backwards).
    pub v: f64,
    /// Road-wheel angle, radians, positive to the left.
    pub phi: f64,
    /// Distance travelled, metres.
    pub odometer: f64,
}

impl VehicleState {
    /// At rest at a pose.
    pub fn at(pose: &Pose) -> VehicleState {
        VehicleState {
            x: pose.x,
            y: pose.y,
            theta: pose.heading(),
            v: 0.0,
            phi: 0.0,
            odometer: 0.0,
        }
    }

    /// Advance by `dt` with speed `v` and road-wheel angle `phi` held (exact).
    pub fn step(&mut self, wheelbase: f64, v: f64, phi: f64, dt: f64) {
        let ds = v * dt;
        let kappa = phi.tan() / wheelbase;
        let dtheta = kappa * ds;
        if dtheta.abs() < 1e-9 {
            // Straight (second-order term kept for continuity).
            let mid = self.theta + dtheta / 2.0;
            self.x += ds * mid.cos();
            self.y += ds * mid.sin();
        } else {
            let r = 1.0 / kappa;
            self.x += r * ((self.theta + dtheta).sin() - self.theta.sin());
            self.y -= r * ((self.theta + dtheta).cos() - self.theta.cos());
        }
        self.theta = wrap_angle(self.theta + dtheta);
        self.v = v;
        self.phi = phi;
        self.odometer += ds.abs();
    }

    /// The footprint rectangle's centre in the world frame and its heading.
    pub fn footprint_center(&self, cfg: &VehicleConfig) -> (f64, f64) {
        let ahead = cfg.length / 2.0 - cfg.rear_overhang;
        (
            self.x + ahead * self.theta.cos(),
            self.y + ahead * self.theta.sin(),
        )
    }

    /// The footprint's four corners, counter-clockwise from rear right.
    pub fn footprint_corners(&self, cfg: &VehicleConfig) -> [(f64, f64); 4] {
        let (cx, cy) = self.footprint_center(cfg);
        let (c, s) = (self.theta.cos(), self.theta.sin());
        let (hl, hw) = (cfg.length / 2.0, cfg.width / 2.0);
        [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)]
            .map(|(a, b)| (cx + a * c - b * s, cy + a * s + b * c))
    }
}

/// Wrap an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start() -> VehicleState {
        VehicleState::at(&Pose {
            x: 0.0,
            y: 0.0,
            heading_deg: 0.0,
        })
    }

    #[test]
    fn constant_steering_traces_the_closed_form_circle() {
        let l = 1.65;
        for phi_deg in [-30.0f64, -5.0, 2.0, 20.0, 35.0] {
            let phi = phi_deg.to_radians();
            let r = l / phi.tan();
            let mut s = start();
            // Centre of the circle: left of the start by r (right when r < 0).
            let (cx, cy) = (0.0, r);
            let mut max_err: f64 = 0.0;
            for _ in 0..4000 {
                s.step(l, 2.0, phi, 0.005);
                let d = ((s.x - cx).powi(2) + (s.y - cy).powi(2)).sqrt();
                max_err = max_err.max((d - r.abs()).abs());
            }
            assert!(max_err < 1e-9, "phi {phi_deg}: radius error {max_err}");
            // Heading change equals arc length / r.
            let expected = wrap_angle(s.odometer / r);
            assert!((wrap_angle(s.theta - expected)).abs() < 1e-9);
        }
    }

    #[test]
    fn straight_line_and_reverse() {
        let mut s = start();
        s.theta = 0.3;
        for _ in 0..100 {
            s.step(1.65, 1.0, 0.0, 0.01);
        }
        assert!((s.x - 0.3f64.cos()).abs() < 1e-12 && (s.y - 0.3f64.sin()).abs() < 1e-12);
        for _ in 0..100 {
            s.step(1.65, -1.0, 0.0, 0.01);
        }
        assert!(s.x.abs() < 1e-12 && s.y.abs() < 1e-12);
        assert!((s.odometer - 2.0).abs() < 1e-12);
    }

    #[test]
    fn footprint_surrounds_the_axles() {
        let cfg = VehicleConfig::default();
        let s = start();
        let corners = s.footprint_corners(&cfg);
        let xs: Vec<f64> = corners.iter().map(|c| c.0).collect();
        assert!((xs.iter().cloned().fold(f64::MAX, f64::min) + cfg.rear_overhang).abs() < 1e-12);
        let front = xs.iter().cloned().fold(f64::MIN, f64::max);
        assert!(
            front > cfg.wheelbase,
            "front bumper {front} ahead of the front axle"
        );
        assert!((corners[2].1 - cfg.width / 2.0).abs() < 1e-12);
    }
}
