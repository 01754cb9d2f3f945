//! ahcmon: actuator health monitoring for MAVLink vehicles.
//!
//! Data flow: source → telemetry → estimators (MIT-UKF ‖ MIT-ESMF) → diagnosis → sinks.
//! This crate holds the pure parts (model, estimate, sim, diagnose) and the evaluation harness.

pub mod airframes;
pub mod diagnose;
pub mod estimate;
pub mod eval;
#[doc(hidden)]
pub mod fuzzing;
pub mod history;
pub mod link;
pub mod model;
pub mod monitor;
pub mod output;
pub mod pipeline;
pub mod protocol;
pub mod scenario;
pub mod sim;
pub mod telemetry;
pub mod toml_file;
