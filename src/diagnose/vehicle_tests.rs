//! One test per rule of `docs/diagnosis.md`: each fails when its rule is taken out.

use super::*;
use crate::sim::rng::Rng;

const DT: f64 = 0.02;

/// An actuator's effective-output change at (t, commands): which actuator, by how much.
type Change<'a> = &'a dyn Fn(f64, &[f64]) -> (usize, f64);

/// A healthy actuator's estimate: gamma 1 ± 0.1, delta 0 ± `delta_half`.
fn healthy(delta_half: f64) -> AhcEstimate {
    AhcEstimate {
        gamma: 1.0,
        gamma_lo: 0.9,
        gamma_hi: 1.1,
        delta_lo: -delta_half,
        delta_hi: delta_half,
        block: [0.0025, 0.0, 0.0004],
        ..Default::default()
    }
}

fn estimate(gamma: f64, g_half: f64, delta: f64, d_half: f64) -> AhcEstimate {
    AhcEstimate {
        gamma,
        gamma_lo: gamma - g_half,
        gamma_hi: gamma + g_half,
        delta,
        delta_lo: delta - d_half,
        delta_hi: delta + d_half,
        block: [(g_half / 3.0).powi(2), 0.0, (d_half / 3.0).powi(2)],
        ..Default::default()
    }
}

/// Healthy estimates of `n` actuators, and from `from` s on the given actuators' instead.
fn faulted(
    n: usize,
    from: f64,
    faults: &[(usize, AhcEstimate)],
) -> impl Fn(f64) -> Vec<AhcEstimate> + use<> {
    let faults = faults.to_vec();
    move |t| {
        let mut e = vec![healthy(0.02); n];
        if t >= from {
            for &(j, f) in &faults {
                e[j] = f;
            }
        }
        e
    }
}

/// A flight of `seconds`: per step the commands, both filters' estimates and, where given,
/// the change of one actuator's effective output (for the healthy model's residual, with
/// white noise of 0.3 per weighted row).
struct Flight {
    profile: Profile,
    d: Diagnoser,
    rng: Rng,
    effects: Vec<[f64; 4]>,
    weights: [f64; 4],
    decisions: Vec<Decision>,
}

impl Flight {
    fn new(profile: &str) -> Self {
        let p = Profile::resolve(profile).unwrap();
        Self {
            d: Diagnoser::new(DiagnosisParams::default(), 1, &p, DT),
            effects: crate::estimate::vehicle::weighted_effects(&p, DT),
            weights: crate::estimate::vehicle::residual_weights(&p, DT),
            profile: p,
            rng: Rng::new(3),
            decisions: vec![],
        }
    }

    /// Steps from `from` to `to` (s).
    fn fly(
        &mut self,
        from: f64,
        to: f64,
        u: impl Fn(f64) -> Vec<f64>,
        est: impl Fn(f64) -> Vec<AhcEstimate>,
        change: Option<Change>,
    ) {
        let mut out = vec![];
        let steps = ((to - from) / DT).round() as usize;
        for k in 0..steps {
            let t = from + k as f64 * DT;
            let u = u(t);
            if let Some(change) = change {
                let (j, s) = change(t, &u);
                let mut residual = [0.0; 4];
                for (i, r) in residual.iter_mut().enumerate() {
                    if self.weights[i] > 0.0 {
                        *r = (self.effects[j][i] * s + 0.3 * self.rng.normal()) / self.weights[i];
                    }
                }
                self.d.observe(t, &residual, &u);
            }
            let e = est(t);
            self.d.update(t, &u, &[&e, &e], &mut out);
            self.decisions.append(&mut out);
        }
    }

    fn events(&self, event: Event) -> Vec<&Decision> {
        (self.decisions.iter())
            .filter(|d| d.event == event)
            .collect()
    }

    /// The class of the last decision that has one.
    fn last_class(&self) -> Option<FaultClass> {
        self.decisions.iter().rev().find_map(|d| d.class)
    }

    fn n(&self) -> usize {
        self.profile.actuators.len()
    }
}

