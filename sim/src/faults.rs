//! Fault injection (`[[faults]]` in scenarios, `ugv-sim run --faults FILE`): the plan
//! and its validation ([`plan`]), and the injector that applies it at the simulator's
//! side of every wire, the same in SIL and HIL ([`inject`]). The plan's format, every
//! kind with its parameters, `[expect]` and what the verdict reports are described in
//! one place, docs/faults.md; the code's documentation says what each piece does.

pub mod inject;
pub mod plan;

pub use inject::{
    ActuatorFaults, FaultRecord, GpsReceiverFaults, Injector, ProcessFault, RxFault, TxFault,
};
pub use plan::{
    CounterMode, EcuFaultCode, EcuName, Expectations, Fault, FaultKind, FaultSpec, Node, Start,
};
