//! `ahcmon eval --matrix --fast`: the scenario matrix's fast subset (every built-in vehicle ×
//! every actuator × a loss to 0.5 and a bias of +0.15 in steady flight with the built-in
//! weather, and two healthy minutes per vehicle), flown through the replay pipeline and
//! scored against the simulator's truth and the oracle. The whole matrix is `ahcmon eval
//! --matrix --seeds N` (docs/results.md).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::ahcmon;

#[test]
fn the_fast_matrix_meets_the_detection_class_and_healthy_lines() {
    let (code, out, err) = ahcmon(&[
        "eval",
        "--matrix",
        "--fast",
        "--healthy-minutes",
        "2",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rows = doc["report"].as_array().unwrap();
    let cases = doc["cases"].as_array().unwrap();
    // 21 actuators × 2 faults + 5 healthy flights.
    assert_eq!(cases.len(), 47);
    let all = rows
        .iter()
        .find(|r| r["vehicle"] == "all" && r["kind"] == "all")
        .unwrap();
    let n = |k: &str| all[k].as_u64().unwrap() as f64;
    // Losses to 0.5 and offsets of 0.15 are within the oracle's reach on (nearly) every case.
    assert!(n("detectable") >= 40.0, "{all}");
    assert!(n("named_right") >= 0.95 * n("detectable"), "{all}");
    assert!(all["delay_p50_s"].as_f64().unwrap() <= 1.0, "{all}");
    assert!(n("class_right") >= 0.9 * n("named_right"), "{all}");
    assert_eq!(n("undetectable_wrong"), 0.0, "{all}");
    assert_eq!(n("false_before_onset"), 0.0, "{all}");
    assert_eq!(n("false_healthy"), 0.0, "{all}");
    assert!(all["healthy_h"].as_f64().unwrap() > 0.1, "{all}");
    // A fault case has the oracle's non-centrality, a healthy flight none.
    for c in cases {
        let fault = !c["case"]["fault"].is_null();
        assert_eq!(fault, !c["oracle_lambda"].is_null(), "{c}");
    }
}

/// Rule T1: in 1.5 times the gusts the thresholds were set on (and 15 % mismatch), the plane's
/// healthy flights are calibrated with their threshold raised by the gusts measured (the
/// replay says so), and have no fault decision (with the profile's threshold unraised these two
/// flights have 4 and 5, elevator and rudder, F1).
#[test]
fn healthy_flights_in_stronger_gusts_keep_the_thresholds_false_alarm_rate() {
    use ahcmon::eval::matrix::{Case, Flight, Weather, run_case};
    let dir = common::temp_dir("matrix_t1");
    for seed in [1, 3] {
        let case = Case {
            vehicle: "plane",
            fault: None,
            flight: Flight::Steady,
            weather: Weather::Rough,
            seed,
            duration_s: 600.0,
        };
        let r = run_case(&case).unwrap();
        assert!(!r.cannot_estimate && !r.cannot_judge, "{r:?}");
        assert!(r.estimating_h > 0.15, "{r:?}");
        assert_eq!(
            r.false_decisions,
            Vec::<(String, String)>::new(),
            "seed {seed}"
        );
        // The same flight as a file, replayed: the calibration raised the threshold.
        let scenario = dir.join(format!("rough-{seed}.toml"));
        let tlog = dir.join(format!("rough-{seed}.tlog"));
        let mut short = case.clone();
        short.duration_s = 40.0;
        std::fs::write(&scenario, short.scenario_toml(0.0)).unwrap();
        let args = [
            "sim",
            "--scenario",
            scenario.to_str().unwrap(),
            "--tlog",
            tlog.to_str().unwrap(),
            "-q",
        ];
        let (code, _, err) = ahcmon(&args);
        assert_eq!(code, 0, "{err}");
        let (code, _, err) = ahcmon(&["replay", tlog.to_str().unwrap(), "--headless"]);
        assert_eq!(code, 0, "{err}");
        let line = err
            .lines()
            .find(|l| l.contains("(rule T1)"))
            .unwrap_or_else(|| panic!("seed {seed}: no T1 in {err}"));
        let factor: f64 = line
            .split("gusts x")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .unwrap()
            .parse()
            .unwrap();
        assert!(factor > 1.1, "seed {seed}: {line}");
    }
}

/// Rule T1 over the flight: this rough flight's calibration stretch came in a lull and read the
/// gusts at x1.0 (no raise), and with the calibration's reading alone the elevator got an F1
/// fault decision at 367 s. The gusts measured again on the stretches after it raise the
/// threshold within the first minutes, and the flight has no fault decision.
#[test]
fn a_rough_flight_read_calm_at_its_calibration_is_raised_in_flight() {
    use ahcmon::eval::matrix::{Case, Flight, Weather, run_case};
    let case = Case {
        vehicle: "plane",
        fault: None,
        flight: Flight::Steady,
        weather: Weather::Rough,
        seed: 14,
        duration_s: 600.0,
    };
    let r = run_case(&case).unwrap();
    assert!(r.estimating_h > 0.15, "{r:?}");
    assert_eq!(r.false_decisions, Vec::<(String, String)>::new());
}
