//! WGS-84 geodesy for the GPS seam: the world frame of the simulator and the
//! controller is a local East-North-Up (ENU) tangent frame around a configured datum;
//! the GPS wire carries WGS-84 latitude, longitude and height.
//!
//! The conversions go through Earth-centred Earth-fixed (ECEF) coordinates on the
//! WGS-84 ellipsoid (the `map_3d` crate): exact, not a flat-earth approximation, so a
//! point 2 km from the datum comes back within a fraction of a millimetre.
//!
//! Angle conventions:
//! - world: x = East, y = North, z = Up; heading `theta` in radians, counter-clockwise
//!   from +x (East), as in the rest of the project;
//! - GPS: course over ground and true heading in degrees, clockwise from true North,
//!   in `[0, 360)`.
//!
//! Heights are ellipsoidal (above the WGS-84 ellipsoid). NMEA GGA carries the height
//! above the geoid (mean sea level) plus the geoid separation; see
//! [`crate::nmea::GpsFix`].

use std::f64::consts::{PI, TAU};

use map_3d::Ellipsoid;
use serde::{Deserialize, Serialize};

/// WGS-84 semi-major axis, metres.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared, `f (2 - f)`.
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// Errors of the geodesy module.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeodesyError {
    #[error("datum {field} = {value} is outside {min}..={max}")]
    DatumOutOfRange {
        field: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// The geodetic origin of a local world frame (x East, y North, z Up), as written in
/// scenario and controller configuration files.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Datum {
    /// Degrees, WGS-84.
    pub latitude: f64,
    /// Degrees, WGS-84.
    pub longitude: f64,
    /// Metres above the ellipsoid.
    pub altitude: f64,
}

impl Default for Datum {
    /// Virginia State University, Petersburg VA (the seed paper's authors).
    fn default() -> Self {
        Datum {
            latitude: 37.2307,
            longitude: -77.4197,
            altitude: 40.0,
        }
    }
}

impl Datum {
    /// The datum as a geodetic position.
    pub fn geodetic(&self) -> Geodetic {
        Geodetic {
            lat_deg: self.latitude,
            lon_deg: self.longitude,
            height_m: self.altitude,
        }
    }
}

/// A WGS-84 geodetic position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Geodetic {
    /// Latitude, degrees, positive North.
    pub lat_deg: f64,
    /// Longitude, degrees, positive East, in `(-180, 180]`.
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid, metres.
    pub height_m: f64,
}

/// A point in the local East-North-Up frame (the world frame: x = East, y = North).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Enu {
    pub east_m: f64,
    pub north_m: f64,
    pub up_m: f64,
}

/// The local tangent frame around a datum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    datum: Geodetic,
    lat0: f64,
    lon0: f64,
}

impl LocalFrame {
    /// A frame whose origin is `datum` (latitude within ±90°, longitude within ±180°,
    /// height within ±100 km, all finite).
    pub fn new(datum: Geodetic) -> Result<Self, GeodesyError> {
        check_range("latitude", datum.lat_deg, -90.0, 90.0)?;
        check_range("longitude", datum.lon_deg, -180.0, 180.0)?;
        check_range("height", datum.height_m, -100_000.0, 100_000.0)?;
        Ok(Self {
            datum,
            lat0: datum.lat_deg.to_radians(),
            lon0: datum.lon_deg.to_radians(),
        })
    }

    /// The origin of the frame.
    pub fn datum(&self) -> Geodetic {
        self.datum
    }

    /// Geodetic position of a local ENU point.
    pub fn to_geodetic(&self, p: Enu) -> Geodetic {
        let (lat, lon, h) = map_3d::enu2geodetic(
            p.east_m,
            p.north_m,
            p.up_m,
            self.lat0,
            self.lon0,
            self.datum.height_m,
            Ellipsoid::WGS84,
        );
        Geodetic {
            lat_deg: lat.to_degrees(),
            lon_deg: normalize_lon_deg(lon.to_degrees()),
            height_m: h,
        }
    }

    /// Local ENU coordinates of a geodetic position.
    pub fn to_enu(&self, g: Geodetic) -> Enu {
        let (e, n, u) = map_3d::geodetic2enu(
            g.lat_deg.to_radians(),
            g.lon_deg.to_radians(),
            g.height_m,
            self.lat0,
            self.lon0,
            self.datum.height_m,
            Ellipsoid::WGS84,
        );
        Enu {
            east_m: e,
            north_m: n,
            up_m: u,
        }
    }
}

