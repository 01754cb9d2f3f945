//! Vehicle profiles, simulators, diagnosis, calibration and the JSONL files (issue 4).

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::eval::run_scenario;
use ahcmon::model::RateParams;
use ahcmon::model::calibrate::{CalibrationSample, ScaledFit, calibrate, calibrate_scaled};
use ahcmon::scenario::resolve;
use ahcmon::sim::vehicle::{Gusts, ModelMismatch, VehicleSim, VehicleSimConfig};
use ahcmon::telemetry::Profile;
use std::process::Command;

fn run(name: &str, seed: u64) -> ahcmon::eval::Run {
    let named = resolve(name).unwrap();
    run_scenario(&named, seed, false).unwrap()
}

/// Every built-in fault scenario on three seeds: the first fault decision names the faulty
/// actuator within 5 s of the onset (the matrix's window), the class in force 5 s after the
/// onset is right, and no decision names any other actuator. The plane's elevator loss is
/// allowed 10 s: a surface's gain loss near trim shows only through the gain statistic, and
/// the data's alarm needs the whitened search's margin (`docs/diagnosis.md`, D2); the matrix
/// reports how often such faults take longer. The truth comes from the simulator; the
/// thresholds from healthy flights (`ahcmon thresholds`), not from these.
#[test]
fn faults_are_isolated_by_both_filters_and_classified() {
    use ahcmon::diagnose::vehicle::Event;
    for (name, actuator, class, within) in [
        ("quad-x-motor2-loe", "motor2", "loss_of_effectiveness", 5.0),
        ("heli-swash2-loe", "swash2", "loss_of_effectiveness", 5.0),
        ("hexa-x-motor3-loe", "motor3", "loss_of_effectiveness", 5.0),
        ("heli-tail-bias", "tail", "bias", 5.0),
        ("plane-aileron-bias", "aileron", "bias", 5.0),
        (
            "plane-elevator-loe",
            "elevator",
            "loss_of_effectiveness",
            10.0,
        ),
        ("quad-x-motor4-bias", "motor4", "bias", 5.0),
        ("hexa-x-motor5-stuck", "motor5", "stuck", 5.0),
    ] {
        let onset = resolve(name).unwrap().scenario.first_fault().unwrap().t;
        for seed in 1..=3 {
            let all = decisions(name, seed);
            let faults: Vec<_> = (all.iter())
                .filter(|d| matches!(d.event, Event::Fault | Event::Changed))
                .collect();
            let first = faults
                .first()
                .unwrap_or_else(|| panic!("{name} seed {seed}: none"));
            let delay = first.t - onset;
            assert!(
                (0.0..=within).contains(&delay) && first.actuator.as_deref() == Some(actuator),
                "{name} seed {seed}: {first:?}"
            );
            assert!(
                faults
                    .iter()
                    .all(|d| d.actuator.as_deref() == Some(actuator)),
                "{name} seed {seed}: {faults:?}"
            );
            let at = onset.max(first.t) + 5.0;
            let in_force = faults.iter().rev().find(|d| d.t <= at).unwrap();
            assert_eq!(
                in_force.class.map(|c| c.as_str()),
                Some(class),
                "{name} seed {seed}: {faults:?}"
            );
        }
    }
}

/// Ten minutes of healthy flight with gusts, manoeuvres and 10 % model mismatch: no fault
/// decision by either filter on any vehicle (3 seeds here, 10 in the README's eval run).
#[test]
fn healthy_flights_with_gusts_and_mismatch_raise_no_fault() {
    for seed in 1..=3 {
        for name in [
            "quad-x-healthy-gusts",
            "hexa-x-healthy-gusts",
            "heli-healthy-gusts",
            "plane-healthy-gusts",
        ] {
            let r = run(name, seed);
            assert_eq!(r.filters.len(), 2);
            for f in &r.filters {
                assert_eq!(
                    f.metrics.false_decisions, 0,
                    "{name} seed {seed} {}",
                    f.filter
                );
            }
        }
    }
}

/// A still hover cannot separate gain from bias: `excitation_low`, never a fault.
#[test]
fn still_hover_reports_excitation_low_not_a_fault() {
    let r = run("quad-x-hover-still", 1);
    for f in &r.filters {
        assert_eq!(f.metrics.false_decisions, 0);
        assert!(f.metrics.excitation_low >= 1);
    }
}

