//! Localisation: GPS fixes (latitude, longitude) into the local world frame around
//! the datum, the antenna's offset removed to get the rear axle; heading from the
//! dual-antenna heading, or from course over ground while moving; speed and steering
//! angle from the actuators' reports; dead reckoning (the bicycle model, integrated
//! report by report) between fixes, which at 1 Hz are a second and 2 m apart.

use firmware_bridge::geodesy::{Enu, Geodetic, LocalFrame, course_deg_to_theta, normalize_rad_pi};
use firmware_bridge::nmea::{FixQuality, GpsReading};

use crate::config::ControllerConfig;

/// Course over ground is trusted for heading above this speed, m/s.
const COG_MIN_SPEED: f64 = 0.8;

/// A fix refused for landing too far from the dead-reckoned pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jump {
    pub at: f64,
    pub metres: f64,
}

/// How late a fix may reach the controller after its epoch, for the jump gate, s.
const FIX_AGE_ALLOWANCE_S: f64 = 0.3;

/// The farthest a fix may land from the dead-reckoned pose, metres: several times
/// what the fix kind's noise and a second of dead reckoning explain (RTK fixed: 1-2
/// cm; float: decimetres), so only a jump or multipath exceeds it.
fn jump_gate(quality: FixQuality) -> f64 {
    match quality {
        FixQuality::RtkFixed => 0.5,
        FixQuality::RtkFloat => 2.0,
        _ => 10.0,
    }
}

/// The estimated state of the rear axle in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    /// Heading, radians CCW from East.
    pub theta: f64,
    /// Wheel speed, m/s.
    pub v: f64,
    /// Road-wheel angle, radians.
    pub phi: f64,
}

/// The localiser's state.
#[derive(Debug, Clone)]
pub struct Localiser {
    frame: LocalFrame,
    wheelbase: f64,
    antenna: (f64, f64),
    pose: Option<Pose>,
    heading_known: bool,
    /// Time of the pose estimate.
    at: f64,
    /// Dead reckoning goes no further than this past the last fix (beyond it the GPS
    /// counts as lost), seconds.
    horizon: f64,
    /// Time of the last fix with a position.
    fixed_at: f64,
    /// Time and quality of the last fix with a position.
    pub last_fix: Option<(f64, FixQuality)>,
    /// The first fix that landed too far from the dead-reckoned pose (a jump,
    /// multipath): refused, and kept for the safety check.
    pub jump: Option<Jump>,
    /// The fix kind of the fix the pose was last taken from.
    pose_quality: Option<FixQuality>,
    speed: f64,
    phi: f64,
}

impl Localiser {
    pub fn new(
        cfg: &ControllerConfig,
    ) -> Result<Localiser, firmware_bridge::geodesy::GeodesyError> {
        Ok(Localiser {
            frame: LocalFrame::new(cfg.mission.datum.geodetic())?,
            wheelbase: cfg.vehicle.wheelbase,
            antenna: (cfg.vehicle.antenna_x, cfg.vehicle.antenna_y),
            pose: None,
            heading_known: false,
            at: 0.0,
            horizon: cfg.safety.gps_timeout(),
            fixed_at: 0.0,
            last_fix: None,
            jump: None,
            pose_quality: None,
            speed: 0.0,
            phi: 0.0,
        })
    }

    /// The actuators' measured speed and steering angle (from their reports) at `now`:
    /// the pose is dead-reckoned up to now with the previous ones, then these hold.
    pub fn on_actuators(&mut self, now: f64, speed: f64, phi: f64) {
        if let Some(p) = self.predict(now) {
            self.pose = Some(p);
            self.at = self.at.max(now.min(self.fixed_at + self.horizon));
        }
        self.speed = speed;
        self.phi = phi;
    }

    /// A GPS epoch arrived at `now`.
    pub fn on_fix(&mut self, now: f64, r: &GpsReading) {
        let quality = r.quality.unwrap_or(FixQuality::Invalid);
        let Some(enu) = r
            .lat_deg
            .zip(r.lon_deg)
            .filter(|_| quality.has_position())
            .map(|(lat, lon)| {
                // Height does not matter for the plane; use the datum's if absent.
                let height = r
                    .ellipsoid_height_m()
                    .unwrap_or(self.frame.datum().height_m);
                self.frame.to_enu(Geodetic {
                    lat_deg: lat,
                    lon_deg: lon,
                    height_m: height,
                })
            })
        else {
            self.last_fix = Some((now, quality));
            return;
        };
        self.last_fix = Some((now, quality));
        let previous = self.predict(now);
        let theta = if let Some(h) = r.heading_deg {
            self.heading_known = true;
            course_deg_to_theta(h)
        } else if let (Some(c), Some(s)) = (r.course_deg, r.speed_mps) {
            if s >= COG_MIN_SPEED {
                self.heading_known = true;
                // Reversing: the course points backwards.
                let cog = course_deg_to_theta(c);
                if self.speed < 0.0 {
                    normalize_rad_pi(cog + std::f64::consts::PI)
                } else {
                    cog
                }
            } else {
                previous.map_or(0.0, |p| p.theta)
            }
        } else {
            previous.map_or(0.0, |p| p.theta)
        };
        let Enu {
            east_m, north_m, ..
        } = enu;
        let (c, s) = (theta.cos(), theta.sin());
        let (ax, ay) = self.antenna;
        let pose = Pose {
            x: east_m - (ax * c - ay * s),
            y: north_m - (ax * s + ay * c),
            theta,
            v: self.speed,
            phi: self.phi,
        };
        if let Some(p) = previous {
            let metres = (pose.x - p.x).hypot(pose.y - p.y);
            // A change of fix kind moves the position by the worse kind's error
            // (float converging to fixed): the wider gate of the two holds.
            // The fix is compared with the pose now, but it was taken at its epoch and
            // may arrive late (a loaded machine, a slow line): the way driven in that
            // time is no jump.
            let gate = jump_gate(quality).max(self.pose_quality.map_or(0.0, jump_gate))
                + self.speed.abs() * FIX_AGE_ALLOWANCE_S;
            if metres > gate {
                self.jump.get_or_insert(Jump { at: now, metres });
                return;
            }
        }
        self.pose = Some(pose);
        self.pose_quality = Some(quality);
        self.at = now;
        self.fixed_at = now;
    }