fn check_range(field: &'static str, value: f64, min: f64, max: f64) -> Result<(), GeodesyError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(GeodesyError::DatumOutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}

/// Longitude wrapped into `(-180, 180]`.
pub fn normalize_lon_deg(lon: f64) -> f64 {
    let w = (lon + 180.0).rem_euclid(360.0) - 180.0;
    if w == -180.0 { 180.0 } else { w }
}

/// Degrees wrapped into `[0, 360)`.
pub fn normalize_deg_360(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    // rem_euclid can round up to exactly 360.0 for tiny negative inputs.
    if w >= 360.0 { 0.0 } else { w }
}

/// Radians wrapped into `(-pi, pi]`. An angle already within a turn of the wrap
/// (`rad + pi` in `[0, 2 pi)`, most of them) skips the `rem_euclid`: its remainder is
/// the angle itself, exactly, and the floating-point remainder costs some 30
/// instructions a call.
pub fn normalize_rad_pi(rad: f64) -> f64 {
    let shifted = rad + PI;
    let w = if (0.0..TAU).contains(&shifted) {
        shifted
    } else {
        shifted.rem_euclid(TAU)
    } - PI;
    if w <= -PI { w + TAU } else { w }
}

/// World heading `theta` (radians, counter-clockwise from East) to a GPS course or
/// true heading (degrees, clockwise from North, `[0, 360)`).
pub fn theta_to_course_deg(theta_rad: f64) -> f64 {
    normalize_deg_360(90.0 - theta_rad.to_degrees())
}

/// GPS course or true heading (degrees, clockwise from North) to world heading
/// `theta` (radians, counter-clockwise from East, `(-pi, pi]`).
pub fn course_deg_to_theta(course_deg: f64) -> f64 {
    normalize_rad_pi((90.0 - course_deg).to_radians())
}

/// Course over ground (degrees clockwise from North) of a world velocity
/// (`v_east`, `v_north`, m/s); 0 for a zero velocity.
pub fn course_of_velocity_deg(v_east: f64, v_north: f64) -> f64 {
    normalize_deg_360(v_east.atan2(v_north).to_degrees())
}

/// Meridian radius of curvature of WGS-84 at a latitude, metres:
/// `M = a (1 - e²) / (1 - e² sin² φ)^(3/2)`.
pub fn meridian_radius_m(lat_deg: f64) -> f64 {
    let s = lat_deg.to_radians().sin();
    WGS84_A * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s * s).powf(1.5)
}

/// Prime-vertical radius of curvature of WGS-84 at a latitude, metres:
/// `N = a / sqrt(1 - e² sin² φ)`.
pub fn prime_vertical_radius_m(lat_deg: f64) -> f64 {
    let s = lat_deg.to_radians().sin();
    WGS84_A / (1.0 - WGS84_E2 * s * s).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heading_conventions() {
        // East: theta 0 is course 90; North: theta pi/2 is course 0.
        assert!((theta_to_course_deg(0.0) - 90.0).abs() < 1e-12);
        assert!(theta_to_course_deg(PI / 2.0).abs() < 1e-12);
        assert!((theta_to_course_deg(PI) - 270.0).abs() < 1e-12);
        assert!((theta_to_course_deg(-PI / 2.0) - 180.0).abs() < 1e-12);
        assert!((course_deg_to_theta(0.0) - PI / 2.0).abs() < 1e-12);
        assert!((course_deg_to_theta(180.0) + PI / 2.0).abs() < 1e-12);
        assert!((course_of_velocity_deg(1.0, 0.0) - 90.0).abs() < 1e-12);
        assert!((course_of_velocity_deg(0.0, -1.0) - 180.0).abs() < 1e-12);
    }

    #[test]
    fn normalisations() {
        assert_eq!(normalize_lon_deg(-180.0), 180.0);
        assert_eq!(normalize_lon_deg(190.0), -170.0);
        assert_eq!(normalize_deg_360(-1e-20), 0.0);
        assert_eq!(normalize_deg_360(360.0), 0.0);
        assert!((normalize_rad_pi(-PI) - PI).abs() < 1e-15);
    }

    #[test]
    fn normalize_rad_pi_without_the_remainder_equals_it() {
        let wrapped = |rad: f64| {
            let w = (rad + PI).rem_euclid(TAU) - PI;
            if w <= -PI { w + TAU } else { w }
        };
        let edges = [
            -PI,
            PI,
            -PI - 1e-16,
            PI - 1e-16,
            TAU - PI,
            0.0,
            -0.0,
            1e-300,
        ];
        let sweep = (-4000..=4000).map(|i| f64::from(i) * 0.002_718_281_828);
        for rad in edges.into_iter().chain(sweep) {
            for r in [rad, rad.next_up(), rad.next_down()] {
                assert_eq!(normalize_rad_pi(r).to_bits(), wrapped(r).to_bits(), "{r}");
            }
        }
        assert!(normalize_rad_pi(f64::NAN).is_nan());
    }

    #[test]
    fn datum_out_of_range_is_refused() {
        let bad = Geodetic {
            lat_deg: 91.0,
            lon_deg: 0.0,
            height_m: 0.0,
        };
        assert!(matches!(
            LocalFrame::new(bad),
            Err(GeodesyError::DatumOutOfRange {
                field: "latitude",
                ..
            })
        ));
    }
}
