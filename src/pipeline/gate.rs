//! Take-off and landing: nothing is estimated on the ground (ground contact is not in the
//! model). Airborne is a known height above `airborne_alt_m`, or without a height, armed for
//! `armed_airborne_s`; the profile is chosen `settle_s` after take-off and the calibration
//! starts.

use super::{Stage, VehiclePipeline};
use crate::output::Sink;
use crate::telemetry::detect::{Detection, detect};
use crate::telemetry::{TelemetrySample, VehicleInfo};

/// What the take-off test saw, to say why a run never started estimating.
#[derive(Debug, Clone, Copy, Default)]
pub struct FlightGate {
    /// Complete samples seen, and those with the vehicle armed.
    pub samples: u64,
    pub armed_samples: u64,
    /// Longest armed stretch (s) and the highest relative altitude while armed (m).
    pub longest_armed_s: f64,
    pub max_rel_alt_armed: Option<f64>,
    /// Longest stretch taken as airborne: its first and last sample times (vehicle clock, s).
    pub longest_airborne: Option<(f64, f64)>,
    /// Samples taken as airborne.
    pub airborne_samples: u64,
    /// Time airborne in all (s): the sum of the steps between consecutive airborne samples,
    /// each at most `MAX_AIRBORNE_STEP_S` (a hole in the data is not flight time seen).
    pub airborne_s: f64,
    last_airborne_t: Option<f64>,
}

impl FlightGate {
    /// How long the longest airborne stretch lasted (s); 0 if never airborne.
    pub fn longest_airborne_s(&self) -> f64 {
        self.longest_airborne.map_or(0.0, |(from, to)| to - from)
    }
}

/// Vehicle seconds since boot after which a first sample already airborne means the monitor
/// joined a flight under way (a real vehicle spends longer than this on the ground between
/// boot and take-off; a simulator starts airborne at boot).
const JOINED_IN_FLIGHT_S: f64 = 30.0;
/// Longest step between two airborne samples counted as flight time (s).
const MAX_AIRBORNE_STEP_S: f64 = 1.0;
pub(super) const JOINED_WARNING: &str = "no take-off seen";

impl VehiclePipeline {
    pub(super) fn airborne(&mut self, s: &TelemetrySample) -> bool {
        self.gate.samples += 1;
        if !s.armed {
            self.armed_since = None;
            self.gate.last_airborne_t = None;
            return false;
        }
        let since = *self.armed_since.get_or_insert(s.t);
        let g = &mut self.gate;
        g.armed_samples += 1;
        g.longest_armed_s = g.longest_armed_s.max(s.t - since);
        if let Some(h) = s.rel_alt {
            g.max_rel_alt_armed = Some(g.max_rel_alt_armed.map_or(h, |m: f64| m.max(h)));
        }
        let airborne = match s.rel_alt {
            Some(h) => h > self.cfg.airborne_alt_m,
            None => s.t - since >= self.cfg.armed_airborne_s,
        };
        g.airborne_samples += u64::from(airborne);
        if airborne {
            if let Some(prev) = g.last_airborne_t {
                g.airborne_s += (s.t - prev).clamp(0.0, MAX_AIRBORNE_STEP_S);
            }
            g.last_airborne_t = Some(s.t);
        } else {
            g.last_airborne_t = None;
        }
        airborne
    }