fn dithered(n: usize, mean: f64, amp: f64) -> impl Fn(f64) -> Vec<f64> {
    move |t| {
        (0..n)
            .map(|i| mean + amp * (t * (2.0 + i as f64)).sin())
            .collect()
    }
}

#[test]
fn s1_bounds_excluding_the_healthy_point_make_a_suspect_and_r1_clears_it() {
    // Quad X, motor 2 reads gamma 0.97 ± 0.02 from 8 s to 14 s: no alarm (the deviation is
    // under the threshold) but the healthy gain is outside its bounds.
    let mut f = Flight::new("quad-x");
    let n = f.n();
    let est = |t: f64| {
        let mut e = vec![healthy(0.02); n];
        if (8.0..14.0).contains(&t) {
            e[1] = estimate(0.97, 0.02, 0.0, 0.02);
        }
        e
    };
    f.fly(0.0, 20.0, dithered(n, 0.5, 0.04), est, None);
    let suspect = f.events(Event::Suspect);
    assert_eq!(suspect.len(), 1, "{:?}", f.decisions);
    assert_eq!(suspect[0].rule, Some(Rule::S1));
    assert!((suspect[0].t - 10.0).abs() < 0.1, "{suspect:?}");
    let back = f.events(Event::SuspectCleared);
    assert!(
        back.len() == 1 && (back[0].t - 16.0).abs() < 0.1,
        "{back:?}"
    );
    assert!(f.events(Event::Fault).is_empty());
}

/// Hexa X, motor 5 stuck at 0.62 from 8 s while its command moves about 0.5; the filters
/// spread it over opposite motor 6's and motor 2's gains (they hold a motor's offset near
/// zero), the healthy model's residuals carry motor 5's real effect.
fn hexa_motor5_stuck(with_data: bool) -> Flight {
    let mut f = Flight::new("hexa-x");
    let est = |t: f64| {
        let mut e = vec![healthy(0.02); 6];
        if t >= 8.0 {
            e[5] = estimate(0.75, 0.05, 0.0, 0.02);
            e[1] = estimate(0.8, 0.05, 0.0, 0.02);
        }
        e
    };
    let change = |t: f64, u: &[f64]| (4usize, if t >= 8.0 { 0.62 - u[4] } else { 0.0 });
    f.fly(
        0.0,
        14.0,
        dithered(6, 0.5, 0.04),
        est,
        with_data.then_some(&change as Change),
    );
    f
}

#[test]
fn s2_c1_an_alarm_the_data_put_on_another_motor_is_that_motors_evidence() {
    let f = hexa_motor5_stuck(true);
    let faults: Vec<_> = (f.decisions.iter())
        .filter(|d| matches!(d.event, Event::Fault | Event::Changed))
        .collect();
    assert!(!faults.is_empty(), "{:?}", f.decisions);
    // Motor 2's alarm is suspect (S2) and listed with motor 5's fault, never decided.
    assert!(
        faults
            .iter()
            .all(|d| d.actuator.as_deref() == Some("motor5")),
        "{faults:?}"
    );
    assert!(
        f.events(Event::Suspect)
            .iter()
            .any(|d| d.actuator.as_deref() == Some("motor2") && d.rule == Some(Rule::S2)),
        "{:?}",
        f.decisions
    );
    assert!(faults.iter().any(|d| d.also.iter().any(|a| a == "motor2")));
    // Decided on the data's actuator, classed stuck by the data.
    assert!(
        matches!(faults[0].rule, Some(Rule::F1 | Rule::F3)),
        "{faults:?}"
    );
    let last = faults.last().unwrap();
    assert_eq!(last.class, Some(FaultClass::Stuck), "{faults:?}");
    // Without the residuals the filters' reading is decided after the wait (F2).
    let without = hexa_motor5_stuck(false);
    let first = without.events(Event::Fault);
    assert_eq!(first[0].actuator.as_deref(), Some("motor6"));
    assert_eq!(first[0].rule, Some(Rule::F2));
}

