//! The error of scenario-like TOML files (scenarios, bench files, fault plans), and the
//! field checks of a scenario's geometry that the shared toolkit (`ugv_fields`) does
//! not know.

use ugv_fields::{FieldError, FieldPath, coordinate, positive_up_to, within};

use super::schema::Motion;

/// Why a scenario, a bench file or a fault plan was refused.
pub type ScenarioError = ugv_fields::FileError;

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
