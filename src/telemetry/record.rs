//! What a vehicle's own log (ArduPilot DataFlash, PX4 ULog) says, as typed records on the
//! vehicle's clock. The MAVLink path reaches the same assembler state through frames; these
//! records carry the log's finer clock (µs) instead of ATTITUDE's milliseconds.

use crate::protocol::dialects::ahcmon::{MavAutopilot, MavType};

#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// The vehicle's type and autopilot, as its heartbeat would say them.
    Vehicle {
        mav_type: MavType,
        autopilot: MavAutopilot,
    },
    Armed(bool),
    Param {
        name: String,
        value: f32,
    },
    /// Body rates (rad/s) at `t` (s since boot).
    Rates {
        t: f64,
        rates: [f64; 3],
    },
    /// Roll, pitch, yaw (rad); the latest goes with the next samples.
    Attitude {
        attitude: [f64; 3],
    },
    /// Output PWM (µs) of channels 1..16 at `t`; 0 = not sent.
    Outputs {
        t: f64,
        pwm: [u16; 16],
    },
    /// Vertical specific force (m/s², body z) at `t`.
    Az {
        t: f64,
        az: f64,
    },
    /// Height above home (m).
    RelAlt(f64),
    Text(String),
    /// The autopilot board's id, as a log's header states it (a ULog's `sys_uuid`), in the
    /// form of [`crate::telemetry::identity`].
    Board(String),
}
