//! ArduPilot DataFlash logs (`.bin`): the records ahcmon uses, as [`Record`]s.
//!
//! The format is self-describing: every message is `0xA3 0x95 type payload`, and FMT messages
//! (type 128, 89 bytes) give each type's length, name, field types and labels. Our own reader,
//! not the `ardupilot-binlog` crate: that one ends the log silently after 256 consecutive
//! errors, counts nothing it skips, and a corrupt FMT declaring a length under 3 underflows
//! its payload size. Here a bad byte makes the reader slide to the next magic (counted, with
//! the bytes skipped), a FMT that cannot be right is refused (counted), and the tail of a
//! truncated log is counted as truncated.
//!
//! Mapping (ArduPilot 3.6 and later): RATE's R, P, Y (deg/s) are the body rates, the rate
//! controller's own (what MAVLink's ATTITUDE carries); ATT's Roll, Pitch, Yaw (deg) the
//! attitude; RCOU's C1..C16 the outputs (µs); IMU instance 0's AccZ the vertical specific
//! force; POS's RelHomeAlt the height above home; PARM the parameters; MSG the firmware
//! ("ArduCopter", "ArduPlane", ...) and, with FRAME_CLASS, the vehicle type; ARM and EV
//! (10 armed, 11 disarmed) the arming state. A log is written only while armed unless
//! LOG_DISARMED is 1, so it starts armed unless that parameter says otherwise.

use super::logfile::{LogError, LogReport};
use crate::protocol::dialects::ahcmon::{MavAutopilot, MavType};
use crate::telemetry::Record;
use std::collections::HashMap;
use std::io::Read;

const MAGIC: [u8; 2] = [0xA3, 0x95];
const FMT_TYPE: u8 = 0x80;
const FMT_LEN: usize = 89;
const RCOU_CHANNELS: [&str; 16] = [
    "C1", "C2", "C3", "C4", "C5", "C6", "C7", "C8", "C9", "C10", "C11", "C12", "C13", "C14", "C15",
    "C16",
];

/// One message type, from its FMT.
#[derive(Debug, Clone)]
struct Format {
    name: String,
    len: usize,
    /// Per field: its type character and byte offset in the message (header included).
    fields: Vec<(u8, usize)>,
    labels: Vec<String>,
}

fn field_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' => 2,
        b'i' | b'I' | b'e' | b'E' | b'f' | b'L' | b'n' => 4,
        b'q' | b'Q' | b'd' => 8,
        b'N' => 16,
        b'Z' => 64,
        b'a' => 64,
        _ => return None,
    })
}

fn text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end])
        .trim_end()
        .to_string()
}

impl Format {
    /// From a FMT message's payload (after the 3-byte header); `None` when it cannot be right
    /// (unknown field type, fields longer than the declared length, more labels than fields).
    fn parse(payload: &[u8]) -> Option<(u8, Format)> {
        let kind = payload[0];
        let len = usize::from(payload[1]);
        let name = text(&payload[2..6]);
        let types: Vec<u8> = payload[6..22]
            .iter()
            .copied()
            .take_while(|&b| b != 0)
            .collect();
        let labels: Vec<String> = text(&payload[22..86])
            .split(',')
            .map(str::to_string)
            .collect();
        let mut offset = 3;
        let mut fields = Vec::with_capacity(types.len());
        for &c in &types {
            fields.push((c, offset));
            offset += field_size(c)?;
        }
        if offset != len || len < 3 || (kind != FMT_TYPE && labels.len() != types.len()) {
            return None;
        }
        Some((
            kind,
            Format {
                name,
                len,
                fields,
                labels,
            },
        ))
    }

    fn field(&self, label: &str) -> Option<usize> {
        self.labels.iter().position(|l| l == label)
    }

