//! The receiver's errors: a first-order Gauss-Markov position error plus white noise,
//! white velocity and heading noise, from one seeded ChaCha8 stream.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use super::config::FixModel;

/// The GPS receiver's ChaCha stream number: `sim.seed` keys the generator, this picks
/// the GPS's own stream ("GPS" in ASCII), so other noise sources never share draws.
pub const GPS_STREAM: u64 = 0x0047_5053;

/// One epoch's errors, world frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EpochError {
    /// Position error east, north, up, metres.
    pub east_m: f64,
    pub north_m: f64,
    pub up_m: f64,
    /// Velocity error east and north, m/s.
    pub v_east_mps: f64,
    pub v_north_mps: f64,
    /// Heading error, degrees.
    pub heading_deg: f64,
}

/// The error processes. Every epoch draws the same nine normals whatever the fix
/// state, so the stream (and so every later epoch) does not depend on when fix
/// events happen.
///
/// The Gauss-Markov state is kept in units of its standard deviation and scaled by
/// the current fix state's sigma, so a change of fix state changes the error's size
/// at once (an RTK fix that drops to float jumps from centimetres to decimetres)
/// while the process stays continuous in shape. Discretisation is exact for any step:
/// `z' = a z + sqrt(1 - a^2) w`, `a = exp(-dt / tau)`, which keeps `z` at unit variance.
#[derive(Debug)]
pub struct ErrorModel {
    rng: ChaCha8Rng,
    /// Gauss-Markov state, unit variance: east, north, up.
    z: [f64; 3],
    last_t: Option<f64>,
}

impl ErrorModel {
    pub fn new(seed: u64) -> ErrorModel {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(GPS_STREAM);
        // Start in the stationary distribution.
        let z = [0; 3].map(|_| rng.sample::<f64, _>(StandardNormal));
        ErrorModel {
            rng,
            z,
            last_t: None,
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    /// The errors of the epoch at sim time `t` under `model` (`None`: no fix, the
    /// processes advance with a 60 s time constant and the errors are zero), with a
    /// white heading error of `heading_sigma_deg`.
    pub fn epoch(
        &mut self,
        t: f64,
        model: Option<&FixModel>,
        heading_sigma_deg: f64,
    ) -> EpochError {
        let tau = model.map_or(60.0, |m| m.time_constant_s);
        let dt = self.last_t.map_or(0.0, |last| (t - last).max(0.0));
        self.last_t = Some(t);
        let a = (-dt / tau).exp();
        let b = (1.0 - a * a).max(0.0).sqrt();
        let innovation = [self.normal(), self.normal(), self.normal()];
        for (z, w) in self.z.iter_mut().zip(innovation) {
            *z = a * *z + b * w;
        }
        let white = [self.normal(), self.normal(), self.normal()];
        let vel = [self.normal(), self.normal()];
        let heading = self.normal();
        let Some(m) = model else {
            return EpochError::default();
        };
        let (gm, wh) = ((1.0 - m.white_fraction).sqrt(), m.white_fraction.sqrt());
        let axis = |i: usize, sigma: f64| sigma * (gm * self.z[i] + wh * white[i]);
        EpochError {
            east_m: axis(0, m.horizontal_sigma_m),
            north_m: axis(1, m.horizontal_sigma_m),
            up_m: axis(2, m.vertical_sigma_m),
            v_east_mps: m.velocity_sigma_mps * vel[0],
            v_north_mps: m.velocity_sigma_mps * vel[1],
            heading_deg: heading_sigma_deg * heading,
        }
    }
}
