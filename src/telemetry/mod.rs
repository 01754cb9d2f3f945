//! Frames → samples per vehicle, and the vehicle profiles that say how to read them.

pub mod assembler;
pub mod detect;
pub mod encode;
pub mod identity;
pub mod profile;
pub mod record;

pub use assembler::{
    Assembler, AssemblerConfig, TelemetryCounters, TelemetrySample, VehicleAssembler, VehicleInfo,
};
pub use profile::{Profile, ProfileError, Role, VehicleKind};
pub use record::Record;