/// Least squares recovers the simulator's D and G (which differ from the profile by the
/// mismatch) within 5 % from 60 s of healthy flight with dither and gyro noise.
#[test]
fn calibration_recovers_damping_and_effectiveness() {
    for (name, fit_offset) in [("plane", true), ("quad-x", false)] {
        let profile = Profile::resolve(name).unwrap();
        let mismatch = ModelMismatch {
            damping: 1.15,
            effectiveness: 0.85,
        };
        let truth = profile
            .rate_params()
            .scaled(mismatch.damping, mismatch.effectiveness);
        // Calm air: a gust the controller reacts to is a disturbance correlated with the
        // commands, which biases any closed-loop least-squares fit (measured: plane roll
        // damping -12 % under 0.3 rad/s² gusts). Calibrate on a calm stretch.
        let cfg = VehicleSimConfig {
            mismatch,
            ..VehicleSimConfig::calm(profile.clone(), 0.02, 5)
        };
        let mut sim = VehicleSim::new(cfg).unwrap();
        let l = profile.actuators.len();
        let samples: Vec<_> = (0..3000).map(|_| sim.step()).collect();
        let az = profile.model.measure_az;
        let cal: Vec<CalibrationSample> = samples
            .iter()
            .enumerate()
            .map(|(k, s)| CalibrationSample {
                rates: [s.y[0], s.y[1], s.y[2]],
                u: &s.u[..l],
                az: az.then_some(s.y[3]),
                follows_previous: true,
                measured: true,
                step: k as u64,
            })
            .collect();
        let (fit, quality) = calibrate(&cal, 0.02, fit_offset).unwrap();
        for i in 0..3 {
            let rel = (fit.damping[i] - truth.damping[i]).abs() / truth.damping[i];
            assert!(
                rel < 0.05,
                "{name} D[{i}]: {} vs {}",
                fit.damping[i],
                truth.damping[i]
            );
            assert!(
                quality.r_squared[i] > 0.5,
                "{name} R² {:?}",
                quality.r_squared
            );
        }
        // Relative to the largest entry of each row: the zero entries stay near zero.
        for i in 0..3 {
            let scale = (0..l)
                .map(|j| truth.effectiveness[j][i].abs())
                .fold(0.0, f64::max);
            for j in 0..l {
                let err = (fit.effectiveness[j][i] - truth.effectiveness[j][i]).abs() / scale;
                assert!(
                    err < 0.05,
                    "{name} G[{i}][{j}]: {} vs {}",
                    fit.effectiveness[j][i],
                    truth.effectiveness[j][i]
                );
            }
        }
    }
}

/// `ahcmon sim --truth/--decisions/--estimates` write JSONL that validates against the schemas
/// in replay/schemas, checked by the `jsonschema` package (an independent validator).
#[test]
fn jsonl_files_validate_against_their_schemas() {
    let dir = common::temp_dir("jsonl");
    let (truth, decisions, estimates) = (
        dir.join("truth.jsonl"),
        dir.join("decisions.jsonl"),
        dir.join("estimates.jsonl"),
    );
    let out = Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(["sim", "--scenario", "quad-x-motor2-loe", "--truth"])
        .arg(&truth)
        .arg("--decisions")
        .arg(&decisions)
        .arg("--estimates")
        .arg(&estimates)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let schemas = concat!(env!("CARGO_MANIFEST_DIR"), "/replay/schemas");
    let script = r#"
import json, sys, jsonschema
schemas, pairs = sys.argv[1], sys.argv[2:]
for kind, path in zip(pairs[::2], pairs[1::2]):
    schema = json.load(open(f"{schemas}/{kind}.schema.json"))
    jsonschema.Draft202012Validator.check_schema(schema)
    v = jsonschema.Draft202012Validator(schema)
    n = 0
    events = set()
    for line in open(path):
        rec = json.loads(line)
        errors = list(v.iter_errors(rec))
        if errors:
            sys.exit(f"{path}:{n+1}: {errors[0].message}")
        events.add(rec.get("event"))
        n += 1
    print(kind, n, sorted(e for e in events if e))
"#;
    let out = common::run_python(&[
        "-c",
        script,
        schemas,
        "truth",
        truth.to_str().unwrap(),
        "decisions",
        decisions.to_str().unwrap(),
        "estimates",
        estimates.to_str().unwrap(),
    ]);
    assert!(out.contains("truth 2000 "), "{out}");
    // Three records a step: the MIT-UKF, the MIT-ESMF and the set filter.
    assert!(out.contains("estimates 6000 "), "{out}");
    assert!(out.contains("'fault'"), "{out}");
}