#[test]
fn f1_an_alarm_the_data_fit_best_is_decided_at_once_and_f2_waits_without_them() {
    // Quad X, motor 2 at gamma 0.6 from 8 s, in the estimates and in the data.
    let run = |with_data: bool| {
        let mut f = Flight::new("quad-x");
        let est = |t: f64| {
            let mut e = vec![healthy(0.02); 4];
            if t >= 8.0 {
                e[1] = estimate(0.6, 0.05, 0.0, 0.02);
            }
            e
        };
        let change = |t: f64, u: &[f64]| (1usize, if t >= 8.0 { -0.4 * u[1] } else { 0.0 });
        f.fly(
            0.0,
            14.0,
            dithered(4, 0.5, 0.04),
            est,
            with_data.then_some(&change as Change),
        );
        // One decision that stands while the data name it (no clearing and deciding again).
        assert!(f.events(Event::Fault).len() <= 1, "{:?}", f.decisions);
        assert!(f.events(Event::Cleared).is_empty(), "{:?}", f.decisions);
        f.events(Event::Fault)
            .first()
            .map(|d| (d.t, d.rule, d.actuator.clone()))
    };
    let (t, rule, who) = run(true).expect("decided");
    assert_eq!((rule, who.as_deref()), (Some(Rule::F1), Some("motor2")));
    assert!(t < 8.5, "{t}");
    let (t, rule, _) = run(false).expect("decided");
    assert_eq!(rule, Some(Rule::F2));
    assert!(t >= 8.0 + DATA_WAIT_S, "{t}");
}

#[test]
fn c2_c3_the_filters_class_needs_bounds_that_tell_and_a_command_that_moves() {
    let first_class = |est: AhcEstimate, amp: f64| {
        let mut f = Flight::new("plane");
        let e = move |t: f64| {
            let mut e = vec![healthy(0.02); 3];
            if t >= 8.0 {
                e[1] = est;
            }
            e
        };
        f.fly(0.0, 16.0, dithered(3, 0.1, amp), e, None);
        let d = f.events(Event::Fault).first().cloned().cloned();
        d.map(|d| (d.class, d.detail.unwrap_or_default()))
    };
    // A gain known to be 0.5, offset within tolerance: a loss.
    let (c, _) = first_class(estimate(0.5, 0.05, 0.0, 0.02), 0.08).unwrap();
    assert_eq!(c, Some(FaultClass::LossOfEffectiveness));
    // An offset known to be +0.2 with the gain within tolerance: a bias.
    let (c, _) = first_class(estimate(1.0, 0.05, 0.2, 0.02), 0.08).unwrap();
    assert_eq!(c, Some(FaultClass::Bias));
    // Both beyond their tolerances (gain 0.75 within [0.63, 0.87], offset -0.06 excluding
    // 0): not a bias because the gain's bounds still reach 0.85, but mixed, and the output
    // moved toward zero by less than the command, so a loss.
    let (c, _) = first_class(estimate(0.75, 0.12, -0.06, 0.009), 0.08).unwrap();
    assert_eq!(c, Some(FaultClass::LossOfEffectiveness));
    // The offset of +0.2 with a gain whose bounds span 0.4 to 1.6: the bounds tell nothing.
    let (c, why) = first_class(estimate(1.0, 0.6, 0.2, 0.02), 0.08).unwrap();
    assert_eq!(c, Some(FaultClass::Unclassified), "{why}");
    assert!(why.contains("C3"), "{why}");
    // A command standing still: no class, and the reason names the excitation.
    let (c, why) = first_class(estimate(1.0, 0.05, 0.2, 0.02), 0.0).unwrap();
    assert_eq!(c, Some(FaultClass::Unclassified));
    assert!(why.contains("not separable"), "{why}");
}

