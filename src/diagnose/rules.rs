//! The state machine's transitions (rules S1-S3, F1-F3, K1, R1, G1 of `docs/diagnosis.md`)
//! and the decisions they make.

use super::*;

impl Diagnoser {
    /// G1: say once when gain and bias cannot be told apart (again after they have been
    /// separable in between); not while a fault is in force, whose class says it (C3).
    pub(super) fn gate(&mut self, t: f64, j: usize, out: &mut Vec<Decision>) {
        let separable = self.separable(j);
        let st = &mut self.actuators[j];
        st.low_for = if separable { 0.0 } else { st.low_for + self.dt };
        if separable {
            st.excitation_reported = false;
            return;
        }
        if st.low_for >= self.params.window_s
            && !st.excitation_reported
            && !matches!(st.health, Health::Fault(_))
        {
            st.excitation_reported = true;
            let mut d = self.decision(t, j, Event::ExcitationLow, None, 0, Rule::G1);
            d.detail = Some(self.not_separable(j));
            out.push(d);
        }
    }

    /// S1's timers: how long the MIT-UKF's bounds have excluded, or included, the healthy point.
    pub(super) fn track_bounds(&mut self, j: usize) {
        let st = &mut self.actuators[j];
        let e = st.channels[0].last;
        // A non-finite bound (a failing filter) is no evidence either way.
        let bounds = [e.gamma_lo, e.gamma_hi, e.delta_lo, e.delta_hi];
        if !bounds.iter().all(|b| b.is_finite()) {
            return;
        }
        let inside =
            e.gamma_lo <= 1.0 && 1.0 <= e.gamma_hi && e.delta_lo <= 0.0 && 0.0 <= e.delta_hi;
        if inside {
            (st.bounds_out, st.bounds_in) = (0.0, st.bounds_in + self.dt);
        } else {
            (st.bounds_out, st.bounds_in) = (st.bounds_out + self.dt, 0.0);
        }
    }

    /// A fault in force that has stood `DATA_WAIT_S`: its onset's spread over other actuators
    /// has had its time, and the change test's fit of it says nothing against another alarm.
    fn older(&self, t: f64, k: usize) -> bool {
        self.active(k).is_some() && t - self.actuators[k].decided_at >= DATA_WAIT_S
    }

    /// Another actuator's fault in force younger than `DATA_WAIT_S`, and the data do not name
    /// `j` clearly: at a fault's onset the filters spread it over other actuators and the
    /// change test's unclear best fit flickers between them, so an alarm elsewhere is only
    /// evidence of the fault in force.
    fn young_elsewhere(&self, t: f64, j: usize) -> bool {
        let young = (0..self.actuators.len())
            .any(|k| k != j && self.active(k).is_some() && !self.older(t, k));
        young && self.naming_reading().is_none_or(|r| r.actuator != j)
    }