/// `gamma_off_after_5s_pct` (issue 4: "the MIT-UKF's gamma within 0.05 of truth within 5 s")
/// recomputed from every step's estimate and the simulator's truth; none for a healthy flight.
#[test]
fn gamma_off_after_5s_is_what_the_steps_say() {
    use ahcmon::diagnose::vehicle::Decision;
    use ahcmon::estimate::vehicle::AhcEstimate;
    use ahcmon::eval::vehicle::run_vehicle_scenario;
    use ahcmon::output::Sink;
    use ahcmon::sim::vehicle::VehicleSample;
    struct Count {
        j: usize,
        from: f64,
        /// The truth of the sample being estimated (the eval hands it over first).
        gamma_true: f64,
        steps: [usize; 2],
        off: [usize; 2],
    }
    impl Sink for Count {
        fn truth(&mut self, s: &VehicleSample, _: &Profile) {
            self.gamma_true = s.gamma[self.j];
        }
        fn estimates(&mut self, t: f64, _: u8, est: &[&[AhcEstimate]; 3], _: &Profile) {
            if t < self.from {
                return;
            }
            for (f, row) in est.iter().take(2).enumerate() {
                self.steps[f] += 1;
                self.off[f] += ((row[self.j].gamma - self.gamma_true).abs() > 0.05) as usize;
            }
        }
        fn decision(&mut self, _: &Decision) {}
    }
    let named = resolve("quad-x-motor2-loe").unwrap();
    let fault = named.scenario.first_fault().unwrap();
    let mut sink = Count {
        j: 1,
        from: fault.t + 5.0,
        gamma_true: f64::NAN,
        steps: [0; 2],
        off: [0; 2],
    };
    let faulty = run_vehicle_scenario(&named, 1, false, None, &mut sink).unwrap();
    for f in 0..2 {
        let want = 100.0 * sink.off[f] as f64 / sink.steps[f] as f64;
        let got = faulty.filters[f].metrics.gamma_off_after_5s_pct.unwrap();
        assert!((got - want).abs() < 1e-9, "filter {f}: {got} vs {want}");
    }
    assert!(sink.steps[0] > 1000);
    let healthy = run("quad-x-healthy-gusts", 1);
    assert!(
        healthy
            .filters
            .iter()
            .all(|f| f.metrics.gamma_off_after_5s_pct.is_none())
    );
}

/// Every decision of one seed of a built-in vehicle scenario, as the eval makes them.
fn decisions(name: &str, seed: u64) -> Vec<ahcmon::diagnose::vehicle::Decision> {
    use ahcmon::diagnose::vehicle::Decision;
    use ahcmon::eval::vehicle::run_vehicle_scenario;
    use ahcmon::output::Sink;
    struct All(Vec<Decision>);
    impl Sink for All {
        fn decision(&mut self, d: &Decision) {
            self.0.push(d.clone());
        }
    }
    let mut all = All(vec![]);
    run_vehicle_scenario(&resolve(name).unwrap(), seed, false, None, &mut all).unwrap();
    all.0
}

/// Hexa X motor 5 stuck high looks, in the rates, like opposite motor 6 losing thrust: the
/// first fault decision names motor 5, as the actuator or as the alternative in its detail
/// (where a filter's alarm on motor 6 comes before the data have a reading).
#[test]
fn a_stuck_high_hexa_motor_is_at_least_named() {
    use ahcmon::diagnose::vehicle::Event;
    for seed in 1..=3 {
        let all = decisions("hexa-x-motor5-stuck", seed);
        let first = all
            .iter()
            .find(|d| d.event == Event::Fault)
            .expect("no fault decision");
        let named_motor5 = first.actuator.as_deref() == Some("motor5")
            || first
                .detail
                .as_deref()
                .is_some_and(|d| d.contains("or motor5 giving more"));
        assert!(named_motor5, "seed {seed}: {first:?}");
    }
}