    /// A numeric field's value, scaled as pymavlink's DFReader scales it (c, C, e, E are
    /// hundredths; L is 1e-7 degrees).
    fn value(&self, msg: &[u8], i: usize) -> Option<f64> {
        let &(c, at) = self.fields.get(i)?;
        let b = |n: usize| msg.get(at..at + n);
        let le2 = |s: &[u8]| [s[0], s[1]];
        let le4 = |s: &[u8]| [s[0], s[1], s[2], s[3]];
        let le8 = |s: &[u8]| [s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]];
        Some(match c {
            b'b' => f64::from(b(1)?[0] as i8),
            b'B' | b'M' => f64::from(b(1)?[0]),
            b'h' => f64::from(i16::from_le_bytes(le2(b(2)?))),
            b'H' => f64::from(u16::from_le_bytes(le2(b(2)?))),
            b'c' => f64::from(i16::from_le_bytes(le2(b(2)?))) * 0.01,
            b'C' => f64::from(u16::from_le_bytes(le2(b(2)?))) * 0.01,
            b'i' => f64::from(i32::from_le_bytes(le4(b(4)?))),
            b'I' => f64::from(u32::from_le_bytes(le4(b(4)?))),
            b'e' => f64::from(i32::from_le_bytes(le4(b(4)?))) * 0.01,
            b'E' => f64::from(u32::from_le_bytes(le4(b(4)?))) * 0.01,
            b'L' => f64::from(i32::from_le_bytes(le4(b(4)?))) * 1e-7,
            b'f' => f64::from(f32::from_le_bytes(le4(b(4)?))),
            b'd' => f64::from_le_bytes(le8(b(8)?)),
            b'q' => i64::from_le_bytes(le8(b(8)?)) as f64,
            b'Q' => u64::from_le_bytes(le8(b(8)?)) as f64,
            _ => return None,
        })
    }

    fn string(&self, msg: &[u8], i: usize) -> Option<String> {
        let &(c, at) = self.fields.get(i)?;
        if !matches!(c, b'n' | b'N' | b'Z') {
            return None;
        }
        Some(text(msg.get(at..at + field_size(c)?)?))
    }

    fn get(&self, msg: &[u8], label: &str) -> Option<f64> {
        self.value(msg, self.field(label)?)
    }
}

/// The firmware a MSG or VER names, from which the vehicle type follows.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Firmware {
    Copter,
    Plane,
    Sub,
    Rover,
}

/// ArduCopter's HEARTBEAT type for a FRAME_CLASS (AP_Motors' classes).
fn copter_type(frame_class: Option<f32>) -> MavType {
    match frame_class.map(|v| v as i64) {
        Some(2) | Some(5) => MavType::MAV_TYPE_HEXAROTOR,
        Some(3) | Some(4) => MavType::MAV_TYPE_OCTOROTOR,
        Some(6) => MavType::MAV_TYPE_HELICOPTER,
        Some(7) => MavType::MAV_TYPE_TRICOPTER,
        Some(12) => MavType::MAV_TYPE_DODECAROTOR,
        Some(11) => MavType::MAV_TYPE_HELICOPTER, // heli dual
        _ => MavType::MAV_TYPE_QUADROTOR,
    }
}

/// Decoding state: formats, what the vehicle said, counters.
struct Decoder {
    formats: HashMap<u8, Format>,
    params: HashMap<String, f32>,
    firmware: Option<Firmware>,
    vehicle_sent: bool,
    report: LogReport,
}

impl Decoder {
    fn message(&mut self, kind: u8, msg: &[u8], emit: &mut dyn FnMut(&Record)) {
        let Some(f) = self.formats.get(&kind) else {
            return;
        };
        let t = f.get(msg, "TimeUS").map(|us| us * 1e-6);
        match f.name.as_str() {
            "PARM" => {
                if let (Some(name), Some(value)) = (
                    f.field("Name").and_then(|i| f.string(msg, i)),
                    f.get(msg, "Value"),
                ) {
                    self.params.insert(name.clone(), value as f32);
                    emit(&Record::Param {
                        name,
                        value: value as f32,
                    });
                }
            }
            "MSG" => {
                if let Some(text) = f.field("Message").and_then(|i| f.string(msg, i)) {
                    let firmware = [
                        ("ArduCopter", Firmware::Copter),
                        ("ArduPlane", Firmware::Plane),
                        ("ArduSub", Firmware::Sub),
                        ("ArduRover", Firmware::Rover),
                        ("APMrover2", Firmware::Rover),
                    ]
                    .iter()
                    .find(|(name, _)| text.starts_with(name))
                    .map(|&(_, fw)| fw);
                    self.firmware = self.firmware.or(firmware);
                    emit(&Record::Text(text));
                }
            }
            "ARM" => {
                if let Some(state) = f.get(msg, "ArmState") {
                    emit(&Record::Armed(state != 0.0));
                }
            }
            "EV" => match f.get(msg, "Id").map(|v| v as i64) {
                Some(10) => emit(&Record::Armed(true)),
                Some(11) => emit(&Record::Armed(false)),
                _ => {}
            },
            "POS" => {
                if let Some(h) = f.get(msg, "RelHomeAlt") {
                    emit(&Record::RelAlt(h));
                }
            }
            "ATT" => {
                if let (Some(r), Some(p), Some(y)) =
                    (f.get(msg, "Roll"), f.get(msg, "Pitch"), f.get(msg, "Yaw"))
                {
                    emit(&Record::Attitude {
                        attitude: [r, p, y].map(f64::to_radians),
                    });
                }
            }
            "RATE" => {
                if let (Some(t), Some(r), Some(p), Some(y)) =
                    (t, f.get(msg, "R"), f.get(msg, "P"), f.get(msg, "Y"))
                {
                    self.vehicle(emit);
                    emit(&Record::Rates {
                        t,
                        rates: [r, p, y].map(f64::to_radians),
                    });
                }
            }
            "RCOU" => {
                if let Some(t) = t {
                    let mut pwm = [0u16; 16];
                    for (k, p) in pwm.iter_mut().enumerate() {
                        if let Some(v) = f.get(msg, RCOU_CHANNELS[k]) {
                            *p = v.clamp(0.0, 65535.0) as u16;
                        }
                    }
                    self.vehicle(emit);
                    emit(&Record::Outputs { t, pwm });
                }
            }
            "IMU" => {
                // Instance 0 only: IMUs have their own biases (older logs: IMU, IMU2, .. by name).
                let instance = f.get(msg, "I").unwrap_or(0.0);
                if let (Some(t), Some(az), 0.0) = (t, f.get(msg, "AccZ"), instance) {
                    emit(&Record::Az { t, az });
                }
            }
            _ => {}
        }
    }