    /// A sample on the ground: a calibration under way starts over at the next take-off, a
    /// run's command history is cut (no residual spans the time on the ground).
    pub(super) fn on_ground(
        &mut self,
        s: &TelemetrySample,
        info: &VehicleInfo,
        sink: &mut dyn Sink,
    ) {
        // Known to be on the ground: disarmed by its heartbeat, or armed at a known low
        // height (not merely not armed long enough, or before the first heartbeat).
        let low = s.rel_alt.is_some_and(|h| h <= self.cfg.airborne_alt_m);
        self.seen_grounded |= info.mav_type.is_some() && (!s.armed || low);
        self.announced_takeoff = None;
        // Where a flight ended, to choose a stretch by (`--calibrate-until`, `calibrate
        // --until`): the take-off was said, the landing was not.
        let flew = self
            .airborne_since
            .take()
            .filter(|since| s.t - since >= self.cfg.settle_s);
        match &mut self.stage {
            Stage::Calibrating { .. } => {
                sink.message(
                    self.sysid,
                    &format!(
                        "landed at t={:.2} s during calibration; starting over at the next take-off",
                        s.t
                    ),
                );
                self.set_stage(Stage::Grounded, "landed");
            }
            Stage::Running(r) => {
                if let Some(since) = flew {
                    sink.message(
                        self.sysid,
                        &format!("landed at t={:.2} s (airborne from t={since:.2} s)", s.t),
                    );
                }
                r.prev_u = None;
                r.u_pushed = 0;
                r.since_gap = 0;
            }
            _ => {}
        }
    }

    /// Airborne since `since` with no profile chosen yet: once settled, the profile is
    /// detected (or the one given) and the calibration stretch starts.
    pub(super) fn take_off(
        &mut self,
        s: &TelemetrySample,
        info: &VehicleInfo,
        since: f64,
        sink: &mut dyn Sink,
    ) {
        if s.t - since < self.cfg.settle_s {
            return;
        }
        let detection = match &self.cfg.profile {
            Some(p) => Ok(Detection {
                profile: p.clone(),
                warnings: crate::telemetry::detect::given_profile_warnings(p, info),
                source: format!("{} (--profile)", p.name),
            }),
            None => detect(info),
        };
        match detection {
            Ok(d) => {
                // Once a run: detection runs again at every take-off until calibrated.
                for w in &d.warnings {
                    if self.warned.insert(w.clone()) {
                        // The message is prefixed with the sysid already.
                        let prefix = format!("sysid {}: ", self.sysid);
                        let w = w.strip_prefix(&prefix).unwrap_or(w);
                        sink.message(self.sysid, &format!("warning: {w}"));
                    }
                }
                let as_is = Self::as_is(&self.cfg, &d.profile);
                let next = if as_is {
                    "its identified model as it is (no calibration in flight)"
                } else {
                    "calibrating"
                };
                if self.announced_takeoff.replace(since) == Some(since) {
                    // A stretch the data could not support was said once; its retries are not.
                    if !self.unsupported {
                        sink.message(
                            self.sysid,
                            &format!(
                                "{next} again from t={:.2} s (in the flight since t={since:.2} s)",
                                s.t
                            ),
                        );
                    }
                } else {
                    sink.message(
                        self.sysid,
                        &format!("airborne at t={since:.2} s; profile {}; {next}", d.source),
                    );
                }
                // Joined a flight under way (a vehicle up for a while, and no sample
                // on the ground): whatever it flies with now is taken as healthy. A
                // simulator's flight starts airborne at boot, and is not warned about.
                if !self.seen_grounded
                    && !as_is
                    && since >= JOINED_IN_FLIGHT_S
                    && self.warned.insert(JOINED_WARNING.into())
                {
                    // Without a height, armed long enough counts as airborne: the
                    // vehicle may still be on the ground.
                    let began = self.armed_since.unwrap_or(since);
                    let how = if s.rel_alt.is_some() {
                        "already airborne"
                    } else {
                        "already armed, with no height to tell the ground from the air"
                    };
                    sink.message(
                        self.sysid,
                        &format!(
                            "warning: {JOINED_WARNING}: the vehicle was {how} when its data began ({began:.0} s after boot). The calibration takes the next stretch as healthy, so a fault already present is calibrated in and not seen; start the monitor before take-off to watch the whole flight"
                        ),
                    );
                }
                let stage = Stage::Calibrating {
                    profile: Box::new(d.profile.clone()),
                    samples: Vec::with_capacity(2048),
                    raw: Vec::with_capacity(2048),
                };
                self.set_stage(
                    stage,
                    &format!("airborne and settled; profile {}", d.source),
                );
                self.detection = Some(d);
            }
            Err(e) => self.fail(e.to_string(), sink),
        }
    }
}
