//! The golf car's navigation firmware (the seed paper's navigation system).

pub mod anfis;
pub mod planner;
