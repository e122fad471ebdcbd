//! The golf car's simulator: a rapier2d world, the kinematic bicycle model of the seed
//! paper, scenarios in TOML, and the simulated devices — the steering and
//! throttle/brake ECUs as CAN nodes that speak golf_car.dbc exactly as the physical
//! ones would — stepped on a fixed timestep, in real time (HIL) or lockstep (SIL).

pub mod clock;
pub mod ecu;
pub mod run;
pub mod scenario;
pub mod vehicle;
pub mod world;

pub use run::{Outcome, RunReport, Sim};
pub use scenario::{Scenario, ScenarioError};
