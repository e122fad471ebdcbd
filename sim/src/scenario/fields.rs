//! Reading scenario-like TOML files (scenarios, bench files, fault plans) with errors
//! that name the file, the line and the field, and the field checks of a scenario's
//! geometry that the shared toolkit (`ugv_fields`) does not know.

use ugv_fields::{FieldError, FieldPath, LocatedError, coordinate, positive_up_to, within};

use super::schema::Motion;

/// Why a scenario was refused.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("{file}: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// Syntax errors and unknown or mistyped fields (the TOML error names line and column).
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    /// A well-formed value that makes no sense (a negative radius, a goal inside a
    /// wall...), with the file and line it is on.
    #[error(transparent)]
    Invalid(#[from] LocatedError),
}

/// Parse TOML `text` of `file` into `T`, its syntax and unknown or mistyped fields
/// refused with the TOML error (which names line and column).
pub fn parse<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, ScenarioError> {
    toml::from_str(text).map_err(|e| ScenarioError::Parse {
        file: file.to_owned(),
        message: e.to_string().trim_end().to_owned(),
    })
}

/// Read the text of `path`.
pub fn read(path: &std::path::Path) -> Result<String, ScenarioError> {
    std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
        file: path.display().to_string(),
        source,
    })
}

pub(super) fn check_points(
    path: &FieldPath,
    points: &[[f64; 2]],
    min: usize,
) -> Result<(), FieldError> {
    if points.len() < min {
        return Err(FieldError::new(
            path.clone(),
            format!("needs at least {min} points, has {}", points.len()),
        ));
    }
    if points.len() > MAX_POINTS {
        return Err(FieldError::new(
            path.clone(),
            format!(
                "has {} points, at most {MAX_POINTS} are allowed",
                points.len()
            ),
        ));
    }
    for (i, p) in points.iter().enumerate() {
        coordinate(&path.index(i), p[0])?;
        coordinate(&path.index(i), p[1])?;
    }
    Ok(())
}

/// Most obstacles in a scenario.
pub(super) const MAX_OBSTACLES: usize = 10_000;

/// Most points of a wall or a waypoint path.
const MAX_POINTS: usize = 10_000;

/// The fastest an obstacle may move, m/s (a car on a course road, with room to spare).
const MAX_OBSTACLE_SPEED: f64 = 50.0;

pub(super) fn check_motion(path: &FieldPath, motion: &Option<Motion>) -> Result<(), FieldError> {
    match motion {
        None => Ok(()),
        Some(Motion::Velocity { vx, vy }) => {
            within(
                &path.key("vx"),
                *vx,
                -MAX_OBSTACLE_SPEED,
                MAX_OBSTACLE_SPEED,
                "m/s",
            )?;
            within(
                &path.key("vy"),
                *vy,
                -MAX_OBSTACLE_SPEED,
                MAX_OBSTACLE_SPEED,
                "m/s",
            )
        }
        Some(Motion::Waypoints { points, speed, .. }) => {
            check_points(&path.key("points"), points, 2)?;
            positive_up_to(&path.key("speed"), *speed, MAX_OBSTACLE_SPEED, "m/s")
        }
    }
}
