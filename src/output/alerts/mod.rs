//! Alerts into a mission planner: the monitor as a MAVLink component of its own — HEARTBEAT at 1 Hz
//! (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID) sent as the vehicle's system id with
//! component id 191, a STATUSTEXT per decision (severity by class, at most 50 characters,
//! rate-limited), NAMED_VALUE_FLOAT `g_<name>` / `d_<name>` per actuator at 2 Hz, and our
//! AHC_ESTIMATE with the probable (MIT-UKF) and guaranteed (set filter) bounds of gamma, delta
//! and the output at the recent command. Pure: encoded frames go to `outbox`; the caller
//! sends them. It never commands the vehicle.

use crate::diagnose::vehicle::{Decision, Event, FaultClass};
use crate::estimate::vehicle::AhcEstimate;
use crate::protocol::dialects::ahcmon::{
    AHC_ESTIMATE_DATA, AhcState, HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag,
    MavSeverity, MavState, MavType, NAMED_VALUE_FLOAT_DATA, STATUSTEXT_DATA,
};
use crate::protocol::frame::encode_v2;
use crate::telemetry::Profile;
use std::collections::{BTreeMap, VecDeque};

/// MAV_COMP_ID_ONBOARD_COMPUTER.
pub const ALERT_COMPID: u8 = 191;
/// At most one STATUSTEXT per vehicle this often (s); more wait in a short queue. When it is
/// full the least severe text goes, but never an actuator's newest (the planner's last word on
/// it must be its state now: a flapping actuator's `cleared` dropped behind its older fault text
/// left the planner showing a fault that had cleared); faults (ERROR, CRITICAL) are dropped only
/// past a hard cap.
const TEXT_INTERVAL_S: f64 = 1.0;
const TEXT_QUEUE: usize = 8;
const TEXT_QUEUE_HARD: usize = 64;
/// STATUSTEXT's text field (bytes).
const TEXT_BYTES: usize = 50;
/// NAMED_VALUE_FLOAT and AHC_ESTIMATE per actuator this often (s).
const VALUE_INTERVAL_S: f64 = 0.5;
/// A loss's size is said again when the MIT-UKF's estimate is this many percentage points
/// from the last text, at most once per `LOSS_RESAY_S` per actuator: the first text comes at
/// the alarm, while the estimate is still on its way (the demo's 40 % swash loss was told as
/// 16 %, then 20 %, and its 31 % never).
const LOSS_RESAY_POINTS: f64 = 10.0;
const LOSS_RESAY_S: f64 = 5.0;

#[derive(Debug, Clone, Copy)]
struct Latest {
    t: f64,
    ukf: AhcEstimate,
    /// The set filter's guaranteed estimate.
    set: AhcEstimate,
    channel: u8,
    /// The actuator's index in its vehicle's profile (AHC_ESTIMATE.actuator).
    index: u8,
}

/// A STATUSTEXT waiting for its turn, and the actuator it is about (if any).
#[derive(Debug, Clone, PartialEq)]
struct QueuedText {
    severity: MavSeverity,
    text: String,
    actuator: Option<String>,
}

#[derive(Debug, Default)]
pub struct Alerts {
    seq: u8,
    /// Encoded frames waiting to be sent.
    pub outbox: Vec<Vec<u8>>,
    /// Vehicles seen (their system ids), for the heartbeat.
    vehicles: Vec<u8>,
    now: f64,
    next_heartbeat: f64,
    text_queue: BTreeMap<u8, VecDeque<QueuedText>>,
    last_text: BTreeMap<u8, f64>,
    latest: BTreeMap<(u8, String), Latest>,
    /// Per vehicle the actuator names of its profile and their NAMED_VALUE_FLOAT names (see
    /// [`value_names`]), in profile order.
    value_names: BTreeMap<u8, (Vec<NamedChannel>, Vec<[String; 2]>)>,
    state: BTreeMap<(u8, String), AhcState>,
    last_values: f64,
    /// The last text queued about each actuator (an actuator's newest is never dropped from
    /// the queue; whether the link delivered it, UDP cannot say).
    last_said: BTreeMap<(u8, String), (u8, String)>,
    /// Per actuator with a loss in force, the decision whose text last said its size: said
    /// again when the MIT-UKF's estimate has moved far from it (see `LOSS_RESAY_POINTS`).
    loss_said: BTreeMap<(u8, String), Decision>,
    /// STATUSTEXT of a loss said again at its new size.
    pub texts_resized: u64,
    /// STATUSTEXT dropped because the queue was full.
    pub texts_dropped: u64,
    /// STATUSTEXT of `changed` decisions not queued because the last text queued about that
    /// actuator reads the same (class, size and filters unchanged: another actuator's alarm
    /// taken over by it, say). A `fault` or `cleared` is always said (after a reboot the same
    /// fault is news again).
    pub texts_repeated: u64,
    /// STATUSTEXT put in the outbox.
    pub texts_sent: u64,
    /// Frames of the outbox the link could not deliver (counted by the sender).
    pub frames_unsent: u64,
}