/// The filters' first fraction of a second after a motor fails: in calm air with an exact
/// model, the MIT-UKF read quad X motor 2's loss as opposite motor 1 giving more (gamma 1.53
/// within 0.24 s, seed 4), and hexa X motor 3's as motor 5's loss (seeds 3 and 4 with a
/// three times larger dither); both were decided before the change test named motor 2 or 3.
/// A motor the data do not name is held while they name another, or while it reads only as
/// an excess: the right motor alone is decided.
#[test]
fn a_motor_the_data_do_not_name_is_not_decided_at_the_onset() {
    for (name, seed, dither) in [
        ("quad-x-motor2-loe", 4, 1.0),
        ("hexa-x-motor3-loe", 3, 3.0),
        ("hexa-x-motor3-loe", 4, 3.0),
    ] {
        let mut named = resolve(name).unwrap();
        let scn = &mut named.scenario;
        scn.gusts = None;
        scn.model_mismatch = None;
        if let Some(d) = scn.attitude_dither.as_mut() {
            d.amplitude = d.amplitude.map(|a| a * dither);
        }
        let r = run_scenario(&named, seed, false).unwrap();
        for f in &r.filters {
            let m = &f.metrics;
            assert_eq!(
                m.isolated_correct,
                Some(true),
                "{name} seed {seed} {}",
                f.filter
            );
            assert_eq!(m.false_decisions, 0, "{name} seed {seed} {}", f.filter);
        }
    }
}

/// A lossy link during the calibration stretch (one sample in 10 lost, as on a radio at range):
/// the steps across each hole are left out of the fit (`follows_previous: false` on the sample
/// after it), so the fit is as good as on the full stretch. Joined as if consecutive, every
/// hole gives a row whose change spans two steps, and the fit is off.
#[test]
fn calibration_leaves_out_the_steps_across_gaps() {
    let profile = Profile::resolve("plane").unwrap();
    let truth = profile.rate_params();
    let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, 5)).unwrap();
    let l = profile.actuators.len();
    let samples: Vec<_> = (0..3000).map(|_| sim.step()).collect();
    let lost = |k: usize| k % 10 == 9;
    let fit_with = |marked: bool| {
        let cal: Vec<CalibrationSample> = samples
            .iter()
            .enumerate()
            .filter(|(k, _)| !lost(*k))
            .map(|(k, s)| CalibrationSample {
                rates: [s.y[0], s.y[1], s.y[2]],
                u: &s.u[..l],
                az: None,
                follows_previous: !(marked && k > 0 && lost(k - 1)),
                measured: true,
                step: k as u64,
            })
            .collect();
        let (fit, _) = calibrate(&cal, 0.02, true).unwrap();
        // Worst relative error of D, and of G relative to each axis's largest entry.
        (0..3)
            .map(|i| {
                let scale = (0..l)
                    .map(|j| truth.effectiveness[j][i].abs())
                    .fold(0.0, f64::max);
                let g = (0..l)
                    .map(|j| (fit.effectiveness[j][i] - truth.effectiveness[j][i]).abs() / scale)
                    .fold(0.0, f64::max);
                ((fit.damping[i] - truth.damping[i]).abs() / truth.damping[i]).max(g)
            })
            .fold(0.0, f64::max)
    };
    let (marked, joined) = (fit_with(true), fit_with(false));
    println!("worst relative error: holes left out {marked:.4}, joined {joined:.4}");
    assert!(marked < 0.05, "holes left out: {marked}");
    assert!(
        joined > 0.05 && joined > 5.0 * marked,
        "joined across the holes: {joined} (left out: {marked})"
    );
}

/// The gusty healthy flights the in-flight calibration tests fit: quad X and plane, seeds 1-3,
/// 10 % model mismatch (true factor 0.9), 60 s after the first 10. For each flight, its name,
/// seed, the true parameters and `calibrate_scaled`'s fit on the samples `lost` leaves (a lost
/// sample's successor has no outputs of the previous instant to pair with, as in the pipeline,
/// and goes too).
fn gusty_calibrations(
    lost: impl Fn(usize) -> bool,
) -> Vec<(&'static str, u64, RateParams, ScaledFit)> {
    let mut out = vec![];
    for name in ["quad-x", "plane"] {
        let profile = Profile::resolve(name).unwrap();
        let base = profile.rate_params();
        let mismatch = ModelMismatch {
            damping: 1.1,
            effectiveness: 0.9,
        };
        let truth = base.scaled(mismatch.damping, mismatch.effectiveness);
        for seed in 1..=3 {
            let cfg = VehicleSimConfig {
                mismatch,
                gusts: Some(Gusts {
                    angular: [0.5, 0.5, 0.15],
                    vertical: 0.3,
                    tau_s: 1.0,
                }),
                ..VehicleSimConfig::calm(profile.clone(), 0.02, seed)
            };
            let mut sim = VehicleSim::new(cfg).unwrap();
            let l = profile.actuators.len();
            let samples: Vec<_> = (0..3500).map(|_| sim.step()).skip(500).collect();
            let gone = |k: usize| lost(k) || (k > 0 && lost(k - 1));
            // A simulator sample holds the outputs applied over its step and the rates at its
            // end, which is what a calibration sample is.
            let cal: Vec<CalibrationSample> = samples
                .iter()
                .enumerate()
                .filter(|(k, _)| !gone(*k))
                .map(|(k, s)| CalibrationSample {
                    rates: [s.y[0], s.y[1], s.y[2]],
                    u: &s.u[..l],
                    az: None,
                    follows_previous: !(k > 0 && gone(k - 1)),
                    measured: true,
                    step: k as u64,
                })
                .collect();
            let fit = calibrate_scaled(&cal, 0.02, &base).unwrap();
            out.push((name, seed, truth.clone(), fit));
        }
    }
    out
}

