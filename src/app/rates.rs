//! `--request-rates`: the only thing the monitor ever sends on the vehicle link. One
//! SET_MESSAGE_INTERVAL per needed message to each vehicle's autopilot after its first
//! heartbeat; then its COMMAND_ACKs and the rates achieved are reported.

use ahcmon::monitor::Monitor;
use ahcmon::output::Sink;
use ahcmon::protocol::Frame;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// The messages the estimators need, by id: ATTITUDE, SERVO_OUTPUT_RAW and the a_z source the
/// assembler reads from this autopilot: RAW_IMU is in mG only on ArduPilot, so others (PX4)
/// are asked for HIGHRES_IMU.
fn needed(autopilot: ahcmon::protocol::dialects::ahcmon::MavAutopilot) -> [(u32, &'static str); 3] {
    use ahcmon::protocol::dialects::ahcmon::MavAutopilot;
    let imu = if autopilot == MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA {
        (27, "RAW_IMU")
    } else {
        (105, "HIGHRES_IMU")
    };
    [
        (30, "ATTITUDE"),
        (SERVO_OUTPUT_RAW_ID, "SERVO_OUTPUT_RAW"),
        imu,
    ]
}
/// How long the achieved rates are counted after the request.
const RATE_WINDOW: Duration = Duration::from_secs(5);

/// `--request-rates`: one SET_MESSAGE_INTERVAL per needed message to each vehicle's autopilot
/// after its first heartbeat; then its COMMAND_ACKs and the rates achieved are reported.
#[derive(Default)]
pub(super) struct RateRequests {
    asked: BTreeMap<u8, Asked>,
    seq: u8,
}

/// What was asked of one vehicle and what came of it.
struct Asked {
    since: Instant,
    acks: u32,
    /// The results of acknowledgements other than ACCEPTED.
    refused: Vec<String>,
    /// Frames of each needed message since the request.
    counts: [u64; 3],
    reported: bool,
    messages: [(u32, &'static str); 3],
    /// Vehicle time (s) of the first and the latest ATTITUDE since the request, and the frames
    /// of each needed message after that first ATTITUDE: the rates are per vehicle second, so
    /// a simulator sent at `--speed` is not reported at its wall rate.
    vehicle_span: Option<(f64, f64)>,
    vehicle_counts: [u64; 3],
    /// ACTUATOR_OUTPUT_STATUS frames (as `counts` and `vehicle_counts`): PX4 may stream its
    /// outputs so, and the assembler takes either; the faster of the two is the outputs' rate.
    status_counts: [u64; 2],
}

const SERVO_OUTPUT_RAW_ID: u32 = 36;
const ACTUATOR_OUTPUT_STATUS_ID: u32 = 375;

impl Asked {
    /// The achieved rates' report, and what to say about missing acknowledgements.
    fn report(&self, hz: f64) -> String {
        let wall = self.since.elapsed().as_secs_f64();
        let (span, clock, counts, status) = match self.vehicle_span {
            Some((a, b)) if b > a => (
                b - a,
                "vehicle",
                &self.vehicle_counts,
                self.status_counts[1],
            ),
            _ => (wall, "wall-clock", &self.counts, self.status_counts[0]),
        };
        // The outputs' rate is the faster of their two messages, under its name.
        let rated: Vec<(&str, u64)> = self
            .messages
            .iter()
            .zip(counts.iter())
            .map(|((id, name), n)| {
                if *id == SERVO_OUTPUT_RAW_ID && status > *n {
                    ("ACTUATOR_OUTPUT_STATUS", status)
                } else {
                    (*name, *n)
                }
            })
            .collect();
        let achieved: Vec<String> = rated
            .iter()
            .map(|(name, n)| format!("{name} {:.1} Hz", *n as f64 / span))
            .collect();
        let mut text = format!(
            "rates achieved (requested {hz} Hz, over {span:.1} s of {clock} time): {}",
            achieved.join(", ")
        );
        // Under 80 % of the rate asked for (ArduPilot caps streams by its SRn_ parameters
        // and by the link's bandwidth).
        let slow: Vec<&str> = rated
            .iter()
            .filter(|(_, n)| (*n as f64 / span) < 0.8 * hz)
            .map(|(name, _)| *name)
            .collect();
        if !slow.is_empty() {
            text.push_str(&format!(
                "; warning: {} under 80 % of the {hz} Hz asked for (the autopilot's stream limits or the link's bandwidth)",
                slow.join(", ")
            ));
        }
        if !self.refused.is_empty() {
            text.push_str(&format!(
                "; warning: {} of {} requests refused ({})",
                self.refused.len(),
                self.messages.len(),
                self.refused.join(", ")
            ));
        }
        let asked = self.messages.len() as u32;
        if self.acks < asked {
            text.push_str(&format!(
                "; warning: {} of {asked} requests got no COMMAND_ACK in {wall:.0} s (the link may be one-way, or the autopilot ignores SET_MESSAGE_INTERVAL)",
                asked - self.acks
            ));
        }
        text
    }
}

impl RateRequests {
    pub(super) fn on_frame(
        &mut self,
        frame: &Frame,
        monitor: &Monitor,
        hz: f64,
        sink: &mut dyn Sink,
    ) -> Vec<Vec<u8>> {
        use ahcmon::protocol::dialects::ahcmon::{
            COMMAND_LONG_DATA, MavAutopilot, MavCmd, MavMessage, MavResult, MavType,
        };
        let mut out = vec![];
        let sysid = frame.sysid;
        if let Some(a) = self.asked.get_mut(&sysid) {
            match &frame.msg {
                MavMessage::COMMAND_ACK(ack)
                    if ack.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
                {
                    a.acks += 1;
                    if ack.result != MavResult::MAV_RESULT_ACCEPTED {
                        a.refused
                            .push(format!("{:?}", ack.result).replace("MAV_RESULT_", ""));
                    }
                    sink.message(
                        sysid,
                        &format!(
                            "COMMAND_ACK SET_MESSAGE_INTERVAL {}/3: {:?}",
                            a.acks, ack.result
                        ),
                    );
                }
                MavMessage::ATTITUDE(att) => {
                    let t = f64::from(att.time_boot_ms) * 1e-3;
                    let first = a.vehicle_span.map_or(t, |(first, _)| first);
                    a.vehicle_span = Some((first, t));
                }
                _ => {}
            }
            let slot = a.messages.iter().position(|(id, _)| *id == frame.msg_id);
            let status = frame.msg_id == ACTUATOR_OUTPUT_STATUS_ID;
            if slot.is_some() || status {
                // The first ATTITUDE opens the span; what comes after it falls within.
                let opened = a.vehicle_span.is_some_and(|(first, last)| {
                    !matches!(frame.msg, MavMessage::ATTITUDE(_)) || last > first
                });
                let (wall, vehicle) = match slot {
                    Some(k) => (&mut a.counts[k], &mut a.vehicle_counts[k]),
                    None => {
                        let [wall, vehicle] = &mut a.status_counts;
                        (wall, vehicle)
                    }
                };
                *wall += 1;
                *vehicle += u64::from(opened);
            }
            if !a.reported && a.since.elapsed() >= RATE_WINDOW {
                a.reported = true;
                sink.message(sysid, &a.report(hz));
            }
            return out;
        }
        let MavMessage::HEARTBEAT(hb) = &frame.msg else {
            return out;
        };
        if hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID
            || matches!(
                hb.mavtype,
                MavType::MAV_TYPE_GCS | MavType::MAV_TYPE_ONBOARD_CONTROLLER
            )
            || !monitor.assembler.vehicles.contains_key(&sysid)
        {
            return out;
        }
        // The autopilot as the assembler knows it (not a gimbal's or companion's heartbeat).
        let Some(info) = monitor.assembler.vehicles.get(&sysid).map(|v| &v.info) else {
            return out;
        };
        let (Some(autopilot), Some(compid)) = (info.autopilot, info.compid) else {
            return out;
        };
        if compid != frame.compid {
            return out;
        }
        let asked = needed(autopilot);
        for (id, _) in asked {
            let msg = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: id as f32,
                param2: (1e6 / hz) as f32,
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                target_system: sysid,
                target_component: frame.compid,
                ..Default::default()
            });
            let mut bytes = Vec::with_capacity(64);
            // As a component of the vehicle's own system (never as a GCS, sysid 255).
            ahcmon::protocol::frame::encode_v2(
                sysid,
                ahcmon::output::alerts::ALERT_COMPID,
                self.seq,
                &msg,
                &mut bytes,
            );
            self.seq = self.seq.wrapping_add(1);
            out.push(bytes);
        }
        let names: Vec<&str> = asked.iter().map(|(_, n)| *n).collect();
        sink.message(
            sysid,
            &format!(
                "requested {} at {hz} Hz (SET_MESSAGE_INTERVAL)",
                names.join(", ")
            ),
        );
        self.asked.insert(
            sysid,
            Asked {
                since: Instant::now(),
                acks: 0,
                refused: vec![],
                counts: [0; 3],
                reported: false,
                messages: asked,
                vehicle_span: None,
                vehicle_counts: [0; 3],
                status_counts: [0; 2],
            },
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ahcmon::output::jsonl::Outputs;
    use ahcmon::pipeline::PipelineConfig;
    use ahcmon::protocol::dialects::ahcmon::{
        ATTITUDE_DATA, HEARTBEAT_DATA, MavAutopilot, MavMessage, MavType,
    };

    use super::super::test_frame as frame;

    /// The rates report after 5 s of a PX4 at 50 Hz that sends, at step k (20 ms apart),
    /// ATTITUDE, HIGHRES_IMU and what `outputs(k, ms)` gives.
    fn px4_rates_report(outputs: impl Fn(u32, u32) -> Vec<MavMessage>) -> String {
        use ahcmon::protocol::dialects::ahcmon::HIGHRES_IMU_DATA;
        let mut m = Monitor::new(PipelineConfig::default());
        let mut sink = Outputs::new(None, None, 1).unwrap();
        sink.echo = false;
        let mut rates = RateRequests::default();
        let heartbeat = frame(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            ..Default::default()
        }));
        m.on_frame(&heartbeat, &mut sink);
        assert_eq!(rates.on_frame(&heartbeat, &m, 50.0, &mut sink).len(), 3);
        for k in 0..250u32 {
            let ms = 1000 + 20 * k;
            let mut msgs = vec![
                MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: ms,
                    ..Default::default()
                }),
                MavMessage::HIGHRES_IMU(HIGHRES_IMU_DATA {
                    time_usec: u64::from(ms) * 1000,
                    ..Default::default()
                }),
            ];
            msgs.extend(outputs(k, ms));
            for msg in msgs {
                let f = frame(msg);
                m.on_frame(&f, &mut sink);
                rates.on_frame(&f, &m, 50.0, &mut sink);
            }
        }
        rates.asked[&3].report(50.0)
    }

    /// A PX4 that streams its outputs as ACTUATOR_OUTPUT_STATUS has them counted as the
    /// outputs, under that name (it was told its SERVO_OUTPUT_RAW was starved at 0.0 Hz); with
    /// both, the faster one is the outputs' rate, not their sum.
    #[test]
    fn outputs_as_actuator_output_status_count_for_the_rate_asked() {
        use ahcmon::protocol::dialects::ahcmon::{
            ACTUATOR_OUTPUT_STATUS_DATA, SERVO_OUTPUT_RAW_DATA,
        };
        let status = |ms: u32| {
            MavMessage::ACTUATOR_OUTPUT_STATUS(ACTUATOR_OUTPUT_STATUS_DATA {
                time_usec: u64::from(ms) * 1000,
                active: 4,
                ..Default::default()
            })
        };
        let report = px4_rates_report(|_, ms| vec![status(ms)]);
        assert!(
            report.contains("ACTUATOR_OUTPUT_STATUS 50.") && !report.contains("under 80 %"),
            "{report}"
        );
        // SERVO_OUTPUT_RAW at 10 Hz and ACTUATOR_OUTPUT_STATUS at 25 Hz: 25 Hz is too slow.
        let report = px4_rates_report(|k, ms| {
            let mut v = vec![];
            if k % 5 == 0 {
                v.push(MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
                    time_usec: ms * 1000,
                    ..Default::default()
                }));
            }
            if k % 2 == 0 {
                v.push(status(ms));
            }
            v
        });
        assert!(
            report.contains("ACTUATOR_OUTPUT_STATUS 25.")
                && report.contains("warning: ACTUATOR_OUTPUT_STATUS under 80 %"),
            "{report}"
        );
    }
}
