//! The matrix's scoring on hand-made runs, and its cases.

use super::*;

fn decision(t: f64, event: Event, actuator: &str, class: Option<&str>) -> Decision {
    let mut d = Decision::monitor(t, 1, event, "");
    d.actuator = Some(actuator.into());
    d.class = class.map(|c| match c {
        "bias" => crate::diagnose::vehicle::FaultClass::Bias,
        _ => crate::diagnose::vehicle::FaultClass::LossOfEffectiveness,
    });
    d
}

fn collect(decisions: Vec<Decision>) -> Collect {
    Collect {
        target: Some(1),
        decisions,
        estimates: vec![(
            60.0,
            AhcEstimate {
                gamma: 0.55,
                delta: 0.02,
                ..Default::default()
            },
        )],
        first_estimate: Some(33.0),
        last_estimate: 65.0,
    }
}

/// The scoring on hand-made decisions: delays from the onset on the vehicle's clock, the
/// class in force 5 s after the decision, a wrong actuator counted, one before the onset
/// false.
#[test]
fn scoring_of_a_hand_made_run() {
    let case = Case {
        vehicle: "quad-x",
        fault: Some(("motor2".into(), FaultKind::Loss050)),
        flight: Flight::Steady,
        weather: Weather::Builtin,
        seed: 1,
        duration_s: FAULT_FLIGHT_S,
    };
    let onset = ONSET_S + BOOT_OFFSET_S;
    let sink = collect(vec![
        decision(onset - 3.0, Event::Fault, "motor1", Some("bias")),
        decision(onset + 0.5, Event::Fault, "motor2", Some("bias")),
        decision(onset + 1.5, Event::Changed, "motor2", Some("loss")),
        decision(onset + 2.0, Event::Fault, "motor3", Some("bias")),
        decision(onset + 7.0, Event::Changed, "motor2", Some("bias")),
    ]);
    let truth = [(onset + 5.5, 0.5, 0.0)];
    let r = score(&case, true, Some(100.0), &sink, &truth, &[100.0]);
    assert_eq!(r.false_before_onset, 1);
    assert_eq!(r.first, Some(("motor2".into(), 0.5)));
    assert_eq!(r.named_after_s, Some(0.5));
    assert_eq!(r.wrong_actuator, 1);
    assert_eq!(r.class.as_deref(), Some("loss_of_effectiveness"));
    assert_eq!(r.class_right, Some(true));
    assert_eq!(r.class_separable, Some(true));
    assert!((r.gamma_error.unwrap() - 0.05).abs() < 1e-12);
    assert_eq!(r.detectable, Some(true));
    let rows = report(std::slice::from_ref(&r));
    let all = rows.iter().find(|x| x.vehicle == "all" && x.kind == "all");
    let all = all.unwrap();
    assert_eq!(
        (all.detectable, all.named_right, all.class_right),
        (1, 1, 1)
    );
    assert_eq!(all.estimate_right, 1);
    assert_eq!((all.class_separable, all.class_right_separable), (1, 1));
    // A class the oracle cannot separate is right still, but not among the separable.
    let r = score(
        &case,
        true,
        Some(100.0),
        &sink,
        &truth,
        &[DETECTABLE_LAMBDA * 0.9],
    );
    assert_eq!(r.class_separable, Some(false));
    let rows = report(&[r]);
    let all = rows.iter().find(|x| x.vehicle == "all" && x.kind == "all");
    let all = all.unwrap();
    assert_eq!(all.class_right, 1);
    assert_eq!((all.class_separable, all.class_right_separable), (0, 0));
    // Below the oracle's level the same run counts as an undetectable wrong decision.
    let r = score(
        &case,
        true,
        Some(DETECTABLE_LAMBDA * 0.9),
        &sink,
        &truth,
        &[100.0],
    );
    let rows = report(&[r]);
    let all = rows.iter().find(|x| x.vehicle == "all" && x.kind == "all");
    assert_eq!(
        all.map(|x| (x.detectable, x.undetectable_wrong)),
        Some((0, 1))
    );
}

#[test]
fn the_fast_subset_and_the_whole_matrix() {
    let spec = |fast| MatrixSpec {
        seeds: 2,
        first_seed: 1,
        healthy_s: 60.0,
        fast,
        vehicles: vec![],
    };
    let all = cases(&spec(false)).unwrap();
    // 21 actuators × 6 kinds + 5 healthy, × 2 flights × 2 weathers × 2 seeds.
    assert_eq!(all.len(), (21 * 6 + 5) * 2 * 2 * 2);
    let fast = cases(&spec(true)).unwrap();
    assert_eq!(fast.len(), (21 * 2 + 5) * 2);
    for c in &all {
        c.named(0.3).unwrap();
    }
}