/// The in-flight calibration (`calibrate_scaled`, what the live pipeline runs) in the gusts of
/// the healthy-flight scenarios. The autopilot reacts to what the wind did, so commands and
/// rates are correlated with the wind's next push, which a plain fit mistakes for weaker
/// actuators and less damping (x0.59-0.81 against a true 0.9 on roll and pitch, damping 10-30 %
/// low). With each axis fitted by maximum likelihood with the wind as a state, roll and pitch
/// over 60 s land at x0.875-0.905 (mean error 1.0 %), the damping at a mean error of 1.2 %.
/// The gusts the fit measures (rule T1's) are the scenario's: 0.45-0.59 rad/s² against 0.5,
/// mean 0.51 (one 60 s flight reads them to about 10 %).
#[test]
fn in_flight_calibration_is_not_fooled_by_gusts() {
    let (mut scale_err, mut damping_err, mut count) = (0.0, 0.0, 0.0);
    let mut gust_sum = 0.0;
    for (name, seed, truth, fit) in gusty_calibrations(|_| false) {
        for axis in 0..2 {
            assert!(
                fit.scaled[axis],
                "{name} seed {seed}: axis {axis} not excited"
            );
            let scale = (fit.scale[axis] - 0.9).abs() / 0.9;
            let d = fit.params.damping[axis];
            let damping = (d - truth.damping[axis]).abs() / truth.damping[axis];
            println!(
                "{name} seed {seed} axis {axis}: x{:.3}, D {d:.3}",
                fit.scale[axis]
            );
            assert!(
                scale < 0.1,
                "{name} seed {seed} axis {axis}: x{}",
                fit.scale[axis]
            );
            assert!(damping < 0.15, "{name} seed {seed} axis {axis}: D {d}");
            scale_err += scale;
            damping_err += damping;
            count += 1.0;
            // The wind the fit measures is the scenario's gusts (0.5 rad/s² on roll and
            // pitch): rule T1 compares it with the gusts the thresholds were set on.
            let gust = fit.gusts[axis].expect("the likelihood fit taken");
            println!("{name} seed {seed} axis {axis}: gusts {gust:.3} rad/s²");
            assert!(
                (gust - 0.5).abs() < 0.15,
                "{name} seed {seed} axis {axis}: {gust}"
            );
            gust_sum += gust;
        }
    }
    let gust_mean = gust_sum / count;
    println!("mean gusts measured {gust_mean:.3} rad/s² (the scenarios' 0.5)");
    assert!((gust_mean - 0.5).abs() < 0.05, "{gust_mean}");
    let (scale_err, damping_err) = (scale_err / count, damping_err / count);
    println!("mean relative error: factor {scale_err:.4}, damping {damping_err:.4}");
    assert!(scale_err < 0.03, "mean factor error {scale_err}");
    assert!(damping_err < 0.05, "mean damping error {damping_err}");
}

