//! The golf car's simulator: a rapier2d world, the kinematic bicycle model of the seed
//! paper, scenarios in TOML, and the simulated devices — the steering and
//! throttle/brake ECUs as CAN nodes that speak golf_car.dbc exactly as the physical
//! ones would — stepped on a fixed timestep, in real time (HIL) or lockstep (SIL).

pub mod epoch;
pub mod hil;
pub mod isolate;
/// Ticks on absolute deadlines and lockstep (shared with the controller).
pub use firmware_bridge::clock;
pub mod busload;
pub mod devices;
pub mod ecu;
pub mod exit;
pub mod faults;
pub mod measure;
pub mod mission;
pub mod mode;
pub mod plot;
pub mod record;
pub mod run;
pub mod scenario;
pub mod sil;
pub mod suite;
pub mod sweep;
pub mod vehicle;
pub mod verdict;
pub mod way_through;
pub mod world;

pub use mode::Mode;
pub use run::{Outcome, RunReport, Sim, SimError};
pub use scenario::{Scenario, ScenarioError};
