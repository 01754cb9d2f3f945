//! Where frames come from and go to: tlog files and live MAVLink connections.

/// Generated MAVLink dialects (build.rs, mavlink-bindgen): `dialects::ahcmon` is ArduPilot's
/// dialect (with common) plus our `AHC_ESTIMATE`.
#[allow(clippy::all, clippy::pedantic, missing_docs, unused)]
pub mod dialects {
    include!(concat!(env!("OUT_DIR"), "/mod.rs"));
}

pub mod frame;
pub mod live;
pub mod simulate;
pub mod tlog;

pub use dialects::ahcmon::MavMessage;
pub use frame::{Frame, FrameCounters};
pub use tlog::{TlogReader, TlogWriter};
pub mod conn;
pub use conn::{ConnError, ConnSpec, Link};
