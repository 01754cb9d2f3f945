//! PX4 ULog files (`.ulg`): the topics ahcmon uses, as [`Record`]s, read by the PX4
//! project's own streaming parser (`px4-ulog`).
//!
//! Mapping: `vehicle_angular_velocity` (instance 0, stamped `timestamp_sample`, the gyro
//! sample's own time) the body rates; `vehicle_attitude`'s quaternion the attitude;
//! `actuator_outputs` instance 0 the outputs (PWM µs, `noutputs` of them); `sensor_combined`'s
//! `accelerometer_m_s2[2]` at its own instant the vertical specific force;
//! `vehicle_local_position`'s `-z` the height above the origin; `vehicle_status`'s
//! `arming_state` (2: armed); the parameters, with `MAV_TYPE` the vehicle type. Logs whose
//! outputs are only in `actuator_motors` / `actuator_servos` (normalised, PX4 1.14 and later
//! with PWM off) carry no PWM: the summary says no output message came.

use super::logfile::{LogError, LogReport};
use crate::protocol::dialects::ahcmon::{MavAutopilot, MavType};
use crate::telemetry::Record;
use num_traits::FromPrimitive;
use px4_ulog::stream_parser::model::{
    Completeness, DataMessage, FlattenedFormat, ParameterMessage,
};
use px4_ulog::stream_parser::{Message, SimpleCallbackResult};

fn f32_field(f: &FlattenedFormat, data: &[u8], name: &str) -> Option<f64> {
    f.get_field_parser::<f32>(name)
        .ok()
        .map(|p| f64::from(p.parse(data)))
}

fn timestamp(f: &FlattenedFormat, data: &[u8], name: &str) -> Option<f64> {
    f.get_field_parser::<u64>(name)
        .ok()
        .map(|p| p.parse(data) as f64 * 1e-6)
}

/// Roll, pitch, yaw (rad) of a unit quaternion `[w, x, y, z]` (PX4's convention, body to NED).
fn euler(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    [roll, pitch, yaw]
}

struct Decoder {
    mav_type: Option<i32>,
    vehicle_sent: bool,
}

impl Decoder {
    fn vehicle(&mut self, emit: &mut dyn FnMut(&Record)) {
        if self.vehicle_sent {
            return;
        }
        self.vehicle_sent = true;
        // PX4's default MAV_TYPE is 2 (quadrotor).
        let mav_type = self
            .mav_type
            .and_then(MavType::from_i32)
            .unwrap_or(MavType::MAV_TYPE_QUADROTOR);
        emit(&Record::Vehicle {
            mav_type,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        });
    }

    fn data(&mut self, m: &DataMessage, emit: &mut dyn FnMut(&Record)) {
        let f = m.flattened_format;
        let d = m.data;
        if m.multi_id.value() != 0 {
            return;
        }
        match f.message_name() {
            "vehicle_angular_velocity" => {
                let t =
                    timestamp(f, d, "timestamp_sample").or_else(|| timestamp(f, d, "timestamp"));
                let xyz = ["xyz[0]", "xyz[1]", "xyz[2]"].map(|k| f32_field(f, d, k));
                if let (Some(t), [Some(p), Some(q), Some(r)]) = (t, xyz) {
                    self.vehicle(emit);
                    emit(&Record::Rates {
                        t,
                        rates: [p, q, r],
                    });
                }
            }
            "vehicle_attitude" => {
                let q = ["q[0]", "q[1]", "q[2]", "q[3]"].map(|k| f32_field(f, d, k));
                if let [Some(w), Some(x), Some(y), Some(z)] = q {
                    emit(&Record::Attitude {
                        attitude: euler([w, x, y, z]),
                    });
                }
            }
            "actuator_outputs" => {
                let Some(t) = timestamp(f, d, "timestamp") else {
                    return;
                };
                let n = f
                    .get_field_parser::<u32>("noutputs")
                    .ok()
                    .map_or(16, |p| p.parse(d) as usize)
                    .min(16);
                let mut pwm = [0u16; 16];
                for (k, p) in pwm.iter_mut().enumerate().take(n) {
                    if let Some(v) = f32_field(f, d, OUTPUT_FIELDS[k])
                        && v.is_finite()
                        && (1.0..65535.0).contains(&v)
                    {
                        *p = v.round() as u16;
                    }
                }
                self.vehicle(emit);
                emit(&Record::Outputs { t, pwm });
            }
            "sensor_combined" => {
                let (Some(t), Some(az)) = (
                    timestamp(f, d, "timestamp"),
                    f32_field(f, d, "accelerometer_m_s2[2]"),
                ) else {
                    return;
                };
                // The accelerometer's own instant, relative to the gyro's (`timestamp`).
                let rel = f
                    .get_field_parser::<i32>("accelerometer_timestamp_relative")
                    .ok()
                    .map(|p| p.parse(d))
                    // INT32_MAX marks "no accelerometer sample".
                    .filter(|&r| r != i32::MAX);
                if let Some(rel) = rel {
                    emit(&Record::Az {
                        t: t + f64::from(rel) * 1e-6,
                        az,
                    });
                }
            }
            "vehicle_local_position" => {
                if let Some(z) = f32_field(f, d, "z") {
                    emit(&Record::RelAlt(-z));
                }
            }
            "vehicle_status" => {
                if let Ok(p) = f.get_field_parser::<u8>("arming_state") {
                    emit(&Record::Armed(p.parse(d) == 2));
                }
            }
            _ => {}
        }
    }
}

