//! The ArduPilot SITL logs (replay/tlogs/sitl_*, truth in each SOURCE.md) replayed through the
//! same pipeline as `ahcmon replay`, with one profile per vehicle type and the same thresholds
//! for every log. These tests hold what is met today; the closing notes list what is not.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::diagnose::vehicle::{Decision, Event, FaultClass, Rule};
use ahcmon::estimate::vehicle::AhcEstimate;
use ahcmon::link::TlogReader;
use ahcmon::monitor::Monitor;
use ahcmon::output::Sink;
use ahcmon::pipeline::PipelineConfig;
use ahcmon::telemetry::Profile;
use std::path::PathBuf;

#[derive(Default)]
struct Collect {
    decisions: Vec<Decision>,
    /// (t, MIT-UKF gamma, delta) per actuator.
    ukf: Vec<(f64, Vec<(f64, f64)>)>,
    /// (t, every filter's estimates per actuator: MIT-UKF, MIT-ESMF, set).
    all: Vec<(f64, [Vec<AhcEstimate>; 3])>,
    messages: Vec<String>,
}

impl Sink for Collect {
    fn decision(&mut self, d: &Decision) {
        self.decisions.push(d.clone());
    }
    fn estimates(&mut self, t: f64, _: u8, est: &[&[AhcEstimate]; 3], _: &Profile) {
        self.ukf
            .push((t, est[0].iter().map(|e| (e.gamma, e.delta)).collect()));
        self.all
            .push((t, [est[0].to_vec(), est[1].to_vec(), est[2].to_vec()]));
    }
    fn message(&mut self, _: u8, text: &str) {
        self.messages.push(text.to_owned());
    }
}

/// The set filter's guaranteed bounds against a log's truth-equivalent fault on actuator `j`
/// (`gamma` the multiplier; `delta` its equivalent: `gamma - 1` for a swash servo, whose trim
/// is mid-throw, 0 for a motor, whose is at its minimum) from `on` to `off`. Gain figures count
/// the steps where the gain is excited (its bound no longer the a priori box's extent), output
/// figures those where the output is bounded; "others" are every actuator's steps but the
/// faulty one's from the onset to 2 s after the fault's end.
#[derive(Debug)]
struct SetFigures {
    /// The fault's excited steps with its gamma and delta inside the bounds.
    fault_inside: f64,
    /// The fault's bounded steps with its output `(γ - 1) ū + δ` at the recent command inside.
    output_inside: f64,
    /// When the fault's output bound first left 0 out (s after the onset; it held 0 on the
    /// last bounded step before).
    zero_out_after: Option<f64>,
    /// The others' output bounds holding 0, and their excited gain bounds holding 1.
    others_output_hold_0: f64,
    others_gain_hold_1: f64,
    /// The share of the others' steps with the gain excited.
    others_gain_excited: f64,
}

fn set_figures(c: &Collect, (on, off): (f64, f64), j: usize, gamma: f64, delta: f64) -> SetFigures {
    let share = |(n, of): (usize, usize)| n as f64 / of.max(1) as f64;
    let (mut fault, mut output, mut hold_0, mut hold_1) = ((0, 0), (0, 0), (0, 0), (0, 0));
    let (mut zero_out_after, mut held_0_before, mut steps) = (None, false, 0);
    for (t, est) in &c.all {
        for (k, e) in est[2].iter().enumerate() {
            let bounds = e.output_bounds;
            let excited = !e.unexcited[0];
            if k == j && *t < on {
                held_0_before = bounds.is_some_and(|[lo, hi]| (lo..=hi).contains(&0.0));
            }
            if k == j && *t >= on && *t < off {
                if excited {
                    fault.1 += 1;
                    fault.0 += usize::from(
                        (e.gamma_lo..=e.gamma_hi).contains(&gamma)
                            && (e.delta_lo..=e.delta_hi).contains(&delta),
                    );
                }
                if let Some([lo, hi]) = bounds {
                    let truth = (gamma - 1.0) * e.command_ref + delta;
                    output.1 += 1;
                    output.0 += usize::from((lo..=hi).contains(&truth));
                    if held_0_before && zero_out_after.is_none() && !(lo..=hi).contains(&0.0) {
                        zero_out_after = Some(t - on);
                    }
                }
            } else if k != j || *t < on || *t >= off + 2.0 {
                steps += 1;
                if let Some([lo, hi]) = bounds {
                    hold_0.1 += 1;
                    hold_0.0 += usize::from((lo..=hi).contains(&0.0));
                }
                if excited {
                    hold_1.1 += 1;
                    hold_1.0 += usize::from((e.gamma_lo..=e.gamma_hi).contains(&1.0));
                }
            }
        }
    }
    assert!(
        fault.1 > 500 && output.1 > 500 && hold_0.1 > 3000 && hold_1.1 > 1000,
        "{fault:?} {output:?} {hold_0:?} {hold_1:?}"
    );
    SetFigures {
        fault_inside: share(fault),
        output_inside: share(output),
        zero_out_after,
        others_output_hold_0: share(hold_0),
        others_gain_hold_1: share(hold_1),
        others_gain_excited: share((hold_1.1, steps)),
    }
}

