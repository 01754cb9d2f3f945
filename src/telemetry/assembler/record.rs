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

#[cfg(test)]
mod tests {
    use super::super::{AssemblerConfig, VehicleAssembler};
    use crate::protocol::dialects::ahcmon::MavMessage;

    fn feed(a: &mut VehicleAssembler, msgs: &[MavMessage]) {
        let mut out = Vec::new();
        for m in msgs {
            a.on_message(1, m, &mut out);
        }
    }

    #[test]
    fn the_board_id_comes_from_autopilot_version_or_the_boot_banner_first_one_kept() {
        use crate::protocol::dialects::ahcmon::{AUTOPILOT_VERSION_DATA, STATUSTEXT_DATA};
        let text = |s: &str| {
            let mut t = [0u8; 50];
            t[..s.len()].copy_from_slice(s.as_bytes());
            MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                text: t.into(),
                ..Default::default()
            })
        };
        let version = |uid: u64| {
            MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
                uid,
                ..Default::default()
            })
        };
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut a, &[text("ArduCopter V4.5.7 (2a3dc4b7)"), version(0)]);
        assert_eq!(a.info.board_uid, None, "SITL's zero uid is no id");
        feed(
            &mut a,
            &[
                text("CubeOrange 003A002D 3138510F 33393935"),
                version(0xABCD),
            ],
        );
        assert_eq!(
            a.info.board_uid.as_deref(),
            Some("mcu 003A002D 3138510F 33393935")
        );
        let mut b = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut b, &[version(0xABCD)]);
        assert_eq!(b.info.board_uid.as_deref(), Some("uid 000000000000ABCD"));
    }
}