    /// The vehicle record, before the first rates or outputs: by then the parameters that
    /// say the frame are in (ArduPilot writes them at the start of every log).
    fn vehicle(&mut self, emit: &mut dyn FnMut(&Record)) {
        if self.vehicle_sent {
            return;
        }
        self.vehicle_sent = true;
        let has = |k: &str| self.params.contains_key(k);
        let firmware = self.firmware.or(if has("FRAME_CLASS") {
            Some(Firmware::Copter)
        } else if has("RLL2SRV_P") || has("RLL_RATE_P") || has("TRIM_ARSPD_CM") {
            Some(Firmware::Plane)
        } else {
            None
        });
        let mav_type = match firmware {
            Some(Firmware::Copter) => copter_type(self.params.get("FRAME_CLASS").copied()),
            Some(Firmware::Plane) => MavType::MAV_TYPE_FIXED_WING,
            Some(Firmware::Sub) => MavType::MAV_TYPE_SUBMARINE,
            Some(Firmware::Rover) => MavType::MAV_TYPE_GROUND_ROVER,
            None => {
                self.report
                    .notes
                    .push("the log does not name its firmware (no MSG) nor a frame parameter; pass --profile".into());
                return;
            }
        };
        emit(&Record::Vehicle {
            mav_type,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        });
        let logs_disarmed = self.params.get("LOG_DISARMED").is_some_and(|&v| v == 1.0);
        emit(&Record::Armed(!logs_disarmed));
    }
}

/// Read a DataFlash log from `input`, calling `emit` for each record and `progress` with the
/// bytes read so far.
pub fn read(
    mut input: impl Read,
    emit: &mut dyn FnMut(&Record),
    progress: &mut dyn FnMut(u64),
) -> Result<LogReport, LogError> {
    let mut d = Decoder {
        formats: HashMap::new(),
        params: HashMap::new(),
        firmware: None,
        vehicle_sent: false,
        report: LogReport::default(),
    };
    let mut buf: Vec<u8> = Vec::with_capacity(1 << 17);
    let mut chunk = vec![0u8; 1 << 16];
    let mut read_total = 0u64;
    let mut at = 0usize;
    let mut sliding = false;
    loop {
        let n = input.read(&mut chunk).map_err(LogError::Io)?;
        read_total += n as u64;
        buf.extend_from_slice(&chunk[..n]);
        let end = n == 0;
        // Decode every whole message in the buffer.
        loop {
            let rest = &buf[at..];
            if rest.len() < 3 {
                break;
            }
            if rest[..2] != MAGIC {
                if !sliding {
                    d.report.counters.resync += 1;
                    sliding = true;
                }
                d.report.counters.skipped_bytes += 1;
                at += 1;
                continue;
            }
            let kind = rest[2];
            let len = if kind == FMT_TYPE {
                FMT_LEN
            } else {
                match d.formats.get(&kind) {
                    Some(f) => f.len,
                    None => {
                        // A type no FMT declared: a false magic inside damaged data.
                        if !sliding {
                            d.report.counters.resync += 1;
                            sliding = true;
                        }
                        d.report.counters.unknown_id += 1;
                        d.report.counters.skipped_bytes += 1;
                        at += 1;
                        continue;
                    }
                }
            };
            if rest.len() < len {
                break;
            }
            let msg = &rest[..len];
            if kind == FMT_TYPE {
                match Format::parse(&msg[3..]) {
                    Some((k, f)) => {
                        d.formats.insert(k, f);
                    }
                    None => d.report.counters.parse_error += 1,
                }
            } else {
                d.message(kind, msg, emit);
            }
            d.report.counters.frames += 1;
            sliding = false;
            at += len;
        }
        if end {
            let left = buf.len() - at;
            if left > 0 {
                d.report.counters.truncated += 1;
                d.report.counters.skipped_bytes += left as u64;
            }
            break;
        }
        buf.drain(..at);
        at = 0;
        progress(read_total);
    }
    progress(read_total);
    d.report.bytes = read_total;
    if d.report.counters.frames == 0 {
        return Err(LogError::Empty);
    }
    Ok(d.report)
}
