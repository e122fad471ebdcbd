//! Localisation: GPS fixes (latitude, longitude) into the local world frame around
//! the datum, the antenna's offset removed to get the rear axle; heading from the
//! dual-antenna heading, or from course over ground while moving; speed and steering
//! angle from the actuators' reports; dead reckoning (the bicycle model, integrated
//! report by report) between fixes, which at 1 Hz are a second and 2 m apart.
//!
//! Beyond taking each fix as it is:
//! - Fix filter: each accepted fix pulls the dead-reckoned pose (position and heading)
//!   towards it by 1 - exp(-dt / tau) (at most half way), dt the time since the last
//!   fix and tau the fix kind's time constant (`localisation.fix_time_constant_s`,
//!   shorter for RTK fixed than for float): white position noise is averaged over a few fixes while the
//!   motion in between comes from dead reckoning, so the pose does not lag. A fix after
//!   the GPS was lost, or the first, is taken as it is.
//! - Steering bias: the wheels may stand off the reported angle (a sensor zero off).
//!   While the car drives straight-ish at speed, the heading change between fixes
//!   (their own headings, unfiltered) against the one dead-reckoned from the reported
//!   angle plus the current estimate says how much bias is left; every metre window
//!   moves the estimate by `steer_bias_gain` of that, within `max_steer_bias_deg`. The
//!   pose's angle, dead reckoning and the controller's commands use the corrected angle.
//! - [`propagate`]: the pose a dead time ahead, with the commands still on their way.

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

/// The bias estimator's window: the heading change over at least this far, metres.
const BIAS_WINDOW_M: f64 = 1.0;
/// It learns only above this speed (m/s) and within this road-wheel angle (degrees),
/// where the heading change is large against the headings' noise and the kinematic
/// model holds best.
const BIAS_MIN_SPEED: f64 = 0.8;
const BIAS_MAX_STEER_DEG: f64 = 12.0;

/// The fix filter never gives a fix more than this weight: at low rates (1 Hz) dead
/// reckoning carries the second between fixes with errors well below the fixes' own
/// noise, so that noise is still averaged over a few fixes.
const MAX_FIX_PULL: f64 = 0.5;

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

/// The rear axle `ds` further along the arc of road-wheel angle `phi` (midpoint
/// heading).
fn advance(p: &mut Pose, ds: f64, phi: f64, wheelbase: f64) {
    let dtheta = ds * phi.tan() / wheelbase;
    let mid = p.theta + dtheta / 2.0;
    p.x += ds * mid.cos();
    p.y += ds * mid.sin();
    p.theta = normalize_rad_pi(p.theta + dtheta);
}

/// The pose `dt` seconds ahead for each target, speed held: in each step the road-wheel
/// angle first moves towards the step's target (the command acting then, in the
/// corrected angle; `None`: the ECU holds) with the actuator's first-order
/// `time_constant`, then the bicycle model advances. The controller propagates its
/// pose over the steering dead time with the commands sent in it, so the law acts on
/// where the car will be when its command bites (a Smith predictor).
pub fn propagate(
    pose: &Pose,
    wheelbase: f64,
    time_constant: f64,
    dt: f64,
    targets: impl IntoIterator<Item = Option<f64>>,
) -> Pose {
    let pull = if time_constant > 0.0 {
        1.0 - (-dt / time_constant).exp()
    } else {
        1.0
    };
    let mut p = *pose;
    for target in targets {
        if let Some(t) = target {
            p.phi += pull * (t - p.phi);
        }
        let (ds, phi) = (p.v * dt, p.phi);
        advance(&mut p, ds, phi, wheelbase);
    }
    p
}