    /// The pose at `now`, dead-reckoned from the last estimate with the measured speed
    /// and steering angle, no further than the GPS timeout past the last fix.
    pub fn predict(&self, now: f64) -> Option<Pose> {
        let mut p = self.pose?;
        let until = now.min(self.fixed_at + self.horizon);
        let dt = (until - self.at).max(0.0);
        let ds = self.speed * dt;
        let dtheta = ds * self.phi.tan() / self.wheelbase;
        let mid = p.theta + dtheta / 2.0;
        p.x += ds * mid.cos();
        p.y += ds * mid.sin();
        p.theta = normalize_rad_pi(p.theta + dtheta);
        p.v = self.speed;
        p.phi = self.phi;
        Some(p)
    }

    /// Whether the heading has been observed (dual antenna, or course while moving).
    pub fn heading_known(&self) -> bool {
        self.heading_known
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(frame: &LocalFrame, east: f64, north: f64, heading_deg: Option<f64>) -> GpsReading {
        let g = frame.to_geodetic(Enu {
            east_m: east,
            north_m: north,
            up_m: 0.0,
        });
        GpsReading {
            quality: Some(FixQuality::RtkFixed),
            lat_deg: Some(g.lat_deg),
            lon_deg: Some(g.lon_deg),
            altitude_msl_m: Some(g.height_m),
            geoid_separation_m: Some(0.0),
            heading_deg,
            speed_mps: Some(0.0),
            course_deg: Some(0.0),
            ..GpsReading::default()
        }
    }

    #[test]
    fn antenna_offset_is_removed_along_the_heading() {
        let cfg = ControllerConfig::default();
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        // Heading 45 degrees CCW from East = course 45 degrees from North.
        let (ax, theta) = (cfg.vehicle.antenna_x, 45f64.to_radians());
        loc.on_fix(
            1.0,
            &reading(
                &frame,
                10.0 + ax * theta.cos(),
                5.0 + ax * theta.sin(),
                Some(45.0),
            ),
        );
        let p = loc.predict(1.0).expect("pose");
        assert!(
            (p.x - 10.0).abs() < 1e-6 && (p.y - 5.0).abs() < 1e-6,
            "{p:?}"
        );
        assert!((p.theta - theta).abs() < 1e-9);
        assert!(loc.heading_known());
    }

    #[test]
    fn dead_reckoning_follows_the_bicycle_model_between_fixes() {
        let cfg = ControllerConfig::default();
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        loc.on_actuators(0.0, 2.0, 0.0);
        loc.on_fix(
            0.0,
            &reading(&frame, cfg.vehicle.antenna_x, 0.0, Some(90.0)),
        );
        let p = loc.predict(0.5).expect("pose");
        assert!((p.x - 1.0).abs() < 1e-6 && p.y.abs() < 1e-6, "{p:?}");
    }

    #[test]
    fn no_heading_until_observed_and_no_position_without_a_fix() {
        let cfg = ControllerConfig::default();
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        let mut r = reading(&frame, 0.0, 0.0, None);
        r.quality = Some(FixQuality::Invalid);
        loc.on_fix(0.0, &r);
        assert!(loc.predict(0.0).is_none());
        r.quality = Some(FixQuality::RtkFixed);
        loc.on_fix(0.1, &r);
        assert!(loc.predict(0.1).is_some() && !loc.heading_known());
        r.speed_mps = Some(2.0);
        r.course_deg = Some(90.0);
        loc.on_fix(0.2, &r);
        assert!(loc.heading_known());
        assert!(
            loc.predict(0.2).expect("pose").theta.abs() < 1e-9,
            "course 90 = East = theta 0"
        );
    }

    #[test]
    fn dead_reckoning_integrates_each_report_between_one_hertz_fixes() {
        let mut cfg = ControllerConfig::default();
        cfg.safety.gps_rate_hz = 1.0;
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        loc.on_fix(
            0.0,
            &reading(&frame, cfg.vehicle.antenna_x, 0.0, Some(90.0)),
        );
        // Accelerating at 1 m/s^2, reported every 10 ms: 0.5 m after 1 s, not the
        // 1 m the last speed alone would give.
        for i in 1..=100 {
            let t = f64::from(i) * 0.01;
            loc.on_actuators(t, t, 0.0);
        }
        let p = loc.predict(1.0).expect("pose");
        assert!((p.x - 0.5).abs() < 0.02, "{p:?}");
        // Dead reckoning stops at the GPS timeout (2.5 s at 1 Hz) past the fix.
        assert_eq!(cfg.safety.gps_timeout(), 2.5);
        let far = loc.predict(10.0).expect("pose");
        assert!((far.x - (0.5 + 1.5)).abs() < 0.02, "{far:?}");
    }
}