/// What every log's guaranteed bounds meet (docs/results.md, the SITL table): the fault's
/// coefficients and output inside on 99 % of its steps, 0 left out within 0.1 s of the onset,
/// the others' output bounds holding 0 on 99 %; and their gain bounds holding 1 on
/// `gain_hold_1` (issue 41 asks 99 %; a guarantee means every step).
fn assert_set_figures(f: &SetFigures, gain_hold_1: f64) {
    println!("{f:?}");
    assert!(f.fault_inside >= 0.99 && f.output_inside >= 0.99, "{f:?}");
    assert!(f.zero_out_after.is_some_and(|s| s <= 0.1), "{f:?}");
    assert!(f.others_output_hold_0 >= 0.99, "{f:?}");
    // The gain figure rests on a quarter of the steps at least (the helicopter's hover excites
    // its swash servos' gains on 27 %).
    assert!(f.others_gain_excited >= 0.25, "{f:?}");
    assert!(f.others_gain_hold_1 >= gain_hold_1, "{f:?}");
}

/// A log under replay/tlogs.
fn tlog(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("replay/tlogs")
        .join(rel)
}

fn replay(rel: &str, profile: Option<&str>) -> Collect {
    let path = tlog(rel);
    let mut r = TlogReader::open(&path).unwrap();
    let mut m = Monitor::new(PipelineConfig {
        profile: profile.map(|p| Profile::resolve(p).unwrap()),
        ..PipelineConfig::default()
    });
    let mut sink = Collect::default();
    while let Some((_, f)) = r.next_frame().unwrap() {
        m.on_frame(&f, &mut sink);
    }
    m.finish(&mut sink);
    assert_eq!(r.counters.dropped(), 0);
    sink
}

fn is_fault(d: &Decision) -> bool {
    matches!(d.event, Event::Fault | Event::Changed)
}

/// The fault decisions of a log, after checking that none comes before the onset and that
/// none names another actuator; and the first on which both filters agree.
fn only_faults_on<'a>(
    c: &'a Collect,
    on: f64,
    actuator: &str,
) -> (Vec<&'a Decision>, &'a Decision) {
    let faults: Vec<&Decision> = c.decisions.iter().filter(|d| is_fault(d)).collect();
    assert!(
        faults.iter().all(|d| d.t >= on),
        "false decision before the onset: {faults:?}"
    );
    assert!(
        faults
            .iter()
            .all(|d| d.actuator.as_deref() == Some(actuator) && d.also.is_empty()),
        "another actuator flagged: {faults:?}"
    );
    let both = *faults
        .iter()
        .find(|d| d.filters.len() == 2)
        .unwrap_or_else(|| panic!("both filters isolate {actuator}: {faults:?}"));
    (faults, both)
}

