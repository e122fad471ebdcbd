//! Noise statistics of the simulated receiver for a fixed seed, per fix quality, read
//! back through the NMEA wire: the horizontal and vertical error sigmas match the
//! model and the GST sentence, the errors are unbiased, correlated in time as the
//! Gauss-Markov model says (not white), and heading and velocity noise have their sigmas.
//!
//! Bounds are 5 standard errors of each estimator for the sample at hand. The position
//! error per axis is `sigma (sqrt(1-f) z + sqrt(f) w)`, `z` a unit AR(1) with
//! `a = exp(-dt / tau)` and `w` white, so its autocorrelation is `rho_0 = 1`,
//! `rho_k = (1-f) a^k`; for N samples of a zero-mean Gaussian process
//! `var(s^2 / sigma^2) = (2 / N) sum_k rho_k^2` (k over all integers) and
//! `var(mean / sigma) = (1 / N) sum_k rho_k`; the lag-1 autocorrelation estimate has
//! Bartlett's variance `(1 / N) sum_k (rho_{k+1} + rho_{k-1} - 2 rho_1 rho_k)^2`.

mod gps_common;

use anyhow::{Context as _, Result, ensure};
use gps_common::{device, read_one, reader, vehicle};
use ugv_sim::devices::gps::{FixKind, FixModel, GpsConfig};

/// Ten hours at 1 Hz.
const N: usize = 36_000;
const RATE_HZ: f64 = 1.0;
/// Standard errors allowed.
const K: f64 = 5.0;

fn rho(m: &FixModel, k: i64) -> f64 {
    if k == 0 {
        1.0
    } else {
        let a = (-1.0 / (RATE_HZ * m.time_constant_s)).exp();
        (1.0 - m.white_fraction) * a.powi(k.unsigned_abs().min(1_000_000) as i32)
    }
}

/// Sum of rho_k^p over k in [-L, L], L far beyond the correlation time.
fn sum_rho(m: &FixModel, p: i32) -> f64 {
    (-20_000..=20_000).map(|k| rho(m, k).powi(p)).sum()
}

fn bartlett_lag1(m: &FixModel) -> f64 {
    let r1 = rho(m, 1);
    (-20_000..=20_000)
        .map(|k| (rho(m, k + 1) + rho(m, k - 1) - 2.0 * r1 * rho(m, k)).powi(2))
        .sum::<f64>()
        / N as f64
}

struct Errors {
    east: Vec<f64>,
    north: Vec<f64>,
    up: Vec<f64>,
    heading: Vec<f64>,
    v_east: Vec<f64>,
    v_north: Vec<f64>,
    gst: (f64, f64, f64),
}