/// As [`in_flight_calibration_is_not_fooled_by_gusts`], over a link that loses one sample in
/// ten: the fit predicts across each hole with the commands interpolated. Measured: x0.86-0.90
/// against 0.9, mean error 2.1 % (the whole stream: 1.0 %). Random loss (5 %, holes of one to
/// three samples): every offset within 0.23 of the truth, factors 1.4 % off. A fit that left
/// the offset unidentified across holes put a simulated quad's roll offset at -15.9 (R² -4.7).
#[test]
fn in_flight_calibration_over_a_lossy_link_is_not_fooled_by_gusts() {
    let fits = gusty_calibrations(|k| k % 10 == 9);
    let mut scale_err = 0.0;
    for (name, seed, _, fit) in &fits {
        for axis in 0..2 {
            println!(
                "lossy {name} seed {seed} axis {axis}: x{:.3}, D {:.3}",
                fit.scale[axis], fit.params.damping[axis]
            );
            scale_err += (fit.scale[axis] - 0.9).abs() / 0.9;
        }
    }
    let scale_err = scale_err / (2 * fits.len()) as f64;
    println!("lossy mean relative error: factor {scale_err:.4}");
    assert!(scale_err < 0.07, "mean factor error {scale_err}");

    // Random loss (5 %, a fixed pseudo-random pattern): holes of one, two or three samples.
    let random = |k: usize| (k as u64).wrapping_mul(2_654_435_761) % 1000 < 50;
    let fits = gusty_calibrations(random);
    let mut scale_err = 0.0;
    for (name, seed, truth, fit) in &fits {
        for axis in 0..3 {
            let (s, c) = (fit.scale[axis], fit.params.offset[axis]);
            println!("random-loss {name} seed {seed} axis {axis}: x{s:.3}, c {c:.4}");
            // The offset is the trim (0, the plane's pitch -1.2; measured within 0.22): a fit
            // that left it unidentified put a simulated quad's roll offset at -15.9 (R² -4.7).
            assert!(
                (c - truth.offset[axis]).abs() < 0.3,
                "{name} seed {seed} axis {axis}: c {c}"
            );
            assert!(
                fit.quality.r_squared[axis] > 0.5,
                "{name} seed {seed} axis {axis}"
            );
        }
        for axis in 0..2 {
            scale_err += (fit.scale[axis] - 0.9).abs() / 0.9;
        }
    }
    let scale_err = scale_err / (2 * fits.len()) as f64;
    println!("random-loss mean relative error: factor {scale_err:.4}");
    assert!(scale_err < 0.07, "mean factor error {scale_err}");
}

/// A drifting offset is read as a drift while it grows, and step faults are not: the heli tail
/// offset ramped 0 → 0.3 over 30 s from 15 s (the tail bias scenario's flight, 60 s; a real
/// file), seeds 1-3, has drift as the class in force for most of the ramp after its first
/// decision (measured 67-79 %); the tail bias and aileron bias step faults of the same seeds
/// have no drift decision at all. (Before the change test's ramp, the drift share was 7-9 %.)
#[test]
fn a_drifting_offset_reads_as_drift_and_a_step_does_not() {
    use ahcmon::diagnose::vehicle::{Event, FaultClass};
    let base = std::fs::read_to_string("replay/scenarios/heli-tail-bias.toml").unwrap();
    let flight = &base[..base.find("[[fault]]").unwrap()];
    let ramp = flight.replace("duration_s = 40.0", "duration_s = 60.0")
        + "[[fault]]\nactuator = \"tail\"\nt = 15.0\nramp = { duration_s = 30.0, delta = 0.3 }\n";
    let dir = common::temp_dir("drift");
    let path = dir.join("heli-tail-drift.toml");
    std::fs::write(&path, ramp).unwrap();
    for seed in 1..=3 {
        let all = decisions(path.to_str().unwrap(), seed);
        let classed: Vec<_> = all
            .iter()
            .filter(|d| matches!(d.event, Event::Fault | Event::Changed | Event::Cleared))
            .collect();
        let first = classed.first().expect("decided").t;
        let mut drift_s = 0.0;
        for (i, d) in classed.iter().enumerate() {
            let end = classed.get(i + 1).map_or(60.0, |n| n.t).min(45.0);
            if d.event != Event::Cleared && d.class == Some(FaultClass::Drift) {
                drift_s += (end - d.t).max(0.0);
            }
        }
        let share = drift_s / (45.0 - first);
        assert!(
            share >= 0.5,
            "seed {seed}: drift {share:.2} of the ramp: {classed:?}"
        );
    }
    for name in ["heli-tail-bias", "plane-aileron-bias"] {
        for seed in 1..=3 {
            let all = decisions(name, seed);
            assert!(
                all.iter().all(|d| d.class != Some(FaultClass::Drift)),
                "{name} seed {seed}: {all:?}"
            );
        }
    }
}
