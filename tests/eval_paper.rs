//! `eval` reproduces the paper's findings as numbers (truth from the simulator, one filter
//! configuration for every scenario).

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::eval::{Row, aggregate, run_scenario};
use ahcmon::scenario;

fn rows(name: &str, seeds: u64) -> Vec<Row> {
    let named = scenario::resolve(name).unwrap();
    let runs: Vec<_> = (0..seeds)
        .map(|i| run_scenario(&named, named.scenario.seed + i, false).unwrap())
        .collect();
    aggregate(&runs)
}

fn row<'a>(rows: &'a [Row], filter: &str) -> &'a Row {
    rows.iter().find(|r| r.filter == filter).unwrap()
}

#[test]
fn fig8_mit_ukf_settles_before_kf_ukf_and_both_before_ukf() {
    let r = rows("paper-fig8-noise-step", 3);
    let (mit, kf, ukf) = (row(&r, "mit-ukf"), row(&r, "kf-ukf"), row(&r, "ukf"));
    println!(
        "settle: mit-ukf {:?} kf-ukf {:?} ukf {:?}",
        mit.settle_s, kf.settle_s, ukf.settle_s
    );
    let mit_s = mit.settle_s.expect("MIT-UKF settles");
    let kf_s = kf.settle_s.expect("KF-UKF settles");
    assert!(mit_s < kf_s, "MIT-UKF {mit_s} s vs KF-UKF {kf_s} s");
    // The UKF either never settles in the run or settles later than both.
    assert!(
        ukf.settle_s.is_none_or(|u| u > kf_s),
        "UKF {:?}",
        ukf.settle_s
    );
}

#[test]
fn fig5_fault_detected_within_one_second_by_ukf_and_esmf() {
    for name in ["paper-fig5-gaussian", "paper-fig5-uniform"] {
        let r = rows(name, 3);
        for f in ["ukf", "esmf", "mit-ukf"] {
            let d = row(&r, f).detection_delay_s;
            assert!(
                d.is_some_and(|d| d <= 1.0),
                "{name} {f}: detection delay {d:?}"
            );
        }
    }
}

#[test]
fn fig5_uniform_truth_inside_esmf_bounds() {
    // Per seed: 100 % of the steps outside the first second after onset, >= 99.9 % of all.
    let named = scenario::resolve("paper-fig5-uniform").unwrap();
    for i in 0..3 {
        let run = run_scenario(&named, named.scenario.seed + i, false).unwrap();
        let set_filters: Vec<_> = run
            .filters
            .iter()
            .filter(|f| f.filter.ends_with("esmf"))
            .collect();
        assert_eq!(set_filters.len(), 2, "esmf and mit-esmf");
        for f in set_filters {
            let m = &f.metrics;
            println!(
                "seed +{i} {}: in bounds {:.2} % of all steps, {:.2} % outside the first second",
                f.filter, m.truth_in_bounds_pct, m.truth_in_bounds_after_1s_pct
            );
            assert_eq!(m.truth_in_bounds_after_1s_pct, 100.0, "{}", f.filter);
            assert!(m.truth_in_bounds_pct >= 99.9, "{}", f.filter);
        }
    }
}

#[test]
fn healthy_ten_minutes_ten_seeds_no_fault_decision() {
    let r = rows("healthy-10min", 10);
    for row in &r {
        assert_eq!(
            row.false_decisions, 0,
            "{}: {} false decisions",
            row.filter, row.false_decisions
        );
        assert_eq!(row.step_errors, 0, "{}", row.filter);
    }
}

#[test]
fn mit_ukf_tracks_gamma_after_the_fault() {
    // The target: after 3 s the MIT-UKF's gamma within 0.05 of the truth (Gaussian case).
    let r = rows("paper-fig8-noise-step", 3);
    let mit = row(&r, "mit-ukf");
    assert!(
        mit.gamma_rmse_steady < 0.05,
        "steady gamma RMSE {}",
        mit.gamma_rmse_steady
    );
}

#[test]
fn fig9_mit_esmf_converges_closer_than_esmf_and_both_detect() {
    // Paper finding (d): the MIT-ESMF converges faster than the ESMF in Fig. 9. Neither centre
    // settles within 0.05, and no process-noise set tried in `examples/esmf_floor` (constant or
    // scheduled with hindsight) gets the ESMF's there, so the finding is the error after the
    // fault: over the 3 s after it (the convergence) and in steady state after the noise step,
    // mean of 10 seeds (measured: 0.0709 against 0.0737, and 0.204 against 0.231). The
    // MIT-ESMF adapts the AHC process set (its rate entries stay at q0: for measured
    // coordinates the paper's loss has no minimum); without the adaptation the two filters are
    // the same and this fails.
    let r = rows("paper-fig9-uniform-step", 10);
    let (mit, esmf) = (row(&r, "mit-esmf"), row(&r, "esmf"));
    let (mit_3s, esmf_3s) = (mit.gamma_rmse_3s.unwrap(), esmf.gamma_rmse_3s.unwrap());
    println!(
        "gamma RMSE 3 s after the fault: mit-esmf {mit_3s:.4} esmf {esmf_3s:.4}; steady: \
         mit-esmf {:.4} esmf {:.4}; detection {:?} {:?}",
        mit.gamma_rmse_steady,
        esmf.gamma_rmse_steady,
        mit.detection_delay_s,
        esmf.detection_delay_s
    );
    assert!(
        mit_3s < esmf_3s,
        "3 s RMSE: mit-esmf {mit_3s} esmf {esmf_3s}"
    );
    assert!(
        mit.gamma_rmse_steady < esmf.gamma_rmse_steady,
        "steady RMSE: mit-esmf {} esmf {}",
        mit.gamma_rmse_steady,
        esmf.gamma_rmse_steady
    );
    // Pins the reason the finding is read from the error: should a centre ever settle, the
    // finding can be judged by settling time instead, and this test should say so.
    assert!(
        mit.settle_s.is_none() && esmf.settle_s.is_none(),
        "settled: mit-esmf {:?} esmf {:?}",
        mit.settle_s,
        esmf.settle_s
    );
    for row in [mit, esmf] {
        assert!(
            row.detection_delay_s.is_some_and(|d| d <= 1.0),
            "{}",
            row.filter
        );
        assert_eq!(row.false_decisions, 0, "{}", row.filter);
    }
}