    /// A healthy or suspect actuator: F1-F3 decide a fault, S1-S2 make it suspect, S3 ends a
    /// suspicion.
    pub(super) fn judge(
        &mut self,
        t: f64,
        j: usize,
        health: Health,
        data_alarm: Option<usize>,
        named: Option<usize>,
        out: &mut Vec<Decision>,
    ) {
        let alarms = self.actuators[j].alarms();
        // The data's best fit, of what is under way. An offset under the threshold
        // (`is_fault_size`) measures the change smaller than a fault: the wind imitates one up
        // to that size. A gain above one is no fault's kind (D2), unless the same change read
        // as an offset is of a fault's size (a motor's offset up near a steady command is a gain
        // above one too). On this actuator either is no evidence for F1, and on any it
        // restarts F2's wait: the data see no fault, and the alarm is the filters' reading of
        // the wind.
        let reading = self.reading.filter(|_| !self.reading_scanned);
        let no_fault = reading.filter(|r| match r.kind {
            ChangeKind::Offset => !self.is_fault_size(r),
            ChangeKind::Gain => r.value > 1.0 && !self.offset_reading_of_fault_size(r),
            ChangeKind::Stuck => false,
        });
        let measured_no_fault = no_fault.is_some_and(|r| r.actuator == j);
        let best = reading.map(|r| r.actuator).filter(|_| !measured_no_fault);
        // The data name another actuator clearly: this alarm is its evidence, even when that
        // actuator's fault is in force (the filters spread a fault over other actuators for as
        // long as it lasts; a second fault under it is listed in its `also`).
        let named_other = named.filter(|&k| k != j);
        if alarms == 0 {
            self.actuators[j].contradicted_at = f64::NEG_INFINITY;
        } else if named_other.is_some() || no_fault.is_some() {
            self.actuators[j].contradicted_at = t;
        }
        let st = &self.actuators[j];
        let rule = if data_alarm == Some(j) {
            Some(Rule::F3)
        } else if alarms != 0 && named_other.is_none() {
            // F2: the data have had the wait since the alarm, or since they last named another
            // actuator clearly, and named none.
            let since = st.first_alarm().unwrap_or(t).max(st.contradicted_at);
            if best.is_some_and(|k| k == j || self.older(t, k)) && !self.young_elsewhere(t, j) {
                Some(Rule::F1)
            } else if t - since >= DATA_WAIT_S {
                Some(Rule::F2)
            } else {
                None
            }
        } else {
            None
        };
        if let Some(rule) = rule {
            self.decide(t, j, rule, out);
            return;
        }
        let suspect = if alarms != 0 {
            Some(Rule::S2)
        } else if st.bounds_out >= self.params.suspect_s {
            Some(Rule::S1)
        } else {
            None
        };
        match (health, suspect) {
            (Health::Healthy, Some(rule)) => {
                let e = st.channels[0].last;
                let why = match rule {
                    Rule::S1 => format!(
                        "the MIT-UKF's bounds exclude the healthy point for {:.1} s (gamma {:.3} [{:.3}, {:.3}], delta {:+.3} [{:+.3}, {:+.3}]) while no alarm reaches its threshold: the deviation is within what healthy flights show",
                        st.bounds_out,
                        e.gamma,
                        e.gamma_lo,
                        e.gamma_hi,
                        e.delta,
                        e.delta_lo,
                        e.delta_hi
                    ),
                    _ => match named.or(best) {
                        Some(k) if k != j && named.is_some() => format!(
                            "the filters alarm; the data name {} clearly, whose evidence this is",
                            self.names[k]
                        ),
                        Some(k) if k != j => format!(
                            "the filters alarm; the data fit {} best so far (not clearly)",
                            self.names[k]
                        ),
                        _ => "the filters alarm; the data have no fit yet".into(),
                    },
                };
                let mut d = self.decision(t, j, Event::Suspect, None, alarms, rule);
                d.detail = Some(why);
                out.push(d);
                self.actuators[j].health = Health::Suspect;
            }
            (Health::Suspect, None) if st.bounds_in >= self.params.clear_s => {
                let mut d = self.decision(t, j, Event::SuspectCleared, None, 0, Rule::S3);
                d.detail = Some(format!(
                    "no alarm, and the MIT-UKF's bounds hold the healthy point again for {} s",
                    self.params.clear_s
                ));
                out.push(d);
                self.actuators[j].health = Health::Healthy;
            }
            _ => {}
        }
    }