/// After the fault's removal the next word on the actuator is its clearing: no `changed` with
/// the recovery's class (the quad X's motor 4 read stuck, the quad + and TradHeli logs bias, in
/// the second before the clearing).
fn cleared_without_a_new_class(c: &Collect, off: f64, actuator: &str) {
    let after: Vec<&Decision> = c
        .decisions
        .iter()
        .filter(|d| d.t > off && d.actuator.as_deref() == Some(actuator))
        .collect();
    assert!(
        after.first().is_some_and(|d| d.event == Event::Cleared),
        "{after:?}"
    );
}

/// Within one fault, the class said of the actuator never goes back to one it has left (no
/// loss, bias, loss, bias as the change test's reading of a gain-and-offset fault alternates).
fn no_class_returns(c: &Collect, actuator: &str) {
    let mut said: Vec<FaultClass> = Vec::new();
    for d in c
        .decisions
        .iter()
        .filter(|d| d.actuator.as_deref() == Some(actuator))
    {
        if d.event == Event::Cleared {
            said.clear();
            continue;
        }
        if !is_fault(d) {
            continue;
        }
        let class = d.class.expect("a fault decision has a class");
        if said.last() != Some(&class) {
            assert!(!said.contains(&class), "{said:?} then {class:?}");
            said.push(class);
        }
    }
}

#[test]
fn quadx_maneuvers_motor4_gain_fault() {
    // SOURCE.md: fault on at time_boot_ms 98604, off at 128625; motor 4, gamma 0.7.
    let (on, off) = (98.604, 128.625);
    let c = replay(
        "sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog",
        None,
    );
    // Isolated by both filters within 2 s, nothing else flagged.
    let (_, both) = only_faults_on(&c, on, "motor4");
    assert!(both.t - on <= 2.0, "both filters at +{:.2} s", both.t - on);
    // MIT-UKF gamma within 0.1 of 0.7 from 5 s after the onset until the fault is removed.
    let j = 3;
    let window: Vec<f64> = c
        .ukf
        .iter()
        .filter(|(t, _)| *t >= on + 5.0 && *t < off)
        .map(|(_, e)| e[j].0)
        .collect();
    assert!(window.len() > 1000);
    let worst = window.iter().map(|g| (g - 0.7).abs()).fold(0.0, f64::max);
    assert!(worst <= 0.1, "MIT-UKF gamma off by {worst:.3}");
    // Cleared after removal.
    cleared_without_a_new_class(&c, off, "motor4");
    no_class_returns(&c, "motor4");
    // Issue 41 asks for the healthy gain bounds to hold 1 on 99 % of the steps: 98.0 % here, a
    // floor against a further fall.
    assert_set_figures(&set_figures(&c, (on, off), 3, 0.7, 0.0), 0.975);
}