/// The heading change from one fix's heading, and what dead reckoning made of it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct BiasWindow {
    /// The fix's heading the window starts from, radians.
    theta: f64,
    /// Heading change and distance dead-reckoned since, radians and metres.
    turned: f64,
    driven: f64,
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
    /// The reported road-wheel angle, radians (the wheels stand at it plus `bias`).
    phi: f64,
    /// Fix filter time constants for RTK fixed and for other fixes, seconds.
    fix_tau: (f64, f64),
    /// The steering bias estimate, its gain and bound, radians.
    bias: f64,
    bias_gain: f64,
    max_bias: f64,
    window: Option<BiasWindow>,
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
            fix_tau: (
                cfg.localisation.fix_time_constant_s,
                cfg.localisation.float_fix_time_constant_s,
            ),
            bias: 0.0,
            bias_gain: cfg.localisation.steer_bias_gain,
            max_bias: cfg.localisation.max_steer_bias_deg.to_radians(),
            window: None,
        })
    }

    /// The actuators' measured speed and steering angle (from their reports) at `now`:
    /// the pose is dead-reckoned up to now with the previous ones, then these hold.
    /// `phi` is the reported angle; the estimated bias is added to it.
    pub fn on_actuators(&mut self, now: f64, speed: f64, phi: f64) {
        self.dead_reckon(now);
        self.speed = speed;
        self.phi = phi;
    }

    /// The estimated steering bias, radians: the wheels stand at the reported angle
    /// plus this, so a command for an angle asks for it minus this.
    pub fn steer_bias(&self) -> f64 {
        self.bias
    }

    /// Dead-reckon the pose up to `now` and keep it (and the bias window's share).
    fn dead_reckon(&mut self, now: f64) -> Option<Pose> {
        let p = self.predict(now)?;
        let until = now.min(self.fixed_at + self.horizon);
        let dt = (until - self.at).max(0.0);
        let phi = self.phi + self.bias;
        if dt > 0.0
            && let Some(w) = &mut self.window
        {
            if self.speed >= BIAS_MIN_SPEED && phi.abs() <= BIAS_MAX_STEER_DEG.to_radians() {
                let ds = self.speed * dt;
                w.turned += ds * phi.tan() / self.wheelbase;
                w.driven += ds;
            } else {
                self.window = None;
            }
        }
        self.pose = Some(p);
        self.at = self.at.max(until);
        Some(p)
    }

    /// A fix's own heading `theta` (`None`: it had none): closes the bias window once it
    /// is long enough, moving the estimate, and opens the next.
    fn learn_bias(&mut self, theta: Option<f64>) {
        let Some(theta) = theta else {
            self.window = None;
            return;
        };
        match self.window {
            Some(w) if w.driven >= BIAS_WINDOW_M => {
                let left = self.wheelbase * normalize_rad_pi(theta - w.theta - w.turned) / w.driven;
                self.bias =
                    (self.bias + self.bias_gain * left).clamp(-self.max_bias, self.max_bias);
            }
            Some(_) => return,
            None => {}
        }
        self.window = Some(BiasWindow {
            theta,
            turned: 0.0,
            driven: 0.0,
        });
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
        let since_fix = now - self.fixed_at;
        let previous = self.dead_reckon(now);
        // The fix's own heading, if it has one.
        let measured = if let Some(h) = r.heading_deg {
            Some(course_deg_to_theta(h))
        } else if let (Some(c), Some(s)) = (r.course_deg, r.speed_mps) {
            // Reversing: the course points backwards.
            (s >= COG_MIN_SPEED).then(|| {
                let cog = course_deg_to_theta(c);
                if self.speed < 0.0 {
                    normalize_rad_pi(cog + std::f64::consts::PI)
                } else {
                    cog
                }
            })
        } else {
            None
        };
        self.heading_known |= measured.is_some();
        let theta = measured.unwrap_or(previous.map_or(0.0, |p| p.theta));
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
            phi: self.phi + self.bias,
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
                self.window = None;
                return;
            }
        }
        self.learn_bias(measured);
        // The filter's pull: all the way for the first fix and after the GPS was lost.
        let tau = if quality == FixQuality::RtkFixed {
            self.fix_tau.0
        } else {
            self.fix_tau.1
        };
        let pull = match previous {
            Some(_) if tau > 0.0 && since_fix <= self.horizon => {
                (1.0 - (-since_fix / tau).exp()).min(MAX_FIX_PULL)
            }
            _ => 1.0,
        };
        let pose = previous.map_or(pose, |p| Pose {
            x: p.x + pull * (pose.x - p.x),
            y: p.y + pull * (pose.y - p.y),
            theta: normalize_rad_pi(p.theta + pull * normalize_rad_pi(pose.theta - p.theta)),
            ..pose
        });
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
        let phi = self.phi + self.bias;
        advance(&mut p, self.speed * dt, phi, self.wheelbase);
        p.v = self.speed;
        p.phi = phi;
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

    /// Deterministic standard normal samples (xorshift64 and Box-Muller), for noise.
    struct Normal(u64);

    impl Normal {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }

        fn sample(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// The fix of the antenna of a car whose rear axle is at `p`, plus `noise` metres
    /// east and north, with its heading.
    fn fix_of(frame: &LocalFrame, p: &Pose, antenna_x: f64, noise: (f64, f64)) -> GpsReading {
        let mut r = reading(
            frame,
            p.x + antenna_x * p.theta.cos() + noise.0,
            p.y + antenna_x * p.theta.sin() + noise.1,
            Some(firmware_bridge::geodesy::theta_to_course_deg(p.theta)),
        );
        r.speed_mps = Some(p.v);
        r
    }

    #[test]
    fn propagation_over_the_dead_time_predicts_the_pose() {
        // A car at 2 m/s whose steering acts 0.25 s late through a 0.08 s lag, weaving
        // on commands of up to 15 degrees. The truth is integrated in 1 ms steps.
        let (wheelbase, dead, lag, dt) = (1.65, 0.25, 0.08f64, 0.01);
        let command = |t: f64| 15f64.to_radians() * (1.3 * t).sin();
        let mut truth = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.3,
            v: 2.0,
            phi: 0.0,
        };
        let mut states = Vec::new();
        for i in 0..4000 {
            let t = f64::from(i) * 0.001;
            if i % 10 == 0 {
                states.push((t, truth));
            }
            // The command sent at the last 10 ms tick at least the dead time ago.
            let sent = ((t - dead) / dt + 1e-9).floor() * dt;
            let target = if sent >= 0.0 { command(sent) } else { 0.0 };
            truth.phi += (target - truth.phi) * (1.0 - (-0.001 / lag).exp());
            let (ds, phi) = (truth.v * 0.001, truth.phi);
            advance(&mut truth, ds, phi, wheelbase);
        }
        let steps = (dead / dt).round() as u32;
        for k in [200usize, 250, 300, 350] {
            let (now, at_now) = states[k];
            let (_, later) = states[k + steps as usize];
            let ahead = propagate(
                &at_now,
                wheelbase,
                lag,
                dt,
                (0..steps).map(|j| {
                    let sent = ((now + f64::from(j) * dt - dead) / dt + 1e-9).floor() * dt;
                    Some(command(sent))
                }),
            );
            let error = (ahead.x - later.x).hypot(ahead.y - later.y);
            let stale = (at_now.x - later.x).hypot(at_now.y - later.y);
            assert!(stale > 0.45, "the car moves half a metre in the dead time");
            assert!(error < 0.01, "at {now}: {error} m off");
            let heading_error = (ahead.theta - later.theta).abs();
            assert!(
                heading_error < 0.2f64.to_radians(),
                "at {now}: {heading_error}"
            );
            assert!((ahead.phi - later.phi).abs() < 0.5f64.to_radians());
            // Without the commands on their way (the ECU holding its angle) the
            // heading is mispredicted several times worse.
            let held = propagate(&at_now, wheelbase, lag, dt, (0..steps).map(|_| None));
            assert!(
                (held.theta - later.theta).abs() > 3.0 * heading_error,
                "at {now}: {} against {heading_error}",
                (held.theta - later.theta).abs()
            );
        }
    }

    /// A car weaving gently at 2 m/s for `seconds`, its wheels at the reported angle
    /// plus `bias` (radians), fixes at 10 Hz with 0.1 degree heading noise; returns the
    /// localiser's bias estimate after each fix.
    fn drive_with_bias(cfg: &ControllerConfig, bias: f64, speed: f64, seconds: f64) -> Vec<f64> {
        let mut loc = Localiser::new(cfg).expect("datum");
        let frame = loc.frame;
        let mut noise = Normal(0x9e37_79b9_7f4a_7c15);
        let mut truth = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: speed,
            phi: 0.0,
        };
        let mut estimates = Vec::new();
        for i in 0..(seconds * 100.0) as u32 {
            let t = f64::from(i) * 0.01;
            let reported = 6f64.to_radians() * (0.4 * t).sin() - bias;
            loc.on_actuators(t, speed, reported);
            if i % 10 == 0 {
                let mut r = fix_of(&frame, &truth, cfg.vehicle.antenna_x, (0.0, 0.0));
                r.heading_deg = r.heading_deg.map(|h| h + 0.1 * noise.sample());
                loc.on_fix(t, &r);
                estimates.push(loc.steer_bias());
            }
            truth.phi = reported + bias;
            let (ds, phi) = (speed * 0.01, truth.phi);
            advance(&mut truth, ds, phi, cfg.vehicle.wheelbase);
        }
        estimates
    }

    #[test]
    fn the_steering_bias_estimate_converges_and_stays_bounded() {
        let cfg = ControllerConfig::default();
        let bias = 3f64.to_radians();
        let estimates = drive_with_bias(&cfg, bias, 2.0, 60.0);
        let settled = &estimates[estimates.len() / 2..];
        for b in settled {
            assert!((b - bias).abs() < 0.3f64.to_radians(), "{}", b.to_degrees());
        }
        // Not there at once: it is a slow estimator.
        assert!((estimates[10] - bias).abs() > 1f64.to_radians());
        // A bias beyond the bound: the estimate stops at it.
        let max = cfg.localisation.max_steer_bias_deg.to_radians();
        let beyond = drive_with_bias(&cfg, 8f64.to_radians(), 2.0, 60.0);
        assert!(beyond.iter().all(|b| b.abs() <= max + 1e-12));
        assert!((beyond[beyond.len() - 1] - max).abs() < 1e-9);
        // Creeping below the speed gate, or with the gain 0, it learns nothing.
        assert!(
            drive_with_bias(&cfg, bias, 0.5, 30.0)
                .iter()
                .all(|b| *b == 0.0)
        );
        let mut off = cfg.clone();
        off.localisation.steer_bias_gain = 0.0;
        assert!(
            drive_with_bias(&off, bias, 2.0, 30.0)
                .iter()
                .all(|b| *b == 0.0)
        );
    }

    #[test]
    fn the_fix_filter_averages_white_noise_and_follows_a_step() {
        let cfg = ControllerConfig::default();
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        let mut noise = Normal(0x2545_f491_4f6c_dd1d);
        let standing = Pose {
            x: 10.0,
            y: 5.0,
            theta: 0.5,
            v: 0.0,
            phi: 0.0,
        };
        let sigma = 0.08;
        let (mut raw, mut filtered) = (Vec::new(), Vec::new());
        for i in 0..400 {
            let t = f64::from(i) * 0.1;
            let n = (sigma * noise.sample(), sigma * noise.sample());
            loc.on_fix(t, &fix_of(&frame, &standing, cfg.vehicle.antenna_x, n));
            let p = loc.predict(t).expect("pose");
            raw.push(n.0);
            filtered.push(p.x - standing.x);
        }
        let rms = |e: &[f64]| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        let (raw, filtered) = (rms(&raw[20..]), rms(&filtered[20..]));
        assert!((raw - sigma).abs() < 0.015, "{raw}");
        assert!(filtered < 0.5 * raw, "{filtered} against {raw}");
        // A step of 0.3 m (RTK float converging, say): followed within two seconds, not
        // taken at once.
        let moved = Pose {
            x: standing.x + 0.3,
            ..standing
        };
        let mut after = Vec::new();
        for i in 400..420 {
            let t = f64::from(i) * 0.1;
            loc.on_fix(
                t,
                &fix_of(&frame, &moved, cfg.vehicle.antenna_x, (0.0, 0.0)),
            );
            after.push(loc.predict(t).expect("pose").x - moved.x);
        }
        assert!(after[0] < -0.15, "{after:?}");
        assert!(after[19].abs() < 0.01, "{after:?}");
        // Without the filter each fix is taken as it is.
        let mut raw_cfg = cfg.clone();
        raw_cfg.localisation.fix_time_constant_s = 0.0;
        let mut loc = Localiser::new(&raw_cfg).expect("datum");
        loc.on_fix(
            0.0,
            &fix_of(&frame, &standing, cfg.vehicle.antenna_x, (0.0, 0.0)),
        );
        loc.on_fix(
            0.1,
            &fix_of(&frame, &moved, cfg.vehicle.antenna_x, (0.0, 0.0)),
        );
        assert!((loc.predict(0.1).expect("pose").x - moved.x).abs() < 1e-6);
    }

    #[test]
    fn a_moving_car_s_exact_fixes_keep_the_filtered_pose_on_the_truth() {
        // Dead reckoning carries the motion between fixes: the filter adds no lag.
        let cfg = ControllerConfig::default();
        let mut loc = Localiser::new(&cfg).expect("datum");
        let frame = loc.frame;
        let mut truth = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.2,
            v: 2.0,
            phi: 0.1,
        };
        for i in 0..500 {
            let t = f64::from(i) * 0.01;
            loc.on_actuators(t, truth.v, truth.phi);
            if i % 10 == 0 {
                loc.on_fix(
                    t,
                    &fix_of(&frame, &truth, cfg.vehicle.antenna_x, (0.0, 0.0)),
                );
                let p = loc.predict(t).expect("pose");
                assert!(
                    (p.x - truth.x).hypot(p.y - truth.y) < 0.005,
                    "{t}: {p:?} {truth:?}"
                );
            }
            let (ds, phi) = (truth.v * 0.01, truth.phi);
            advance(&mut truth, ds, phi, cfg.vehicle.wheelbase);
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