const OUTPUT_FIELDS: [&str; 16] = [
    "output[0]",
    "output[1]",
    "output[2]",
    "output[3]",
    "output[4]",
    "output[5]",
    "output[6]",
    "output[7]",
    "output[8]",
    "output[9]",
    "output[10]",
    "output[11]",
    "output[12]",
    "output[13]",
    "output[14]",
    "output[15]",
];

thread_local! {
    /// Set while px4-ulog's own code runs on this thread (not our callback inside it).
    static IN_PX4_ULOG: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// What px4-ulog's last panic on this thread said.
    static PX4_ULOG_PANIC: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// A panic inside px4-ulog is kept for the log's note instead of printed as a crash; every
/// other panic goes to the hook there was. (With `panic = "abort"` nothing can be caught: the
/// profiles here unwind.)
fn quiet_px4_ulog_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_PX4_ULOG.with(std::cell::Cell::get) {
                let at = info
                    .location()
                    .map_or(String::new(), |l| format!(" at {}:{}", l.file(), l.line()));
                let what = info
                    .payload()
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| info.payload().downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                PX4_ULOG_PANIC.with(|p| *p.borrow_mut() = Some(format!("{what}{at}")));
            } else {
                previous(info);
            }
        }));
    });
}

/// Read a ULog file, calling `emit` for each record.
pub fn read(path: &std::path::Path, emit: &mut dyn FnMut(&Record)) -> Result<LogReport, LogError> {
    let path_str = path
        .to_str()
        .ok_or_else(|| LogError::Malformed("the path is not valid UTF-8".into()))?;
    let bytes = std::fs::metadata(path)?.len();
    let mut report = LogReport {
        bytes,
        ..Default::default()
    };
    let mut d = Decoder {
        mav_type: None,
        vehicle_sent: false,
    };
    let mut messages = 0u64;
    // px4-ulog indexes into messages without checking their length (an empty 'A' message
    // panics, found by fuzzing): its panic is caught and the log called damaged.
    quiet_px4_ulog_panics();
    // A panic in our own code inside the callback is not the log's: kept, and raised again
    // once px4-ulog has returned.
    let mut ours: Option<Box<dyn std::any::Any + Send>> = None;
    IN_PX4_ULOG.with(|f| f.set(true));
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        px4_ulog::stream_parser::read_file_with_simple_callback(path_str, &mut |m| {
            IN_PX4_ULOG.with(|f| f.set(false));
            let step = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                messages += 1;
                match m {
                    Message::Data(data) => d.data(data, emit),
                    Message::ParameterMessage(p) => {
                        let (name, value) = match p {
                            ParameterMessage::Float(n, v, _) => (*n, *v),
                            ParameterMessage::Int32(n, v, _) => {
                                if *n == "MAV_TYPE" {
                                    d.mav_type = Some(*v);
                                }
                                (*n, *v as f32)
                            }
                        };
                        emit(&Record::Param {
                            name: name.to_string(),
                            value,
                        });
                    }
                    Message::LoggedMessage(s) => emit(&Record::Text(s.logged_message.to_string())),
                    Message::TaggedLoggedMessage(s) => {
                        emit(&Record::Text(s.logged_message.to_string()));
                    }
                    Message::DropoutMessage(drop) => report.note_dropout(drop.duration_ms),
                    Message::InfoMessage(info) if info.key == "sys_uuid" => {
                        let text = std::str::from_utf8(info.value).unwrap_or_default();
                        if let Some(id) = crate::telemetry::identity::from_px4_uuid(text) {
                            emit(&Record::Board(id));
                        }
                    }
                    _ => {}
                }
            }));
            IN_PX4_ULOG.with(|f| f.set(true));
            match step {
                Ok(()) => SimpleCallbackResult::KeepReading,
                Err(payload) => {
                    ours = Some(payload);
                    SimpleCallbackResult::Stop
                }
            }
        })
    }));
    IN_PX4_ULOG.with(|f| f.set(false));
    if let Some(payload) = ours {
        std::panic::resume_unwind(payload);
    }
    let completeness = match parsed {
        Ok(r) => r,
        Err(_) => Ok(Completeness::MalformedRecord(format!(
            "the ULog reader failed on it: {}",
            PX4_ULOG_PANIC
                .with(|p| p.borrow_mut().take())
                .unwrap_or_default()
        ))),
    }
    .map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound | std::io::ErrorKind::PermissionDenied => LogError::Io(e),
        _ => LogError::Malformed(e.to_string()),
    })?;
    report.counters.frames = messages;
    match completeness {
        Completeness::Complete => {}
        Completeness::Truncated => {
            report.counters.truncated += 1;
            report
                .notes
                .push("the log ends inside a message (cut off): read up to there".into());
        }
        Completeness::MalformedRecord(why) => {
            report.counters.parse_error += 1;
            report.notes.push(format!(
                "a damaged message ({why}): the log was read up to it, the rest could not be"
            ));
        }
    }
    if messages == 0 {
        return Err(LogError::Empty);
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_level_quaternion_is_level_and_yaw_follows_z() {
        let e = euler([1.0, 0.0, 0.0, 0.0]);
        assert!(e.iter().all(|x| x.abs() < 1e-12));
        let h = std::f64::consts::FRAC_PI_4; // 90° yaw
        let e = euler([h.cos(), 0.0, 0.0, h.sin()]);
        assert!((e[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-12, "{e:?}");
    }
}