#[test]
fn quad_plus_hover_motor1_gain_fault() {
    // SOURCE.md: PARAM_VALUE echoes at log t=112.42 (on) and 132.44 (off); the log's first
    // ATTITUDE is time_boot_ms 2451 at log t=1.40, so vehicle time = log time + 1.05.
    let (on, off) = (112.42 + 1.05, 132.44 + 1.05);
    let c = replay(
        "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog",
        Some("quad-plus"),
    );
    let faults: Vec<&Decision> = c.decisions.iter().filter(|d| is_fault(d)).collect();
    assert!(
        faults.iter().all(|d| d.t >= on),
        "false decision before the onset: {faults:?}"
    );
    // Motor 1 isolated by both filters within 5 s; nothing else flagged while the fault is on.
    let both = faults
        .iter()
        .find(|d| d.filters.len() == 2 && d.actuator.as_deref() == Some("motor1"))
        .expect("both filters isolate motor1");
    assert!(both.t - on <= 5.0, "both filters at +{:.2} s", both.t - on);
    assert!(
        faults
            .iter()
            .filter(|d| d.t < off)
            .all(|d| d.actuator.as_deref() == Some("motor1")),
        "{faults:?}"
    );
    // The effective output at the operating point (gamma*u + delta, u = 0.845 the command
    // the controller settles on) within 0.05 of the truth 0.7*0.845.
    let u = 0.845;
    let e: Vec<f64> = c
        .ukf
        .iter()
        .filter(|(t, _)| *t >= on + 5.0 && *t < off)
        .map(|(_, e)| e[0].0 * u + e[0].1)
        .collect();
    let worst = e.iter().map(|v| (v - 0.7 * u).abs()).fold(0.0, f64::max);
    assert!(worst <= 0.05, "effective output off by {worst:.3}");
    // And its MIT-UKF gamma within 0.1 of 0.7 while the fault is on (after 5 s). In a still
    // hover the split into gain and bias comes from the prior (a motor's bias is rare).
    let worst = c
        .ukf
        .iter()
        .filter(|(t, _)| *t >= on + 5.0 && *t < off)
        .map(|(_, e)| (e[0].0 - 0.7).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 0.1, "MIT-UKF gamma off by {worst:.3}");
    cleared_without_a_new_class(&c, off, "motor1");
    no_class_returns(&c, "motor1");
    // The outputs' bounds hold; the healthy gains' do on 61.1 % of the excited steps, where 99 %
    // is asked and a guarantee means all (the ignored test below): a floor against a further
    // fall.
    assert_set_figures(&set_figures(&c, (on, off), 0, 0.7, 0.0), 0.60);
    // Once cleared, the MIT-UKF's gain and bias are back at the healthy point: the still
    // hover cannot move the fault's split of the output back (without the return to the prior
    // on clearing, gamma stayed at 0.87 and delta at +0.084, bounds excluding 1).
    let end = c.all.last().map_or(0.0, |(t, _)| *t);
    assert!(end >= off + 15.0, "the log ends at {end} s");
    for (t, e) in c.all.iter().filter(|(t, _)| *t >= off + 5.0) {
        let m = &e[0][0];
        assert!(
            (m.gamma - 1.0).abs() <= 0.05 && m.gamma_lo <= 1.0 && 1.0 <= m.gamma_hi,
            "t = {t}: MIT-UKF gamma {:.3} [{:.3}, {:.3}]",
            m.gamma,
            m.gamma_lo,
            m.gamma_hi
        );
        assert!(
            m.delta.abs() <= 0.02,
            "t = {t}: MIT-UKF delta {:.3}",
            m.delta
        );
    }
}