    /// A fault decision on `j` by `rule`.
    pub(super) fn decide(&mut self, t: f64, j: usize, rule: Rule, out: &mut Vec<Decision>) {
        let (class, class_rule, mixed, why) = self.classify(j);
        let why = why.map(|w| self.why_text(j, w));
        let filters = self.actuators[j].alarms();
        let mut d = self.decision(t, j, Event::Fault, Some(class), filters, rule);
        d.also = self.also(j);
        let evidence = match rule {
            Rule::F1 => "the filters alarm and the data fit this actuator best",
            Rule::F2 => "the filters alarm, and the data named no other actuator in 3 s",
            _ => "the data name it clearly, with a change as large as a fault",
        };
        d.detail = Some(format!(
            "{evidence}; class by {}",
            class_rule_text(class_rule)
        ));
        for note in [why, self.data_note(j)].into_iter().flatten() {
            append_detail(&mut d, note);
        }
        out.push(d);
        let st = &mut self.actuators[j];
        st.health = Health::Fault(class);
        st.decided_filters = filters;
        st.class_from_data = class_rule == Rule::C1;
        st.class_mixed = mixed;
        st.class_candidate = None;
        st.stronger_since = None;
        st.decided_at = t;
        st.decided_by = Some(rule);
    }
    /// A fault in force: R1 clears it; otherwise a class read anew replaces the one in force
    /// once it has held `CLASS_HOLD_S`, the data's class outranking the filters'.
    pub(super) fn in_force(
        &mut self,
        t: f64,
        j: usize,
        prev: FaultClass,
        data_alarm: Option<usize>,
        out: &mut Vec<Decision>,
    ) {
        let st = &self.actuators[j];
        let alarms = st.alarms();
        // (The data naming the actuator do not hold the fault: after its end the store still
        // holds it, and its end is a change too. A data alarm needs a change that began inside
        // the store, which the end of a fault is not.)
        // A fault the data alone decided (F3) stands until they have not named it clearly
        // for `clear_s`, as a filter's alarm ends (once it is in force the whitened search
        // gives way to the plain one, which may lose it for a moment while the fault's start
        // and the manoeuvres after it share the store).
        let data_hold =
            st.decided_by == Some(Rule::F3) && t - st.data_named_at < self.params.clear_s;
        // Nor, for an angle output, while the MIT-UKF's bounds still show a fault by the class
        // definitions: near trim a surface's or servo's loss moves the output too little for
        // an alarm to last, while its gain stays known to be off. (A range output works far
        // from zero, where a gain's fault is in the deviation itself.)
        let shown = self.is_angle[j] && self.filter_shows_fault(j);
        if alarms == 0 && data_alarm != Some(j) && !data_hold && !shown {
            let mut d = self.decision(t, j, Event::Cleared, None, 0, Rule::R1);
            d.detail = Some(format!(
                "no filter alarm for {} s and no data alarm",
                self.params.clear_s
            ));
            out.push(d);
            let st = &mut self.actuators[j];
            st.health = Health::Healthy;
            st.class_candidate = None;
            return;
        }
        let (class, rule, mixed, _) = self.classify(j);
        // A class in force changes only on evidence of the fault as it is now: the filters'
        // (C2) while the attributed deviation is still beyond its threshold (under it, the
        // output is back at the operating point and the fault is ending), the data's (C1) on a
        // change dated inside the store (a fit over the whole store may be of the recovery's
        // transient). The data's class stands against the filters' while the data still fit
        // this actuator best; a mixed reading or none changes nothing but an open class; a
        // filter warming up after a reset says nothing.
        let p = &self.params;
        let ch = &st.channels[0];
        let visible =
            ch.e.hypot(ch.excursion) >= p.threshold || ch.gain_gap.abs() >= p.gain_threshold;
        let dated = self
            .reading
            .is_some_and(|r| r.actuator == j && r.samples < self.change.len());
        let current = prev == FaultClass::Unclassified
            || match rule {
                // (A drift is read on the store's own stretch: it is the fault as it is now.)
                Rule::C1 => dated || class == FaultClass::Drift,
                _ => visible,
            };
        let ukf_warming = t < ch.hold_until;
        let data_still = st.class_from_data
            && rule != Rule::C1
            && self
                .reading
                .is_some_and(|r| r.actuator == j && -r.margin_over(r.mixed_drop) < DATA_MARGIN);
        let keep = class == FaultClass::Unclassified
            || (mixed && prev != FaultClass::Unclassified)
            || !current
            || ukf_warming
            || data_still;
        let mut next = if keep { prev } else { class };
        if next != prev {
            let st = &mut self.actuators[j];
            let since = match st.class_candidate {
                Some((c, since)) if c == next => since,
                _ => {
                    st.class_candidate = Some((next, t));
                    t
                }
            };
            if t - since < CLASS_HOLD_S && prev != FaultClass::Unclassified {
                next = prev;
            }
        } else {
            let st = &mut self.actuators[j];
            st.class_candidate = None;
            // The class in force read again, on current evidence, by a stronger rule (the
            // data's class outranks the filters', a told kind the mixed fallback) for
            // `CLASS_HOLD_S`, as a new class must hold: it is that rule's from then on, so what
            // follows the class (the filters' identification) follows the stronger reading.
            let by_data = rule == Rule::C1 && !st.class_from_data;
            let told = rule == Rule::C2 && !mixed && st.class_mixed;
            if class == prev && current && !ukf_warming && (by_data || told) {
                let since = *st.stronger_since.get_or_insert(t);
                if t - since >= CLASS_HOLD_S {
                    st.class_from_data |= by_data;
                    st.class_mixed = false;
                    st.stronger_since = None;
                }
            } else {
                st.stronger_since = None;
            }
        }
        let union = self.actuators[j].decided_filters | alarms;
        if next != prev || union != self.actuators[j].decided_filters {
            let mut d = self.decision(t, j, Event::Changed, Some(next), union, Rule::K1);
            d.also = self.also(j);
            if next != prev {
                d.detail = Some(format!("class by {}", class_rule_text(rule)));
            }
            if let Some(note) = self.data_note(j) {
                append_detail(&mut d, note);
            }
            out.push(d);
            let st = &mut self.actuators[j];
            st.health = Health::Fault(next);
            st.decided_filters = union;
            if next != prev {
                st.class_from_data = rule == Rule::C1;
                st.class_mixed = mixed;
                st.stronger_since = None;
            }
        }
    }
    /// The other actuators alarmed by either filter, by name.
    pub(super) fn also(&self, j: usize) -> Vec<String> {
        (0..self.actuators.len())
            .filter(|&k| k != j && self.actuators[k].alarms() != 0)
            .map(|k| self.names[k].clone())
            .collect()
    }
    pub(super) fn decision(
        &self,
        t: f64,
        j: usize,
        event: Event,
        class: Option<FaultClass>,
        filters: u8,
        rule: Rule,
    ) -> Decision {
        let st = &self.actuators[j];
        // The numbers are the MIT-UKF's: the point estimate with its bounds. The MIT-ESMF's set
        // on a vehicle mostly sits at its a priori box; its set is in the estimates.
        let e = st.channels[0].last;
        let together = st.channels.iter().all(|c| c.alarm)
            && (st.channels[0].alarm_since - st.channels[1].alarm_since).abs()
                <= self.params.agree_s;
        let filter_bits = filters;
        let filters: Vec<&'static str> = (0..2)
            .filter(|f| filters & (1 << f) != 0)
            .map(|f| FILTER_NAMES[f])
            .collect();
        let confidence = match (filters.len(), rule) {
            (0, Rule::F3) => 0.6,
            (0, _) => 0.0,
            (1, _) => 0.6,
            _ if together => 0.9,
            _ => 0.75,
        };
        // The numbers behind the filters' alarm: the statistic standing highest against its
        // threshold among the filters alarming now (the alarm is a CUSUM: the value, of this
        // step, may stand under its threshold while the alarm holds).
        let p = &self.params;
        let evidence = (0..2)
            .filter(|&f| filter_bits & (1 << f) != 0 && st.channels[f].alarm)
            .map(|f| {
                let ch = &st.channels[f];
                let deviation = ch.e.hypot(ch.excursion);
                let (statistic, value, threshold) =
                    if deviation / p.threshold >= ch.gain_gap.abs() / p.gain_threshold {
                        ("deviation", deviation, p.threshold)
                    } else {
                        ("gain_gap", ch.gain_gap.abs(), p.gain_threshold)
                    };
                Evidence {
                    filter: FILTER_NAMES[f],
                    statistic,
                    value,
                    threshold,
                }
            })
            .filter(|e| e.value.is_finite() && e.threshold.is_finite())
            .max_by(|a, b| (a.value / a.threshold).total_cmp(&(b.value / b.threshold)));
        Decision {
            t,
            sysid: self.sysid,
            event,
            actuator: Some(self.names[j].clone()),
            channel: Some(self.channels[j]),
            class,
            gamma: Some(e.gamma),
            delta: Some(e.delta),
            gamma_bounds: Some([e.gamma_lo, e.gamma_hi]),
            delta_bounds: Some([e.delta_lo, e.delta_hi]),
            deviation: Some(st.channels[0].e),
            filters,
            confidence,
            also: vec![],
            rule: Some(rule),
            in_crash: false,
            evidence,
            detail: None,
        }
    }
}

fn class_rule_text(rule: Rule) -> &'static str {
    match rule {
        Rule::C1 => "the data (C1)",
        Rule::C2 => "the MIT-UKF's gain and bias (C2)",
        _ => "none yet (C3)",
    }
}

pub(super) fn append_detail(d: &mut Decision, note: String) {
    d.detail = Some(match d.detail.take() {
        Some(s) => format!("{s}; {note}"),
        None => note,
    });
}
