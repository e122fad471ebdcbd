//! The golf car's navigation firmware (the seed paper's navigation system).

pub mod planner;