/// Helicopter logs: no `--profile` (the heartbeat says helicopter, the default head is H3-120);
/// the model is identified on the healthy stretch (`dynamics = "arx"` in the profile).
#[test]
fn heli_hover_servo1_gain_fault() {
    // SOURCE.md: PARAM_VALUE echoes at log t=92.27 (on) and 112.29 (off); the first ATTITUDE
    // is time_boot_ms 23279 at log t=0.001, so vehicle time = log time + 23.278.
    let (on, off) = (92.27 + 23.278, 112.29 + 23.278);
    let c = replay(
        "sitl_heli_servo1_gain0p7/arducopter-heli_sitl_servo1_mul0.7.tlog",
        None,
    );
    let (_, both) = only_faults_on(&c, on, "swash1");
    assert!(both.t - on <= 5.0, "both filters at +{:.2} s", both.t - on);
    // Truth: the physics sees (pwm - 1000) * 0.7 + 1000. ArduPilot drives a swash servo at
    // 1500 µs trim ± 500 µs for a full command (SERVOn_MIN/MAX only clip), so in normalised
    // units that is gamma 0.7, delta -0.3. The controller holds servo 1 at 1858 ± 25 µs
    // (SOURCE.md), u = 0.716 ± 0.05, so the effective output deviation at the operating point
    // is -(0.3 u + 0.3) = -0.515 ± 0.015. Rates alone cannot split a swash servo's deviation
    // from the collective, so the deviation judged is the one the measurements attribute to
    // swash1 (both filters), from 5 s after the onset until the removal: within 20 µs on 99 %
    // of the steps, and on every step within 20 µs plus the truth's own spread over the
    // operating point (±0.015: the reference is its mean, not each step's command).
    let truth_dev = -(0.3 * 0.716 + 0.3);
    let tolerance = 20.0 / 500.0;
    let (mut n, mut within) = (0, [0usize; 2]);
    for (t, est) in c.all.iter().filter(|(t, _)| *t >= on + 5.0 && *t < off) {
        // The deviation statistic is the two detectors'.
        for (f, e) in est.iter().take(2).enumerate() {
            let dev = e[0].deviation;
            assert!(
                (dev - truth_dev).abs() <= tolerance + 0.015,
                "filter {f} at t={t:.2}: deviation {dev:.3}"
            );
            within[f] += usize::from((dev - truth_dev).abs() <= tolerance);
        }
        n += 1;
    }
    assert!(n > 500, "{n} steps in the window");
    for (f, w) in within.iter().enumerate() {
        assert!(
            *w * 100 >= n * 99,
            "filter {f}: {w} of {n} steps within 20 µs"
        );
    }
    // The truth (0.7, -0.3) inside every filter's bounds once the MIT-UKF has settled (10 s
    // after the onset; the split into gain and bias needs the command's transient to fade).
    for (t, est) in c.all.iter().filter(|(t, _)| *t >= on + 10.0 && *t < off) {
        for (f, e) in est.iter().enumerate() {
            let e = &e[0];
            assert!(
                e.gamma_lo <= 0.7 && 0.7 <= e.gamma_hi && e.delta_lo <= -0.3 && -0.3 <= e.delta_hi,
                "filter {f} at t={t:.2}: gamma [{:.3}, {:.3}], delta [{:.3}, {:.3}]",
                e.gamma_lo,
                e.gamma_hi,
                e.delta_lo,
                e.delta_hi
            );
        }
    }
    assert!(c.decisions.iter().any(|d| d.event == Event::Cleared
        && d.t > off
        && d.actuator.as_deref() == Some("swash1")));
    // Gain and offset both off: the class found for it stays (it read loss, bias, loss, bias
    // from 120 s to 132 s). Nor is it called stuck while the MIT-UKF's gamma swings through
    // zero on its way from 1 (it read stuck for 3 s).
    no_class_returns(&c, "swash1");
    assert_set_figures(&set_figures(&c, (on, off), 0, 0.7, -0.3), 0.99);
    assert!(
        c.decisions
            .iter()
            .all(|d| d.class != Some(FaultClass::Stuck)),
        "{:?}",
        c.decisions
    );
}

#[test]
fn heli_maneuvers_servo3_gain_fault() {
    // SOURCE.md: fault on at time_boot_ms 108195, off at 138213; swash servo 3, gain 0.75.
    let (on, off) = (108.195, 138.213);
    let c = replay(
        "sitl_heli_maneuvers_servo3_gain0p75/sitl_heli_maneuvers_servo3_gain0p75.tlog",
        None,
    );
    let (faults, both) = only_faults_on(&c, on, "swash3");
    assert!(both.t - on <= 2.0, "both filters at +{:.2} s", both.t - on);
    // A gain loss is never called a bias: the first decision (the MIT-ESMF's, the MIT-UKF
    // still at gamma 1.00, delta 0.000) said bias from the sign of noise, and kept it 6.6 s.
    // The class is loss of effectiveness by +3 s.
    let classes: Vec<(f64, FaultClass)> = faults
        .iter()
        .map(|d| (d.t - on, d.class.expect("a class")))
        .collect();
    assert!(
        classes.iter().all(|(_, c)| *c != FaultClass::Bias),
        "{classes:?}"
    );
    assert!(
        classes
            .iter()
            .any(|(t, c)| *t <= 3.0 && *c == FaultClass::LossOfEffectiveness),
        "{classes:?}"
    );
    // The manoeuvres move servo 3 enough to separate gain and bias: its MIT-UKF gamma within
    // 0.1 of 0.75 from 5 s after the onset until the removal.
    let window: Vec<f64> = c
        .ukf
        .iter()
        .filter(|(t, _)| *t >= on + 5.0 && *t < off)
        .map(|(_, e)| e[2].0)
        .collect();
    assert!(window.len() > 1000);
    let worst = window.iter().map(|g| (g - 0.75).abs()).fold(0.0, f64::max);
    assert!(worst <= 0.1, "MIT-UKF gamma off by {worst:.3}");
    cleared_without_a_new_class(&c, off, "swash3");
    no_class_returns(&c, "swash3");
    assert_set_figures(&set_figures(&c, (on, off), 2, 0.75, -0.25), 0.99);
}