#[test]
fn r1_a_fault_clears_when_its_alarm_ends() {
    let mut f = Flight::new("plane");
    let est = |t: f64| {
        let mut e = vec![healthy(0.02); 3];
        if (8.0..14.0).contains(&t) {
            e[0] = estimate(1.0, 0.05, 0.2, 0.02);
        }
        e
    };
    f.fly(0.0, 20.0, dithered(3, 0.0, 0.08), est, None);
    let fault = f.events(Event::Fault);
    let cleared = f.events(Event::Cleared);
    assert_eq!((fault.len(), cleared.len()), (1, 1), "{:?}", f.decisions);
    assert_eq!(cleared[0].rule, Some(Rule::R1));
    // Two seconds under half the threshold after the estimates went back.
    assert!((cleared[0].t - 16.0).abs() < 0.1, "{cleared:?}");
}

#[test]
fn g1_a_command_that_does_not_move_is_said_once() {
    let mut f = Flight::new("quad-x");
    f.fly(
        0.0,
        12.0,
        |_| vec![0.5; 4],
        |_| vec![healthy(0.02); 4],
        None,
    );
    let low = f.events(Event::ExcitationLow);
    assert_eq!(low.len(), 4, "{low:?}");
    assert!(low.iter().all(|d| d.rule == Some(Rule::G1)));
    assert!(f.events(Event::Fault).is_empty());
}

#[test]
fn k1_a_class_changes_only_once_held_and_while_the_fault_shows() {
    // Plane aileron: a bias from 8 s; from 12 s the MIT-UKF reads a loss instead. While the
    // deviation stays beyond the threshold the loss replaces the bias after CLASS_HOLD_S; a
    // loss read once the output is back within the threshold is the recovery's and does not.
    let run = |visible: bool| {
        let mut f = Flight::new("plane");
        let est = move |t: f64| {
            let mut e = vec![healthy(0.02); 3];
            if t >= 12.0 {
                // u ≈ 0.3: gamma 0.5 moves the output by -0.15 (visible), gamma 0.9 by -0.03.
                e[0] = if visible {
                    estimate(0.5, 0.05, 0.0, 0.02)
                } else {
                    estimate(0.8, 0.03, 0.0, 0.02)
                };
            } else if t >= 8.0 {
                e[0] = estimate(1.0, 0.05, 0.2, 0.02);
            }
            e
        };
        f.fly(0.0, 16.0, dithered(3, 0.3, 0.02), est, None);
        f.events(Event::Changed)
            .iter()
            .filter(|d| d.class == Some(FaultClass::LossOfEffectiveness))
            .map(|d| d.t)
            .next()
    };
    let t = run(true).expect("the loss replaces the bias");
    assert!(
        (12.0 + CLASS_HOLD_S - 0.05..12.0 + CLASS_HOLD_S + 0.3).contains(&t),
        "{t}"
    );
    assert_eq!(run(false), None);
}

#[test]
fn k1_a_class_the_data_read_again_is_theirs_and_their_fit_is_followed() {
    // Plane aileron, an offset of +0.2 from 8 s in the data; the MIT-UKF reads it as a gain of
    // 1.3 instead (the trade along γ u + δ), so the fault is decided on the filters' mixed
    // fallback, a bias, before the data have the second they need for a class. Once they
    // read the same bias clearly, the class is theirs, and the filters follow their fit.
    let mut f = Flight::new("plane");
    let est = |t: f64| {
        let mut e = vec![healthy(0.02); 3];
        if t >= 8.0 {
            e[0] = estimate(1.3, 0.05, 0.0, 0.02);
        }
        e
    };
    let change = |t: f64, _: &[f64]| (0usize, if t >= 8.0 { 0.2 } else { 0.0 });
    f.fly(0.0, 12.0, dithered(3, 0.5, 0.08), est, Some(&change));
    let faults = f.events(Event::Fault);
    assert_eq!(faults.len(), 1, "{:?}", f.decisions);
    assert_eq!(faults[0].class, Some(FaultClass::Bias));
    assert!(faults[0].t < 9.0, "{:?}", faults[0]);
    let detail = faults[0].detail.clone().unwrap_or_default();
    assert!(detail.contains("(C2)"), "{detail}");
    assert!(f.events(Event::Changed).is_empty(), "{:?}", f.decisions);
    let id = f.d.identified(0).expect("the data's bias is followed");
    assert_eq!(id.kind, IdentifiedKind::Offset);
    assert!((id.delta - 0.2).abs() < 0.02, "{id:?}");
    assert_eq!(id.gamma, 1.0);
}

