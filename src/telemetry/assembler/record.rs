//! A vehicle's own log (DataFlash, ULog) into the same state the MAVLink frames reach: its
//! records carry µs stamps and the autopilot's own values, so there is no component to pick
//! and no heartbeat to wait for.

use super::{AzSource, TelemetrySample, VehicleAssembler};
use crate::telemetry::Record;

impl VehicleAssembler {
    /// One record of the vehicle's log; complete samples are appended to `out`.
    pub fn on_record(&mut self, record: &Record, out: &mut Vec<TelemetrySample>) {
        let rate_instant = match record {
            Record::Rates { t, .. } => Some(*t),
            _ => None,
        };
        self.release_pending(rate_instant, out);
        let emitted = self.record(record);
        self.deliver(emitted, out);
    }

    fn record(&mut self, record: &Record) -> Option<TelemetrySample> {
        match record {
            Record::Vehicle {
                mav_type,
                autopilot,
            } => {
                self.info.compid = Some(1);
                self.info.mav_type = Some(*mav_type);
                self.info.autopilot = Some(*autopilot);
                None
            }
            Record::Armed(armed) => {
                self.info.armed = *armed;
                None
            }
            Record::Param { name, value } => {
                if !name.is_empty() && value.is_finite() {
                    self.info.params.insert(name.clone(), *value);
                }
                None
            }
            Record::Text(text) => {
                self.note_text(text);
                None
            }
            Record::Board(id) => {
                if self.info.board_uid.is_none() {
                    self.info.board_uid = Some(id.clone());
                }
                None
            }
            Record::RelAlt(h) => {
                if h.is_finite() {
                    self.rel_alt = Some(*h);
                } else {
                    self.counters.non_finite += 1;
                }
                None
            }
            Record::Attitude { attitude } => {
                if attitude.iter().all(|x| x.is_finite()) {
                    self.attitude = *attitude;
                } else {
                    self.counters.non_finite += 1;
                }
                None
            }
            Record::Rates { t, rates } => {
                if !t.is_finite() || rates.iter().any(|x| !x.is_finite()) {
                    self.counters.non_finite += 1;
                    return None;
                }
                self.rates_ms_clock = false;
                self.on_rates(*t, *rates, self.attitude)
            }
            Record::Outputs { t, pwm } => {
                if !t.is_finite() || !self.tick(*t) {
                    return None;
                }
                self.set_outputs(*t, *pwm)
            }
            Record::Az { t, az } => {
                if !t.is_finite() {
                    self.counters.non_finite += 1;
                    return None;
                }
                self.on_az(AzSource::HighresImu, *t, *az)
            }
        }
    }

    /// A text the vehicle sent (STATUSTEXT) or logged: kept (the first 1000), and its board id
    /// read.
    pub(super) fn note_text(&mut self, text: &str) {
        if self.info.statustext.len() < 1000 {
            self.info.statustext.push(text.to_string());
        }
        if self.info.board_uid.is_none() {
            self.info.board_uid = crate::telemetry::identity::from_banner(text);
        }
    }
}