/// The hover quad's healthy motors' gain bounds hold 1 on 99 % of the excited steps, as issue
/// 41 asks: they do on 61.1 % (its hover calibration's yaw is some 2.8 times too weak, and the
/// fault's first 0.4 s cut motors 3 and 4 beside the truth; motor 1's excludes 1 for 14.7 s after
/// the fault; docs/results.md).
#[test]
#[ignore = "known defect, open in issue 41: 61.1 % (docs/results.md, the SITL table)"]
fn quad_plus_hover_healthy_gain_bounds_hold_1() {
    let (on, off) = (112.42 + 1.05, 132.44 + 1.05);
    let c = replay(
        "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog",
        Some("quad-plus"),
    );
    assert_set_figures(&set_figures(&c, (on, off), 0, 0.7, 0.0), 0.99);
}

#[test]
fn a_profile_for_another_vehicle_is_warned_about_twice() {
    let rel = "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog";
    let warned = |run: &Collect, what: &str| {
        run.messages.iter().any(|m| m.contains(what))
            || run.decisions.iter().any(|d| {
                d.event == Event::CannotEstimate
                    && d.detail.as_deref().is_some_and(|t| t.contains(what))
            })
    };
    // Chosen from the HEARTBEAT: neither warning.
    let run = replay(rel, None);
    assert!(!warned(&run, "mean nothing") && !warned(&run, "worse than a constant"));
    // A plane's profile on the quadrotor: the HEARTBEAT says so before the flight, and the
    // calibration's fit after 20 s (roll R² = -46) as a cannot_estimate decision.
    let run = replay(rel, Some("plane"));
    assert!(warned(&run, "mean nothing"), "{:?}", run.messages);
    assert!(warned(&run, "worse than a constant"), "{:?}", run.messages);
    // Its next stretch fits pitch and yaw, but roll moved with nothing in the plane's
    // geometry to explain it: the aileron, acting on roll alone, is not judged (G2), and no
    // decision but that one is made on it.
    let on_aileron: Vec<_> = (run.decisions.iter())
        .filter(|d| d.actuator.as_deref() == Some("aileron"))
        .collect();
    assert_eq!(on_aileron.len(), 1, "{on_aileron:?}");
    assert_eq!(on_aileron[0].event, Event::CannotJudge);
    assert_eq!(on_aileron[0].rule, Some(Rule::G2));
    assert!(on_aileron[0].gamma.is_none());
    assert!(
        (on_aileron[0].detail.as_deref()).is_some_and(|t| t.contains("roll (it moved")),
        "{on_aileron:?}"
    );
    // As written to the decisions JSONL, it validates against the schema (jsonschema).
    let schema = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/replay/schemas/decisions.schema.json"
    );
    let line = serde_json::to_string(on_aileron[0]).unwrap();
    let checked = common::run_python(&[
        "-c",
        "import json, sys, jsonschema; jsonschema.validate(json.loads(sys.argv[2]), json.load(open(sys.argv[1])), cls=jsonschema.Draft202012Validator); print('valid')",
        schema,
        &line,
    ]);
    assert!(checked.contains("valid"), "{checked}");
}

/// `ahcmon calibrate LOG --until UNTIL -o OUT`, and the profile it wrote.
fn calibrated(log: &std::path::Path, until: &str, out: &std::path::Path) -> Profile {
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .arg("calibrate")
        .arg(log)
        .args(["--until", until, "-o"])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    Profile::resolve(out.to_str().unwrap()).unwrap()
}

