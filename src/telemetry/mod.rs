//! Frames → samples per vehicle, and the vehicle profiles that say how to read them.

pub mod profile;

pub use profile::{Profile, ProfileError, Role, VehicleKind};