#[test]
fn c1_a_motors_gain_weakening_under_a_thrust_holding_controller_is_a_drift() {
    // Quad X motor 1's gain ramps from 1 by -0.05 a second from 8 s; the controller holds its
    // thrust, so its command rises as 0.5 / gamma (with its dither) and its output stays at
    // 0.5: read as a step, the data's best kind is a stuck output. The residual's ramp beats
    // the step: a drift.
    let mut f = Flight::new("quad-x");
    let gamma = |t: f64| {
        if t >= 8.0 {
            1.0 - 0.05 * (t - 8.0)
        } else {
            1.0
        }
    };
    let dither = dithered(4, 0.0, 0.03);
    let u = move |t: f64| {
        let mut u: Vec<f64> = dither(t).iter().map(|d| 0.5 + d).collect();
        u[0] = 0.5 / gamma(t) + u[0] - 0.5;
        u
    };
    let est = move |t: f64| {
        let mut e = vec![healthy(0.02); 4];
        if t >= 9.0 {
            e[0] = estimate(gamma(t), 0.05, 0.0, 0.02);
        }
        e
    };
    let change = move |t: f64, u: &[f64]| (0usize, (gamma(t) - 1.0) * u[0]);
    f.fly(0.0, 14.0, u, est, Some(&change));
    let classed: Vec<_> = (f.decisions.iter())
        .filter(|d| matches!(d.event, Event::Fault | Event::Changed))
        .collect();
    let last = classed.last().expect("decided");
    assert_eq!(last.actuator.as_deref(), Some("motor1"), "{classed:?}");
    assert_eq!(last.class, Some(FaultClass::Drift), "{classed:?}");
}

#[test]
fn c1_a_ramp_back_toward_the_healthy_output_is_no_drift() {
    // Plane aileron: an offset of +0.3 from 2 s, which from 9 s eases back by 0.04 a second
    // (the fault's end, or the wind's slow part): the store then holds a ramp, but one toward
    // the healthy output. The bias stays; the same ramp away from it is a drift.
    let run = |away: bool| {
        let mut f = Flight::new("plane");
        let sign = if away { 1.0 } else { -1.0 };
        let offset = move |t: f64| {
            if t < 2.0 {
                0.0
            } else {
                0.3 + sign * 0.04 * (t - 9.0).max(0.0)
            }
        };
        let est = move |t: f64| {
            let mut e = vec![healthy(0.02); 3];
            if t >= 2.0 {
                e[0] = estimate(1.0, 0.05, offset(t), 0.02);
            }
            e
        };
        let change = move |t: f64, _: &[f64]| (0usize, offset(t));
        f.fly(0.0, 16.0, dithered(3, 0.3, 0.02), est, Some(&change));
        (f.decisions.iter())
            .filter(|d| matches!(d.event, Event::Fault | Event::Changed))
            .filter_map(|d| d.class)
            .collect::<Vec<_>>()
    };
    let toward = run(false);
    assert_eq!(toward.first(), Some(&FaultClass::Bias), "{toward:?}");
    assert!(!toward.contains(&FaultClass::Drift), "{toward:?}");
    let away = run(true);
    assert!(away.contains(&FaultClass::Drift), "{away:?}");
}