#[test]
fn calibrate_writes_a_profile_that_replay_uses() {
    let dir = common::temp_dir("sitl_calibrate");
    let out = dir.join("quadx.toml");
    let log = tlog("sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog");
    let p = calibrated(&log, "90", &out);
    assert_eq!(p.name, "quad-x-calibrated");
    assert!(p.identified);
    // The identified X pattern: motor 1 (front right) rolls left and pitches up.
    let g = p.actuators[0].effectiveness.unwrap();
    assert!(g[0] < 0.0 && g[1] > 0.0, "{g:?}");
    // The replay uses the identified model as it is (no calibration in flight).
    let c = replay(
        "sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog",
        Some(out.to_str().unwrap()),
    );
    assert!(
        c.messages
            .iter()
            .any(|m| m.starts_with("estimating with the profile's identified model")),
        "{:?}",
        c.messages
    );
    assert!(!c.messages.iter().any(|m| m.starts_with("calibrated on")));
    assert!(
        c.decisions
            .iter()
            .filter(|d| is_fault(d))
            .all(|d| d.actuator.as_deref() == Some("motor4") && d.t >= 98.604)
    );
    // Past the end of the log: a clear error, exit 2.
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .arg("calibrate")
        .arg(&log)
        .args(["--until", "100000", "-o"])
        .arg(dir.join("never.toml"))
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("no healthy stretch ending at t = 100000 s")
            && err.contains("chosen to end at t=100000 s"),
        "{err}"
    );
}

/// A helicopter's identified profile at another telemetry rate than it was identified at: its
/// discrete model does not hold there, so the monitor calibrates in flight instead (it used to
/// fail the run for good).
#[test]
fn a_helicopter_profile_identified_at_another_rate_calibrates_in_flight() {
    let dir = common::temp_dir("sitl_heli_identified_rate");
    let rel = "sitl_heli_servo1_gain0p7/arducopter-heli_sitl_servo1_mul0.7.tlog";
    let out = dir.join("heli.toml");
    let mut p = calibrated(&tlog(rel), "110", &out);
    assert!(p.identified && p.model.arx.is_some());
    // At its own rate the model is used as it is.
    let c = replay(rel, Some(out.to_str().unwrap()));
    assert!(
        c.messages
            .iter()
            .any(|m| m.starts_with("estimating with the profile's"))
    );
    // As if identified at 40 Hz (this log is 50 Hz).
    p.model.arx.as_mut().unwrap().dt = 0.025;
    p.rate_hz = 40.0;
    let other = dir.join("heli-40hz.toml");
    std::fs::write(&other, toml::to_string(&p).unwrap()).unwrap();
    let c = replay(rel, Some(other.to_str().unwrap()));
    assert!(
        c.messages
            .iter()
            .any(|m| m.contains("calibrating in flight instead")),
        "{:?}",
        c.messages
    );
    assert!(c.messages.iter().any(|m| m.starts_with("calibrated on")));
    // And the fault is found (SOURCE.md: servo 1 from t = 115.55 s).
    let (_, both) = only_faults_on(&c, 115.55, "swash1");
    assert!(both.t - 115.55 <= 2.0, "{both:?}");
}

#[test]
fn replay_plot_of_the_heli_log_is_valid_svg_with_the_fault_marked() {
    let dir = common::temp_dir("sitl_plot");
    let svg = dir.join("heli.svg");
    let log = tlog("sitl_heli_maneuvers_servo3_gain0p75/sitl_heli_maneuvers_servo3_gain0p75.tlog");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .arg("replay")
        .arg(&log)
        .args(["--headless", "--plot"])
        .arg(&svg)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // Valid XML for a real parser.
    let script = format!(
        "import xml.etree.ElementTree as E; r = E.parse({:?}).getroot(); print(r.tag, len(list(r.iter())))",
        svg.display().to_string()
    );
    let out = common::run_python(&["-c", &script]);
    assert!(out.starts_with("{http://www.w3.org/2000/svg}svg"), "{out}");
    let text = std::fs::read_to_string(&svg).unwrap();
    for name in ["swash1", "swash2", "swash3", "tail"] {
        for panel in ["gamma", "delta", "output (γ-1)ū+δ"] {
            let heading = format!("sysid 1 · {name} (ch");
            assert!(
                text.split(&heading).skip(1).any(|rest| rest
                    .split('<')
                    .next()
                    .unwrap()
                    .contains(panel)),
                "{name} {panel} panel missing"
            );
        }
    }
    // The fault on swash3 is marked (a decision line with its label) after the onset, 108.2 s.
    assert!(text.contains(">fault "), "no fault mark");
}