fn collect(fix: FixKind) -> Result<(GpsConfig, Errors)> {
    let cfg = GpsConfig {
        rate_hz: RATE_HZ,
        fix,
        ..GpsConfig::default()
    };
    let mut dev = device(cfg.clone())?;
    let mut rd = reader(&cfg);
    let s = vehicle(25.0, -40.0, 60.0, 0.0, 0.0);
    let mut e = Errors {
        east: Vec::with_capacity(N),
        north: Vec::with_capacity(N),
        up: Vec::with_capacity(N),
        heading: Vec::with_capacity(N),
        v_east: Vec::with_capacity(N),
        v_north: Vec::with_capacity(N),
        gst: (0.0, 0.0, 0.0),
    };
    for k in 0..N {
        let epoch = dev
            .poll(k as f64 / RATE_HZ, &s)?
            .context("an epoch each second")?;
        let r = read_one(&mut rd, &epoch.text)?;
        let enu = r.enu(dev.frame()).context("position")?;
        e.east.push(enu.east_m - epoch.truth.enu.east_m);
        e.north.push(enu.north_m - epoch.truth.enu.north_m);
        e.up.push(r.ellipsoid_height_m().context("height")? - epoch.truth.geodetic.height_m);
        let dh = r.heading_deg.context("heading")? - epoch.truth.heading_deg;
        e.heading.push((dh + 540.0).rem_euclid(360.0) - 180.0);
        let (speed, course) = (
            r.speed_mps.context("speed")?,
            r.course_deg.context("course")?.to_radians(),
        );
        e.v_east.push(speed * course.sin());
        e.v_north.push(speed * course.cos());
        let a = r.accuracy.context("GST")?;
        ensure!(
            a.lat_sigma_m == a.lon_sigma_m,
            "GST lat/lon sigmas differ: {a:?}"
        );
        e.gst = (a.lat_sigma_m, a.lon_sigma_m, a.alt_sigma_m);
    }
    Ok((cfg, e))
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn lag1(x: &[f64]) -> f64 {
    let m = mean(x);
    let var: f64 = x.iter().map(|v| (v - m).powi(2)).sum();
    let cov: f64 = x.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    cov / var
}

fn check(fix: FixKind) -> Result<()> {
    let (cfg, e) = collect(fix)?;
    let m = cfg.model(fix).context("a model")?;
    let n = N as f64;
    // GST says what the model says (written with millimetres, parsed as f32).
    ensure!(
        (e.gst.0 - m.horizontal_sigma_m).abs() < 1e-6,
        "{fix:?}: GST {:?}",
        e.gst
    );
    ensure!(
        (e.gst.2 - m.vertical_sigma_m).abs() < 1e-6,
        "{fix:?}: GST {:?}",
        e.gst
    );

    // Sigma: relative standard error of s is half that of s^2.
    let se_sigma = (2.0 * sum_rho(&m, 2) / n).sqrt() / 2.0;
    let horizontal = ((rms(&e.east).powi(2) + rms(&e.north).powi(2)) / 2.0).sqrt();
    let bound_h = K * se_sigma / 2f64.sqrt(); // two independent axes pooled
    let ratio_h = horizontal / e.gst.0;
    ensure!(
        (ratio_h - 1.0).abs() < bound_h,
        "{fix:?}: horizontal sigma {horizontal:.4} m vs GST {} m (ratio {ratio_h:.4}, bound ±{bound_h:.4})",
        e.gst.0
    );
    let ratio_v = rms(&e.up) / e.gst.2;
    ensure!(
        (ratio_v - 1.0).abs() < K * se_sigma,
        "{fix:?}: vertical sigma {:.4} m vs GST {} m (ratio {ratio_v:.4}, bound ±{:.4})",
        rms(&e.up),
        e.gst.2,
        K * se_sigma
    );
    eprintln!(
        "{fix:?}: sigma ratios horizontal {ratio_h:.4} (±{bound_h:.4}), vertical {ratio_v:.4} (±{:.4}); lag-1 model {:.4}",
        K * se_sigma,
        rho(&m, 1)
    );
    // No bias.
    let se_mean = (sum_rho(&m, 1) / n).sqrt();
    for (axis, x, sigma) in [
        ("east", &e.east, m.horizontal_sigma_m),
        ("north", &e.north, m.horizontal_sigma_m),
        ("up", &e.up, m.vertical_sigma_m),
    ] {
        let mu = mean(x) / sigma;
        ensure!(
            mu.abs() < K * se_mean,
            "{fix:?}: {axis} mean {mu:.4} sigma (bound {:.4})",
            K * se_mean
        );
    }
    // Correlated as the model says: far from white noise's 0.
    let want = rho(&m, 1);
    let bound = K * bartlett_lag1(&m).sqrt();
    for (axis, x) in [("east", &e.east), ("north", &e.north), ("up", &e.up)] {
        let r1 = lag1(x);
        ensure!(
            (r1 - want).abs() < bound,
            "{fix:?}: {axis} lag-1 autocorrelation {r1:.4}, model {want:.4} ± {bound:.4}"
        );
    }
    // White heading and velocity noise.
    let se_white = 1.0 / (2.0 * n).sqrt();
    let rh = rms(&e.heading) / cfg.heading_sigma_deg;
    ensure!(
        (rh - 1.0).abs() < K * se_white,
        "{fix:?}: heading sigma ratio {rh:.4}"
    );
    let rv =
        ((rms(&e.v_east).powi(2) + rms(&e.v_north).powi(2)) / 2.0).sqrt() / m.velocity_sigma_mps;
    // Speed goes out in 0.001 knot (0.5 mm/s) steps: negligible against 2 cm/s.
    ensure!(
        (rv - 1.0).abs() < K * se_white / 2f64.sqrt() + 0.001,
        "{fix:?}: velocity sigma ratio {rv:.4}"
    );
    Ok(())
}

#[test]
fn rtk_fixed_noise_statistics() -> Result<()> {
    check(FixKind::Rtk)
}

#[test]
fn rtk_float_noise_statistics() -> Result<()> {
    check(FixKind::Float)
}

#[test]
fn single_point_noise_statistics() -> Result<()> {
    check(FixKind::Single)
}
