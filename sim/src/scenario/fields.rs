//! The error of scenario-like TOML files (scenarios, bench files, fault plans), and the
//! field checks of a scenario's geometry that the shared toolkit (`ugv_fields`) does
//! not know.

use ugv_fields::{FieldError, FieldPath, angle_deg, coordinate};

use super::ranges::{OBSTACLE_PACE, OBSTACLE_SIZE, OBSTACLE_SPEED, WALL_THICKNESS};
use super::schema::{Motion, Obstacle};

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
const MAX_OBSTACLES: usize = 10_000;

/// Most points of a wall or a waypoint path.
const MAX_POINTS: usize = 10_000;

fn check_motion(path: &FieldPath, motion: &Option<Motion>) -> Result<(), FieldError> {
    match motion {
        None => Ok(()),
        Some(Motion::Velocity { vx, vy }) => {
            OBSTACLE_SPEED.check(&path.key("vx"), *vx)?;
            OBSTACLE_SPEED.check(&path.key("vy"), *vy)
        }
        Some(Motion::Waypoints { points, speed, .. }) => {
            check_points(&path.key("points"), points, 2)?;
            OBSTACLE_PACE.check(&path.key("speed"), *speed)
        }
    }
}

/// Every obstacle: its place, its size and speed within their ranges
/// ([`super::ranges`]), a wall's points distinct.
pub(super) fn check_obstacles(at: &FieldPath, obstacles: &[Obstacle]) -> Result<(), FieldError> {
    if obstacles.len() > MAX_OBSTACLES {
        return Err(FieldError::new(
            at.clone(),
            format!(
                "has {} obstacles, at most {MAX_OBSTACLES} are allowed",
                obstacles.len()
            ),
        ));
    }
    for (i, o) in obstacles.iter().enumerate() {
        let p = at.index(i);
        match o {
            Obstacle::Circle {
                x,
                y,
                radius,
                motion,
            } => {
                coordinate(&p.key("x"), *x)?;
                coordinate(&p.key("y"), *y)?;
                OBSTACLE_SIZE.check(&p.key("radius"), *radius)?;
                check_motion(&p.key("motion"), motion)?;
            }
            Obstacle::Box {
                x,
                y,
                length,
                width,
                heading_deg,
                motion,
            } => {
                coordinate(&p.key("x"), *x)?;
                coordinate(&p.key("y"), *y)?;
                OBSTACLE_SIZE.check(&p.key("length"), *length)?;
                OBSTACLE_SIZE.check(&p.key("width"), *width)?;
                angle_deg(&p.key("heading_deg"), *heading_deg)?;
                check_motion(&p.key("motion"), motion)?;
            }
            Obstacle::Wall { points, thickness } => {
                check_points(&p.key("points"), points, 2)?;
                WALL_THICKNESS.check(&p.key("thickness"), *thickness)?;
                if let Some(j) = points.windows(2).position(|w| w[0] == w[1]) {
                    return Err(FieldError::new(
                        p.key("points").index(j + 1),
                        "repeats the previous point",
                    ));
                }
            }
        }
    }
    Ok(())
}
