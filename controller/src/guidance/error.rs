//! Why guidance fails: it cannot be set up (the follower's ANFIS model), or the planner
//! refuses a replanning's problem. A problem with no feasible path is no error: its
//! outcome has no path, and the car stops.

use crate::anfis::AnfisError;
use crate::planner::PlanError;

/// Why guidance could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum GuidanceError {
    #[error("loading the ANFIS model {path}: {source}")]
    Anfis {
        path: String,
        #[source]
        source: AnfisError,
    },
}

/// Why a replanning has no outcome: the planner refused a problem of it. Each variant
/// reads as the planner's own message (the car's stop reason is `planner: ` and this),
/// and keeps that error as its source.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReplanError {
    /// The planner refused the planning problem (towards the local goal or a detour,
    /// at some pace).
    #[error("{0}")]
    Planner(#[source] PlanError),
    /// The reference line a path's cost is measured from could not be set up.
    #[error("{0}")]
    ReferenceLine(#[source] PlanError),
}
