//! The end-of-run summary as one JSON document (`--summary FILE`): what the text summary says,
//! for a script. NaN and infinite numbers (a filter that failed) are `null`.

use super::summary::actuator_state;
use crate::diagnose::vehicle::{Decision, Event};
use crate::estimate::vehicle::FILTER_NAMES;
use crate::monitor::Monitor;
use crate::protocol::FrameCounters;
use serde_json::{Value, json};

/// Format version of the document: a key removed or changed in meaning raises it.
pub const SUMMARY_VERSION: u32 = 1;

pub fn summary_json(monitor: &Monitor, frames: &FrameCounters, decisions: &[Decision]) -> Value {
    let vehicles: Vec<Value> = monitor
        .assembler
        .vehicles
        .iter()
        .map(|(sysid, v)| {
            let mut vehicle = json!({
                "sysid": sysid,
                "type": v.info.mav_type.map(|t| format!("{t:?}")
                    .trim_start_matches("MAV_TYPE_")
                    .to_lowercase()),
                "telemetry": v.counters,
            });
            let Some(p) = monitor.pipelines.get(sysid) else {
                vehicle["stage"] = json!("no complete samples");
                return vehicle;
            };
            vehicle["stage"] = json!(p.stage_name());
            vehicle["pipeline"] = json!(p.counters);
            vehicle["no_estimates"] = json!(p.why_not_estimating(v.info.mav_type.is_some()));
            vehicle["profile"] = json!(p.detection.as_ref().map(|d| d.source.clone()));
            let (Some(profile), Some((t, est))) = (p.profile(), &p.last) else {
                return vehicle;
            };
            vehicle["t"] = json!(t);
            vehicle["before_reboot"] = json!(p.before_reboot.is_some_and(|b| !b.estimated_since));
            let actuators: Vec<Value> = profile
                .actuators
                .iter()
                .enumerate()
                .map(|(j, a)| {
                    let (faults, state) = actuator_state(p, *sysid, j, &a.name, decisions);
                    let estimates: serde_json::Map<String, Value> = FILTER_NAMES
                        .iter()
                        .enumerate()
                        .map(|(f, name)| {
                            let e = est[f][j];
                            let filter = json!({
                                "gamma": e.gamma,
                                "gamma_bounds": [e.gamma_lo, e.gamma_hi],
                                "delta": e.delta,
                                "delta_bounds": [e.delta_lo, e.delta_hi],
                                "unexcited": e.unexcited,
                            });
                            (name.to_string(), filter)
                        })
                        .collect();
                    json!({
                        "name": a.name,
                        "channel": a.channel,
                        "faults": faults,
                        "fault_in_force": p.active[j].map(|c| c.as_str()),
                        "health": p.health[j].as_str(),
                        "state": state,
                        "estimates": estimates,
                    })
                })
                .collect();
            vehicle["actuators"] = json!(actuators);
            vehicle
        })
        .collect();
    json!({
        "version": SUMMARY_VERSION,
        "link": frames,
        "decisions": decisions.len(),
        "fault_decisions": decisions.iter().filter(|d| d.event == Event::Fault).count(),
        "vehicles": vehicles,
    })
}
