//! Fault injection (`[[faults]]` in scenarios, `ugv-sim run --faults FILE`): the plan
//! and its validation ([`plan`]), and the injector that applies it at the simulator's
//! side of every wire, the same in SIL and HIL ([`inject`]).

pub mod inject;
pub mod plan;

pub use inject::{ActuatorFaults, FaultRecord, Injector, ProcessFault, RxFault, TxFault};
pub use plan::{
    CounterMode, EcuFaultCode, EcuName, Expectations, Fault, FaultKind, FaultSpec, Node, Start,
};