#[test]
fn c1_a_pair_that_fits_better_within_the_tolerance_keeps_the_kinds_class() {
    // Quad X motor 1: from 16 s an offset of +0.15 and, as the calibrated model's own error on
    // the command's swings, a gain of 1.08 about the mean command: a gain and an offset fit
    // together significantly better than the offset alone, but the pair's gain is within the
    // loss tolerance, so the class definitions read the pair as a bias too. The MIT-UKF reads
    // a gain of 1.3 instead (the mixed fallback's bias). The data's bias is followed; a pair
    // gain beyond the tolerance (1.3) is not.
    let run = |pair_gain: f64| {
        let mut f = Flight::new("quad-x");
        let est = |t: f64| {
            let mut e = vec![healthy(0.02); 4];
            if t >= 16.0 {
                e[0] = estimate(1.3, 0.05, 0.0, 0.02);
            }
            e
        };
        let change = move |t: f64, u: &[f64]| {
            let d = if t >= 16.0 {
                0.15 + (pair_gain - 1.0) * (u[0] - 0.5)
            } else {
                0.0
            };
            (0usize, d)
        };
        f.fly(0.0, 22.0, dithered(4, 0.5, 0.1), est, Some(&change));
        assert_eq!(
            f.events(Event::Fault).first().and_then(|d| d.class),
            Some(FaultClass::Bias),
            "{:?}",
            f.decisions
        );
        f.d.identified(0)
    };
    let id = run(1.08).expect("the data's bias is followed");
    assert_eq!(id.kind, IdentifiedKind::Offset);
    assert!((id.delta - 0.15).abs() < 0.03, "{id:?}");
    assert_eq!(run(1.3), None);
}

#[test]
fn every_decision_says_its_rule() {
    let f = hexa_motor5_stuck(true);
    assert!(!f.decisions.is_empty());
    assert!(
        f.decisions.iter().all(|d| d.rule.is_some()),
        "{:?}",
        f.decisions
    );
}

#[test]
fn a_nan_estimate_spoils_no_attribution() {
    let p = Profile::resolve("quad-x").unwrap();
    let mut d = Diagnoser::new(DiagnosisParams::default(), 1, &p, DT);
    let mut ukf = [healthy(0.1); 4];
    ukf[2].gamma = f64::NAN;
    let mut esmf = [healthy(0.1); 4];
    esmf[1].gamma = 0.6;
    let mut out = vec![];
    d.update(0.0, &[0.5; 4], &[&ukf, &esmf], &mut out);
    for f in 0..2 {
        for j in 0..4 {
            assert!(d.deviation(f, j).is_finite(), "filter {f} actuator {j}");
        }
    }
    assert!((d.deviation(1, 1) + 0.2).abs() < 1e-9);
}

#[test]
fn f3_a_clear_reading_as_large_as_a_fault_decides_what_the_estimates_show_weakly() {
    // Plane, elevator commanded about 0.1 ± 0.08; from 16 s its gain is 0.45. The filters
    // show it only weakly: a gain statistic just over its threshold (bounds up to 0.61
    // against the 0.62 the gain threshold implies), which alone alarms after about 10 s. The
    // residuals carry the change, and the whitened search (its colour learned in the first
    // 16 s) names it clearly: decided by the data within 3 s; without them, not in 6 s.
    let run = |with_data: bool| {
        let mut f = Flight::new("plane");
        let est = |t: f64| {
            let mut e = vec![healthy(0.02); 3];
            if t >= 16.0 {
                e[1] = estimate(0.58, 0.03, 0.0, 0.02);
            }
            e
        };
        let u = |t: f64| {
            vec![
                0.02 * (t * 2.0).sin(),
                0.1 + 0.08 * (t * 3.1).sin(),
                0.02 * (t * 1.7).sin(),
            ]
        };
        let change = |t: f64, u: &[f64]| (1usize, if t >= 16.0 { -0.55 * u[1] } else { 0.0 });
        f.fly(0.0, 22.0, u, est, with_data.then_some(&change as Change));
        // One decision that stands while the data name it (no clearing and deciding again).
        assert!(f.events(Event::Fault).len() <= 1, "{:?}", f.decisions);
        assert!(f.events(Event::Cleared).is_empty(), "{:?}", f.decisions);
        f.events(Event::Fault)
            .first()
            .map(|d| (d.t, d.rule, d.actuator.clone()))
    };
    let (t, rule, who) = run(true).expect("decided");
    assert_eq!((rule, who.as_deref()), (Some(Rule::F3), Some("elevator")));
    assert!(t < 19.0, "{t}");
    assert_eq!(run(false), None);
}

// The envelope (X1), the data read while nothing is under way (D2) and the rules added
// with them: in their own file, to keep each under the module size.
#[path = "vehicle_tests_more.rs"]
mod more;