/// What starts each STATUSTEXT: whose it is. Planners label a STATUSTEXT by their own rules
/// (MAVProxy's console prints every one it shows as `AP: ...`, the autopilot's), so the text
/// itself names its sender.
pub const TEXT_PREFIX: &str = "ahcmon: ";

/// `ahcmon: swash2 LOE 41% UKF+ESMF`: what the planner shows (≤ 50 characters).
pub fn statustext(d: &Decision) -> Option<(MavSeverity, String)> {
    let who = d.actuator.as_deref().unwrap_or("");
    let by = crate::output::filters_short(d);
    // The actuator's name is what gives way when the text is too long, not the class.
    let fit = |what: &str, by: &str| {
        let tail = format!(" {what} {by}");
        let room = TEXT_BYTES.saturating_sub(TEXT_PREFIX.len() + tail.trim_end().len());
        format!("{TEXT_PREFIX}{}{}", cut_bytes(who, room), tail.trim_end())
    };
    let (sev, text) = match d.event {
        Event::Fault | Event::Changed => {
            let (sev, what) = match d.class {
                Some(FaultClass::LossOfEffectiveness) => (
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    format!("LOE {:.0}%", (1.0 - d.gamma.unwrap_or(1.0)) * 100.0),
                ),
                Some(FaultClass::Stuck) => (MavSeverity::MAV_SEVERITY_CRITICAL, "stuck".into()),
                // The output's offset at the operating point: the filter's delta alone can be
                // ~0 with the change in its gain (hexa motor 5 stuck read "bias -0.00"). In %
                // of the output's range (motor) or throw (servo: trim to end), as a planner
                // shows nothing to say what a bare "+0.15" is.
                Some(FaultClass::Bias) => (
                    MavSeverity::MAV_SEVERITY_ERROR,
                    format!(
                        "bias {:+.0}%",
                        d.deviation.or(d.delta).unwrap_or(0.0) * 100.0
                    ),
                ),
                Some(FaultClass::Drift) => (MavSeverity::MAV_SEVERITY_WARNING, "drift".into()),
                Some(FaultClass::Unclassified) | None => {
                    (MavSeverity::MAV_SEVERITY_ERROR, "output off".into())
                }
            };
            (sev, fit(&what, &by))
        }
        Event::Cleared => (MavSeverity::MAV_SEVERITY_NOTICE, fit("cleared", "")),
        // Statements, not faults: the dashboard, summary and decisions carry them.
        Event::ExcitationLow | Event::Suspect | Event::SuspectCleared => return None,
        Event::FilterReset => (
            MavSeverity::MAV_SEVERITY_WARNING,
            format!("{TEXT_PREFIX}filter reset"),
        ),
        Event::CannotEstimate => (
            MavSeverity::MAV_SEVERITY_WARNING,
            format!("{TEXT_PREFIX}cannot estimate"),
        ),
        // Not a fault, but the planner should know the actuator is not monitored.
        Event::CannotJudge => (MavSeverity::MAV_SEVERITY_WARNING, fit("cannot judge", "")),
        Event::LinkLost | Event::LinkRestored => return None,
        // The planner hears both senders itself; its operator should know ours is unsure.
        Event::Contaminated => (
            MavSeverity::MAV_SEVERITY_WARNING,
            format!("{TEXT_PREFIX}two senders of this id: estimates unsure"),
        ),
    };
    Some((sev, cut_bytes(text.trim(), TEXT_BYTES).to_string()))
}

