//! The alert component's tests: texts, rate limits, queues, value names, AHC_ESTIMATE.

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
    assert_eq!(text, "ahcmon: swash2 LOE 41% UKF+ESMF");
    assert_eq!(sev, MavSeverity::MAV_SEVERITY_CRITICAL);
    // A long name gives way, the class and the filters stay; bytes, not characters, and
    // never half a character.
    d.actuator = Some("a_very_long_actuator_name_that_goes_on_and_on".into());
    let (_, text) = statustext(&d).unwrap();
    assert!(text.len() <= 50, "{text}");
    assert!(text.starts_with("ahcmon: a_very_long") && text.ends_with(" LOE 41% UKF+ESMF"));
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
    assert_eq!(text, "ahcmon: motor5 bias +12% UKF+ESMF");
    assert_eq!(sev, MavSeverity::MAV_SEVERITY_ERROR);
    // An actuator the model cannot judge (G2) is no fault, but the planner is told it is not
    // monitored; the other statements stay off the planner.
    let mut d = Decision::monitor(1.0, 1, Event::CannotJudge, "");
    d.actuator = Some("rudder".into());
    let (sev, text) = statustext(&d).unwrap();
    assert_eq!(text, "ahcmon: rudder cannot judge");
    assert_eq!(sev, MavSeverity::MAV_SEVERITY_WARNING);
    d.event = Event::ExcitationLow;
    assert!(statustext(&d).is_none());
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
    a.on_estimates(1.0, 1, &[&est, &est, &est], &p);
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
    a.on_estimates(2.0, 1, &[&est6, &est6, &est6], &hexa);
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
    assert_eq!(texts(&a), vec!["ahcmon: swash2 LOE 16% UKF"]);
    est[1].gamma = 0.69;
    // Too soon after the last text: not yet.
    a.on_estimates(45.0, 1, &[&est, &est, &est], &p);
    assert_eq!(texts(&a).len(), 1);
    a.on_estimates(47.5, 1, &[&est, &est, &est], &p);
    assert_eq!(texts(&a)[1], "ahcmon: swash2 LOE 31% UKF");
    // Within 10 points of the new size: nothing more.
    est[1].gamma = 0.62;
    a.on_estimates(60.0, 1, &[&est, &est, &est], &p);
    assert_eq!(texts(&a).len(), 2);
    assert_eq!(a.texts_resized, 1);
    // Cleared: its size is not told again.
    a.on_decision(&decision(Event::Cleared, "swash2", None));
    est[1].gamma = 0.3;
    a.on_estimates(70.0, 1, &[&est, &est, &est], &p);
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
    d.gamma = Some(if k.is_multiple_of(2) { 0.5 } else { 0.4 });
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
        q.iter().any(|x| x.text.starts_with("ahcmon: motor2 LOE")),
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
        q.iter().any(|x| x.text.starts_with("ahcmon: motor2 stuck")),
        "{q:?}"
    );
    // Sent in order, the planner's last text about motor1 says it cleared.
    let mut last = None;
    for k in 1..=40 {
        a.tick(k as f64 * TEXT_INTERVAL_S);
    }
    assert!(a.text_queue[&1].is_empty());
    for frame in a.outbox.drain(..) {
        if let crate::protocol::frame::Parsed::Frame(f, _) = crate::protocol::frame::parse(&frame)
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
    a.on_estimates(1.0, 1, &[&est[..4], &est[..4], &est[..4]], &quad);
    a.on_estimates(1.0, 2, &[&est[..3], &est[..3], &est[..3]], &plane);
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
fn ahc_estimate_sends_the_probable_and_the_guaranteed_bounds_and_nan_where_not_excited() {
    use crate::protocol::frame::{Parsed, parse};
    let quad = Profile::resolve("quad-x").unwrap();
    let mut ukf = [AhcEstimate::default(); 4];
    let mut esmf = [AhcEstimate::default(); 4];
    let mut set = [AhcEstimate::default(); 4];
    for j in 0..4 {
        let x = j as f64;
        ukf[j] = AhcEstimate {
            gamma: 0.9 - 0.01 * x,
            gamma_lo: 0.8,
            gamma_hi: 1.0,
            delta: 0.01,
            delta_lo: -0.02,
            delta_hi: 0.04,
            // Variances of gamma 0.01², delta 0.02², uncorrelated.
            block: [1e-4, 0.0, 4e-4],
            ..AhcEstimate::default()
        };
        // Not sent: the MIT-ESMF is a detector, not the guaranteed bound.
        esmf[j].gamma = 7.0;
        set[j] = AhcEstimate {
            gamma: 0.7 + 0.01 * x,
            gamma_lo: 0.5,
            gamma_hi: 0.95,
            delta: -0.03,
            delta_lo: -0.1,
            delta_hi: 0.05,
            unexcited: [j == 1, j == 2],
            output_bounds: (j != 3).then_some([-0.2, -0.1]),
            command_ref: 0.5,
            ..AhcEstimate::default()
        };
    }
    let mut a = Alerts::default();
    a.on_estimates(2.0, 1, &[&ukf, &esmf, &set], &quad);
    a.tick(2.0);
    let mut sent = Vec::new();
    for frame in &a.outbox {
        if let Parsed::Frame(f, _) = parse(frame)
            && let MavMessage::AHC_ESTIMATE(m) = f.msg
        {
            sent.push(m);
        }
    }
    sent.sort_by_key(|m| m.actuator);
    assert_eq!(sent.len(), 4);
    for (j, m) in sent.iter().enumerate() {
        let x = j as f32;
        assert_eq!(m.ukf_gamma, 0.9 - 0.01 * x);
        assert_eq!([m.ukf_gamma_lo, m.ukf_gamma_hi], [0.8, 1.0]);
        assert_eq!(m.set_unexcited, u8::from(j == 1) | u8::from(j == 2) << 1);
        let gamma = [m.set_gamma, m.set_gamma_lo, m.set_gamma_hi];
        let delta = [m.set_delta, m.set_delta_lo, m.set_delta_hi];
        if j == 1 {
            assert!(gamma.iter().all(|v| v.is_nan()), "{m:?}");
        } else {
            assert_eq!(gamma, [(0.7 + 0.01 * j as f64) as f32, 0.5, 0.95]);
        }
        if j == 2 {
            assert!(delta.iter().all(|v| v.is_nan()), "{m:?}");
        } else {
            assert_eq!(delta, [-0.03, -0.1, 0.05]);
        }
        // The output at the set's recent command: the set's guaranteed bounds (NaN where not
        // excited) beside the MIT-UKF's probable ones, (γ - 1) u + δ ± 3 sd(γ u + δ).
        assert_eq!(m.command_ref, 0.5);
        if j == 3 {
            assert!(
                m.set_output_lo.is_nan() && m.set_output_hi.is_nan(),
                "{m:?}"
            );
        } else {
            assert_eq!([m.set_output_lo, m.set_output_hi], [-0.2, -0.1]);
        }
        let centre = (0.9 - 0.01 * j as f64 - 1.0) * 0.5 + 0.01;
        let sd = (0.25f64 * 1e-4 + 4e-4).sqrt();
        for (sent, want) in [m.ukf_output_lo, m.ukf_output_hi]
            .into_iter()
            .zip([centre - 3.0 * sd, centre + 3.0 * sd])
        {
            assert!((f64::from(sent) - want).abs() < 1e-6, "{m:?}");
        }
    }
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
            "ahcmon: motor5 stuck UKF",
            "ahcmon: motor5 cleared",
            "ahcmon: motor5 stuck UKF",
            "ahcmon: motor6 stuck UKF",
            "ahcmon: motor6 stuck UKF"
        ]
    );
}
