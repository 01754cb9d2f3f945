//! Alerts into a mission planner (DESIGN.md "Alerts to a mission planner", shared/mavlink.md
//! §3): the monitor as a MAVLink component of its own — HEARTBEAT at 1 Hz
//! (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID) sent as the vehicle's system id with
//! component id 191, a STATUSTEXT per decision (severity by class, at most 50 characters,
//! rate-limited), NAMED_VALUE_FLOAT `g_<name>` / `d_<name>` per actuator at 2 Hz, and our
//! AHC_ESTIMATE with both filters' bounds. Pure: encoded frames go to `outbox`; the caller
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
    esmf: AhcEstimate,
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

/// `AHC swash2 LOE 41% UKF+ESMF`: what the planner shows (≤ 50 characters).
pub fn statustext(d: &Decision) -> Option<(MavSeverity, String)> {
    let who = d.actuator.as_deref().unwrap_or("");
    let by: Vec<&str> = d
        .filters
        .iter()
        .map(|f| match *f {
            "mit-ukf" => "UKF",
            "mit-esmf" => "ESMF",
            other => other,
        })
        .collect();
    let by = by.join("+");
    // The actuator's name is what gives way when the text is too long, not the class.
    let fit = |what: &str, by: &str| {
        let tail = format!(" {what} {by}");
        let room = TEXT_BYTES.saturating_sub("AHC ".len() + tail.trim_end().len());
        format!("AHC {}{}", cut_bytes(who, room), tail.trim_end())
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
        Event::ExcitationLow => return None,
        Event::FilterReset => (MavSeverity::MAV_SEVERITY_WARNING, "AHC filter reset".into()),
        Event::LinkLost | Event::LinkRestored => return None,
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
        est: &[&[AhcEstimate]; 2],
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
                    esmf: est[1][j],
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
                    esmf_gamma: l.esmf.gamma as f32,
                    esmf_gamma_lo: l.esmf.gamma_lo as f32,
                    esmf_gamma_hi: l.esmf.gamma_hi as f32,
                    esmf_delta: l.esmf.delta as f32,
                    esmf_delta_lo: l.esmf.delta_lo as f32,
                    esmf_delta_hi: l.esmf.delta_hi as f32,
                });
                self.push(sysid, &msg);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statustext_fits_and_names_the_actuator() {
        let mut d = Decision::monitor(1.0, 1, Event::Fault, "");
        d.detail = None;
        d.actuator = Some("swash2".into());
        d.class = Some(FaultClass::LossOfEffectiveness);
        d.gamma = Some(0.59);
        d.filters = vec!["mit-ukf", "mit-esmf"];
        let (sev, text) = statustext(&d).unwrap();
        assert_eq!(text, "AHC swash2 LOE 41% UKF+ESMF");
        assert_eq!(sev, MavSeverity::MAV_SEVERITY_CRITICAL);
        // A long name gives way, the class and the filters stay; bytes, not characters, and
        // never half a character.
        d.actuator = Some("a_very_long_actuator_name_that_goes_on_and_on".into());
        let (_, text) = statustext(&d).unwrap();
        assert!(text.len() <= 50, "{text}");
        assert!(text.starts_with("AHC a_very_long") && text.ends_with(" LOE 41% UKF+ESMF"));
        d.actuator = Some("höhenruder_links_äußeres_ruder_über_alles".into());
        let (_, text) = statustext(&d).unwrap();
        assert!(
            text.len() <= 50 && text.ends_with(" LOE 41% UKF+ESMF"),
            "{text}"
        );
        assert_eq!(short_name("g", "servo1_ä"), "g_servo1_");
        assert_eq!(short_name("g", "motor1"), "g_motor1");
        // A bias's size is the output's offset at the operating point, whatever the filter's
        // split (gain 1.25 with delta -0.001 on a hovering motor read "bias -0.00").
        d.actuator = Some("motor5".into());
        d.class = Some(FaultClass::Bias);
        d.gamma = Some(1.25);
        d.delta = Some(-0.001);
        d.deviation = Some(0.121);
        let (sev, text) = statustext(&d).unwrap();
        assert_eq!(text, "AHC motor5 bias +12% UKF+ESMF");
        assert_eq!(sev, MavSeverity::MAV_SEVERITY_ERROR);
    }

    #[test]
    fn value_names_are_unique_within_a_vehicle() {
        use crate::protocol::frame::{Parsed, parse};
        // `esc_motor_1`..`_3` all cut to `g_esc_moto`: every actuator takes its channel.
        let mut p = Profile::resolve("quad-x").unwrap();
        for (j, a) in p.actuators.iter_mut().enumerate() {
            a.name = format!("esc_motor_{}", j + 1);
        }
        p.actuators[3].name = "tail".into();
        let names = value_names(&p);
        assert_eq!(names[0], ["g_ch1", "d_ch1"]);
        assert_eq!(names[2], ["g_ch3", "d_ch3"]);
        assert_eq!(names[3], ["g_ch4", "d_ch4"]);
        let mut apart = p.clone();
        for (j, a) in apart.actuators.iter_mut().take(3).enumerate() {
            a.name = format!("m{}", j + 1);
        }
        assert_eq!(value_names(&apart)[3], ["g_tail", "d_tail"]);
        let mut a = Alerts::default();
        let est = [AhcEstimate::default(); 4];
        a.on_estimates(1.0, 1, &[&est, &est], &p);
        a.tick(1.0);
        let mut sent = std::collections::BTreeSet::new();
        for frame in &a.outbox {
            if let Parsed::Frame(f, _) = parse(frame)
                && let MavMessage::NAMED_VALUE_FLOAT(m) = f.msg
            {
                sent.insert(m.name.to_str().unwrap().trim_end_matches('\0').to_string());
            }
        }
        assert_eq!(sent.len(), 8, "{sent:?}");
        // The vehicle's profile changes (a reboot as another frame): only the new actuators'
        // values are sent, each under its own name (the old ones went on under new names).
        let hexa = Profile::resolve("hexa-x").unwrap();
        let est6 = [AhcEstimate::default(); 6];
        a.on_estimates(2.0, 1, &[&est6, &est6], &hexa);
        a.outbox.clear();
        a.tick(2.0);
        let mut count = std::collections::BTreeMap::new();
        for frame in &a.outbox {
            if let Parsed::Frame(f, _) = parse(frame)
                && let MavMessage::NAMED_VALUE_FLOAT(m) = f.msg
            {
                let name = m.name.to_str().unwrap().trim_end_matches('\0').to_string();
                *count.entry(name).or_insert(0) += 1;
            }
        }
        assert_eq!(count.len(), 12, "{count:?}");
        assert!(count.values().all(|n| *n == 1), "{count:?}");
        assert!(count.contains_key("g_motor6"), "{count:?}");
    }

    /// A loss told at the alarm is told again once the MIT-UKF's estimate has moved 10
    /// percentage points from it (not sooner than 5 s after the last text); a cleared one no more.
    #[test]
    fn a_loss_is_told_again_at_its_new_size() {
        let p = Profile::resolve("heli-h3-120").unwrap();
        let mut a = Alerts::default();
        let mut d = decision(
            Event::Fault,
            "swash2",
            Some(FaultClass::LossOfEffectiveness),
        );
        d.t = 42.0;
        d.gamma = Some(0.84);
        a.on_decision(&d);
        let mut est = [AhcEstimate::default(); 4];
        for e in est.iter_mut() {
            e.gamma = 1.0;
        }
        // Sent (the outbox) and then waiting (the queue), in order.
        let texts = |a: &Alerts| -> Vec<String> {
            use crate::protocol::frame::{Parsed, parse};
            let sent = a.outbox.iter().filter_map(|f| match parse(f) {
                Parsed::Frame(f, _) => match f.msg {
                    MavMessage::STATUSTEXT(m) => {
                        Some(m.text.to_str().unwrap().trim_end_matches('\0').to_string())
                    }
                    _ => None,
                },
                _ => None,
            });
            let queued = a.text_queue.values().flatten().map(|q| q.text.clone());
            sent.chain(queued).collect()
        };
        assert_eq!(texts(&a), vec!["AHC swash2 LOE 16% UKF"]);
        est[1].gamma = 0.69;
        // Too soon after the last text: not yet.
        a.on_estimates(45.0, 1, &[&est, &est], &p);
        assert_eq!(texts(&a).len(), 1);
        a.on_estimates(47.5, 1, &[&est, &est], &p);
        assert_eq!(texts(&a)[1], "AHC swash2 LOE 31% UKF");
        // Within 10 points of the new size: nothing more.
        est[1].gamma = 0.62;
        a.on_estimates(60.0, 1, &[&est, &est], &p);
        assert_eq!(texts(&a).len(), 2);
        assert_eq!(a.texts_resized, 1);
        // Cleared: its size is not told again.
        a.on_decision(&decision(Event::Cleared, "swash2", None));
        est[1].gamma = 0.3;
        a.on_estimates(70.0, 1, &[&est, &est], &p);
        assert_eq!(texts(&a).len(), 3, "{:?}", texts(&a));
    }

    /// A decision about `actuator` of vehicle 1, as the diagnosis makes them.
    fn decision(event: Event, actuator: &str, class: Option<FaultClass>) -> Decision {
        let mut d = Decision::monitor(1.0, 1, event, "");
        d.actuator = Some(actuator.into());
        d.class = class;
        d.gamma = Some(0.5);
        d.filters = vec!["mit-ukf"];
        d
    }

    /// A loss of effectiveness whose size alternates (50 %, 60 %) with `k`: each text unlike
    /// the one before.
    fn changing_loss(actuator: &str, k: usize) -> Decision {
        let mut d = decision(
            Event::Fault,
            actuator,
            Some(FaultClass::LossOfEffectiveness),
        );
        d.gamma = Some(if k % 2 == 0 { 0.5 } else { 0.4 });
        d
    }

    /// The STATUSTEXT in the outbox, in order.
    fn sent_texts(a: &Alerts) -> Vec<String> {
        a.outbox
            .iter()
            .filter_map(|frame| match crate::protocol::frame::parse(frame) {
                crate::protocol::frame::Parsed::Frame(f, _) => match f.msg {
                    MavMessage::STATUSTEXT(t) => Some(
                        String::from_utf8_lossy(&t.text[..])
                            .trim_end_matches('\0')
                            .to_string(),
                    ),
                    _ => None,
                },
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_full_text_queue_drops_the_least_severe_never_a_fault() {
        let mut a = Alerts::default();
        a.tick(0.0);
        // One text goes at once; then a fault and a flood of notices and resets.
        a.on_decision(&decision(Event::Cleared, "motor1", None));
        a.on_decision(&decision(
            Event::Fault,
            "motor2",
            Some(FaultClass::LossOfEffectiveness),
        ));
        for k in 0..20 {
            let e = if k % 2 == 0 {
                Event::Cleared
            } else {
                Event::FilterReset
            };
            a.on_decision(&decision(e, "motor3", None));
        }
        assert_eq!(a.texts_dropped, 21 - TEXT_QUEUE as u64);
        let q = &a.text_queue[&1];
        assert_eq!(q.len(), TEXT_QUEUE);
        assert!(
            q.iter().any(|x| x.text.starts_with("AHC motor2 LOE")),
            "{q:?}"
        );
        // Faults alone grow the queue past the soft cap rather than being dropped (each text
        // unlike the one before, or it would not be queued at all).
        for k in 0..20 {
            a.on_decision(&changing_loss("motor4", k));
        }
        let q = &a.text_queue[&1];
        assert!(
            q.iter()
                .filter(|x| x.severity == MavSeverity::MAV_SEVERITY_CRITICAL)
                .count()
                == 21
        );
    }

    #[test]
    fn a_flapping_actuator_s_last_queued_text_is_its_state_now() {
        let mut a = Alerts::default();
        a.tick(0.0);
        // Faster than texts go (the first goes at once): motor2 faults, then motor1 faults and
        // clears ten times.
        a.on_decision(&decision(Event::Cleared, "motor3", None));
        a.on_decision(&decision(Event::Fault, "motor2", Some(FaultClass::Stuck)));
        for _ in 0..10 {
            a.on_decision(&decision(
                Event::Fault,
                "motor1",
                Some(FaultClass::LossOfEffectiveness),
            ));
            a.on_decision(&decision(Event::Cleared, "motor1", None));
        }
        let q = &a.text_queue[&1];
        let last_motor1 = q
            .iter()
            .rev()
            .find(|x| x.actuator.as_deref() == Some("motor1"))
            .unwrap();
        assert!(last_motor1.text.contains("cleared"), "{q:?}");
        assert!(
            q.iter().any(|x| x.text.starts_with("AHC motor2 stuck")),
            "{q:?}"
        );
        // Sent in order, the planner's last text about motor1 says it cleared.
        let mut last = None;
        for k in 1..=40 {
            a.tick(k as f64 * TEXT_INTERVAL_S);
        }
        assert!(a.text_queue[&1].is_empty());
        for frame in a.outbox.drain(..) {
            if let crate::protocol::frame::Parsed::Frame(f, _) =
                crate::protocol::frame::parse(&frame)
                && let MavMessage::STATUSTEXT(t) = f.msg
            {
                let text = String::from_utf8_lossy(&t.text[..]).into_owned();
                if text.contains("motor1") {
                    last = Some(text);
                }
            }
        }
        assert!(
            last.as_deref().is_some_and(|t| t.contains("cleared")),
            "{last:?}"
        );
    }

    #[test]
    fn past_the_hard_cap_an_actuator_s_newest_text_still_stays() {
        let mut a = Alerts::default();
        a.tick(0.0);
        a.on_decision(&decision(Event::Cleared, "motor3", None));
        // motor2's clearing waits behind a flood of motor1 faults past the hard cap.
        a.on_decision(&decision(Event::Cleared, "motor2", None));
        for k in 0..2 * TEXT_QUEUE_HARD {
            a.on_decision(&changing_loss("motor1", k));
        }
        let q = &a.text_queue[&1];
        assert!(q.len() <= TEXT_QUEUE_HARD + 1, "{}", q.len());
        assert!(
            q.iter().any(|x| x.actuator.as_deref() == Some("motor2")),
            "{q:?}"
        );
        assert_eq!(a.texts_dropped, (2 * TEXT_QUEUE_HARD + 1 - q.len()) as u64);
    }

    #[test]
    fn ahc_estimate_carries_the_profile_index_of_each_vehicle() {
        use crate::protocol::frame::{Parsed, parse};
        let quad = Profile::resolve("quad-x").unwrap();
        let plane = Profile::resolve("plane").unwrap();
        let est = [AhcEstimate::default(); 8];
        let mut a = Alerts::default();
        a.on_estimates(1.0, 1, &[&est[..4], &est[..4]], &quad);
        a.on_estimates(1.0, 2, &[&est[..3], &est[..3]], &plane);
        a.tick(1.0);
        let mut seen = Vec::new();
        for frame in &a.outbox {
            if let Parsed::Frame(f, _) = parse(frame)
                && let MavMessage::AHC_ESTIMATE(m) = f.msg
            {
                let name = m.name.to_str().unwrap().trim_end_matches('\0').to_string();
                seen.push((f.sysid, name, m.actuator));
            }
        }
        seen.sort();
        let mut expected = Vec::new();
        for (p, sysid) in [(&quad, 1u8), (&plane, 2)] {
            for (j, a) in p.actuators.iter().enumerate() {
                expected.push((sysid, a.name.clone(), j as u8));
            }
        }
        expected.sort();
        assert_eq!(seen, expected);
    }

    #[test]
    fn texts_are_rate_limited_and_queued() {
        let mut a = Alerts::default();
        a.tick(0.0);
        assert!(
            a.outbox.is_empty(),
            "no heartbeat before a vehicle is known"
        );
        a.see(1);
        a.tick(1.0);
        let hb = a.outbox.len();
        assert_eq!(hb, 1, "one heartbeat");
        for motor in ["motor1", "motor2", "motor3"] {
            let mut d = Decision::monitor(1.0, 1, Event::Cleared, "");
            d.actuator = Some(motor.into());
            a.on_decision(&d);
        }
        assert_eq!(a.texts_sent, 1);
        a.tick(1.5);
        assert_eq!(a.texts_sent, 1);
        a.tick(2.1);
        assert_eq!(a.texts_sent, 2);
    }

    #[test]
    fn a_text_the_planner_already_has_for_the_actuator_is_not_repeated() {
        // hexa motor 5 stuck: `changed` decisions that only take over other motors' alarms
        // read "stuck UKF+ESMF" again and again (29 of 209 texts over the eight fault
        // scenarios, seeds 1-10). The planner hears it once; a different text about the same
        // actuator, the same text after a different one, or a `fault`, is said.
        let mut a = Alerts::default();
        let stuck = decision(Event::Fault, "motor5", Some(FaultClass::Stuck));
        let mut again = stuck.clone();
        again.event = Event::Changed;
        for (k, d) in [&stuck, &again, &again].into_iter().enumerate() {
            a.tick(k as f64 * 2.0);
            a.on_decision(d);
        }
        assert_eq!((a.texts_sent, a.texts_repeated), (1, 2));
        let cleared = decision(Event::Cleared, "motor5", None);
        let other = decision(Event::Fault, "motor6", Some(FaultClass::Stuck));
        for (k, d) in [&cleared, &stuck, &other].into_iter().enumerate() {
            a.tick(10.0 + k as f64 * 2.0);
            a.on_decision(d);
        }
        assert_eq!((a.texts_sent, a.texts_repeated), (4, 2));
        // After a reboot (a fresh diagnosis, no `cleared`) the same fault is decided again:
        // news, so said.
        a.tick(20.0);
        a.on_decision(&other);
        assert_eq!((a.texts_sent, a.texts_repeated), (5, 2));
        let texts: Vec<String> = sent_texts(&a);
        assert_eq!(
            texts,
            [
                "AHC motor5 stuck UKF",
                "AHC motor5 cleared",
                "AHC motor5 stuck UKF",
                "AHC motor6 stuck UKF",
                "AHC motor6 stuck UKF"
            ]
        );
    }
}
