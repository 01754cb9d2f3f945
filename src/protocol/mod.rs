//! MAVLink as data: the generated dialect and our framing (decode with drop counters,
//! encode). No I/O: `link/` moves the bytes, `telemetry/` and `output/` read and write
//! messages through this module.

/// Generated MAVLink dialects (build.rs, mavlink-bindgen): `dialects::ahcmon` is ArduPilot's
/// dialect (with common) plus our `AHC_ESTIMATE`.
#[allow(clippy::all, clippy::pedantic, missing_docs, unused)]
pub mod dialects {
    include!(concat!(env!("OUT_DIR"), "/mod.rs"));
}

pub mod frame;
pub mod merge;
pub mod signing;

pub use dialects::ahcmon::MavMessage;
pub use frame::{Frame, FrameCounters};
