//! The built-in vehicle simulator: dynamics, controller, actuator faults, noise (pure; no I/O).

pub mod fault;
pub mod lqr;
pub mod noise;
pub mod paper;
pub mod rng;
pub mod vehicle;
