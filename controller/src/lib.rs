//! The golf car's navigation firmware (the seed paper's navigation system):
//! localisation from RTK GPS, obstacle detection with the laser, the Qu et al. optimal
//! collision-free planner, path following with the optimal law or ANFIS, and the
//! safety stop, over the real wires (NMEA, iceoryx2 laser frames, SocketCAN).

pub mod anfis;
pub mod car;
pub mod config;
pub mod control;
pub mod grid;
pub mod guidance;
pub mod localisation;
pub mod lockstep;
pub mod perception;
pub mod planner;
pub mod ranges;
pub mod record;
pub mod route;
pub mod runtime;
pub mod safety;
pub mod trace;