/// The longest prefix of `s` of at most `max` bytes that ends on a character boundary.
fn cut_bytes(s: &str, max: usize) -> &str {
    let mut end = max.min(s.len());
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

/// NAMED_VALUE_FLOAT's name (10 bytes): `g_` / `d_` and as much of the actuator's name as fits.
fn short_name(prefix: &str, name: &str) -> String {
    cut_bytes(&format!("{prefix}_{name}"), 10).to_string()
}

/// An actuator's name and output channel.
type NamedChannel = (String, u8);

/// Each actuator's NAMED_VALUE_FLOAT names, `[gamma, delta]`: [`short_name`]s, or when two of
/// a vehicle's cut names would be the same (`esc_motor_1`, `esc_motor_2`), `g_ch<channel>`
/// for every actuator (the channels differ; a mix could meet an actuator called `ch3`).
fn value_names(profile: &Profile) -> Vec<[String; 2]> {
    let cut: Vec<[String; 2]> = profile
        .actuators
        .iter()
        .map(|a| [short_name("g", &a.name), short_name("d", &a.name)])
        .collect();
    let unique = cut
        .iter()
        .enumerate()
        .all(|(j, c)| cut[..j].iter().all(|other| other[0] != c[0]));
    if unique {
        cut
    } else {
        profile
            .actuators
            .iter()
            .map(|a| [format!("g_ch{}", a.channel), format!("d_ch{}", a.channel)])
            .collect()
    }
}

fn state_of(d: &Decision) -> Option<AhcState> {
    Some(match d.event {
        Event::Cleared => AhcState::AHC_STATE_HEALTHY,
        Event::ExcitationLow => AhcState::AHC_STATE_EXCITATION_LOW,
        Event::Fault | Event::Changed => match d.class? {
            FaultClass::LossOfEffectiveness => AhcState::AHC_STATE_LOSS_OF_EFFECTIVENESS,
            FaultClass::Stuck => AhcState::AHC_STATE_STUCK,
            FaultClass::Bias | FaultClass::Unclassified => AhcState::AHC_STATE_BIAS,
            FaultClass::Drift => AhcState::AHC_STATE_DRIFT,
        },
        _ => return None,
    })
}

impl Alerts {
    fn push(&mut self, sysid: u8, msg: &MavMessage) {
        let mut frame = Vec::with_capacity(64);
        encode_v2(sysid, ALERT_COMPID, self.seq, msg, &mut frame);
        self.seq = self.seq.wrapping_add(1);
        self.outbox.push(frame);
    }

    /// A vehicle is known (its heartbeat or telemetry heard): the heartbeat speaks as it.
    pub fn see(&mut self, sysid: u8) {
        if !self.vehicles.contains(&sysid) {
            self.vehicles.push(sysid);
            // Announce it at the next tick.
            self.next_heartbeat = self.now;
        }
    }

    pub fn on_decision(&mut self, d: &Decision) {
        // (A link event may be about any system the link carried; only vehicles are seen.)
        if !matches!(d.event, Event::LinkLost | Event::LinkRestored) {
            self.see(d.sysid);
        }
        if let (Some(a), Some(s)) = (&d.actuator, state_of(d)) {
            self.state.insert((d.sysid, a.clone()), s);
        }
        if let Some(a) = &d.actuator {
            let loss = matches!(d.event, Event::Fault | Event::Changed)
                && d.class == Some(FaultClass::LossOfEffectiveness);
            if loss {
                self.loss_said.insert((d.sysid, a.clone()), d.clone());
            } else if d.event != Event::ExcitationLow {
                self.loss_said.remove(&(d.sysid, a.clone()));
            }
        }
        if let Some((severity, text)) = statustext(d) {
            if let Some(a) = &d.actuator {
                let said = (severity as u8, text.clone());
                if d.event == Event::Changed
                    && self.last_said.get(&(d.sysid, a.clone())) == Some(&said)
                {
                    self.texts_repeated += 1;
                    return;
                }
                self.last_said.insert((d.sysid, a.clone()), said);
            }
            let q = self.text_queue.entry(d.sysid).or_default();
            q.push_back(QueuedText {
                severity,
                text,
                actuator: d.actuator.clone(),
            });
            if q.len() > TEXT_QUEUE {
                // A text a newer one about the same actuator follows can go; an actuator's
                // newest stays. MAV_SEVERITY: lower is more severe. The least severe of those
                // that can go goes (the oldest of those), unless it is a fault and the hard cap
                // is not reached; past the cap the oldest of those that can go.
                let superseded = |i: usize| {
                    q[i].actuator.is_none()
                        || q.range(i + 1..)
                            .any(|later| later.actuator == q[i].actuator)
                };
                let least = (0..q.len())
                    .rev()
                    .filter(|&i| superseded(i))
                    .max_by_key(|&i| q[i].severity as u8);
                let is_fault =
                    |i: usize| (q[i].severity as u8) <= MavSeverity::MAV_SEVERITY_ERROR as u8;
                let drop_at = match least {
                    Some(i) if !is_fault(i) => Some(i),
                    _ if q.len() > TEXT_QUEUE_HARD => {
                        Some((0..q.len()).find(|&i| superseded(i)).unwrap_or(0))
                    }
                    _ => None,
                };
                if let Some(i) = drop_at {
                    q.remove(i);
                    self.texts_dropped += 1;
                }
            }
            self.flush_texts();
        }
    }

    pub fn on_estimates(
        &mut self,
        t: f64,
        sysid: u8,
        est: &[&[AhcEstimate]; 3],
        profile: &Profile,
    ) {
        self.see(sysid);
        // Made again only when the profile's actuators change (a reboot, another profile).
        let known = self.value_names.get(&sysid).is_some_and(|(names, _)| {
            names
                .iter()
                .map(|(n, c)| (n, *c))
                .eq(profile.actuators.iter().map(|a| (&a.name, a.channel)))
        });
        if !known {
            let names = profile
                .actuators
                .iter()
                .map(|a| (a.name.clone(), a.channel))
                .collect();
            self.value_names
                .insert(sysid, (names, value_names(profile)));
            // The old profile's actuators would go on being sent under the new names (their
            // index); the states of actuators it no longer has would never change again.
            self.latest.retain(|(id, _), _| *id != sysid);
            let kept = |(id, name): &(u8, String)| {
                *id != sysid || profile.actuators.iter().any(|a| &a.name == name)
            };
            self.state.retain(|k, _| kept(k));
            self.loss_said.retain(|k, _| kept(k));
        }
        // Losses in force whose size has moved far from their last text (looked up per loss,
        // not per actuator and step: no key is made unless one is due).
        let points = |g: f64| (1.0 - g) * 100.0;
        let resay: Vec<Decision> = self
            .loss_said
            .iter()
            .filter(|((id, _), said)| *id == sysid && t - said.t >= LOSS_RESAY_S)
            .filter_map(|((_, name), said)| {
                let j = profile.actuators.iter().position(|a| &a.name == name)?;
                let gamma = est[0].get(j)?.gamma;
                let moved = (points(gamma) - points(said.gamma.unwrap_or(1.0))).abs();
                (moved >= LOSS_RESAY_POINTS).then(|| {
                    let mut d = said.clone();
                    d.event = Event::Changed;
                    d.t = t;
                    d.gamma = Some(gamma);
                    d
                })
            })
            .collect();
        for d in resay {
            self.texts_resized += 1;
            self.on_decision(&d);
        }
        for (j, a) in profile.actuators.iter().enumerate() {
            self.latest.insert(
                (sysid, a.name.clone()),
                Latest {
                    t,
                    ukf: est[0][j],
                    set: est[2][j],
                    channel: a.channel,
                    index: j as u8,
                },
            );
        }
    }

    fn flush_texts(&mut self) {
        let ids: Vec<u8> = self.text_queue.keys().copied().collect();
        for sysid in ids {
            let last = self
                .last_text
                .get(&sysid)
                .copied()
                .unwrap_or(f64::NEG_INFINITY);
            if self.now - last < TEXT_INTERVAL_S {
                continue;
            }
            let Some(QueuedText { severity, text, .. }) =
                self.text_queue.get_mut(&sysid).and_then(|q| q.pop_front())
            else {
                continue;
            };
            self.last_text.insert(sysid, self.now);
            self.texts_sent += 1;
            let msg = MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                severity,
                text: text.as_str().into(),
                id: 0,
                chunk_seq: 0,
            });
            self.push(sysid, &msg);
        }
    }

    /// Advance the wall clock (s): heartbeat, queued texts, values.
    pub fn tick(&mut self, now: f64) {
        self.now = now;
        if now >= self.next_heartbeat {
            self.next_heartbeat = now + 1.0;
            // As each vehicle's system id; before any is known, nothing (a component of a
            // system 1 that may not be there, or be another vehicle).
            for sysid in self.vehicles.clone() {
                let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                    base_mode: MavModeFlag::empty(),
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                });
                self.push(sysid, &msg);
            }
        }
        self.flush_texts();
        if now - self.last_values >= VALUE_INTERVAL_S {
            self.last_values = now;
            let latest: Vec<((u8, String), Latest)> =
                self.latest.iter().map(|(k, v)| (k.clone(), *v)).collect();
            for ((sysid, name), l) in latest {
                let time_boot_ms = (l.t * 1e3).max(0.0) as u32;
                let names = self
                    .value_names
                    .get(&sysid)
                    .and_then(|(_, v)| v.get(usize::from(l.index)))
                    .cloned()
                    .unwrap_or_else(|| [short_name("g", &name), short_name("d", &name)]);
                for (value_name, value) in names.iter().zip([l.ukf.gamma, l.ukf.delta]) {
                    let msg = MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                        time_boot_ms,
                        value: value as f32,
                        name: value_name.as_str().into(),
                    });
                    self.push(sysid, &msg);
                }
                let state = self
                    .state
                    .get(&(sysid, name.clone()))
                    .copied()
                    .unwrap_or(AhcState::AHC_STATE_HEALTHY);
                let [g, d] = guaranteed(&l.set);
                // Both filters' bounds of the output at the same recent command.
                let ukf_output = l.ukf.output_probable(l.set.command_ref);
                let set_output = l
                    .set
                    .output_bounds
                    .map_or([f32::NAN; 2], |b| b.map(|v| v as f32));
                let msg = MavMessage::AHC_ESTIMATE(AHC_ESTIMATE_DATA {
                    time_boot_ms,
                    actuator: l.index,
                    channel: l.channel,
                    state,
                    name: name.as_str().into(),
                    ukf_gamma: l.ukf.gamma as f32,
                    ukf_gamma_lo: l.ukf.gamma_lo as f32,
                    ukf_gamma_hi: l.ukf.gamma_hi as f32,
                    ukf_delta: l.ukf.delta as f32,
                    ukf_delta_lo: l.ukf.delta_lo as f32,
                    ukf_delta_hi: l.ukf.delta_hi as f32,
                    set_gamma: g[0],
                    set_gamma_lo: g[1],
                    set_gamma_hi: g[2],
                    set_delta: d[0],
                    set_delta_lo: d[1],
                    set_delta_hi: d[2],
                    set_unexcited: u8::from(l.set.unexcited[0]) | u8::from(l.set.unexcited[1]) << 1,
                    command_ref: l.set.command_ref as f32,
                    ukf_output_lo: ukf_output[1] as f32,
                    ukf_output_hi: ukf_output[2] as f32,
                    set_output_lo: set_output[0],
                    set_output_hi: set_output[1],
                });
                self.push(sysid, &msg);
            }
        }
    }
}

/// The set filter's `[estimate, lo, hi]` of gamma and of delta as sent: NaN for a coefficient
/// still at its a priori box, which says nothing (a planner draws no line for NaN).
fn guaranteed(set: &AhcEstimate) -> [[f32; 3]; 2] {
    let sent =
        |unexcited: bool, v: [f64; 3]| v.map(|x| if unexcited { f32::NAN } else { x as f32 });
    [
        sent(set.unexcited[0], [set.gamma, set.gamma_lo, set.gamma_hi]),
        sent(set.unexcited[1], [set.delta, set.delta_lo, set.delta_hi]),
    ]
}

#[cfg(test)]
mod tests;
